// Codes and protocol on a real server: bytes that are not a request get INVALID_ARGUMENT naming
// the message (every method); an unknown method gets UNIMPLEMENTED with a message; a request_id
// reused for another request gets ALREADY_EXISTS; requests over a size limit get
// RESOURCE_EXHAUSTED; a Process call refuses messages after its start and streams its progress
// no more often than the server's interval; a TLS key that is not its
// certificate's stops the server at start-up with that said; a full queue's retry hint follows
// how long the running job has run.
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "grpcpp/generic/generic_stub.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "proto/retry_hint.h"
#include "server/grpc_log.h"
#include "server/job_manager.h"
#include "server/status_util.h"
#include "tests/server/http_util.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/start_gate.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::EndsWith;
using ::testing::HasSubstr;
using ::testing::StartsWith;

// Not a protobuf message: field 15 with a length far past the end.
const std::string kGarbage = std::string("\x7a\xff\xff\xff\x0f", 5) + "not a message";

// One call of `method` with the raw request bytes `request`, reading every response.
grpc::Status RawCall(const std::shared_ptr<grpc::Channel>& channel, const std::string& method,
                     const std::string& request) {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  SetDeadline(context);
  grpc::CompletionQueue queue;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call =
      stub.PrepareCall(&context, method, &queue);
  auto step = [&queue] {
    void* tag = nullptr;
    bool ok = false;
    return queue.Next(&tag, &ok) && ok;
  };
  int tag = 0;
  call->StartCall(&tag);
  step();
  grpc::Slice slice(request);
  grpc::ByteBuffer out(&slice, 1);
  call->Write(out, &tag);
  step();
  call->WritesDone(&tag);
  step();
  grpc::ByteBuffer in;
  for (;;) {
    call->Read(&in, &tag);
    if (!step()) break;
  }
  grpc::Status status;
  call->Finish(&status, &tag);
  step();
  return status;
}

class ProtocolTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server::ServerOptions options = TestServerOptions();
    options.max_clip_samples = 100'000;
    server_ = StartServer(options);
    ASSERT_NE(server_, nullptr);
    channel_ = Connect(server_->target());
    stub_ = v1::MotionService::NewStub(channel_);
  }

  std::unique_ptr<server::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(ProtocolTest, BytesThatAreNotARequestAreInvalidArgumentOnEveryMethod) {
  const std::vector<std::pair<std::string, std::string>> methods = {
      {"GetServerInfo", "GetServerInfo request: 18 bytes are not a valid tempokey.v1.GetServerInfoRequest message"},
      {"SubmitJob", "SubmitJob request: 18 bytes are not a valid tempokey.v1.SubmitJobRequest message"},
      {"GetJob", "GetJob request: 18 bytes are not a valid tempokey.v1.GetJobRequest message"},
      {"ListJobs", "ListJobs request: 18 bytes are not a valid tempokey.v1.ListJobsRequest message"},
      {"CancelJob", "CancelJob request: 18 bytes are not a valid tempokey.v1.CancelJobRequest message"},
      {"DeleteJob", "DeleteJob request: 18 bytes are not a valid tempokey.v1.DeleteJobRequest message"},
      {"WatchJob", "WatchJob request: 18 bytes are not a valid tempokey.v1.WatchJobRequest message"},
      {"GetJobResult", "GetJobResult request: 18 bytes are not a valid tempokey.v1.GetJobResultRequest message"},
      {"UploadClip", "upload message 1: 18 bytes are not a valid tempokey.v1.UploadClipRequest message"},
      {"Process", "Process message 1: 18 bytes are not a valid tempokey.v1.ProcessRequest message"},
  };
  ASSERT_EQ(kGarbage.size(), 18u);

  for (const auto& [method, message] : methods) {
    const grpc::Status status = RawCall(channel_, "/tempokey.v1.MotionService/" + method, kGarbage);

    EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, message)) << method;
  }
  TEMPOKEY_ASSERT_GRPC_OK(UploadClip(*stub_, MakeClip(1, 10)).status);  // still serving
}

