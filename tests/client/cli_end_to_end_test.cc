// The real `tempokey` binary against a real `tempokey-server` child on 127.0.0.1: exit codes,
// exact user-facing text and the files written.
#include <sys/stat.h>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/csv.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/angle_jumps.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::AllOf;
using ::testing::ContainsRegex;
using ::testing::EndsWith;
using ::testing::HasSubstr;
using ::testing::MatchesRegex;
using ::testing::Not;
using ::testing::StartsWith;

std::vector<std::string> Lines(const std::string& text) {
  return absl::StrSplit(text, '\n', absl::SkipEmpty());
}

// The value of the "label: value" line of a summary, or "".
std::string Field(const std::string& text, const std::string& label) {
  for (const std::string& line : Lines(text)) {
    if (line.rfind(label + ":", 0) != 0) continue;
    std::string value = line.substr(label.size() + 1);
    value.erase(0, value.find_first_not_of(' '));
    return value;
  }
  return "";
}

bool FileExists(const std::string& path) {
  struct stat info;
  return stat(path.c_str(), &info) == 0;
}

// The clip at `path` as the input was read, but for its name (the file stem).
core::Clip ReadBvhNamed(const std::string& path, const std::string& name) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(path);
  EXPECT_TRUE(clip.ok()) << clip.status();
  if (!clip.ok()) return {};
  clip->name = name;
  return *std::move(clip);
}

class CliEndToEndTest : public ServerProcessTest {
 protected:
  // `tempokey --server <the server> args...`.
  ProcessResult Tempokey(std::vector<std::string> args) {
    args.insert(args.begin(), {"--server", server_->target()});
    return RunTempokey(args, dir_);
  }

  // The id of the job `args` (a command with --detach) submits, once `jobs watch` saw it end
  // well; "" (and a failure recorded) otherwise.
  std::string FinishedJob(const std::vector<std::string>& args) {
    const ProcessResult submit = Tempokey(args);
    EXPECT_EQ(submit.exit_code, 0) << submit.err;
    const std::string job = Field(submit.out, "job");
    const ProcessResult watch = Tempokey({"jobs", "watch", job});
    EXPECT_EQ(watch.exit_code, 0) << watch.err;
    return submit.exit_code == 0 && watch.exit_code == 0 ? job : "";
  }
};

const std::string& CmuClip() {
  static const std::string path = SharedBvh("cmu/131_01.bvh");
  return path;
}
const std::string& BandaiClip() {
  static const std::string path = SharedBvh("bandai/dataset-1_walk_active_001.bvh");
  return path;
}

// ---- health, info, upload -----------------------------------------------------------------------

TEST_F(CliEndToEndTest, HealthReportsServingAndExitsZero) {
  ProcessResult run = Tempokey({"health"});

  EXPECT_EQ(run.exit_code, 0);
  EXPECT_EQ(run.out, kHealthyOutput);
  EXPECT_EQ(run.err, "");
}

TEST_F(CliEndToEndTest, ServerInfoListsVersionAndOperations) {
  ProcessResult run = Tempokey({"server-info"});

  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(Field(run.out, "version"), TEMPOKEY_VERSION);
  EXPECT_THAT(Field(run.out, "operations"), HasSubstr("convert"));
  EXPECT_EQ(Field(run.out, "wire features"), "sample_slices, batch_parts");
  EXPECT_EQ(run.err, "");
}

TEST_F(CliEndToEndTest, InfoPrintsTheExactSummaryOfABandaiClip) {
  ProcessResult run = RunTempokey({"info", SharedBvh("bandai/dataset-1_kick_normal_001.bvh")}, dir_);

  EXPECT_EQ(run.exit_code, 0);
  EXPECT_EQ(run.out,
            "name:            dataset-1_kick_normal_001\n"
            "frames:          358\n"
            "rate:            30 fps (0.0333333 s)\n"
            "duration:        11.900 s\n"
            "joints:          22\n"
            "channels:        132 (66 position, 66 rotation)\n"
            "rotation orders: ZXY (22 joints)\n");
  EXPECT_EQ(run.err, "");
}

