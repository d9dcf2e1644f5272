// The paper's reduction through a real server: every malformed parameter of the core table
// (tests/core/reduce/reduce_invalid_cases.h) and every malformed clip is refused with INVALID_ARGUMENT
// and a precise message before anything is queued, the server keeps serving, and a constant
// channel comes back as two flat keys.
#include <cmath>
#include <limits>
#include <memory>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "proto/operations_convert.h"
#include "server/job_manager.h"
#include "server/server.h"
#include "tests/core/reduce/reduce_invalid_cases.h"
#include "tests/server/server_test_util.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

v1::Operation PaperReduce(const core::PaperParams& params) {
  core::ReduceStep step;
  step.options.method = core::ReduceMethod::kPaper;
  step.options.paper = params;
  return wire::PipelineStepToProto(step);
}

class ReduceServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = StartServer(TestServerOptions());
    ASSERT_NE(server_, nullptr);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }

  JobOutcome SubmitInline(const v1::Clip& clip, const v1::Operation& operation) {
    v1::SubmitJobRequest request;
    *request.mutable_inline_clip() = clip;
    *request.add_operations() = operation;
    return Submit(*stub_, request);
  }

  void ExpectServingAndNothingQueued() {
    EXPECT_EQ(server_->jobs().job_count(), 0);
    const absl::StatusOr<int> health = CheckHealth(Connect(server_->target()), "");
    ASSERT_TRUE(health.ok()) << health.status();
    EXPECT_EQ(*health, 1);  // SERVING
  }

  std::unique_ptr<server::Server> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(ReduceServiceTest, EveryMalformedPaperParameterIsRefusedWithItsCoreMessage) {
  const v1::Clip clip = wire::ClipToProto(MakeClip(1, 60));
  int refused = 0;

  for (const core::reduce_cases::BadPaperParams& bad : core::reduce_cases::BadPaperParamsTable()) {
    core::PaperParams params;
    bad.mutate(params);

    const JobOutcome outcome = SubmitInline(clip, PaperReduce(params));

    EXPECT_THAT(outcome.status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                                             std::string("operation 1 (reduce): ") + bad.message));
    refused += outcome.status.error_code() == grpc::StatusCode::INVALID_ARGUMENT;
  }

  EXPECT_GE(refused, 10);
  ExpectServingAndNothingQueued();
}

TEST_F(ReduceServiceTest, MalformedToleranceParametersAreRefusedNamingTheField) {
  const v1::Clip clip = wire::ClipToProto(MakeClip(1, 60));
  struct Case {
    void (*set)(v1::ToleranceParams&);
    const char* message;
  } cases[] = {
      {[](v1::ToleranceParams& t) { t.set_max_rotation_error_degrees(0); },
       "operation 1 (reduce): tolerance.max_rotation_error_degrees must be > 0, got 0"},
      {[](v1::ToleranceParams& t) { t.set_max_position_error(std::nan("")); },
       "operation 1 (reduce): tolerance.max_position_error must be > 0, got NaN"},
      {[](v1::ToleranceParams& t) { t.set_max_scalar_error(-2); },
       "operation 1 (reduce): tolerance.max_scalar_error must be > 0, got -2"},
      {[](v1::ToleranceParams& t) { t.set_key_budget(1); },
       "operation 1 (reduce): tolerance.key_budget must be >= 2 when set, got 1"},
      {[](v1::ToleranceParams& t) { t.set_pose_alignment(static_cast<v1::PoseAlignment>(7)); },
       "operation 1: reduce.tolerance.pose_alignment has unknown value 7"},
  };

  for (const Case& c : cases) {
    v1::Operation operation;
    operation.mutable_reduce()->set_method(v1::REDUCE_METHOD_TOLERANCE);
    c.set(*operation.mutable_reduce()->mutable_tolerance());

    EXPECT_THAT(SubmitInline(clip, operation).status,
                GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, c.message));
  }
  ExpectServingAndNothingQueued();
}

