#include "client/client.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <random>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "proto/arena_message.h"
#include "proto/bearer_token.h"
#include "proto/jobs_convert.h"
#include "proto/loopback.h"
#include "proto/operations_convert.h"
#include "proto/scratch_arena.h"
#include "grpcpp/client_context.h"
#include "grpcpp/create_channel.h"
#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/security/credentials.h"
#include "grpcpp/support/byte_buffer.h"
#include "grpcpp/support/channel_arguments.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using Clock = std::chrono::system_clock;

constexpr std::array<const char*, 6> kUnaryMethods = {
    "GetServerInfo", "SubmitJob", "GetJob", "ListJobs", "CancelJob", "DeleteJob"};

// Seconds as a service-config duration ("0.1s").
std::string ConfigDuration(double seconds) { return absl::StrFormat("%.3fs", seconds); }

int Milliseconds(double seconds) {
  return static_cast<int>(std::clamp(seconds * 1000.0, 1.0, 2.0e9));
}

// A fresh random idempotency key in UUID v4 form.
std::string NewRequestId() {
  thread_local std::mt19937_64 engine{std::random_device{}()};
  std::array<std::uint8_t, 16> bytes;
  for (std::size_t i = 0; i < bytes.size(); i += 8) {
    std::uint64_t word = engine();
    for (std::size_t j = 0; j < 8; ++j) bytes[i + j] = static_cast<std::uint8_t>(word >> (8 * j));
  }
  bytes[6] = static_cast<std::uint8_t>((bytes[6] & 0x0f) | 0x40);
  bytes[8] = static_cast<std::uint8_t>((bytes[8] & 0x3f) | 0x80);
  std::string out;
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    if (i == 4 || i == 6 || i == 8 || i == 10) out.push_back('-');
    out += absl::StrFormat("%02x", bytes[i]);
  }
  return out;
}

std::shared_ptr<grpc::ChannelCredentials> MakeCredentials(const TlsOptions& tls) {
  if (!tls.enabled) return grpc::InsecureChannelCredentials();
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = tls.root_ca_pem;
  ssl.pem_cert_chain = tls.cert_chain_pem;
  ssl.pem_private_key = tls.private_key_pem;
  return grpc::SslCredentials(ssl);
}

// Outcome of one attempt of a streaming call: its status and whether any response arrived
// (after which retrying would repeat what the caller has already seen).
struct Attempt {
  absl::Status status;
  bool received = false;
};

}  // namespace

absl::Status ValidateClientOptions(const ClientOptions& options) {
  if (options.target.empty()) return absl::InvalidArgumentError("the server target is empty");
  TEMPOKEY_RETURN_IF_ERROR(core::Annotate(wire::CheckTargetPorts(options.target),
                                          absl::StrCat("server ", options.target)));
  if (!std::isfinite(options.timeout_seconds)) {
    return absl::InvalidArgumentError("the timeout must be a finite number of seconds");
  }
  if (options.max_receive_message_bytes <= 0) {
    return absl::InvalidArgumentError("the receive limit must be > 0 bytes");
  }
  if (options.max_attempts < 1 || options.max_attempts > 10) {
    return absl::InvalidArgumentError(
        absl::StrCat("attempts must be in 1..10, got ", options.max_attempts));
  }
  if (!(options.initial_backoff_seconds > 0) || !(options.max_backoff_seconds > 0) ||
      !std::isfinite(options.max_backoff_seconds)) {
    return absl::InvalidArgumentError("retry backoff must be a positive number of seconds");
  }
  if (options.load_balancing_policy != "round_robin" &&
      options.load_balancing_policy != "pick_first") {
    return absl::InvalidArgumentError(absl::StrCat("load balancing policy '",
                                                   options.load_balancing_policy,
                                                   "' is not round_robin or pick_first"));
  }
  if (!std::isfinite(options.keepalive_time_seconds) ||
      !(options.keepalive_timeout_seconds > 0)) {
    return absl::InvalidArgumentError("keepalive times must be finite and the timeout > 0");
  }
  if (options.tls.cert_chain_pem.empty() != options.tls.private_key_pem.empty()) {
    return absl::InvalidArgumentError(
        "a client certificate needs its private key and a key its certificate");
  }
  // gRPC aborts the whole process on a call whose metadata is no valid header value.
  TEMPOKEY_RETURN_IF_ERROR(wire::CheckBearerToken(options.bearer_token));
  if (!options.bearer_token.empty() && !options.tls.enabled && !options.allow_plaintext_token &&
      !wire::IsLoopbackTarget(options.target)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "refusing to send the bearer token in cleartext to ", options.target,
        ", which is not on this machine: connect with TLS (the CLI's --tls or --ca), or allow it "
        "(--allow-plaintext-token) only where the network itself is trusted, as in a service "
        "mesh that encrypts it"));
  }
  if (!options.tls.enabled && (!options.tls.root_ca_pem.empty() ||
                               !options.tls.cert_chain_pem.empty() ||
                               !options.tls.target_name_override.empty())) {
    return absl::InvalidArgumentError("TLS settings were given but TLS is not enabled");
  }
  if (options.slice_bytes < 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("the slice size must be >= 8 bytes, got ", options.slice_bytes));
  }
  return absl::OkStatus();
}

