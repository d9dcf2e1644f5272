// The job service end to end over a real server on 127.0.0.1:0: submit, watch, result, list,
// cancel, delete, dedupe, and retime / reduce through the service where core implements them.
#include <algorithm>
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/job_manager.h"
#include "server/job_pool.h"
#include "server/server.h"
#include "tempokey/core/io/bvh.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::SizeIs;


class JobsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = StartServer(TestServerOptions());
    ASSERT_NE(server_, nullptr);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }

  std::string Upload(const core::Clip& clip) {
    UploadOutcome outcome = UploadClip(*stub_, clip);
    EXPECT_TRUE(outcome.status.ok()) << outcome.status.error_message();
    return outcome.response.clip_id();
  }

  std::unique_ptr<server::Server> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(JobsTest, FullLifecycleFromSubmitToDelete) {
  const core::Clip clip = MakeClip(4, 500);
  const std::string clip_id = Upload(clip);
  v1::SubmitJobRequest request = SubmitRequest(clip_id);
  (*request.mutable_labels())["shot"] = "a12";
  request.set_request_id("lifecycle-1");

  JobOutcome submitted = Submit(*stub_, request);
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  WatchOutcome watch = WatchJob(*stub_, submitted.job.job_id());
  JobOutcome got = GetJob(*stub_, submitted.job.job_id());
  ResultOutcome result = GetResult(*stub_, submitted.job.job_id());
  grpc::ClientContext list_context;
  SetDeadline(list_context);
  v1::ListJobsRequest list_request;
  (*list_request.mutable_labels())["shot"] = "a12";
  v1::ListJobsResponse listed;
  const grpc::Status list_status = stub_->ListJobs(&list_context, list_request, &listed);
  grpc::ClientContext delete_context;
  SetDeadline(delete_context);
  v1::DeleteJobRequest delete_request;
  delete_request.set_job_id(submitted.job.job_id());
  v1::DeleteJobResponse deleted;
  const grpc::Status delete_status = stub_->DeleteJob(&delete_context, delete_request, &deleted);

  EXPECT_EQ(submitted.job.clip_id(), clip_id);
  EXPECT_EQ(submitted.job.request_id(), "lifecycle-1");
  EXPECT_TRUE(submitted.job.state() == v1::JOB_STATE_QUEUED ||
              submitted.job.state() == v1::JOB_STATE_RUNNING);
  TEMPOKEY_ASSERT_GRPC_OK(watch.status);
  ASSERT_FALSE(watch.updates.empty());
  EXPECT_EQ(watch.updates.back().state(), v1::JOB_STATE_SUCCEEDED);
  TEMPOKEY_ASSERT_GRPC_OK(got.status);
  EXPECT_EQ(got.job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(got.job.progress(), 1.0);
  EXPECT_EQ(got.job.labels().at("shot"), "a12");
  ASSERT_THAT(got.job.operations(), SizeIs(1));
  EXPECT_TRUE(got.job.operations(0).convert().wrap_rotations());
  EXPECT_TRUE(got.job.has_start_time());
  EXPECT_TRUE(got.job.has_end_time());
  TEMPOKEY_ASSERT_GRPC_OK(result.status);
  absl::StatusOr<core::Clip> output = AssembleClipResult(result.parts);
  ASSERT_TRUE(output.ok()) << output.status();
  EXPECT_EQ(*output, WrappedCopy(clip));
  TEMPOKEY_ASSERT_GRPC_OK(list_status);
  ASSERT_THAT(listed.jobs(), SizeIs(1));
  EXPECT_EQ(listed.jobs(0).job_id(), submitted.job.job_id());
  TEMPOKEY_ASSERT_GRPC_OK(delete_status);
  EXPECT_THAT(GetJob(*stub_, submitted.job.job_id()).status,
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("not found")));
  EXPECT_THAT(GetResult(*stub_, submitted.job.job_id()).status,
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("not found")));
}