// A message quoting a long input travels in a header, which gRPC clients refuse over 8 KiB: a
// 100 KB page token came back as "received initial metadata size exceeds limit". The server's
// messages are capped, so the client reads the server's own message.
TEST_F(ProtocolTest, AMessageQuotingALongInputReachesTheClientCapped) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ListJobsRequest request;
  request.set_page_token(std::string(100'000, 'x'));
  v1::ListJobsResponse response;

  const grpc::Status status = stub_->ListJobs(&context, request, &response);

  // The server's message: page_token "xxx...x" is not a token this server issued.
  const std::size_t full = 12 + 100'000 + 35;
  const std::string note =
      " ... (" + std::to_string(full - server::kMaxStatusMessageBytes) + " more bytes not shown)";
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(status.error_message(), StartsWith("page_token \"xxx"));
  EXPECT_THAT(status.error_message(), EndsWith(note));
  EXPECT_EQ(status.error_message().size(), server::kMaxStatusMessageBytes + note.size());
}

TEST(CappedStatusMessageTest, CutsAtACharacterBoundaryAndSaysHowMuchWasCut) {
  const std::string short_message(server::kMaxStatusMessageBytes, 'a');
  // A 2-byte character straddling the cap is left out whole.
  const std::string straddling = std::string(server::kMaxStatusMessageBytes - 1, 'a') + "\xc3\xa9" + "b";

  EXPECT_EQ(server::CappedStatusMessage(short_message), short_message);
  EXPECT_EQ(server::CappedStatusMessage(straddling),
            std::string(server::kMaxStatusMessageBytes - 1, 'a') + " ... (3 more bytes not shown)");
}

TEST_F(ProtocolTest, UnknownMethodIsUnimplementedWithAMessage) {
  const grpc::Status status = RawCall(channel_, "/tempokey.v1.MotionService/Teleport", "");

  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::UNIMPLEMENTED,
                                   "method /tempokey.v1.MotionService/Teleport is not served by "
                                   "tempokey-server"));
}

TEST_F(ProtocolTest, RequestIdReusedForAnotherRequestIsAlreadyExists) {
  const std::string clip_id = UploadClip(*stub_, MakeClip(1, 40)).response.clip_id();
  v1::SubmitJobRequest first = SubmitRequest(clip_id);
  first.set_request_id("5e0c7c6e-import-17");
  (*first.mutable_labels())["shot"] = "17";
  (*first.mutable_labels())["take"] = "3";
  v1::SubmitJobRequest other = first;
  *other.mutable_operations() = WrapOperations(2);
  v1::SubmitJobRequest invalid = first;
  invalid.clear_operations();

  const JobOutcome accepted = Submit(*stub_, first);
  const JobOutcome retried = Submit(*stub_, first);
  const JobOutcome different = Submit(*stub_, other);
  const JobOutcome broken = Submit(*stub_, invalid);

  TEMPOKEY_ASSERT_GRPC_OK(accepted.status);
  TEMPOKEY_ASSERT_GRPC_OK(retried.status);
  EXPECT_EQ(retried.job.job_id(), accepted.job.job_id());
  const std::string refusal = "request_id \"5e0c7c6e-import-17\" already named job " +
                              accepted.job.job_id() +
                              ", submitted with a different request; a retry must send the same "
                              "request, a new request needs a new request_id";
  EXPECT_THAT(different.status, GrpcStatusIs(grpc::StatusCode::ALREADY_EXISTS, refusal));
  EXPECT_THAT(broken.status, GrpcStatusIs(grpc::StatusCode::ALREADY_EXISTS, refusal));
  EXPECT_EQ(server_->jobs().job_count(), 1);
}

