// The speed figures of SPEC 8 for one build, each beside its peer measured in the same run, as
// rows for bench/run_all (which prints the table and puts two builds side by side):
//
//   retime    the default (rotation-aware) Retime() on every shared clip under three warps: the
//             half-speed section "0s:1,2s:1,2s:0.5,4s:0.5,4s:1", a 2.5x speed-up (filtered), and
//             120/30 -> 30 fps. Output samples (frames x channels) per second of CPU. Peer: the
//             scalar path (RotationMode::kEuler, every channel through the tent kernel).
//   tolerance ReduceKeys() with the defaults (0.5 degrees), CMU and the Bandai clips: milliseconds
//             of CPU per million samples (all channels), keys of the rotation channels without
//             constant ones. Peer: the greedy Catmull-Rom Hermite of greedy_hermite.h on the same
//             channels and bounds.
//   noise     the noise-aware method with sigma estimated: ms per million samples, and keys of
//             the rotation channels without constant ones. Peer: the smoothing spline of
//             smoothing_spline.h with s = N sigma^2, sigma estimated the same way
//             (EstimateNoiseSigma()), on every channel (also those whose estimate is 0, which the
//             noise method keys without smoothing).
//   world     the world-space bound: 1 cm on the Bandai clips, 0.5 % of the height on CMU: ms per
//             million samples. Peer: the per-channel 0.5 degree reduction of the same clips.
//   paper     `paper`, all 96 channels of CMU 131_01, 8 iterations: seconds.
//   pipeline  retime (speed 0s:1,2s:0.5,4s:1 to 30 fps) then reduce (tolerance defaults) on every
//             shared clip through a real tempokey-server with 1, then 2 workers, 4 clients calling
//             Process: clips per hour, input samples per second, and the speed-up.
//
//   fewest    `tolerance` with the fewest-keys search (--fewest-keys): keys of the rotation
//             channels without constant ones (SPEC 8's key counts), ms per million samples.
//             Peer: the default search, in the same run.
//
//   spec8_bench [--only=retime,tolerance,fewest,noise,world,paper,pipeline] [--seconds=S]
//               [--server_binary=PATH] [--rounds=N] [--once] [--clips=SUBSTRING]
//
// --once makes every measured call once, without repeats, and --clips keeps only the clips whose
// name contains SUBSTRING: for profiling one figure (valgrind --tool=callgrind spec8_bench ...).
//
// Single-core figures are CPU time of the measuring thread (CLOCK_THREAD_CPUTIME_ID), the best of
// three rounds of repeated calls lasting about --seconds each (default 0.1): robust to other
// processes on the machine, which take wall time but not this thread's CPU time. The pipeline
// figures are wall time (two workers and the clients share the machine).
//
// Output, one figure per line, tab-separated:
//   row  ID  FIGURE  TARGET  VALUE  UNIT  BETTER(higher|lower)  PEER  PEER_VALUE
// TARGET, PEER and PEER_VALUE are "-" when there is none. Progress goes to stderr.
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "bench/greedy_hermite.h"
#include "bench/server_child.h"
#include "bench/smoothing_spline.h"
#include "client/client.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/core/reduce/noise_fit.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::bench {
namespace {

using core::Clip;

struct Flags {
  std::set<std::string> only = {"retime", "tolerance", "fewest", "noise",
                                "world",  "paper",     "pipeline"};
  double seconds = 0.1;
  int rounds = 4;  // pipeline: passes over the shared clips per worker count
  std::string server_binary;
  // Profiling: every measured call made once (no repeats), only clips whose name contains this.
  bool once = false;
  std::string clips;
};

bool g_once = false;

bool ParseFlags(int argc, char** argv, Flags& flags) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    const auto eq = arg.find('=');
    const std::string name = arg.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : arg.substr(eq + 1);
    if (name == "--only") {
      flags.only.clear();
      for (absl::string_view part : absl::StrSplit(value, ',')) flags.only.insert(std::string(part));
    } else if (name == "--seconds" && std::atof(value.c_str()) > 0.0) {
      flags.seconds = std::atof(value.c_str());
    } else if (name == "--rounds" && std::atoi(value.c_str()) > 0) {
      flags.rounds = std::atoi(value.c_str());
    } else if (name == "--server_binary") {
      flags.server_binary = value;
    } else if (name == "--once" && value.empty()) {
      flags.once = g_once = true;
    } else if (name == "--clips") {
      flags.clips = value;
    } else {
      std::fprintf(stderr, "spec8_bench: bad argument %s\n", arg.c_str());
      return false;
    }
  }
  return true;
}

