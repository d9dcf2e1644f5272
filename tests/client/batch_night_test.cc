// A simulated night on one machine: three tempokey-server children on 127.0.0.1 behind one
// round-robin target, a batch of 200 files split over four shard processes of the real CLI, one
// server killed (SIGKILL, no drain) and one shard's process killed while they work; the killed
// shard re-run alone completes the night. Every file must end up processed exactly once into a
// correct output, checked against a closed form, and the merged summary must say so. Then a
// re-run with nothing changed skips every file, and a changed pipeline redoes them all.
//
// Holding a shard mid-run without timing: each shard logs one line per finished file to stderr
// (the non-terminal progress format), and here stderr is a pipe of one page that the test does
// not read at first. A shard therefore stalls after about a dozen files, whatever the machine's
// speed, and stays stalled until the test reads its pipe; the killed shard is killed while
// stalled, so it has certainly started and certainly not finished.
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_digest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tests/testing/batch_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr int kFiles = 200;
constexpr int kShards = 4;
constexpr int kServers = 3;
constexpr int kJobsPerShard = 2;
constexpr int kKilledShard = 2;
constexpr int kKilledServer = 1;
// The night's pipeline: double speed with linear interpolation of Euler angles and no nudging
// of the speed, so output frame j is source frame 2j exactly (SPEC 3.1 with T_o = T_s / 2).
constexpr char kPipeline[] =
    R"({"operations": [{"retime": {"speed": "0s:2", "filter": "linear", "rotation": "euler",
                                   "no-fit-to-grid": true}}]})";
// The same outputs, but a different pipeline as written: a speed limit the speed never reaches.
constexpr char kTouchedPipeline[] =
    R"({"operations": [{"retime": {"speed": "0s:2", "filter": "linear", "rotation": "euler",
                                   "no-fit-to-grid": true, "max-speed": 50}}]})";
// Exact in practice (the interpolation weight at an integer source frame is 0); the bound only
// absorbs a last-bit difference of the time map.
constexpr double kSampleTolerance = 1e-9;

// A shard's process whose stderr is a one-page pipe the test reads only when told.
class StalledShard {
 public:
  // Starts `argv` with stdout into `out_path` and stderr into a pipe of at most one page.
  static std::unique_ptr<StalledShard> Start(const std::vector<std::string>& argv,
                                             const std::string& out_path) {
    auto shard = std::unique_ptr<StalledShard>(new StalledShard());
    int fds[2];
    if (pipe2(fds, O_CLOEXEC) != 0) return nullptr;
    shard->pipe_bytes_ = fcntl(fds[1], F_SETPIPE_SZ, 4096);
    if (shard->pipe_bytes_ <= 0) shard->pipe_bytes_ = fcntl(fds[1], F_GETPIPE_SZ);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&actions, fds[1], STDERR_FILENO);
    std::vector<char*> args;
    for (const std::string& arg : argv) args.push_back(const_cast<char*>(arg.c_str()));
    args.push_back(nullptr);
    const int error = posix_spawn(&shard->pid_, args[0], &actions, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    close(fds[1]);
    shard->read_fd_ = fds[0];
    if (error != 0) return nullptr;
    return shard;
  }

  ~StalledShard() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      WaitFor(pid_, std::chrono::seconds(10));
    }
    if (reader_.joinable()) reader_.join();
    if (read_fd_ >= 0) close(read_fd_);
  }

  pid_t pid() const { return pid_; }
  int pipe_bytes() const { return pipe_bytes_; }

  // Reads the pipe to its end on a thread, so the shard runs on.
  void Release() {
    reader_ = std::thread([this] {
      char buffer[4096];
      ssize_t n = 0;
      while ((n = read(read_fd_, buffer, sizeof buffer)) > 0) log_.append(buffer, static_cast<std::size_t>(n));
    });
  }

  // Waits (bounded) for the exit; the exit code, -1 for a signal, nullopt on timeout.
  std::optional<int> Wait() {
    std::optional<int> code = WaitFor(pid_, kProcessTimeout);
    if (code) pid_ = -1;
    return code;
  }

  void Kill() {
    kill(pid_, SIGKILL);
    WaitFor(pid_, std::chrono::seconds(30));
    pid_ = -1;
  }

  // The log read by Release(), once the process has exited.
  std::string log() {
    if (reader_.joinable()) reader_.join();
    return log_;
  }

 private:
  StalledShard() = default;

  pid_t pid_ = -1;
  int read_fd_ = -1;
  int pipe_bytes_ = 0;
  std::thread reader_;
  std::string log_;
};

