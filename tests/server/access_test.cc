// Who may do what, on the real tempokey-server binary with two bearer tokens: a job belongs to the
// token that submitted it and a clip to the token that uploaded it. Another token's calls find
// neither (NOT_FOUND, worded exactly like an unknown id, so ids reveal nothing), and its listing
// is empty; request ids are per token.
#include <memory>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "tempokey/core/io/file_io.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

constexpr char kAlice[] = "alice-4f1c9a";
constexpr char kBob[] = "bob-77d0e2";

// A context with a deadline and the caller's bearer token.
std::unique_ptr<grpc::ClientContext> As(const std::string& token) {
  auto context = std::make_unique<grpc::ClientContext>();
  SetDeadline(*context);
  context->AddMetadata("authorization", "Bearer " + token);
  return context;
}

class AccessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string dir = MakeTempDir();
    ASSERT_TRUE(core::WriteFileAtomically(dir + "/tokens",
                                          std::string(kAlice) + "\n" + kBob + "\n").ok());
    absl::StatusOr<std::unique_ptr<ServerProcess>> server =
        ServerProcess::Start(dir, {"--auth_token_file", dir + "/tokens"});
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = *std::move(server);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }

  v1::UploadClipResponse Upload(const std::string& token, const core::Clip& clip) {
    auto context = As(token);
    v1::UploadClipResponse response;
    auto writer = stub_->UploadClip(context.get(), &response);
    for (const v1::UploadClipRequest& request : UploadRequests(clip, wire::kDefaultSliceBytes)) {
      writer->Write(request);
    }
    writer->WritesDone();
    const grpc::Status status = writer->Finish();
    EXPECT_TRUE(status.ok()) << status.error_message();
    return response;
  }

  JobOutcome SubmitAs(const std::string& token, const v1::SubmitJobRequest& request) {
    JobOutcome outcome;
    outcome.status = stub_->SubmitJob(As(token).get(), request, &outcome.job);
    return outcome;
  }

  // Every call that takes a job id, made by `token`; their statuses in call order.
  std::vector<grpc::Status> EveryJobCall(const std::string& token, const std::string& job_id) {
    std::vector<grpc::Status> statuses;
    v1::Job job;
    v1::GetJobRequest get;
    get.set_job_id(job_id);
    statuses.push_back(stub_->GetJob(As(token).get(), get, &job));
    v1::CancelJobRequest cancel;
    cancel.set_job_id(job_id);
    statuses.push_back(stub_->CancelJob(As(token).get(), cancel, &job));
    {
      auto context = As(token);
      v1::WatchJobRequest watch;
      watch.set_job_id(job_id);
      auto reader = stub_->WatchJob(context.get(), watch);
      while (reader->Read(&job)) {
      }
      statuses.push_back(reader->Finish());
    }
    {
      auto context = As(token);
      v1::GetJobResultRequest result;
      result.set_job_id(job_id);
      auto reader = stub_->GetJobResult(context.get(), result);
      v1::ResultPart part;
      while (reader->Read(&part)) {
      }
      statuses.push_back(reader->Finish());
    }
    v1::DeleteJobRequest del;
    del.set_job_id(job_id);
    v1::DeleteJobResponse deleted;
    statuses.push_back(stub_->DeleteJob(As(token).get(), del, &deleted));
    return statuses;
  }

  v1::ListJobsResponse ListAs(const std::string& token) {
    v1::ListJobsResponse page;
    const grpc::Status status = stub_->ListJobs(As(token).get(), v1::ListJobsRequest(), &page);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return page;
  }

  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(AccessTest, AnotherTokensJobsAreNotFoundLikeUnknownOnes) {
  const std::string clip_id = Upload(kAlice, MakeClip(1, 40)).clip_id();
  const JobOutcome job = SubmitAs(kAlice, SubmitRequest(clip_id));
  ASSERT_TRUE(job.status.ok()) << job.status.error_message();
  const std::string id = job.job.job_id();
  const std::string unknown = "job-0123456789abcdef";

  const std::vector<grpc::Status> bob = EveryJobCall(kBob, id);
  const std::vector<grpc::Status> bob_unknown = EveryJobCall(kBob, unknown);
  const v1::ListJobsResponse bob_list = ListAs(kBob);
  const v1::ListJobsResponse alice_list = ListAs(kAlice);

  ASSERT_EQ(bob.size(), bob_unknown.size());
  for (std::size_t i = 0; i < bob.size(); ++i) {
    EXPECT_EQ(bob[i].error_code(), grpc::StatusCode::NOT_FOUND) << "call " << i;
    // Word for word what an id that never existed gets, but for the id itself.
    std::string expected = bob_unknown[i].error_message();
    expected.replace(expected.find(unknown), unknown.size(), id);
    EXPECT_EQ(bob[i].error_message(), expected) << "call " << i;
  }
  EXPECT_EQ(bob_list.jobs_size(), 0);
  ASSERT_EQ(alice_list.jobs_size(), 1);
  EXPECT_EQ(alice_list.jobs(0).job_id(), id);
}