TEST_F(ReduceServiceTest, ToleranceJobKeepsEveryChannelWithinItsBound) {
  const core::Clip clip = MakeClip(3, 400);
  v1::Operation operation;
  operation.mutable_reduce()->set_method(v1::REDUCE_METHOD_TOLERANCE);
  operation.mutable_reduce()->mutable_tolerance()->set_max_rotation_error_degrees(0.25);
  operation.mutable_reduce()->mutable_tolerance()->set_max_position_error(0.1);

  const JobOutcome submitted = SubmitInline(wire::ClipToProto(clip), operation);
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  const v1::Job done = WaitForJob(*stub_, submitted.job.job_id());
  const ResultOutcome result = GetResult(*stub_, submitted.job.job_id());
  TEMPOKEY_ASSERT_GRPC_OK(result.status);
  const absl::StatusOr<core::KeyedClip> keyed = AssembleKeyedResult(result.parts);
  ASSERT_TRUE(keyed.ok()) << keyed.status();
  const absl::StatusOr<core::ReductionReport> measured = core::MeasureReduction(clip, *keyed);

  ASSERT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED) << done.error_message();
  ASSERT_TRUE(measured.ok()) << measured.status();
  for (const core::ChannelReduction& channel : measured->channels) {
    const double bound = core::IsRotation(clip.channels[channel.channel_index].kind) ? 0.25 : 0.1;
    EXPECT_LE(channel.max_error, bound) << channel.channel_index;
  }
  EXPECT_EQ(done.reports(0).reduction().key_count(), measured->key_count);
  EXPECT_LT(measured->key_count, clip.sample_count() / 5);
}

TEST_F(ReduceServiceTest, MalformedClipsAreRefusedNamingTheProblem) {
  const v1::Operation reduce = PaperReduce({});
  v1::Clip nan_clip = wire::ClipToProto(MakeClip(1, 60));
  nan_clip.mutable_samples(0)->mutable_samples()->Set(7, std::numeric_limits<double>::quiet_NaN());
  v1::Clip no_frames = wire::ClipToProto(MakeClip(1, 60));
  no_frames.mutable_header()->set_frame_count(0);
  no_frames.clear_samples();
  v1::Clip no_channels;
  *no_channels.mutable_header() = wire::ClipHeaderToProto(MakeClip(1, 60));
  no_channels.mutable_header()->clear_channels();
  no_channels.mutable_header()->clear_joints();
  v1::Clip short_channel = wire::ClipToProto(MakeClip(1, 60));
  short_channel.mutable_samples(2)->mutable_samples()->RemoveLast();

  EXPECT_THAT(SubmitInline(nan_clip, reduce).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           HasSubstr("channel 0 (joint0.Xposition): sample at frame 7 is NaN")));
  EXPECT_THAT(SubmitInline(no_frames, reduce).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("frame")));
  EXPECT_THAT(SubmitInline(no_channels, reduce).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("channel")));
  EXPECT_THAT(SubmitInline(short_channel, reduce).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("never arrived")));
  ExpectServingAndNothingQueued();
}

TEST_F(ReduceServiceTest, ConstantChannelReducesToTwoFlatKeys) {
  core::Clip clip = MakeClip(1, 90);
  std::fill(clip.channels[4].samples.begin(), clip.channels[4].samples.end(), 12.5);

  const JobOutcome submitted = SubmitInline(wire::ClipToProto(clip), PaperReduce({}));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  const v1::Job done = WaitForJob(*stub_, submitted.job.job_id());
  const ResultOutcome result = GetResult(*stub_, submitted.job.job_id());
  TEMPOKEY_ASSERT_GRPC_OK(result.status);
  const absl::StatusOr<core::KeyedClip> keyed = AssembleKeyedResult(result.parts);

  ASSERT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED) << done.error_message();
  ASSERT_TRUE(keyed.ok()) << keyed.status();
  const core::Curve& flat = keyed->curves[4];
  ASSERT_EQ(flat.keys.size(), 2u);
  for (const core::Key& key : flat.keys) {
    EXPECT_EQ(key.value, 12.5);
    EXPECT_EQ(key.in_tangent, 0.0);
    EXPECT_EQ(key.out_tangent, 0.0);
  }
  EXPECT_EQ(flat.keys.front().time_seconds, 0.0);
  EXPECT_DOUBLE_EQ(flat.keys.back().time_seconds, 89 * clip.frame_time_seconds);
}

}  // namespace
}  // namespace tempokey::testing
