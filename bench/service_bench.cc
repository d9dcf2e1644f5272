// Service figures of SPEC 8 measured against the real `tempokey-server` binary on loopback,
// through the real C++ client library:
//   1. Process round trip latency (p50 / p90 / p99) of a 132-channel x 128-frame clip, sequential
//      calls after a warm-up, for a light retime, a convert and a tolerance reduction;
//   2. Process jobs per second with 16 concurrent clients against 2 workers: each client on its
//      own TCP connection, each made by Client::Connect(), and all sharing one Client;
//   3. a submit flood against the bounded queue (accepted, refused, server memory);
//   4. streaming upload MB/s of a ~50 MB clip, each upload distinct so the content digest cannot
//      short-circuit it;
// and the server's resident set (VmRSS, peak VmHWM) after each phase. Diagnostic rows marked
// "(context)" rerun a figure with the clip's samples in one channel: same bytes, one message
// each way instead of one per channel, which shows what the per-channel messages cost.
//
//   service_bench [--server_binary=PATH] [--clip=PATH|synthetic] [--calls=N] [--warmup=N]
//                 [--clients=N] [--seconds=S] [--flood_seconds=S] [--upload_mb=MB]
//                 [--uploads=N] [--server_log_level=LEVEL] [--phases=latency,throughput,...]
//   (--phases=latency_retime: the latency phase's first row alone, the SPEC 8 figure, to profile)
//
// A plain harness, not Google Benchmark: the figures are percentiles and rates over one server
// process, which Benchmark's per-iteration model does not report. The bench and the server share
// the machine's cores, as a client on the same host would; the CPU each side used is printed so
// the split (and any other load on the machine) is visible. Nothing here asserts a figure.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <latch>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "bench/server_child.h"
#include "client/client.h"
#include "grpcpp/create_channel.h"
#include "grpcpp/security/credentials.h"
#include "grpcpp/support/channel_arguments.h"
#include "proto/retry_hint.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::bench {
namespace {

using Clock = std::chrono::steady_clock;

// SPEC 8's reference shape is exactly the Bandai bow clip: 132 channels x 128 frames at 30 fps.
constexpr char kDefaultClip[] = TEMPOKEY_SHARED_DIR "/data/bvh/bandai/dataset-1_bow_active_001.bvh";
constexpr int kChannels = 132;
constexpr std::int64_t kFrames = 128;
constexpr int kServerWorkers = 2;
// A refused flood client waits at most this long, whatever the server's hint says, so the
// queue stays under pressure.
constexpr std::chrono::milliseconds kFloodMaxBackoff{20};

// ---- flags --------------------------------------------------------------------------------------

struct BenchFlags {
  std::string server_binary;  // empty: next to this binary, ../server/tempokey-server
  std::string clip = kDefaultClip;
  int calls = 2000;
  int warmup = 200;
  int clients = 16;
  double seconds = 5.0;
  double flood_seconds = 3.0;
  double upload_mb = 50.0;
  int uploads = 5;
  // The server's own default: one log line per job is part of what a deployment pays.
  std::string server_log_level = "info";
  // Comma-separated subset of latency,throughput,flood,upload (in that order), e.g. to profile one;
  // latency_retime is the latency phase's first row alone (the SPEC 8 figure; latency includes it).
  std::string phases = "latency,throughput,flood,upload";
};

// Accepts --name=value and --name value. Returns nullopt (after printing why) on a bad flag.
std::optional<BenchFlags> ParseFlags(int argc, char** argv) {
  BenchFlags flags;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    std::string value;
    if (const auto eq = arg.find('='); eq != std::string::npos) {
      value = arg.substr(eq + 1);
      arg.resize(eq);
    } else if (i + 1 < argc) {
      value = argv[++i];
    }
    bool ok = true;
    if (arg == "--server_binary") {
      flags.server_binary = value;
    } else if (arg == "--clip") {
      flags.clip = value;
    } else if (arg == "--phases") {
      flags.phases = value;
    } else if (arg == "--server_log_level") {
      flags.server_log_level = value;
    } else if (arg == "--calls") {
      ok = absl::SimpleAtoi(value, &flags.calls) && flags.calls > 0;
    } else if (arg == "--warmup") {
      ok = absl::SimpleAtoi(value, &flags.warmup) && flags.warmup >= 0;
    } else if (arg == "--clients") {
      ok = absl::SimpleAtoi(value, &flags.clients) && flags.clients > 0;
    } else if (arg == "--seconds") {
      ok = absl::SimpleAtod(value, &flags.seconds) && flags.seconds > 0;
    } else if (arg == "--flood_seconds") {
      ok = absl::SimpleAtod(value, &flags.flood_seconds) && flags.flood_seconds >= 0;
    } else if (arg == "--upload_mb") {
      ok = absl::SimpleAtod(value, &flags.upload_mb) && flags.upload_mb > 0;
    } else if (arg == "--uploads") {
      ok = absl::SimpleAtoi(value, &flags.uploads) && flags.uploads > 0;
    } else {
      std::fprintf(stderr, "unknown flag %s\n", arg.c_str());
      return std::nullopt;
    }
    if (!ok) {
      std::fprintf(stderr, "bad value '%s' for %s\n", value.c_str(), arg.c_str());
      return std::nullopt;
    }
  }
  return flags;
}

