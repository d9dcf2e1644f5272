// The world-space bound and the world error report on the wire (operations.proto): a joint
// tolerance travels as file units or as a percentage, unset per-channel bounds stay unset (the
// server resolves the scale-aware defaults against the clip), and the report round-trips exactly.
#include <variant>
#include <vector>

#include "gtest/gtest.h"
#include "proto/operations_convert.h"

#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::wire {
namespace {

core::ReduceStep ReduceWith(std::optional<core::JointTolerance> joint) {
  core::ReduceStep step;
  step.options.tolerance.joint_tolerance = joint;
  return step;
}

core::ReduceStep RoundTrip(const core::ReduceStep& step) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  *ops.Add() = PipelineStepToProto(step);
  absl::StatusOr<std::vector<core::PipelineStep>> back = PipelineFromProto(ops);
  EXPECT_TRUE(back.ok()) << back.status();
  return std::get<core::ReduceStep>(back->front());
}

TEST(WorldErrorConvertTest, JointToleranceTravelsInFileUnitsOrPercent) {
  const core::ReduceStep units = ReduceWith(core::JointTolerance{.value = 1.0});
  const core::ReduceStep percent =
      ReduceWith(core::JointTolerance{.value = 0.5, .percent_of_height = true});

  const v1::Operation units_wire = PipelineStepToProto(units);
  const v1::Operation percent_wire = PipelineStepToProto(percent);

  EXPECT_EQ(units_wire.reduce().tolerance().max_joint_error(), 1.0);
  EXPECT_EQ(percent_wire.reduce().tolerance().max_joint_error_percent_of_height(), 0.5);
  EXPECT_EQ(RoundTrip(units).options.tolerance.joint_tolerance, units.options.tolerance.joint_tolerance);
  EXPECT_EQ(RoundTrip(percent).options.tolerance.joint_tolerance,
            percent.options.tolerance.joint_tolerance);
  EXPECT_FALSE(RoundTrip(ReduceWith(std::nullopt)).options.tolerance.joint_tolerance.has_value());
}

TEST(WorldErrorConvertTest, UnsetBoundsStayUnsetOnTheWire) {
  core::ReduceStep step;
  step.options.tolerance.max_rotation_error_degrees = 0.25;

  const v1::Operation wire = PipelineStepToProto(step);

  EXPECT_TRUE(wire.reduce().tolerance().has_max_rotation_error_degrees());
  EXPECT_FALSE(wire.reduce().tolerance().has_max_position_error());
  const core::ReduceStep back = RoundTrip(step);
  EXPECT_EQ(back.options.tolerance.max_rotation_error_degrees, 0.25);
  EXPECT_FALSE(back.options.tolerance.max_position_error.has_value());
}

TEST(WorldErrorConvertTest, ReductionReportCarriesTheWorldErrorExactly) {
  core::ReductionReport report;
  report.key_count = 12;
  report.world = core::WorldErrorReport{
      .figure_height = 139.25,
      .max_error = 0.9850123456789,
      .worst_point = {.joint = 7, .end_site = 0},
      .worst_point_name = "Toes_R end site",
      .worst_frame = 94,
      .rms_error = 0.246,
      .joint_tolerance = 1.0};
  core::ReductionReport without = report;
  without.world.reset();

  const core::StepReport back = StepReportFromProto(StepReportToProto(report));
  const core::StepReport back_without = StepReportFromProto(StepReportToProto(without));

  EXPECT_EQ(std::get<core::ReductionReport>(back).world, report.world);
  EXPECT_FALSE(std::get<core::ReductionReport>(back_without).world.has_value());
  EXPECT_FALSE(StepReportToProto(without).reduction().has_world_error());
}

}  // namespace
}  // namespace tempokey::wire
