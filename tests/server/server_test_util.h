// Helpers for server tests: a real server on 127.0.0.1:0 with real gRPC stubs, synthetic clips,
// status matchers, and small wrappers around the MotionService calls.
#ifndef TEMPOKEY_TESTS_SERVER_SERVER_TEST_UTIL_H_
#define TEMPOKEY_TESTS_SERVER_SERVER_TEST_UTIL_H_

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "gmock/gmock.h"
#include "grpcpp/client_context.h"
#include "grpcpp/create_channel.h"
#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/support/byte_buffer.h"
#include "grpcpp/security/credentials.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "proto/retry_hint.h"
#include "server/server.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/v1/motion_service.grpc.pb.h"
#include "tests/server/test_clips.h"

namespace grpc {
// gtest prints a grpc::Status by its code and message.
inline void PrintTo(const Status& status, std::ostream* os) {
  *os << "gRPC status " << static_cast<int>(status.error_code()) << " \"" << status.error_message()
      << "\"";
}
}  // namespace grpc

namespace tempokey::testing {

namespace v1 = ::tempokey::v1;

// Deadline for every test call: long enough never to fire on a working server, short enough
// that a hang fails the test instead of the CI job.
inline constexpr std::chrono::seconds kCallDeadline{60};

inline void SetDeadline(grpc::ClientContext& context,
                        std::chrono::seconds deadline = kCallDeadline) {
  context.set_deadline(std::chrono::system_clock::now() + deadline);
}

// ---- matchers -----------------------------------------------------------------------------------

MATCHER_P2(GrpcStatusIs, code, message_matcher,
           "gRPC status " + ::testing::PrintToString(code) + " whose message " +
               ::testing::DescribeMatcher<std::string>(message_matcher)) {
  if (arg.error_code() != code) {
    *result_listener << "code " << arg.error_code() << " message \"" << arg.error_message() << "\"";
    return false;
  }
  return ::testing::ExplainMatchResult(message_matcher, arg.error_message(), result_listener);
}

inline const absl::Status& StatusOf(const absl::Status& status) { return status; }
template <typename T>
const absl::Status& StatusOf(const absl::StatusOr<T>& status_or) {
  return status_or.status();
}

// Matches an absl::Status or absl::StatusOr<T> by code and message.
MATCHER_P2(StatusIs, code, message_matcher,
           "status " + ::testing::PrintToString(code) + " whose message " +
               ::testing::DescribeMatcher<std::string>(message_matcher)) {
  const absl::Status& status = StatusOf(arg);
  if (status.code() != code) {
    *result_listener << "status " << status.ToString();
    return false;
  }
  return ::testing::ExplainMatchResult(message_matcher, std::string(status.message()),
                                       result_listener);
}

#define TEMPOKEY_ASSERT_OK(expr)                              \
  do {                                                        \
    const auto& tempokey_assert_status_ = (expr);             \
    ASSERT_TRUE(tempokey_assert_status_.ok()) << tempokey_assert_status_; \
  } while (false)

#define TEMPOKEY_ASSERT_GRPC_OK(expr)                                               \
  do {                                                                              \
    const ::grpc::Status tempokey_assert_status_ = (expr);                          \
    ASSERT_TRUE(tempokey_assert_status_.ok())                                       \
        << tempokey_assert_status_.error_code() << ": "                            \
        << tempokey_assert_status_.error_message();                                 \
  } while (false)

inline google::protobuf::RepeatedPtrField<v1::Operation> WrapOperations(int count = 1) {
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  for (int i = 0; i < count; ++i) operations.Add()->mutable_convert()->set_wrap_rotations(true);
  return operations;
}

// ---- a real server ------------------------------------------------------------------------------

// Options for a test server: loopback port 0, small pool, short grace.
inline server::ServerOptions TestServerOptions() {
  server::ServerOptions options;
  options.address = "127.0.0.1:0";
  options.workers = 2;
  options.queue_capacity = 16;
  options.drain_grace = std::chrono::seconds(20);
  return options;
}

inline std::unique_ptr<server::Server> StartServer(server::ServerOptions options) {
  absl::StatusOr<std::unique_ptr<server::Server>> server = server::Server::Start(std::move(options));
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

// A plaintext channel to `target` with gRPC's default limits (4 MiB receive).
inline std::shared_ptr<grpc::Channel> Connect(const std::string& target) {
  return grpc::CreateChannel(target, grpc::InsecureChannelCredentials());
}

// One unary call of `method` ("/package.Service/Method") with the request's bytes, through the
// generic stub (no generated stubs needed): the response's bytes, or the call's error.
inline absl::StatusOr<std::string> CallUnaryBytes(const std::shared_ptr<grpc::Channel>& channel,
                                                  const std::string& method,
                                                  const std::string& request) {
  grpc::GenericStub stub(channel);
  grpc::Slice slice(request);
  grpc::ByteBuffer in(&slice, 1);
  grpc::ByteBuffer out;
  grpc::ClientContext context;
  SetDeadline(context);
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, method, grpc::StubOptions(), &in, &out,
                 [&done](grpc::Status status) { done.set_value(std::move(status)); });
  const grpc::Status status = done.get_future().get();
  if (!status.ok()) {
    return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
  }
  std::vector<grpc::Slice> slices;
  if (!out.Dump(&slices).ok()) return absl::InternalError("cannot read the response");
  std::string bytes;
  for (const grpc::Slice& s : slices) bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return bytes;
}

// grpc.health.v1.Health/Check for `service` (messages encoded by hand: Debian ships no health
// stubs): the ServingStatus number (1 SERVING, 2 NOT_SERVING) or the call's error.
inline absl::StatusOr<int> CheckHealth(const std::shared_ptr<grpc::Channel>& channel,
                                       const std::string& service) {
  std::string request;
  if (!service.empty()) {  // HealthCheckRequest { string service = 1; } (short names only)
    request.push_back('\x0a');
    request.push_back(static_cast<char>(service.size()));
    request += service;
  }
  const absl::StatusOr<std::string> bytes =
      CallUnaryBytes(channel, "/grpc.health.v1.Health/Check", request);
  if (!bytes.ok()) return bytes.status();
  if (bytes->empty()) return 0;  // proto3 default: UNKNOWN
  if (bytes->size() != 2 || (*bytes)[0] != '\x08') {
    return absl::InternalError("unexpected health response bytes");
  }
  return static_cast<int>((*bytes)[1]);
}

// ---- calls --------------------------------------------------------------------------------------

// The server's retry hint on a finished call (trailing metadata wire::kRetryAfterMetadataKey), or
// "" for none.
inline std::string RetryAfterOf(const grpc::ClientContext& context) {
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto hint = trailers.find(wire::kRetryAfterMetadataKey);
  return hint == trailers.end() ? "" : std::string(hint->second.data(), hint->second.size());
}

struct UploadOutcome {
  grpc::Status status;
  v1::UploadClipResponse response;
  std::string retry_after_ms;  // RetryAfterOf() the call
};

// Streams `requests` as one UploadClip call.
inline UploadOutcome UploadMessages(v1::MotionService::Stub& stub,
                                    const std::vector<v1::UploadClipRequest>& requests) {
  grpc::ClientContext context;
  SetDeadline(context);
  UploadOutcome outcome;
  auto writer = stub.UploadClip(&context, &outcome.response);
  for (const v1::UploadClipRequest& request : requests) {
    if (!writer->Write(request)) break;  // the server ended the call; Finish() says why
  }
  writer->WritesDone();
  outcome.status = writer->Finish();
  outcome.retry_after_ms = RetryAfterOf(context);
  return outcome;
}

// Header then slices of `slice_bytes`, in channel order unless `reverse_slices`.
inline std::vector<v1::UploadClipRequest> UploadRequests(const core::Clip& clip,
                                                         std::int64_t slice_bytes,
                                                         bool reverse_slices = false) {
  std::vector<v1::UploadClipRequest> requests(1);
  *requests[0].mutable_header() = wire::ClipHeaderToProto(clip);
  absl::Status sliced = wire::ForEachSamplesSlice(
      clip, slice_bytes, [&](v1::ChannelSamples&& samples) {
        v1::UploadClipRequest request;
        *request.mutable_samples() = std::move(samples);
        requests.push_back(std::move(request));
        return absl::OkStatus();
      });
  EXPECT_TRUE(sliced.ok()) << sliced;
  if (reverse_slices) std::reverse(requests.begin() + 1, requests.end());
  return requests;
}

inline UploadOutcome UploadClip(v1::MotionService::Stub& stub, const core::Clip& clip,
                                std::int64_t slice_bytes = wire::kDefaultSliceBytes) {
  return UploadMessages(stub, UploadRequests(clip, slice_bytes));
}

// A Process call's input before its start message: the clip header, then its sample slices.
inline std::vector<v1::ProcessRequest> ProcessClipRequests(const core::Clip& clip) {
  std::vector<v1::ProcessRequest> requests(1);
  *requests[0].mutable_header() = wire::ClipHeaderToProto(clip);
  const absl::Status sliced = wire::ForEachSamplesSlice(
      clip, wire::kDefaultSliceBytes, [&](v1::ChannelSamples&& samples) {
        *requests.emplace_back().mutable_samples() = std::move(samples);
        return absl::OkStatus();
      });
  EXPECT_TRUE(sliced.ok()) << sliced;
  return requests;
}

// A whole Process call: `clip`, a start with `operations`, the half-close, then every response.
struct ProcessOutcome {
  grpc::Status status;
  std::vector<v1::ProcessResponse> responses;

