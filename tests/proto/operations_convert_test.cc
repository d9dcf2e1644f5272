// Operation conversions (proto/operations_convert.h): defaults, the encoding's own mistakes named
// by field, and exact round trips of every step and report.
#include "proto/operations_convert.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/server_test_util.h"

namespace tempokey::wire {
namespace {

using ::tempokey::testing::MakeClip;
using ::tempokey::testing::StatusIs;
using ::testing::HasSubstr;


TEST(OperationConvertTest, UnsetOptionalFieldsTakeCoreDefaults) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  ops.Add()->mutable_reduce()->set_method(v1::REDUCE_METHOD_PAPER);

  absl::StatusOr<std::vector<core::PipelineStep>> steps = PipelineFromProto(ops);

  ASSERT_TRUE(steps.ok()) << steps.status();
  const auto& reduce = std::get<core::ReduceStep>((*steps)[0]);
  const core::PaperParams defaults;
  EXPECT_EQ(reduce.options.method, core::ReduceMethod::kPaper);
  EXPECT_EQ(reduce.options.paper.step_y, defaults.step_y);
  EXPECT_EQ(reduce.options.paper.max_iterations, defaults.max_iterations);
  EXPECT_EQ(reduce.options.tolerance.max_rotation_error_degrees,
            core::ToleranceParams().max_rotation_error_degrees);
}

TEST(OperationConvertTest, SetOptionalFieldsAreUsed) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  v1::ReduceOperation* reduce = ops.Add()->mutable_reduce();
  reduce->mutable_paper()->set_step_y(0.125);
  reduce->mutable_paper()->set_max_iterations(3);
  reduce->mutable_tolerance()->set_max_rotation_error_degrees(0.2);
  reduce->mutable_tolerance()->set_key_budget(40);
  reduce->mutable_tolerance()->set_pose_alignment(v1::POSE_ALIGNMENT_JOINT);
  reduce->mutable_tolerance()->set_fewest_keys(true);

  absl::StatusOr<std::vector<core::PipelineStep>> steps = PipelineFromProto(ops);

  ASSERT_TRUE(steps.ok()) << steps.status();
  const auto& step = std::get<core::ReduceStep>((*steps)[0]);
  EXPECT_EQ(step.options.method, core::ReduceMethod::kTolerance);
  EXPECT_EQ(step.options.paper.step_y, 0.125);
  EXPECT_EQ(step.options.paper.max_iterations, 3);
  EXPECT_EQ(step.options.tolerance.max_rotation_error_degrees, 0.2);
  EXPECT_EQ(step.options.tolerance.key_budget, 40);
  EXPECT_EQ(step.options.tolerance.pose_alignment, core::PoseAlignment::kJoint);
  EXPECT_TRUE(step.options.tolerance.fewest_keys);
}

struct BadOperationCase {
  const char* name;
  std::function<void(google::protobuf::RepeatedPtrField<v1::Operation>&)> build;
  const char* message;
};

class BadOperationTest : public ::testing::TestWithParam<BadOperationCase> {};

TEST_P(BadOperationTest, IsRefusedWithAMessageNamingTheField) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  ops.Add()->mutable_convert();
  GetParam().build(ops);

  EXPECT_THAT(PipelineFromProto(ops),
              StatusIs(absl::StatusCode::kInvalidArgument, GetParam().message));
}

INSTANTIATE_TEST_SUITE_P(
    Table, BadOperationTest,
    ::testing::Values(
        BadOperationCase{"UnknownReduceMethod",
                         [](auto& ops) {
                           ops.Add()->mutable_reduce()->set_method(static_cast<v1::ReduceMethod>(9));
                         },
                         "operation 2: reduce.method has unknown value 9"},
        BadOperationCase{"EmptyOperation", [](auto& ops) { ops.Add(); },
                         "operation 2: no operation set (one of retime, reduce, bake, convert)"},
        BadOperationCase{"TwoWarpDomains",
                         [](auto& ops) {
                           v1::RetimeOperation* r = ops.Add()->mutable_retime();
                           r->add_speed_over_source()->mutable_time()->set_seconds(0);
                           r->add_time_map()->mutable_output()->set_seconds(0);
                         },
                         "operation 2: retime takes at most one of speed_over_source, "
                         "speed_over_output and time_map, got speed_over_source and time_map"},
        BadOperationCase{"KnotWithoutUnit",
                         [](auto& ops) {
                           ops.Add()->mutable_retime()->add_speed_over_output()->set_speed(1.0);
                         },
                         "operation 2: retime.speed_over_output[0].time has no unit: set seconds "
                         "or frames"},
        BadOperationCase{"UnknownFilter",
                         [](auto& ops) {
                           ops.Add()->mutable_retime()->set_filter(static_cast<v1::ResampleFilter>(42));
                         },
                         "operation 2: retime.filter has unknown value 42"}),
    [](const ::testing::TestParamInfo<BadOperationCase>& p) { return p.param.name; });