TEST_F(ProtocolTest, LabelsOverTheLimitAreRefusedBeforeTheRequestIdIsLookedUp) {
  // The request id's lookup digests the whole request, labels sorted: a request's labels are
  // checked against their limit first, so that a flood of them costs no sort. A retry of an
  // accepted request has labels within the limit, so it is answered as before.
  const std::string clip_id = UploadClip(*stub_, MakeClip(1, 40)).response.clip_id();
  v1::SubmitJobRequest first = SubmitRequest(clip_id);
  first.set_request_id("import-18");
  v1::SubmitJobRequest flooded = first;
  for (int i = 0; i < 65; ++i) (*flooded.mutable_labels())["k" + std::to_string(i)] = "v";

  const JobOutcome accepted = Submit(*stub_, first);
  const JobOutcome refused = Submit(*stub_, flooded);
  const JobOutcome retried = Submit(*stub_, first);

  TEMPOKEY_ASSERT_GRPC_OK(accepted.status);
  EXPECT_THAT(refused.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                           "labels has 65 entries, over the limit of 64"));
  TEMPOKEY_ASSERT_GRPC_OK(retried.status);
  EXPECT_EQ(retried.job.job_id(), accepted.job.job_id());
}

TEST_F(ProtocolTest, RequestsOverASizeLimitAreResourceExhausted) {
  const std::string clip_id = UploadClip(*stub_, MakeClip(1, 40)).response.clip_id();
  v1::SubmitJobRequest labels = SubmitRequest(clip_id);
  for (int i = 0; i < 65; ++i) (*labels.mutable_labels())["k" + std::to_string(i)] = "v";
  v1::SubmitJobRequest request_id = SubmitRequest(clip_id);
  request_id.set_request_id(std::string(257, 'r'));
  v1::SubmitJobRequest operations = SubmitRequest(clip_id, WrapOperations(65));
  v1::SubmitJobRequest too_big_clip;
  *too_big_clip.mutable_inline_clip() = wire::ClipToProto(MakeClip(4, 10'000));  // 150 000 samples
  *too_big_clip.mutable_operations() = WrapOperations();

  EXPECT_THAT(Submit(*stub_, labels).status,
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           "labels has 65 entries, over the limit of 64"));
  EXPECT_THAT(Submit(*stub_, request_id).status,
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           "request_id is 257 bytes, over the limit of 256"));
  EXPECT_THAT(Submit(*stub_, operations).status,
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           HasSubstr("the pipeline has 65 operations, over the limit of 64")));
  EXPECT_THAT(Submit(*stub_, too_big_clip).status,
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           "inline_clip: clip header: clip has 10000 frames x 15 channels, over "
                           "the limit of 100000 samples"));
  EXPECT_THAT(UploadClip(*stub_, MakeClip(4, 10'000)).status,
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           "clip header: clip has 10000 frames x 15 channels, over the limit of "
                           "100000 samples"));
}

// Reading a message costs about 66 bytes per message inside it: a header of 3 M empty markers
// (6 MB) took 198 MB to read before any limit looked at it. A header holding more than a million
// is refused from its tags, and the server goes on serving.
TEST_F(ProtocolTest, AMessageHoldingOverAMillionItemsIsRefusedBeforeItIsRead) {
  v1::UploadClipRequest header;
  header.mutable_header()->set_frame_time_seconds(1.0 / 30);
  header.mutable_header()->set_frame_count(2);
  for (int m = 0; m < 1'000'000; ++m) header.mutable_header()->add_markers();

  const UploadOutcome refused = UploadMessages(*stub_, {header});
  const UploadOutcome after = UploadClip(*stub_, MakeClip(1, 40));

  EXPECT_THAT(refused.status,
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           "upload message 1: more than 1000000 items inside one "
                           "tempokey.v1.UploadClipRequest (joints, channels, markers, knots, "
                           "names, unknown fields...), over the limit"));
  TEMPOKEY_ASSERT_GRPC_OK(after.status);
}

