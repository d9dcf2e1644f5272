// tempokey-server: serves tempokey.v1.MotionService until SIGTERM or SIGINT, then drains.
//
// Prints "tempokey-server listening on <host>:<port>" on stdout once serving (and "tempokey-server
// metrics on <host>:<port>" with --metrics_address), and with --port_file / --metrics_port_file
// writes the ports there atomically, so scripts can wait for either. Exit codes: 0 after a clean
// drain, 1 when the server cannot start, 2 for bad flags.
#include <pthread.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/strings/str_cat.h"
#include "server/grpc_log.h"
#include "server/http/http_front_end.h"
#include "server/memory_budget.h"
#include "server/server.h"
#include "server/server_usage.h"
#include "spdlog/sinks/stdout_sinks.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/status.h"

ABSL_FLAG(std::string, address, "127.0.0.1:50051",
          "Address to listen on; port 0 picks a free port (see --port_file).");
ABSL_FLAG(std::string, port_file, "",
          "Write the bound port to this file once serving (not with a unix: socket --address, "
          "which has no port).");
ABSL_FLAG(int, workers, 0,
          "Worker threads running pipelines; 0: the CPUs this process may use (affinity and "
          "cgroup quota).");
ABSL_FLAG(int, queue_capacity, 64, "Jobs waiting for a worker before submits are refused.");
ABSL_FLAG(int64_t, memory_budget_bytes, 0,
          "Memory for clips being received, stored clips, jobs and results, in bytes; past it "
          "requests get RESOURCE_EXHAUSTED. 0: half the memory this process may use (physical "
          "memory or cgroup limit).");
ABSL_FLAG(double, stream_idle_timeout_seconds, 30,
          "End a streaming call whose client sends nothing (or takes no message) for this long; "
          "0: never.");
ABSL_FLAG(double, handshake_timeout_seconds, 20,
          "Close a connection that has not finished its TLS handshake and HTTP/2 opening within "
          "this long (gRPC's own default: 120). In [0.1, 3600]: shorter, real TLS clients fail.");
ABSL_FLAG(int64_t, process_progress_interval_ms, 100,
          "A Process call streams its first progress message at once, then at most one per "
          "this many milliseconds, the latest sent when the interval ends; 0: every new stage "
          "label (one per channel) or percent. At most 3600000.");
ABSL_FLAG(int64_t, max_message_bytes, int64_t{64} << 20, "Largest message received, in bytes.");
ABSL_FLAG(int64_t, max_clip_samples, int64_t{32} << 20,
          "Largest clip accepted, in samples (frames x channels).");
ABSL_FLAG(int64_t, max_stored_clips, 256, "Uploaded clips kept (least recently used evicted).");
ABSL_FLAG(int64_t, max_stored_clip_bytes, int64_t{2} << 30, "Bytes of uploaded clips kept.");
ABSL_FLAG(int64_t, max_stored_results, 1000, "Finished jobs kept with their results.");
ABSL_FLAG(int64_t, max_stored_result_bytes, int64_t{2} << 30,
          "Bytes of finished jobs kept: their results and operations.");
ABSL_FLAG(int64_t, job_ttl_seconds, 3600, "Finished jobs are deleted this long after they end.");
ABSL_FLAG(int64_t, drain_grace_seconds, 25,
          "On SIGTERM, how long queued and running jobs get to finish.");
ABSL_FLAG(double, max_job_cost_seconds, 60.0,
          "Refuse (RESOURCE_EXHAUSTED, before queueing) requests whose predicted work is over "
          "this many seconds of one core; 0: no limit.");
ABSL_FLAG(int, max_concurrent_streams, 1024, "Streaming calls open at once.");
ABSL_FLAG(int64_t, max_connection_age_seconds, 0,
          "Close connections after this long so clients rebalance; 0: never.");
ABSL_FLAG(std::string, metrics_address, "",
          "Serve Prometheus metrics on this address (e.g. 127.0.0.1:9464; port 0 picks one, see "
          "--metrics_port_file); plain HTTP, so beyond loopback it needs --allow_insecure_remote; "
          "with --auth_token_file a scrape needs the bearer token; empty: off.");
ABSL_FLAG(std::string, metrics_port_file, "",
          "Write the bound metrics port to this file once serving.");
ABSL_FLAG(std::string, tls_cert, "", "PEM certificate chain; with --tls_key enables TLS.");
ABSL_FLAG(std::string, tls_key, "", "PEM private key of --tls_cert.");
ABSL_FLAG(std::string, tls_client_ca, "",
          "PEM CA bundle; requires and verifies client certificates (mutual TLS).");
ABSL_FLAG(std::string, auth_token_file, "",
          "File of accepted bearer tokens, one per line; calls need "
          "'authorization: Bearer <token>'.");
ABSL_FLAG(bool, allow_insecure_remote, false,
          "Allow a non-loopback --address without TLS, and a non-loopback --metrics_address.");