TEST_F(JobsTest, RealClipRunsThroughTheService) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  const std::string clip_id = Upload(*clip);

  JobOutcome submitted = Submit(*stub_, SubmitRequest(clip_id));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  const v1::Job done = WaitForJob(*stub_, submitted.job.job_id());
  ResultOutcome result = GetResult(*stub_, submitted.job.job_id());

  EXPECT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED) << done.error_message();
  TEMPOKEY_ASSERT_GRPC_OK(result.status);
  absl::StatusOr<core::Clip> output = AssembleClipResult(result.parts);
  ASSERT_TRUE(output.ok()) << output.status();
  EXPECT_EQ(output->frame_count, 994);
  EXPECT_EQ(output->channels.size(), 96u);
  EXPECT_EQ(*output, WrappedCopy(*clip));
}

TEST_F(JobsTest, InlineClipJobGetsTheSameContentIdAsAnUpload) {
  const core::Clip clip = MakeClip(2, 120);
  const std::string uploaded_id = Upload(clip);
  v1::SubmitJobRequest request;
  *request.mutable_inline_clip() = wire::ClipToProto(clip);
  *request.mutable_operations() = WrapOperations();

  JobOutcome submitted = Submit(*stub_, request);
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  WaitForJob(*stub_, submitted.job.job_id());
  ResultOutcome result = GetResult(*stub_, submitted.job.job_id());

  EXPECT_EQ(submitted.job.clip_id(), uploaded_id);
  absl::StatusOr<core::Clip> output = AssembleClipResult(result.parts);
  ASSERT_TRUE(output.ok()) << output.status();
  EXPECT_EQ(*output, WrappedCopy(clip));
}

TEST_F(JobsTest, ResultArrivesInSlicesOfTheRequestedSize) {
  const core::Clip clip = MakeClip(1, 1000);
  JobOutcome submitted = Submit(*stub_, SubmitRequest(Upload(clip)));
  WaitForJob(*stub_, submitted.job.job_id());

  ResultOutcome result = GetResult(*stub_, submitted.job.job_id(), /*slice_bytes=*/8 * 125);

  TEMPOKEY_ASSERT_GRPC_OK(result.status);
  ASSERT_THAT(result.parts, SizeIs(1 + 6 * 8));  // header, then 8 slices of 125 per channel
  ASSERT_TRUE(result.parts[0].has_header());
  for (std::size_t i = 1; i < result.parts.size(); ++i) {
    EXPECT_EQ(result.parts[i].samples().samples_size(), 125);
  }
  absl::StatusOr<core::Clip> output = AssembleClipResult(result.parts);
  ASSERT_TRUE(output.ok()) << output.status();
  EXPECT_EQ(*output, WrappedCopy(clip));
}

TEST_F(JobsTest, ResultStreamsRefusedOrEndedGiveTheirStreamSlotsBack) {
  const std::string job_id = Submit(*stub_, SubmitRequest(Upload(MakeClip(1, 100)))).job.job_id();
  WaitForJob(*stub_, job_id);

  // Each stream gives its slot back before its status goes out: none is open once the client
  // has it.
  const ResultOutcome negative = GetResult(*stub_, job_id, /*slice_bytes=*/-1);
  EXPECT_EQ(server_->open_streams(), 0);
  const ResultOutcome unknown = GetResult(*stub_, "no-such-job");
  EXPECT_EQ(server_->open_streams(), 0);
  const ResultOutcome whole = GetResult(*stub_, job_id);
  EXPECT_EQ(server_->open_streams(), 0);

  EXPECT_THAT(negative.status, GrpcStatusIs(grpc::INVALID_ARGUMENT,
                                            "slice_bytes must be >= 0 (0: 1 MiB), got -1"));
  EXPECT_THAT(negative.parts, SizeIs(0));
  EXPECT_THAT(unknown.status, GrpcStatusIs(grpc::NOT_FOUND, HasSubstr("no-such-job")));
  EXPECT_TRUE(whole.status.ok()) << whole.status.error_message();
  EXPECT_TRUE(AssembleClipResult(whole.parts).ok());
}