TEST(ProcessProtocolTest, ProcessRefusesAMessageAfterItsStart) {
  // The pipeline is held at its start, so the extra message is read before any result exists
  // and while the pipeline runs.
  server::ServerOptions options = TestServerOptions();
  options.metrics_address = "127.0.0.1:0";
  GatedServer gated(options);
  ASSERT_NE(gated.server, nullptr);
  grpc::ClientContext context;
  SetDeadline(context);
  auto process = gated.stub->Process(&context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(MakeClip(1, 40))) {
    ASSERT_TRUE(process->Write(request));
  }
  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = WrapOperations();
  ASSERT_TRUE(process->Write(start));
  // Running: its worker holds it at the gate (an abort of a call still queued never runs it).
  ASSERT_TRUE(gated.gate->WaitArrivals(1));
  // A second clip header after the start: the call takes one clip and one start.
  process->Write(ProcessClipRequests(MakeClip(1, 40))[0]);
  process->WritesDone();
  v1::ProcessResponse response;
  while (process->Read(&response)) {
  }
  const grpc::Status status = process->Finish();
  gated.gate->Open();

  // Header, 6 slices, start: the 9th message is refused, and the pipeline with it.
  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                                   "Process message 9 arrived after ProcessStart; a Process call "
                                   "takes one clip and one start, then the client only reads"));
  // The pipeline, stopped by that refusal, is counted as the call ended: failed, not cancelled
  // (a probe found "outcome=cancelled" logged for calls its client saw refused). Its count comes
  // once the worker has run it past the gate.
  const std::string failed = R"(tempokey_jobs_total{kind="process",outcome="failed"})";
  const std::string cancelled = R"(tempokey_jobs_total{kind="process",outcome="cancelled"})";
  std::map<std::string, double> samples;
  const auto deadline = std::chrono::steady_clock::now() + StartGate::kWaitLimit;
  do {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
    const std::optional<std::string> scrape = HttpGet(gated.server->metrics_port(), "/metrics");
    ASSERT_TRUE(scrape.has_value());
    samples = ParseSamples(*scrape);
  } while (Sample(samples, failed) + Sample(samples, cancelled) < 1 &&
           std::chrono::steady_clock::now() < deadline);
  EXPECT_EQ(Sample(samples, failed), 1.0);
  EXPECT_EQ(Sample(samples, cancelled), 0.0);
}

TEST(ProcessProtocolTest, AProcessCallStreamsOnlyItsFirstProgressWhileTheIntervalLasts) {
  server::ServerOptions options = TestServerOptions();
  options.process_progress_interval = std::chrono::hours(1);
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const core::Clip clip = MakeClip(8, 400);

  // 24 steps, a report each, all deferred within the hour and superseded by the result.
  const ProcessOutcome outcome = RunProcess(*stub, clip, WrapOperations(24));

  TEMPOKEY_ASSERT_GRPC_OK(outcome.status);
  const std::vector<v1::ProcessResponse>& responses = outcome.responses;
  ASSERT_GE(responses.size(), 2u);
  EXPECT_TRUE(responses[0].has_progress());
  EXPECT_EQ(responses[0].progress().progress(), 0.0);
  for (std::size_t i = 1; i < responses.size(); ++i) {
    EXPECT_TRUE(responses[i].has_result()) << "message " << i + 1 << " is progress";
  }
  absl::StatusOr<core::Clip> result = AssembleClipResult(outcome.ResultParts());
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, WrappedCopy(clip));
}

// A deferred report reaches the client when the interval ends, while the pipeline still runs: the
// worker is held right after offering its second report until the client has read a second
// message, which can then only be that report (sent when the interval ends if it was deferred, at
// once if the interval had already passed). Without the flush the client reads nothing more until
// the hold gives up (StartGate::kWaitLimit) or the call's deadline passes: the test then fails
// (checked by disabling the flush: it failed after 60 s).
TEST(ProcessProtocolTest, ADeferredProgressReachesTheClientWhileThePipelineIsHeld) {
  struct Offered {
    std::mutex mutex;
    std::vector<std::pair<double, std::string>> reports;
  };
  auto offered = std::make_shared<Offered>();
  auto gate = std::make_shared<StartGate>();
  server::ServerOptions options = TestServerOptions();
  options.process_progress_interval = std::chrono::milliseconds(20);
  options.test_hooks.on_process_progress = [offered, gate](double fraction,
                                                           std::string_view stage) {
    std::size_t count = 0;
    {
      std::lock_guard lock(offered->mutex);
      offered->reports.emplace_back(fraction, std::string(stage));
      count = offered->reports.size();
    }
    if (count == 2) gate->Arrive();
  };
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const core::Clip clip = MakeClip(8, 400);
  int read = 0;

  const ProcessOutcome outcome =
      RunProcess(*stub, clip, WrapOperations(24), [&](const v1::ProcessResponse&) {
        if (++read == 2) gate->Open();
      });
  gate->Open();

  TEMPOKEY_ASSERT_GRPC_OK(outcome.status);
  const std::vector<v1::ProcessResponse>& responses = outcome.responses;
  ASSERT_GE(responses.size(), 3u);
  std::lock_guard lock(offered->mutex);
  ASSERT_GE(offered->reports.size(), 2u);
  for (int i : {0, 1}) {
    SCOPED_TRACE(i);
    ASSERT_TRUE(responses[i].has_progress());
    EXPECT_EQ(responses[i].progress().progress(), offered->reports[i].first);
    EXPECT_EQ(responses[i].progress().stage(), offered->reports[i].second);
  }
  EXPECT_NE(offered->reports[1], offered->reports[0]);
  absl::StatusOr<core::Clip> result = AssembleClipResult(outcome.ResultParts());
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, WrappedCopy(clip));
}

