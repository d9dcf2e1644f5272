#include "server/http/http_status.h"

#include <cctype>

#include "absl/strings/str_cat.h"
#include "proto/loopback.h"
#include "server/server_options.h"
#include "tempokey/core/io/json.h"

namespace tempokey::server::http {
namespace {

std::string_view CodeName(absl::StatusCode code) {
  switch (code) {
    case absl::StatusCode::kOk: return "OK";
    case absl::StatusCode::kCancelled: return "CANCELLED";
    case absl::StatusCode::kUnknown: return "UNKNOWN";
    case absl::StatusCode::kInvalidArgument: return "INVALID_ARGUMENT";
    case absl::StatusCode::kDeadlineExceeded: return "DEADLINE_EXCEEDED";
    case absl::StatusCode::kNotFound: return "NOT_FOUND";
    case absl::StatusCode::kAlreadyExists: return "ALREADY_EXISTS";
    case absl::StatusCode::kPermissionDenied: return "PERMISSION_DENIED";
    case absl::StatusCode::kResourceExhausted: return "RESOURCE_EXHAUSTED";
    case absl::StatusCode::kFailedPrecondition: return "FAILED_PRECONDITION";
    case absl::StatusCode::kAborted: return "ABORTED";
    case absl::StatusCode::kOutOfRange: return "OUT_OF_RANGE";
    case absl::StatusCode::kUnimplemented: return "UNIMPLEMENTED";
    case absl::StatusCode::kInternal: return "INTERNAL";
    case absl::StatusCode::kUnavailable: return "UNAVAILABLE";
    case absl::StatusCode::kDataLoss: return "DATA_LOSS";
    case absl::StatusCode::kUnauthenticated: return "UNAUTHENTICATED";
    default: return "UNKNOWN";
  }
}

std::string_view HostOf(std::string_view host_header) {
  if (!host_header.empty() && host_header.front() == '[') {
    const std::size_t close = host_header.find(']');
    return close == std::string_view::npos ? host_header : host_header.substr(1, close - 1);
  }
  return host_header.substr(0, host_header.find(':'));
}

}  // namespace

int HttpStatusOf(absl::StatusCode code, bool retry_hint) {
  switch (code) {
    case absl::StatusCode::kOk: return 200;
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kFailedPrecondition:
    case absl::StatusCode::kOutOfRange: return 400;
    case absl::StatusCode::kUnauthenticated: return 401;
    case absl::StatusCode::kPermissionDenied: return 403;
    case absl::StatusCode::kNotFound: return 404;
    case absl::StatusCode::kAlreadyExists:
    case absl::StatusCode::kAborted: return 409;
    // With a retry hint the refusal is the server's state (a full queue, no stream slot, the
    // memory budget in use): 429 Too Many Requests, which says "retry later" (RFC 6585, 4).
    // Without one the request itself is over a limit, which retrying cannot help: 413 Content
    // Too Large, "larger than the server is willing or able to process" (RFC 9110, 15.5.14).
    case absl::StatusCode::kResourceExhausted: return retry_hint ? 429 : 413;
    case absl::StatusCode::kCancelled: return 499;
    case absl::StatusCode::kUnimplemented: return 501;
    case absl::StatusCode::kUnavailable: return 503;
    case absl::StatusCode::kDeadlineExceeded: return 504;
    default: return 500;
  }
}

std::string StatusToJson(const absl::Status& status,
                         std::optional<std::chrono::milliseconds> retry_after) {
  std::string out = absl::StrCat("{\"code\":", static_cast<int>(status.code()), ",\"status\":\"",
                                 std::string(CodeName(status.code())), "\",\"message\":");
  // core's writer: a byte that does not start valid UTF-8 (a client's, quoted in a message)
  // becomes U+FFFD, since JSON is UTF-8 (RFC 8259, 8.1).
  core::AppendJsonString(out, std::string_view(status.message().data(), status.message().size()));
  if (retry_after) absl::StrAppend(&out, ",\"retryAfterMs\":", retry_after->count());
  out += '}';
  return out;
}

absl::Status CheckApiRequest(std::string_view content_type, std::string_view origin,
                             std::string_view host, bool loopback_host_only) {
  std::string type(content_type.substr(0, content_type.find(';')));
  while (!type.empty() && type.back() == ' ') type.pop_back();
  for (char& c : type) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (type != "application/json" && type != "application/x-ndjson") {
    return absl::InvalidArgumentError(absl::StrCat(
        "API requests carry JSON: Content-Type must be application/json or "
        "application/x-ndjson, got \"", std::string(content_type.substr(0, 64)), "\""));
  }
  // A TLS-terminating proxy in front makes the page's origin https:// on the same Host.
  if (!origin.empty() && origin != absl::StrCat("http://", std::string(host)) &&
      origin != absl::StrCat("https://", std::string(host))) {
    return absl::PermissionDeniedError(absl::StrCat(
        "cross-origin API requests are refused: origin ", std::string(origin.substr(0, 128)),
        " is not this server"));
  }
  if (loopback_host_only) {
    const std::string_view name = HostOf(host);
    if (!wire::IsLoopbackLiteral(name)) {
      return absl::PermissionDeniedError(absl::StrCat(
          "Host \"", std::string(host.substr(0, 128)),
          "\" is not a loopback name; this server only answers requests to its loopback address"));
    }
  }
  return absl::OkStatus();
}

}  // namespace tempokey::server::http