TEST_F(CliEndToEndTest, UploadPrintsTheClipIdAndSeesARepeatAsAlreadyStored) {
  ProcessResult first = Tempokey({"upload", BandaiClip()});
  ProcessResult second = Tempokey({"upload", BandaiClip()});

  EXPECT_EQ(first.exit_code, 0) << first.err;
  EXPECT_THAT(Field(first.out, "clip id"), MatchesRegex("sha256:[0-9a-f]{64}"));
  EXPECT_EQ(Field(first.out, "stored"), "new");
  EXPECT_EQ(Field(first.out, "frames"), "146");
  EXPECT_EQ(second.exit_code, 0) << second.err;
  EXPECT_EQ(Field(second.out, "clip id"), Field(first.out, "clip id"));
  EXPECT_EQ(Field(second.out, "stored"), "already stored");
}

TEST_F(CliEndToEndTest, UploadOfAMalformedFileFailsWithOneLineNamingTheLocation) {
  const std::string path = Path("walk.bvh");
  ASSERT_TRUE(core::WriteFileAtomically(
                  path, "HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0 0\n\tCHANNELS 2 Xrotation\n}\n")
                  .ok());

  ProcessResult run = Tempokey({"upload", path});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.out, "");
  EXPECT_THAT(run.err, IsOneErrorLine());
  EXPECT_THAT(run.err, StartsWith("error: " + path + ":5:"));
}

// ---- run: the foundation job --------------------------------------------------------------------

TEST_F(CliEndToEndTest, RunWritesBackABvhThatRereadsIdenticalToTheInput) {
  for (const std::string& input : {CmuClip(), BandaiClip()}) {
    const std::string output = Path("roundtrip.bvh");

    ProcessResult run = Tempokey({"run", input, "-o", output});

    ASSERT_EQ(run.exit_code, 0) << run.err;
    EXPECT_EQ(run.err, "");
    EXPECT_THAT(Field(run.out, "clip id"), StartsWith("sha256:"));
    EXPECT_THAT(Field(run.out, "job"), Not(""));
    EXPECT_EQ(Field(run.out, "wrote"), output);
    const core::Clip original = ReadBvhNamed(input, "x");
    EXPECT_EQ(ReadBvhNamed(output, "x"), original) << input;
    EXPECT_EQ(Field(run.out, "frames"), std::to_string(original.frame_count));
  }
}

TEST_F(CliEndToEndTest, RunWritesCsvWithEveryChannelAndSample) {
  const std::string output = Path("walk.csv");

  ProcessResult run = Tempokey({"run", BandaiClip(), "-o", output});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  const core::Clip original = ReadBvhNamed(BandaiClip(), "x");
  absl::StatusOr<core::Clip> table = core::ReadCsvFile(output, original.frame_time_seconds);
  ASSERT_TRUE(table.ok()) << table.status();
  ASSERT_EQ(table->channels.size(), original.channels.size());
  EXPECT_EQ(table->frame_count, original.frame_count);
  for (std::size_t c = 0; c < original.channels.size(); ++c) {
    EXPECT_EQ(table->channels[c].samples, original.channels[c].samples) << "channel " << c;
  }
}

TEST_F(CliEndToEndTest, DetachedRunCanBeFollowedFetchedListedAndDeletedWithJobsCommands) {
  ProcessResult submit =
      Tempokey({"run", BandaiClip(), "-o", Path("unused.bvh"), "--detach", "--label", "shot=12"});
  ASSERT_EQ(submit.exit_code, 0) << submit.err;
  const std::string job = Field(submit.out, "job");
  ASSERT_THAT(job, Not(""));
  EXPECT_FALSE(FileExists(Path("unused.bvh")));

  ProcessResult watch = Tempokey({"jobs", "watch", job});
  ProcessResult get = Tempokey({"jobs", "get", job});
  ProcessResult result = Tempokey({"jobs", "result", job, "-o", Path("result.bvh")});
  ProcessResult list = Tempokey({"jobs", "list", "--label", "shot=12"});
  ProcessResult other = Tempokey({"jobs", "list", "--label", "shot=13"});
  ProcessResult deleted = Tempokey({"jobs", "delete", job});
  ProcessResult gone = Tempokey({"jobs", "get", job});

  EXPECT_EQ(watch.exit_code, 0) << watch.err;
  EXPECT_EQ(Lines(watch.out).back(), "SUCCEEDED 100%  done");
  EXPECT_EQ(get.exit_code, 0) << get.err;
  EXPECT_EQ(Field(get.out, "state"), "SUCCEEDED");
  EXPECT_EQ(Field(get.out, "operations"), "convert");
  EXPECT_EQ(Field(get.out, "labels"), "shot=12");
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(ReadBvhNamed(Path("result.bvh"), "x"), ReadBvhNamed(BandaiClip(), "x"));
  EXPECT_EQ(list.exit_code, 0) << list.err;
  ASSERT_EQ(Lines(list.out).size(), 2u) << list.out;
  EXPECT_THAT(Lines(list.out)[0], StartsWith("JOB"));
  EXPECT_THAT(Lines(list.out)[1], AllOf(StartsWith(job + "  SUCCEEDED  100%"), EndsWith("shot=12")));
  EXPECT_EQ(Lines(other.out).size(), 1u) << other.out;
  EXPECT_EQ(deleted.exit_code, 0) << deleted.err;
  EXPECT_EQ(Field(deleted.out, "deleted"), job);
  EXPECT_EQ(gone.exit_code, 1);
  EXPECT_EQ(gone.out, "");
  EXPECT_EQ(gone.err, "error: server: NOT_FOUND: job \"" + job +
                          "\" not found (unknown, deleted, or past its retention time)\n");
}

