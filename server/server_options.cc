#include "server/server_options.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sched.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

#include "absl/status/statusor.h"
#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "proto/bearer_token.h"
#include "proto/loopback.h"
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
  std::istringstream lines{std::string(wire::TokenFileText(text))};
  std::string line;
  for (int number = 1; std::getline(lines, line); ++number) {
    std::string token = Trim(line);
    if (token.empty() || token[0] == '#') continue;
    // No client could send it (wire::CheckBearerToken()): refused here rather than never matched.
    if (absl::Status valid = wire::CheckBearerToken(token); !valid.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(path, ":", number, ": ", valid.message()));
    }
    tokens.push_back(std::move(token));
  }
  if (tokens.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": holds no token"));
  }
  return tokens;
}

namespace {

std::string DescribeSockaddr(const sockaddr* address) {
  char text[INET6_ADDRSTRLEN] = "?";
  if (address->sa_family == AF_INET) {
    inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in*>(address)->sin_addr, text, sizeof text);
  } else if (address->sa_family == AF_INET6) {
    inet_ntop(AF_INET6, &reinterpret_cast<const sockaddr_in6*>(address)->sin6_addr, text,
              sizeof text);
  }
  return text;
}

}  // namespace

bool IsUnixSocketAddress(std::string_view address) {
  return address.starts_with("unix:") || address.starts_with("unix-abstract:");
}

absl::Status CheckUnixSocketFree(std::string_view address) {
  if (!address.starts_with("unix:")) return absl::OkStatus();
  std::string_view path = address.substr(5);
  if (path.starts_with("//")) path.remove_prefix(2);  // unix:///abs: an empty authority
  sockaddr_un socket_address{};
  socket_address.sun_family = AF_UNIX;
  if (path.empty() || path.size() >= sizeof socket_address.sun_path) return absl::OkStatus();
  path.copy(socket_address.sun_path, path.size());
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return absl::OkStatus();
  const bool answered = ::connect(fd, reinterpret_cast<const sockaddr*>(&socket_address),
                                  sizeof socket_address) == 0;
  ::close(fd);
  if (!answered) return absl::OkStatus();
  return absl::UnavailableError(absl::StrCat("cannot listen on ", core::AsAbsl(address),
                                             ": another server is listening on this socket"));
}

absl::Status CheckLoopbackAddress(std::string_view address) {
  if (IsUnixSocketAddress(address)) return absl::OkStatus();
  // Names are case-insensitive (DNS, /etc/hosts); lower-case them so the resolver sees one form.
  const std::string host = absl::AsciiStrToLower(wire::HostOf(address));
  if (host.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "\"", core::AsAbsl(address), "\" has no host: it listens on every interface"));
  }
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* found = nullptr;
  if (const int error = getaddrinfo(host.c_str(), nullptr, &hints, &found); error != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat(host, " does not resolve (", gai_strerror(error), ")"));
  }
  absl::Status verdict = absl::OkStatus();
  for (const addrinfo* a = found; a != nullptr && verdict.ok(); a = a->ai_next) {
    if (!wire::IsLoopbackSockaddr(a->ai_addr)) {
      const std::string resolved = DescribeSockaddr(a->ai_addr);
      verdict = absl::InvalidArgumentError(
          resolved == host ? absl::StrCat(host, " is not a loopback address")
                           : absl::StrCat(host, " resolves to ", resolved,
                                          ", not a loopback address"));
    }
  }
  freeaddrinfo(found);
  return verdict;
}

bool IsLoopbackAddress(std::string_view address) { return CheckLoopbackAddress(address).ok(); }

std::int64_t MemoryLimitFrom(std::string_view v2_memory_max, std::string_view v1_limit_in_bytes,
                             std::int64_t physical_bytes) {
  std::int64_t limit = physical_bytes > 0 ? physical_bytes : 0;
  auto take = [&](std::int64_t bytes) {
    if (bytes > 0 && (limit == 0 || bytes < limit)) limit = bytes;
  };
  const std::string v2 = Trim(v2_memory_max);
  std::int64_t bytes = 0;
  if (!v2.empty()) {
    if (v2 != "max" && absl::SimpleAtoi(v2, &bytes)) take(bytes);
  } else if (absl::SimpleAtoi(Trim(v1_limit_in_bytes), &bytes)) {
    take(bytes);  // "no limit" reads as a page-rounded 2^63 - 1, above any physical memory
  }
  return limit;
}

std::int64_t MemoryLimitBytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page_size = sysconf(_SC_PAGESIZE);
  const std::int64_t physical =
      pages > 0 && page_size > 0 ? static_cast<std::int64_t>(pages) * page_size : 0;
  std::string v2 = ReadSmallFile(CgroupV2Dir() + "/memory.max");
  if (v2.empty()) v2 = ReadSmallFile("/sys/fs/cgroup/memory.max");
  return MemoryLimitFrom(v2, ReadSmallFile("/sys/fs/cgroup/memory/memory.limit_in_bytes"),
                         physical);
}