// ---- measuring ----------------------------------------------------------------------------------

double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

// CPU seconds of one call of `fn`: a first call, then three rounds of calls lasting about
// `budget` seconds each; the best per-call time of all.
double BestSeconds(const std::function<void()>& fn, double budget) {
  double start = ThreadCpuSeconds();
  fn();
  double best = ThreadCpuSeconds() - start;
  if (g_once) return best;
  const int calls = static_cast<int>(std::clamp(budget / std::max(best, 1e-9), 1.0, 1e6));
  for (int round = 0; round < 3; ++round) {
    start = ThreadCpuSeconds();
    for (int i = 0; i < calls; ++i) fn();
    best = std::min(best, (ThreadCpuSeconds() - start) / calls);
  }
  return best;
}

struct Row {
  std::string id;
  std::string figure;
  std::string target = "-";
  double value = 0.0;
  std::string unit;
  bool higher_is_better = true;
  std::string peer = "-";
  double peer_value = std::numeric_limits<double>::quiet_NaN();
};

void Print(const Row& row) {
  std::printf("row\t%s\t%s\t%s\t%.6g\t%s\t%s\t%s\t%s\n", row.id.c_str(), row.figure.c_str(),
              row.target.c_str(), row.value, row.unit.c_str(),
              row.higher_is_better ? "higher" : "lower", row.peer.c_str(),
              std::isnan(row.peer_value) ? "-" : absl::StrFormat("%.6g", row.peer_value).c_str());
  std::fflush(stdout);
}

// ---- data ---------------------------------------------------------------------------------------

struct SharedClip {
  std::string name;  // "cmu/131_01.bvh"
  bool cmu = false;
  Clip clip;
};

std::vector<SharedClip> LoadSharedClips() {
  std::vector<SharedClip> clips;
  for (const char* set : {"cmu", "bandai"}) {
    const std::string dir = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/" + set;
    std::vector<std::string> files;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      if (entry.path().extension() == ".bvh") files.push_back(entry.path().string());
    }
    std::sort(files.begin(), files.end());
    for (const std::string& file : files) {
      absl::StatusOr<Clip> clip = core::ReadBvhFile(file);
      if (!clip.ok()) {
        std::fprintf(stderr, "%s\n", std::string(clip.status().message()).c_str());
        std::exit(1);
      }
      clips.push_back({std::string(set) + "/" + std::filesystem::path(file).filename().string(),
                       std::string(set) == "cmu", *std::move(clip)});
    }
  }
  return clips;
}

void Fail(const std::string& what, const absl::Status& status) {
  std::fprintf(stderr, "spec8_bench: %s: %s\n", what.c_str(), std::string(status.message()).c_str());
  std::exit(1);
}

bool IsConstant(std::span<const double> samples) {
  return std::all_of(samples.begin(), samples.end(),
                     [&](double v) { return v == samples.front(); });
}

// Each channel's samples as the reductions fit them: rotations unwrapped.
std::vector<std::vector<double>> FittedSamples(const Clip& clip) {
  std::vector<std::vector<double>> out;
  for (const core::Channel& channel : clip.channels) {
    out.push_back(channel.samples);
    if (core::IsRotation(channel.kind)) core::UnwrapDegrees(out.back());
  }
  return out;
}

// ---- retime -------------------------------------------------------------------------------------

struct Warp {
  const char* name;
  core::TimeWarpSpec spec;
  core::RetimeOptions options;
};