std::string ServiceConfigJson(const ClientOptions& options) {
  std::vector<std::string> names;
  for (const char* method : kUnaryMethods) {
    names.push_back(absl::StrFormat(R"({"service":"%s","method":"%s"})", kMotionServiceName, method));
  }
  names.push_back(R"({"service":"grpc.health.v1.Health","method":"Check"})");
  std::string method_config;
  if (options.max_attempts > 1) {
    method_config = absl::StrFormat(
        R"(,"methodConfig":[{"name":[%s],"retryPolicy":{"maxAttempts":%d,)"
        R"("initialBackoff":"%s","maxBackoff":"%s","backoffMultiplier":2,)"
        R"("retryableStatusCodes":["UNAVAILABLE"]}}])",
        absl::StrJoin(names, ","), options.max_attempts,
        ConfigDuration(options.initial_backoff_seconds),
        ConfigDuration(options.max_backoff_seconds));
  }
  return absl::StrFormat(R"({"loadBalancingConfig":[{"%s":{}}]%s})",
                         options.load_balancing_policy, method_config);
}

absl::Status FromGrpcStatus(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message());
}

// ---- Client -------------------------------------------------------------------------------------

struct Client::CallScope {
  std::optional<Clock::time_point> deadline;
};

absl::StatusOr<std::unique_ptr<Client>> Client::Connect(const ClientOptions& options) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClientOptions(options));
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options.max_receive_message_bytes);
  args.SetServiceConfigJSON(ServiceConfigJson(options));
  args.SetInt(GRPC_ARG_ENABLE_RETRIES, options.max_attempts > 1 ? 1 : 0);
  // Each Client its own connections: gRPC otherwise shares one TCP connection among all channels
  // with equal arguments, and clients meant to work in parallel (batch workers, load tests)
  // then queue behind each other on it (service_bench: 178 vs 308 jobs/s with 16 clients).
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);
  if (options.keepalive_time_seconds > 0) {
    args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, Milliseconds(options.keepalive_time_seconds));
    args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, Milliseconds(options.keepalive_timeout_seconds));
    args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 0);
  }
  if (options.tls.enabled && !options.tls.target_name_override.empty()) {
    args.SetSslTargetNameOverride(options.tls.target_name_override);
  }
  args.SetUserAgentPrefix(absl::StrCat("tempokey-client/", TEMPOKEY_VERSION));
  std::shared_ptr<grpc::Channel> channel =
      grpc::CreateCustomChannel(options.target, MakeCredentials(options.tls), args);
  if (channel == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat("cannot create a channel to '", options.target, "'"));
  }
  return std::make_unique<Client>(std::move(channel), options);
}

