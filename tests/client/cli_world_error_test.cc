// `tempokey reduce` and `tempokey batch` with the joint world-position error (SPEC 4.4): the real
// CLI against a real tempokey-server child on 127.0.0.1. The report's lines, --joint-tolerance in
// file units and in percent of the figure's height (measured here on the written curves), the
// same option in a pipeline file, and the exact messages of its misuse.
#include <filesystem>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/reduce/world_error.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

namespace fs = std::filesystem;
using ::testing::MatchesRegex;

// The value of the "label: value" line of a report, or "".
std::string Field(const std::string& text, const std::string& label) {
  for (absl::string_view line : absl::StrSplit(text, '\n', absl::SkipEmpty())) {
    if (!absl::StartsWith(line, label + ":")) continue;
    std::string value(line.substr(label.size() + 1));
    value.erase(0, value.find_first_not_of(' '));
    return value;
  }
  return "";
}

core::Clip ReadSource(const std::string& path) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(path);
  EXPECT_TRUE(clip.ok()) << clip.status();
  return clip.ok() ? *std::move(clip) : core::Clip();
}

// The curves written to `path` measured through the skeleton against `source`.
core::WorldErrorReport Measure(const std::string& source, const std::string& path) {
  absl::StatusOr<core::KeyedClip> keyed = core::ReadKeyedClipJsonFile(path);
  EXPECT_TRUE(keyed.ok()) << keyed.status();
  if (!keyed.ok()) return {};
  core::Clip clip = ReadSource(source);
  absl::StatusOr<core::WorldErrorReport> world = core::MeasureWorldError(clip, *keyed);
  EXPECT_TRUE(world.ok()) << world.status();
  return world.ok() ? *world : core::WorldErrorReport();
}

class CliWorldErrorTest : public ServerProcessTest {
 protected:
  ProcessResult Tempokey(std::vector<std::string> args) {
    args.insert(args.begin(), {"--server", server_->target()});
    return RunTempokey(args, dir_);
  }
};

const std::string& BandaiClip() {
  static const std::string path = SharedBvh("bandai/dataset-1_kick_normal_001.bvh");
  return path;
}
const std::string& CmuClip() {
  static const std::string path = SharedBvh("cmu/131_01.bvh");
  return path;
}

TEST_F(CliWorldErrorTest, ReducePrintsTheJointErrorInFileUnitsAndPercentOfTheHeight) {
  const std::string output = Path("default.json");

  ProcessResult run = Tempokey({"reduce", BandaiClip(), "-o", output});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  const core::WorldErrorReport measured = Measure(BandaiClip(), output);
  const double height = *core::FigureHeight(ReadSource(BandaiClip()));
  EXPECT_EQ(Field(run.out, "figure height"), absl::StrFormat("%.4g (first frame)", height));
  EXPECT_EQ(Field(run.out, "joint max error"),
            absl::StrFormat("%.4f (%.3f%% of height) at %s, frame %d", measured.max_error,
                            100.0 * measured.max_error / height, measured.worst_point_name,
                            measured.worst_frame));
  EXPECT_EQ(Field(run.out, "joint rms error"),
            absl::StrFormat("%.4f (%.3f%% of height)", measured.rms_error,
                            100.0 * measured.rms_error / height));
  EXPECT_EQ(Field(run.out, "joint bound"), "");  // none was asked for
  EXPECT_GT(measured.max_error, 1.0);
}

TEST_F(CliWorldErrorTest, JointToleranceOfOneUnitKeepsEveryJointWithinIt) {
  const std::string output = Path("one.json");

  ProcessResult run = Tempokey({"reduce", BandaiClip(), "-o", output, "--joint-tolerance", "1"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(run.err, "");
  EXPECT_LE(Measure(BandaiClip(), output).max_error, 1.0);
  EXPECT_THAT(Field(run.out, "joint bound"), MatchesRegex("1 \\([0-9.]+% of height\\)"));
}

TEST_F(CliWorldErrorTest, JointToleranceInPercentIsOfTheFigureHeight) {
  const std::string output = Path("percent.json");

  ProcessResult run =
      Tempokey({"reduce", CmuClip(), "-o", output, "--joint-tolerance", "0.5%"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  const double bound = 0.005 * *core::FigureHeight(ReadSource(CmuClip()));
  EXPECT_LE(Measure(CmuClip(), output).max_error, bound);
  EXPECT_EQ(Field(run.out, "joint bound"), absl::StrFormat("%.4g (0.500%% of height)", bound));
}

TEST_F(CliWorldErrorTest, MisusedJointToleranceGetsExactMessages) {
  ProcessResult syntax =
      Tempokey({"reduce", BandaiClip(), "-o", Path("x.json"), "--joint-tolerance", "1cm"});
  ProcessResult paper = Tempokey({"reduce", BandaiClip(), "-o", Path("x.json"), "--method",
                                  "paper", "--joint-tolerance", "1"});
  ProcessResult negative =
      Tempokey({"reduce", BandaiClip(), "-o", Path("x.json"), "--joint-tolerance", "-1%"});
  ASSERT_TRUE(core::WriteFileAtomically(Path("plain.csv"), "weight\n1\n2\n4\n").ok());
  ProcessResult no_skeleton = Tempokey({"reduce", Path("plain.csv"), "--input-fps", "30", "-o",
                                        Path("x.json"), "--joint-tolerance", "1"});

  EXPECT_EQ(syntax.exit_code, 2);
  EXPECT_EQ(syntax.err,
            "error: --joint-tolerance: expected a distance in file units or a percentage of the "
            "figure's height (1, 0.5%), got '1cm'\n");
  EXPECT_EQ(paper.exit_code, 2);
  EXPECT_EQ(paper.err, "error: --joint-tolerance does not apply to --method paper\n");
  EXPECT_EQ(negative.exit_code, 1);
  EXPECT_EQ(negative.err,
            "error: operation 1 (reduce): tolerance.joint_tolerance must be finite and > 0, got "
            "-1%\n");
  EXPECT_EQ(no_skeleton.exit_code, 1);
  EXPECT_EQ(no_skeleton.err,
            "error: operation 1 (reduce): tolerance.joint_tolerance needs a skeleton, the clip "
            "has none\n");
  EXPECT_FALSE(fs::exists(Path("x.json")));
}

TEST_F(CliWorldErrorTest, BatchPipelineFileTakesTheJointToleranceAndSummarizesTheJointError) {
  const std::string in = Path("in");
  fs::create_directories(in);
  fs::copy_file(BandaiClip(), in + "/kick.bvh");
  ASSERT_TRUE(core::WriteFileAtomically(
                  Path("ops.json"), R"({"operations": [{"reduce": {"joint_tolerance": "0.5%"}}]})")
                  .ok());

  ProcessResult run = Tempokey({"batch", in, "-o", Path("out"), "--ops", Path("ops.json")});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  absl::StatusOr<core::JsonValue> summary = core::ParseJson(run.out, "summary");
  ASSERT_TRUE(summary.ok()) << summary.status() << "\n" << run.out;
  const core::JsonValue& entry = summary->Find("results")->array->front();
  ASSERT_NE(entry.Find("max_joint_error"), nullptr) << run.out;
  const double bound = 0.005 * *core::FigureHeight(ReadSource(BandaiClip()));
  const core::WorldErrorReport measured = Measure(BandaiClip(), Path("out/kick.json"));
  EXPECT_EQ(entry.Find("max_joint_error")->number, measured.max_error);
  EXPECT_LE(measured.max_error, bound);
}

}  // namespace
}  // namespace tempokey::testing