TEST_F(ProtocolTest, HalfClosingAfterTheStartIsTheNormalEnd) {
  const ProcessOutcome outcome = RunProcess(*stub_, MakeClip(1, 40), WrapOperations());

  TEMPOKEY_ASSERT_GRPC_OK(outcome.status);
  absl::StatusOr<core::Clip> result = AssembleClipResult(outcome.ResultParts());
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(*result, WrappedCopy(MakeClip(1, 40)));
}

// A Process call the drain deadline stops ends UNAVAILABLE, which clients (the CLI's batch, the
// Python package) retry on another server; as CANCELLED a batch took it for a client's own
// cancel and failed the file.
TEST(ProcessProtocolTest, AProcessCallTheDrainDeadlineStopsEndsUnavailable) {
  auto gate = std::make_shared<StartGate>();
  server::ServerOptions options = TestServerOptions();
  options.workers = 1;
  options.test_hooks.on_job_start = [gate](std::string_view id) { gate->Arrive(id); };
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  ProcessOutcome outcome;
  std::thread call([&] { outcome = RunProcess(*stub, MakeClip(2, 50), WrapOperations()); });
  ASSERT_TRUE(gate->WaitArrivals(1));
  server->pool().RequestStopAll();  // what the drain does once its grace is over
  gate->Open();
  call.join();

  EXPECT_THAT(outcome.status, GrpcStatusIs(grpc::StatusCode::UNAVAILABLE,
                                           HasSubstr("its drain deadline passed while this call "
                                                     "ran; retry on another server")));
}

TEST(RetryHintTest, FullQueueHintIsAtLeastHowLongTheRunningJobHasRun) {
  server::ServerOptions options = TestServerOptions();
  options.workers = 1;
  options.queue_capacity = 1;
  GatedServer gated(options);
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 40)).response.clip_id();
  TEMPOKEY_ASSERT_GRPC_OK(Submit(*gated.stub, SubmitRequest(clip_id)).status);
  ASSERT_TRUE(gated.gate->WaitArrivals(1));
  const auto seen_running = std::chrono::steady_clock::now();
  TEMPOKEY_ASSERT_GRPC_OK(Submit(*gated.stub, SubmitRequest(clip_id)).status);  // queued

  grpc::ClientContext context;
  SetDeadline(context);
  v1::Job refused_job;
  const grpc::Status refused = gated.stub->SubmitJob(&context, SubmitRequest(clip_id), &refused_job);
  const auto running_at_least = std::chrono::steady_clock::now() - seen_running;
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto hint = trailers.find(wire::kRetryAfterMetadataKey);
  gated.gate->Open();

  EXPECT_THAT(refused, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED, HasSubstr("queue is full")));
  ASSERT_NE(hint, trailers.end());
  const std::optional<std::chrono::milliseconds> hint_ms =
      wire::ParseRetryAfter(std::string(hint->second.data(), hint->second.size()));
  ASSERT_TRUE(hint_ms.has_value());
  // No job has finished yet: the running job is expected to take as long again as it has run,
  // which is at least as long as this test has seen it running.
  EXPECT_GE(*hint_ms, std::chrono::duration_cast<std::chrono::milliseconds>(running_at_least));
}

