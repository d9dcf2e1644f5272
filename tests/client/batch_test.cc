// `tempokey batch` end to end: the real CLI against real tempokey-server children on 127.0.0.1,
// on folders of real captures; the summary, the files written, failures, and scale-out over a
// round-robin list of servers with one of them killed mid-batch.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <memory>
#include <regex>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/io/keyed_json.h"
#include "tests/testing/batch_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

std::string Stem(const std::string& path) { return fs::path(path).stem().string(); }

class BatchTest : public ServerProcessTest {
 protected:
  // A folder `name` holding copies of `sources`, each under its own file name.
  std::string FolderOf(const std::string& name, const std::vector<std::string>& sources) {
    const std::string folder = Path(name);
    fs::create_directories(folder);
    for (const std::string& source : sources) {
      fs::copy_file(source, folder + "/" + fs::path(source).filename().string(),
                    fs::copy_options::overwrite_existing);
    }
    return folder;
  }

  std::string PipelineFile(const std::string& json) {
    const std::string path = Path(absl::StrCat("ops-", pipeline_count_++, ".json"));
    EXPECT_TRUE(core::WriteFileAtomically(path, json).ok());
    return path;
  }

  ProcessResult Batch(std::vector<std::string> args, const std::string& target = "") {
    args.insert(args.begin(), {"--server", target.empty() ? server_->target() : target, "batch"});
    return RunTempokey(args, dir_);
  }

  int pipeline_count_ = 0;
};

constexpr char kRetimeThenReduce[] = R"({"operations": [
  {"retime": {"speed": "0s:1,2s:1,2s:0.5,4s:0.5,4s:1"}},
  {"reduce": {"tolerance": 0.5}}
]})";

TEST_F(BatchTest, EveryClipOfTheFolderIsProcessedAndSummarized) {
  const std::vector<std::string> sources = AllSharedBvhFiles();
  const std::string in = FolderOf("in", sources);
  ASSERT_TRUE(core::WriteFileAtomically(in + "/notes.txt", "not a clip").ok());
  ASSERT_TRUE(core::WriteFileAtomically(in + "/.hidden.bvh", "not read").ok());
  fs::create_directory(in + "/folder.bvh");  // a folder, not a clip: skipped

  ProcessResult run = Batch({in, "-o", Path("out"), "--ops", PipelineFile(kRetimeThenReduce),
                             "--jobs", "3", "--summary", Path("summary.json")});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(core::ReadFile(Path("summary.json")).value_or(""), run.out);
  // Without a terminal, one line per file, in the order they finish.
  const std::vector<std::string> log = Lines(run.err);
  ASSERT_EQ(log.size(), sources.size()) << run.err;
  for (std::size_t i = 0; i < log.size(); ++i) {
    const std::regex line(absl::StrFormat(R"(\[ ?%d/%d\] ok (\S+)\.bvh -> %s/\1\.json \(1 attempt, \d+\.\d{3} s\))",
                                          i + 1, sources.size(), Path("out")));
    EXPECT_TRUE(std::regex_match(log[i], line)) << log[i];
  }
  const Summary summary = ParseSummary(run.out);
  EXPECT_EQ(summary.files, static_cast<int>(sources.size()));
  EXPECT_EQ(summary.succeeded, static_cast<int>(sources.size()));
  EXPECT_EQ(summary.failed, 0);
  std::vector<std::string> expected_outputs;
  for (const std::string& source : sources) {
    const std::string name = fs::path(source).filename().string();
    expected_outputs.push_back(Stem(source) + ".json");
    ASSERT_EQ(summary.by_input.count(name), 1u) << name;
    const SummaryEntry& entry = summary.by_input.at(name);
    EXPECT_EQ(entry.status, "ok");
    EXPECT_EQ(entry.attempts, 1);
    EXPECT_EQ(entry.output, Path("out/" + Stem(source) + ".json"));
    absl::StatusOr<core::KeyedClip> keyed = core::ReadKeyedClipJsonFile(entry.output);
    ASSERT_TRUE(keyed.ok()) << keyed.status();
    double keys = 0;
    for (const core::Curve& curve : keyed->curves) keys += static_cast<double>(curve.keys.size());
    EXPECT_EQ(keys, entry.keys) << name;
    EXPECT_GT(entry.max_error, 0.0) << name;
    EXPECT_LE(entry.max_error, 0.5 + 1e-9) << name;
  }
  expected_outputs.push_back(kManifestName);
  std::sort(expected_outputs.begin(), expected_outputs.end());
  EXPECT_EQ(FilesIn(Path("out")), expected_outputs);  // nothing else, no temporaries
}