std::vector<Warp> RetimeWarps() {
  std::vector<Warp> warps(3);
  warps[0].name = "half-speed section";
  warps[0].spec.domain = core::WarpDomain::kSpeedOverSource;
  warps[0].spec.speed = *core::ParseSpeedKnots("0s:1,2s:1,2s:0.5,4s:0.5,4s:1");
  warps[1].name = "2.5x speed-up";
  warps[1].spec.domain = core::WarpDomain::kSpeedOverSource;
  warps[1].spec.speed = *core::ParseSpeedKnots("0s:2.5");
  warps[2].name = "to 30 fps";
  warps[2].options.output_rate = core::FrameRate{30, 1};
  return warps;
}

// Output samples per CPU second of Retime() on `clip`.
double RetimeRate(const Clip& clip, const Warp& warp, core::RotationMode mode, double budget,
                  std::int64_t* samples) {
  core::RetimeOptions options = warp.options;
  options.rotation_mode = mode;
  absl::StatusOr<core::RetimeResult> first = core::Retime(clip, warp.spec, options);
  if (!first.ok()) Fail("retime", first.status());
  *samples = first->clip.sample_count();
  const double seconds = BestSeconds(
      [&] {
        absl::StatusOr<core::RetimeResult> r = core::Retime(clip, warp.spec, options);
        if (!r.ok()) Fail("retime", r.status());
      },
      budget);
  return static_cast<double>(*samples) / seconds;
}

void RunRetime(const std::vector<SharedClip>& clips, const Flags& flags) {
  double slowest = std::numeric_limits<double>::infinity();
  double slowest_peer = 0.0;
  std::string slowest_name;
  for (const Warp& warp : RetimeWarps()) {
    double seconds = 0.0, peer_seconds = 0.0;
    std::int64_t total = 0;
    for (const SharedClip& shared : clips) {
      std::fprintf(stderr, "retime %s %s\n", warp.name, shared.name.c_str());
      std::int64_t samples = 0;
      const double rate = RetimeRate(shared.clip, warp, core::RotationMode::kQuaternion,
                                     flags.seconds, &samples);
      const double peer =
          RetimeRate(shared.clip, warp, core::RotationMode::kEuler, flags.seconds, &samples);
      total += samples;
      seconds += static_cast<double>(samples) / rate;
      peer_seconds += static_cast<double>(samples) / peer;
      if (rate < slowest) {
        slowest = rate;
        slowest_peer = peer;
        slowest_name = absl::StrFormat("%s, %s", shared.name, warp.name);
      }
    }
    Print({.id = absl::StrFormat("retime.%s", warp.name),
           .figure = absl::StrFormat("default retime (rotation-aware), all shared clips, %s",
                                     warp.name),
           .target = ">= 100",
           .value = 1e-6 * static_cast<double>(total) / seconds,
           .unit = "M samples/s",
           .peer = "scalar path (euler mode)",
           .peer_value = 1e-6 * static_cast<double>(total) / peer_seconds});
  }
  Print({.id = "retime.slowest",
         .figure = "default retime, slowest clip and warp (" + slowest_name + ")",
         .target = ">= 100",
         .value = 1e-6 * slowest,
         .unit = "M samples/s",
         .peer = "scalar path (euler mode)",
         .peer_value = 1e-6 * slowest_peer});
}

// ---- reductions ---------------------------------------------------------------------------------

// CPU seconds of ReduceKeys(clip, options), and its result.
double ReduceSeconds(const Clip& clip, const core::ReduceOptions& options, double budget,
                     core::ReduceResult* result) {
  absl::StatusOr<core::ReduceResult> first = core::ReduceKeys(clip, options);
  if (!first.ok()) Fail("reduce " + clip.name, first.status());
  *result = *std::move(first);
  return BestSeconds(
      [&] {
        absl::StatusOr<core::ReduceResult> r = core::ReduceKeys(clip, options);
        if (!r.ok()) Fail("reduce", r.status());
      },
      budget);
}