TEST(JobsGatedTest, WatchSeesStrictlyIncreasingVersionsAndEndsOnTheTerminalState) {
  GatedServer gated;
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(20, 300)).response.clip_id();
  JobOutcome submitted = Submit(*gated.stub, SubmitRequest(clip_id, WrapOperations(4)));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  ASSERT_TRUE(gated.gate->WaitArrivals(1));

  WatchOutcome watch = WatchJob(*gated.stub, submitted.job.job_id(), [&](const v1::Job& job) {
    if (job.state() == v1::JOB_STATE_RUNNING) gated.gate->Open();
  });

  TEMPOKEY_ASSERT_GRPC_OK(watch.status);
  ASSERT_GE(watch.updates.size(), 2u);
  EXPECT_EQ(watch.updates.front().state(), v1::JOB_STATE_RUNNING);  // the snapshot, at once
  EXPECT_EQ(watch.updates.back().state(), v1::JOB_STATE_SUCCEEDED);
  for (std::size_t i = 1; i < watch.updates.size(); ++i) {
    EXPECT_LT(watch.updates[i - 1].version(), watch.updates[i].version());
    EXPECT_LE(watch.updates[i - 1].progress(), watch.updates[i].progress());
  }
  EXPECT_GT(watch.updates.front().version(), submitted.job.version());
}

TEST(JobsGatedTest, CancelledQueuedJobNeverRuns) {
  server::ServerOptions options = TestServerOptions();
  options.workers = 1;
  GatedServer gated(options);
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 50)).response.clip_id();
  JobOutcome running = Submit(*gated.stub, SubmitRequest(clip_id));
  ASSERT_TRUE(gated.gate->WaitArrivals(1));
  JobOutcome queued = Submit(*gated.stub, SubmitRequest(clip_id));

  grpc::ClientContext context;
  SetDeadline(context);
  v1::CancelJobRequest cancel;
  cancel.set_job_id(queued.job.job_id());
  v1::Job cancelled;
  TEMPOKEY_ASSERT_GRPC_OK(gated.stub->CancelJob(&context, cancel, &cancelled));
  grpc::ClientContext again_context;
  SetDeadline(again_context);
  v1::Job again;
  TEMPOKEY_ASSERT_GRPC_OK(gated.stub->CancelJob(&again_context, cancel, &again));
  gated.gate->Open();
  const v1::Job first_done = WaitForJob(*gated.stub, running.job.job_id());
  ASSERT_TRUE(gated.server->pool().WaitIdle(std::chrono::steady_clock::now() + kCallDeadline));
  const v1::Job final_state = GetJob(*gated.stub, queued.job.job_id()).job;

  EXPECT_EQ(queued.job.state(), v1::JOB_STATE_QUEUED);
  EXPECT_EQ(cancelled.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(again.version(), cancelled.version());
  EXPECT_EQ(first_done.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(final_state.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(final_state.error_code(), static_cast<int>(grpc::StatusCode::CANCELLED));
  EXPECT_FALSE(final_state.has_start_time());
  EXPECT_EQ(gated.gate->arrived(), 1);  // only the first job ever reached a worker
  EXPECT_THAT(GetResult(*gated.stub, queued.job.job_id()).status,
              GrpcStatusIs(grpc::StatusCode::FAILED_PRECONDITION, HasSubstr("was cancelled")));
}

TEST(JobsGatedTest, CancelledRunningJobEndsCancelled) {
  GatedServer gated;
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(3, 200)).response.clip_id();
  JobOutcome submitted = Submit(*gated.stub, SubmitRequest(clip_id));
  ASSERT_TRUE(gated.gate->WaitArrivals(1));

  grpc::ClientContext context;
  SetDeadline(context);
  v1::CancelJobRequest cancel;
  cancel.set_job_id(submitted.job.job_id());
  v1::Job cancelling;
  TEMPOKEY_ASSERT_GRPC_OK(gated.stub->CancelJob(&context, cancel, &cancelling));
  gated.gate->Open();
  const v1::Job done = WaitForJob(*gated.stub, submitted.job.job_id());

  EXPECT_EQ(cancelling.state(), v1::JOB_STATE_RUNNING);
  EXPECT_EQ(cancelling.stage(), "cancelling");
  EXPECT_EQ(done.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(done.error_code(), static_cast<int>(grpc::StatusCode::CANCELLED));
}

TEST(JobsGatedTest, ProcessStartedDuringADrainIsRefusedWithUnavailable) {
  GatedServer gated;
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 50)).response.clip_id();
  const JobOutcome running = Submit(*gated.stub, SubmitRequest(clip_id));
  ASSERT_TRUE(gated.gate->WaitArrivals(1));  // a job holds the drain open
  grpc::ClientContext context;
  SetDeadline(context);
  auto stream = gated.stub->Process(&context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(MakeClip(1, 40))) {
    ASSERT_TRUE(stream->Write(request));
  }
  std::thread drain([&] { gated.server->Drain(); });
  auto channel = Connect(gated.server->target());
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  while (CheckHealth(channel, server::kMotionServiceName).value_or(0) != 2 &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }

  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = WrapOperations();
  stream->Write(start);
  stream->WritesDone();
  v1::ProcessResponse response;
  int responses = 0;
  while (stream->Read(&response)) ++responses;
  const grpc::Status status = stream->Finish();
  gated.gate->Open();
  drain.join();

  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::UNAVAILABLE, HasSubstr("shutting down")));
  EXPECT_EQ(responses, 0);
  TEMPOKEY_ASSERT_GRPC_OK(running.status);
}

