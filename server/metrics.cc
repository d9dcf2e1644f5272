#include "server/metrics.h"

#include <exception>
#include <map>
#include <mutex>
#include <utility>
#include <vector>

#include "CivetServer.h"
#include "civetweb.h"
#include "absl/strings/str_cat.h"
#include "prometheus/client_metric.h"
#include "prometheus/collectable.h"
#include "prometheus/counter.h"
#include "prometheus/exposer.h"
#include "prometheus/family.h"
#include "prometheus/histogram.h"
#include "prometheus/metric_family.h"
#include "prometheus/registry.h"

namespace tempokey::server {
namespace {

// Gauges computed when Prometheus scrapes, so they are never stale.
class GaugeCollectable : public prometheus::Collectable {
 public:
  explicit GaugeCollectable(MetricsGaugeSources sources) : sources_(std::move(sources)) {}

  std::vector<prometheus::MetricFamily> Collect() const override {
    std::vector<prometheus::MetricFamily> families;
    auto add = [&](std::string name, std::string help, double value) {
      prometheus::MetricFamily family;
      family.name = std::move(name);
      family.help = std::move(help);
      family.type = prometheus::MetricType::Gauge;
      prometheus::ClientMetric metric;
      metric.gauge.value = value;
      family.metric.push_back(std::move(metric));
      families.push_back(std::move(family));
    };
    if (sources_.queue_depth) {
      add("tempokey_queue_depth", "Jobs and Process calls waiting for a worker.",
          sources_.queue_depth());
    }
    if (sources_.running) {
      add("tempokey_running_jobs", "Jobs and Process calls running on a worker.",
          sources_.running());
    }
    if (sources_.stored_jobs) {
      add("tempokey_stored_jobs", "Jobs the server holds, in any state.",
          static_cast<double>(sources_.stored_jobs()));
    }
    if (sources_.stored_clips) {
      add("tempokey_stored_clips", "Uploaded clips the server holds.",
          static_cast<double>(sources_.stored_clips()));
    }
    if (sources_.memory_budget) {
      add("tempokey_memory_budget_bytes", "The server's memory budget (--memory_budget_bytes).",
          static_cast<double>(sources_.memory_budget()));
    }
    if (sources_.digest_threads) {
      add("tempokey_upload_digest_threads",
          "Uploads whose content id is being hashed on a thread of its own.",
          sources_.digest_threads());
    }
    if (sources_.digest_threads_max) {
      add("tempokey_upload_digest_threads_max",
          "Uploads that may hash on threads of their own at once (past them, an upload hashes "
          "where its samples arrive).",
          sources_.digest_threads_max());
    }
    if (sources_.memory_used) {
      prometheus::MetricFamily family;
      family.name = "tempokey_memory_used_bytes";
      family.help = "Bytes of the memory budget in use, by what holds them.";
      family.type = prometheus::MetricType::Gauge;
      for (const auto& [use, bytes] : sources_.memory_used()) {
        prometheus::ClientMetric metric;
        metric.label.push_back({"use", use});
        metric.gauge.value = static_cast<double>(bytes);
        family.metric.push_back(std::move(metric));
      }
      families.push_back(std::move(family));
    }
    return families;
  }

