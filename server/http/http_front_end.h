// The studio's HTTP front end (`tempokey-server --http_address`): serves the page (web root and
// three.js) and the HTTP/JSON API (json_bridge.h) on civetweb (Debian's libcivetweb), with a
// bounded number of threads, a size cap on every request message and socket timeouts. With the
// server's TLS flags it serves HTTPS with the same certificate, and with --tls_client_ca it
// requires client certificates from the same CA, as the gRPC port does.
//
// Routes:
//   POST /tempokey.v1.MotionService/<Method>   the API (README "HTTP API")
//   GET  /three/<path>                         three.js files from HttpOptions::three_root
//   GET  /<path>                               the page's files from HttpOptions::web_root
//                                              ("/" is index.html)
#ifndef TEMPOKEY_SERVER_HTTP_HTTP_FRONT_END_H_
#define TEMPOKEY_SERVER_HTTP_HTTP_FRONT_END_H_

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "server/http/http_options.h"
#include "server/http/json_bridge.h"
#include "server/server.h"

struct mg_context;
struct mg_connection;

namespace tempokey::server::http {

class HttpFrontEnd {
 public:
  // Starts serving `options` for `server`, which must outlive the front end (calls go through
  // its in-process channel; TLS files and limits are its options').
  // Errors: kInvalidArgument bad options (ValidateHttpOptions()); kUnavailable when the address
  // cannot be bound or TLS cannot be set up (civetweb's message).
  static absl::StatusOr<std::unique_ptr<HttpFrontEnd>> Start(const HttpOptions& options,
                                                            Server& server);
  // Stop().
  ~HttpFrontEnd();
  HttpFrontEnd(const HttpFrontEnd&) = delete;
  HttpFrontEnd& operator=(const HttpFrontEnd&) = delete;

  // The bound port (the real one for port 0).
  int port() const { return port_; }
  bool tls() const { return tls_; }
  // "http://127.0.0.1:8080/" (https with TLS): where the page is.
  std::string url() const;

  // Stops accepting connections and waits for requests in flight to end. Calls in flight end
  // as the server's calls do: after Server::Drain() they have ended already. Idempotent.
  void Stop();

  // civetweb's entry points (internal).
  int HandleRequest(mg_connection* connection);
  int InitTls(void* ssl_context);

 private:
  HttpFrontEnd(const HttpOptions& options, Server& server);

  HttpOptions options_;
  Server& server_;
  JsonBridge bridge_;
  bool loopback_only_ = true;
  bool tls_ = false;
  int port_ = 0;
  std::string host_;
  std::string tls_cert_pem_;
  std::string tls_key_pem_;
  std::string tls_client_ca_pem_;
  mg_context* context_ = nullptr;
};

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_HTTP_FRONT_END_H_