// Values are core's to check (one set of limits and messages): the conversion hands them over
// untouched, and core::ValidatePipeline() refuses them naming the field.
TEST(OperationConvertTest, ValuesPassThroughForCoreToCheck) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  v1::ReduceOperation* reduce = ops.Add()->mutable_reduce();
  reduce->set_method(v1::REDUCE_METHOD_PAPER);
  reduce->mutable_paper()->set_step_y(-1);
  reduce->mutable_paper()->set_max_iterations(0);
  v1::RetimeOperation* retime = ops.Add()->mutable_retime();
  retime->set_output_rate_numerator(30);
  retime->set_fit_frames(0);
  v1::SpeedKnot* knot = retime->add_speed_over_source();
  knot->mutable_time()->set_frames(std::numeric_limits<double>::infinity());
  knot->set_speed(std::nan(""));
  core::Clip clip = MakeClip(1, 40);

  absl::StatusOr<std::vector<core::PipelineStep>> steps = PipelineFromProto(ops);

  ASSERT_TRUE(steps.ok()) << steps.status();
  const auto& paper = std::get<core::ReduceStep>((*steps)[0]).options.paper;
  EXPECT_EQ(paper.step_y, -1);
  EXPECT_EQ(paper.max_iterations, 0);
  const auto& r = std::get<core::RetimeStep>((*steps)[1]);
  ASSERT_TRUE(r.options.output_rate.has_value());
  EXPECT_EQ(r.options.output_rate->numerator, 30);
  EXPECT_EQ(r.options.output_rate->denominator, 0);
  EXPECT_EQ(r.options.fit_frames, 0);
  EXPECT_TRUE(std::isinf(r.warp.speed[0].time.value));
  EXPECT_TRUE(std::isnan(r.warp.speed[0].speed));
  EXPECT_THAT(core::ValidatePipeline(clip, *steps),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "operation 1 (reduce): paper.step_y must be > 0, got -1"));
}