// ---- process figures ----------------------------------------------------------------------------

struct Memory {
  double rss_mib = 0.0;   // VmRSS: resident now
  double peak_mib = 0.0;  // VmHWM: the most ever resident
};

Memory ReadMemory(pid_t pid) {
  Memory memory;
  std::ifstream status(absl::StrCat("/proc/", pid, "/status"));
  std::string line;
  while (std::getline(status, line)) {
    std::istringstream fields(line);
    std::string key;
    double kib = 0.0;
    fields >> key >> kib;
    if (key == "VmRSS:") memory.rss_mib = kib / 1024.0;
    if (key == "VmHWM:") memory.peak_mib = kib / 1024.0;
  }
  return memory;
}

// CPU seconds (user + system) used so far by `pid`, from /proc/<pid>/stat fields 14 and 15.
double ProcessCpuSeconds(pid_t pid) {
  std::ifstream stat(absl::StrCat("/proc/", pid, "/stat"));
  std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
  // The command name (field 2) may hold spaces; the fields after it follow its closing ')'.
  std::istringstream fields(text.substr(text.rfind(')') + 2));
  std::string field;
  double ticks = 0.0;
  for (int index = 3; index <= 15 && fields >> field; ++index) {
    if (index >= 14) ticks += std::strtod(field.c_str(), nullptr);
  }
  return ticks / static_cast<double>(sysconf(_SC_CLK_TCK));
}

double SelfCpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  auto seconds = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_usec) * 1e-6;
  };
  return seconds(usage.ru_utime) + seconds(usage.ru_stime);
}

// Established TCP connections whose remote end is `port` on this host (the client sides of the
// server's connections). gRPC listens on a dual-stack socket, so they may be in either table.
int CountConnectionsTo(int port) {
  int count = 0;
  for (const char* table : {"/proc/net/tcp", "/proc/net/tcp6"}) {
    std::ifstream tcp(table);
    std::string line;
    std::getline(tcp, line);  // header
    while (std::getline(tcp, line)) {
      std::istringstream fields(line);
      std::string slot, local, remote, state;
      fields >> slot >> local >> remote >> state;
      const auto colon = remote.rfind(':');
      if (state == "01" && colon != std::string::npos &&
          std::strtol(remote.c_str() + colon + 1, nullptr, 16) == port) {
        ++count;
      }
    }
  }
  return count;
}

int PortOf(const std::string& target) { return std::atoi(target.c_str() + target.rfind(':') + 1); }

// ---- clips and operations -----------------------------------------------------------------------

// `kChannels` channels (a root with 6, then 42 joints with 3 rotations each) of smooth, distinct
// motion, `frames` frames at 30 fps.
core::Clip MakeSyntheticClip(std::int64_t frames) {
  core::Clip clip;
  clip.name = "synthetic";
  clip.frame_count = frames;
  constexpr int kJoints = 1 + (kChannels - 6) / 3;
  for (int j = 0; j < kJoints; ++j) {
    core::Joint joint;
    joint.name = absl::StrCat("joint", j);
    joint.parent = j - 1;
    joint.offset = {0.0, 10.0, 0.0};
    std::vector<core::ChannelKind> kinds = {core::ChannelKind::kZRotation,
                                            core::ChannelKind::kXRotation,
                                            core::ChannelKind::kYRotation};
    if (j == 0) {
      kinds.insert(kinds.begin(), {core::ChannelKind::kXPosition, core::ChannelKind::kYPosition,
                                   core::ChannelKind::kZPosition});
    }
    for (core::ChannelKind kind : kinds) {
      const int c = static_cast<int>(clip.channels.size());
      core::Channel channel{.joint = j, .kind = kind, .name = {}, .samples = {}};
      channel.samples.resize(static_cast<std::size_t>(frames));
      for (std::int64_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) * clip.frame_time_seconds;
        channel.samples[static_cast<std::size_t>(f)] =
            60.0 * std::sin(1.3 * t + 0.37 * c) + 5.0 * std::sin(7.1 * t + c);
      }
      joint.channels.push_back(c);
      clip.channels.push_back(std::move(channel));
    }
    clip.skeleton.joints.push_back(std::move(joint));
  }
  return clip;
}

