// The C++ client library of tempokey.v1.MotionService (SPEC 6): channel set-up, deadlines, retries
// on UNAVAILABLE, and whole-clip calls (upload, submit, watch, result, process) in core terms.
//
// Every method returns absl::Status / absl::StatusOr. A failed call keeps the gRPC status code and
// message exactly as the server (or the gRPC runtime) gave them: absl status codes are the gRPC
// codes, so kInvalidArgument from the server arrives as kInvalidArgument here.
#ifndef TEMPOKEY_CLIENT_CLIENT_H_
#define TEMPOKEY_CLIENT_CLIENT_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <span>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "client/health_codec.h"
#include "grpcpp/channel.h"
#include "grpcpp/support/status.h"
#include "proto/clip_convert.h"
#include "proto/jobs_convert.h"
#include "proto/retry_hint.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/v1/motion_service.grpc.pb.h"

namespace tempokey::client {

namespace v1 = ::tempokey::v1;

// The fully qualified name of the service, as health checks and service configs spell it.
inline constexpr char kMotionServiceName[] = "tempokey.v1.MotionService";

// Transport security. With `enabled` false the channel is plaintext (loopback, tests, meshes that
// terminate TLS themselves).
struct TlsOptions {
  bool enabled = false;
  // PEM roots that sign the server's certificate; empty uses the system roots.
  std::string root_ca_pem;
  // PEM client certificate chain and private key for mutual TLS; both or neither.
  std::string cert_chain_pem;
  std::string private_key_pem;
  // Name to expect in the server's certificate instead of the target's host (test certificates).
  std::string target_name_override;
};

struct ClientOptions {
  // Any gRPC target: "host:port", "dns:///host:port", "ipv4:127.0.0.1:1,127.0.0.1:2", ...
  std::string target = "127.0.0.1:50051";
  // Deadline of each method call, in seconds, covering all its retries; <= 0 means none.
  double timeout_seconds = 60.0;
  // Largest message accepted from the server, in bytes (results come in slices well below it).
  int max_receive_message_bytes = 64 << 20;
  // Attempts per call when the server answers UNAVAILABLE (the only code retried, SPEC 5);
  // 1 disables retries. Unary calls retry through the channel's service config, streaming calls
  // in this library (only while nothing has been received, so no update is seen twice).
  int max_attempts = 4;
  double initial_backoff_seconds = 0.1;
  double max_backoff_seconds = 1.0;
  // "round_robin" spreads calls over every address the target resolves to (a list, a headless
  // service); "pick_first" sticks to one.
  std::string load_balancing_policy = "round_robin";
  // Interval of HTTP/2 keepalive pings while calls are active, in seconds; <= 0 disables them.
  // Not below gRPC servers' default minimum ping interval (300 s), or they answer with GOAWAY.
  double keepalive_time_seconds = 300.0;
  double keepalive_timeout_seconds = 20.0;
  TlsOptions tls;
  // Sent as "authorization: Bearer <token>" on every call when not empty: over TLS, or to a
  // target on this machine (wire::IsLoopbackTarget()), unless allow_plaintext_token says the
  // network itself is trusted (a service mesh whose sidecars encrypt it).
  std::string bearer_token;
  bool allow_plaintext_token = false;
  // Bytes of samples per message when sending clips (>= 8).
  std::int64_t slice_bytes = wire::kDefaultSliceBytes;
};

// Checks `options` for values no channel can use (empty target, a client certificate without its
// key, non-positive sizes, attempts outside 1..10, unknown load-balancing policy), and a bearer
// token that would travel in cleartext off this machine (RFC 6750 5.3: bearer tokens only over
// TLS).
// Errors: kInvalidArgument naming the option.
absl::Status ValidateClientOptions(const ClientOptions& options);

// The gRPC service config the channel is created with: `options.load_balancing_policy`, and a
// retry policy on UNAVAILABLE for the unary methods of MotionService and grpc.health.v1.Health.
std::string ServiceConfigJson(const ClientOptions& options);

// The one place gRPC statuses become absl statuses: same code, same message.
absl::Status FromGrpcStatus(const grpc::Status& status);

// Where a job's pipeline runs on: an uploaded clip (by id) or a clip sent inline.
struct SubmitOptions {
  // Labels the job carries (ListJobs filters on them).
  std::map<std::string, std::string> labels;
  // Idempotency key; empty makes SubmitJob generate a fresh random one, so that the library's own
  // retries of one SubmitJob call never create two jobs.
  std::string request_id;
};

// Called with every snapshot of a watched job, in increasing `version` order.
using JobUpdateFn = std::function<void(const v1::Job& job)>;

// A client of one target. Thread-safe: every method may be called from several threads at once
// (the channel and stub are thread-safe; the only other state is an atomic cache of the server's
// wire features).
class Client {
 public:
  // Creates the channel (no connection is made until the first call).
  // Errors: kInvalidArgument from ValidateClientOptions().
  static absl::StatusOr<std::unique_ptr<Client>> Connect(const ClientOptions& options);