TEST_F(BatchTest, SampledOutputsHaveTheFittedFrameCountAndKeepTheEndPoses) {
  const std::vector<std::string> sources = {SharedBvh("cmu/131_01.bvh"),
                                            SharedBvh("bandai/dataset-1_kick_normal_001.bvh"),
                                            SharedBvh("bandai/dataset-1_walk_active_001.bvh")};
  const std::string in = FolderOf("in", sources);

  ProcessResult run = Batch(
      {in, "-o", Path("out"), "--ops",
       PipelineFile(R"({"operations": [{"retime": {"speed": "0s:0.5,1s:2", "fit_frames": 90}}]})")});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  for (const std::string& source : sources) {
    absl::StatusOr<core::Clip> input = core::ReadBvhFile(source);
    absl::StatusOr<core::Clip> output = core::ReadBvhFile(Path("out/" + Stem(source) + ".bvh"));
    ASSERT_TRUE(input.ok() && output.ok()) << source;
    EXPECT_EQ(output->frame_count, 90) << source;
    ASSERT_EQ(output->channels.size(), input->channels.size());
    for (std::size_t c = 0; c < input->channels.size(); ++c) {
      const std::vector<double>& a = input->channels[c].samples;
      const std::vector<double>& b = output->channels[c].samples;
      EXPECT_NEAR(b.front(), a.front(), 1e-9) << source << " channel " << c;
      EXPECT_NEAR(b.back(), a.back(), 1e-9) << source << " channel " << c;
    }
  }
}

TEST_F(BatchTest, KeyedPipelineBakedWhenASampledFormatIsAsked) {
  const std::string source = SharedBvh("bandai/dataset-1_punch_normal_001.bvh");
  const std::string in = FolderOf("in", {source});

  ProcessResult run =
      Batch({in, "-o", Path("out"), "--format", "bvh", "--ops",
             PipelineFile(R"({"operations": [{"reduce": {"tolerance": 0.5}}]})")});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  absl::StatusOr<core::Clip> input = core::ReadBvhFile(source);
  absl::StatusOr<core::Clip> baked = core::ReadBvhFile(Path("out/" + Stem(source) + ".bvh"));
  ASSERT_TRUE(input.ok() && baked.ok());
  EXPECT_EQ(baked->frame_count, input->frame_count);
  EXPECT_EQ(baked->frame_time_seconds, input->frame_time_seconds);
}

// A manifest that cannot be saved at the end (here its path is a folder) was the run's only
// error line: the files that failed went unmentioned. Both are said now, in one line, and the
// summary on stdout still lists every file.
TEST_F(BatchTest, AManifestThatCannotBeSavedDoesNotHideTheFilesThatFailed) {
  const std::string in = FolderOf("in", {SharedBvh("bandai/dataset-1_walk_active_001.bvh")});
  const std::string whole = core::ReadFile(SharedBvh("bandai/dataset-1_bow_active_001.bvh")).value();
  ASSERT_TRUE(core::WriteFileAtomically(in + "/broken.bvh", whole.substr(0, 3000)).ok());
  const std::string out = Path("out");
  std::filesystem::create_directories(out + "/.tempokey-batch.json/in-the-way");

  ProcessResult run = Batch({in, "-o", out, "--ops", PipelineFile(kRetimeThenReduce)});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_THAT(LastLine(run.err), IsOneErrorLine());
  EXPECT_THAT(LastLine(run.err),
              StartsWith("error: " + out + "/.tempokey-batch.json: cannot replace the file: "));
  EXPECT_THAT(LastLine(run.err),
              HasSubstr("; and 1 of 2 files failed; first: " + in + "/broken.bvh:96:24: "));
  const Summary summary = ParseSummary(run.out);
  EXPECT_EQ(summary.succeeded, 1);
  EXPECT_EQ(summary.failed, 1);
}

