// Resumable and sharded `tempokey batch`, end to end: the real CLI against a real tempokey-server
// child on 127.0.0.1, on folders of real captures. What a re-run skips and redoes, --force, the
// manifest's input ids against the server's own, shards covering a folder exactly once and
// staying put when files are added, and `tempokey batch-summary`.
#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <thread>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tests/testing/batch_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::StartsWith;

constexpr char kReduce[] = R"({"operations": [{"reduce": {"tolerance": 0.5}}]})";
// The same pipeline written differently: spacing, member order, "0.50" for 0.5.
constexpr char kReduceRespelled[] = R"({ "operations" : [ { "reduce" : { "tolerance" : "0.50" } } ] })";
constexpr char kReduceTighter[] = R"({"operations": [{"reduce": {"tolerance": 0.4}}]})";

// The captures of ../shared without the long dance, for short runs.
std::vector<std::string> QuickSources() {
  std::vector<std::string> sources;
  for (const std::string& source : AllSharedBvhFiles()) {
    if (source.find("dance") == std::string::npos) sources.push_back(source);
  }
  return sources;
}

// {output name: bytes} of the outputs in `dir` (manifests left out).
std::map<std::string, std::string> Outputs(const std::string& dir) {
  std::map<std::string, std::string> outputs;
  for (const std::string& name : FilesIn(dir)) {
    if (name.starts_with(".tempokey-batch")) continue;
    outputs[name] = core::ReadFile(dir + "/" + name).value_or("");
  }
  return outputs;
}

std::set<std::string> WithStatus(const Summary& summary, const std::string& status) {
  std::set<std::string> inputs;
  for (const auto& [input, entry] : summary.by_input) {
    if (entry.status == status) inputs.insert(input);
  }
  return inputs;
}

class BatchResumeTest : public ServerProcessTest {
 protected:
  // A folder holding `copies` copies of each quick source, as "<k>_<name>.bvh".
  std::string Folder(const std::string& name, int copies = 1) {
    const std::string folder = Path(name);
    fs::create_directories(folder);
    for (const std::string& source : QuickSources()) {
      for (int k = 0; k < copies; ++k) {
        fs::copy_file(source, absl::StrCat(folder, "/", k, "_", fs::path(source).filename().string()),
                      fs::copy_options::overwrite_existing);
      }
    }
    return folder;
  }

  std::string Ops(const std::string& json) {
    const std::string path = Path(absl::StrCat("ops-", ops_count_++, ".json"));
    EXPECT_TRUE(core::WriteFileAtomically(path, json).ok());
    return path;
  }

  ProcessResult Batch(std::vector<std::string> args) {
    args.insert(args.begin(), {"--server", target_.empty() ? server_->target() : target_, "batch"});
    return RunTempokey(args, dir_);
  }

  int ops_count_ = 0;
  std::string target_;
};

TEST_F(BatchResumeTest, ReRunWithNothingChangedSkipsEveryFileWithoutAServer) {
  const std::string in = Folder("in");
  const std::string ops = Ops(kReduce);
  ProcessResult first = Batch({in, "-o", Path("out"), "--ops", ops});
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const std::map<std::string, std::string> before = Outputs(Path("out"));
  // Nothing may be sent: with the server gone, any call would fail UNAVAILABLE.
  ASSERT_EQ(server_->Stop(), 0);

  ProcessResult again = Batch({in, "-o", Path("out"), "--ops", Ops(kReduceRespelled)});

  ASSERT_EQ(again.exit_code, 0) << again.err;
  const Summary summary = ParseSummary(again.out);
  const int files = static_cast<int>(QuickSources().size());
  EXPECT_EQ(summary.files, files);
  EXPECT_EQ(summary.skipped, files);
  EXPECT_EQ(summary.done, 0);
  EXPECT_EQ(summary.succeeded, files);
  for (const auto& [input, entry] : summary.by_input) {
    EXPECT_EQ(entry.status, "skipped") << input;
    EXPECT_EQ(entry.attempts, 0) << input;
    EXPECT_GT(entry.keys, 0) << input << ": the recorded key count is reported";
  }
  for (const std::string& line : Lines(again.err)) {
    EXPECT_THAT(line, HasSubstr("] skipped ")) << line;
    EXPECT_THAT(line, ::testing::EndsWith(" (up to date)")) << line;
  }
  EXPECT_EQ(Outputs(Path("out")), before);
}