TEST(JobsGatedTest, DuplicateRequestIdRunsOnce) {
  GatedServer gated;
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 50)).response.clip_id();
  v1::SubmitJobRequest request = SubmitRequest(clip_id);
  request.set_request_id("0f6b2a4e-retry");

  JobOutcome first = Submit(*gated.stub, request);
  JobOutcome retry = Submit(*gated.stub, request);
  gated.gate->Open();
  WaitForJob(*gated.stub, first.job.job_id());
  JobOutcome late_retry = Submit(*gated.stub, request);
  ASSERT_TRUE(gated.server->pool().WaitIdle(std::chrono::steady_clock::now() + kCallDeadline));
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ListJobsResponse all;
  TEMPOKEY_ASSERT_GRPC_OK(gated.stub->ListJobs(&context, v1::ListJobsRequest(), &all));

  TEMPOKEY_ASSERT_GRPC_OK(first.status);
  TEMPOKEY_ASSERT_GRPC_OK(retry.status);
  EXPECT_EQ(retry.job.job_id(), first.job.job_id());
  EXPECT_EQ(late_retry.job.job_id(), first.job.job_id());
  EXPECT_EQ(late_retry.job.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_THAT(all.jobs(), SizeIs(1));
  EXPECT_EQ(gated.gate->arrived(), 1);
}

TEST_F(JobsTest, ListJobsPagesAndFiltersByState) {
  const std::string clip_id = Upload(MakeClip(1, 20));
  std::vector<std::string> ids;
  for (int i = 0; i < 5; ++i) {
    JobOutcome job = Submit(*stub_, SubmitRequest(clip_id));
    TEMPOKEY_ASSERT_GRPC_OK(job.status);
    ids.push_back(job.job.job_id());
    WaitForJob(*stub_, job.job.job_id());
  }

  std::vector<std::string> seen;
  std::string token;
  int pages = 0;
  do {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::ListJobsRequest request;
    request.set_page_size(2);
    request.set_page_token(token);
    request.add_states(v1::JOB_STATE_SUCCEEDED);
    v1::ListJobsResponse page;
    TEMPOKEY_ASSERT_GRPC_OK(stub_->ListJobs(&context, request, &page));
    for (const v1::Job& job : page.jobs()) seen.push_back(job.job_id());
    token = page.next_page_token();
    ++pages;
  } while (!token.empty() && pages < 10);
  grpc::ClientContext running_context;
  SetDeadline(running_context);
  v1::ListJobsRequest running_request;
  running_request.add_states(v1::JOB_STATE_RUNNING);
  v1::ListJobsResponse running;
  TEMPOKEY_ASSERT_GRPC_OK(stub_->ListJobs(&running_context, running_request, &running));

  EXPECT_EQ(seen, ids);
  EXPECT_EQ(pages, 3);
  EXPECT_THAT(running.jobs(), SizeIs(0));
}