 private:
  MetricsGaugeSources sources_;
};

// CivetWeb calls begin_request with its own server as user data, so the auth check of each
// listening port is found here. Keyed by port: one Metrics per port at a time.
std::mutex g_auth_mu;
std::map<int, MetricsAuthCheck>& AuthChecks() {
  static auto* checks = new std::map<int, MetricsAuthCheck>();
  return *checks;
}

// Answers 401 (and ends the request) unless the check of the connection's port accepts it. A
// port without a check yet (the instant between binding and registering) is refused too.
int CheckRequest(struct mg_connection* connection) {
  mg_server_port ports[4];
  const int count = mg_get_server_ports(mg_get_context(connection), 4, ports);
  MetricsAuthCheck check;
  {
    std::lock_guard lock(g_auth_mu);
    for (int i = 0; i < count && !check; ++i) {
      auto it = AuthChecks().find(ports[i].port);
      if (it != AuthChecks().end()) check = it->second;
    }
  }
  const absl::Status status =
      check ? check(mg_get_header(connection, "Authorization"))
            : absl::UnauthenticatedError("the metrics endpoint is not ready");
  if (status.ok()) return 0;  // CivetWeb goes on and serves it
  const std::string body = absl::StrCat(status.message(), "\n");
  mg_printf(connection,
            "HTTP/1.1 401 Unauthorized\r\nWWW-Authenticate: Bearer\r\n"
            "Content-Type: text/plain\r\nContent-Length: %zu\r\nConnection: close\r\n\r\n%s",
            body.size(), body.c_str());
  return 401;
}

}  // namespace

struct Metrics::Impl {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  std::shared_ptr<GaugeCollectable> gauges;
  std::unique_ptr<prometheus::Exposer> exposer;
  prometheus::Family<prometheus::Counter>* jobs = nullptr;
  prometheus::Family<prometheus::Histogram>* latency = nullptr;
  prometheus::Counter* bytes_in = nullptr;
  prometheus::Counter* bytes_out = nullptr;
  int auth_port = 0;  // registered in AuthChecks(), 0: none
};

absl::StatusOr<std::unique_ptr<Metrics>> Metrics::Start(const std::string& address,
                                                        MetricsGaugeSources gauges,
                                                        MetricsAuthCheck check_auth) {
  auto impl = std::make_unique<Impl>();
  // CivetWeb options (its user manual): several threads, and a connection that has not sent its
  // request within the timeout is closed; no keep-alive, so a scraper holds no thread between
  // scrapes.
  std::vector<std::string> options = {
      "listening_ports",    address,
      "num_threads",        absl::StrCat(kMetricsThreads),
      "request_timeout_ms", absl::StrCat(kMetricsRequestTimeoutMs),
      "enable_keep_alive",  "no",
  };
  CivetCallbacks callbacks{};
  if (check_auth) callbacks.begin_request = &CheckRequest;
  // prometheus-cpp (CivetWeb) reports a failed bind by throwing; this is the boundary where it
  // becomes a status.
  try {
    impl->exposer = std::make_unique<prometheus::Exposer>(std::move(options), &callbacks);
  } catch (const std::exception& e) {
    return absl::UnavailableError(
        absl::StrCat("cannot serve metrics on ", address, ": ", e.what()));
  }
  if (check_auth) {
    const std::vector<int> ports = impl->exposer->GetListeningPorts();
    if (!ports.empty()) {
      impl->auth_port = ports.front();
      std::lock_guard lock(g_auth_mu);
      AuthChecks()[impl->auth_port] = std::move(check_auth);
    }
  }
  impl->jobs = &prometheus::BuildCounter()
                    .Name("tempokey_jobs_total")
                    .Help("Jobs, Process calls and exports by kind and outcome "
                          "(rejected: queue full).")
                    .Register(*impl->registry);
  impl->latency = &prometheus::BuildHistogram()
                       .Name("tempokey_job_latency_seconds")
                       .Help("Time from submission to the end of a job, a Process call or "
                             "an export's formatting.")
                       .Register(*impl->registry);
  auto& bytes = prometheus::BuildCounter()
                    .Name("tempokey_bytes_total")
                    .Help("Payload bytes received (in) and sent (out).")
                    .Register(*impl->registry);
  impl->bytes_in = &bytes.Add({{"direction", "in"}});
  impl->bytes_out = &bytes.Add({{"direction", "out"}});
  impl->gauges = std::make_shared<GaugeCollectable>(std::move(gauges));
  impl->exposer->RegisterCollectable(impl->registry);
  impl->exposer->RegisterCollectable(impl->gauges);
  return std::unique_ptr<Metrics>(new Metrics(std::move(impl)));
}

Metrics::Metrics(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Metrics::~Metrics() {
  // Stop serving before the registry, collectables and auth check go away.
  impl_->exposer.reset();
  if (impl_->auth_port != 0) {
    std::lock_guard lock(g_auth_mu);
    AuthChecks().erase(impl_->auth_port);
  }
}

int Metrics::port() const {
  std::vector<int> ports = impl_->exposer->GetListeningPorts();
  return ports.empty() ? 0 : ports.front();
}

void Metrics::RecordFinished(std::string_view kind, std::string_view outcome, double seconds) {
  impl_->jobs->Add({{"kind", std::string(kind)}, {"outcome", std::string(outcome)}}).Increment();
  static const prometheus::Histogram::BucketBoundaries kBuckets = {
      0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 30, 60, 300};
  impl_->latency->Add({{"kind", std::string(kind)}}, kBuckets).Observe(seconds);
}

void Metrics::RecordRejected(std::string_view kind) {
  impl_->jobs->Add({{"kind", std::string(kind)}, {"outcome", "rejected"}}).Increment();
}

void Metrics::AddBytesIn(std::int64_t bytes) {
  impl_->bytes_in->Increment(static_cast<double>(bytes));
}

void Metrics::AddBytesOut(std::int64_t bytes) {
  impl_->bytes_out->Increment(static_cast<double>(bytes));
}

}  // namespace tempokey::server
