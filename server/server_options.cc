#include "server/server_options.h"

#include <sched.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

std::string Trim(std::string_view s) {
  std::size_t b = 0;
  std::size_t e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return std::string(s.substr(b, e - b));
}

std::string ReadSmallFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return {};
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

// The cgroup v2 directory of this process ("0::/some/path" in /proc/self/cgroup).
std::string CgroupV2Dir() {
  std::istringstream lines(ReadSmallFile("/proc/self/cgroup"));
  std::string line;
  while (std::getline(lines, line)) {
    if (line.rfind("0::", 0) == 0) return "/sys/fs/cgroup" + Trim(line.substr(3));
  }
  return "/sys/fs/cgroup";
}

// CPUs allowed by this process's cgroup quota, or 0 when there is none.
int CgroupCpuLimit() {
  std::string cpu_max = ReadSmallFile(CgroupV2Dir() + "/cpu.max");
  if (cpu_max.empty()) cpu_max = ReadSmallFile("/sys/fs/cgroup/cpu.max");
  return CpuQuotaLimit(cpu_max, ReadSmallFile("/sys/fs/cgroup/cpu/cpu.cfs_quota_us"),
                       ReadSmallFile("/sys/fs/cgroup/cpu/cpu.cfs_period_us"));
}

}  // namespace

int CpuQuotaLimit(std::string_view v2_cpu_max, std::string_view v1_quota_us,
                  std::string_view v1_period_us) {
  auto ceil_ratio = [](double quota, double period) {
    return std::max(1, static_cast<int>(std::ceil(quota / period)));
  };
  // v2: "max 100000" (no quota) or "<quota> <period>".
  std::istringstream v2{std::string(v2_cpu_max)};
  std::string quota;
  double period = 0;
  if (v2 >> quota >> period) {
    if (quota == "max" || !(period > 0)) return 0;
    char* end = nullptr;
    const double q = std::strtod(quota.c_str(), &end);
    return end != quota.c_str() && q > 0 ? ceil_ratio(q, period) : 0;
  }
  // v1: a quota of -1 means none.
  std::istringstream quota_in{std::string(v1_quota_us)};
  std::istringstream period_in{std::string(v1_period_us)};
  double q = 0;
  double p = 0;
  if ((quota_in >> q) && (period_in >> p) && q > 0 && p > 0) return ceil_ratio(q, p);
  return 0;
}

int DefaultWorkerCount() {
  int cpus = 0;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) == 0) cpus = CPU_COUNT(&set);
  if (cpus <= 0) cpus = 1;
  const int quota = CgroupCpuLimit();
  if (quota > 0) cpus = std::min(cpus, quota);
  return std::max(1, cpus);
}

absl::StatusOr<std::vector<std::string>> ReadTokenFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open the token file"));
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  std::vector<std::string> tokens;
  std::istringstream lines(text);
  std::string line;
  while (std::getline(lines, line)) {
    std::string token = Trim(line);
    if (token.empty() || token[0] == '#') continue;
    tokens.push_back(std::move(token));
  }
  if (tokens.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": holds no token"));
  }
  return tokens;
}

bool IsLoopbackAddress(std::string_view address) {
  if (address.rfind("unix:", 0) == 0 || address.rfind("unix-abstract:", 0) == 0) return true;
  std::string_view host = address;
  if (!host.empty() && host.front() == '[') {
    const std::size_t close = host.find(']');
    if (close == std::string_view::npos) return false;
    host = host.substr(1, close - 1);
  } else if (const std::size_t colon = host.rfind(':');
             colon != std::string_view::npos && host.find(':') == colon) {
    host = host.substr(0, colon);  // "host:port" (a bare IPv6 address has several colons)
  }
  if (host == "localhost" || host == "::1") return true;
  return host.rfind("127.", 0) == 0;
}

absl::Status ValidateServerOptions(const ServerOptions& o) {
  auto positive = [](std::string_view name, std::int64_t value) -> absl::Status {
    if (value > 0) return absl::OkStatus();
    return absl::InvalidArgumentError(
        absl::StrCat("--", core::AsAbsl(name), " must be > 0, got ", value));
  };
  if (o.address.empty()) return absl::InvalidArgumentError("--address must not be empty");
  TEMPOKEY_RETURN_IF_ERROR(positive("queue_capacity", o.queue_capacity));
  TEMPOKEY_RETURN_IF_ERROR(positive("max_message_bytes", o.max_message_bytes));
  if (o.max_message_bytes > (std::int64_t{1} << 31) - 1) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--max_message_bytes must be below 2 GiB, got ", o.max_message_bytes));
  }
  TEMPOKEY_RETURN_IF_ERROR(positive("max_clip_samples", o.max_clip_samples));
  TEMPOKEY_RETURN_IF_ERROR(positive("max_stored_clips", o.max_stored_clips));
  TEMPOKEY_RETURN_IF_ERROR(positive("max_stored_clip_bytes", o.max_stored_clip_bytes));
  TEMPOKEY_RETURN_IF_ERROR(positive("max_stored_results", o.max_stored_results));
  TEMPOKEY_RETURN_IF_ERROR(positive("max_stored_result_bytes", o.max_stored_result_bytes));
  TEMPOKEY_RETURN_IF_ERROR(positive("max_concurrent_streams", o.max_concurrent_streams));
  if (o.job_ttl.count() < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("--job_ttl_seconds must be >= 0, got ", o.job_ttl.count()));
  }
  if (o.drain_grace.count() < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("--drain_grace_seconds must be >= 0, got ", o.drain_grace.count()));
  }
  if (!(o.max_job_cost_seconds >= 0.0 && std::isfinite(o.max_job_cost_seconds))) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--max_job_cost_seconds must be finite and >= 0 (0: no limit), got ",
        o.max_job_cost_seconds));
  }
  if (o.tls_cert_file.empty() != o.tls_key_file.empty()) {
    return absl::InvalidArgumentError("--tls_cert and --tls_key must be given together");
  }
  if (!o.tls_client_ca_file.empty() && o.tls_cert_file.empty()) {
    return absl::InvalidArgumentError(
        "--tls_client_ca needs --tls_cert and --tls_key (mutual TLS is TLS first)");
  }
  for (const std::string& token : o.auth_tokens) {
    if (token.empty()) return absl::InvalidArgumentError("an auth token is empty");
  }
  if (o.tls_cert_file.empty() && !o.allow_insecure_remote && !IsLoopbackAddress(o.address)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "refusing to listen on non-loopback address ", o.address,
        " without TLS: give --tls_cert and --tls_key, or --allow_insecure_remote"));
  }
  return absl::OkStatus();
}

}  // namespace tempokey::server