Client::Client(std::shared_ptr<grpc::Channel> channel, ClientOptions options)
    : channel_(std::move(channel)),
      options_(std::move(options)),
      stub_(v1::MotionService::NewStub(channel_)) {}

Client::CallScope Client::BeginCall() const {
  CallScope scope;
  if (options_.timeout_seconds > 0) {
    scope.deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(options_.timeout_seconds));
  }
  return scope;
}

void Client::PrepareContext(const CallScope& scope, grpc::ClientContext& context) const {
  if (scope.deadline) context.set_deadline(*scope.deadline);
  if (!options_.bearer_token.empty()) {
    context.AddMetadata("authorization", absl::StrCat("Bearer ", options_.bearer_token));
  }
}

namespace {

// Streams `clip`'s samples on `writer`, as SampleSlices batches when the server takes them,
// otherwise one ChannelSamples per message (servers of the first v1).
template <typename Request, typename Writer>
absl::Status WriteSamples(const core::Clip& clip, std::int64_t slice_bytes, bool batched,
                          Writer& writer) {
  if (batched) {
    // One request in this thread's scratch arena for every batch, cleared between them so that
    // each batch reuses the last one's slices (SamplesBatcher).
    wire::ScratchMessage<Request> request;
    wire::SamplesBatcher batches(clip, slice_bytes);
    while (batches.Next(request->mutable_sample_slices())) {
      if (!writer.Write(*request)) return absl::AbortedError("stream closed");
      request->mutable_sample_slices()->Clear();
    }
    return absl::OkStatus();
  }
  Request request;
  return wire::ForEachSamplesSlice(clip, slice_bytes, [&](v1::ChannelSamples&& samples) {
    *request.mutable_samples() = std::move(samples);
    if (!writer.Write(request)) return absl::AbortedError("stream closed");
    return absl::OkStatus();
  });
}

// Carries the server's retry hint (trailing metadata) over to `status` as its payload.
absl::Status WithRetryHint(absl::Status status, const grpc::ClientContext& context) {
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto hint = trailers.find(wire::kRetryAfterMetadataKey);
  if (hint == trailers.end()) return status;
  if (std::optional<std::chrono::milliseconds> delay =
          wire::ParseRetryAfter(std::string_view(hint->second.data(), hint->second.size()))) {
    wire::SetRetryAfter(status, *delay);
  }
  return status;
}

// Runs `attempt` until it succeeds, fails with another code than UNAVAILABLE, fails after a
// response arrived, runs out of attempts, or the next backoff would pass the deadline.
template <class AttemptFn>
absl::Status RetryWhileUnavailable(const ClientOptions& options,
                                   std::optional<Clock::time_point> deadline, AttemptFn attempt) {
  double backoff = options.initial_backoff_seconds;
  thread_local std::mt19937_64 engine{std::random_device{}()};
  for (int i = 1;; ++i) {
    Attempt result = attempt();
    if (result.status.ok() || result.status.code() != absl::StatusCode::kUnavailable ||
        result.received || i >= options.max_attempts) {
      return result.status;
    }
    // Full jitter, as gRPC's own retries do, so clients that failed together spread out.
    std::uniform_real_distribution<double> jitter(0.0, backoff);
    const auto pause = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(jitter(engine)));
    if (deadline && Clock::now() + pause >= *deadline) return result.status;
    std::this_thread::sleep_for(pause);
    backoff = std::min(backoff * 2.0, options.max_backoff_seconds);
  }
}

template <class Stub, class Request, class Response>
absl::StatusOr<Response> CallUnary(
    grpc::Status (Stub::*method)(grpc::ClientContext*, const Request&, Response*), Stub& stub,
    grpc::ClientContext& context, const Request& request) {
  Response response;
  grpc::Status status = (stub.*method)(&context, request, &response);
  if (!status.ok()) return WithRetryHint(FromGrpcStatus(status), context);
  return response;
}

}  // namespace

absl::StatusOr<v1::ServerInfo> Client::GetServerInfo() const {
  grpc::ClientContext context;
  PrepareContext(BeginCall(), context);
  return CallUnary(&v1::MotionService::Stub::GetServerInfo, *stub_, context,
                   v1::GetServerInfoRequest());
}