// The samples of `clip` end to end in one rotation channel of one joint: the same bytes and the
// same per-sample work as `clip`, but 1 slice each way instead of one per channel, which isolates
// what the number of stream messages costs a round trip.
core::Clip OneChannelCopy(const core::Clip& clip) {
  core::Clip one;
  one.name = "one-channel";
  one.frame_time_seconds = clip.frame_time_seconds;
  one.frame_count = clip.sample_count();
  core::Channel channel{.joint = 0, .kind = core::ChannelKind::kZRotation, .name = {}, .samples = {}};
  for (const core::Channel& c : clip.channels) {
    channel.samples.insert(channel.samples.end(), c.samples.begin(), c.samples.end());
  }
  one.channels.push_back(std::move(channel));
  core::Joint joint;
  joint.name = "all";
  joint.channels = {0};
  one.skeleton.joints.push_back(std::move(joint));
  return one;
}

absl::StatusOr<core::Clip> LoadClip(const std::string& path) {
  if (path == "synthetic") return MakeSyntheticClip(kFrames);
  return core::ReadBvhFile(path);
}

// What the measured calls run, with the words the table uses.
struct Operation {
  std::string name;
  std::vector<core::PipelineStep> steps;
};

// `tempokey retime --speed 0s:1 --fps 24`: a frame-rate change at constant speed, the lightest
// real retime (one time map, the tent filter since 30 -> 24 fps compresses).
Operation RetimeToFilmRate() {
  core::RetimeStep retime;
  retime.warp.domain = core::WarpDomain::kSpeedOverSource;
  retime.warp.speed = {core::SpeedKnot{.time = {}, .speed = 1.0}};
  retime.options.output_rate = core::FrameRate{.numerator = 24, .denominator = 1};
  return {"retime speed 1, fps -> 24", {retime}};
}

Operation WrapRotations() {
  return {"convert (wrap rotations)", {core::ConvertStep{.wrap_rotations = true}}};
}

// `tempokey reduce` defaults: the tolerance method within 0.5 deg / 0.5 units.
Operation ReduceWithinTolerance() {
  return {"reduce tolerance 0.5 deg", {core::ReduceStep{}}};
}

// ---- statistics ---------------------------------------------------------------------------------

struct Percentiles {
  double p50 = 0.0, p90 = 0.0, p99 = 0.0, mean = 0.0;  // milliseconds
};

// Nearest-rank percentiles of `ms`.
Percentiles Summarize(std::vector<double> ms) {
  Percentiles p;
  if (ms.empty()) return p;
  std::sort(ms.begin(), ms.end());
  auto rank = [&](double q) {
    const auto index = static_cast<std::size_t>(std::ceil(q * static_cast<double>(ms.size()))) - 1;
    return ms[std::min(index, ms.size() - 1)];
  };
  p.p50 = rank(0.50);
  p.p90 = rank(0.90);
  p.p99 = rank(0.99);
  double sum = 0.0;
  for (double v : ms) sum += v;
  p.mean = sum / static_cast<double>(ms.size());
  return p;
}

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Server-side times of the Process calls logged since `offset` in the server's log ("process
// ... queue_wait_ms=Q run_ms=R ..."), so a round trip can be split into pipeline and the rest.
struct ServerTimes {
  Percentiles queue_wait;
  Percentiles run;
  std::size_t calls = 0;
};

ServerTimes ReadServerTimes(const std::string& log_path, std::streamoff offset) {
  std::ifstream log(log_path);
  log.seekg(offset);
  std::vector<double> queue_wait, run;
  std::string line;
  auto value_after = [&](std::string_view key) {
    const auto at = line.find(key);
    return at == std::string::npos ? -1.0 : std::strtod(line.c_str() + at + key.size(), nullptr);
  };
  while (std::getline(log, line)) {
    if (line.find("process frames=") == std::string::npos) continue;
    queue_wait.push_back(value_after("queue_wait_ms="));
    run.push_back(value_after("run_ms="));
  }
  return {Summarize(queue_wait), Summarize(run), run.size()};
}

std::streamoff LogSize(const std::string& log_path) {
  std::error_code error;
  const auto size = std::filesystem::file_size(log_path, error);
  return error ? 0 : static_cast<std::streamoff>(size);
}

// ---- 1. latency ---------------------------------------------------------------------------------

struct LatencyFigures {
  std::string operation;
  Percentiles round_trip;
  ServerTimes server;
  double progress_per_call = 0.0;  // Progress messages the client received
  double server_cpu_ms_per_call = 0.0;
  double bench_cpu_ms_per_call = 0.0;
  int failures = 0;
  std::string first_error;
};