  // The result parts among the responses, in order.
  std::vector<v1::ResultPart> ResultParts() const {
    std::vector<v1::ResultPart> parts;
    for (const v1::ProcessResponse& response : responses) {
      if (response.has_result()) parts.push_back(response.result());
    }
    return parts;
  }
};

// `on_read` (optional) sees each response as it arrives, before the next is read.
inline ProcessOutcome RunProcess(
    v1::MotionService::Stub& stub, const core::Clip& clip,
    const google::protobuf::RepeatedPtrField<v1::Operation>& operations,
    const std::function<void(const v1::ProcessResponse&)>& on_read = {}) {
  ProcessOutcome outcome;
  grpc::ClientContext context;
  SetDeadline(context);
  auto process = stub.Process(&context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(clip)) {
    EXPECT_TRUE(process->Write(request));
  }
  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = operations;
  EXPECT_TRUE(process->Write(start));
  process->WritesDone();
  v1::ProcessResponse response;
  while (process->Read(&response)) {
    if (on_read) on_read(response);
    outcome.responses.push_back(response);
  }
  outcome.status = process->Finish();
  return outcome;
}

struct JobOutcome {
  grpc::Status status;
  v1::Job job;
  std::string retry_after_ms;  // RetryAfterOf() the call
};

inline JobOutcome Submit(v1::MotionService::Stub& stub, const v1::SubmitJobRequest& request) {
  grpc::ClientContext context;
  SetDeadline(context);
  JobOutcome outcome;
  outcome.status = stub.SubmitJob(&context, request, &outcome.job);
  outcome.retry_after_ms = RetryAfterOf(context);
  return outcome;
}

inline v1::SubmitJobRequest SubmitRequest(
    const std::string& clip_id,
    const google::protobuf::RepeatedPtrField<v1::Operation>& operations = WrapOperations()) {
  v1::SubmitJobRequest request;
  request.set_clip_id(clip_id);
  *request.mutable_operations() = operations;
  return request;
}

inline JobOutcome GetJob(v1::MotionService::Stub& stub, const std::string& job_id) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::GetJobRequest request;
  request.set_job_id(job_id);
  JobOutcome outcome;
  outcome.status = stub.GetJob(&context, request, &outcome.job);
  return outcome;
}