ABSL_FLAG(bool, open_reflection, false,
          "Serve gRPC reflection to callers without a token (with --auth_token_file it otherwise "
          "needs one).");
ABSL_FLAG(std::string, log_level, "info", "trace, debug, info, warn, error or off.");
ABSL_FLAG(std::string, http_address, "",
          "Serve the studio page and the HTTP/JSON API here (e.g. 127.0.0.1:8080); empty: off.");
ABSL_FLAG(std::string, web_root, "",
          "The studio page's folder; empty: web/ beside the binary or ../share/tempokey/web.");
ABSL_FLAG(std::string, three_root, "/usr/share/javascript/three",
          "three.js (Debian's libjs-three), served under /three/.");
ABSL_FLAG(int, http_threads, 16, "HTTP requests served at once.");

namespace {

using tempokey::server::ServerOptions;

int Run(int argc, char** argv) {
  // Block the stop signals in every thread (threads inherit the mask), then wait for them on
  // this one with sigwait(): nothing runs in signal-handler context.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGTERM);
  sigaddset(&stop_signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  if (tempokey::server::WantsUsage(std::span<char* const>(argv, static_cast<std::size_t>(argc)))) {
    std::fputs(tempokey::server::ServerUsage().c_str(), stdout);
    return 0;
  }
  absl::SetProgramUsageMessage("tempokey-server [--address host:port] [flags]");
  std::vector<char*> positional = absl::ParseCommandLine(argc, argv);
  spdlog::set_default_logger(spdlog::stderr_logger_mt("tempokey"));
  spdlog::set_level(spdlog::level::from_str(absl::GetFlag(FLAGS_log_level)));
  tempokey::server::RouteGrpcLogToSpdlog();
  if (positional.size() > 1) {
    spdlog::error("unexpected argument \"{}\" (flags only; see --help)", positional[1]);
    return 2;
  }

  if (const absl::Status tuned = tempokey::server::TuneAllocatorForServing(); !tuned.ok()) {
    spdlog::info("allocator left at its defaults: {}", std::string(tuned.message()));
  }

  ServerOptions options;
  options.address = absl::GetFlag(FLAGS_address);
  options.workers = absl::GetFlag(FLAGS_workers);
  options.queue_capacity = absl::GetFlag(FLAGS_queue_capacity);
  options.memory_budget_bytes = absl::GetFlag(FLAGS_memory_budget_bytes);
  const double idle_seconds = absl::GetFlag(FLAGS_stream_idle_timeout_seconds);
  if (!(idle_seconds >= 0.0 && idle_seconds <= 1e6)) {
    spdlog::error("--stream_idle_timeout_seconds must be in [0, 1e6], got {}", idle_seconds);
    return 2;
  }
  options.stream_idle_timeout =
      std::chrono::milliseconds(static_cast<std::int64_t>(idle_seconds * 1000.0));
  const double handshake_seconds = absl::GetFlag(FLAGS_handshake_timeout_seconds);
  if (!(handshake_seconds >= 0.1 && handshake_seconds <= 3600.0)) {
    spdlog::error("--handshake_timeout_seconds must be in [0.1, 3600], got {}", handshake_seconds);
    return 2;
  }
  options.handshake_timeout =
      std::chrono::milliseconds(std::llround(handshake_seconds * 1000.0));
  options.process_progress_interval =
      std::chrono::milliseconds(absl::GetFlag(FLAGS_process_progress_interval_ms));
  options.max_message_bytes = absl::GetFlag(FLAGS_max_message_bytes);
  options.max_clip_samples = absl::GetFlag(FLAGS_max_clip_samples);
  options.max_stored_clips = absl::GetFlag(FLAGS_max_stored_clips);
  options.max_stored_clip_bytes = absl::GetFlag(FLAGS_max_stored_clip_bytes);
  options.max_stored_results = absl::GetFlag(FLAGS_max_stored_results);
  options.max_stored_result_bytes = absl::GetFlag(FLAGS_max_stored_result_bytes);
  options.job_ttl = std::chrono::seconds(absl::GetFlag(FLAGS_job_ttl_seconds));
  options.drain_grace = std::chrono::seconds(absl::GetFlag(FLAGS_drain_grace_seconds));
  options.max_job_cost_seconds = absl::GetFlag(FLAGS_max_job_cost_seconds);
  options.max_concurrent_streams = absl::GetFlag(FLAGS_max_concurrent_streams);
  options.max_connection_age = std::chrono::seconds(absl::GetFlag(FLAGS_max_connection_age_seconds));
  options.metrics_address = absl::GetFlag(FLAGS_metrics_address);
  options.tls_cert_file = absl::GetFlag(FLAGS_tls_cert);
  options.tls_key_file = absl::GetFlag(FLAGS_tls_key);
  options.tls_client_ca_file = absl::GetFlag(FLAGS_tls_client_ca);
  options.allow_insecure_remote = absl::GetFlag(FLAGS_allow_insecure_remote);
  options.open_reflection = absl::GetFlag(FLAGS_open_reflection);
  if (const std::string token_file = absl::GetFlag(FLAGS_auth_token_file); !token_file.empty()) {
    absl::StatusOr<std::vector<std::string>> tokens = tempokey::server::ReadTokenFile(token_file);
    if (!tokens.ok()) {
      spdlog::error("--auth_token_file: {}", tempokey::core::AsStd(tokens.status().message()));
      return 2;
    }
    options.auth_tokens = *std::move(tokens);
  }
  if (tempokey::server::IsUnixSocketAddress(options.address) &&
      !absl::GetFlag(FLAGS_port_file).empty()) {
    spdlog::error("--port_file: {} is a unix socket, which has no port; the socket is the "
                  "address itself, and \"tempokey-server listening on {}\" on stdout says "
                  "when it serves",
                  options.address, options.address);
    return 2;
  }
  if (absl::Status valid = tempokey::server::ValidateServerOptions(options); !valid.ok()) {
    spdlog::error("{}", tempokey::core::AsStd(valid.message()));
    return 2;
  }
  tempokey::server::http::HttpOptions http_options;
  http_options.address = absl::GetFlag(FLAGS_http_address);
  http_options.web_root = absl::GetFlag(FLAGS_web_root);
  if (http_options.web_root.empty()) {
    http_options.web_root = tempokey::server::http::DefaultWebRoot(argv[0]);
  }
  http_options.three_root = absl::GetFlag(FLAGS_three_root);
  http_options.threads = absl::GetFlag(FLAGS_http_threads);
  if (absl::Status valid = tempokey::server::http::ValidateHttpOptions(http_options, options);
      !valid.ok()) {
    spdlog::error("{}", tempokey::core::AsStd(valid.message()));
    return 2;
  }

  absl::StatusOr<std::unique_ptr<tempokey::server::Server>> server =
      tempokey::server::Server::Start(options);
  if (!server.ok()) {
    spdlog::error("cannot start: {}", tempokey::core::AsStd(server.status().message()));
    return 1;
  }
  auto announce = spdlog::stdout_logger_mt("announce");
  announce->set_pattern("%v");
  announce->set_level(spdlog::level::info);  // the announcement is not subject to --log_level
  // Announces "<what> on host:port" (or on the unix socket's address) on stdout and in the log.
  auto announce_port = [&](std::string_view what, const std::string& address, int port) {
    const std::string where = tempokey::server::IsUnixSocketAddress(address)
                                  ? address
                                  : absl::StrCat(address.substr(0, address.rfind(':')), ":", port);
    announce->info("tempokey-server {} on {}", what, where);
    announce->flush();
    spdlog::info("{} on {}", what, where);
  };
  // Writes `port` to `port_file` (if given).
  auto write_port = [](int port, const std::string& port_file, std::string_view flag) {
    if (port_file.empty()) return true;
    absl::Status written = tempokey::core::WriteFileAtomically(port_file, absl::StrCat(port, "\n"));
    if (!written.ok()) spdlog::error("--{}: {}", flag, tempokey::core::AsStd(written.message()));
    return written.ok();
  };
  // The listening line first (scripts read the first line); both lines before the port files,
  // and the metrics port file before the main one: once the main port file exists, everything
  // is there to read.
  announce_port("listening", options.address, (*server)->port());
  bool reported = true;
  if (!options.metrics_address.empty()) {
    announce_port("metrics", options.metrics_address, (*server)->metrics_port());
    reported = write_port((*server)->metrics_port(), absl::GetFlag(FLAGS_metrics_port_file),
                          "metrics_port_file");
  }
  reported = reported && write_port((*server)->port(), absl::GetFlag(FLAGS_port_file), "port_file");
  if (!reported) {
    (*server)->Drain();
    return 1;
  }

  std::unique_ptr<tempokey::server::http::HttpFrontEnd> studio;
  if (!http_options.address.empty()) {
    auto started = tempokey::server::http::HttpFrontEnd::Start(http_options, **server);
    if (!started.ok()) {
      spdlog::error("cannot start: {}", tempokey::core::AsStd(started.status().message()));
      (*server)->Drain();
      return 1;
    }
    studio = *std::move(started);
    announce->info("tempokey-server studio on {}", studio->url());
    announce->flush();
  }

  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  spdlog::info("received {}, draining", signal_number == SIGTERM ? "SIGTERM" : "SIGINT");
  (*server)->Quiesce();
  if (studio != nullptr) studio->Stop();  // after the drain: HTTP calls get its answers too
  // Nothing is left to answer. Ending the process here instead of shutting gRPC down closes the
  // connections, which clients see as UNAVAILABLE (and retry elsewhere): gRPC's shutdown would
  // cancel with CANCELLED any call that arrived in the meantime (its core zombifies calls it
  // accepts after shutdown began), and clients do not retry CANCELLED.
  spdlog::info("exiting");
  spdlog::shutdown();
  std::fflush(nullptr);
  std::_Exit(0);
}

}  // namespace

int main(int argc, char** argv) { return Run(argc, argv); }