TEST_F(BatchResumeTest, ChangingThePipelineRedoesEveryFile) {
  const std::string in = Folder("in");
  ASSERT_EQ(Batch({in, "-o", Path("out"), "--ops", Ops(kReduce)}).exit_code, 0);

  ProcessResult tighter = Batch({in, "-o", Path("out"), "--ops", Ops(kReduceTighter)});
  ProcessResult same_again = Batch({in, "-o", Path("out"), "--ops", Ops(kReduceTighter)});
  ProcessResult other_format =
      Batch({in, "-o", Path("out"), "--ops", Ops(kReduceTighter), "--format", "json"});

  const int files = static_cast<int>(QuickSources().size());
  ASSERT_EQ(tighter.exit_code, 0) << tighter.err;
  EXPECT_EQ(ParseSummary(tighter.out).done, files);
  EXPECT_EQ(ParseSummary(tighter.out).skipped, 0);
  EXPECT_EQ(ParseSummary(same_again.out).skipped, files);
  // --format json names the format each output already had: the same outputs, skipped.
  EXPECT_EQ(ParseSummary(other_format.out).skipped, files);
  EXPECT_NE(ParseSummary(tighter.out).pipeline, ParseSummary(other_format.out).pipeline);
}

TEST_F(BatchResumeTest, ChangedInputsAndMissingOrAlteredOutputsAreRedoneTheRestSkipped) {
  const std::string in = Folder("in");
  const std::string out = Path("out");
  const std::string ops = Ops(kReduce);
  ASSERT_EQ(Batch({in, "-o", out, "--ops", ops}).exit_code, 0);
  // Another capture under the same name: the input changed.
  fs::copy_file(SharedBvh("cmu/131_01.bvh"), in + "/0_dataset-1_bow_active_001.bvh",
                fs::copy_options::overwrite_existing);
  // The same motion saved with CRLF line endings: other bytes, same clip, so nothing to redo.
  const std::string kick = in + "/0_dataset-1_kick_normal_001.bvh";
  ASSERT_TRUE(core::WriteFileAtomically(
                  kick, absl::StrReplaceAll(core::ReadFile(kick).value(), {{"\n", "\r\n"}}))
                  .ok());
  fs::remove(out + "/0_dataset-1_punch_normal_001.json");
  const std::string walk = out + "/0_dataset-1_walk_active_001.json";
  ASSERT_TRUE(core::WriteFileAtomically(walk, core::ReadFile(walk).value() + " ").ok());

  ProcessResult again = Batch({in, "-o", out, "--ops", ops});

  ASSERT_EQ(again.exit_code, 0) << again.err;
  const Summary summary = ParseSummary(again.out);
  EXPECT_EQ(WithStatus(summary, "ok"),
            (std::set<std::string>{"0_dataset-1_bow_active_001.bvh",
                                   "0_dataset-1_punch_normal_001.bvh",
                                   "0_dataset-1_walk_active_001.bvh"}));
  EXPECT_EQ(summary.skipped, summary.files - 3);
  EXPECT_EQ(summary.by_input.at("0_dataset-1_kick_normal_001.bvh").status, "skipped");
  EXPECT_TRUE(fs::exists(out + "/0_dataset-1_punch_normal_001.json"));
}

TEST_F(BatchResumeTest, ForceRedoesEveryFile) {
  const std::string in = Folder("in");
  const std::string ops = Ops(kReduce);
  ASSERT_EQ(Batch({in, "-o", Path("out"), "--ops", ops}).exit_code, 0);

  ProcessResult forced = Batch({in, "-o", Path("out"), "--ops", ops, "--force"});
  ProcessResult after = Batch({in, "-o", Path("out"), "--ops", ops});

  ASSERT_EQ(forced.exit_code, 0) << forced.err;
  const int files = static_cast<int>(QuickSources().size());
  EXPECT_EQ(ParseSummary(forced.out).done, files);
  EXPECT_EQ(ParseSummary(after.out).skipped, files);
}