TEST_F(JobsTest, ListJobsWithItsStatesRepeatedFiltersAsWithEachOnce) {
  // 2 000 000 states (about 2 MB, packed): the server takes each state once (a list of states
  // searched for every job held the job manager's lock for seconds per such request).
  const std::string clip_id = Upload(MakeClip(1, 20));
  for (int i = 0; i < 3; ++i) {
    JobOutcome job = Submit(*stub_, SubmitRequest(clip_id));
    TEMPOKEY_ASSERT_GRPC_OK(job.status);
    WaitForJob(*stub_, job.job.job_id());
  }
  v1::ListJobsRequest done;
  v1::ListJobsRequest running;
  for (int i = 0; i < 1'000'000; ++i) {
    done.add_states(v1::JOB_STATE_RUNNING);
    done.add_states(v1::JOB_STATE_SUCCEEDED);
    running.add_states(v1::JOB_STATE_RUNNING);
    running.add_states(v1::JOB_STATE_QUEUED);
  }
  v1::ListJobsRequest bad = running;
  bad.add_states(v1::JOB_STATE_UNSPECIFIED);
  auto list = [&](const v1::ListJobsRequest& request, v1::ListJobsResponse& response) {
    grpc::ClientContext context;
    SetDeadline(context);
    return stub_->ListJobs(&context, request, &response);
  };
  v1::ListJobsResponse listed_done, listed_running, listed_bad;

  TEMPOKEY_ASSERT_GRPC_OK(list(done, listed_done));
  TEMPOKEY_ASSERT_GRPC_OK(list(running, listed_running));
  EXPECT_THAT(listed_done.jobs(), SizeIs(3));
  EXPECT_THAT(listed_running.jobs(), SizeIs(0));
  EXPECT_THAT(list(bad, listed_bad),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           "states[2000000]: job state 0 is not a state"));
}

TEST_F(JobsTest, BadListRequestsAreRefused) {
  grpc::ClientContext a;
  SetDeadline(a);
  v1::ListJobsRequest bad_token;
  bad_token.set_page_token("not-a-token");
  v1::ListJobsResponse response;
  grpc::ClientContext b;
  SetDeadline(b);
  v1::ListJobsRequest bad_state;
  bad_state.add_states(v1::JOB_STATE_UNSPECIFIED);

  EXPECT_THAT(stub_->ListJobs(&a, bad_token, &response),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("page_token \"not-a-token\"")));
  EXPECT_THAT(stub_->ListJobs(&b, bad_state, &response),
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, "states[0]: job state 0 is not a state"));
}

TEST_F(JobsTest, BadSubmitsGetPreciseErrors) {
  const core::Clip clip = MakeClip(1, 10);
  const std::string clip_id = Upload(clip);
  v1::SubmitJobRequest unknown_clip = SubmitRequest("sha256:0000");
  v1::SubmitJobRequest no_ops = SubmitRequest(clip_id, {});
  google::protobuf::RepeatedPtrField<v1::Operation> bake;
  bake.Add()->mutable_bake();
  v1::SubmitJobRequest bake_sampled = SubmitRequest(clip_id, bake);
  v1::SubmitJobRequest nan_inline;
  *nan_inline.mutable_inline_clip() = wire::ClipToProto(clip);
  nan_inline.mutable_inline_clip()->mutable_samples(0)->set_samples(3, std::nan(""));
  *nan_inline.mutable_operations() = WrapOperations();
  v1::SubmitJobRequest no_source;
  *no_source.mutable_operations() = WrapOperations();
  v1::SubmitJobRequest bad_label = SubmitRequest(clip_id);
  (*bad_label.mutable_labels())[""] = "x";

  EXPECT_THAT(Submit(*stub_, unknown_clip).status,
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("clip \"sha256:0000\" not found")));
  EXPECT_THAT(Submit(*stub_, no_ops).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, "the pipeline has no operations"));
  EXPECT_THAT(Submit(*stub_, bake_sampled).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           HasSubstr("operation 1 (bake): needs a keyed clip, got a sampled clip")));
  EXPECT_THAT(Submit(*stub_, nan_inline).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           "inline_clip: samples message 1: channel 0 (joint0.Xposition): sample "
                           "at frame 3 is NaN"));
  EXPECT_THAT(Submit(*stub_, no_source).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           "the job has no clip: set clip_id or inline_clip"));
  EXPECT_THAT(Submit(*stub_, bad_label).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("label key")));
  // Nothing was queued by any of them.
  EXPECT_EQ(server_->jobs().job_count(), 0);
}

TEST_F(JobsTest, ServerOffersEveryOperation) {
  EXPECT_THAT(server_->operations(),
              ElementsAre("convert", "retime", "retime/paper", "reduce", "reduce/tolerance",
                          "reduce/paper", "reduce/noise", "bake"));
}