struct SetTotals {
  double seconds = 0.0;
  std::int64_t samples = 0;        // every channel: what the time covers
  std::int64_t rotation_keys = 0;  // rotation channels without constant ones
  std::int64_t rotation_samples = 0;
  std::int64_t keys = 0;            // every channel
  double worst_joint = 0.0;         // file units, the largest world error of any reduction

  double MsPerMillion() const { return 1e9 * seconds / static_cast<double>(samples); }
  double KeyPercent() const {
    return 100.0 * static_cast<double>(rotation_keys) / static_cast<double>(rotation_samples);
  }
};

void AddReduction(const Clip& clip, const core::ReduceResult& result, double seconds,
                  SetTotals& totals) {
  totals.seconds += seconds;
  totals.samples += clip.sample_count();
  totals.keys += result.report.key_count;
  if (result.report.world) {
    totals.worst_joint = std::max(totals.worst_joint, result.report.world->max_error);
  }
  for (const core::ChannelReduction& channel : result.report.channels) {
    const core::Channel& source = clip.channels[channel.channel_index];
    if (!core::IsRotation(source.kind) || IsConstant(source.samples)) continue;
    totals.rotation_keys += channel.key_count;
    totals.rotation_samples += channel.sample_count;
  }
}

// The greedy Hermite anchor on every channel of `clip` with ReduceKeys()'s default bounds:
// CPU seconds, and keys added to `totals`.
void GreedyAnchor(const Clip& clip, double budget, SetTotals& totals) {
  const std::vector<std::vector<double>> fitted = FittedSamples(clip);
  absl::StatusOr<double> height = core::FigureHeight(clip);
  if (!height.ok()) Fail("figure height", height.status());
  std::vector<double> bounds;
  for (const core::Channel& channel : clip.channels) {
    bounds.push_back(core::IsRotation(channel.kind)   ? core::kDefaultMaxRotationErrorDegrees
                     : core::IsPosition(channel.kind) ? core::kDefaultPositionErrorHeightFraction * *height
                                                      : core::kDefaultMaxScalarError);
  }
  GreedyHermite greedy;
  std::vector<std::int64_t> keys(fitted.size(), 2);
  totals.seconds += BestSeconds(
      [&] {
        for (std::size_t c = 0; c < fitted.size(); ++c) {
          if (!IsConstant(fitted[c])) keys[c] = greedy.Reduce(fitted[c], bounds[c]);
        }
      },
      budget);
  totals.samples += clip.sample_count();
  for (std::size_t c = 0; c < fitted.size(); ++c) {
    if (!core::IsRotation(clip.channels[c].kind) || IsConstant(fitted[c])) continue;
    totals.rotation_keys += keys[c];
    totals.rotation_samples += static_cast<std::int64_t>(fitted[c].size());
  }
}

// The smoothing-spline anchor on every channel of `clip`, s = N sigma^2 with sigma estimated as
// the noise method does (at least its min_sigma): CPU seconds.
void SplineAnchor(const Clip& clip, double budget, SetTotals& totals) {
  const std::vector<std::vector<double>> fitted = FittedSamples(clip);
  const double min_sigma = core::NoiseParams{}.min_sigma;
  totals.seconds += BestSeconds(
      [&] {
        for (const std::vector<double>& samples : fitted) {
          if (IsConstant(samples)) continue;
          const double sigma = std::max(core::EstimateNoiseSigma(samples), min_sigma);
          std::int64_t knots = 0;
          SmoothingSpline(samples, static_cast<double>(samples.size()) * sigma * sigma, &knots);
        }
      },
      budget);
  totals.samples += clip.sample_count();
}

