#include "server/http/http_options.h"

#include <filesystem>
#include <system_error>

#include "absl/strings/str_cat.h"

namespace tempokey::server::http {

absl::Status ValidateHttpOptions(const HttpOptions& http, const ServerOptions& server) {
  if (http.address.empty()) return absl::OkStatus();
  if (http.threads < 1 || http.threads > 256) {
    return absl::InvalidArgumentError(
        absl::StrCat("--http_threads must be in [1, 256], got ", http.threads));
  }
  if (http.io_timeout.count() <= 0 || http.body_timeout.count() <= 0) {
    return absl::InvalidArgumentError("HTTP timeouts must be > 0");
  }
  if (http.web_root.empty()) return absl::InvalidArgumentError("--web_root must not be empty");
  if (http.three_root.empty()) return absl::InvalidArgumentError("--three_root must not be empty");
  if (http.address.rfind("unix:", 0) == 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("--http_address ", http.address, ": expected host:port"));
  }
  // The HTTP front end has no TLS (http_front_end.h): the rule --address follows for a listener
  // without TLS, by the same helper (server_options.h).
  if (!server.allow_insecure_remote && !IsLoopbackAddress(http.address)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "refusing to serve HTTP on non-loopback address ", http.address,
        " without TLS (the HTTP front end has none): use a loopback address behind a TLS proxy, "
        "or --allow_insecure_remote"));
  }
  if (!server.tls_client_ca_file.empty()) {
    return absl::InvalidArgumentError(
        "--http_address cannot check client certificates, which --tls_client_ca requires: serve "
        "the studio from a server without --tls_client_ca");
  }
  return absl::OkStatus();
}

std::string DefaultWebRoot(std::string_view executable_path) {
  namespace fs = std::filesystem;
  std::error_code error;
  fs::path executable = fs::canonical(fs::path(executable_path), error);
  if (error) executable = fs::absolute(fs::path(executable_path), error);
  const fs::path dir = executable.parent_path();
  const fs::path candidates[] = {dir / "web", dir.parent_path() / "share" / "tempokey" / "web"};
  for (const fs::path& candidate : candidates) {
    if (fs::is_regular_file(candidate / "index.html", error)) return candidate.string();
  }
  return candidates[0].string();
}

}  // namespace tempokey::server::http