// The manifest records the id the server itself gives the clip (`tempokey upload` prints it).
TEST_F(BatchResumeTest, ManifestInputIdIsTheServersContentId) {
  const std::string in = Folder("in");
  ASSERT_EQ(Batch({in, "-o", Path("out"), "--ops", Ops(kReduce)}).exit_code, 0);
  absl::StatusOr<core::JsonValue> manifest =
      core::ParseJson(core::ReadFile(Path("out/") + kManifestName).value_or(""), "manifest");
  ASSERT_TRUE(manifest.ok()) << manifest.status();
  const core::JsonValue* outputs = manifest->Find("outputs");
  ASSERT_NE(outputs, nullptr);
  ASSERT_EQ(outputs->object->size(), QuickSources().size());

  for (const auto& [output, record] : *outputs->object) {
    const std::string input = JsonText(record.Find("input"));
    ProcessResult upload =
        RunTempokey({"--server", server_->target(), "upload", in + "/" + input}, dir_);

    ASSERT_EQ(upload.exit_code, 0) << upload.err;
    EXPECT_THAT(upload.out, HasSubstr(JsonText(record.Find("input_id")))) << input;
    EXPECT_THAT(JsonText(record.Find("input_id")), ::testing::MatchesRegex("sha256:[0-9a-f]{64}"));
  }
}

TEST_F(BatchResumeTest, ShardsCoverTheFolderOnceAndKeepTheirFilesWhenFilesAreAdded) {
  const std::string in = Folder("in", 3);
  const std::string out = Path("out");
  const std::string ops = Ops(kReduce);
  const int first_count = 3 * static_cast<int>(QuickSources().size());
  std::map<std::string, std::string> shard_of;  // input -> "i/3"
  std::vector<std::string> summaries;
  for (int i = 0; i < 3; ++i) {
    summaries.push_back(Path(absl::StrCat("shard-", i, ".json")));
    ProcessResult run = Batch({in, "-o", out, "--ops", ops, "--shard", absl::StrCat(i, "/3"),
                               "--summary", summaries.back()});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const Summary summary = ParseSummary(run.out);
    EXPECT_EQ(summary.shard, absl::StrCat(i, "/3"));
    for (const std::string& input : summary.inputs) {
      EXPECT_TRUE(shard_of.emplace(input, summary.shard).second) << input << " in two shards";
    }
  }
  ASSERT_EQ(static_cast<int>(shard_of.size()), first_count);
  EXPECT_EQ(static_cast<int>(Outputs(out).size()), first_count);
  ProcessResult merged = RunTempokey({"batch-summary", summaries[2], summaries[0], summaries[1]}, dir_);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  EXPECT_EQ(ParseSummary(merged.out).files, first_count);
  EXPECT_EQ(ParseSummary(merged.out).shards, 3);

  // More files arrive; every old file stays in its shard (and is skipped), the new ones are done.
  for (const std::string& source : QuickSources()) {
    fs::copy_file(source, in + "/new_" + fs::path(source).filename().string());
  }
  std::set<std::string> seen;
  for (int i = 0; i < 3; ++i) {
    ProcessResult run = Batch({in, "-o", out, "--ops", ops, "--shard", absl::StrCat(i, "/3"),
                               "--summary", summaries[static_cast<std::size_t>(i)]});
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const Summary summary = ParseSummary(run.out);
    for (const auto& [input, entry] : summary.by_input) {
      seen.insert(input);
      if (input.starts_with("new_")) {
        EXPECT_EQ(entry.status, "ok") << input;
      } else {
        EXPECT_EQ(shard_of[input], summary.shard) << input << " moved";
        EXPECT_EQ(entry.status, "skipped") << input;
      }
    }
  }
  const int all = first_count + static_cast<int>(QuickSources().size());
  EXPECT_EQ(static_cast<int>(seen.size()), all);
  ProcessResult remerged = RunTempokey({"batch-summary", summaries[0], summaries[1], summaries[2],
                                        "-o", Path("merged.json")},
                                       dir_);
  ASSERT_EQ(remerged.exit_code, 0) << remerged.err;
  const Summary total = ParseSummary(remerged.out);
  EXPECT_EQ(total.files, all);
  EXPECT_EQ(total.skipped, first_count);
  EXPECT_EQ(total.done, all - first_count);
  EXPECT_EQ(core::ReadFile(Path("merged.json")).value_or(""), remerged.out);
  // One manifest per shard, nothing else beside the outputs.
  std::vector<std::string> manifests;
  for (const std::string& name : FilesIn(out)) {
    if (name.starts_with(".")) manifests.push_back(name);
  }
  EXPECT_EQ(manifests, (std::vector<std::string>{".tempokey-batch.shard-0-of-3.json",
                                                 ".tempokey-batch.shard-1-of-3.json",
                                                 ".tempokey-batch.shard-2-of-3.json"}));
}

