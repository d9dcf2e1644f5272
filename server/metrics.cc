#include "server/metrics.h"

#include <exception>
#include <utility>
#include <vector>

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
    return families;
  }

 private:
  MetricsGaugeSources sources_;
};

}  // namespace

struct Metrics::Impl {
  std::shared_ptr<prometheus::Registry> registry = std::make_shared<prometheus::Registry>();
  std::shared_ptr<GaugeCollectable> gauges;
  std::unique_ptr<prometheus::Exposer> exposer;
  prometheus::Family<prometheus::Counter>* jobs = nullptr;
  prometheus::Family<prometheus::Histogram>* latency = nullptr;
  prometheus::Counter* bytes_in = nullptr;
  prometheus::Counter* bytes_out = nullptr;
};

absl::StatusOr<std::unique_ptr<Metrics>> Metrics::Start(const std::string& address,
                                                        MetricsGaugeSources gauges) {
  auto impl = std::make_unique<Impl>();
  // prometheus-cpp (CivetWeb) reports a failed bind by throwing; this is the boundary where it
  // becomes a status.
  try {
    impl->exposer = std::make_unique<prometheus::Exposer>(address, 1);
  } catch (const std::exception& e) {
    return absl::UnavailableError(
        absl::StrCat("cannot serve metrics on ", address, ": ", e.what()));
  }
  impl->jobs = &prometheus::BuildCounter()
                    .Name("tempokey_jobs_total")
                    .Help("Jobs and Process calls by kind and outcome (rejected: queue full).")
                    .Register(*impl->registry);
  impl->latency = &prometheus::BuildHistogram()
                       .Name("tempokey_job_latency_seconds")
                       .Help("Time from submission to the end of a job or Process call.")
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
  // Stop serving before the registry and collectables go away.
  impl_->exposer.reset();
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