std::int64_t DefaultMemoryBudget() {
  const std::int64_t limit = MemoryLimitBytes();
  return limit > 0 ? limit / 2 : std::int64_t{1} << 30;
}

absl::Status ValidateServerOptions(const ServerOptions& o) {
  auto positive = [](std::string_view name, std::int64_t value) -> absl::Status {
    if (value > 0) return absl::OkStatus();
    return absl::InvalidArgumentError(
        absl::StrCat("--", core::AsAbsl(name), " must be > 0, got ", value));
  };
  if (o.address.empty()) return absl::InvalidArgumentError("--address must not be empty");
  for (const auto& [flag, address] : {std::pair<const char*, const std::string&>{"--address", o.address},
                                      {"--metrics_address", o.metrics_address}}) {
    TEMPOKEY_RETURN_IF_ERROR(
        core::Annotate(wire::CheckTargetPorts(address), absl::StrCat(flag, " ", address)));
  }
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
  // Durations in seconds end up as clock times in nanoseconds (a TTL, a drain's end), and the
  // connection age as gRPC's int of milliseconds: values past these bounds overflowed (an age of
  // 30 days became negative, and the server answered no call).
  auto seconds_within = [](std::string_view name, std::chrono::seconds value,
                           std::int64_t most, std::string_view zero) -> absl::Status {
    if (value.count() >= 0 && value.count() <= most) return absl::OkStatus();
    return absl::InvalidArgumentError(absl::StrCat("--", core::AsAbsl(name), " must be in [0, ",
                                                   most, "]", core::AsAbsl(zero), ", got ",
                                                   value.count()));
  };
  TEMPOKEY_RETURN_IF_ERROR(seconds_within("job_ttl_seconds", o.job_ttl, kMaxDurationSeconds, ""));
  TEMPOKEY_RETURN_IF_ERROR(
      seconds_within("drain_grace_seconds", o.drain_grace, kMaxDurationSeconds, ""));
  TEMPOKEY_RETURN_IF_ERROR(seconds_within("max_connection_age_seconds", o.max_connection_age,
                                          kMaxConnectionAgeSeconds, " (0: never)"));
  if (o.min_client_ping_interval.count() < 0 ||
      o.min_client_ping_interval.count() > std::numeric_limits<int>::max()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "min_client_ping_interval must be in [0, ", std::numeric_limits<int>::max(),
        "] ms, got ", o.min_client_ping_interval.count()));
  }
  if (o.handshake_timeout.count() < kMinHandshakeTimeoutMs ||
      o.handshake_timeout.count() > kMaxHandshakeTimeoutMs) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--handshake_timeout_seconds must be in [0.1, ", kMaxHandshakeTimeoutMs / 1000, "], got ",
        static_cast<double>(o.handshake_timeout.count()) / 1000.0));
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
    if (absl::Status valid = wire::CheckBearerToken(token); !valid.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("an auth token: ", valid.message()));
    }
  }
  if (o.memory_budget_bytes < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--memory_budget_bytes must be >= 0 (0: half the memory the process may use), got ",
        o.memory_budget_bytes));
  }
  if (o.stream_idle_timeout.count() < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--stream_idle_timeout_seconds must be >= 0 (0: none), got ",
        static_cast<double>(o.stream_idle_timeout.count()) / 1000.0));
  }
  if (o.process_progress_interval < std::chrono::milliseconds(0) ||
      o.process_progress_interval > std::chrono::hours(1)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--process_progress_interval_ms must be in [0, 3600000] (0: every new stage label or "
        "percent), got ",
        o.process_progress_interval.count()));
  }
  if (o.tls_cert_file.empty() && !o.allow_insecure_remote) {
    if (absl::Status loopback = CheckLoopbackAddress(o.address); !loopback.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "refusing to listen on non-loopback address ", o.address, " without TLS (",
          loopback.message(), "): give --tls_cert and --tls_key, or --allow_insecure_remote"));
    }
  }
  // Metrics are plain HTTP whatever the gRPC port does, so only loopback is safe by default.
  if (!o.metrics_address.empty() && !o.allow_insecure_remote) {
    if (absl::Status loopback = CheckLoopbackAddress(o.metrics_address); !loopback.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "refusing to serve metrics on non-loopback address ", o.metrics_address, " (",
          loopback.message(),
          "): metrics are plain HTTP; scrape over loopback, or give --allow_insecure_remote"));
    }
  }
  return absl::OkStatus();
}

}  // namespace tempokey::server