// Bytes received by the kernel for the process listening on 127.0.0.1:`port` that it has not
// read yet, over its established connections: proc(5), /proc/net/tcp and /proc/net/tcp6 (gRPC
// listens on a dual-stack socket, so 127.0.0.1 shows as the v4-mapped ::ffff:127.0.0.1), whose
// "tx_queue:rx_queue" field is in hex. A stopped server's unread bytes are requests waiting.
std::int64_t UnreadBytesAt(int port) {
  const std::vector<std::string> locals = {
      absl::StrFormat("0100007F:%04X", port),
      absl::StrFormat("0000000000000000FFFF00000100007F:%04X", port)};
  constexpr char kEstablished[] = "01";
  std::int64_t unread = 0;
  for (const char* table : {"/proc/net/tcp", "/proc/net/tcp6"}) {
    for (const std::string& line : Lines(ReadOrEmpty(table))) {
      std::vector<std::string> fields = absl::StrSplit(line, ' ', absl::SkipEmpty());
      if (fields.size() < 5 || fields[3] != kEstablished ||
          std::find(locals.begin(), locals.end(), fields[1]) == locals.end()) {
        continue;
      }
      const std::size_t colon = fields[4].find(':');
      if (colon != std::string::npos) unread += std::stoll(fields[4].substr(colon + 1), nullptr, 16);
    }
  }
  return unread;
}

// The records of a manifest file: {output: record}; empty when it does not exist yet.
std::map<std::string, core::JsonValue> ManifestRecords(const std::string& path) {
  std::map<std::string, core::JsonValue> records;
  absl::StatusOr<std::string> text = core::ReadFile(path);
  if (!text.ok()) return records;
  absl::StatusOr<core::JsonValue> root = core::ParseJson(*text, path);
  EXPECT_TRUE(root.ok()) << "a manifest must always parse: " << root.status();
  if (!root.ok() || root->Find("outputs") == nullptr) return records;
  for (const auto& [output, record] : *root->Find("outputs")->object) records[output] = record;
  return records;
}

class BatchNightTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = MakeTempDir();
    in_ = dir_ + "/captures";
    // A long folder name makes long log lines, so a one-page pipe holds few of them.
    out_ = dir_ + "/night-outputs-of-the-four-shards-" + std::string(160, 'n');
    fs::create_directories(in_);
    std::vector<std::string> sources;
    for (const std::string& source : AllSharedBvhFiles()) {
      if (source.find("dance") == std::string::npos) sources.push_back(source);  // keep it short
    }
    ASSERT_FALSE(sources.empty());
    for (int i = 0; i < kFiles; ++i) {
      const std::string& source = sources[static_cast<std::size_t>(i) % sources.size()];
      const std::string name = absl::StrFormat("take%03d_%s", i, fs::path(source).filename().string());
      fs::copy_file(source, in_ + "/" + name);
      source_of_[name] = source;
    }
    for (const std::string& source : sources) {
      absl::StatusOr<core::Clip> clip = core::ReadBvhFile(source);
      ASSERT_TRUE(clip.ok()) << clip.status();
      clips_[source] = *std::move(clip);
    }
    ops_ = dir_ + "/night.json";
    ASSERT_TRUE(core::WriteFileAtomically(ops_, kPipeline).ok());
  }

  std::string ShardFile(int index, const std::string& what) const {
    return absl::StrCat(dir_, "/shard-", index, ".", what);
  }
  std::string ManifestOf(int index) const {
    return absl::StrCat(out_, "/.tempokey-batch.shard-", index, "-of-", kShards, ".json");
  }

  std::vector<std::string> ShardArgs(const std::string& target, int index) const {
    return {TempokeyBinary(), "--server", target,  "batch",   in_,
            "-o",             out_,       "--ops", ops_,      "--shard",
            absl::StrCat(index, "/", kShards), "--jobs", absl::StrCat(kJobsPerShard),
            "--attempts",     "10",       "--summary", ShardFile(index, "summary.json")};
  }

  // Checks an output against the closed form of the night's pipeline on its source.
  void ExpectCorrectOutput(const std::string& input, const std::string& output_path) {
    const core::Clip& source = clips_.at(source_of_.at(input));
    absl::StatusOr<core::Clip> output = core::ReadBvhFile(output_path);
    ASSERT_TRUE(output.ok()) << output.status();
    const std::int64_t expected_frames =
        static_cast<std::int64_t>(std::floor(static_cast<double>(source.frame_count - 1) / 2.0 + 1e-9)) + 1;
    ASSERT_EQ(output->frame_count, expected_frames) << input;
    ASSERT_EQ(output->channels.size(), source.channels.size()) << input;
    double worst = 0;
    for (std::size_t c = 0; c < source.channels.size(); ++c) {
      for (std::int64_t j = 0; j < expected_frames; ++j) {
        const double want = source.channels[c].samples[static_cast<std::size_t>(2 * j)];
        const double got = output->channels[c].samples[static_cast<std::size_t>(j)];
        worst = std::max(worst, std::abs(got - want) / std::max(1.0, std::abs(want)));
      }
    }
    EXPECT_LE(worst, kSampleTolerance) << input;
  }

  std::string dir_;
  std::string in_;
  std::string out_;
  std::string ops_;
  std::map<std::string, std::string> source_of_;  // input name -> shared capture
  std::map<std::string, core::Clip> clips_;       // shared capture -> clip
};