TEST_F(BatchResumeTest, UnshardedReRunSkipsWhatTheShardsDid) {
  const std::string in = Folder("in");
  const std::string ops = Ops(kReduce);
  for (int i = 0; i < 2; ++i) {
    ASSERT_EQ(Batch({in, "-o", Path("out"), "--ops", ops, "--shard", absl::StrCat(i, "/2")}).exit_code, 0);
  }

  ProcessResult whole = Batch({in, "-o", Path("out"), "--ops", ops});

  ASSERT_EQ(whole.exit_code, 0) << whole.err;
  EXPECT_EQ(ParseSummary(whole.out).skipped, static_cast<int>(QuickSources().size()));
}

TEST_F(BatchResumeTest, MergeOfAnIncompleteRunNamesTheMissingShardsAndFails) {
  const std::string in = Folder("in");
  ProcessResult one = Batch({in, "-o", Path("out"), "--ops", Ops(kReduce), "--shard", "1/3",
                             "--summary", Path("s1.json")});
  ASSERT_EQ(one.exit_code, 0) << one.err;

  ProcessResult merged = RunTempokey({"batch-summary", Path("s1.json")}, dir_);
  ProcessResult twice = RunTempokey({"batch-summary", Path("s1.json"), Path("s1.json")}, dir_);
  ProcessResult none = RunTempokey({"batch-summary"}, dir_);

  EXPECT_EQ(merged.exit_code, 1);
  EXPECT_EQ(merged.err,
            "error: shards 0/3, 2/3 missing: the run is incomplete (run them with batch --shard)\n");
  EXPECT_EQ(ParseSummary(merged.out).missing_shards, (std::vector<std::string>{"0/3", "2/3"}));
  EXPECT_EQ(twice.exit_code, 1);
  EXPECT_EQ(twice.err, "error: shard 1/3 is given twice: " + Path("s1.json") + " and " +
                           Path("s1.json") + "\n");
  EXPECT_EQ(none.exit_code, 2);
  EXPECT_EQ(none.err, "error: batch-summary: missing SUMMARY (see tempokey batch-summary --help)\n");
}

TEST_F(BatchResumeTest, DamagedManifestStopsTheRunNamingItUnlessForced) {
  const std::string in = Folder("in");
  const std::string ops = Ops(kReduce);
  fs::create_directories(Path("out"));
  ASSERT_TRUE(core::WriteFileAtomically(Path("out/") + kManifestName, "{\"format\": 3}").ok());

  ProcessResult stopped = Batch({in, "-o", Path("out"), "--ops", ops});
  ProcessResult forced = Batch({in, "-o", Path("out"), "--ops", ops, "--force"});

  EXPECT_EQ(stopped.exit_code, 1);
  EXPECT_EQ(stopped.err, "error: " + Path("out/") + kManifestName +
                             ":1:12: not a batch manifest (\"format\" must be "
                             "\"tempokey.batch_manifest\"); remove the file or run with --force\n");
  EXPECT_EQ(stopped.out, "");
  EXPECT_EQ(forced.exit_code, 0) << forced.err;
  EXPECT_EQ(ParseSummary(forced.out).done, static_cast<int>(QuickSources().size()));
}

TEST_F(BatchResumeTest, ShardAndProgressMistakesAreUsageErrors) {
  const std::string in = Folder("in");
  const std::string ops = Ops(kReduce);

  ProcessResult shard = Batch({in, "-o", Path("out"), "--ops", ops, "--shard", "4/4"});
  ProcessResult progress = Batch({in, "-o", Path("out"), "--ops", ops, "--progress", "dots"});

  EXPECT_EQ(shard.exit_code, 2);
  EXPECT_EQ(shard.err,
            "error: --shard: expected I/N with 0 <= I < N <= 100000 (I counts from 0), got '4/4'\n");
  EXPECT_EQ(progress.exit_code, 2);
  EXPECT_EQ(progress.err,
            "error: --progress: expected one of auto, bar, lines, none, got 'dots'\n");
  EXPECT_FALSE(fs::exists(Path("out")));
}

constexpr char kHalfSpeed[] = R"({"operations": [{"retime": {"speed": "0s:0.5"}}]})";