TEST_F(BatchTest, AFailedFileIsReportedAndTheOthersAreStillWritten) {
  const std::string in = FolderOf("in", {SharedBvh("bandai/dataset-1_walk_active_001.bvh")});
  const std::string whole = core::ReadFile(SharedBvh("bandai/dataset-1_bow_active_001.bvh")).value();
  ASSERT_TRUE(core::WriteFileAtomically(in + "/broken.bvh", whole.substr(0, 3000)).ok());

  ProcessResult run = Batch({in, "-o", Path("out"), "--ops", PipelineFile(kRetimeThenReduce)});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_THAT(LastLine(run.err), IsOneErrorLine());
  EXPECT_THAT(LastLine(run.err),
              StartsWith("error: 1 of 2 files failed; first: " + in + "/broken.bvh:96:24: "));
  const Summary summary = ParseSummary(run.out);
  EXPECT_EQ(summary.succeeded, 1);
  EXPECT_EQ(summary.failed, 1);
  ASSERT_EQ(summary.by_input.count("broken.bvh"), 1u);
  const SummaryEntry& broken = summary.by_input.at("broken.bvh");
  EXPECT_EQ(broken.status, "failed");
  EXPECT_EQ(broken.code, "INVALID_ARGUMENT");
  EXPECT_THAT(broken.error, StartsWith(in + "/broken.bvh:96:24: expected 3 numbers after OFFSET"));
  EXPECT_EQ(broken.attempts, 0);  // refused before anything was sent
  EXPECT_EQ(FilesIn(Path("out")),
            (std::vector<std::string>{kManifestName, "dataset-1_walk_active_001.json"}));
}

TEST_F(BatchTest, InvalidOperationFailsEveryFileWithTheCoreMessage) {
  const std::string in = FolderOf("in", {SharedBvh("bandai/dataset-1_walk_active_001.bvh")});

  ProcessResult run = Batch(
      {in, "-o", Path("out"), "--ops",
       PipelineFile(R"({"operations": [{"retime": {"speed": "0s:1,1s:0"}}]})")});

  EXPECT_EQ(run.exit_code, 1);
  const std::vector<std::string> lines = Lines(run.err);
  ASSERT_EQ(lines.size(), 2u) << run.err;
  EXPECT_TRUE(std::regex_match(
      lines[0], std::regex(R"(\[1/1\] failed dataset-1_walk_active_001\.bvh \(0 attempts, )"
                           R"(\d+\.\d{3} s\): dataset-1_walk_active_001\.bvh: operation 1 )"
                           R"(\(retime\): speed knot 2 \(1s:0\): speed must be > 0)")))
      << lines[0];
  EXPECT_EQ(lines[1],
            "error: 1 of 1 files failed; first: dataset-1_walk_active_001.bvh: operation 1 "
            "(retime): speed knot 2 (1s:0): speed must be > 0");
  EXPECT_TRUE(FilesIn(Path("out")).empty());
}

TEST_F(BatchTest, UsageMistakesExitTwoWithOneLine) {
  const std::string in = FolderOf("in", {SharedBvh("bandai/dataset-1_walk_active_001.bvh")});
  const std::string retime_only = PipelineFile(R"({"operations": [{"retime": {}}]})");
  struct Case {
    std::vector<std::string> args;
    std::string error;
  };
  const std::vector<Case> cases = {
      {{in, "-o", Path("out"), "--ops", PipelineFile("{\"operations\": [{\"retime\": {\"fsp\": 1}}]}")},
       "error: " + Path("ops-1.json") + ":1:36: operation 1 (retime): no option 'fsp'"},
      {{in, "-o", Path("out")}, "error: batch: missing --ops FILE (see tempokey batch --help)"},
      {{in, "-o", Path("out"), "--ops", retime_only, "--format", "anim"},
       "error: --format anim needs a pipeline that ends with reduce"},
      {{in, "-o", Path("out"), "--ops", retime_only, "--jobs", "0"},
       "error: --jobs: expected 1 to 256, got 0"},
      {{in, "-o", Path("out"), "--ops", retime_only, "--format", "fbx"},
       "error: --format: expected one of bvh, csv, json, anim, gltf, glb, got 'fbx'"},
      {{in, "-o", Path("out"), "--ops", Path("missing.json")},
       "error: " + Path("missing.json") + ": no such file"},
  };
  for (const Case& c : cases) {
    ProcessResult run = Batch(c.args);
    EXPECT_EQ(run.exit_code, 2) << c.error << "\n" << run.err;
    EXPECT_THAT(run.err, IsOneErrorLine());
    EXPECT_THAT(run.err, StartsWith(c.error));
    EXPECT_EQ(run.out, "");
  }
  EXPECT_FALSE(fs::exists(Path("out")));
}

