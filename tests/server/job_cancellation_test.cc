// Work that cannot be bounded or stopped, end to end against the real tempokey-server binary:
// the paper's reduction of one 16 000-frame channel with 1000 passes at accuracy 1e-300 (tens of
// seconds of one core) is stopped from inside the channel by CancelJob, by a Process client that
// cancels, and by the drain deadline after SIGTERM; and the same request is refused up front by a
// server with a work limit, with the estimate in the message. What is asserted are states and
// their order (CANCELLED, never SUCCEEDED; the worker's next job runs after the cancelled one
// ended); how long each stop took is printed for the record, never asserted.
#include <signal.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "google/protobuf/util/time_util.h"
#include "gtest/gtest.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// One plain channel of Gaussian noise at 120 Hz: every frame is an extremum, so the paper's fit
// keeps thousands of keys and no pass is cheap.
core::Clip NoiseChannel(std::int64_t frames) {
  core::Clip clip;
  clip.name = "noise";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = frames;
  core::Channel channel;
  channel.name = "noise";
  std::mt19937_64 random(11);
  std::normal_distribution<double> noise(0.0, 10.0);
  for (std::int64_t f = 0; f < frames; ++f) channel.samples.push_back(noise(random));
  clip.channels.push_back(std::move(channel));
  return clip;
}

// The request of the finding: max_iterations 1000, accuracy 1e-300.
google::protobuf::RepeatedPtrField<v1::Operation> LongPaperReduction() {
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  v1::ReduceOperation* reduce = operations.Add()->mutable_reduce();
  reduce->set_method(v1::REDUCE_METHOD_PAPER);
  reduce->mutable_paper()->set_max_iterations(1000);
  reduce->mutable_paper()->set_accuracy(1e-300);
  return operations;
}