// `warmup` unmeasured calls (connection, allocator and caches settle), then `calls` timed ones,
// one at a time. Counting progress updates shows how many messages a call streams besides the
// clip's and the result's slices.
LatencyFigures MeasureLatency(const client::Client& client, const ServerChild& server,
                              const core::Clip& clip, const Operation& operation, int warmup,
                              int calls) {
  LatencyFigures figures;
  figures.operation = operation.name;
  for (int i = 0; i < warmup; ++i) (void)client.Process(clip, operation.steps);
  const std::streamoff log_offset = LogSize(server.log_path());
  const double server_cpu_before = ProcessCpuSeconds(server.pid());
  const double bench_cpu_before = SelfCpuSeconds();
  std::int64_t progress_updates = 0;
  const core::ProgressFn count_progress = [&](double, std::string_view) { ++progress_updates; };
  std::vector<double> ms;
  ms.reserve(static_cast<std::size_t>(calls));
  for (int i = 0; i < calls; ++i) {
    const auto start = Clock::now();
    absl::StatusOr<core::PipelineResult> result =
        client.Process(clip, operation.steps, count_progress);
    ms.push_back(MillisecondsSince(start));
    if (!result.ok() && figures.failures++ == 0) figures.first_error = result.status().ToString();
  }
  figures.server_cpu_ms_per_call = (ProcessCpuSeconds(server.pid()) - server_cpu_before) * 1e3 / calls;
  figures.bench_cpu_ms_per_call = (SelfCpuSeconds() - bench_cpu_before) * 1e3 / calls;
  figures.progress_per_call = static_cast<double>(progress_updates) / calls;
  figures.round_trip = Summarize(std::move(ms));
  figures.server = ReadServerTimes(server.log_path(), log_offset);
  return figures;
}

// ---- 2. throughput ------------------------------------------------------------------------------

// How the concurrent clients reach the server.
enum class Sharing {
  kOwnConnection,  // a Client each, on a channel with its own subchannel pool: one TCP each
  kOwnConnect,     // a Client each from Client::Connect() (gRPC may share their connection)
  kSharedClient,   // one Client (one channel) used by every thread
};

const char* SharingName(Sharing sharing) {
  switch (sharing) {
    case Sharing::kOwnConnection: return "own Client, own TCP connection";
    case Sharing::kOwnConnect: return "own Client::Connect()";
    case Sharing::kSharedClient: return "one shared Client";
  }
  return "";
}

client::ClientOptions OptionsFor(const std::string& target) {
  client::ClientOptions options;
  options.target = target;
  return options;
}

// gRPC keeps one global pool of subchannels, so channels with equal arguments share a TCP
// connection; a local pool per channel gives each client a connection of its own, as separate
// client processes would have. The rest mirrors Client::Connect().
std::unique_ptr<client::Client> ClientOnOwnConnection(const std::string& target) {
  const client::ClientOptions options = OptionsFor(target);
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options.max_receive_message_bytes);
  args.SetServiceConfigJSON(client::ServiceConfigJson(options));
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  return std::make_unique<client::Client>(
      grpc::CreateCustomChannel(target, grpc::InsecureChannelCredentials(), args), options);
}

std::vector<std::unique_ptr<client::Client>> MakeClients(const std::string& target,
                                                         Sharing sharing, int count) {
  std::vector<std::unique_ptr<client::Client>> clients;
  const int distinct = sharing == Sharing::kSharedClient ? 1 : count;
  for (int i = 0; i < distinct; ++i) {
    if (sharing == Sharing::kOwnConnection) {
      clients.push_back(ClientOnOwnConnection(target));
    } else {
      // value(): OptionsFor() only sets a target, which Connect() always accepts.
      clients.push_back(client::Client::Connect(OptionsFor(target)).value());
    }
  }
  return clients;
}

struct ThroughputFigures {
  std::string label;  // how the clients connect, and the clip when it is not the reference one
  bool reference = true;  // the SPEC 8 configuration, not a diagnostic variant
  Sharing sharing = Sharing::kOwnConnection;
  int clients = 0;
  int connections = 0;
  std::int64_t jobs = 0;
  int failures = 0;
  std::string first_error;
  double seconds = 0.0;
  double jobs_per_second = 0.0;
  Percentiles round_trip;
  double server_cpu_ms_per_job = 0.0;
  double bench_cpu_ms_per_job = 0.0;
  // CPU seconds per second taken by server and bench together: well below the core count means
  // other work on the machine had the rest.
  double cores_used = 0.0;
};