struct WatchOutcome {
  grpc::Status status;
  std::vector<v1::Job> updates;
  std::string retry_after_ms;  // RetryAfterOf() the call
};

// Reads a whole WatchJob stream; `on_update` (optional) sees each update as it arrives.
// `deadline` only keeps a hang from holding the test.
inline WatchOutcome WatchJob(v1::MotionService::Stub& stub, const std::string& job_id,
                             const std::function<void(const v1::Job&)>& on_update = {},
                             std::chrono::seconds deadline = kCallDeadline) {
  grpc::ClientContext context;
  SetDeadline(context, deadline);
  v1::WatchJobRequest request;
  request.set_job_id(job_id);
  WatchOutcome outcome;
  auto reader = stub.WatchJob(&context, request);
  v1::Job job;
  while (reader->Read(&job)) {
    outcome.updates.push_back(job);
    if (on_update) on_update(job);
  }
  outcome.status = reader->Finish();
  outcome.retry_after_ms = RetryAfterOf(context);
  return outcome;
}

// Watches until the job is terminal and returns the last snapshot.
inline v1::Job WaitForJob(v1::MotionService::Stub& stub, const std::string& job_id,
                          std::chrono::seconds deadline = kCallDeadline) {
  WatchOutcome watch = WatchJob(stub, job_id, {}, deadline);
  EXPECT_TRUE(watch.status.ok()) << watch.status.error_message();
  return watch.updates.empty() ? v1::Job() : watch.updates.back();
}