TEST_F(JobsTest, LookupsOfUnknownJobsAreNotFound) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::CancelJobRequest cancel;
  cancel.set_job_id("job-0000000000000000");
  v1::Job job;

  EXPECT_THAT(GetJob(*stub_, "job-0000000000000000").status,
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("job-0000000000000000")));
  EXPECT_THAT(WatchJob(*stub_, "job-0000000000000000").status,
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("not found")));
  EXPECT_THAT(stub_->CancelJob(&context, cancel, &job),
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("not found")));
  EXPECT_THAT(GetJob(*stub_, "").status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, "job_id is empty"));
}

TEST_F(JobsTest, EveryCallTakingAJobIdRefusesAMalformedOne) {
  const std::string too_long(300, 'j');

  for (const std::string& id : {std::string(), too_long}) {
    // An empty id is malformed; an id over the size limit is refused like every size cap.
    const std::string message =
        id.empty() ? "job_id is empty" : "job_id is 300 bytes, over the limit of 256";
    const grpc::StatusCode code =
        id.empty() ? grpc::StatusCode::INVALID_ARGUMENT : grpc::StatusCode::RESOURCE_EXHAUSTED;
    EXPECT_THAT(GetJob(*stub_, id).status, GrpcStatusIs(code, message));
    EXPECT_THAT(WatchJob(*stub_, id).status, GrpcStatusIs(code, message));
    EXPECT_THAT(GetResult(*stub_, id).status, GrpcStatusIs(code, message));
  }
}

TEST(JobsGatedTest, ResultBeforeSuccessIsAPreconditionError) {
  GatedServer gated;
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 50)).response.clip_id();
  JobOutcome submitted = Submit(*gated.stub, SubmitRequest(clip_id));
  ASSERT_TRUE(gated.gate->WaitArrivals(1));

  ResultOutcome early = GetResult(*gated.stub, submitted.job.job_id());
  grpc::ClientContext context;
  SetDeadline(context);
  v1::DeleteJobRequest del;
  del.set_job_id(submitted.job.job_id());
  v1::DeleteJobResponse response;
  const grpc::Status delete_running = gated.stub->DeleteJob(&context, del, &response);

  EXPECT_THAT(early.status, GrpcStatusIs(grpc::StatusCode::FAILED_PRECONDITION,
                                         HasSubstr("has no result yet: it is RUNNING")));
  EXPECT_THAT(delete_running, GrpcStatusIs(grpc::StatusCode::FAILED_PRECONDITION,
                                           HasSubstr("cancel it and delete it once it has ended")));
}

// Waits (bounded) until the server holds no open streams.
bool NoStreamsLeft(const server::Server& server) {
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  while (server.open_streams() != 0) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

TEST(JobsGatedTest, ClientCancellingAWatchReleasesServerState) {
  GatedServer gated;
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 50)).response.clip_id();
  JobOutcome submitted = Submit(*gated.stub, SubmitRequest(clip_id));
  ASSERT_TRUE(gated.gate->WaitArrivals(1));
  // The upload stream's server side may still be closing after the client saw its response.
  ASSERT_TRUE(NoStreamsLeft(*gated.server));

  grpc::ClientContext context;
  SetDeadline(context);
  v1::WatchJobRequest request;
  request.set_job_id(submitted.job.job_id());
  auto reader = gated.stub->WatchJob(&context, request);
  v1::Job snapshot;
  ASSERT_TRUE(reader->Read(&snapshot));
  const int open_during = gated.server->open_streams();
  context.TryCancel();
  while (reader->Read(&snapshot)) {
  }
  const grpc::Status status = reader->Finish();

  EXPECT_EQ(open_during, 1);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::CANCELLED);
  EXPECT_TRUE(NoStreamsLeft(*gated.server));
}

TEST(JobsGatedTest, WatchDeadlineReleasesServerState) {
  GatedServer gated;
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 50)).response.clip_id();
  JobOutcome submitted = Submit(*gated.stub, SubmitRequest(clip_id));
  ASSERT_TRUE(gated.gate->WaitArrivals(1));

  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(300));
  v1::WatchJobRequest request;
  request.set_job_id(submitted.job.job_id());
  auto reader = gated.stub->WatchJob(&context, request);
  v1::Job snapshot;
  int reads = 0;
  while (reader->Read(&snapshot)) ++reads;
  const grpc::Status status = reader->Finish();

  // The snapshot at most (a loaded machine may reach the deadline before it is written); the
  // job is held, so nothing else can happen.
  EXPECT_LE(reads, 1);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_TRUE(NoStreamsLeft(*gated.server));
}