// Lets `pid` go on (SIGCONT) each time the write hook stops it, until it ends (bounded); its
// exit code, nullopt for a signal or a timeout.
std::optional<int> ContinueUntilExit(pid_t pid) {
  const auto deadline = std::chrono::steady_clock::now() + kProcessTimeout;
  kill(pid, SIGCONT);
  while (std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    const pid_t changed = waitpid(pid, &status, WNOHANG | WUNTRACED);
    if (changed == pid && WIFSTOPPED(status)) kill(pid, SIGCONT);
    if (changed == pid && WIFEXITED(status)) return WEXITSTATUS(status);
    if (changed < 0 || (changed == pid && WIFSIGNALED(status))) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  kill(pid, SIGKILL);
  return std::nullopt;
}

// The names in `dir` of a batch's staging files and atomic-write temporaries.
std::vector<std::string> Leftovers(const std::string& dir) {
  std::vector<std::string> names;
  for (const std::string& name : FilesIn(dir)) {
    if (name.find(".staged-") != std::string::npos || name.find(".tmp-") != std::string::npos) {
      names.push_back(name);
    }
  }
  return names;
}

// An in-place batch (--overwrite) killed right after an output replaced its input, before
// anything else was written: the resume finds that file done, redoes none twice, and the folder
// ends as a clean run leaves it. Before, the record was written after the replace, and the
// resume took the output for a changed input and retimed it again (twice the frames).
TEST_F(BatchResumeTest, InPlaceRunKilledRightAfterAReplaceIsResumedWithoutRedoingThatFile) {
  const std::string ops = Ops(kHalfSpeed);
  const std::string clean = Folder("clean");
  ASSERT_EQ(Batch({clean, "-o", clean, "--overwrite", "--ops", ops}).exit_code, 0);
  const std::string work = Folder("work");
  const int files = static_cast<int>(QuickSources().size());
  ASSERT_GE(files, 3);

  // The test hook kills the CLI (SIGKILL) right after its 2nd replace: no race.
  const ProcessResult killed = RunTempokey(
      {"--server", server_->target(), "batch", work, "-o", work, "--overwrite", "--ops", ops,
       "--jobs", "1"},
      dir_, {"TEMPOKEY_TEST_BATCH_KILL_AFTER_REPLACE=2"});
  ProcessResult resumed = Batch({work, "-o", work, "--overwrite", "--ops", ops});

  EXPECT_EQ(killed.exit_code, -1) << "killed by the hook\n" << killed.err;
  ASSERT_EQ(resumed.exit_code, 0) << resumed.err;
  const Summary summary = ParseSummary(resumed.out);
  EXPECT_EQ(summary.skipped, 2);
  EXPECT_EQ(summary.done, files - 2);
  const std::map<std::string, std::string> expected = Outputs(clean);
  const std::map<std::string, std::string> outputs = Outputs(work);
  EXPECT_EQ(outputs.size(), expected.size());
  for (const auto& [name, bytes] : expected) {
    EXPECT_TRUE(outputs.count(name) > 0 && outputs.at(name) == bytes)
        << name << ": not what a clean run writes (retimed twice?)";
  }
  EXPECT_THAT(Leftovers(work), ::testing::IsEmpty());
  EXPECT_FALSE(fs::exists(work + "/.tempokey-batch.journal"));
}

// A probe interrupting in-place runs (SIGINT) found, once in nine, a whole staging file left
// beside the inputs until the next run: interrupted between an output's write and its rename,
// the signal handler removed only temporaries. The test hook interrupts right there (no race):
// the staging file goes with the process, the input is as it was, and a resume completes.
TEST_F(BatchResumeTest, AnInPlaceRunInterruptedBetweenStagingAndReplacingLeavesNoStagingFile) {
  const std::string ops = Ops(kHalfSpeed);
  const std::string work = Folder("work");
  const std::map<std::string, std::string> inputs = Outputs(work);

  const ProcessResult interrupted = RunTempokey(
      {"--server", server_->target(), "batch", work, "-o", work, "--overwrite", "--ops", ops,
       "--jobs", "1"},
      dir_, {"TEMPOKEY_TEST_BATCH_INTERRUPT_AFTER_STAGING=1"});
  const std::vector<std::string> left = Leftovers(work);
  const std::map<std::string, std::string> after = Outputs(work);
  ProcessResult resumed = Batch({work, "-o", work, "--overwrite", "--ops", ops});

  EXPECT_NE(interrupted.exit_code, 0) << "interrupted by the hook\n" << interrupted.err;
  EXPECT_THAT(left, ::testing::IsEmpty());
  EXPECT_EQ(after, inputs);  // nothing replaced yet
  ASSERT_EQ(resumed.exit_code, 0) << resumed.err;
  EXPECT_EQ(ParseSummary(resumed.out).done, static_cast<int>(inputs.size()));
  EXPECT_THAT(Leftovers(work), ::testing::IsEmpty());
}

// An in-place output is written beside its input first, as a hidden staging file; when that
// write fails, the error named the staging file alone ("/w/.tempokey-batch.staged-4a08...:
// cannot write: file too large"), a file the user never asked for. It now names the file it
// would have replaced, and the input is left whole. The write fails for real: the CLI runs under
// a file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored: EFBIG) above the manifest's size and below
// any output's (half speed doubles a clip's frames).
TEST_F(BatchResumeTest, AnInPlaceOutputThatCannotBeWrittenIsNamedByTheFileItWouldReplace) {
  const std::string work = Folder("work");
  const std::map<std::string, std::string> inputs = Outputs(work);
  std::size_t smallest = std::string::npos;
  for (const auto& [name, bytes] : inputs) smallest = std::min(smallest, bytes.size());
  const std::vector<std::string> argv = {
      "/bin/sh", "-c", "trap '' XFSZ; exec prlimit --fsize=\"$0\" \"$@\"",
      absl::StrCat(smallest), TempokeyBinary(), "--server", server_->target(), "batch", work,
      "-o", work, "--overwrite", "--ops", Ops(kHalfSpeed), "--jobs", "1", "--progress", "none"};

  const ProcessResult limited = RunProcess(argv, dir_);

  EXPECT_EQ(limited.exit_code, 1) << limited.err;
  const Summary summary = ParseSummary(limited.out);
  EXPECT_EQ(summary.failed, static_cast<int>(inputs.size())) << limited.out;
  for (const auto& [input, entry] : summary.by_input) {
    EXPECT_THAT(entry.error, StartsWith(absl::StrCat(work, "/", input,
                                                     " (written first as .tempokey-batch.staged-")))
        << entry.error;
    EXPECT_THAT(entry.error, HasSubstr("): cannot write: file too large"));
  }
  EXPECT_EQ(Outputs(work), inputs);
  EXPECT_THAT(Leftovers(work), ::testing::IsEmpty());
}

// Two runs of one manifest into one folder: the second is refused at once with one line and
// exit 1, and leaves the first's temporary alone (before, its start-up clean-up removed it and
// the first failed "cannot replace the file"); another shard runs beside the first.
TEST_F(BatchResumeTest, SecondRunOfTheSameManifestIsRefusedAndAnotherShardRunsBeside) {
  const std::string in = Folder("in");
  const std::string ops = Ops(kReduce);
  const std::string out = Path("out");
  auto args = [&](const std::string& shard) {
    return std::vector<std::string>{TempokeyBinary(), "--server", server_->target(), "batch",
                                    in, "-o", out, "--ops", ops, "--jobs", "1", "--shard", shard,
                                    "--progress", "none"};
  };
  // The test hook stops the first run (SIGSTOP) right after its first temporary file exists.
  absl::StatusOr<pid_t> first =
      Spawn(args("0/2"), Path("first.out"), Path("first.err"), {"TEMPOKEY_TEST_STOP_IN_WRITE=1"});
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(WaitUntilStopped(*first)) << ReadOrEmpty(Path("first.err"));
  const std::vector<std::string> during = Leftovers(out);

  const ProcessResult second = RunProcess(args("0/2"), dir_);
  const ProcessResult other_shard = RunProcess(args("1/2"), dir_);
  const std::vector<std::string> after = Leftovers(out);
  const std::optional<int> first_exit = ContinueUntilExit(*first);

  ASSERT_EQ(during.size(), 1u);
  EXPECT_EQ(second.exit_code, 1);
  EXPECT_EQ(second.err, "error: " + out + "/.tempokey-batch.shard-0-of-2.lock: another tempokey "
                        "batch is running with this manifest (.tempokey-batch.shard-0-of-2.json); "
                        "wait for it to end, or give this run another -o or --shard\n");
  EXPECT_EQ(second.out, "");
  EXPECT_EQ(other_shard.exit_code, 0) << other_shard.err;
  EXPECT_EQ(after, during);
  EXPECT_EQ(first_exit, std::optional<int>(0)) << ReadOrEmpty(Path("first.err"));
  EXPECT_THAT(Leftovers(out), ::testing::IsEmpty());
  EXPECT_EQ(ParseSummary(ReadOrEmpty(Path("first.out"))).failed, 0);
  EXPECT_EQ(Outputs(out).size(), QuickSources().size());
  EXPECT_FALSE(fs::exists(out + "/.tempokey-batch.shard-0-of-2.lock"));
}

}  // namespace
}  // namespace tempokey::testing