struct ResultOutcome {
  grpc::Status status;
  std::vector<v1::ResultPart> parts;
  std::int64_t largest_part_bytes = 0;
};

inline ResultOutcome GetResult(v1::MotionService::Stub& stub, const std::string& job_id,
                               std::int32_t slice_bytes = 0) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::GetJobResultRequest request;
  request.set_job_id(job_id);
  request.set_slice_bytes(slice_bytes);
  ResultOutcome outcome;
  auto reader = stub.GetJobResult(&context, request);
  v1::ResultPart part;
  while (reader->Read(&part)) {
    outcome.largest_part_bytes =
        std::max<std::int64_t>(outcome.largest_part_bytes, static_cast<std::int64_t>(part.ByteSizeLong()));
    outcome.parts.push_back(part);
  }
  outcome.status = reader->Finish();
  return outcome;
}

// Rebuilds the sampled clip of a result stream (header first, then samples).
inline absl::StatusOr<core::Clip> AssembleClipResult(const std::vector<v1::ResultPart>& parts,
                                                     core::ClipLimits limits = {}) {
  wire::ClipAssembler assembler(limits);
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const v1::ResultPart& part = parts[i];
    absl::Status status;
    if (part.has_header()) {
      if (i != 0) return absl::InvalidArgumentError("header not first");
      if (!part.header().has_clip()) return absl::InvalidArgumentError("not a sampled clip");
      status = assembler.AddHeader(part.header().clip());
    } else if (part.has_samples()) {
      status = assembler.AddSamples(part.samples());
    } else {
      return absl::InvalidArgumentError("unexpected part");
    }
    if (!status.ok()) return status;
  }
  return std::move(assembler).Finish();
}

// Rebuilds the keyed clip of a result stream (header first, then curve pieces).
inline absl::StatusOr<core::KeyedClip> AssembleKeyedResult(const std::vector<v1::ResultPart>& parts) {
  v1::KeyedClip keyed;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const v1::ResultPart& part = parts[i];
    if (part.has_header()) {
      if (i != 0 || !part.header().has_keyed_clip()) {
        return absl::InvalidArgumentError("expected a keyed-clip header first");
      }
      *keyed.mutable_header() = part.header().keyed_clip();
    } else if (part.has_curve()) {
      *keyed.add_curves() = part.curve();
    } else {
      return absl::InvalidArgumentError("unexpected part in a keyed result");
    }
  }
  return wire::KeyedClipFromProto(keyed);
}

// A server whose workers stop at job start until the test opens the gate.
struct GatedServer {
  std::shared_ptr<StartGate> gate = std::make_shared<StartGate>();
  std::unique_ptr<server::Server> server;
  std::unique_ptr<v1::MotionService::Stub> stub;

  explicit GatedServer(server::ServerOptions options = TestServerOptions()) {
    options.test_hooks.on_job_start = [g = gate](std::string_view id) { g->Arrive(id); };
    server = StartServer(std::move(options));
    if (server != nullptr) stub = v1::MotionService::NewStub(Connect(server->target()));
  }
  ~GatedServer() {
    gate->Open();
    server.reset();
  }
};

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_SERVER_SERVER_TEST_UTIL_H_