// `thread_count` threads call Process back to back for `seconds`, all released at once.
ThroughputFigures MeasureThroughput(const ServerChild& server, Sharing sharing, int thread_count,
                                    const core::Clip& clip, const Operation& operation,
                                    double seconds) {
  ThroughputFigures figures;
  figures.label = SharingName(sharing);
  figures.sharing = sharing;
  figures.clients = thread_count;
  const std::vector<std::unique_ptr<client::Client>> clients =
      MakeClients(server.target(), sharing, thread_count);
  // Connect every channel (and warm the server's threads) before the clock starts.
  for (const auto& c : clients) {
    for (int i = 0; i < 5; ++i) (void)c->Process(clip, operation.steps);
  }
  figures.connections = CountConnectionsTo(PortOf(server.target()));

  std::vector<std::vector<double>> ms(static_cast<std::size_t>(thread_count));
  std::vector<int> failures(static_cast<std::size_t>(thread_count), 0);
  std::vector<std::string> errors(static_cast<std::size_t>(thread_count));
  std::latch ready(thread_count + 1);
  std::atomic<bool> stop{false};
  std::vector<std::thread> threads;
  for (int t = 0; t < thread_count; ++t) {
    threads.emplace_back([&, t] {
      const auto i = static_cast<std::size_t>(t);
      const client::Client& c = *clients[i % clients.size()];
      ready.arrive_and_wait();
      while (!stop.load(std::memory_order_relaxed)) {
        const auto start = Clock::now();
        absl::StatusOr<core::PipelineResult> result = c.Process(clip, operation.steps);
        ms[i].push_back(MillisecondsSince(start));
        if (!result.ok() && failures[i]++ == 0) errors[i] = result.status().ToString();
      }
    });
  }
  const double server_cpu_before = ProcessCpuSeconds(server.pid());
  const double bench_cpu_before = SelfCpuSeconds();
  const auto start = Clock::now();
  ready.arrive_and_wait();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  stop = true;
  for (std::thread& thread : threads) thread.join();
  figures.seconds = MillisecondsSince(start) / 1000.0;

  std::vector<double> all;
  for (std::size_t i = 0; i < ms.size(); ++i) {
    all.insert(all.end(), ms[i].begin(), ms[i].end());
    figures.failures += failures[i];
    if (figures.first_error.empty()) figures.first_error = errors[i];
  }
  figures.jobs = static_cast<std::int64_t>(all.size()) - figures.failures;
  figures.jobs_per_second = static_cast<double>(figures.jobs) / figures.seconds;
  figures.round_trip = Summarize(std::move(all));
  const double jobs = static_cast<double>(std::max<std::int64_t>(figures.jobs, 1));
  figures.server_cpu_ms_per_job = (ProcessCpuSeconds(server.pid()) - server_cpu_before) * 1e3 / jobs;
  figures.bench_cpu_ms_per_job = (SelfCpuSeconds() - bench_cpu_before) * 1e3 / jobs;
  figures.cores_used =
      (figures.server_cpu_ms_per_job + figures.bench_cpu_ms_per_job) * jobs / 1e3 / figures.seconds;
  return figures;
}

// ---- 3. flood -----------------------------------------------------------------------------------

struct FloodFigures {
  int clients = 0;
  std::int64_t accepted = 0;
  std::int64_t refused = 0;   // RESOURCE_EXHAUSTED
  std::int64_t without_hint = 0;
  std::int64_t other_errors = 0;
  std::string first_error;
  double seconds = 0.0;
};

// Every client submits inline jobs without waiting for them, backing off (capped) as the server's
// retry hint says when the queue is full; then each waits for its last accepted job, so the
// server is idle again for the next phase.
FloodFigures RunFlood(const ServerChild& server, int thread_count, const core::Clip& clip,
                      const Operation& operation, double seconds) {
  FloodFigures figures;
  figures.clients = thread_count;
  const std::vector<std::unique_ptr<client::Client>> clients =
      MakeClients(server.target(), Sharing::kOwnConnection, thread_count);
  std::vector<FloodFigures> tallies(static_cast<std::size_t>(thread_count));
  const auto start = Clock::now();
  const auto end = start + std::chrono::duration_cast<Clock::duration>(
                               std::chrono::duration<double>(seconds));
  std::vector<std::thread> threads;
  for (int t = 0; t < thread_count; ++t) {
    threads.emplace_back([&, t] {
      const client::Client& c = *clients[static_cast<std::size_t>(t)];
      FloodFigures& tally = tallies[static_cast<std::size_t>(t)];
      std::string last_job;
      while (Clock::now() < end) {
        absl::StatusOr<v1::Job> job = c.SubmitInlineJob(clip, operation.steps);
        if (job.ok()) {
          ++tally.accepted;
          last_job = job->job_id();
        } else if (job.status().code() == absl::StatusCode::kResourceExhausted) {
          ++tally.refused;
          const std::optional<std::chrono::milliseconds> hint = wire::GetRetryAfter(job.status());
          if (!hint) ++tally.without_hint;
          std::this_thread::sleep_for(std::min(hint.value_or(kFloodMaxBackoff), kFloodMaxBackoff));
        } else if (tally.other_errors++ == 0) {
          tally.first_error = job.status().ToString();
        }
      }
      if (!last_job.empty()) (void)c.WatchJob(last_job, {});
    });
  }
  for (std::thread& thread : threads) thread.join();
  figures.seconds = MillisecondsSince(start) / 1000.0;
  for (const FloodFigures& tally : tallies) {
    figures.accepted += tally.accepted;
    figures.refused += tally.refused;
    figures.without_hint += tally.without_hint;
    figures.other_errors += tally.other_errors;
    if (figures.first_error.empty()) figures.first_error = tally.first_error;
  }
  return figures;
}

// ---- 4. upload ----------------------------------------------------------------------------------