// ---- TLS start-up ---------------------------------------------------------------------------------

// A self-signed certificate and its key, <stem>.pem and <stem>.key, made by the openssl tool.
bool MakeSelfSigned(const std::string& dir, const std::string& stem) {
  const ProcessResult run = RunProcess(
      {"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
       "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", dir + "/" + stem + ".key", "-out",
       dir + "/" + stem + ".pem", "-days", "2", "-subj", "/CN=localhost"},
      dir);
  return run.exit_code == 0;
}

TEST(TlsStartupTest, KeyOfAnotherCertificateIsNamedAtStartUp) {
  const std::string dir = MakeTempDir();
  ASSERT_TRUE(MakeSelfSigned(dir, "a"));
  ASSERT_TRUE(MakeSelfSigned(dir, "b"));
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/not.pem", "not a certificate\n").ok());

  const ProcessResult mismatched = RunProcess(
      {ServerBinary(), "--address=127.0.0.1:0", "--tls_cert=" + dir + "/a.pem",
       "--tls_key=" + dir + "/b.key"},
      dir, {}, std::chrono::seconds(60));
  const ProcessResult garbage = RunProcess(
      {ServerBinary(), "--address=127.0.0.1:0", "--tls_cert=" + dir + "/not.pem",
       "--tls_key=" + dir + "/a.key"},
      dir, {}, std::chrono::seconds(60));

  EXPECT_EQ(mismatched.exit_code, 1);
  EXPECT_THAT(mismatched.err, HasSubstr("cannot start: --tls_key " + dir +
                                        "/b.key is not the private key of the certificate in "
                                        "--tls_cert " + dir + "/a.pem"));
  EXPECT_THAT(mismatched.err, ::testing::Not(HasSubstr("address in use")));
  EXPECT_EQ(garbage.exit_code, 1);
  EXPECT_THAT(garbage.err, HasSubstr("--tls_cert " + dir + "/not.pem: holds no PEM certificate"));
}

// An encrypted key made the server print "Enter PEM pass phrase:" and wait on its stdin for ever
// (OpenSSL's default callback), and with the passphrase typed, gRPC refused the key and the
// server blamed the address ("address in use or invalid?"). Its stdin here is a FIFO the server
// itself holds open for writing, so a read would wait for ever and the 60 s limit would end it.
TEST(TlsStartupTest, AnEncryptedKeyIsRefusedWithoutAskingForAPassphrase) {
  const std::string dir = MakeTempDir();
  ASSERT_TRUE(MakeSelfSigned(dir, "a"));
  ASSERT_EQ(RunProcess({"/usr/bin/openssl", "pkey", "-in", dir + "/a.key", "-aes256", "-passout",
                        "pass:secret", "-out", dir + "/encrypted.key"},
                       dir).exit_code,
            0);
  ASSERT_EQ(::mkfifo((dir + "/stdin").c_str(), 0600), 0);

  const ProcessResult run = RunProcess(
      {"/bin/sh", "-c", "exec 3<>\"$0\"; exec \"$@\" < \"$0\"", dir + "/stdin", ServerBinary(),
       "--address=127.0.0.1:0", "--tls_cert=" + dir + "/a.pem",
       "--tls_key=" + dir + "/encrypted.key"},
      dir, {}, std::chrono::seconds(60));

  EXPECT_EQ(run.exit_code, 1) << run.err;
  EXPECT_THAT(run.err, HasSubstr("cannot start: --tls_key " + dir +
                                 "/encrypted.key: the key is encrypted, and gRPC takes an "
                                 "unencrypted PEM key"));
  EXPECT_THAT(run.out + run.err, ::testing::Not(HasSubstr("pass phrase")));
}

