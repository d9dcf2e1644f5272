// Settings of a tempokey server: listening address, worker pool, limits, retention, security.
#ifndef TEMPOKEY_SERVER_SERVER_OPTIONS_H_
#define TEMPOKEY_SERVER_SERVER_OPTIONS_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <stop_token>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tempokey::server {

// Test-only hooks. Production code leaves them empty; tests use them to hold a worker at a known
// point (e.g. to cancel or drain while a job is running) without faking any work.
struct TestHooks {
  // Called on the worker thread right before a job's pipeline (or a Process call's pipeline)
  // runs, with the job id ("" for Process). May block; the job counts as running meanwhile.
  std::function<void(std::string_view job_id)> on_job_start;
  // Called on the worker thread after each progress report of a Process call's pipeline was
  // offered to the call (sent, deferred or dropped by its ProgressThrottle). May block.
  std::function<void(double fraction, std::string_view stage)> on_process_progress;
  // Called on the worker thread right before an ExportFile call's file is formatted, with its
  // format's name and the export's stop token (requested by the client's cancel or the drain
  // deadline). May block; the export counts as running meanwhile.
  std::function<void(std::string_view format, std::stop_token stop)> on_export_start;
};

struct ServerOptions {
  // Where to listen: "host:port" ("127.0.0.1:0" picks a free port; Server::port() tells which).
  std::string address = "127.0.0.1:50051";
  // Worker threads running pipelines; <= 0 means DefaultWorkerCount().
  int workers = 0;
  // Jobs (and Process calls) waiting for a worker; beyond it submits get RESOURCE_EXHAUSTED.
  int queue_capacity = 64;
  // The one budget for clips being received, stored clips, queued and running jobs (operations
  // and inputs) and results, in bytes; <= 0 means DefaultMemoryBudget(). Past it, requests get
  // RESOURCE_EXHAUSTED after stored clips and finished jobs were evicted to make room.
  std::int64_t memory_budget_bytes = 0;
  // Largest message the server accepts, in bytes (uploads come in slices far below it).
  std::int64_t max_message_bytes = std::int64_t{64} << 20;
  // Largest clip accepted (frames x channels), from uploads, inline clips and Process.
  std::int64_t max_clip_samples = std::int64_t{32} << 20;
  // Stored uploaded clips: count and total bytes of samples; least recently used evicted first.
  std::int64_t max_stored_clips = 256;
  std::int64_t max_stored_clip_bytes = std::int64_t{2} << 30;
  // Finished jobs kept (with their results): count and total bytes of results; oldest first,
  // never a job a watcher is attached to.
  std::int64_t max_stored_results = 1000;
  std::int64_t max_stored_result_bytes = std::int64_t{2} << 30;
  // A finished job is deleted this long after it ended.
  std::chrono::seconds job_ttl{3600};
  // SIGTERM: how long running and queued jobs get to finish before they are cancelled.
  std::chrono::seconds drain_grace{25};
  // Requests whose predicted work (core/pipeline/cost.h: seconds of one core, pessimistic) is
  // over this are refused before they are queued, with RESOURCE_EXHAUSTED; 0 disables the check.
  double max_job_cost_seconds = 60.0;
  // Streaming calls (uploads, watches, results, Process) open at once; beyond it new ones get
  // RESOURCE_EXHAUSTED.
  int max_concurrent_streams = 1024;
  // A streaming call whose client sends nothing for this long while the server waits for its
  // next message (uploads, Process before its start), or does not take a message the server
  // sends for this long (results, watches, Process output), is ended; 0 disables it.
  std::chrono::milliseconds stream_idle_timeout{30'000};
  // A Process call streams its first progress report at once, then at most one per this
  // interval, the latest kept and sent when it ends (server/progress_throttle.h); 0 sends every
  // new stage label (one per channel) or percent. At most one hour.
  std::chrono::milliseconds process_progress_interval{100};
  // Connections are closed (GOAWAY) after this long so clients rebalance across replicas;
  // 0 disables it. Calls in flight on a closed connection run to their end (no age grace).
  std::chrono::seconds max_connection_age{0};
  // Clients may send keepalive pings this often (with or without calls in flight); more often
  // and gRPC ends the connection after two such pings (GOAWAY "too_many_pings"). gRPC's default
  // is 5 minutes, which ended a quiet WatchJob of a client keeping its connection alive through
  // a NAT or load balancer every 30 s. At most INT_MAX milliseconds (gRPC's int).
  std::chrono::milliseconds min_client_ping_interval{10'000};
  // A connection that has not finished its TLS handshake and sent HTTP/2's opening SETTINGS
  // within this long is closed. gRPC's default is 120 s: 200 connections that opened and sent
  // nothing (or half a TLS hello) each held a socket and a handshake for two minutes. Real
  // clients finish in a few round trips. In [kMinHandshakeTimeoutMs, kMaxHandshakeTimeoutMs].
  std::chrono::milliseconds handshake_timeout{20'000};
  // Prometheus exposition ("127.0.0.1:9464"); empty disables metrics. Plain HTTP: beyond
  // loopback it needs allow_insecure_remote, whatever the gRPC port's TLS. With auth_tokens, a
  // scrape needs "Authorization: Bearer <token>" like every gRPC call.
  std::string metrics_address;
  // PEM files. Certificate and key enable TLS; a client CA additionally requires and verifies
  // client certificates (mTLS).
  std::string tls_cert_file;
  std::string tls_key_file;
  std::string tls_client_ca_file;
  // Bearer tokens accepted in "authorization: Bearer <token>"; empty disables the check.
  std::vector<std::string> auth_tokens;
  // Allows listening on a non-loopback address without TLS (and metrics beyond loopback).
  bool allow_insecure_remote = false;
  // Serves gRPC server reflection to callers without a token (with auth_tokens, reflection
  // otherwise needs one like MotionService).
  bool open_reflection = false;
  TestHooks test_hooks;
};

// Worker threads this process may use: the CPUs of its affinity mask, capped by the cgroup CPU
// quota (cgroup v2 cpu.max, or v1 cpu.cfs_quota_us / cpu.cfs_period_us), rounded up; >= 1.
int DefaultWorkerCount();

// CPUs a cgroup CPU quota allows, from the text of cgroup v2's cpu.max ("150000 100000" -> 2,
// rounded up; "max 100000" -> no quota) or, when that is empty or unreadable, cgroup v1's
// cpu.cfs_quota_us and cpu.cfs_period_us (a quota of -1 is none). 0 means no quota.
int CpuQuotaLimit(std::string_view v2_cpu_max, std::string_view v1_quota_us,
                  std::string_view v1_period_us);

// Bytes of memory this process may use: the smaller of the machine's physical memory and the
// cgroup memory limit (v2 memory.max, v1 memory.limit_in_bytes); 0 when unknown.
std::int64_t MemoryLimitBytes();

// The memory limit from the texts of cgroup v2's memory.max ("max" or bytes) or, when that is
// empty, cgroup v1's memory.limit_in_bytes (a huge value means none), and the physical memory in
// bytes: the smallest that is set, 0 when none is.
std::int64_t MemoryLimitFrom(std::string_view v2_memory_max, std::string_view v1_limit_in_bytes,
                             std::int64_t physical_bytes);

// Half of MemoryLimitBytes() (the rest is the pipelines' working memory, gRPC's buffers and the
// workers' caches), or 1 GiB when the limit is unknown.
std::int64_t DefaultMemoryBudget();

// Reads bearer tokens from `path`: one per line, blank lines and lines starting with '#'
// ignored, surrounding whitespace (and a leading UTF-8 byte order mark) trimmed.
// Errors: kNotFound / kUnavailable reading the file; kInvalidArgument when it holds no token, or
// a token no client could send (wire::CheckBearerToken(), "path:line: ...").
absl::StatusOr<std::vector<std::string>> ReadTokenFile(const std::string& path);

// True for gRPC's unix-domain socket addresses ("unix:PATH", "unix:///PATH",
// "unix-abstract:NAME"): they have no port.
bool IsUnixSocketAddress(std::string_view address);

// OK unless `address` is a unix-domain socket path ("unix:PATH", "unix:///PATH") that a process
// accepts connections on: gRPC removes the file before it binds, so a second server on the path
// started and took it over silently, the first left running unreachable. A file nobody listens on
// (left by a server that ended) is free. Errors: kUnavailable "cannot listen on ADDRESS: another
// server is listening on this socket".
absl::Status CheckUnixSocketFree(std::string_view address);

// OK when every address the host of `address` ("host:port", "[v6]:port", "unix:...") resolves
// to is a loopback address (127.0.0.0/8, ::1, ::ffff:127.0.0.0/104), or for unix-domain
// sockets. Names are resolved (getaddrinfo), so "LOCALHOST" and "[::ffff:127.0.0.1]" are
// loopback and "127.attacker.invalid" is not; an empty host ("":port, all interfaces) is not.
// Errors: kInvalidArgument saying why ("0.0.0.0 is not a loopback address",
// "127.attacker.invalid does not resolve (Name or service not known)", "example.com resolves
// to 93.184.216.34, not a loopback address").
absl::Status CheckLoopbackAddress(std::string_view address);
bool IsLoopbackAddress(std::string_view address);

// The largest job TTL and drain grace, in seconds: a year.
inline constexpr std::int64_t kMaxDurationSeconds = 365 * 24 * 3600;
// The largest connection age, in seconds: gRPC holds it as an int of milliseconds (24.8 days).
inline constexpr std::int64_t kMaxConnectionAgeSeconds = 2'147'483;
// The handshake timeout's range, in milliseconds: a tenth of a second (below, even a TLS client on
// this machine may not finish) to an hour.
inline constexpr std::int64_t kMinHandshakeTimeoutMs = 100;
inline constexpr std::int64_t kMaxHandshakeTimeoutMs = 3'600'000;

// Checks values no server can run with (sizes <= 0, durations outside the bounds above, a TLS
// key without its certificate, a non-loopback address without TLS unless
// allow_insecure_remote).
// Errors: kInvalidArgument naming the option and value.
absl::Status ValidateServerOptions(const ServerOptions& options);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_SERVER_OPTIONS_H_