struct UploadFigures {
  double megabytes = 0.0;  // of samples, 10^6 bytes
  std::vector<double> mb_per_second;
  double median = 0.0, best = 0.0;
  int failures = 0;
  std::string first_error;
  double server_cpu_s_per_upload = 0.0;
  double bench_cpu_s_per_upload = 0.0;
};

// Uploads a clip of about `megabytes` of samples `count` times, one sample changed each time so
// the server's content digest sees a new clip and stores it again.
UploadFigures MeasureUpload(const ServerChild& server, double megabytes, int count) {
  const std::unique_ptr<client::Client> c = ClientOnOwnConnection(server.target());
  const auto frames = static_cast<std::int64_t>(megabytes * 1e6 / (8.0 * kChannels));
  core::Clip clip = MakeSyntheticClip(frames);
  UploadFigures figures;
  figures.megabytes = static_cast<double>(clip.sample_count()) * 8.0 / 1e6;
  const double server_cpu_before = ProcessCpuSeconds(server.pid());
  const double bench_cpu_before = SelfCpuSeconds();
  for (int i = 0; i < count; ++i) {
    clip.channels[0].samples[0] = 1000.0 + i;
    const auto start = Clock::now();
    absl::StatusOr<v1::UploadClipResponse> response = c->UploadClip(clip);
    const double seconds = MillisecondsSince(start) / 1000.0;
    if (!response.ok()) {
      if (figures.failures++ == 0) figures.first_error = response.status().ToString();
      continue;
    }
    figures.mb_per_second.push_back(figures.megabytes / seconds);
  }
  figures.server_cpu_s_per_upload = (ProcessCpuSeconds(server.pid()) - server_cpu_before) / count;
  figures.bench_cpu_s_per_upload = (SelfCpuSeconds() - bench_cpu_before) / count;
  std::vector<double> sorted = figures.mb_per_second;
  std::sort(sorted.begin(), sorted.end());
  if (!sorted.empty()) {
    figures.median = sorted[sorted.size() / 2];
    figures.best = sorted.back();
  }
  return figures;
}

// ---- report -------------------------------------------------------------------------------------

void PrintHeader(int argc, char** argv, const BenchFlags& flags, const core::Clip& clip,
                 const ServerChild& server, const std::vector<std::string>& server_flags) {
  std::string command;
  for (int i = 0; i < argc; ++i) absl::StrAppend(&command, i ? " " : "", argv[i]);
  std::string server_command = flags.server_binary + " --address 127.0.0.1:0";
  for (const std::string& f : server_flags) absl::StrAppend(&server_command, " ", f);
  double load[3] = {0, 0, 0};
  getloadavg(load, 3);
  std::printf("command:  %s\nserver:   %s  (pid %d, %s, log %s)\n", command.c_str(),
              server_command.c_str(), static_cast<int>(server.pid()), server.target().c_str(),
              server.log_path().c_str());
  std::printf("machine:  %u CPUs online to this process, load average %.2f %.2f %.2f at start\n",
              std::thread::hardware_concurrency(), load[0], load[1], load[2]);
  std::printf("clip:     %s: %zu channels x %lld frames at %.4g fps\n\n", flags.clip.c_str(),
              clip.channels.size(), static_cast<long long>(clip.frame_count), clip.frame_rate());
}

void PrintLatency(const LatencyFigures& f, int calls) {
  std::printf("  %-26s round trip p50 %6.3f  p90 %6.3f  p99 %6.3f  mean %6.3f ms\n"
              "  %-26s server log: run p50 %.1f ms, queue p50 %.1f ms (%zu calls logged); "
              "CPU/call server %.3f ms, bench %.3f ms; %.1f progress messages/call%s\n",
              f.operation.c_str(), f.round_trip.p50, f.round_trip.p90, f.round_trip.p99,
              f.round_trip.mean, "", f.server.run.p50, f.server.queue_wait.p50, f.server.calls,
              f.server_cpu_ms_per_call, f.bench_cpu_ms_per_call, f.progress_per_call,
              f.failures ? absl::StrCat("  FAILED ", f.failures, "/", calls, ": ",
                                        f.first_error).c_str()
                         : "");
}

void PrintThroughput(const ThroughputFigures& f) {
  std::printf("  %-44s %2d threads, %2d TCP: %7.0f jobs/s (%lld in %.2f s)  round trip p50 "
              "%6.2f p99 %6.2f ms  CPU/job server %.3f ms, bench %.3f ms (%.2f cores)%s\n",
              f.label.c_str(), f.clients, f.connections, f.jobs_per_second,
              static_cast<long long>(f.jobs), f.seconds, f.round_trip.p50, f.round_trip.p99,
              f.server_cpu_ms_per_job, f.bench_cpu_ms_per_job, f.cores_used,
              f.failures ? absl::StrCat("  FAILED ", f.failures, ": ", f.first_error).c_str()
                         : "");
}