// An empty --tls_client_ca started a server that refused every client; a file of garbage (or a
// key) failed the bind as "address in use or invalid?".
TEST(TlsStartupTest, AClientCaFileWithoutACertificateIsNamedAtStartUp) {
  const std::string dir = MakeTempDir();
  ASSERT_TRUE(MakeSelfSigned(dir, "a"));
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/empty.pem", "").ok());

  std::vector<ProcessResult> runs;
  for (const std::string& ca : {dir + "/empty.pem", dir + "/a.key"}) {
    runs.push_back(RunProcess({ServerBinary(), "--address=127.0.0.1:0",
                               "--tls_cert=" + dir + "/a.pem", "--tls_key=" + dir + "/a.key",
                               "--tls_client_ca=" + ca},
                              dir, {}, std::chrono::seconds(60)));
  }

  ASSERT_EQ(runs.size(), 2u);
  for (const ProcessResult& run : runs) {
    EXPECT_EQ(run.exit_code, 1) << run.err;
    EXPECT_THAT(run.err, HasSubstr(": holds no PEM certificate"));
    EXPECT_THAT(run.err, ::testing::Not(HasSubstr("address in use")));
  }
  EXPECT_THAT(runs[0].err, HasSubstr("--tls_client_ca " + dir + "/empty.pem: "));
}

// A certificate whose extended key usage lacks serverAuth is refused by every standard client
// (RFC 5280 4.2.1.12); the server says so at start-up, and still starts.
TEST(TlsStartupTest, ACertificateNoClientAcceptsIsWarnedOfAtStartUp) {
  const std::string dir = MakeTempDir();
  ASSERT_EQ(RunProcess({"/usr/bin/openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                        "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", dir + "/c.key",
                        "-out", dir + "/c.pem", "-days", "2", "-subj", "/CN=localhost",
                        "-addext", "extendedKeyUsage=clientAuth"},
                       dir).exit_code,
            0);

  absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(
      dir, {"--tls_cert", dir + "/c.pem", "--tls_key", dir + "/c.key"});

  ASSERT_TRUE(server.ok()) << server.status();
  EXPECT_THAT((*server)->log(), HasSubstr("--tls_cert " + dir + "/c.pem: its extended key usage "
                                          "lacks serverAuth; clients will refuse it"));
}

// gRPC wrote each failed TLS handshake as its own raw "E1201 ..." line on stderr, at any
// --log_level and without limit: any peer could fill the log. Now its lines are the server's
// warnings ("grpc: ..."), at most kGrpcLinesPerWindow a window, and --log_level off silences
// them. Each peer below waits for the server to close its connection, so the server has handled
// its handshake before it is stopped and its log read. On a machine slow enough that the peers
// span several windows, each window may show its share and a count of the rest: the bound grows
// with the windows the peers took, so no load makes it fail (unlimited, it would be 60 lines).
TEST(GrpcLogTest, FailedHandshakesAreTheServersWarningsAndLimited) {
  const std::string dir = MakeTempDir();
  ASSERT_TRUE(MakeSelfSigned(dir, "a"));
  std::chrono::steady_clock::duration took{};
  auto fail_handshakes = [&](const std::vector<std::string>& flags, int count) {
    std::vector<std::string> all = {"--tls_cert", dir + "/a.pem", "--tls_key", dir + "/a.key"};
    all.insert(all.end(), flags.begin(), flags.end());
    absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(dir, all);
    EXPECT_TRUE(server.ok()) << server.status();
    if (!server.ok()) return std::string();
    const auto start = std::chrono::steady_clock::now();
    for (int i = 0; i < count; ++i) {
      const int fd = ConnectLoopback((*server)->port());
      if (fd < 0) continue;
      const std::string garbage(200, 'G');
      ::send(fd, garbage.data(), garbage.size(), MSG_NOSIGNAL);
      ReadToEnd(fd);
      ::close(fd);
    }
    (*server)->Stop();
    took = std::chrono::steady_clock::now() - start;
    return (*server)->log();
  };

  const std::string warned = fail_handshakes({}, 3 * server::kGrpcLinesPerWindow);
  // The windows the peers and the stop may have spanned, each its lines and one count line.
  const auto windows = 2 + took / server::kGrpcLogWindow;
  const std::string silent = fail_handshakes({"--log_level", "off"}, 5);

  int grpc_lines = 0;
  for (const absl::string_view line : absl::StrSplit(warned, '\n', absl::SkipEmpty())) {
    EXPECT_THAT(std::string(line), ::testing::StartsWith("[")) << "not the server's format";
    if (absl::StrContains(line, "] [warning] grpc: ")) ++grpc_lines;
  }
  EXPECT_GE(grpc_lines, 1) << warned;
  // 42 when the peers take under 10 s, as they do in well under a second: unlimited, 60.
  EXPECT_LE(grpc_lines, windows * (server::kGrpcLinesPerWindow + 1)) << warned;
  EXPECT_EQ(silent, "");
}