TEST_F(CliEndToEndTest, JobsResultRefusesAFormatThatDoesNotFitTheResult) {
  const std::string job = FinishedJob({"run", BandaiClip(), "-o", Path("x.bvh"), "--detach"});
  ASSERT_NE(job, "");

  ProcessResult run = Tempokey({"jobs", "result", job, "-o", Path("x.json")});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "error: -o " + Path("x.json") + ": job " + job +
                         " produced a sampled clip, which has no curves: write .bvh, .csv, .gltf "
                         "or .glb\n");
  EXPECT_FALSE(FileExists(Path("x.json")));
}

// A reduce job's curves are fetched in every format `reduce --job` writes: .glb and .bvh as the
// server formats them (the glTF fitted against the job's stored clip, the samples baked), the
// same bytes as the reduce command's own files. They were refused ("write .json or .anim").
TEST_F(CliEndToEndTest, JobsResultOfAReduceWritesEveryFormatTheReduceCommandWrites) {
  const std::string job = FinishedJob({"reduce", BandaiClip(), "-o", Path("x.json"), "--detach"});
  ASSERT_NE(job, "");

  ProcessResult glb = Tempokey({"jobs", "result", job, "-o", Path("fetched.glb")});
  ProcessResult bvh = Tempokey({"jobs", "result", job, "-o", Path("fetched.bvh")});
  ProcessResult json = Tempokey({"jobs", "result", job, "-o", Path("fetched.json")});
  ProcessResult own_glb = Tempokey({"reduce", BandaiClip(), "-o", Path("own.glb"), "--job"});
  ProcessResult own_bvh = Tempokey({"reduce", BandaiClip(), "-o", Path("own.bvh"), "--job"});

  for (const ProcessResult* run : {&glb, &bvh, &json, &own_glb, &own_bvh}) {
    EXPECT_EQ(run->exit_code, 0) << run->err;
  }
  EXPECT_EQ(Field(glb.out, "wrote"), Path("fetched.glb"));
  const auto bytes = [&](const std::string& name) {
    return core::ReadFile(Path(name)).value_or("unreadable " + name);
  };
  EXPECT_EQ(bytes("fetched.glb").substr(0, 4), "glTF");
  EXPECT_TRUE(bytes("fetched.glb") == bytes("own.glb"));
  EXPECT_TRUE(bytes("fetched.bvh") == bytes("own.bvh"));
  EXPECT_GT(bytes("fetched.json").size(), 1000u);
}

TEST_F(CliEndToEndTest, JobsCancelOfAFinishedJobKeepsItsState) {
  ProcessResult submit = Tempokey({"run", BandaiClip(), "-o", Path("x.bvh"), "--detach"});
  ASSERT_EQ(submit.exit_code, 0) << submit.err;
  const std::string job = Field(submit.out, "job");
  ASSERT_EQ(Tempokey({"jobs", "watch", job}).exit_code, 0);

  ProcessResult cancel = Tempokey({"jobs", "cancel", job});

  EXPECT_EQ(cancel.exit_code, 0) << cancel.err;
  EXPECT_EQ(cancel.out, "job:             " + job + "\nstate:           SUCCEEDED\n");
}

// ---- errors -------------------------------------------------------------------------------------

