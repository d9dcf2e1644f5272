// Batch pipeline files: the same options as the command line, every mistake pointed at.
#include "client/pipeline_file.h"

#include <string>
#include <variant>

#include "client/cli_errors.h"
#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

TEST(PipelineFileTest, OperationsTakeTheCommandsOptions) {
  absl::StatusOr<std::vector<core::PipelineStep>> steps = ParsePipelineJson(R"({"operations": [
    {"retime": {"speed": "0s:1,2s:0.5,4s:1", "fps": 29.97, "fit_frames": 100,
                "hold": ["1s:0.5", "3s:0.25"], "reverse": true, "no-fit-to-grid": false}},
    {"reduce": {"tolerance": 0.25, "position-tolerance": 1, "pose_align": "joint"}},
    {"bake": {"fps": "30000/1001"}},
    {"convert": {"wrap-rotations": true}}
  ]})",
                                                                            "ops.json");
  ASSERT_TRUE(steps.ok()) << steps.status();
  ASSERT_EQ(steps->size(), 4u);

  const auto& retime = std::get<core::RetimeStep>((*steps)[0]);
  ASSERT_EQ(retime.warp.speed.size(), 3u);
  EXPECT_EQ(retime.warp.speed[1].time.value, 2.0);
  EXPECT_EQ(retime.warp.speed[1].speed, 0.5);
  ASSERT_TRUE(retime.options.output_rate.has_value());
  EXPECT_EQ(retime.options.output_rate->numerator, 30000);  // 29.97 as every video tool means it
  EXPECT_EQ(retime.options.output_rate->denominator, 1001);
  EXPECT_EQ(retime.options.fit_frames, 100);
  ASSERT_EQ(retime.warp.holds.size(), 2u);
  EXPECT_EQ(retime.warp.holds[1].duration_seconds, 0.25);
  EXPECT_TRUE(retime.warp.reverse);
  EXPECT_TRUE(retime.options.fit_to_grid);  // a false switch is as if not given

  const auto& reduce = std::get<core::ReduceStep>((*steps)[1]);
  EXPECT_EQ(reduce.options.method, core::ReduceMethod::kTolerance);
  EXPECT_EQ(reduce.options.tolerance.max_rotation_error_degrees, 0.25);
  EXPECT_EQ(reduce.options.tolerance.max_position_error, 1.0);
  EXPECT_EQ(reduce.options.tolerance.pose_alignment, core::PoseAlignment::kJoint);

  const auto& bake = std::get<core::BakeStep>((*steps)[2]);
  ASSERT_TRUE(bake.rate.has_value());
  EXPECT_EQ(bake.rate->numerator, 30000);
  EXPECT_TRUE(std::get<core::ConvertStep>((*steps)[3]).wrap_rotations);
}

TEST(PipelineFileTest, PaperMethodTakesItsOwnParameters) {
  absl::StatusOr<std::vector<core::PipelineStep>> steps = ParsePipelineJson(
      R"({"operations": [{"reduce": {"method": "paper", "iterations": 3, "step-y": 0.25}}]})",
      "ops.json");
  ASSERT_TRUE(steps.ok()) << steps.status();
  const auto& reduce = std::get<core::ReduceStep>((*steps)[0]);
  EXPECT_EQ(reduce.options.method, core::ReduceMethod::kPaper);
  EXPECT_EQ(reduce.options.paper.max_iterations, 3);
  EXPECT_EQ(reduce.options.paper.step_y, 0.25);
}

struct BadPipeline {
  const char* name;
  const char* text;
  const char* message;
};

class PipelineFileErrorTest : public ::testing::TestWithParam<BadPipeline> {};

TEST_P(PipelineFileErrorTest, IsAUsageErrorPointingAtTheMistake) {
  absl::StatusOr<std::vector<core::PipelineStep>> steps =
      ParsePipelineJson(GetParam().text, "ops.json");
  ASSERT_FALSE(steps.ok());
  EXPECT_TRUE(IsUsageError(steps.status()));
  EXPECT_EQ(std::string(steps.status().message()), GetParam().message);
}