bool Client::ServerTakesSampleSlices() const {
  const int known = sample_slices_.load(std::memory_order_relaxed);
  if (known != kFeatureUnknown) return known == kFeatureOn;
  absl::StatusOr<v1::ServerInfo> info = GetServerInfo();
  // Unknown stays unknown when the server cannot say now; the call sends single slices, which
  // every server takes, and the next call asks again.
  if (!info.ok()) return false;
  const bool on = std::find(info->features().begin(), info->features().end(),
                            wire::kFeatureSampleSlices) != info->features().end();
  sample_slices_.store(on ? kFeatureOn : kFeatureOff, std::memory_order_relaxed);
  return on;
}

absl::StatusOr<HealthState> Client::CheckHealth(const std::string& service) const {
  grpc::GenericStub generic(channel_);
  grpc::ClientContext context;
  PrepareContext(BeginCall(), context);
  const std::string request_bytes = EncodeHealthCheckRequest(service);
  grpc::Slice slice(request_bytes);
  grpc::ByteBuffer request(&slice, 1);
  grpc::ByteBuffer response;

  std::mutex mutex;
  std::condition_variable done_cv;
  bool done = false;
  grpc::Status status;
  generic.UnaryCall(&context, kHealthCheckMethod, grpc::StubOptions(), &request, &response,
                    [&](grpc::Status s) {
                      std::lock_guard lock(mutex);
                      status = std::move(s);
                      done = true;
                      done_cv.notify_one();
                    });
  {
    // The call always completes: on success, error or its deadline.
    std::unique_lock lock(mutex);
    done_cv.wait(lock, [&] { return done; });
  }
  if (!status.ok()) return FromGrpcStatus(status);

  std::vector<grpc::Slice> slices;
  if (grpc::Status dump = response.Dump(&slices); !dump.ok()) return FromGrpcStatus(dump);
  std::string bytes;
  for (const grpc::Slice& s : slices) {
    bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  }
  return DecodeHealthCheckResponse(bytes);
}

absl::StatusOr<v1::UploadClipResponse> Client::UploadClip(const core::Clip& clip) const {
  TEMPOKEY_RETURN_IF_ERROR(core::ValidateClip(clip));
  const CallScope scope = BeginCall();
  v1::UploadClipResponse response;
  v1::UploadClipRequest header_request;
  *header_request.mutable_header() = wire::ClipHeaderToProto(clip);
  const bool batched = ServerTakesSampleSlices();

  TEMPOKEY_RETURN_IF_ERROR(RetryWhileUnavailable(options_, scope.deadline, [&]() -> Attempt {
    grpc::ClientContext context;
    PrepareContext(scope, context);
    std::unique_ptr<grpc::ClientWriter<v1::UploadClipRequest>> writer =
        stub_->UploadClip(&context, &response);
    // A failed Write means the server has ended the call; Finish() tells why.
    bool open = writer->Write(header_request);
    if (open) {
      absl::Status sent = WriteSamples<v1::UploadClipRequest>(clip, options_.slice_bytes,
                                                              batched, *writer);
      open = sent.ok();
    }
    if (open) writer->WritesDone();
    return Attempt{WithRetryHint(FromGrpcStatus(writer->Finish()), context), false};
  }));
  return response;
}

absl::StatusOr<v1::Job> Client::Submit(v1::SubmitJobRequest request,
                                       std::span<const core::PipelineStep> steps,
                                       const SubmitOptions& submit) const {
  for (const core::PipelineStep& step : steps) {
    *request.add_operations() = wire::PipelineStepToProto(step);
  }
  for (const auto& [key, value] : submit.labels) (*request.mutable_labels())[key] = value;
  request.set_request_id(submit.request_id.empty() ? NewRequestId() : submit.request_id);
  grpc::ClientContext context;
  PrepareContext(BeginCall(), context);
  return CallUnary(&v1::MotionService::Stub::SubmitJob, *stub_, context, request);
}