TEST_F(AccessTest, TheOwnerStillDoesEverythingWithItsJob) {
  const std::string clip_id = Upload(kAlice, MakeClip(1, 40)).clip_id();
  const JobOutcome job = SubmitAs(kAlice, SubmitRequest(clip_id));
  ASSERT_TRUE(job.status.ok()) << job.status.error_message();

  const std::vector<grpc::Status> alice = EveryJobCall(kAlice, job.job.job_id());

  // Get, cancel (idempotent on a finished or running job), watch to the end, result, delete.
  for (std::size_t i = 0; i < alice.size(); ++i) {
    const bool result_of_cancelled = i == 3 && alice[i].error_code() == grpc::StatusCode::FAILED_PRECONDITION;
    EXPECT_TRUE(alice[i].ok() || result_of_cancelled) << "call " << i << ": " << alice[i].error_message();
  }
  EXPECT_EQ(ListAs(kAlice).jobs_size(), 0);  // deleted
}

TEST_F(AccessTest, ClipsBelongToTheTokenThatUploadedThem) {
  const core::Clip clip = MakeClip(1, 40);
  const v1::UploadClipResponse alice = Upload(kAlice, clip);

  const JobOutcome bob_job = SubmitAs(kBob, SubmitRequest(alice.clip_id()));
  const v1::UploadClipResponse bob = Upload(kBob, clip);
  const JobOutcome bob_own = SubmitAs(kBob, SubmitRequest(bob.clip_id()));

  EXPECT_THAT(bob_job.status,
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND,
                           "clip \"" + alice.clip_id() +
                               "\" not found (never uploaded, or evicted: upload it again)"));
  // The same content under Bob's token: same id, but stored for Bob (nothing said of Alice's).
  EXPECT_EQ(bob.clip_id(), alice.clip_id());
  EXPECT_FALSE(bob.already_stored());
  TEMPOKEY_ASSERT_GRPC_OK(bob_own.status);
}

TEST_F(AccessTest, RequestIdsArePerToken) {
  const std::string alice_clip = Upload(kAlice, MakeClip(1, 40)).clip_id();
  const std::string bob_clip = Upload(kBob, MakeClip(1, 40)).clip_id();
  v1::SubmitJobRequest alice_request = SubmitRequest(alice_clip);
  alice_request.set_request_id("nightly-17");
  v1::SubmitJobRequest bob_request = SubmitRequest(bob_clip, WrapOperations(2));
  bob_request.set_request_id("nightly-17");

  const JobOutcome alice = SubmitAs(kAlice, alice_request);
  const JobOutcome bob = SubmitAs(kBob, bob_request);

  TEMPOKEY_ASSERT_GRPC_OK(alice.status);
  TEMPOKEY_ASSERT_GRPC_OK(bob.status);
  EXPECT_NE(alice.job.job_id(), bob.job.job_id());
}

TEST_F(AccessTest, CallsWithoutAnAcceptedTokenAreUnauthenticated) {
  grpc::ClientContext anonymous;
  SetDeadline(anonymous);
  v1::ServerInfo info;

  const grpc::Status none = stub_->GetServerInfo(&anonymous, v1::GetServerInfoRequest(), &info);
  const grpc::Status wrong = stub_->GetServerInfo(As("guessed").get(), v1::GetServerInfoRequest(), &info);

  EXPECT_THAT(none, GrpcStatusIs(grpc::StatusCode::UNAUTHENTICATED, HasSubstr("missing")));
  EXPECT_THAT(wrong, GrpcStatusIs(grpc::StatusCode::UNAUTHENTICATED,
                                  "the bearer token is not accepted"));
}

// An authentication scheme's name is case-insensitive (RFC 9110, 11.1): "bearer" was refused.
TEST_F(AccessTest, TheSchemeNameIsCaseInsensitive) {
  grpc::ClientContext lower;
  SetDeadline(lower);
  lower.AddMetadata("authorization", "bearer " + std::string(kAlice));
  grpc::ClientContext other;
  SetDeadline(other);
  other.AddMetadata("authorization", "Basic " + std::string(kAlice));
  v1::ServerInfo info;

  TEMPOKEY_ASSERT_GRPC_OK(stub_->GetServerInfo(&lower, v1::GetServerInfoRequest(), &info));
  EXPECT_THAT(stub_->GetServerInfo(&other, v1::GetServerInfoRequest(), &info),
              GrpcStatusIs(grpc::StatusCode::UNAUTHENTICATED,
                           "authorization is not \"Bearer <token>\""));
}

}  // namespace
}  // namespace tempokey::testing