// `tolerance` with the fewest-keys search (--fewest-keys): SPEC 8's key counts, and the time
// they take, beside the default search's in the same run.
void RunFewest(const std::vector<SharedClip>& clips, const Flags& flags) {
  core::ReduceOptions options;
  options.tolerance.fewest_keys = true;
  for (bool cmu : {true, false}) {
    SetTotals fewest, usual;
    for (const SharedClip& shared : clips) {
      if (shared.cmu != cmu) continue;
      std::fprintf(stderr, "fewest %s\n", shared.name.c_str());
      core::ReduceResult result;
      const double fewest_seconds = ReduceSeconds(shared.clip, options, flags.seconds, &result);
      AddReduction(shared.clip, result, fewest_seconds, fewest);
      const double usual_seconds = ReduceSeconds(shared.clip, {}, flags.seconds, &result);
      AddReduction(shared.clip, result, usual_seconds, usual);
    }
    const std::string set = cmu ? "CMU" : "Bandai";
    Print({.id = "fewest.keys." + set,
           .figure = "tolerance --fewest-keys 0.5 deg, " + set +
                     ", keys of non-constant rotation channels",
           .target = cmu ? "<= 4" : "<= 12",
           .value = fewest.KeyPercent(),
           .unit = "% of samples",
           .higher_is_better = false,
           .peer = "tolerance, default search",
           .peer_value = usual.KeyPercent()});
    Print({.id = "fewest.speed." + set,
           .figure = "tolerance --fewest-keys 0.5 deg, " + set + ", all channels",
           .target = "-",
           .value = fewest.MsPerMillion(),
           .unit = "ms per M samples",
           .higher_is_better = false,
           .peer = "tolerance, default search",
           .peer_value = usual.MsPerMillion()});
  }
}

void RunTolerance(const std::vector<SharedClip>& clips, const Flags& flags) {
  for (bool cmu : {true, false}) {
    SetTotals ours, greedy;
    for (const SharedClip& shared : clips) {
      if (shared.cmu != cmu) continue;
      std::fprintf(stderr, "tolerance %s\n", shared.name.c_str());
      core::ReduceResult result;
      const double seconds = ReduceSeconds(shared.clip, {}, flags.seconds, &result);
      AddReduction(shared.clip, result, seconds, ours);
      GreedyAnchor(shared.clip, flags.seconds, greedy);
    }
    const std::string set = cmu ? "CMU" : "Bandai";
    Print({.id = "tolerance.speed." + set,
           .figure = "tolerance 0.5 deg, " + set + ", all channels",
           .target = "<= 60",
           .value = ours.MsPerMillion(),
           .unit = "ms per M samples",
           .higher_is_better = false,
           .peer = "greedy Catmull-Rom Hermite",
           .peer_value = greedy.MsPerMillion()});
    Print({.id = "tolerance.keys." + set,
           .figure = "tolerance 0.5 deg, " + set + ", keys of non-constant rotation channels",
           .target = cmu ? "<= 4" : "<= 12",
           .value = ours.KeyPercent(),
           .unit = "% of samples",
           .higher_is_better = false,
           .peer = "greedy Catmull-Rom Hermite",
           .peer_value = greedy.KeyPercent()});
  }
}

void RunNoise(const std::vector<SharedClip>& clips, const Flags& flags) {
  core::ReduceOptions options;
  options.method = core::ReduceMethod::kNoise;
  for (bool cmu : {true, false}) {
    SetTotals ours, spline;
    for (const SharedClip& shared : clips) {
      if (shared.cmu != cmu) continue;
      std::fprintf(stderr, "noise %s\n", shared.name.c_str());
      core::ReduceResult result;
      const double seconds = ReduceSeconds(shared.clip, options, flags.seconds, &result);
      AddReduction(shared.clip, result, seconds, ours);
      SplineAnchor(shared.clip, flags.seconds, spline);
    }
    const std::string set = cmu ? "CMU" : "Bandai";
    Print({.id = "noise.speed." + set,
           .figure = "noise, sigma estimated, " + set + ", all channels",
           .target = "<= 200",
           .value = ours.MsPerMillion(),
           .unit = "ms per M samples",
           .higher_is_better = false,
           .peer = "smoothing spline s = N sigma^2",
           .peer_value = spline.MsPerMillion()});
    Print({.id = "noise.keys." + set,
           .figure = "noise, sigma estimated, " + set + ", keys of non-constant rotation channels",
           .value = ours.KeyPercent(),
           .unit = "% of samples",
           .higher_is_better = false});
  }
}