absl::StatusOr<v1::Job> Client::SubmitJob(const std::string& clip_id,
                                          std::span<const core::PipelineStep> steps,
                                          const SubmitOptions& submit) const {
  v1::SubmitJobRequest request;
  request.set_clip_id(clip_id);
  return Submit(std::move(request), steps, submit);
}

absl::StatusOr<v1::Job> Client::SubmitInlineJob(const core::Clip& clip,
                                                std::span<const core::PipelineStep> steps,
                                                const SubmitOptions& submit) const {
  TEMPOKEY_RETURN_IF_ERROR(core::ValidateClip(clip));
  v1::SubmitJobRequest request;
  *request.mutable_inline_clip() = wire::ClipToProto(clip);
  return Submit(std::move(request), steps, submit);
}

absl::StatusOr<v1::Job> Client::GetJob(const std::string& job_id) const {
  v1::GetJobRequest request;
  request.set_job_id(job_id);
  grpc::ClientContext context;
  PrepareContext(BeginCall(), context);
  return CallUnary(&v1::MotionService::Stub::GetJob, *stub_, context, request);
}

absl::StatusOr<v1::ListJobsResponse> Client::ListJobs(const v1::ListJobsRequest& request) const {
  grpc::ClientContext context;
  PrepareContext(BeginCall(), context);
  return CallUnary(&v1::MotionService::Stub::ListJobs, *stub_, context, request);
}

absl::StatusOr<v1::Job> Client::CancelJob(const std::string& job_id) const {
  v1::CancelJobRequest request;
  request.set_job_id(job_id);
  grpc::ClientContext context;
  PrepareContext(BeginCall(), context);
  return CallUnary(&v1::MotionService::Stub::CancelJob, *stub_, context, request);
}

absl::Status Client::DeleteJob(const std::string& job_id) const {
  v1::DeleteJobRequest request;
  request.set_job_id(job_id);
  grpc::ClientContext context;
  PrepareContext(BeginCall(), context);
  return CallUnary(&v1::MotionService::Stub::DeleteJob, *stub_, context, request).status();
}

absl::StatusOr<v1::Job> Client::WatchJob(const std::string& job_id,
                                         const JobUpdateFn& on_update) const {
  const CallScope scope = BeginCall();
  v1::WatchJobRequest request;
  request.set_job_id(job_id);
  v1::Job last;
  bool any = false;
  TEMPOKEY_RETURN_IF_ERROR(RetryWhileUnavailable(options_, scope.deadline, [&]() -> Attempt {
    grpc::ClientContext context;
    PrepareContext(scope, context);
    std::unique_ptr<grpc::ClientReader<v1::Job>> reader = stub_->WatchJob(&context, request);
    v1::Job job;
    while (reader->Read(&job)) {
      any = true;
      if (on_update) on_update(job);
      last = std::move(job);
      job.Clear();
    }
    return Attempt{WithRetryHint(FromGrpcStatus(reader->Finish()), context), any};
  }));
  if (!any) return absl::InternalError("the watch ended without sending the job");
  return last;
}

absl::StatusOr<std::string> Client::ExportJobFile(const std::string& job_id,
                                                  const std::string& format,
                                                  std::int64_t max_bytes) const {
  const CallScope scope = BeginCall();
  v1::ExportFileRequest request;
  request.set_job_id(job_id);
  request.set_format(format);
  std::string bytes;
  TEMPOKEY_RETURN_IF_ERROR(RetryWhileUnavailable(options_, scope.deadline, [&]() -> Attempt {
    bytes.clear();
    grpc::ClientContext context;
    PrepareContext(scope, context);
    std::unique_ptr<grpc::ClientReader<v1::FileChunk>> reader = stub_->ExportFile(&context, request);
    bool received = false;
    v1::FileChunk chunk;
    while (reader->Read(&chunk)) {
      received = true;
      if (static_cast<std::int64_t>(bytes.size() + chunk.data().size()) > max_bytes) {
        context.TryCancel();
        reader->Finish();
        std::string().swap(bytes);
        return Attempt{absl::ResourceExhaustedError(absl::StrCat(
                           "the exported ", format, " file is over ", max_bytes, " bytes")),
                       true};
      }
      bytes += chunk.data();
    }
    return Attempt{WithRetryHint(FromGrpcStatus(reader->Finish()), context), received};
  }));
  return bytes;
}

