// Prometheus metrics of the server, exposed over HTTP on their own address (prometheus-cpp
// Exposer): jobs by outcome, queue depth, running jobs, job latency, bytes in and out.
#ifndef TEMPOKEY_SERVER_METRICS_H_
#define TEMPOKEY_SERVER_METRICS_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace tempokey::server {

// Read at scrape time for the gauges.
struct MetricsGaugeSources {
  std::function<int()> queue_depth;
  std::function<int()> running;
  std::function<std::int64_t()> stored_jobs;
  std::function<std::int64_t()> stored_clips;
};

// Thread-safe: the recording methods may be called from any thread.
class Metrics {
 public:
  // Serves /metrics on `address` ("127.0.0.1:0" picks a free port, see port()).
  // Errors: kUnavailable when the address cannot be bound.
  static absl::StatusOr<std::unique_ptr<Metrics>> Start(const std::string& address,
                                                         MetricsGaugeSources gauges);
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
