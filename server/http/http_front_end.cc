#include "server/http/http_front_end.h"

#include <civetweb.h>
#include <poll.h>
#include <sys/socket.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "grpcpp/support/channel_arguments.h"
#include "proto/loopback.h"
#include "server/http/connection_socket.h"
#include "server/http/http_status.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server::http {
namespace {

namespace fs = std::filesystem;

constexpr std::string_view kApiPrefix = "/tempokey.v1.MotionService/";
constexpr std::string_view kThreePrefix = "/three/";
// Header lines every answer carries.
constexpr char kApiHeaders[] = "Cache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\n";
// The page loads only from this server: no CDN, no other origin.
constexpr char kPageHeaders[] =
    "X-Content-Type-Options: nosniff\r\n"
    "Content-Security-Policy: default-src 'self'; img-src 'self' blob: data:; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; frame-ancestors 'none'\r\n";
constexpr std::size_t kReadBlock = 64 * 1024;

std::string_view HeaderOf(const mg_connection* connection, const char* name) {
  const char* value = mg_get_header(connection, name);
  return value == nullptr ? std::string_view() : std::string_view(value);
}

bool StartsWith(std::string_view text, std::string_view prefix) {
  return text.substr(0, prefix.size()) == prefix;
}

std::string Lower(std::string_view text) {
  std::string out(text);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

std::string_view MediaTypeOf(const fs::path& path) {
  const std::string extension = Lower(path.extension().string());
  if (extension == ".html") return "text/html; charset=utf-8";
  if (extension == ".js" || extension == ".mjs") return "text/javascript; charset=utf-8";
  if (extension == ".css") return "text/css; charset=utf-8";
  if (extension == ".json") return "application/json";
  if (extension == ".png") return "image/png";
  if (extension == ".svg") return "image/svg+xml";
  if (extension == ".ico") return "image/x-icon";
  return "application/octet-stream";
}

// A file below `root` named by the cleaned URL path `relative`, or nullopt when the path has a
// hidden or parent component or names no regular file.
std::optional<fs::path> FileBelow(const std::string& root, std::string_view relative) {
  fs::path path(root);
  std::size_t start = 0;
  while (start <= relative.size()) {
    std::size_t end = relative.find('/', start);
    if (end == std::string_view::npos) end = relative.size();
    const std::string_view part = relative.substr(start, end - start);
    if (!part.empty()) {
      if (part.front() == '.' || part.find('\\') != std::string_view::npos ||
          part.find('\0') != std::string_view::npos) {
        return std::nullopt;
      }
      path /= std::string(part);
    }
    start = end + 1;
  }
  std::error_code error;
  if (!fs::is_regular_file(path, error)) return std::nullopt;
  return path;
}

void SendText(mg_connection* connection, int code, std::string_view content_type,
              std::string_view body, std::string_view extra_headers = {}) {
  mg_response_header_start(connection, code);
  mg_response_header_add(connection, "Content-Type", content_type.data(),
                         static_cast<int>(content_type.size()));
  const std::string length = std::to_string(body.size());
  mg_response_header_add(connection, "Content-Length", length.c_str(), -1);
  mg_response_header_add_lines(connection, kApiHeaders);
  if (!extra_headers.empty()) mg_response_header_add_lines(connection, std::string(extra_headers).c_str());
  mg_response_header_send(connection);
  if (!body.empty() && std::string_view(mg_get_request_info(connection)->request_method) != "HEAD") {
    mg_write(connection, body.data(), body.size());
  }
}

// An error as the API answers it: the HTTP status of its code (HttpStatusOf(): a
// RESOURCE_EXHAUSTED is 429 with a retry hint, 413 without) and {"code", "status", "message"}.
int SendApiError(mg_connection* connection, const absl::Status& status,
                 std::optional<std::chrono::milliseconds> retry_after = std::nullopt) {
  std::string extra;
  if (retry_after) {
    // Retry-After is in whole seconds; round up so a client never comes back too early.
    absl::StrAppend(&extra, "Retry-After: ", (retry_after->count() + 999) / 1000, "\r\n");
  }
  const int code = HttpStatusOf(status.code(), retry_after.has_value());
  // A 401 names the scheme it wants (RFC 9110, 11.6.1).
  if (code == 401) extra += "WWW-Authenticate: Bearer\r\n";
  SendText(connection, code, "application/json", StatusToJson(status, retry_after) + "\n", extra);
  return code;
}

// A request message over `max_bytes` of JSON: RESOURCE_EXHAUSTED without a retry hint, answered
// 413 Content Too Large (RFC 9110, 15.5.14), not the 429 that clients take as "retry later".
absl::Status MessageOverLimit(std::int64_t max_bytes) {
  return absl::ResourceExhaustedError(
      absl::StrCat("a request message is over the limit of ", max_bytes, " bytes of JSON"));
}

// The request body of one call: the whole body as one message, or one message per line for
// client-streaming methods; and the answer: one JSON object, or NDJSON lines
// {"result": ...} / {"error": ...} for server-streaming methods.
class HttpCallStream final : public JsonBridge::Stream {
 public:
  // `body_watch` (SlowBodyGuard) ends once the whole body has been read; `local_port` is the
  // front end's, which with the peer names the connection's socket.
  HttpCallStream(mg_connection* connection, const google::protobuf::MethodDescriptor& method,
                 std::int64_t max_message_bytes, SlowBodyGuard::Watch& body_watch,
                 int local_port)
      : connection_(connection),
        method_(method),
        max_bytes_(max_message_bytes),
        body_watch_(body_watch),
        local_port_(local_port) {}

  // Looked for only once a call has run for a while (kDepartureLook): short calls never scan
  // the process's descriptors. A departure is the peer's FIN or a reset, as nginx takes it
  // (proxy_ignore_client_abort off, its default, closes the upstream call when "a client closes
  // the connection without waiting for a response",
  // https://nginx.org/en/docs/http/ngx_http_proxy_module.html#proxy_ignore_client_abort).
  bool ClientGone() override {
    if (!looked_for_socket_) {
      looked_for_socket_ = true;
      const mg_request_info* info = mg_get_request_info(connection_);
      socket_ = FindConnectionSocket(local_port_, info->remote_addr, info->remote_port);
    }
    return socket_ >= 0 && PeerHasLeft(socket_);
  }

  absl::StatusOr<std::optional<std::string>> NextRequest() override {
    if (!method_.client_streaming()) {
      if (sent_single_) return std::optional<std::string>();
      sent_single_ = true;
      TEMPOKEY_RETURN_IF_ERROR(ReadUntil(/*line=*/false));
      std::string body = std::move(buffer_);
      buffer_.clear();
      if (body.find_first_not_of(" \t\r\n") == std::string::npos) body = "{}";
      return std::optional<std::string>(std::move(body));
    }
    while (true) {
      TEMPOKEY_RETURN_IF_ERROR(ReadUntil(/*line=*/true));
      const std::size_t newline = buffer_.find('\n');
      std::string line;
      if (newline == std::string::npos) {
        if (buffer_.empty()) return std::optional<std::string>();
        line = std::move(buffer_);
        buffer_.clear();
      } else {
        line = buffer_.substr(0, newline);
        buffer_.erase(0, newline + 1);
      }
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;  // blank line
      // ReadUntil() checks what it reads; a line that came with the one before is checked here.
      if (static_cast<std::int64_t>(line.size()) > max_bytes_) return OverSizeError();
      return std::optional<std::string>(std::move(line));
    }
  }

  // Whether the body was read to its end.
  bool read_to_end() const { return done_reading_; }

  bool WriteResponse(std::string_view json) override {
    if (!method_.server_streaming()) {
      single_response_ = std::string(json);
      return true;
    }
    if (!streaming_started_) {
      streaming_started_ = true;
      mg_response_header_start(connection_, 200);
      mg_response_header_add(connection_, "Content-Type", "application/x-ndjson", -1);
      // HTTP/1.0 has no chunks (RFC 9112, 6.1: no Transfer-Encoding to a 1.0 request; nginx
      // speaks 1.0 to its upstreams by default): the answer ends where the connection does, as
      // every connection here ends after its one request.
      if (!http10_) mg_response_header_add(connection_, "Transfer-Encoding", "chunked", -1);
      mg_response_header_add_lines(connection_, kApiHeaders);
      mg_response_header_send(connection_);
    }
    return SendPart(absl::StrCat("{\"result\":", core::AsAbsl(json), "}\n"));
  }

  // Sends what the call ended with: its one answer or error, or the end of the NDJSON stream.
  int Finish(const JsonBridge::Outcome& outcome) {
    // Nobody to tell (and civetweb does not know 499, the status logs give such calls).
    if (outcome.client_gone) {
      return HttpStatusOf(outcome.status.code(), outcome.retry_after.has_value());
    }
    if (streaming_started_) {
      if (!outcome.status.ok()) {
        SendPart(absl::StrCat("{\"error\":", StatusToJson(outcome.status, outcome.retry_after),
                              "}\n"));
      }
      if (!http10_) mg_send_chunk(connection_, "", 0);
      return 200;
    }
    if (!outcome.status.ok()) {
      return SendApiError(connection_, outcome.status, outcome.retry_after);
    }
    if (method_.server_streaming()) {  // a stream that ended with no message: an empty body
      SendText(connection_, 200, "application/x-ndjson", "");
      return 200;
    }
    SendText(connection_, 200, "application/json", single_response_ + "\n");
    return 200;
  }

 private:
  // Reads until a whole line is buffered (`line`) or to the end of the body, within the size cap.
  absl::Status ReadUntil(bool line) {
    // On the heap: civetweb's worker threads have small stacks (about 100 KiB).
    block_.resize(kReadBlock);
    while (!done_reading_ && !(line && buffer_.find('\n') != std::string::npos)) {
      const int got = mg_read(connection_, block_.data(), block_.size());
      if (got < 0) {
        // civetweb's chunk parser and its I/O errors say no more: a client that left cancelled
        // its call; one still there sent a body that cannot be read.
        if (ClientGone()) return absl::CancelledError("the HTTP request body could not be read");
        return absl::InvalidArgumentError(
            "the HTTP request body could not be read: its chunked framing is malformed, or it "
            "stopped arriving; nothing was done");
      }
      if (got == 0) {
        // civetweb's mg_read() also gives 0 when its I/O timeout passes: a body short of its
        // Content-Length is incomplete and is not acted on (RFC 9112, 8). Taken as whole, the
        // part that came was run as the call: a job submitted from a body cut short.
        const long long declared = mg_get_request_info(connection_)->content_length;
        if (declared >= 0 && received_ < declared) {
          return absl::InvalidArgumentError(absl::StrCat(
              "the HTTP request body ended after ", received_, " of the ", declared,
              " bytes its Content-Length declares; nothing was done"));
        }
        done_reading_ = true;
        body_watch_.End();
        break;
      }
      received_ += got;
      buffer_.append(block_.data(), static_cast<std::size_t>(got));
      const std::size_t pending = line ? std::min(buffer_.size(), buffer_.find('\n')) : buffer_.size();
      if (static_cast<std::int64_t>(pending) > max_bytes_) return OverSizeError();
    }
    return absl::OkStatus();
  }

  // One NDJSON line of a streamed answer: a chunk, or (HTTP/1.0) the bytes themselves.
  bool SendPart(const std::string& line) {
    if (http10_) return mg_write(connection_, line.data(), line.size()) > 0;
    return mg_send_chunk(connection_, line.data(), static_cast<unsigned>(line.size())) > 0;
  }

  absl::Status OverSizeError() { return MessageOverLimit(max_bytes_); }

  mg_connection* const connection_;
  const google::protobuf::MethodDescriptor& method_;
  const std::int64_t max_bytes_;
  SlowBodyGuard::Watch& body_watch_;
  const int local_port_;
  bool looked_for_socket_ = false;
  int socket_ = -1;  // civetweb's, open while the handler runs
  std::string buffer_;
  std::vector<char> block_;
  long long received_ = 0;  // bytes of the body read so far
  bool done_reading_ = false;
  bool sent_single_ = false;
  bool streaming_started_ = false;
  const bool http10_ =
      std::string_view(mg_get_request_info(connection_)->http_version) == "1.0";
  std::string single_response_;
};

// Whether the request asks for "100 Continue" before it sends its body (RFC 9110, 10.1.1): on
// HTTP/1.1 only, since a server MUST ignore that expectation in an HTTP/1.0 request (10.1.1),
// which has no interim answers (15.2).
bool ExpectsContinue(const mg_connection* connection) {
  return absl::EqualsIgnoreCase(core::AsAbsl(HeaderOf(connection, "Expect")), "100-continue") &&
         std::string_view(mg_get_request_info(connection)->http_version) == "1.1";
}

// Framing civetweb accepts but a proxy in front may read otherwise, so that a body read by one
// length here and another there is a second request (RFC 9112: 6.3, 3.2, RFC 6585: 5): two
// Content-Lengths (civetweb takes the first), Content-Length with Transfer-Encoding, no Host or
// two, and more header fields than civetweb keeps (it drops the rest, an Origin among them).
// The status and reason to refuse the request with, or 0.
std::pair<int, std::string_view> FramingRefusal(const mg_connection* connection) {
  const mg_request_info& info = *mg_get_request_info(connection);
  constexpr int kCivetwebMaxHeaders = 64;  // MG_MAX_HEADERS: the 65th and later are dropped
  if (info.num_headers >= kCivetwebMaxHeaders) {
    return {431, "a request may carry at most 63 header fields"};
  }
  int lengths = 0;
  int encodings = 0;
  int hosts = 0;
  for (int i = 0; i < info.num_headers; ++i) {
    const absl::string_view name = info.http_headers[i].name;
    if (absl::EqualsIgnoreCase(name, "Content-Length")) ++lengths;
    if (absl::EqualsIgnoreCase(name, "Transfer-Encoding")) ++encodings;
    if (absl::EqualsIgnoreCase(name, "Host")) ++hosts;
  }
  if (lengths > 1) return {400, "a request carries one Content-Length"};
  if (lengths > 0 && encodings > 0) {
    return {400, "a request carries Content-Length or Transfer-Encoding, not both"};
  }
  const bool http11 = std::string_view(info.http_version) == "1.1";
  // civetweb reads the first Transfer-Encoding only (a "chunked" after an "identity" read the
  // body as empty) and honours one on HTTP/1.0, where it has no meaning (RFC 9112, 6.1).
  if (encodings > 0) {
    if (encodings > 1 || !http11 ||
        !absl::EqualsIgnoreCase(core::AsAbsl(HeaderOf(connection, "Transfer-Encoding")),
                                "chunked")) {
      return {400, "a request's Transfer-Encoding is one \"chunked\", on HTTP/1.1"};
    }
  }
  if (lengths == 1) {
    const std::string_view length = HeaderOf(connection, "Content-Length");
    if (length.empty() || length.find_first_not_of("0123456789") != std::string_view::npos) {
      return {400, "a request's Content-Length is a decimal number"};
    }
  }
  if (hosts > 1 || (hosts == 0 && http11)) return {400, "an HTTP/1.1 request carries one Host"};
  return {0, {}};
}

// How long a refused call's body is still read and dropped after its answer, so that a client
// that sends it anyway (RFC 9110 10.1.1 allows it; most HTTP libraries send the whole body before
// they read) reads the whole answer rather than a reset, which closing a socket with unread data
// sends: a lingering close, as nginx's (lingering_time 30 s, lingering_timeout 5 s:
// https://nginx.org/en/docs/http/ngx_http_core_module.html#lingering_close). A body that keeps
// coming is read for up to kLingerTotal (the SlowBodyGuard still watches its pace); one that
// stops is left after kLingerPause with nothing received.
constexpr std::chrono::milliseconds kLingerTotal{30000};
constexpr std::chrono::milliseconds kLingerPause{2000};

// Ends a refused call's connection after its answer and returns `code`. The answer is ended on
// the socket itself (its FIN after it): a client that waits for "100 Continue" sends no body
// after a final answer, sees the end and closes. What a client sends anyway is read and dropped
// as above; then the connection is aborted (AbortConnection()), so that civetweb, which reads the
// rest of a body after the handler (unwatched), finds its end at once, and nothing more is taken.
// Before, the rest of a declared body was read to its end: 16 requests declaring 99999999999
// bytes and sending 2 held all 16 threads for 90 s, through their 413s. `local_port` is the front
// end's (FindConnectionSocket()).
int DiscardBody(mg_connection* connection, int local_port, int code) {
  const mg_request_info& info = *mg_get_request_info(connection);
  const auto deadline = std::chrono::steady_clock::now() + kLingerTotal;
  std::vector<char> block(kReadBlock);  // on the heap: civetweb's threads have small stacks
  const int socket = FindConnectionSocket(local_port, info.remote_addr, info.remote_port);
  if (socket < 0) {
    // Aborted already (the guard's cut), or not to be told apart (descriptors exhausted, an
    // ambiguous match): civetweb's reads, each up to its I/O timeout, under the guard's watch,
    // until the deadline.
    while (std::chrono::steady_clock::now() < deadline &&
           mg_read(connection, block.data(), block.size()) > 0) {
    }
    return code;
  }
  ::shutdown(socket, SHUT_WR);
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd readable{socket, POLLIN, 0};
    if (::poll(&readable, 1, static_cast<int>(std::min(left, kLingerPause).count())) <= 0) break;
    if (::recv(socket, block.data(), block.size(), MSG_DONTWAIT) <= 0) break;
  }
  AbortConnection(socket);
  return code;
}

int HandleRequestThunk(mg_connection* connection, void* front_end) {
  return static_cast<HttpFrontEnd*>(front_end)->HandleRequest(connection);
}

int LogMessage(const mg_connection*, const char* message) {
  // civetweb's messages quote what clients sent (a request line, a URI): one log line each.
  spdlog::warn("http: {}", core::PrintableText(message, core::LineBreaks::kEscaped));
  return 1;
}

// civetweb's listening_ports entry for "host:port": IPv4 literals only (Debian's civetweb is
// built without IPv6); "localhost" is 127.0.0.1.
absl::StatusOr<std::string> ListeningPort(const std::string& address) {
  const std::size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon + 1 == address.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--http_address ", address, ": expected host:port"));
  }
  std::string host = address.substr(0, colon);
  const std::string port = address.substr(colon + 1);
  if (host == "localhost") host = "127.0.0.1";
  if (host.find(':') != std::string::npos || host.find('[') != std::string::npos) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--http_address ", address, ": IPv6 is not supported by the HTTP front end; use an IPv4 "
        "address such as 127.0.0.1"));
  }
  if (port.find_first_not_of("0123456789") != std::string::npos) {
    return absl::InvalidArgumentError(
        absl::StrCat("--http_address ", address, ": port \"", port, "\" is not a number"));
  }
  TEMPOKEY_RETURN_IF_ERROR(core::Annotate(wire::CheckTargetPorts(address),
                                          absl::StrCat("--http_address ", address)));
  return absl::StrCat(host, ":", port);
}

}  // namespace