// ---- operations other engineers implement in core -----------------------------------------------

TEST_F(JobsTest, IdentityRetimeThroughTheServiceIsBitExact) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  ops.Add()->mutable_retime();

  JobOutcome submitted = Submit(*stub_, SubmitRequest(Upload(*clip), ops));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  const v1::Job done = WaitForJob(*stub_, submitted.job.job_id());
  ResultOutcome result = GetResult(*stub_, submitted.job.job_id());

  ASSERT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED) << done.error_message();
  ASSERT_THAT(done.reports(), SizeIs(1));
  EXPECT_EQ(done.reports(0).retime().output_frame_count(), clip->frame_count);
  absl::StatusOr<core::Clip> output = AssembleClipResult(result.parts);
  ASSERT_TRUE(output.ok()) << output.status();
  ASSERT_EQ(output->channels.size(), clip->channels.size());
  for (std::size_t c = 0; c < clip->channels.size(); ++c) {
    EXPECT_EQ(output->channels[c].samples, clip->channels[c].samples) << "channel " << c;
  }
}

TEST_F(JobsTest, HalfSpeedRetimeThroughTheServiceDoublesTheDuration) {
  const core::Clip clip = MakeClip(2, 121);
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  v1::SpeedKnot* knot = ops.Add()->mutable_retime()->add_speed_over_source();
  knot->mutable_time()->set_seconds(0);
  knot->set_speed(0.5);

  JobOutcome submitted = Submit(*stub_, SubmitRequest(Upload(clip), ops));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  const v1::Job done = WaitForJob(*stub_, submitted.job.job_id());
  ResultOutcome result = GetResult(*stub_, submitted.job.job_id());

  ASSERT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED) << done.error_message();
  absl::StatusOr<core::Clip> output = AssembleClipResult(result.parts);
  ASSERT_TRUE(output.ok()) << output.status();
  EXPECT_EQ(output->frame_count, 2 * 120 + 1);  // T_o = 2 T_s, M = 2 (N - 1) + 1
  EXPECT_EQ(done.reports(0).retime().output_frame_count(), 241);
  EXPECT_EQ(output->channels[0].samples.front(), clip.channels[0].samples.front());
  EXPECT_EQ(output->channels[0].samples.back(), clip.channels[0].samples.back());
}

TEST_F(JobsTest, InvalidRetimeIsRefusedBeforeQueueing) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  v1::SpeedKnot* knot = ops.Add()->mutable_retime()->add_speed_over_source();
  knot->mutable_time()->set_seconds(0);
  knot->set_speed(-2.0);

  const grpc::Status status = Submit(*stub_, SubmitRequest(Upload(MakeClip(1, 30)), ops)).status;

  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("operation 1 (retime)")));
  EXPECT_EQ(server_->jobs().job_count(), 0);
}

TEST_F(JobsTest, ReductionThroughTheServiceStreamsAKeyedClip) {
  const core::Clip clip = MakeClip(1, 90);
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  ops.Add()->mutable_reduce()->set_method(v1::REDUCE_METHOD_TOLERANCE);

  JobOutcome submitted = Submit(*stub_, SubmitRequest(Upload(clip), ops));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  const v1::Job done = WaitForJob(*stub_, submitted.job.job_id());
  ResultOutcome result = GetResult(*stub_, submitted.job.job_id());

  ASSERT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED) << done.error_message();
  ASSERT_THAT(done.reports(), SizeIs(1));
  EXPECT_GT(done.reports(0).reduction().key_count(), 0);
  EXPECT_EQ(done.reports(0).reduction().sample_count(), clip.sample_count());
  TEMPOKEY_ASSERT_GRPC_OK(result.status);
  absl::StatusOr<core::KeyedClip> keyed = AssembleKeyedResult(result.parts);
  ASSERT_TRUE(keyed.ok()) << keyed.status();
  EXPECT_EQ(keyed->curves.size(), clip.channels.size());
  std::int64_t keys = 0;
  for (const core::Curve& curve : keyed->curves) keys += static_cast<std::int64_t>(curve.keys.size());
  EXPECT_EQ(keys, done.reports(0).reduction().key_count());
}

}  // namespace
}  // namespace tempokey::testing