TEST_F(CliEndToEndTest, UsageErrorsExitTwoWithOneLine) {
  ProcessResult unknown_flag = Tempokey({"retime", CmuClip(), "-o", Path("x.bvh"), "--sped", "1"});
  ProcessResult no_command = Tempokey({});
  ProcessResult bad_number = Tempokey({"reduce", CmuClip(), "-o", Path("x.json"), "--tolerance", "½"});

  EXPECT_EQ(unknown_flag.exit_code, 2);
  EXPECT_EQ(unknown_flag.err, "error: unknown flag --sped for 'retime' (see tempokey retime --help)\n");
  EXPECT_EQ(no_command.exit_code, 2);
  EXPECT_EQ(no_command.err, "error: missing command (see tempokey --help)\n");
  EXPECT_EQ(bad_number.exit_code, 2);
  EXPECT_EQ(bad_number.err, "error: --tolerance: expected a number, got '½'\n");
  EXPECT_FALSE(FileExists(Path("x.bvh")));
}

TEST_F(CliEndToEndTest, UnreachableServerFailsWithOneLine) {
  ProcessResult run = RunTempokey({"--server", "127.0.0.1:1", "--timeout", "20", "health"}, dir_);
  ProcessResult upload =
      RunTempokey({"--server", "127.0.0.1:1", "--timeout", "20", "upload", BandaiClip()}, dir_);

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.out, "");
  EXPECT_THAT(run.err, IsOneErrorLine());
  EXPECT_THAT(run.err, StartsWith("error: server: UNAVAILABLE: "));
  EXPECT_EQ(upload.exit_code, 1);
  EXPECT_THAT(upload.err, IsOneErrorLine());
  EXPECT_THAT(upload.err, StartsWith("error: server: UNAVAILABLE: "));
}

TEST_F(CliEndToEndTest, RoundRobinTargetSkipsADeadAddress) {
  const std::string target = "ipv4:127.0.0.1:1," + server_->target();

  ProcessResult health = RunTempokey({"--server", target, "health"}, dir_);
  ProcessResult run = RunTempokey({"--server", target, "run", BandaiClip(), "-o", Path("rr.bvh")}, dir_);

  EXPECT_EQ(health.exit_code, 0) << health.err;
  EXPECT_EQ(health.out, kHealthyOutput);
  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(ReadBvhNamed(Path("rr.bvh"), "x"), ReadBvhNamed(BandaiClip(), "x"));
}

TEST_F(CliEndToEndTest, StoppedServerIsReportedByHealth) {
  ASSERT_EQ(server_->Stop(), 0) << server_->log();

  ProcessResult run = Tempokey({"--timeout", "20", "health"});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_THAT(run.err, IsOneErrorLine());
  EXPECT_THAT(run.err, StartsWith("error: server: UNAVAILABLE: "));
}

TEST_F(CliEndToEndTest, ServerRefusalIsOneLineWithTheCodeAndLeavesTheOldOutput) {
  const std::string output = Path("keep.json");
  ASSERT_TRUE(core::WriteFileAtomically(output, "old contents").ok());

  // Only the server knows its work limit (60 s by default): 1000 passes of the paper's fit over
  // 132 channels are predicted above it.
  ProcessResult run = Tempokey(
      {"reduce", BandaiClip(), "-o", output, "--method", "paper", "--iterations", "1000"});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.out, "");
  EXPECT_THAT(run.err, IsOneErrorLine());
  EXPECT_THAT(run.err, StartsWith("error: server: RESOURCE_EXHAUSTED: the request is over this "
                                  "server's work limit: predicted "));
  EXPECT_THAT(run.err, HasSubstr("reduce (paper): 132 channels x "));
  EXPECT_EQ(*core::ReadFile(output), "old contents");
}

TEST_F(CliEndToEndTest, InvalidStepsAreRefusedBeforeAnythingIsSentAndLeaveTheOldOutput) {
  const std::string output = Path("keep.bvh");
  ASSERT_TRUE(core::WriteFileAtomically(output, "old contents").ok());

  ProcessResult run =
      Tempokey({"retime", CmuClip(), "-o", output, "--speed", "0s:1,1s:1000", "--job"});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.out, "");  // no "clip id:" line: nothing was uploaded
  EXPECT_EQ(run.err,
            "error: operation 1 (retime): speed knot 2 (1s:1000): speed 1000 is outside the "
            "allowed range [0.01, 100]\n");
  EXPECT_EQ(*core::ReadFile(output), "old contents");
}