TEST_F(BatchTest, MissingOrEmptyInputFolderFails) {
  fs::create_directories(Path("empty"));
  const std::string ops = PipelineFile(kRetimeThenReduce);

  ProcessResult missing = Batch({Path("nowhere"), "-o", Path("out"), "--ops", ops});
  ProcessResult empty = Batch({Path("empty"), "-o", Path("out"), "--ops", ops});

  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_EQ(missing.err, "error: " + Path("nowhere") + ": no such folder\n");
  EXPECT_EQ(empty.exit_code, 1);
  EXPECT_EQ(empty.err, "error: " + Path("empty") + ": no .bvh files\n");
}

TEST_F(BatchTest, UnreachableServerFailsEachFileAfterItsAttempts) {
  const std::string in = FolderOf("in", {SharedBvh("bandai/dataset-1_walk_active_001.bvh"),
                                         SharedBvh("bandai/dataset-1_bow_active_001.bvh")});
  const std::string target = server_->target();
  ASSERT_EQ(server_->Stop(), 0);  // the port is now closed

  ProcessResult run = Batch({in, "-o", Path("out"), "--ops", PipelineFile(kRetimeThenReduce),
                             "--attempts", "2"},
                            target);

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_THAT(LastLine(run.err), StartsWith("error: 2 of 2 files failed; first: "));
  const Summary summary = ParseSummary(run.out);
  ASSERT_EQ(summary.by_input.size(), 2u);
  for (const auto& [name, entry] : summary.by_input) {
    EXPECT_EQ(entry.code, "UNAVAILABLE") << name;
    EXPECT_EQ(entry.attempts, 2) << name;
    EXPECT_THAT(entry.error, HasSubstr("server: UNAVAILABLE: ")) << name;
  }
  EXPECT_TRUE(FilesIn(Path("out")).empty());
}

// An entry named as an input that cannot be read as one (a dangling or looping link) is a failed
// file of the summary, with the reader's message; it used to be left out without a word.
TEST_F(BatchTest, InputsThatAreBrokenLinksAreReportedFailedNotLeftOut) {
  const std::string in = FolderOf("in", {SharedBvh("bandai/dataset-1_walk_active_001.bvh")});
  ASSERT_EQ(::symlink("/nonexistent/clip.bvh", (in + "/dangling.bvh").c_str()), 0);
  ASSERT_EQ(::symlink("loop.bvh", (in + "/loop.bvh").c_str()), 0);

  ProcessResult run = Batch({in, "-o", Path("out"), "--ops", PipelineFile(kRetimeThenReduce)});

  EXPECT_EQ(run.exit_code, 1);
  const Summary summary = ParseSummary(run.out);
  EXPECT_EQ(summary.files, 3);
  EXPECT_EQ(summary.failed, 2);
  EXPECT_EQ(summary.by_input.at("dangling.bvh").error, in + "/dangling.bvh: no such file");
  EXPECT_THAT(summary.by_input.at("loop.bvh").error, HasSubstr("too many levels of symbolic links"));
  EXPECT_EQ(summary.by_input.at("dataset-1_walk_active_001.bvh").status, "ok");
}