HttpFrontEnd::HttpFrontEnd(const HttpOptions& options, Server& server)
    : options_(options),
      server_(server),
      bridge_(
          [&server] {
            grpc::ChannelArguments args;
            args.SetMaxReceiveMessageSize(-1);  // answers are bounded by the server's own limits
            return server.InProcessChannel(args);
          }(),
          server.options().max_message_bytes) {}

absl::StatusOr<std::unique_ptr<HttpFrontEnd>> HttpFrontEnd::Start(const HttpOptions& options,
                                                                 Server& server) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateHttpOptions(options, server.options()));
  if (options.address.empty()) return absl::InvalidArgumentError("--http_address is empty");
  std::unique_ptr<HttpFrontEnd> front_end(new HttpFrontEnd(options, server));
  front_end->loopback_only_ = IsLoopbackAddress(options.address);
  front_end->host_ = options.address.substr(0, options.address.rfind(':'));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string ports, ListeningPort(options.address));
  const std::string threads = std::to_string(options.threads);
  const std::string io_timeout = std::to_string(options.io_timeout.count());
  const char* settings[] = {"listening_ports",       ports.c_str(),
                            "num_threads",           threads.c_str(),
                            "request_timeout_ms",    io_timeout.c_str(),
                            // One request per connection: civetweb drops header lines after
                            // a folded or non-ASCII one, and reads only the first of several
                            // Transfer-Encodings, so a body could be read as a second request
                            // that a proxy in front never saw (request smuggling, RFC 9112
                            // 11.2); on a closed connection no second request is read. (A
                            // connection that never sends a request still holds a thread until
                            // the I/O timeout.)
                            "enable_keep_alive",     "no",
                            "max_request_size",      "16384",
                            "static_file_cache_control", "no-cache",
                            // civetweb's defaults ("*") answered every CORS preflight itself,
                            // from any origin, and put "Access-Control-Allow-Origin: *" on
                            // static files and errors: no cross-origin access at all.
                            "access_control_allow_origin",  "",
                            "access_control_allow_methods", "",
                            "access_control_allow_headers", "",
                            nullptr};
  mg_callbacks callbacks;
  std::memset(&callbacks, 0, sizeof callbacks);
  callbacks.log_message = LogMessage;
  mg_init_library(0);
  char error_text[256] = {0};
  mg_init_data init;
  std::memset(&init, 0, sizeof init);
  init.callbacks = &callbacks;
  init.user_data = front_end.get();
  init.configuration_options = settings;
  mg_error_data error;
  std::memset(&error, 0, sizeof error);
  error.text = error_text;
  error.text_buffer_size = sizeof error_text;
  front_end->context_ = mg_start2(&init, &error);
  if (front_end->context_ == nullptr) {
    return absl::UnavailableError(absl::StrCat("cannot serve HTTP on ", options.address, ": ",
                                               error_text[0] != 0 ? error_text : "civetweb failed"));
  }
  mg_server_port port;
  std::memset(&port, 0, sizeof port);
  if (mg_get_server_ports(front_end->context_, 1, &port) < 1) {
    return absl::UnavailableError(absl::StrCat("cannot serve HTTP on ", options.address));
  }
  front_end->port_ = port.port;
  // Before the handler: a request may come in as soon as it is set, and it uses the guard.
  front_end->guard_ = std::make_unique<SlowBodyGuard>(port.port);
  mg_set_request_handler(front_end->context_, "/", HandleRequestThunk, front_end.get());
  spdlog::info("http: serving the studio on {} (threads={})", front_end->url(), options.threads);
  return front_end;
}