absl::StatusOr<core::PipelineResult> Client::GetJobResult(const std::string& job_id) const {
  const CallScope scope = BeginCall();
  v1::GetJobResultRequest request;
  request.set_job_id(job_id);
  request.set_batch_parts(true);
  std::optional<wire::ResultAssembler> assembler;
  TEMPOKEY_RETURN_IF_ERROR(RetryWhileUnavailable(options_, scope.deadline, [&]() -> Attempt {
    assembler.emplace();
    grpc::ClientContext context;
    PrepareContext(scope, context);
    std::unique_ptr<grpc::ClientReader<v1::ResultPart>> reader =
        stub_->GetJobResult(&context, request);
    bool received = false;
    absl::Status assembled;
    for (;;) {
      wire::ScratchMessage<v1::ResultPart> part;
      if (!reader->Read(part.get())) break;
      received = true;
      assembled = assembler->AddPart(*part);
      if (!assembled.ok()) {
        context.TryCancel();
        break;
      }
    }
    absl::Status status = WithRetryHint(FromGrpcStatus(reader->Finish()), context);
    if (!assembled.ok()) return Attempt{assembled, true};
    return Attempt{status, received};
  }));
  return std::move(*assembler).Finish();
}

absl::StatusOr<core::PipelineResult> Client::Process(const core::Clip& clip,
                                                     std::span<const core::PipelineStep> steps,
                                                     const core::ProgressFn& progress) const {
  TEMPOKEY_RETURN_IF_ERROR(core::ValidateClip(clip));
  const CallScope scope = BeginCall();
  // The header in an arena of its own: a message and a name per channel, kept for retries.
  wire::ArenaMessage<v1::ProcessRequest> header_request;
  header_request->set_allocated_header(wire::ClipHeaderOnArena(clip, header_request->GetArena()));
  v1::ProcessRequest start_request;
  for (const core::PipelineStep& step : steps) {
    *start_request.mutable_start()->add_operations() = wire::PipelineStepToProto(step);
  }
  start_request.mutable_start()->set_batch_parts(true);  // servers without it ignore it
  const bool batched = ServerTakesSampleSlices();

  std::optional<wire::ResultAssembler> assembler;
  TEMPOKEY_RETURN_IF_ERROR(RetryWhileUnavailable(options_, scope.deadline, [&]() -> Attempt {
    assembler.emplace();
    grpc::ClientContext context;
    PrepareContext(scope, context);
    std::unique_ptr<grpc::ClientReaderWriter<v1::ProcessRequest, v1::ProcessResponse>> stream =
        stub_->Process(&context);
    bool open = stream->Write(*header_request);
    if (open) {
      absl::Status sent =
          WriteSamples<v1::ProcessRequest>(clip, options_.slice_bytes, batched, *stream);
      open = sent.ok() && stream->Write(start_request);
    }
    if (open) stream->WritesDone();

    bool received = false;
    absl::Status assembled;
    for (;;) {
      wire::ScratchMessage<v1::ProcessResponse> response;
      if (!stream->Read(response.get())) break;
      received = true;
      if (response->has_progress()) {
        core::ReportProgress(progress, response->progress().progress(),
                             response->progress().stage());
      } else if (response->has_result()) {
        assembled = assembler->AddPart(response->result());
        if (!assembled.ok()) {
          context.TryCancel();
          break;
        }
      }
    }
    absl::Status status = WithRetryHint(FromGrpcStatus(stream->Finish()), context);
    if (!assembled.ok()) return Attempt{assembled, true};
    return Attempt{status, received};
  }));
  return std::move(*assembler).Finish();
}

}  // namespace tempokey::client