INSTANTIATE_TEST_SUITE_P(
    Cases, PipelineFileErrorTest,
    ::testing::Values(
        BadPipeline{"Syntax", "{\"operations\": [\n  {\"retime\": {}},\n]}",
                    "ops.json:3:1: expected a value, got \"]\""},
        BadPipeline{"NotAnObject", "[1]", "ops.json:1:1: expected an object {\"operations\": [...]}"},
        BadPipeline{"MissingOperations", "{}", "ops.json:1:1: missing \"operations\""},
        BadPipeline{"UnknownRootMember", "{\"operations\": [], \"ops\": 1}",
                    "ops.json:1:27: unknown member 'ops' (expected \"operations\")"},
        BadPipeline{"OperationsNotAnArray", "{\"operations\": {}}",
                    "ops.json:1:16: \"operations\" must be an array"},
        BadPipeline{"Empty", "{\"operations\": []}",
                    "ops.json:1:16: the pipeline has no operations"},
        BadPipeline{"UnknownOperation", "{\"operations\": [{\"reduse\": {}}]}",
                    "ops.json:1:17: operation 1: expected one of retime, reduce, bake, convert, "
                    "got 'reduse'"},
        BadPipeline{"TwoOperationsInOneObject",
                    "{\"operations\": [{\"retime\": {}, \"reduce\": {}}]}",
                    "ops.json:1:17: operation 1: expected an object with one member, such as "
                    "{\"retime\": {...}}"},
        BadPipeline{"OptionsNotAnObject", "{\"operations\": [{\"retime\": \"0s:1\"}]}",
                    "ops.json:1:28: operation 1 (retime): expected an object of options"},
        BadPipeline{"UnknownOption",
                    "{\"operations\": [\n  {\"reduce\": {\"tolerence\": 0.5}}]}",
                    "ops.json:2:28: operation 1 (reduce): no option 'tolerence' (options: "
                    "method, tolerance, position-tolerance, scalar-tolerance, key-budget, "
                    "pose-align, joint-tolerance, fewest-keys, step-x, step-y, step-tangent-x, "
                    "step-tangent-y, accuracy, iterations, smoothing-sigma, min-key-spacing, "
                    "noise, position-noise, euler-filter)"},
        BadPipeline{"BadValueIsPointedAt",
                    "{\"operations\": [{\"retime\": {\"speed\": \"0s:1\", \"fps\": \"fast\"}}]}",
                    "ops.json:1:53: operation 1 (retime): --fps: expected a frame rate such as "
                    "30, 29.97 or 30000/1001, got 'fast'"},
        BadPipeline{"BadSpeedSyntax", "{\"operations\": [{\"retime\": {\"speed\": \"2x:1\"}}]}",
                    "ops.json:1:38: operation 1 (retime): --speed: speed knot 1 '2x:1': time "
                    "needs a unit, s or f"},
        BadPipeline{"SwitchWithAValue",
                    "{\"operations\": [{\"retime\": {\"reverse\": \"yes\"}}]}",
                    "ops.json:1:40: operation 1 (retime): reverse: expected true or false"},
        BadPipeline{"ListForASingleValue",
                    "{\"operations\": [{\"retime\": {\"fps\": [30, 24]}}]}",
                    "ops.json:1:36: operation 1 (retime): fps: takes one value, not a list"},
        BadPipeline{"ObjectValue",
                    "{\"operations\": [{\"reduce\": {\"tolerance\": {\"deg\": 1}}}]}",
                    "ops.json:1:42: operation 1 (reduce): tolerance: expected a string or a "
                    "number"},
        BadPipeline{"SameOptionTwoSpellings",
                    "{\"operations\": [{\"retime\": {\"fit_frames\": 10, \"fit-frames\": 20}}]}",
                    "ops.json:1:28: operation 1 (retime): --fit-frames given twice"},
        BadPipeline{"OptionOfTheOtherMethod",
                    "{\"operations\": [{\"reduce\": {\"method\": \"paper\", \"tolerance\": 1}}]}",
                    "ops.json:1:61: operation 1 (reduce): --tolerance does not apply to "
                    "--method paper"},
        BadPipeline{"BakeOfSamples", "{\"operations\": [{\"retime\": {}}, {\"bake\": {}}]}",
                    "ops.json:1:16: operation 2 (bake): needs a keyed clip, got a sampled clip"}),
    [](const ::testing::TestParamInfo<BadPipeline>& test) { return test.param.name; });

TEST(PipelineFileTest, MissingFileIsAUsageErrorNamingIt) {
  absl::StatusOr<std::vector<core::PipelineStep>> steps =
      ReadPipelineFile("/nonexistent/ops.json");
  ASSERT_FALSE(steps.ok());
  EXPECT_TRUE(IsUsageError(steps.status()));
  EXPECT_EQ(std::string(steps.status().message()), "/nonexistent/ops.json: no such file");
}

}  // namespace
}  // namespace tempokey::client