TEST_F(BatchNightTest, FourShardsOverThreeServersSurviveAKilledServerAndAKilledShard) {
  std::vector<std::unique_ptr<ServerProcess>> servers;
  std::vector<std::string> addresses;
  for (int i = 0; i < kServers; ++i) {
    absl::StatusOr<std::unique_ptr<ServerProcess>> server =
        ServerProcess::Start(dir_, {"--workers", "1"});
    ASSERT_TRUE(server.ok()) << server.status();
    addresses.push_back(absl::StrCat("127.0.0.1:", (*server)->port()));
    servers.push_back(*std::move(server));
  }
  const std::string target = "ipv4:" + absl::StrJoin(addresses, ",");

  // The night starts: four shards, each stalling on its unread log after a dozen files.
  std::vector<std::unique_ptr<StalledShard>> shards;
  for (int i = 0; i < kShards; ++i) {
    shards.push_back(StalledShard::Start(ShardArgs(target, i), ShardFile(i, "out")));
    ASSERT_NE(shards.back(), nullptr);
  }
  // The stall is certain when a shard has more files than a full pipe holds lines (plus the
  // files its other workers finish meanwhile): a line names its input twice and the output
  // folder once, so it is longer than those.
  const std::size_t shortest_name = std::min_element(
      source_of_.begin(), source_of_.end(), [](const auto& a, const auto& b) {
        return a.first.size() < b.first.size();
      })->first.size();
  const std::size_t min_line = out_.size() + 2 * shortest_name;
  const int lines_in_pipe = static_cast<int>(
      static_cast<std::size_t>(shards[kKilledShard]->pipe_bytes()) / min_line);

  // Wait (bounded) until every shard has recorded some files, i.e. the night is under way.
  const auto deadline = Clock::now() + kProcessTimeout;
  auto recorded = [&](int i) { return static_cast<int>(ManifestRecords(ManifestOf(i)).size()); };
  for (int i = 0; i < kShards; ++i) {
    while (recorded(i) < 3 && Clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ASSERT_GE(recorded(i), 3) << "shard " << i << " made no progress";
  }

  // A server stops answering while the shards go on: calls routed to it wait. Once a request
  // (a clip: tens of kilobytes, not a flow-control frame) is waiting at it, it dies without
  // draining, so that call fails and must be retried elsewhere (by the client library, or by
  // the batch: "attempts" counts only the latter). A shard's process dies while stalled.
  servers[kKilledServer]->Signal(SIGSTOP);
  for (int i = 0; i < kShards; ++i) {
    if (i != kKilledShard) shards[static_cast<std::size_t>(i)]->Release();
  }
  constexpr std::int64_t kWaitingRequestBytes = 16 << 10;
  while (UnreadBytesAt(servers[kKilledServer]->port()) < kWaitingRequestBytes &&
         Clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_GE(UnreadBytesAt(servers[kKilledServer]->port()), kWaitingRequestBytes)
      << "no request reached the stopped server";
  servers[kKilledServer]->Signal(SIGKILL);
  ASSERT_EQ(servers[kKilledServer]->WaitExit(std::chrono::seconds(30)), -1);
  shards[kKilledShard]->Kill();
  for (int i = 0; i < kShards; ++i) {
    if (i == kKilledShard) continue;
    std::optional<int> code = shards[static_cast<std::size_t>(i)]->Wait();
    ASSERT_TRUE(code.has_value()) << "shard " << i << " did not finish";
    EXPECT_EQ(*code, 0) << "shard " << i << ":\n" << shards[static_cast<std::size_t>(i)]->log();
  }

  // What the killed shard left: a manifest that parses, every record true of the file on disk,
  // no summary, and fewer files than its share.
  const std::map<std::string, core::JsonValue> left = ManifestRecords(ManifestOf(kKilledShard));
  for (const auto& [output, record] : left) {
    const std::string bytes = core::ReadFile(out_ + "/" + output).value_or("");
    EXPECT_EQ(static_cast<double>(bytes.size()), JsonNumber(record.Find("output_bytes"))) << output;
    EXPECT_EQ(wire::Sha256Id(bytes), JsonText(record.Find("output_id"))) << output;
  }
  EXPECT_FALSE(fs::exists(ShardFile(kKilledShard, "summary.json")));

  // Morning: the killed shard alone is run again and completes the night.
  ProcessResult rerun = RunProcess(ShardArgs(target, kKilledShard), dir_);
  ASSERT_EQ(rerun.exit_code, 0) << rerun.err;
  const Summary resumed = ParseSummary(rerun.out);
  const int killed_share = resumed.files;
  EXPECT_GT(killed_share, lines_in_pipe + kJobsPerShard)
      << "the killed shard's share must exceed what it can finish while stalled";
  EXPECT_LT(static_cast<int>(left.size()), killed_share);
  EXPECT_EQ(resumed.skipped, static_cast<int>(left.size())) << "every recorded file is skipped";
  EXPECT_EQ(resumed.done, killed_share - static_cast<int>(left.size()));
  EXPECT_EQ(resumed.failed, 0);

  // The merged summary: every file once, none failed.
  std::vector<std::string> merge = {"batch-summary"};
  for (int i = 0; i < kShards; ++i) merge.push_back(ShardFile(i, "summary.json"));
  ProcessResult merged = RunTempokey(merge, dir_);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  const Summary night = ParseSummary(merged.out);
  EXPECT_EQ(night.files, kFiles);
  EXPECT_EQ(night.succeeded, kFiles);
  EXPECT_EQ(night.failed, 0);
  EXPECT_EQ(night.shards, kShards);
  EXPECT_TRUE(night.missing_shards.empty());
  EXPECT_EQ(night.skipped, static_cast<int>(left.size()));
  EXPECT_EQ(night.done, kFiles - static_cast<int>(left.size()));
  ASSERT_EQ(night.by_input.size(), static_cast<std::size_t>(kFiles));
  int retried = 0;
  for (const auto& [input, entry] : night.by_input) retried += entry.attempts > 1 ? 1 : 0;

  // Every output exactly once: the folder holds the 200 outputs and the 4 manifests, nothing
  // else (no temporaries), each output recorded by exactly one shard, each one correct.
  std::map<std::string, int> recorded_by;
  for (int i = 0; i < kShards; ++i) {
    for (const auto& [output, record] : ManifestRecords(ManifestOf(i))) ++recorded_by[output];
  }
  std::vector<std::string> expected_files;
  for (int i = 0; i < kShards; ++i) expected_files.push_back(fs::path(ManifestOf(i)).filename());
  for (const auto& [input, source] : source_of_) {
    expected_files.push_back(input);  // a .bvh in, a .bvh out under the same name
    EXPECT_EQ(recorded_by[input], 1) << input;
    ASSERT_EQ(night.by_input.count(input), 1u) << input;
    EXPECT_EQ(night.by_input.at(input).output, out_ + "/" + input);
    ExpectCorrectOutput(input, out_ + "/" + input);
  }
  std::sort(expected_files.begin(), expected_files.end());
  EXPECT_EQ(FilesIn(out_), expected_files);

  // The next night with nothing changed skips every file (one unsharded run reads the four
  // shards' manifests); a changed pipeline redoes them all.
  const std::string alive = absl::StrCat("ipv4:", addresses[0], ",", addresses[2]);
  const auto skip_start = Clock::now();
  ProcessResult unchanged = RunTempokey({"--server", alive, "batch", in_, "-o", out_, "--ops", ops_,
                                         "--jobs", "4"},
                                        dir_);
  const double skip_seconds = std::chrono::duration<double>(Clock::now() - skip_start).count();
  ASSERT_EQ(unchanged.exit_code, 0) << unchanged.err;
  EXPECT_EQ(ParseSummary(unchanged.out).skipped, kFiles);

  ASSERT_TRUE(core::WriteFileAtomically(ops_, kTouchedPipeline).ok());
  ProcessResult touched = RunTempokey({"--server", alive, "batch", in_, "-o", out_, "--ops", ops_,
                                       "--jobs", "4"},
                                      dir_);
  ASSERT_EQ(touched.exit_code, 0) << touched.err;
  EXPECT_EQ(ParseSummary(touched.out).done, kFiles);
  for (const auto& [input, source] : source_of_) ExpectCorrectOutput(input, out_ + "/" + input);

  RecordProperty("killed_shard_files", killed_share);
  RecordProperty("killed_shard_recorded_before_the_kill", static_cast<int>(left.size()));
  RecordProperty("files_retried_after_the_server_kill", retried);
  RecordProperty("rerun_skipping_200_files_seconds", absl::StrFormat("%.3f", skip_seconds));
  std::printf("night: killed shard had %zu of %d files recorded; %d files retried after the "
              "server kill; unchanged re-run skipped %d files in %.3f s\n",
              left.size(), killed_share, retried, kFiles, skip_seconds);
  EXPECT_EQ(servers[0]->Stop(), 0);
  EXPECT_EQ(servers[2]->Stop(), 0);
}

}  // namespace
}  // namespace tempokey::testing
