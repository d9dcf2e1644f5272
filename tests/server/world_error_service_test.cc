// Joint world-position error through a real server (SPEC 4.4): a reduction's report carries it,
// a joint tolerance in file units or in percent of the figure's height travels as its own field
// and holds at every frame of a real capture (measured here on the curves the server sent back),
// and a joint tolerance on a clip without a skeleton is refused before anything is queued.
#include <memory>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "proto/operations_convert.h"
#include "server/job_manager.h"
#include "server/server.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/reduce/world_error.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

class WorldErrorServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = StartServer(TestServerOptions());
    ASSERT_NE(server_, nullptr);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }

  // Runs one reduce with `tolerance` on `clip` as a stored job; the finished job and its curves.
  std::pair<v1::Job, core::KeyedClip> Reduce(const core::Clip& clip,
                                            const v1::ToleranceParams& tolerance) {
    v1::SubmitJobRequest request;
    *request.mutable_inline_clip() = wire::ClipToProto(clip);
    v1::ReduceOperation* reduce = request.add_operations()->mutable_reduce();
    reduce->set_method(v1::REDUCE_METHOD_TOLERANCE);
    *reduce->mutable_tolerance() = tolerance;
    const JobOutcome submitted = Submit(*stub_, request);
    EXPECT_TRUE(submitted.status.ok()) << submitted.status.error_message();
    const v1::Job done = WaitForJob(*stub_, submitted.job.job_id());
    const ResultOutcome result = GetResult(*stub_, submitted.job.job_id());
    EXPECT_TRUE(result.status.ok()) << result.status.error_message();
    absl::StatusOr<core::KeyedClip> keyed = AssembleKeyedResult(result.parts);
    EXPECT_TRUE(keyed.ok()) << keyed.status();
    return {done, keyed.ok() ? *std::move(keyed) : core::KeyedClip()};
  }

  std::unique_ptr<server::Server> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

core::Clip ReadShared(const std::string& relative) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(SharedBvh(relative));
  EXPECT_TRUE(clip.ok()) << clip.status();
  return clip.ok() ? *std::move(clip) : core::Clip();
}

TEST_F(WorldErrorServiceTest, JointToleranceInFileUnitsHoldsAndIsReported) {
  const core::Clip clip = ReadShared("bandai/dataset-1_walk_active_001.bvh");
  v1::ToleranceParams tolerance;
  tolerance.set_max_joint_error(1.0);

  const auto [job, keyed] = Reduce(clip, tolerance);

  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
  const absl::StatusOr<core::WorldErrorReport> measured = core::MeasureWorldError(clip, keyed);
  ASSERT_TRUE(measured.ok()) << measured.status();
  EXPECT_LE(measured->max_error, 1.0);
  ASSERT_TRUE(job.reports(0).reduction().has_world_error());
  const v1::WorldErrorReport& world = job.reports(0).reduction().world_error();
  EXPECT_DOUBLE_EQ(world.max_error_units(), measured->max_error);
  EXPECT_DOUBLE_EQ(world.rms_error_units(), measured->rms_error);
  EXPECT_EQ(world.worst_point(), measured->worst_point_name);
  EXPECT_EQ(world.worst_frame(), measured->worst_frame);
  EXPECT_EQ(world.joint_tolerance_units(), 1.0);
  EXPECT_DOUBLE_EQ(world.figure_height_units(), *core::FigureHeight(clip));
}

TEST_F(WorldErrorServiceTest, JointToleranceInPercentIsOfTheFigureHeight) {
  const core::Clip clip = ReadShared("cmu/131_01.bvh");
  v1::ToleranceParams tolerance;
  tolerance.set_max_joint_error_percent_of_height(0.5);

  const auto [job, keyed] = Reduce(clip, tolerance);

  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
  const double bound = 0.005 * *core::FigureHeight(clip);
  const v1::WorldErrorReport& world = job.reports(0).reduction().world_error();
  EXPECT_DOUBLE_EQ(world.joint_tolerance_units(), bound);
  const absl::StatusOr<core::WorldErrorReport> measured = core::MeasureWorldError(clip, keyed);
  ASSERT_TRUE(measured.ok()) << measured.status();
  EXPECT_LE(measured->max_error, bound);
}

TEST_F(WorldErrorServiceTest, DefaultReductionReportsTheWorldErrorWithoutABound) {
  const core::Clip clip = ReadShared("bandai/dataset-1_walk_active_001.bvh");

  const auto [job, keyed] = Reduce(clip, v1::ToleranceParams());

  ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error_message();
  const v1::WorldErrorReport& world = job.reports(0).reduction().world_error();
  EXPECT_GT(world.max_error_units(), 1.0);  // 0.5 degrees per channel moves a toe further
  EXPECT_EQ(world.joint_tolerance_units(), 0.0);
}

TEST_F(WorldErrorServiceTest, JointToleranceWithoutASkeletonIsRefusedBeforeQueueing) {
  core::Clip plain;
  plain.name = "plain";
  plain.frame_count = 3;
  plain.channels.push_back({.name = "weight", .samples = {1.0, 2.0, 4.0}});
  v1::SubmitJobRequest request;
  *request.mutable_inline_clip() = wire::ClipToProto(plain);
  v1::ReduceOperation* reduce = request.add_operations()->mutable_reduce();
  reduce->mutable_tolerance()->set_max_joint_error(1.0);

  const JobOutcome outcome = Submit(*stub_, request);

  EXPECT_THAT(outcome.status,
              GrpcStatusIs(grpc::StatusCode::FAILED_PRECONDITION,
                           "operation 1 (reduce): tolerance.joint_tolerance needs a skeleton, the "
                           "clip has none"));
  EXPECT_EQ(server_->jobs().job_count(), 0);
}

TEST_F(WorldErrorServiceTest, InvalidJointToleranceIsRefusedNamingTheField) {
  const core::Clip clip = ReadShared("bandai/dataset-1_walk_active_001.bvh");
  v1::SubmitJobRequest request;
  *request.mutable_inline_clip() = wire::ClipToProto(clip);
  request.add_operations()->mutable_reduce()->mutable_tolerance()
      ->set_max_joint_error_percent_of_height(-2);

  const JobOutcome outcome = Submit(*stub_, request);

  EXPECT_THAT(outcome.status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           "operation 1 (reduce): tolerance.joint_tolerance must be finite and > "
                           "0, got -2%"));
}

}  // namespace
}  // namespace tempokey::testing