// Whether the peer ended the connection on `fd` (a FIN or a reset) before the socket's 60 s
// receive guard; false when the guard fired with the connection still open.
bool PeerEndsConnection(int fd) {
  char buffer[4096];
  while (true) {
    const ssize_t n = ::recv(fd, buffer, sizeof buffer, 0);
    if (n == 0) return true;
    if (n < 0) return errno == ECONNRESET;
  }
}

// gRPC's own handshake timeout is 120 s: connections that opened and sent nothing, or half a
// TLS hello, each held a socket and a handshake that long (200 of them in a probe). The server
// closes them at --handshake_timeout_seconds; here 1 s, against the tests' 60 s guard, so only a
// server that keeps them longer than a minute fails, however loaded the machine.
TEST(HandshakeTimeoutTest, AConnectionThatNeverFinishesItsHandshakeIsClosed) {
  const std::string dir = MakeTempDir();
  ASSERT_TRUE(MakeSelfSigned(dir, "a"));
  absl::StatusOr<std::unique_ptr<ServerProcess>> plain =
      ServerProcess::Start(dir, {"--handshake_timeout_seconds", "1"});
  absl::StatusOr<std::unique_ptr<ServerProcess>> tls = ServerProcess::Start(
      dir, {"--handshake_timeout_seconds", "1", "--tls_cert", dir + "/a.pem", "--tls_key",
            dir + "/a.key"});
  ASSERT_TRUE(plain.ok()) << plain.status();
  ASSERT_TRUE(tls.ok()) << tls.status();

  // Nothing at all, and the first 9 bytes of a TLS 1.2 ClientHello record (RFC 8446 5.1: a
  // handshake record of 512 bytes, its message header announcing 508).
  const int silent = ConnectLoopback((*plain)->port());
  const int half_hello = ConnectLoopback((*tls)->port());
  ASSERT_GE(silent, 0);
  ASSERT_GE(half_hello, 0);
  const std::string hello_start("\x16\x03\x01\x02\x00\x01\x00\x01\xfc", 9);
  ASSERT_EQ(::send(half_hello, hello_start.data(), hello_start.size(), MSG_NOSIGNAL), 9);

  EXPECT_TRUE(PeerEndsConnection(silent));
  EXPECT_TRUE(PeerEndsConnection(half_hello));
  ::close(silent);
  ::close(half_hello);
  // Both still serve calls that do handshake.
  const absl::StatusOr<int> live = CheckHealth(Connect((*plain)->target()), "");
  ASSERT_TRUE(live.ok()) << live.status();
  EXPECT_EQ(*live, 1);
  EXPECT_EQ((*plain)->Stop(), 0) << (*plain)->log();
  EXPECT_EQ((*tls)->Stop(), 0) << (*tls)->log();
}

TEST(HandshakeTimeoutTest, ATimeoutOutsideItsRangeIsAUsageError) {
  for (const char* value : {"0", "0.05", "-1", "3601", "nan"}) {
    const ProcessResult run =
        RunProcess({ServerBinary(), "--address=127.0.0.1:0",
                    std::string("--handshake_timeout_seconds=") + value},
                   MakeTempDir(), {}, std::chrono::seconds(60));
    EXPECT_EQ(run.exit_code, 2) << value << run.err;
    EXPECT_THAT(run.err, HasSubstr("--handshake_timeout_seconds must be in [0.1, 3600], got "))
        << value;
  }
}

}  // namespace
}  // namespace tempokey::testing