// ---- retime -------------------------------------------------------------------------------------

TEST_F(CliEndToEndTest, RetimeAtHalfSpeedBetweenTwoAndFourSecondsAddsTwoSeconds) {
  const std::string output = Path("slow.bvh");

  ProcessResult run =
      Tempokey({"retime", CmuClip(), "-o", output, "--speed", "0s:1,2s:1,2s:0.5,4s:0.5,4s:1"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(run.err, "");
  // 994 source frames at 120 fps last 8.275 s; 2 s at half speed play for 4 s: 240 more frames.
  EXPECT_EQ(Field(run.out, "output frames"), "1234");
  EXPECT_EQ(Field(run.out, "wrote"), output);
  const core::Clip source = ReadBvhNamed(CmuClip(), "x");
  const core::Clip slow = ReadBvhNamed(output, "x");
  EXPECT_EQ(slow.frame_count, 1234);
  EXPECT_EQ(slow.frame_time_seconds, source.frame_time_seconds);
  EXPECT_EQ(slow.skeleton, source.skeleton);
  ASSERT_EQ(slow.channels.size(), source.channels.size());
  // Fit to grid: the first and the last output frames are the first and last source poses.
  constexpr double kPoseTolerance = 1e-6;  // degrees / file units, far below the file's 4 decimals
  for (std::size_t c = 0; c < source.channels.size(); ++c) {
    EXPECT_NEAR(slow.channels[c].samples.front(), source.channels[c].samples.front(), kPoseTolerance);
    EXPECT_NEAR(slow.channels[c].samples.back(), source.channels[c].samples.back(), kPoseTolerance);
  }
  // The joints move continuously: no output step over 20 degrees that the source lacks.
  absl::StatusOr<std::vector<core::SpeedKnot>> knots =
      core::ParseSpeedKnots("0s:1,2s:1,2s:0.5,4s:0.5,4s:1");
  ASSERT_TRUE(knots.ok()) << knots.status();
  core::TimeWarpSpec warp;
  warp.domain = core::WarpDomain::kSpeedOverSource;
  warp.speed = *knots;
  for (const Jump& jump : JumpsTheSourceLacks(source, slow, warp, {})) {
    ADD_FAILURE() << "channel " << jump.channel << " output frame " << jump.output_frame
                  << ": step " << jump.output_step << " where the source moves "
                  << jump.source_variation;
  }
}

TEST_F(CliEndToEndTest, RetimeToThirtyFpsWritesCsvAtTheNewRate) {
  const std::string output = Path("walk30.csv");

  ProcessResult run = Tempokey({"retime", CmuClip(), "-o", output, "--fps", "30"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(Field(run.out, "rate"), "30 fps (0.03333333333333333 s)");
  const std::string frames = Field(run.out, "frames");
  absl::StatusOr<core::Clip> table = core::ReadCsvFile(output, 1.0 / 30.0);
  ASSERT_TRUE(table.ok()) << table.status();
  EXPECT_EQ(std::to_string(table->frame_count), frames);
  EXPECT_EQ(table->channels.size(), 96u);
}

TEST_F(CliEndToEndTest, RetimeThroughAJobWritesTheSameFileAsProcess) {
  const std::vector<std::string> retime = {"retime", BandaiClip(), "--speed", "0s:1,1s:2",
                                           "--filter", "box"};
  std::vector<std::string> via_process = retime;
  via_process.insert(via_process.end(), {"-o", Path("process.bvh")});
  std::vector<std::string> via_job = retime;
  via_job.insert(via_job.end(), {"-o", Path("job.bvh"), "--job"});

  ProcessResult process = Tempokey(via_process);
  ProcessResult job = Tempokey(via_job);

  ASSERT_EQ(process.exit_code, 0) << process.err;
  ASSERT_EQ(job.exit_code, 0) << job.err;
  EXPECT_THAT(Field(job.out, "job"), Not(""));
  EXPECT_EQ(*core::ReadFile(Path("job.bvh")), *core::ReadFile(Path("process.bvh")));
}

TEST_F(CliEndToEndTest, RetimeRefusesBadSpeedSyntaxAsUsage) {
  ProcessResult run = Tempokey({"retime", CmuClip(), "-o", Path("x.bvh"), "--speed", "0s:1,2x:0.5"});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "error: --speed: speed knot 2 '2x:0.5': time needs a unit, s or f\n");
  EXPECT_FALSE(FileExists(Path("x.bvh")));
}

// ---- reduce -------------------------------------------------------------------------------------

TEST_F(CliEndToEndTest, ReducePaperToBvhBakesAtTheSourceRateAndReportsQuality) {
  const std::string output = Path("reduced.bvh");

  ProcessResult run = Tempokey({"reduce", BandaiClip(), "-o", output, "--method", "paper",
                                "--iterations", "2"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_THAT(Field(run.out, "keys"), ContainsRegex("^[0-9]+ of 19272 samples \\([0-9.]+%\\)$"));
  EXPECT_THAT(Field(run.out, "rms error"), MatchesRegex("[0-9]+\\.[0-9]{4}"));
  EXPECT_THAT(Field(run.out, "worst"), ContainsRegex("^channel [0-9]+ \\(.*\\) at frame [0-9]+$"));
  EXPECT_EQ(Field(run.out, "wrote"), output);
  const core::Clip source = ReadBvhNamed(BandaiClip(), "x");
  const core::Clip baked = ReadBvhNamed(output, "x");
  EXPECT_EQ(baked.frame_count, source.frame_count);
  EXPECT_EQ(baked.frame_time_seconds, source.frame_time_seconds);
  EXPECT_EQ(baked.skeleton, source.skeleton);
}

// The number before " of " in the report's keys line ("1810 of 19272 samples (9.39%)").
std::int64_t ReportedKeys(const std::string& out) {
  const std::string keys = Field(out, "keys");
  return std::stoll(keys.substr(0, keys.find(' ')));
}

// The keyed clip `run` wrote to `output` (.json), measured again against BandaiClip(): every
// channel within `bound` at every frame, with the keys `run` reported.
void ExpectFileKeepsBoundWithReportedKeys(const std::string& output, const ProcessResult& run,
                                          double bound) {
  absl::StatusOr<core::KeyedClip> keyed = core::ReadKeyedClipJsonFile(output);
  ASSERT_TRUE(keyed.ok()) << keyed.status();
  absl::StatusOr<core::ReductionReport> measured =
      core::MeasureReduction(ReadBvhNamed(BandaiClip(), "x"), *keyed);
  ASSERT_TRUE(measured.ok()) << measured.status();
  EXPECT_LE(measured->max_error, bound);
  EXPECT_EQ(measured->key_count, ReportedKeys(run.out));
}

TEST_F(CliEndToEndTest, ReducePaperKeyedExportsAgreeWithTheBakedBvhAndTheReport) {
  const std::vector<std::string> reduce = {"reduce", BandaiClip(), "--method", "paper",
                                           "--iterations", "2"};
  std::vector<ProcessResult> runs;
  for (const std::string output : {"keys.json", "keys.anim", "baked.bvh"}) {
    std::vector<std::string> args = reduce;
    args.insert(args.end(), {"-o", Path(output)});
    runs.push_back(Tempokey(args));
    ASSERT_EQ(runs.back().exit_code, 0) << output << ": " << runs.back().err;
    EXPECT_EQ(Field(runs.back().out, "wrote"), Path(output));
  }

  const core::Clip source = ReadBvhNamed(BandaiClip(), "x");
  absl::StatusOr<core::KeyedClip> keyed = core::ReadKeyedClipJsonFile(Path("keys.json"));
  ASSERT_TRUE(keyed.ok()) << keyed.status();
  ASSERT_EQ(keyed->curves.size(), source.channels.size());
  std::int64_t key_count = 0;
  for (const core::Curve& curve : keyed->curves) key_count += static_cast<std::int64_t>(curve.keys.size());
  EXPECT_EQ(key_count, ReportedKeys(runs[0].out));
  EXPECT_EQ(keyed->layout.skeleton, source.skeleton);
  // The same fit, reported alike whatever the output format.
  EXPECT_EQ(Field(runs[1].out, "keys"), Field(runs[0].out, "keys"));
  EXPECT_EQ(Field(runs[2].out, "max error"), Field(runs[0].out, "max error"));
  // The report measures the curves against the source, as core measures them here.
  absl::StatusOr<core::ReductionReport> measured = core::MeasureReduction(source, *keyed);
  ASSERT_TRUE(measured.ok()) << measured.status();
  EXPECT_EQ(Field(runs[0].out, "max error"), absl::StrFormat("%.4f", measured->max_error));
  // The .bvh is those curves baked at the source rate.
  absl::StatusOr<core::Clip> baked_here = core::Bake(*keyed);
  ASSERT_TRUE(baked_here.ok()) << baked_here.status();
  const core::Clip baked_there = ReadBvhNamed(Path("baked.bvh"), "x");
  ASSERT_EQ(baked_there.channels.size(), baked_here->channels.size());
  EXPECT_EQ(baked_there.frame_count, source.frame_count);
  for (std::size_t c = 0; c < baked_here->channels.size(); ++c) {
    EXPECT_EQ(baked_there.channels[c].samples, baked_here->channels[c].samples) << "channel " << c;
  }
  // One Maya anim block per channel.
  const std::string anim = *core::ReadFile(Path("keys.anim"));
  EXPECT_THAT(anim, StartsWith("animVersion 1.1;\n"));
  std::size_t blocks = 0;
  for (std::size_t at = anim.find("\nanim "); at != std::string::npos; at = anim.find("\nanim ", at + 1)) {
    ++blocks;
  }
  EXPECT_EQ(blocks, source.channels.size());
}

TEST_F(CliEndToEndTest, ReduceByDefaultStaysWithinTheBoundWithFewKeys) {
  const std::string output = Path("tolerance.json");

  ProcessResult run = Tempokey({"reduce", BandaiClip(), "-o", output, "--tolerance", "0.5",
                                "--position-tolerance", "0.5"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(run.err, "");
  ExpectFileKeepsBoundWithReportedKeys(output, run, 0.5);
  // 146 frames x 132 channels; most channels of the walk are constant (two keys each).
  EXPECT_LT(ReportedKeys(run.out), 146 * 132 / 10);
}

// --fewest-keys: the same bounds, kept at every frame (measured again from the file written), with
// fewer keys than the default search on a real capture.
TEST_F(CliEndToEndTest, ReduceWithFewestKeysKeepsTheBoundWithFewerKeys) {
  const std::string output = Path("fewest.json");
  const std::vector<std::string> bounds = {"--tolerance", "0.5", "--position-tolerance", "0.5"};
  std::vector<std::string> plain_args = {"reduce", BandaiClip(), "-o", Path("plain.json")};
  std::vector<std::string> fewest_args = {"reduce", BandaiClip(), "-o", output, "--fewest-keys"};
  plain_args.insert(plain_args.end(), bounds.begin(), bounds.end());
  fewest_args.insert(fewest_args.end(), bounds.begin(), bounds.end());

  ProcessResult plain = Tempokey(plain_args);
  ProcessResult fewest = Tempokey(fewest_args);

  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  ASSERT_EQ(fewest.exit_code, 0) << fewest.err;
  EXPECT_LT(ReportedKeys(fewest.out), ReportedKeys(plain.out));
  ExpectFileKeepsBoundWithReportedKeys(output, fewest, 0.5);
}

TEST_F(CliEndToEndTest, ReduceWithAKeyBudgetKeepsIt) {
  const std::string output = Path("budget.anim");

  ProcessResult run = Tempokey({"reduce", BandaiClip(), "-o", output, "--key-budget", "600"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_LE(ReportedKeys(run.out), 600);
  EXPECT_TRUE(FileExists(output));
}

TEST_F(CliEndToEndTest, ReduceRefusesAKeyBudgetBelowTwoKeysPerChannelBeforeSendingAnything) {
  ProcessResult run = Tempokey({"reduce", BandaiClip(), "-o", Path("x.json"), "--key-budget", "100"});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_THAT(run.err, IsOneErrorLine());
  EXPECT_EQ(run.err,
            "error: operation 1 (reduce): tolerance.key_budget 100 is below the 264 keys any fit "
            "of 132 channels needs (2 per channel)\n");
  EXPECT_FALSE(FileExists(Path("x.json")));
}

TEST_F(CliEndToEndTest, ReduceRefusesInvalidPaperParametersBeforeSending) {
  ProcessResult run = Tempokey({"reduce", BandaiClip(), "-o", Path("x.bvh"), "--method", "paper",
                                "--step-y", "-1"});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err, "error: operation 1 (reduce): paper.step_y must be > 0, got -1\n");
  EXPECT_FALSE(FileExists(Path("x.bvh")));
}

}  // namespace
}  // namespace tempokey::testing
