// Idle and slow peers: a stream whose client stops sending, or stops reading, is ended after
// --stream_idle_timeout_seconds and its stream slot freed. The tests wait for the server to end
// the call (a blocking Finish, or the server's open-stream count polled with a deadline that
// only bounds a hang); no assertion depends on how fast anything ran.
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "grpcpp/generic/generic_stub.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

// Waits (bounded) until the in-process server holds `count` streams.
bool WaitForOpenStreams(const server::Server& server, int count) {
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  while (server.open_streams() != count) {
    if (std::chrono::steady_clock::now() > deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

class IdleStreamProcessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(
        MakeTempDir(), {"--stream_idle_timeout_seconds=1", "--max_concurrent_streams=1"});
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = *std::move(server);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }

  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(IdleStreamProcessTest, UploadThatStopsSendingEndsWithDeadlineExceededAndFreesItsSlot) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::UploadClipResponse response;
  auto upload = stub_->UploadClip(&context, &response);
  std::vector<v1::UploadClipRequest> requests = UploadRequests(MakeClip(1, 100), 8 * 10);
  ASSERT_TRUE(upload->Write(requests[0]));
  ASSERT_TRUE(upload->Write(requests[1]));

  // Nothing more is sent: the server ends the call (Finish blocks until it does).
  const grpc::Status idle = upload->Finish();
  // The only stream slot (--max_concurrent_streams=1) is free again.
  const UploadOutcome next = UploadClip(*stub_, MakeClip(1, 100));

  EXPECT_THAT(idle, GrpcStatusIs(grpc::StatusCode::DEADLINE_EXCEEDED,
                                 "UploadClip: the client sent nothing for 1 s "
                                 "(--stream_idle_timeout_seconds); the call was ended"));
  TEMPOKEY_ASSERT_GRPC_OK(next.status);
}

TEST_F(IdleStreamProcessTest, ProcessThatStopsBeforeItsStartEndsWithDeadlineExceeded) {
  grpc::ClientContext context;
  SetDeadline(context);
  auto process = stub_->Process(&context);
  ASSERT_TRUE(process->Write(ProcessClipRequests(MakeClip(1, 50))[0]));  // the header only

  v1::ProcessResponse response;
  const bool got_response = process->Read(&response);
  const grpc::Status idle = process->Finish();

  EXPECT_FALSE(got_response);
  EXPECT_THAT(idle, GrpcStatusIs(grpc::StatusCode::DEADLINE_EXCEEDED,
                                 HasSubstr("Process: the client sent nothing for 1 s")));
  TEMPOKEY_ASSERT_GRPC_OK(UploadClip(*stub_, MakeClip(1, 100)).status);
}

// Reflection ended its idle streams with a cancel ("Cancelled on the server side"), unlike every
// other stream.
TEST_F(IdleStreamProcessTest, ReflectionStreamThatSendsNothingEndsWithDeadlineExceeded) {
  grpc::GenericStub stub(Connect(server_->target()));
  grpc::ClientContext context;
  SetDeadline(context);
  grpc::CompletionQueue queue;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call = stub.PrepareCall(
      &context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &queue);
  int tag = 0;
  void* got = nullptr;
  bool ok = false;
  call->StartCall(&tag);
  ASSERT_TRUE(queue.Next(&got, &ok));
  grpc::Status idle;
  call->Finish(&idle, &tag);  // nothing is sent: completes once the server ends the call
  ASSERT_TRUE(queue.Next(&got, &ok));

  EXPECT_THAT(idle, GrpcStatusIs(grpc::StatusCode::DEADLINE_EXCEEDED,
                                 "ServerReflectionInfo: the client sent nothing for 1 s "
                                 "(--stream_idle_timeout_seconds); the call was ended"));
  TEMPOKEY_ASSERT_GRPC_OK(UploadClip(*stub_, MakeClip(1, 100)).status);  // its slot is free
}

TEST(IdleStreamActiveTest, ActiveUploadsAreNotCutShort) {
  // An upload that keeps sending: the idle timer restarts at each message and never ends it. The
  // timeout is 10 s, not the 1 s above, so only a stall of that long between two messages of one
  // client (a broken machine, not a loaded one) could end it; IdleReaperTest pins the timer itself.
  absl::StatusOr<std::unique_ptr<ServerProcess>> server =
      ServerProcess::Start(MakeTempDir(), {"--stream_idle_timeout_seconds=10"});
  ASSERT_TRUE(server.ok()) << server.status();
  auto stub = v1::MotionService::NewStub(Connect((*server)->target()));

  const UploadOutcome upload = UploadClip(*stub, MakeClip(2, 20'000), 8 * 1000);

  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
}

TEST(IdleStreamTest, ClientThatStopsReadingAResultIsCancelledAndItsSlotFreed) {
  server::ServerOptions options = TestServerOptions();
  options.stream_idle_timeout = std::chrono::milliseconds(500);
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  // A 30 MB result: far more than HTTP/2 flow control lets through to a client that reads
  // nothing, so the server's writes stall.
  const UploadOutcome upload = UploadClip(*stub, MakeClip(100, 12'500));
  ASSERT_TRUE(upload.status.ok()) << upload.status.error_message();
  const JobOutcome job = Submit(*stub, SubmitRequest(upload.response.clip_id()));
  ASSERT_EQ(WaitForJob(*stub, job.job.job_id()).state(), v1::JOB_STATE_SUCCEEDED);
  ASSERT_TRUE(WaitForOpenStreams(*server, 0));

  grpc::ClientContext context;
  SetDeadline(context);
  v1::GetJobResultRequest request;
  request.set_job_id(job.job.job_id());
  auto reader = stub->GetJobResult(&context, request);
  ASSERT_TRUE(WaitForOpenStreams(*server, 1));
  // Nothing is read: the server cancels the call once a write has waited for the timeout.
  const bool released = WaitForOpenStreams(*server, 0);
  context.TryCancel();
  reader->Finish();

  EXPECT_TRUE(released);
}

}  // namespace
}  // namespace tempokey::testing