struct Summary {
  std::vector<LatencyFigures> latency;
  std::vector<ThroughputFigures> throughput;
  std::optional<FloodFigures> flood;
  std::optional<UploadFigures> upload;
  std::vector<std::pair<std::string, Memory>> memory;  // after each phase, in order
  int server_exit = -1;
};

void RecordMemory(const ServerChild& server, const std::string& when, Summary& summary) {
  summary.memory.emplace_back(when, ReadMemory(server.pid()));
  const Memory& m = summary.memory.back().second;
  std::printf("  server memory after %s: VmRSS %.1f MiB, VmHWM (peak) %.1f MiB\n", when.c_str(),
              m.rss_mib, m.peak_mib);
}

// `retime_only`: the SPEC 8 figure's row alone (the film-rate retime), for profiles.
void RunLatencyPhase(const BenchFlags& flags, const ServerChild& server, const core::Clip& clip,
                     bool retime_only, Summary& summary) {
  std::printf("\n1. Process latency, %d sequential calls after %d warm-up calls, one client\n",
              flags.calls, flags.warmup);
  const std::unique_ptr<client::Client> c = ClientOnOwnConnection(server.target());
  std::vector<Operation> operations = {RetimeToFilmRate()};
  if (!retime_only) {
    operations.push_back(WrapRotations());
    operations.push_back(ReduceWithinTolerance());
  }
  for (const Operation& operation : operations) {
    summary.latency.push_back(
        MeasureLatency(*c, server, clip, operation, flags.warmup, flags.calls));
    PrintLatency(summary.latency.back(), flags.calls);
  }
  if (retime_only) {
    RecordMemory(server, "latency", summary);
    return;
  }
  Operation one_channel = WrapRotations();
  one_channel.name = absl::StrCat("convert, 1 ch x ", clip.sample_count(), " f");
  summary.latency.push_back(MeasureLatency(*c, server, OneChannelCopy(clip), one_channel,
                                           flags.warmup, flags.calls));
  PrintLatency(summary.latency.back(), flags.calls);
  RecordMemory(server, "latency", summary);
}

void RunThroughputPhase(const BenchFlags& flags, const ServerChild& server,
                        const core::Clip& clip, Summary& summary) {
  std::printf("\n2. Process throughput, %s, %.1f s each, server with %d workers\n",
              RetimeToFilmRate().name.c_str(), flags.seconds, kServerWorkers);
  for (Sharing sharing : {Sharing::kOwnConnection, Sharing::kOwnConnect, Sharing::kSharedClient}) {
    summary.throughput.push_back(MeasureThroughput(server, sharing, flags.clients, clip,
                                                   RetimeToFilmRate(), flags.seconds));
    PrintThroughput(summary.throughput.back());
  }
  // The same convert on both shapes: the difference is what the per-channel messages cost
  // (a retime of one long Euler channel does different work from 44 joints' quaternions).
  const core::Clip one_channel = OneChannelCopy(clip);
  for (const core::Clip* shape : {&clip, &one_channel}) {
    ThroughputFigures f = MeasureThroughput(server, Sharing::kOwnConnection, flags.clients, *shape,
                                            WrapRotations(), flags.seconds);
    f.label = absl::StrFormat("own TCP, convert, %d ch x %d f", shape->channels.size(),
                              shape->frame_count);
    f.reference = false;
    summary.throughput.push_back(std::move(f));
    PrintThroughput(summary.throughput.back());
  }
  RecordMemory(server, "throughput", summary);
}

// Twice the throughput phase's clients, as the flood test does, so the queue surely fills.
void RunFloodPhase(const BenchFlags& flags, const ServerChild& server, const core::Clip& clip,
                   Summary& summary) {
  std::printf("\n3. Flood: inline SubmitJob without waiting for results, default queue (64)\n");
  const FloodFigures f =
      RunFlood(server, flags.clients * 2, clip, RetimeToFilmRate(), flags.flood_seconds);
  std::printf("  %d clients, %.1f s: %lld accepted, %lld refused RESOURCE_EXHAUSTED "
              "(%lld without a retry hint), %lld other errors %s\n",
              f.clients, f.seconds, static_cast<long long>(f.accepted),
              static_cast<long long>(f.refused), static_cast<long long>(f.without_hint),
              static_cast<long long>(f.other_errors), f.first_error.c_str());
  summary.flood = f;
  RecordMemory(server, "flood", summary);
}

void RunUploadPhase(const BenchFlags& flags, const ServerChild& server, Summary& summary) {
  std::printf("\n4. Streaming upload, %d distinct uploads, slices of %lld bytes (default)\n",
              flags.uploads, static_cast<long long>(wire::kDefaultSliceBytes));
  const UploadFigures f = MeasureUpload(server, flags.upload_mb, flags.uploads);
  std::printf("  %.1f MB each:", f.megabytes);
  for (double rate : f.mb_per_second) std::printf(" %.0f", rate);
  std::printf(" MB/s; CPU per upload server %.3f s, bench %.3f s%s\n", f.server_cpu_s_per_upload,
              f.bench_cpu_s_per_upload,
              f.failures ? absl::StrCat("  FAILED ", f.failures, ": ", f.first_error).c_str() : "");
  summary.upload = f;
  RecordMemory(server, "upload", summary);
}

