// The CLI in-process (RunCli with string streams) for everything that needs no server: info,
// help, usage errors, bad files and flag values refused before any connection is made.
#include "client/cli.h"

#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/cli_errors.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::client {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;
using ::tempokey::testing::MakeTempDir;
using ::tempokey::testing::SharedBvh;

struct CliRun {
  int exit_code = -1;
  std::string out;
  std::string err;
};

CliRun RunTempokey(std::vector<std::string> args) {
  std::ostringstream out;
  std::ostringstream err;
  CliRun run;
  run.exit_code = RunCli(args, CliIo{.out = out, .err = err, .show_progress = false});
  run.out = out.str();
  run.err = err.str();
  return run;
}

// An address nothing listens on: commands that fail before connecting never notice.
constexpr char kNoServer[] = "127.0.0.1:1";

TEST(CliInfoTest, SummarizesTheCmuClip) {
  CliRun run = RunTempokey({"info", SharedBvh("cmu/131_01.bvh")});

  EXPECT_EQ(run.exit_code, 0);
  EXPECT_EQ(run.err, "");
  EXPECT_EQ(run.out,
            "name:            131_01\n"
            "frames:          994\n"
            "rate:            120 fps (0.0083333 s)\n"
            "duration:        8.275 s\n"
            "joints:          31\n"
            "channels:        96 (3 position, 93 rotation)\n"
            "rotation orders: ZYX (19 joints), ZXY (12 joints)\n");
}

// A result nobody got is a failure: with stdout on a full disk every command exited 0 (a batch
// leaving an empty summary, an upload its id nowhere). /dev/full fails every write with ENOSPC.
TEST(CliInfoTest, AResultThatCannotBeWrittenToStdoutIsAFailure) {
  const testing::ProcessResult run = testing::RunProcess(
      {"/bin/sh", "-c",
       absl::StrCat("'", testing::TempokeyBinary(), "' info '", SharedBvh("cmu/131_01.bvh"),
                    "' > /dev/full")},
      MakeTempDir());

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err, "error: cannot write the result to standard output: no space left on device\n");
}

TEST(CliInfoTest, SummarizesABandaiClip) {
  CliRun run = RunTempokey({"info", SharedBvh("bandai/dataset-1_walk_active_001.bvh")});

  EXPECT_EQ(run.exit_code, 0);
  EXPECT_EQ(run.err, "");
  EXPECT_EQ(run.out,
            "name:            dataset-1_walk_active_001\n"
            "frames:          146\n"
            "rate:            30 fps (0.0333333 s)\n"
            "duration:        4.833 s\n"
            "joints:          22\n"
            "channels:        132 (66 position, 66 rotation)\n"
            "rotation orders: ZXY (22 joints)\n");
}

TEST(CliInfoTest, ReadsCsvAtTheGivenRate) {
  const std::string dir = MakeTempDir();
  const std::string path = dir + "/table.csv";
  ASSERT_TRUE(core::WriteFileAtomically(path, "Hips.Xrotation,Hips.Yrotation,weight\n"
                                              "1,2,0.5\n3,4,0.25\n5,6,0\n")
                  .ok());

  CliRun run = RunTempokey({"info", path, "--input-fps", "29.97"});

  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_THAT(run.out, HasSubstr("frames:          3\n"));
  EXPECT_THAT(run.out, HasSubstr("rate:            29.97 fps (0.03336666666666667 s)\n"));
  EXPECT_THAT(run.out, HasSubstr("channels:        3 (0 position, 2 rotation, 1 scalar)\n"));
  EXPECT_THAT(run.out, HasSubstr("rotation orders: XY (1 joint)\n"));
}

TEST(CliInfoTest, RefusesCsvWithoutARateAsUsage) {
  const std::string dir = MakeTempDir();
  const std::string path = dir + "/table.csv";
  ASSERT_TRUE(core::WriteFileAtomically(path, "a\n1\n").ok());

  CliRun run = RunTempokey({"info", path});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.out, "");
  EXPECT_EQ(run.err, "error: " + path +
                         ": a CSV file does not store its frame rate; give it with --input-fps\n");
}

TEST(CliInfoTest, AnInputRateOutsideTheFrameTimesAClipMayHaveIsAUsageErrorNamingTheFlag) {
  const std::string dir = MakeTempDir();
  const std::string path = dir + "/table.csv";
  ASSERT_TRUE(core::WriteFileAtomically(path, "a\n1\n").ok());

  CliRun run = RunTempokey({"info", path, "--input-fps", "999999999999999"});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "error: --input-fps 999999999999999: must be from 1/3600 (a frame an "
                     "hour) to 1000000 frames per second\n");
}