TEST(OperationConvertTest, EveryStepRoundTripsThroughProto) {
  core::RetimeStep retime;
  retime.warp.domain = core::WarpDomain::kSpeedOverSource;
  retime.warp.speed = {core::SpeedKnot{.time = {.value = 0, .in_frames = false}, .speed = 1},
                       core::SpeedKnot{.time = {.value = 48, .in_frames = true}, .speed = 0.5}};
  retime.warp.holds = {core::Hold{.at = {.value = 0.5, .in_frames = false}, .duration_seconds = 0.25}};
  retime.warp.reverse = true;
  retime.options.fit_frames = 120;
  retime.options.fit_to_grid = false;
  retime.options.output_rate = core::FrameRate{.numerator = 30000, .denominator = 1001};
  retime.options.filter = core::ResampleFilter::kLanczos3;
  retime.options.method = core::RetimeMethod::kPaper;
  retime.options.rotation_mode = core::RotationMode::kEuler;
  retime.options.pins = {core::Pin{.source = {.value = 10, .in_frames = true}, .output_frame = 20}};
  retime.options.min_speed = 0.1;
  retime.options.max_speed = 10;
  core::ReduceStep reduce;
  reduce.options.tolerance.key_budget = 12;
  reduce.options.tolerance.max_scalar_error = 0.01;
  reduce.options.tolerance.fewest_keys = true;
  core::ReduceStep paper;
  paper.options.method = core::ReduceMethod::kPaper;
  paper.options.paper.accuracy = 0.001;
  retime.euler_filter = true;
  core::ReduceStep noise;
  noise.options.method = core::ReduceMethod::kNoise;
  noise.options.noise.position_sigma = 0.25;
  noise.options.noise.key_sigmas = 0.3;
  noise.options.euler_filter = false;
  const std::vector<core::PipelineStep> steps = {
      retime, reduce, paper, core::BakeStep{.rate = core::FrameRate{.numerator = 24, .denominator = 1}},
      core::BakeStep{}, core::ConvertStep{.wrap_rotations = true, .euler_filter = true}, noise};
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  for (const core::PipelineStep& step : steps) *ops.Add() = PipelineStepToProto(step);

  absl::StatusOr<std::vector<core::PipelineStep>> back = PipelineFromProto(ops);

  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->size(), steps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    EXPECT_EQ(PipelineStepToProto((*back)[i]).SerializeAsString(), ops[static_cast<int>(i)].SerializeAsString())
        << "step " << i;
  }
  const auto& r = std::get<core::RetimeStep>((*back)[0]);
  EXPECT_EQ(r.warp.domain, core::WarpDomain::kSpeedOverSource);
  EXPECT_TRUE(r.warp.speed[1].time.in_frames);
  EXPECT_EQ(r.options.output_rate->numerator, 30000);
  EXPECT_EQ(r.options.pins[0].output_frame, 20);
  EXPECT_EQ(std::get<core::ReduceStep>((*back)[1]).options.tolerance.key_budget, 12);
  EXPECT_TRUE(std::get<core::ReduceStep>((*back)[1]).options.tolerance.fewest_keys);
  EXPECT_FALSE(std::get<core::ReduceStep>((*back)[2]).options.tolerance.fewest_keys);
  EXPECT_EQ(std::get<core::ReduceStep>((*back)[2]).options.paper.accuracy, 0.001);
  EXPECT_FALSE(std::get<core::BakeStep>((*back)[4]).rate.has_value());
  EXPECT_TRUE(std::get<core::ConvertStep>((*back)[5]).wrap_rotations);
  EXPECT_TRUE(std::get<core::ConvertStep>((*back)[5]).euler_filter);
  EXPECT_TRUE(r.euler_filter);
  EXPECT_FALSE(std::get<core::ReduceStep>((*back)[1]).options.euler_filter.has_value());
  const core::ReduceOptions& n = std::get<core::ReduceStep>((*back)[6]).options;
  EXPECT_EQ(n.method, core::ReduceMethod::kNoise);
  EXPECT_FALSE(n.noise.rotation_sigma_degrees.has_value());
  EXPECT_EQ(n.noise.position_sigma, 0.25);
  EXPECT_EQ(n.noise.key_sigmas, 0.3);
  EXPECT_EQ(n.euler_filter, false);
}

TEST(ReportConvertTest, ReportsRoundTrip) {
  core::ReductionReport reduction;
  reduction.channels.push_back(core::ChannelReduction{.channel_index = 3,
                                                      .key_count = 7,
                                                      .sample_count = 100,
                                                      .rms_error = 0.1,
                                                      .max_error = 0.4,
                                                      .max_error_frame = 55,
                                                      .noise_sigma = 0.45,
                                                      .noise_sigma_estimated = true});
  reduction.euler_filtered_frames = 12;
  reduction.key_count = 7;
  reduction.sample_count = 100;
  reduction.worst_channel_index = 3;
  reduction.worst_frame = 55;
  reduction.iterations = 4;
  const core::RetimeReport retime{.output_duration_seconds = 2.5,
                                  .output_frame_count = 76,
                                  .fit_factor = 1.001,
                                  .max_decimation_ratio = 2.0,
                                  .filtered_sample_count = 30};

  const core::StepReport a = StepReportFromProto(StepReportToProto(reduction));
  const core::StepReport b = StepReportFromProto(StepReportToProto(retime));

  const auto& ra = std::get<core::ReductionReport>(a);
  EXPECT_EQ(ra.channels[0].max_error_frame, 55);
  EXPECT_EQ(ra.iterations, 4);
  EXPECT_EQ(ra.worst_channel_index, 3);
  EXPECT_EQ(ra.channels[0].noise_sigma, 0.45);
  EXPECT_TRUE(ra.channels[0].noise_sigma_estimated);
  EXPECT_EQ(ra.euler_filtered_frames, 12);
  const auto& rb = std::get<core::RetimeReport>(b);
  EXPECT_EQ(rb.output_frame_count, 76);
  EXPECT_EQ(rb.fit_factor, 1.001);
}

}  // namespace
}  // namespace tempokey::wire