// A batch with more files in flight (--jobs 8) than its server takes (one worker, a queue of
// one): the calls refused for the full queue teach the batch how many the server holds, and the
// refused files wait for one of the batch's own calls to end instead of spending their attempts
// on a queue the batch keeps full (with 8 files waiting out the same retry hint, a third of
// them used to fail after 5 attempts). Every file is done.
TEST_F(BatchTest, MoreFilesInFlightThanTheServerHoldsAreAllDone) {
  absl::StatusOr<std::unique_ptr<ServerProcess>> small =
      ServerProcess::Start(dir_, {"--workers", "1", "--queue_capacity", "1"});
  ASSERT_TRUE(small.ok()) << small.status();
  const std::string in = Path("in");
  fs::create_directories(in);
  for (int i = 0; i < 12; ++i) {
    fs::copy_file(SharedBvh("bandai/dataset-1_dance-short_normal_001.bvh"),
                  absl::StrFormat("%s/dance_%02d.bvh", in, i));
  }

  ProcessResult run = Batch({in, "-o", Path("out"), "--ops", PipelineFile(kRetimeThenReduce),
                             "--jobs", "8"},
                            (*small)->target());

  EXPECT_EQ(run.exit_code, 0) << run.err;
  const Summary summary = ParseSummary(run.out);
  EXPECT_EQ(summary.files, 12);
  EXPECT_EQ(summary.done, 12);
  for (const auto& [name, entry] : summary.by_input) {
    EXPECT_EQ(entry.status, "ok") << name << ": " << entry.error;
    EXPECT_TRUE(fs::exists(entry.output)) << name;
  }
}

// SPEC 7's scale-out on one machine: three servers behind one round-robin target, the CLI's
// batch over them, one server killed (SIGKILL, no drain) once outputs are appearing; every file
// must still be processed, by the servers that remain.
TEST_F(BatchTest, EveryFileIsProcessedWhenAServerIsKilledMidBatch) {
  std::vector<std::unique_ptr<ServerProcess>> servers;
  std::vector<std::string> addresses;
  for (int i = 0; i < 3; ++i) {
    absl::StatusOr<std::unique_ptr<ServerProcess>> server =
        ServerProcess::Start(dir_, {"--workers", "1"});
    ASSERT_TRUE(server.ok()) << server.status();
    addresses.push_back(absl::StrCat("127.0.0.1:", (*server)->port()));
    servers.push_back(*std::move(server));
  }
  const std::string target = "ipv4:" + absl::StrJoin(addresses, ",");
  std::vector<std::string> sources;
  const std::string in = Path("in");
  fs::create_directories(in);
  int copies = 0;
  for (const std::string& source : AllSharedBvhFiles()) {
    if (source.find("dance") != std::string::npos) continue;  // keep the run short
    for (int k = 0; k < 4; ++k) {
      fs::copy_file(source, absl::StrCat(in, "/", k, "_", fs::path(source).filename().string()));
      ++copies;
    }
  }
  // The paper's method keeps every call busy long enough for the kill to land mid-call.
  const std::string ops = PipelineFile(
      R"({"operations": [{"retime": {"speed": "0s:0.75"}}, {"reduce": {"method": "paper"}}]})");
  const std::string out = Path("out");
  absl::StatusOr<pid_t> cli =
      Spawn({TempokeyBinary(), "--server", target, "batch", in, "-o", out, "--ops", ops, "--jobs",
             "3"},
            Path("batch.out"), Path("batch.err"));
  ASSERT_TRUE(cli.ok()) << cli.status();

  const auto deadline = std::chrono::steady_clock::now() + kProcessTimeout;
  while (FilesIn(out).size() < 3 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  servers[1]->Signal(SIGKILL);
  std::optional<int> code = WaitFor(*cli, kProcessTimeout);
  if (!code) kill(*cli, SIGKILL);

  ASSERT_TRUE(code.has_value()) << "the batch did not finish";
  EXPECT_EQ(*code, 0) << ReadOrEmpty(Path("batch.err"));
  const Summary summary = ParseSummary(ReadOrEmpty(Path("batch.out")));
  EXPECT_EQ(summary.files, copies);
  EXPECT_EQ(summary.succeeded, copies);
  EXPECT_EQ(FilesIn(out).size(), static_cast<std::size_t>(copies) + 1);  // and the manifest
  int retried = 0;
  for (const auto& [name, entry] : summary.by_input) retried += entry.attempts > 1 ? 1 : 0;
  RecordProperty("files_retried_after_the_kill", retried);
  EXPECT_EQ(servers[0]->Stop(), 0);
  EXPECT_EQ(servers[2]->Stop(), 0);
}

}  // namespace
}  // namespace tempokey::testing
