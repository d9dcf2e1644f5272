// The studio's HTTP front end (`tempokey-server --http_address`): serves the page (web root and
// three.js) and the HTTP/JSON API (json_bridge.h) on civetweb (Debian's libcivetweb), with a
// bounded number of threads, a size cap on every request message and socket timeouts.
//
// Plain HTTP only: Debian 12's civetweb 1.15 loads OpenSSL 3 at run time and its HTTPS fails
// after the handshake (its own `civetweb` binary included; civetweb's OpenSSL 3 binding was never
// tested, civetweb issue #1047). So the address follows --address's rule for a listener without
// TLS (loopback, or --allow_insecure_remote), and a server that requires client certificates
// (--tls_client_ca) refuses an HTTP front end that could not check them (http_options.h).
//
// Routes:
//   POST /tempokey.v1.MotionService/<Method>   the API (README "HTTP API")
//   GET  /three/<path>                         three.js files from HttpOptions::three_root
//   GET  /<path>                               the page's files from HttpOptions::web_root
//                                              ("/" is index.html)
#ifndef TEMPOKEY_SERVER_HTTP_HTTP_FRONT_END_H_
#define TEMPOKEY_SERVER_HTTP_HTTP_FRONT_END_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "server/http/http_options.h"
#include "server/http/json_bridge.h"
#include "server/http/slow_body_guard.h"
#include "server/server.h"

struct mg_context;
struct mg_connection;

namespace tempokey::server::http {

class HttpFrontEnd {
 public:
  // Starts serving `options` for `server`, which must outlive the front end (calls go through
  // its in-process channel; TLS files and limits are its options').
  // Errors: kInvalidArgument bad options (ValidateHttpOptions()); kUnavailable when the address
  // cannot be bound (civetweb's message).
  static absl::StatusOr<std::unique_ptr<HttpFrontEnd>> Start(const HttpOptions& options,
                                                            Server& server);
  // Stop().
  ~HttpFrontEnd();
  HttpFrontEnd(const HttpFrontEnd&) = delete;
  HttpFrontEnd& operator=(const HttpFrontEnd&) = delete;

  // The bound port (the real one for port 0).
  int port() const { return port_; }
  // "http://127.0.0.1:8080/": where the page is.
  std::string url() const;

  // Stops accepting connections and waits for requests in flight to end. Calls in flight end
  // as the server's calls do: after Server::Drain() they have ended already. Idempotent.
  void Stop();

  // Request bodies shut down for arriving too slowly (SlowBodyGuard), so far.
  std::int64_t cut_off_bodies() const { return guard_ == nullptr ? 0 : guard_->cut_off(); }
  // API calls cancelled because their client went away while they ran, so far.
  std::int64_t departed_clients() const {
    return departed_clients_.load(std::memory_order_relaxed);
  }

  // civetweb's entry point (internal).
  int HandleRequest(mg_connection* connection);

 private:
  HttpFrontEnd(const HttpOptions& options, Server& server);

  HttpOptions options_;
  Server& server_;
  JsonBridge bridge_;
  bool loopback_only_ = true;
  int port_ = 0;
  std::string host_;
  // Started once the port is known; stopped after civetweb (Stop()), whose handlers use it.
  std::unique_ptr<SlowBodyGuard> guard_;
  std::atomic<std::int64_t> departed_clients_{0};
  mg_context* context_ = nullptr;
};

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_HTTP_FRONT_END_H_