// A control character quoted from a file (or a server) is shown, not sent to the terminal: an
// escape sequence in a pipeline file's value could otherwise clear the user's screen.
TEST(CliErrorLineTest, ControlCharactersAreShownEscapedOnOneLine) {
  constexpr char kMessage[] = "speed '0s:1\x1b[2J\0' on\nline 2\r \xc2\x9b ok \xc3\xa9\x7f \x9b" "2J";
  const absl::Status status =
      absl::InvalidArgumentError(std::string(kMessage, sizeof kMessage - 1));

  EXPECT_EQ(ErrorLine(status),
            "error: speed '0s:1\\x1b[2J\\x00' on line 2  \\u009b ok \xc3\xa9\\x7f \\x9b2J");
}

TEST(CliInfoTest, ReportsAMalformedFileAsOneLineWithItsLocation) {
  const std::string dir = MakeTempDir();
  const std::string path = dir + "/walk.bvh";
  ASSERT_TRUE(core::WriteFileAtomically(path, "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n}\n").ok());

  CliRun run = RunTempokey({"info", path});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.out, "");
  EXPECT_EQ(run.err, "error: " + path + ":4:13: expected 3 numbers after OFFSET, found 2\n");
}

TEST(CliInfoTest, ReportsAMissingFile) {
  CliRun run = RunTempokey({"info", "/nonexistent/walk.bvh"});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err, "error: /nonexistent/walk.bvh: no such file\n");
}