void PrintTable(const Summary& s) {
  auto row = [](const std::string& figure, const char* target, const std::string& measured) {
    std::printf("| %-62s | %-13s | %-40s |\n", figure.c_str(), target, measured.c_str());
  };
  std::printf("\nSPEC 8, Service\n");
  row("figure", "target", "measured");
  std::printf("|%s|%s|%s|\n", std::string(64, '-').c_str(), std::string(15, '-').c_str(),
              std::string(42, '-').c_str());
  for (std::size_t i = 0; i < s.latency.size(); ++i) {
    const LatencyFigures& f = s.latency[i];
    row(absl::StrCat("Process round trip p50, ", f.operation), i == 0 ? "<= 2 ms" : "(context)",
        absl::StrFormat("%.3f ms (p90 %.3f, p99 %.3f)", f.round_trip.p50, f.round_trip.p90,
                        f.round_trip.p99));
  }
  for (const ThroughputFigures& f : s.throughput) {
    row(absl::StrCat("jobs/s, ", f.clients, " clients, ", f.label),
        f.reference ? ">= 500 /s" : "(context)",
        absl::StrFormat("%.0f /s (%d TCP connections)", f.jobs_per_second, f.connections));
  }
  if (s.upload) {
    row(absl::StrFormat("streaming upload of %.1f MB, median (best)", s.upload->megabytes),
        ">= 500 MB/s", absl::StrFormat("%.0f MB/s (%.0f)", s.upload->median, s.upload->best));
  }
  if (s.flood) {
    row(absl::StrFormat("flood %.0f s x %d clients: accepted / RESOURCE_EXHAUSTED",
                        s.flood->seconds, s.flood->clients),
        "refusals only",
        absl::StrFormat("%lld / %lld, other errors %lld", static_cast<long long>(s.flood->accepted),
                        static_cast<long long>(s.flood->refused),
                        static_cast<long long>(s.flood->other_errors)));
  }
  for (const auto& [when, m] : s.memory) {
    row(absl::StrCat("server peak RSS (VmHWM) after ", when), "bounded",
        absl::StrFormat("%.1f MiB (VmRSS %.1f)", m.peak_mib, m.rss_mib));
  }
  row("server exit status after SIGTERM (drain)", "0", std::to_string(s.server_exit));
  // Other work on the machine takes cores from both sides; the figures mean little without it.
  double load[3] = {0, 0, 0};
  getloadavg(load, 3);
  std::printf("load average at the end: %.2f %.2f %.2f\n", load[0], load[1], load[2]);
}

bool Wants(const BenchFlags& flags, const std::string& phase) {
  return absl::StrCat(",", flags.phases, ",").find(absl::StrCat(",", phase, ",")) !=
         std::string::npos;
}

int Run(int argc, char** argv) {
  std::optional<BenchFlags> parsed = ParseFlags(argc, argv);
  if (!parsed) return 2;
  BenchFlags flags = *std::move(parsed);
  if (flags.server_binary.empty()) flags.server_binary = DefaultServerBinary();
  absl::StatusOr<core::Clip> clip = LoadClip(flags.clip);
  if (!clip.ok()) {
    std::fprintf(stderr, "%s\n", clip.status().ToString().c_str());
    return 1;
  }

  const std::vector<std::string> server_flags = {
      "--workers", std::to_string(kServerWorkers), "--log_level", flags.server_log_level};
  const std::string log_path = absl::StrCat(std::filesystem::temp_directory_path().string(),
                                            "/service_bench-", getpid(), "-server.log");
  absl::StatusOr<std::unique_ptr<ServerChild>> server =
      ServerChild::Start(flags.server_binary, server_flags, log_path);
  if (!server.ok()) {
    std::fprintf(stderr, "%s\n", server.status().ToString().c_str());
    return 1;
  }
  PrintHeader(argc, argv, flags, *clip, **server, server_flags);

  Summary summary;
  RecordMemory(**server, "start", summary);
  if (Wants(flags, "latency") || Wants(flags, "latency_retime")) {
    RunLatencyPhase(flags, **server, *clip, /*retime_only=*/!Wants(flags, "latency"), summary);
  }
  if (Wants(flags, "throughput")) RunThroughputPhase(flags, **server, *clip, summary);
  if (Wants(flags, "flood")) RunFloodPhase(flags, **server, *clip, summary);
  if (Wants(flags, "upload")) RunUploadPhase(flags, **server, summary);
  summary.server_exit = (*server)->Stop();
  PrintTable(summary);
  return 0;
}

}  // namespace
}  // namespace tempokey::bench

int main(int argc, char** argv) { return tempokey::bench::Run(argc, argv); }