// A tempokey-server child with info logging (the tests read its per-job lines).
std::unique_ptr<ServerProcess> StartServer(const std::vector<std::string>& flags) {
  std::vector<std::string> all = {"--log_level", "info"};
  all.insert(all.end(), flags.begin(), flags.end());
  absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(MakeTempDir(), all);
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

std::int64_t Nanos(const google::protobuf::Timestamp& t) {
  return google::protobuf::util::TimeUtil::TimestampToNanoseconds(t);
}

// One worker and no work limit: the long job runs, and nothing else can until it ends.
const std::vector<std::string> kOneUnlimitedWorker = {"--workers=1", "--max_job_cost_seconds=0"};

TEST(JobCancellationTest, CancellingARunningPaperReductionEndsItCancelledAndFreesTheWorker) {
  std::unique_ptr<ServerProcess> server = StartServer(kOneUnlimitedWorker);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const UploadOutcome upload = UploadClip(*stub, NoiseChannel(16000));
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  const JobOutcome long_job =
      Submit(*stub, SubmitRequest(upload.response.clip_id(), LongPaperReduction()));
  TEMPOKEY_ASSERT_GRPC_OK(long_job.status);

  // Cancel as soon as the job is seen running; the watch then follows it to its end.
  std::optional<v1::Job> cancel_answer;
  Clock::time_point cancelled_at;
  WatchOutcome watch = WatchJob(*stub, long_job.job.job_id(), [&](const v1::Job& job) {
    if (job.state() != v1::JOB_STATE_RUNNING || cancel_answer) return;
    grpc::ClientContext context;
    SetDeadline(context);
    v1::CancelJobRequest cancel;
    cancel.set_job_id(job.job_id());
    v1::Job answer;
    cancelled_at = Clock::now();
    EXPECT_TRUE(stub->CancelJob(&context, cancel, &answer).ok());
    cancel_answer = answer;
  });
  const double cancel_to_end = SecondsSince(cancelled_at);
  const JobOutcome small = Submit(*stub, SubmitRequest(upload.response.clip_id()));
  TEMPOKEY_ASSERT_GRPC_OK(small.status);
  const v1::Job small_done = WaitForJob(*stub, small.job.job_id());
  const double cancel_to_next_done = SecondsSince(cancelled_at);
  const v1::Job long_done = GetJob(*stub, long_job.job.job_id()).job;
  std::printf("cancel -> CANCELLED seen: %.3f s; cancel -> next job done on the freed worker: "
              "%.3f s\n",
              cancel_to_end, cancel_to_next_done);
  RecordProperty("cancel_to_cancelled_ms", static_cast<int>(cancel_to_end * 1000));

  TEMPOKEY_ASSERT_GRPC_OK(watch.status);
  ASSERT_TRUE(cancel_answer.has_value());
  EXPECT_EQ(cancel_answer->state(), v1::JOB_STATE_RUNNING);
  EXPECT_EQ(cancel_answer->stage(), "cancelling");
  ASSERT_FALSE(watch.updates.empty());
  EXPECT_EQ(watch.updates.back().state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(long_done.state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(long_done.error_code(), static_cast<int>(grpc::StatusCode::CANCELLED));
  EXPECT_EQ(small_done.state(), v1::JOB_STATE_SUCCEEDED);
  // One worker: the next job started only once the cancelled one had ended.
  EXPECT_LE(Nanos(long_done.end_time()), Nanos(small_done.start_time()));
  server->Stop();
  EXPECT_THAT(server->log(), HasSubstr("job id=" + long_job.job.job_id()));
  EXPECT_THAT(server->log(), HasSubstr("outcome=cancelled"));
}

TEST(JobCancellationTest, AProcessCallTheClientCancelsFreesItsWorkerAndIsLoggedCancelled) {
  std::unique_ptr<ServerProcess> server = StartServer(kOneUnlimitedWorker);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));

  grpc::ClientContext context;
  SetDeadline(context, std::chrono::seconds(600));
  auto stream = stub->Process(&context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(NoiseChannel(16000))) {
    ASSERT_TRUE(stream->Write(request));
  }
  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = LongPaperReduction();
  ASSERT_TRUE(stream->Write(start));
  stream->WritesDone();
  // The first progress message says the pipeline runs on the worker; then the client leaves.
  v1::ProcessResponse response;
  ASSERT_TRUE(stream->Read(&response));
  EXPECT_TRUE(response.has_progress());
  const Clock::time_point cancelled_at = Clock::now();
  context.TryCancel();
  while (stream->Read(&response)) {
  }
  const grpc::Status status = stream->Finish();
  // A second call can only run once the first has given its worker back.
  grpc::ClientContext next_context;
  SetDeadline(next_context);
  auto next = stub->Process(&next_context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(NoiseChannel(100))) {
    ASSERT_TRUE(next->Write(request));
  }
  v1::ProcessRequest convert;
  *convert.mutable_start()->mutable_operations() = WrapOperations();
  ASSERT_TRUE(next->Write(convert));
  next->WritesDone();
  int parts = 0;
  while (next->Read(&response)) parts += response.has_result() ? 1 : 0;
  const grpc::Status next_status = next->Finish();
  std::printf("client cancel -> next Process call done on the freed worker: %.3f s\n",
              SecondsSince(cancelled_at));
  server->Stop();
  const std::string log = server->log();

  EXPECT_EQ(status.error_code(), grpc::StatusCode::CANCELLED);
  TEMPOKEY_ASSERT_GRPC_OK(next_status);
  EXPECT_GT(parts, 0);
  EXPECT_THAT(log, HasSubstr("process frames=16000 channels=1 operations=reduce"));
  EXPECT_THAT(log, ::testing::ContainsRegex("operations=reduce queue_wait_ms=[0-9.]+ "
                                            "run_ms=[0-9.]+ outcome=cancelled"));
  EXPECT_THAT(log, Not(::testing::ContainsRegex("operations=reduce queue_wait_ms=[0-9.]+ "
                                                "run_ms=[0-9.]+ outcome=succeeded")));
}

TEST(JobCancellationTest, SigtermStopsRunningWorkOnceTheDrainGraceIsOverAndExitsZero) {
  std::unique_ptr<ServerProcess> server = StartServer(
      {"--workers=1", "--max_job_cost_seconds=0", "--drain_grace_seconds=1"});
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const UploadOutcome upload = UploadClip(*stub, NoiseChannel(16000));
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  const JobOutcome long_job =
      Submit(*stub, SubmitRequest(upload.response.clip_id(), LongPaperReduction()));
  TEMPOKEY_ASSERT_GRPC_OK(long_job.status);

  Clock::time_point signalled_at;
  bool signalled = false;
  const WatchOutcome watch = WatchJob(*stub, long_job.job.job_id(), [&](const v1::Job& job) {
    if (job.state() == v1::JOB_STATE_RUNNING && !signalled) {
      signalled = true;
      signalled_at = Clock::now();
      server->Signal(SIGTERM);
    }
  });
  // Bounds a hang only: uncancellable, the job alone would hold the exit for half a minute.
  const std::optional<int> code = server->WaitExit(std::chrono::seconds(300));
  std::printf("SIGTERM -> exit with a 1 s grace: %.3f s\n", SecondsSince(signalled_at));
  const std::string log = server->log();

  ASSERT_TRUE(signalled);
  EXPECT_THAT(watch.status, GrpcStatusIs(grpc::StatusCode::UNAVAILABLE, HasSubstr("shutting down")));
  EXPECT_EQ(code, 0) << log;
  EXPECT_THAT(log, HasSubstr("drain grace period over: cancelling 0 queued and 1 running"));
  EXPECT_THAT(log, HasSubstr("job id=" + long_job.job.job_id()));
  EXPECT_THAT(log, HasSubstr("outcome=cancelled"));
  EXPECT_THAT(log, Not(HasSubstr("outcome=succeeded")));
  EXPECT_THAT(log, HasSubstr("drained"));
}

// ---- refusals before queueing --------------------------------------------------------------------

class WorkLimitTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = StartServer({"--workers=1"});  // the default limit, 60 s
    ASSERT_NE(server_, nullptr);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }

  int StoredJobs() {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::ListJobsResponse listed;
    EXPECT_TRUE(stub_->ListJobs(&context, v1::ListJobsRequest(), &listed).ok());
    return listed.jobs_size();
  }

  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(WorkLimitTest, ARequestPredictedOverTheLimitIsRefusedUpFrontWithTheEstimate) {
  const UploadOutcome upload = UploadClip(*stub_, NoiseChannel(16000));
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);

  grpc::ClientContext submit_context;
  SetDeadline(submit_context);
  v1::Job job;
  const grpc::Status submitted =
      stub_->SubmitJob(&submit_context, SubmitRequest(upload.response.clip_id(), LongPaperReduction()), &job);
  grpc::ClientContext process_context;
  SetDeadline(process_context);
  auto stream = stub_->Process(&process_context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(NoiseChannel(16000))) {
    ASSERT_TRUE(stream->Write(request));
  }
  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = LongPaperReduction();
  stream->Write(start);
  stream->WritesDone();
  v1::ProcessResponse response;
  int responses = 0;
  while (stream->Read(&response)) ++responses;
  const grpc::Status processed = stream->Finish();
  std::printf("refusal: %s\n", submitted.error_message().c_str());

  const auto refusal = ::testing::AllOf(
      ::testing::StartsWith("the request is over this server's work limit: predicted "),
      HasSubstr(" s of work (operation 1, reduce (paper): 1 channel x 16000 frames x up to "
                "1000 passes: "),
      HasSubstr("over the limit of 60 s (--max_job_cost_seconds)"));
  EXPECT_THAT(submitted, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED, refusal));
  EXPECT_EQ(submit_context.GetServerTrailingMetadata().count("retry-after-ms"), 0u);
  EXPECT_THAT(processed, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED, refusal));
  EXPECT_EQ(responses, 0);
  EXPECT_EQ(StoredJobs(), 0);
}