void RunWorld(const std::vector<SharedClip>& clips, const Flags& flags) {
  for (bool cmu : {true, false}) {
    core::ReduceOptions options;
    options.tolerance.joint_tolerance =
        cmu ? core::JointTolerance{.value = 0.5, .percent_of_height = true}
            : core::JointTolerance{.value = 1.0};
    SetTotals ours, per_channel;
    for (const SharedClip& shared : clips) {
      if (shared.cmu != cmu) continue;
      std::fprintf(stderr, "world %s\n", shared.name.c_str());
      core::ReduceResult result;
      double seconds = ReduceSeconds(shared.clip, options, flags.seconds, &result);
      AddReduction(shared.clip, result, seconds, ours);
      seconds = ReduceSeconds(shared.clip, {}, flags.seconds, &result);
      AddReduction(shared.clip, result, seconds, per_channel);
    }
    const std::string set = cmu ? "CMU, 0.5 % of the height" : "Bandai, 1 cm";
    Print({.id = cmu ? "world.speed.CMU" : "world.speed.Bandai",
           .figure = "world-space bound, " + set,
           .target = "<= 200",
           .value = ours.MsPerMillion(),
           .unit = "ms per M samples",
           .higher_is_better = false,
           .peer = "per-channel 0.5 deg",
           .peer_value = per_channel.MsPerMillion()});
    // The quality side of the same runs (SPEC 8: at 1 cm on the Bandai clips, every joint within
    // 1 cm at every frame with no more keys than the per-channel reduction).
    if (cmu) continue;
    Print({.id = "world.keys.Bandai",
           .figure = "world-space bound, Bandai, 1 cm: keys, all channels",
           .target = "<= peer",
           .value = static_cast<double>(ours.keys),
           .unit = "keys",
           .higher_is_better = false,
           .peer = "per-channel 0.5 deg",
           .peer_value = static_cast<double>(per_channel.keys)});
    Print({.id = "world.worst.Bandai",
           .figure = "world-space bound, Bandai, 1 cm: worst joint at any frame",
           .target = "<= 1",
           .value = ours.worst_joint,
           .unit = "cm",
           .higher_is_better = false,
           .peer = "per-channel 0.5 deg",
           .peer_value = per_channel.worst_joint});
  }
}

void RunPaper(const std::vector<SharedClip>& clips, const Flags& flags) {
  core::ReduceOptions options;
  options.method = core::ReduceMethod::kPaper;
  options.paper.max_iterations = 8;
  for (const SharedClip& shared : clips) {
    if (!shared.cmu) continue;
    std::fprintf(stderr, "paper %s\n", shared.name.c_str());
    core::ReduceResult result;
    const double seconds = ReduceSeconds(shared.clip, options, flags.seconds, &result);
    Print({.id = "paper.cmu",
           .figure = "paper, CMU 131_01, all 96 channels, 8 iterations",
           .target = "<= 0.3",
           .value = seconds,
           .unit = "s",
           .higher_is_better = false});
  }
}

// ---- the pipeline through a server ---------------------------------------------------------------

constexpr int kPipelineClients = 4;

std::vector<core::PipelineStep> PipelineSteps() {
  core::RetimeStep retime;
  retime.warp.domain = core::WarpDomain::kSpeedOverSource;
  retime.warp.speed = *core::ParseSpeedKnots("0s:1,2s:0.5,4s:1");
  retime.options.output_rate = core::FrameRate{30, 1};
  return {retime, core::ReduceStep{}};
}

struct PipelineFigures {
  double seconds = 0.0;
  std::int64_t clips = 0;
  std::int64_t samples = 0;
};

