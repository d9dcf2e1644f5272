// How the HTTP/JSON API speaks of statuses: gRPC codes as HTTP statuses (the mapping
// google.rpc.Code documents and grpc-gateway uses), errors as JSON, and the rules every API
// request must meet in a browser.
#ifndef TEMPOKEY_SERVER_HTTP_HTTP_STATUS_H_
#define TEMPOKEY_SERVER_HTTP_HTTP_STATUS_H_

#include <chrono>
#include <optional>
#include <string>
#include <string_view>

#include "absl/status/status.h"

namespace tempokey::server::http {

// OK 200, INVALID_ARGUMENT / FAILED_PRECONDITION / OUT_OF_RANGE 400, UNAUTHENTICATED 401,
// PERMISSION_DENIED 403, NOT_FOUND 404, ALREADY_EXISTS / ABORTED 409, RESOURCE_EXHAUSTED 429
// when the server gave a retry hint (`retry_hint`: a full queue, no stream slot, the memory
// budget in use) and 413 without one (a request over a limit: retrying cannot help),
// CANCELLED 499, UNIMPLEMENTED 501, UNAVAILABLE 503, DEADLINE_EXCEEDED 504, others 500.
int HttpStatusOf(absl::StatusCode code, bool retry_hint);

// {"code":3,"status":"INVALID_ARGUMENT","message":"..."} plus "retryAfterMs" when a hint is
// given. The message is escaped for JSON.
std::string StatusToJson(const absl::Status& status,
                         std::optional<std::chrono::milliseconds> retry_after = std::nullopt);

// The browser rules of an API request: a JSON body ("application/json" or "application/x-ndjson",
// which a cross-site form cannot send without a CORS preflight this server never grants); an
// Origin, when the browser sends one, that is this server's own (http:// or https:// and the
// Host); and, with `loopback_host_only` (a loopback address and no bearer tokens), a Host that is
// a loopback name or address, so a DNS-rebound name cannot reach an unprotected local server.
// Errors: kInvalidArgument for the content type; kPermissionDenied for the origin or host.
absl::Status CheckApiRequest(std::string_view content_type, std::string_view origin,
                             std::string_view host, bool loopback_host_only);

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_HTTP_STATUS_H_
