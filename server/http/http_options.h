// Settings of the studio's HTTP front end (`tempokey-server --http_address`): where it listens,
// where the page's files are, and its bounds.
#ifndef TEMPOKEY_SERVER_HTTP_HTTP_OPTIONS_H_
#define TEMPOKEY_SERVER_HTTP_HTTP_OPTIONS_H_

#include <chrono>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "server/server_options.h"

namespace tempokey::server::http {

struct HttpOptions {
  // "host:port" ("127.0.0.1:0" picks a free port); empty: no HTTP front end.
  std::string address;
  // The studio page's folder (index.html, js/, ...), and three.js's (Debian's libjs-three:
  // build/three.module.js and examples/jsm/), served under /three/.
  std::string web_root;
  std::string three_root = "/usr/share/javascript/three";
  // Requests served at once (civetweb worker threads); further connections wait in its queue.
  int threads = 16;
  // A request's socket reads and writes time out after this long without progress.
  std::chrono::milliseconds io_timeout{30000};
  // A request body must arrive within this plus its length at 64 KiB/s (SlowBodyGuard): the
  // timeout above is per read, which a byte now and then keeps from ever firing.
  std::chrono::milliseconds body_timeout{30000};
};

// Checks `http` against the gRPC server's `server` options: the rule --address follows for a
// listener without TLS (the HTTP front end has none): loopback only unless allow_insecure_remote,
// by the same IsLoopbackAddress(); no --tls_client_ca (the HTTP front end could not check client
// certificates); threads in [1, 256], timeouts > 0 and folders given.
// Errors: kInvalidArgument naming the flag and value.
absl::Status ValidateHttpOptions(const HttpOptions& http, const ServerOptions& server);

// Where the page's files are by default, for a server binary at `executable_path`: a `web`
// folder beside it (the build tree links one there) or `../share/tempokey/web` (installed, the
// container image). Returns the first that holds index.html, else the first candidate.
std::string DefaultWebRoot(std::string_view executable_path);

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_HTTP_OPTIONS_H_