// `rounds` passes over `clips`, kPipelineClients calls in flight, against a server with
// `workers` workers.
PipelineFigures RunPipelineOn(const std::vector<SharedClip>& clips, int workers, int rounds,
                              const std::string& binary) {
  const std::string log = std::filesystem::temp_directory_path() /
                          absl::StrFormat("spec8_bench_server_%d_%d.log", getpid(), workers);
  absl::StatusOr<std::unique_ptr<ServerChild>> server = ServerChild::Start(
      binary, {"--workers", std::to_string(workers), "--log_level", "warn"}, log);
  if (!server.ok()) Fail("server", server.status());
  client::ClientOptions options;
  options.target = (*server)->target();
  absl::StatusOr<std::unique_ptr<client::Client>> connected = client::Client::Connect(options);
  if (!connected.ok()) Fail("client", connected.status());
  const client::Client& client = **connected;
  const std::vector<core::PipelineStep> steps = PipelineSteps();
  // A warm-up call per clip: connections made, the server's first-use costs paid.
  for (const SharedClip& shared : clips) {
    absl::StatusOr<core::PipelineResult> r = client.Process(shared.clip, steps);
    if (!r.ok()) Fail("pipeline " + shared.name, r.status());
  }
  const std::int64_t total = static_cast<std::int64_t>(clips.size()) * rounds;
  std::atomic<std::int64_t> next{0};
  std::atomic<bool> failed{false};
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> threads;
  for (int t = 0; t < kPipelineClients; ++t) {
    threads.emplace_back([&] {
      for (std::int64_t i = next++; i < total; i = next++) {
        const SharedClip& shared = clips[static_cast<std::size_t>(i) % clips.size()];
        absl::StatusOr<core::PipelineResult> r = client.Process(shared.clip, steps);
        if (!r.ok()) {
          std::fprintf(stderr, "pipeline %s: %s\n", shared.name.c_str(),
                       std::string(r.status().message()).c_str());
          failed = true;
        }
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  PipelineFigures figures;
  figures.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (failed) std::exit(1);
  figures.clips = total;
  for (const SharedClip& shared : clips) figures.samples += shared.clip.sample_count() * rounds;
  (*server)->Stop();
  return figures;
}

void RunPipeline(const std::vector<SharedClip>& clips, const Flags& flags) {
  const std::string binary =
      flags.server_binary.empty() ? DefaultServerBinary() : flags.server_binary;
  std::fprintf(stderr, "pipeline, 1 worker\n");
  const PipelineFigures one = RunPipelineOn(clips, 1, flags.rounds, binary);
  std::fprintf(stderr, "pipeline, 2 workers\n");
  const PipelineFigures two = RunPipelineOn(clips, 2, flags.rounds, binary);
  for (const auto& [workers, figures] : {std::pair{1, one}, std::pair{2, two}}) {
    const std::string label = absl::StrFormat(
        "pipeline retime + reduce, every shared clip, server with %d worker%s", workers,
        workers == 1 ? "" : "s");
    Print({.id = absl::StrFormat("pipeline.clips.%d", workers),
           .figure = label,
           .value = 3600.0 * static_cast<double>(figures.clips) / figures.seconds,
           .unit = "clips/hour"});
    Print({.id = absl::StrFormat("pipeline.samples.%d", workers),
           .figure = label + ", input samples",
           .value = 1e-6 * static_cast<double>(figures.samples) / figures.seconds,
           .unit = "M samples/s"});
  }
  Print({.id = "pipeline.speedup",
         .figure = "pipeline speed-up, 1 -> 2 workers",
         .value = one.seconds / two.seconds,
         .unit = "x"});
}

}  // namespace
}  // namespace tempokey::bench

int main(int argc, char** argv) {
  using namespace tempokey::bench;
  Flags flags;
  if (!ParseFlags(argc, argv, flags)) return 2;
  std::vector<SharedClip> clips = LoadSharedClips();
  std::erase_if(clips, [&](const SharedClip& c) { return c.name.find(flags.clips) == std::string::npos; });
  if (flags.only.count("retime")) RunRetime(clips, flags);
  if (flags.only.count("tolerance")) RunTolerance(clips, flags);
  if (flags.only.count("fewest")) RunFewest(clips, flags);
  if (flags.only.count("world")) RunWorld(clips, flags);
  if (flags.only.count("noise")) RunNoise(clips, flags);
  if (flags.only.count("paper")) RunPaper(clips, flags);
  if (flags.only.count("pipeline")) RunPipeline(clips, flags);
  return 0;
}
