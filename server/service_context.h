// What the MotionService handlers share: options, the pool, jobs, clips, metrics, the stream
// counter, and the one bearer-token check.
#ifndef TEMPOKEY_SERVER_SERVICE_CONTEXT_H_
#define TEMPOKEY_SERVER_SERVICE_CONTEXT_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "grpcpp/server_context.h"
#include "absl/status/statusor.h"
#include "server/background_digest.h"
#include "server/clip_store.h"
#include "server/idle_reaper.h"
#include "server/job_manager.h"
#include "server/job_pool.h"
#include "server/memory_budget.h"
#include "server/metrics.h"
#include "server/server_options.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::server {

// The retry hint of a streaming call refused for want of a stream slot: a slot frees when another
// call ends, which the server cannot foresee, so a fixed second (clients add their own random
// share).
inline constexpr std::chrono::milliseconds kStreamRetryAfter{1000};

// Owned by Server, outlives every call. Thread-safe.
struct ServiceContext {
  ServerOptions options;
  core::ClipLimits clip_limits;       // from options.max_clip_samples
  JobPool* pool = nullptr;
  JobManager* jobs = nullptr;
  ClipStore* clips = nullptr;
  Metrics* metrics = nullptr;         // null without --metrics_address
  MemoryBudget* budget = nullptr;
  IdleReaper* idle = nullptr;
  // owner_ids[i] is the owner of options.auth_tokens[i] (OwnerIdOfToken()).
  std::vector<std::string> owner_ids;
  std::vector<std::string> operations;  // what GetServerInfo offers
  std::atomic<bool> draining{false};
  std::atomic<int> open_streams{0};
  // Uploads hashing on threads of their own (BackgroundClipDigest).
  DigestThreads digest_threads;

  // The bearer-token check of every MotionService and reflection call: the caller's owner id
  // ("" when no tokens are configured), when the call carries "authorization: Bearer <one of
  // them>" (compared in constant time). Errors: kUnauthenticated.
  absl::StatusOr<std::string> Authenticate(const grpc::ServerContextBase& context) const;
  absl::Status CheckAuth(const grpc::ServerContextBase& context) const {
    return Authenticate(context).status();
  }
  // The same check for an HTTP "Authorization" header value (metrics); `header` is null when the
  // request has none. Errors: kUnauthenticated.
  absl::Status CheckBearer(const char* header) const;

  // Claims one of options.max_concurrent_streams streaming calls; false when all are taken.
  bool TryOpenStream();
  void CloseStream();
  // kUnavailable while draining (unless `allow_while_draining`: result downloads still work
  // during the grace period), kResourceExhausted with no stream left (with the retry hint
  // kStreamRetryAfter); on OK the caller owns a stream slot (CloseStream() when the call ends).
  absl::Status AdmitStream(bool allow_while_draining = false);

  void BytesIn(std::int64_t bytes) const {
    if (metrics != nullptr) metrics->AddBytesIn(bytes);
  }
  void BytesOut(std::int64_t bytes) const {
    if (metrics != nullptr) metrics->AddBytesOut(bytes);
  }
};

// The owner id of a bearer token: "token-" and the first 8 bytes of its SHA-256 in hex, so logs
// and job records never hold the token itself.
std::string OwnerIdOfToken(std::string_view token);

// A claim on one of the server's streaming-call slots (ServiceContext::AdmitStream()), given back
// when the call answers (release it right before Finish(), so a client that saw the end of its
// call finds the slot free) or at the latest when the reactor goes. Release() is thread-safe and
// idempotent.
class StreamSlot {
 public:
  StreamSlot() = default;
  ~StreamSlot() { Release(); }
  StreamSlot(const StreamSlot&) = delete;
  StreamSlot& operator=(const StreamSlot&) = delete;

  // Errors: as ServiceContext::AdmitStream().
  absl::Status Claim(ServiceContext& service, bool allow_while_draining = false);
  void Release();
  // Whether the slot is claimed and not yet released.
  bool held() const { return service_.load() != nullptr; }

 private:
  std::atomic<ServiceContext*> service_{nullptr};
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_SERVICE_CONTEXT_H_