TEST_F(WorkLimitTest, ANoiseReductionOfALongCaptureIsAdmittedAndRuns) {
  // 96 channels slowed to a tenth (9 931 frames): the noise method takes about half a second of one
  // core on them. It was costed as the paper's method (68 s), over the default limit.
  const UploadOutcome upload = UploadClip(*stub_, MakeClip(31, 994));
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  v1::SpeedKnot* knot = operations.Add()->mutable_retime()->add_speed_over_source();
  knot->mutable_time()->set_seconds(0.0);
  knot->set_speed(0.1);
  operations.Add()->mutable_reduce()->set_method(v1::REDUCE_METHOD_NOISE);

  const JobOutcome submitted = Submit(*stub_, SubmitRequest(upload.response.clip_id(), operations));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  // About half a second of work, 12 s under ASan: the wait's guard is far beyond both.
  const v1::Job done = WaitForJob(*stub_, submitted.job.job_id(), std::chrono::seconds(600));

  EXPECT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED) << done.error_message();
}

TEST_F(WorkLimitTest, AKeyBudgetBelowTwoKeysPerChannelIsRefusedAtSubmit) {
  const UploadOutcome upload = UploadClip(*stub_, MakeClip(31, 200));  // 96 channels
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  operations.Add()->mutable_reduce()->mutable_tolerance()->set_key_budget(2);

  const JobOutcome submitted = Submit(*stub_, SubmitRequest(upload.response.clip_id(), operations));

  EXPECT_THAT(submitted.status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           "operation 1 (reduce): tolerance.key_budget 2 is below the 192 keys "
                           "any fit of 96 channels needs (2 per channel)"));
  EXPECT_EQ(StoredJobs(), 0);
}

TEST_F(WorkLimitTest, ChainedRetimesWhoseOutputExceedsTheCapAreRefusedAtSubmit) {
  const UploadOutcome upload = UploadClip(*stub_, MakeClip(31, 994));  // 96 channels
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  for (int i = 0; i < 2; ++i) {
    v1::SpeedKnot* knot = operations.Add()->mutable_retime()->add_speed_over_source();
    knot->mutable_time()->set_seconds(0.0);
    knot->set_speed(0.01);
  }

  const JobOutcome submitted = Submit(*stub_, SubmitRequest(upload.response.clip_id(), operations));

  EXPECT_THAT(submitted.status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           "operation 2 (retime): the retimed clip would have 9930001 frames x 96 "
                           "channels, over the limit of 33554432 samples"));
  EXPECT_EQ(StoredJobs(), 0);
}

}  // namespace
}  // namespace tempokey::testing
