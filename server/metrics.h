// Prometheus metrics of the server, exposed over HTTP on their own address (prometheus-cpp
// Exposer): jobs by outcome, queue depth, running jobs, job latency, bytes in and out, the memory
// budget and its use, uploads hashing on threads of their own.
//
// The HTTP server (CivetWeb) runs kMetricsThreads threads and drops a connection that has not
// sent a whole request within kMetricsRequestTimeout, so a few slow or idle clients cannot keep
// every scrape waiting. With a bearer-token check, a request without an accepted
// "Authorization: Bearer <token>" gets 401.
#ifndef TEMPOKEY_SERVER_METRICS_H_
#define TEMPOKEY_SERVER_METRICS_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tempokey::server {

// Read at scrape time for the gauges.
struct MetricsGaugeSources {
  std::function<int()> queue_depth;
  std::function<int()> running;
  std::function<std::int64_t()> stored_jobs;
  std::function<std::int64_t()> stored_clips;
  std::function<std::int64_t()> memory_budget;
  // Bytes of the budget in use by kind ("upload", "stored_clip", "job", "result", "process").
  std::function<std::vector<std::pair<std::string, std::int64_t>>()> memory_used;
  // Uploads whose content id is being hashed on a thread of its own (DigestThreads), and how many
  // may be at once.
  std::function<int()> digest_threads;
  std::function<int()> digest_threads_max;
};

inline constexpr int kMetricsThreads = 32;
inline constexpr int kMetricsRequestTimeoutMs = 2000;

// Checks an HTTP request's Authorization header (null when it has none); non-OK answers 401.
using MetricsAuthCheck = std::function<absl::Status(const char* authorization)>;

// Thread-safe: the recording methods may be called from any thread.
class Metrics {
 public:
  // Serves /metrics on `address` ("127.0.0.1:0" picks a free port, see port()); `check_auth`
  // (optional) is asked about every request before it is served.
  // Errors: kUnavailable when the address cannot be bound.
  static absl::StatusOr<std::unique_ptr<Metrics>> Start(const std::string& address,
                                                         MetricsGaugeSources gauges,
                                                         MetricsAuthCheck check_auth = {});
  ~Metrics();

  // The bound HTTP port.
  int port() const;

  // A job or Process call ended: `kind` "job" or "process", `outcome` "succeeded", "failed" or
  // "cancelled"; `seconds` from submission to the end.
  void RecordFinished(std::string_view kind, std::string_view outcome, double seconds);
  // A submit or Process call refused because the queue was full.
  void RecordRejected(std::string_view kind);
  // Payload bytes received (clips, requests) and sent (results, jobs).
  void AddBytesIn(std::int64_t bytes);
  void AddBytesOut(std::int64_t bytes);

 private:
  struct Impl;
  explicit Metrics(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_METRICS_H_