  // Uses an existing channel, e.g. an in-process one; `options` supply deadlines, retries, token
  // and slice size (target, TLS and channel arguments are the channel's own). Its token must
  // pass wire::CheckBearerToken() (ValidateClientOptions() checks it): gRPC aborts the process
  // on a call whose metadata is no valid header value.
  Client(std::shared_ptr<grpc::Channel> channel, ClientOptions options);

  const ClientOptions& options() const { return options_; }
  const std::shared_ptr<grpc::Channel>& channel() const { return channel_; }

  // Version, limits and operations of the server that answers.
  absl::StatusOr<v1::ServerInfo> GetServerInfo() const;

  // grpc.health.v1.Health/Check for `service` ("" = the server overall, kMotionServiceName = ready
  // for jobs). Errors: kNotFound when the server does not know `service`; any call error.
  absl::StatusOr<HealthState> CheckHealth(const std::string& service) const;

  // Streams `clip` (header, then slices of options().slice_bytes) and returns the server's answer
  // with the clip's content id. Retried whole on UNAVAILABLE (uploads are idempotent).
  // Errors: kInvalidArgument when `clip` fails core::ValidateClip() (checked before sending) or
  // the server refuses it; kResourceExhausted over the server's limits, or refused for the
  // moment (no stream slot, its memory budget in use) with a retry hint (wire::GetRetryAfter());
  // any call error.
  absl::StatusOr<v1::UploadClipResponse> UploadClip(const core::Clip& clip) const;

  // Queues `steps` on the uploaded clip `clip_id` / on `clip` sent inline.
  // Errors: kNotFound unknown clip id; kInvalidArgument bad pipeline; kResourceExhausted queue
  // full or memory budget in use, carrying the server's hint of when to try again
  // (wire::GetRetryAfter()), or over a limit without one; kUnimplemented an operation the server
  // lacks; any call error.
  absl::StatusOr<v1::Job> SubmitJob(const std::string& clip_id,
                                    std::span<const core::PipelineStep> steps,
                                    const SubmitOptions& submit = {}) const;
  absl::StatusOr<v1::Job> SubmitInlineJob(const core::Clip& clip,
                                          std::span<const core::PipelineStep> steps,
                                          const SubmitOptions& submit = {}) const;

  // Errors: kNotFound unknown job; any call error.
  absl::StatusOr<v1::Job> GetJob(const std::string& job_id) const;
  absl::StatusOr<v1::ListJobsResponse> ListJobs(const v1::ListJobsRequest& request) const;
  absl::StatusOr<v1::Job> CancelJob(const std::string& job_id) const;
  absl::Status DeleteJob(const std::string& job_id) const;

  // Follows a job until it ends: calls `on_update` (if set) with each snapshot and returns the
  // last one, which is terminal unless the server ended the stream early.
  // Errors: kNotFound unknown job; kUnavailable the server is draining; any call error.
  absl::StatusOr<v1::Job> WatchJob(const std::string& job_id, const JobUpdateFn& on_update) const;

  // The result of a succeeded job, reassembled and validated (wire::ClipAssembler for a sampled
  // clip, wire::KeyedClipFromProto for a keyed one), with its reports.
  // Errors: kFailedPrecondition the job has not succeeded; kNotFound; kInvalidArgument when the
  // parts do not make a valid clip; any call error.
  absl::StatusOr<core::PipelineResult> GetJobResult(const std::string& job_id) const;

  // The file the server formats from a succeeded job's result (ExportFile; `format` an
  // ExportFormat name: "glb", "bvh", ...), its chunks joined; at most `max_bytes` (more is
  // refused, kResourceExhausted, without keeping them). A keyed glTF is fitted against the job's
  // stored input clip, as the CLI fits its own; a sampled format bakes the curves.
  absl::StatusOr<std::string> ExportJobFile(const std::string& job_id, const std::string& format,
                                            std::int64_t max_bytes) const;

  // Runs `steps` on `clip` in one stateless call: streams the clip in, reports progress to
  // `progress` (if set; called on this thread), and returns the result. Retried whole on
  // UNAVAILABLE while no response has arrived.
  // Errors: as UploadClip() and SubmitJob(), plus the pipeline's own errors
  // ("operation 1 (retime): ...") and those of GetJobResult()'s reassembly.
  absl::StatusOr<core::PipelineResult> Process(const core::Clip& clip,
                                               std::span<const core::PipelineStep> steps,
                                               const core::ProgressFn& progress = {}) const;

 private:
  struct CallScope;  // deadline of one method call across its attempts

  // Whether the server accepts SampleSlices (ServerInfo.features), asked once per Client.
  bool ServerTakesSampleSlices() const;
  CallScope BeginCall() const;
  void PrepareContext(const CallScope& scope, grpc::ClientContext& context) const;
  absl::StatusOr<v1::Job> Submit(v1::SubmitJobRequest request,
                                 std::span<const core::PipelineStep> steps,
                                 const SubmitOptions& submit) const;

  std::shared_ptr<grpc::Channel> channel_;
  ClientOptions options_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
  static constexpr int kFeatureUnknown = 0;
  static constexpr int kFeatureOn = 1;
  static constexpr int kFeatureOff = 2;
  mutable std::atomic<int> sample_slices_{kFeatureUnknown};
};

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_CLIENT_H_
