// Every bad warp of the core table (tests/core/retime/retime_invalid_cases.h) that v1 can express, sent to
// a real server as an inline-clip job and as a Process call: each is refused with INVALID_ARGUMENT
// and the core's exact message behind "operation 1 (retime): ", nothing is queued, and the server
// keeps serving.
#include <memory>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "proto/operations_convert.h"
#include "server/job_manager.h"
#include "server/server.h"
#include "tests/core/retime/retime_invalid_cases.h"
#include "tests/server/server_test_util.h"

namespace tempokey::testing {
namespace {

using core::retime_cases::BadRetime;

// Cases v1 cannot express, so no client can send them: it names the warp domain by which knot
// list is filled (an empty speed_over_source list is the identity, and knots always carry their
// domain), and `fit` is a oneof.
bool ExpressibleOnTheWire(const BadRetime& bad) {
  return bad.name != "KnotsWithIdentityDomain" && bad.name != "NoKnots" && bad.name != "BothFits";
}

std::vector<BadRetime> WireCases() {
  std::vector<BadRetime> cases;
  for (const BadRetime& bad : core::retime_cases::BadRetimes()) {
    if (ExpressibleOnTheWire(bad)) cases.push_back(bad);
  }
  return cases;
}

class RetimeServiceTest : public ::testing::TestWithParam<BadRetime> {
 protected:
  static void SetUpTestSuite() {
    server_ = StartServer(TestServerOptions()).release();
    if (server_ != nullptr) stub_ = v1::MotionService::NewStub(Connect(server_->target())).release();
  }
  static void TearDownTestSuite() {
    delete stub_;
    delete server_;
  }

  static v1::Operation RetimeOperation(const BadRetime& bad) {
    return wire::PipelineStepToProto(core::RetimeStep{.warp = bad.warp, .options = bad.options});
  }

  static server::Server* server_;
  static v1::MotionService::Stub* stub_;
};

server::Server* RetimeServiceTest::server_ = nullptr;
v1::MotionService::Stub* RetimeServiceTest::stub_ = nullptr;

TEST_P(RetimeServiceTest, SubmitIsRefusedWithTheCoreMessageAndNothingIsQueued) {
  ASSERT_NE(server_, nullptr);
  const BadRetime& bad = GetParam();
  v1::SubmitJobRequest request;
  *request.mutable_inline_clip() = wire::ClipToProto(core::retime_cases::EightSecondClip());
  *request.add_operations() = RetimeOperation(bad);
  const std::int64_t jobs_before = server_->jobs().job_count();

  const JobOutcome outcome = Submit(*stub_, request);

  EXPECT_THAT(outcome.status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, "operation 1 (retime): " + bad.message));
  EXPECT_EQ(server_->jobs().job_count(), jobs_before);
  const absl::StatusOr<int> health = CheckHealth(Connect(server_->target()),
                                                server::kMotionServiceName);
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_EQ(*health, 1);  // SERVING
}

TEST_P(RetimeServiceTest, ProcessIsRefusedWithTheCoreMessage) {
  ASSERT_NE(server_, nullptr);
  const BadRetime& bad = GetParam();
  const core::Clip clip = core::retime_cases::EightSecondClip();
  grpc::ClientContext context;
  SetDeadline(context);
  auto stream = stub_->Process(&context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(clip)) {
    ASSERT_TRUE(stream->Write(request));
  }
  v1::ProcessRequest start;
  *start.mutable_start()->add_operations() = RetimeOperation(bad);
  stream->Write(start);
  stream->WritesDone();
  v1::ProcessResponse response;
  int responses = 0;
  while (stream->Read(&response)) ++responses;

  const grpc::Status status = stream->Finish();

  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, "operation 1 (retime): " + bad.message));
  EXPECT_EQ(responses, 0);
}

INSTANTIATE_TEST_SUITE_P(CoreTable, RetimeServiceTest, ::testing::ValuesIn(WireCases()),
                         [](const ::testing::TestParamInfo<BadRetime>& row) {
                           return row.param.name;
                         });

TEST(RetimeServiceTableTest, CoversAtLeastTenBadWarpsOnTheWire) {
  EXPECT_GE(WireCases().size(), 10u);
}

}  // namespace
}  // namespace tempokey::testing