TEST(CliUsageTest, RefusesMistakesWithExitCode2AndOneLine) {
  struct Case {
    std::vector<std::string> args;
    std::string error;
  };
  const std::string cmu = SharedBvh("cmu/131_01.bvh");
  const Case cases[] = {
      {{}, "error: missing command (see tempokey --help)\n"},
      {{"frobnicate"}, "error: unknown command 'frobnicate' (see tempokey --help)\n"},
      {{"--colour", "info"}, "error: unknown flag --colour (see tempokey --help)\n"},
      {{"info"}, "error: info: missing FILE (see tempokey info --help)\n"},
      {{"info", "a.bvh", "b.bvh"}, "error: info: unexpected argument 'b.bvh' (see tempokey info --help)\n"},
      {{"info", "a.txt"}, "error: a.txt: unknown format '.txt' (expected .bvh, .csv)\n"},
      {{"retime", cmu, "--fsp", "30"},
       "error: unknown flag --fsp for 'retime' (see tempokey retime --help)\n"},
      {{"retime", cmu}, "error: retime: missing -o/--output FILE (see tempokey retime --help)\n"},
      {{"retime", cmu, "-o", "out.anim"},
       "error: -o out.anim: unknown format '.anim' (expected .bvh, .csv, .gltf, .glb)\n"},
      {{"retime", cmu, "-o", "out.bvh", "--fps", "0"},
       "error: --fps: expected a frame rate > 0, got '0'\n"},
      {{"retime", cmu, "-o", "out.bvh", "--fit-frames", "12.5"},
       "error: --fit-frames: expected an integer, got '12.5'\n"},
      {{"retime", cmu, "-o", "out.bvh", "--fit-frames", "10", "--fit-seconds", "2"},
       "error: --fit-frames and --fit-seconds exclude each other\n"},
      {{"retime", cmu, "-o", "out.bvh", "--filter", "gauss"},
       "error: --filter: expected one of tent, linear, box, cubic, lanczos3, got 'gauss'\n"},
      {{"retime", cmu, "-o", "out.bvh", "--hold", "2s"},
       "error: --hold: expected T:DURATION, such as 2s:0.5s, got '2s'\n"},
      {{"retime", cmu, "-o", "out.bvh", "--speed-over", "output"},
       "error: --speed-over needs --speed\n"},
      {{"retime", cmu, "-o", "out.bvh", "--label", "a=b"},
       "error: --label applies to jobs: add --job or --detach\n"},
      // The paper's method refused these naming the options' fields ("output_rate must be
      // unset"); a rate for a BVH, which stores its own, was silently ignored.
      {{"retime", cmu, "-o", "out.bvh", "--method", "paper", "--fps", "60"},
       "error: --method paper takes no --fps: the published procedure keeps the source's frame "
       "rate\n"},
      {{"retime", cmu, "-o", "out.bvh", "--method", "paper", "--fit-seconds", "3"},
       "error: --method paper takes no --fit-seconds: the published procedure rounds each "
       "region's frames itself\n"},
      {{"retime", cmu, "-o", "out.bvh", "--method", "paper", "--fit-frames", "300"},
       "error: --method paper takes no --fit-frames: the published procedure rounds each "
       "region's frames itself\n"},
      {{"retime", cmu, "-o", "out.bvh", "--method", "paper", "--pin", "2s:60"},
       "error: --method paper takes no --pin: the published procedure has no pins\n"},
      {{"retime", cmu, "-o", "out.bvh", "--method", "paper", "--filter", "lanczos3"},
       "error: --method paper takes no --filter other than box: the published procedure weights "
       "samples with its own box\n"},
      {{"info", cmu, "--input-fps", "30"},
       "error: --input-fps is for CSV input: " + cmu +
           " stores its own frame time (retime --fps changes the rate)\n"},
      {{"reduce", cmu, "-o", "out.txt"},
       "error: -o out.txt: unknown format '.txt' (expected .bvh, .csv, .json, .anim, .gltf, .glb)\n"},
      {{"reduce", cmu, "-o", "out.json", "--tolerance", "abc"},
       "error: --tolerance: expected a number, got 'abc'\n"},
      {{"reduce", cmu, "-o", "out.json", "--method", "paper", "--tolerance", "1"},
       "error: --tolerance does not apply to --method paper\n"},
      {{"reduce", cmu, "-o", "out.json", "--step-x", "2"},
       "error: --step-x does not apply to --method tolerance\n"},
      {{"jobs"}, "error: jobs: missing subcommand: list, get, cancel, delete, watch or result (see "
                 "tempokey jobs --help)\n"},
      {{"jobs", "pause", "j1"}, "error: jobs: unknown subcommand 'pause' (see tempokey jobs --help)\n"},
      {{"jobs", "get"}, "error: jobs get: missing JOB (see tempokey jobs get --help)\n"},
      {{"jobs", "list", "--state", "done"},
       "error: --state: expected one of queued, running, succeeded, failed, cancelled, got 'done'\n"},
      {{"health", "--timeout", "-1"}, "error: --timeout: expected seconds >= 0, got '-1'\n"},
      {{"health", "--cert", "c.pem"}, "error: --cert and --key go together (mutual TLS needs both)\n"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = c.args;
    args.insert(args.begin(), {"--server", kNoServer});
    if (c.args.empty()) args.clear();

    CliRun run = RunTempokey(args);

    EXPECT_EQ(run.exit_code, 2) << c.error;
    EXPECT_EQ(run.err, c.error);
    EXPECT_EQ(run.out, "") << c.error;
  }
}

TEST(CliUsageTest, DoesNotWriteTheOutputWhenRefusingUsage) {
  const std::string dir = MakeTempDir();
  const std::string output = dir + "/out.bvh";

  CliRun run = RunTempokey({"retime", SharedBvh("cmu/131_01.bvh"), "-o", output, "--fps", "x"});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_FALSE(core::ReadFile(output).ok());
}

TEST(CliHelpTest, PrintsToolHelpListingEveryCommand) {
  CliRun run = RunTempokey({"--help"});

  EXPECT_EQ(run.exit_code, 0);
  EXPECT_EQ(run.err, "");
  EXPECT_THAT(run.out, StartsWith("usage: tempokey [global options] COMMAND [ARGS] [options]\n"));
  for (const char* command : {"info", "upload", "run", "retime", "reduce", "health", "server-info",
                              "jobs list", "jobs get", "jobs watch", "jobs result", "jobs cancel",
                              "jobs delete"}) {
    EXPECT_THAT(run.out, HasSubstr(std::string("\n  ") + command + " ")) << command;
  }
  EXPECT_THAT(run.out, HasSubstr("Exit codes: 0 ok, 1 failed, 2 usage.\n"));
}

TEST(CliHelpTest, PrintsEachCommandsHelpWithItsFlags) {
  CliRun retime = RunTempokey({"retime", "--help"});
  CliRun reduce = RunTempokey({"help", "reduce"});
  CliRun jobs = RunTempokey({"jobs", "--help"});
  CliRun watch = RunTempokey({"jobs", "watch", "-h"});

  EXPECT_EQ(retime.exit_code, 0);
  EXPECT_THAT(retime.out, StartsWith("usage: tempokey retime IN -o OUT [--speed KNOTS] [options]\n"));
  EXPECT_THAT(retime.out, HasSubstr("  --speed KNOTS "));
  EXPECT_THAT(retime.out, HasSubstr("  --fps RATE "));
  EXPECT_EQ(reduce.exit_code, 0);
  EXPECT_THAT(reduce.out, HasSubstr("  --method NAME "));
  EXPECT_THAT(reduce.out, HasSubstr("  --step-tangent-y V "));
  EXPECT_EQ(jobs.exit_code, 0);
  EXPECT_THAT(jobs.out, StartsWith("usage: tempokey jobs SUBCOMMAND [ARGS] [options]\n"));
  EXPECT_EQ(watch.exit_code, 0);
  EXPECT_THAT(watch.out, StartsWith("usage: tempokey jobs watch JOB\n"));
}

TEST(CliHelpTest, PrintsTheVersion) {
  CliRun run = RunTempokey({"--version"});

  EXPECT_EQ(run.exit_code, 0);
  EXPECT_EQ(run.out, std::string("tempokey ") + TEMPOKEY_VERSION + "\n");
}

}  // namespace
}  // namespace tempokey::client