HttpFrontEnd::~HttpFrontEnd() { Stop(); }

void HttpFrontEnd::Stop() {
  if (context_ == nullptr) return;
  mg_stop(context_);
  context_ = nullptr;
}

std::string HttpFrontEnd::url() const {
  const std::string host = host_ == "localhost" || host_.empty() ? "127.0.0.1" : host_;
  return absl::StrCat("http://", host, ":", port_, "/");
}

int HttpFrontEnd::HandleRequest(mg_connection* connection) {
  const mg_request_info* info = mg_get_request_info(connection);
  if (const auto [status, reason] = FramingRefusal(connection); status != 0) {
    // civetweb's error closes the connection: nothing after this head is read as a request.
    mg_send_http_error(connection, status, "%.*s", static_cast<int>(reason.size()),
                       reason.data());
    return status;
  }
  const std::string_view verb = info->request_method;
  const std::string_view path = info->local_uri != nullptr ? info->local_uri : "";
  if (StartsWith(path, kApiPrefix)) {
    // The body must arrive at a reasonable pace (SlowBodyGuard), not a byte now and then; also
    // when the call is refused below, since civetweb reads the rest of the body after it.
    SlowBodyGuard::Watch body_watch = guard_->Start(
        info->remote_addr, info->remote_port,
        SlowBodyGuard::Clock::now() + SlowBodyGuard::Allowance(options_.body_timeout,
                                                               info->content_length,
                                                               bridge_.max_message_bytes()));
    if (verb != "POST") {
      SendText(connection, 405, "application/json",
               StatusToJson(absl::InvalidArgumentError("API calls are POST requests")) + "\n",
               "Allow: POST\r\n");
      return DiscardBody(connection, port_, 405);
    }
    const google::protobuf::MethodDescriptor* method = JsonBridge::FindMethod(path);
    if (method == nullptr) {
      const absl::Status unknown = absl::UnimplementedError(
          absl::StrCat("no method ", core::AsAbsl(path.substr(1)), " in this server"));
      return DiscardBody(connection, port_, SendApiError(connection, unknown));
    }
    if (absl::Status allowed = CheckApiRequest(
            HeaderOf(connection, "Content-Type"), HeaderOf(connection, "Origin"),
            HeaderOf(connection, "Host"), loopback_only_ && server_.options().auth_tokens.empty());
        !allowed.ok()) {
      return DiscardBody(connection, port_, SendApiError(connection, allowed));
    }
    // What can be refused without the body is refused before it is read (or, from a client
    // that waits for "100 Continue", before it is asked for: RFC 9110 10.1.1, a final answer
    // instead of 100): a missing or wrong token, and a declared length over the limit of a
    // call whose body is one message.
    if (absl::Status access = server_.CheckBearer(mg_get_header(connection, "Authorization"));
        !access.ok()) {
      return DiscardBody(connection, port_, SendApiError(connection, access));
    }
    if (!method->client_streaming() && info->content_length > bridge_.max_message_bytes()) {
      return DiscardBody(connection, port_,
                         SendApiError(connection, MessageOverLimit(bridge_.max_message_bytes())));
    }
    if (const std::string_view expect = HeaderOf(connection, "Expect"); !expect.empty()) {
      if (!absl::EqualsIgnoreCase(core::AsAbsl(expect), "100-continue")) {
        mg_send_http_error(connection, 417, "only \"Expect: 100-continue\" is understood");
        return 417;
      }
      // civetweb answers it only for its own file uploads: a client waited a second for it.
      // Written on the socket itself: through civetweb, any write counts as the answer's start,
      // and the answer's own head would no longer be sent.
      if (ExpectsContinue(connection)) {
        constexpr std::string_view kContinue = "HTTP/1.1 100 Continue\r\n\r\n";
        if (const int socket = FindConnectionSocket(port_, info->remote_addr, info->remote_port);
            socket >= 0) {
          ::send(socket, kContinue.data(), kContinue.size(), MSG_NOSIGNAL);
        }
      }
    }
    HttpCallStream stream(connection, *method, bridge_.max_message_bytes(), body_watch, port_);
    const JsonBridge::Outcome outcome =
        bridge_.Call(*method, HeaderOf(connection, "Authorization"), stream);
    if (outcome.client_gone) {
      departed_clients_.fetch_add(1, std::memory_order_relaxed);
      spdlog::info("http: the client of {} ({}:{}) went away; the call was cancelled",
                   method->name(), info->remote_addr, info->remote_port);
    }
    const int code = stream.Finish(outcome);
    // Refused while its body was being read (cut short, over the size limit, malformed): the
    // rest of the body is dropped as for a refusal before it (civetweb would read it after the
    // handler, unwatched, up to its declared end).
    if (!outcome.status.ok() && !stream.read_to_end()) return DiscardBody(connection, port_, code);
    return code;
  }
  if (verb != "GET" && verb != "HEAD") {
    SendText(connection, 405, "text/plain; charset=utf-8", "method not allowed\n",
             "Allow: GET, HEAD\r\n");
    return 405;
  }
  std::optional<fs::path> file;
  if (StartsWith(path, kThreePrefix)) {
    file = FileBelow(options_.three_root, path.substr(kThreePrefix.size()));
  } else {
    file = FileBelow(options_.web_root, path == "/" ? std::string_view("index.html") : path);
  }
  if (!file) {
    SendText(connection, 404, "text/plain; charset=utf-8", "not found\n");
    return 404;
  }
  const std::string media_type(MediaTypeOf(*file));
  mg_send_mime_file2(connection, file->c_str(), media_type.c_str(), kPageHeaders);
  return 200;
}

}  // namespace tempokey::server::http
