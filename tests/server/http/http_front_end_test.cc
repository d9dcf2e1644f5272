// The HTTP front end's pieces: its options against the --address rule, the status mapping and
// browser rules, and the JSON bridge driving a real server's handlers through its in-process
// channel.
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <utility>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "absl/strings/str_cat.h"
#include "google/protobuf/util/json_util.h"
#include "server/http/http_front_end.h"
#include "server/http/http_options.h"
#include "server/http/http_status.h"
#include "server/http/json_bridge.h"
#include "server/http/json_names.h"
#include "server/server.h"
#include "tempokey/core/io/json.h"
#include "tempokey/v1/motion_service.pb.h"
#include "tests/server/http_util.h"
#include "tests/server/server_test_util.h"
#include "tests/server/test_clips.h"
#include "tests/testing/test_paths.h"

namespace tempokey::server::http {
namespace {

using ::testing::HasSubstr;

HttpOptions Options(std::string address) {
  HttpOptions options;
  options.address = std::move(address);
  options.web_root = "/nowhere";
  return options;
}

TEST(HttpOptionsTest, FollowsTheAddressLoopbackRuleForAListenerWithoutTls) {
  ServerOptions server;
  ServerOptions insecure;
  insecure.allow_insecure_remote = true;
  ServerOptions tls;
  tls.tls_cert_file = "cert.pem";
  tls.tls_key_file = "key.pem";
  ServerOptions mutual = tls;
  mutual.tls_client_ca_file = "ca.pem";

  EXPECT_TRUE(ValidateHttpOptions(Options("127.0.0.1:0"), server).ok());
  EXPECT_TRUE(ValidateHttpOptions(Options("localhost:8080"), server).ok());
  EXPECT_TRUE(ValidateHttpOptions(Options(""), server).ok());
  EXPECT_THAT(std::string(ValidateHttpOptions(Options("0.0.0.0:8080"), server).message()),
              HasSubstr("refusing to serve HTTP on non-loopback address 0.0.0.0:8080 without TLS"));
  EXPECT_THAT(std::string(ValidateHttpOptions(Options("10.1.2.3:8080"), tls).message()),
              HasSubstr("refusing to serve HTTP on non-loopback address"));
  EXPECT_TRUE(ValidateHttpOptions(Options("0.0.0.0:8080"), insecure).ok());
  EXPECT_TRUE(ValidateHttpOptions(Options("127.0.0.1:8080"), tls).ok());
  EXPECT_THAT(std::string(ValidateHttpOptions(Options("127.0.0.1:8080"), mutual).message()),
              HasSubstr("cannot check client certificates"));
  HttpOptions no_threads = Options("127.0.0.1:0");
  no_threads.threads = 0;
  EXPECT_EQ(ValidateHttpOptions(no_threads, server).message(), "--http_threads must be in [1, 256], got 0");
}

TEST(HttpOptionsTest, DefaultWebRootIsTheFolderBesideTheBinaryThatHoldsThePage) {
  namespace fs = std::filesystem;
  const fs::path dir = testing::MakeTempDir();
  fs::create_directories(dir / "bin");
  fs::create_directories(dir / "share" / "tempokey" / "web");
  std::ofstream(dir / "share" / "tempokey" / "web" / "index.html") << "<!doctype html>";

  EXPECT_EQ(DefaultWebRoot((dir / "bin" / "tempokey-server").string()),
            (dir / "share" / "tempokey" / "web").string());
  fs::create_directories(dir / "bin" / "web");
  std::ofstream(dir / "bin" / "web" / "index.html") << "<!doctype html>";
  EXPECT_EQ(DefaultWebRoot((dir / "bin" / "tempokey-server").string()), (dir / "bin" / "web").string());
}

TEST(HttpStatusTest, GrpcCodesMapToTheDocumentedHttpStatuses) {
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kOk, false), 200);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kInvalidArgument, false), 400);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kFailedPrecondition, false), 400);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kUnauthenticated, false), 401);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kPermissionDenied, false), 403);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kNotFound, false), 404);
  // RESOURCE_EXHAUSTED: "retry later" only when the server said when (its retry hint).
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kResourceExhausted, true), 429);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kResourceExhausted, false), 413);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kCancelled, false), 499);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kInternal, false), 500);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kUnimplemented, false), 501);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kUnavailable, false), 503);
  EXPECT_EQ(HttpStatusOf(absl::StatusCode::kDeadlineExceeded, false), 504);
}

TEST(HttpStatusTest, ErrorJsonEscapesTheMessageAndCarriesTheRetryHint) {
  EXPECT_EQ(StatusToJson(absl::InvalidArgumentError("walk.bvh:1:2: got \"x\"\t\\\n")),
            R"({"code":3,"status":"INVALID_ARGUMENT","message":"walk.bvh:1:2: got \"x\"\t\\\n"})");
  EXPECT_EQ(StatusToJson(absl::ResourceExhaustedError("full"), std::chrono::milliseconds(250)),
            R"({"code":8,"status":"RESOURCE_EXHAUSTED","message":"full","retryAfterMs":250})");
  // A client's bytes quoted in a message ({"text":"\xff\xfe"}, a method name "Get%FFInfo"):
  // JSON is UTF-8, so they are U+FFFD (the body was not JSON a parser would read).
  const std::string quoted = StatusToJson(absl::InvalidArgumentError("got \"\xff\xfe\" é"));
  EXPECT_EQ(quoted, "{\"code\":3,\"status\":\"INVALID_ARGUMENT\",\"message\":\"got "
                    "\\\"\xef\xbf\xbd\xef\xbf\xbd\\\" é\"}");
  EXPECT_TRUE(core::IsUtf8(quoted));
}

TEST(HttpStatusTest, BrowserRulesRefuseOtherOriginsRebindingHostsAndFormBodies) {
  EXPECT_TRUE(CheckApiRequest("application/json", "", "127.0.0.1:80", true).ok());
  EXPECT_TRUE(CheckApiRequest("application/x-ndjson; charset=utf-8", "http://localhost:8080",
                              "localhost:8080", true).ok());
  EXPECT_TRUE(CheckApiRequest("application/json", "https://studio.example", "studio.example", false).ok());
  EXPECT_EQ(CheckApiRequest("text/plain", "", "127.0.0.1:80", true).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(CheckApiRequest("application/json", "http://evil.example", "127.0.0.1:80", true).code(),
            absl::StatusCode::kPermissionDenied);
  EXPECT_EQ(CheckApiRequest("application/json", "", "rebound.example:80", true).code(),
            absl::StatusCode::kPermissionDenied);
  EXPECT_TRUE(CheckApiRequest("application/json", "", "rebound.example:80", false).ok());
}

// One call's request lines and answers, in memory.
class MemoryStream final : public JsonBridge::Stream {
 public:
  explicit MemoryStream(std::vector<std::string> requests) : requests_(std::move(requests)) {}
  absl::StatusOr<std::optional<std::string>> NextRequest() override {
    if (next_ == requests_.size()) return std::optional<std::string>();
    return std::optional<std::string>(requests_[next_++]);
  }
  bool WriteResponse(std::string_view json) override {
    responses.emplace_back(json);
    return true;
  }
  std::vector<std::string> responses;

 private:
  std::vector<std::string> requests_;
  std::size_t next_ = 0;
};

TEST(JsonBridgeTest, FindsEveryMethodOfTheServiceAndNothingElse) {
  const auto* service = google::protobuf::DescriptorPool::generated_pool()->FindServiceByName(kBridgedService);
  ASSERT_NE(service, nullptr);
  for (int i = 0; i < service->method_count(); ++i) {
    EXPECT_EQ(JsonBridge::FindMethod("/tempokey.v1.MotionService/" + service->method(i)->name()),
              service->method(i));
  }
  EXPECT_EQ(JsonBridge::FindMethod("/tempokey.v1.MotionService/Nope"), nullptr);
  EXPECT_EQ(JsonBridge::FindMethod("/grpc.health.v1.Health/Check"), nullptr);
  EXPECT_EQ(JsonBridge::FindMethod("tempokey.v1.MotionService/GetJob"), nullptr);
}

TEST(JsonBridgeTest, CallsTheServersOwnHandlersWithJsonMessages) {
  std::unique_ptr<Server> server = testing::StartServer(testing::TestServerOptions());
  ASSERT_NE(server, nullptr);
  JsonBridge bridge(server->InProcessChannel(), 1 << 20);
  MemoryStream info({"{}"});
  MemoryStream missing({R"({"jobId": "job-none"})"});
  MemoryStream mistyped({R"({"jobID": 3})"});

  const JsonBridge::Outcome a =
      bridge.Call(*JsonBridge::FindMethod("/tempokey.v1.MotionService/GetServerInfo"), "", info);
  const JsonBridge::Outcome b =
      bridge.Call(*JsonBridge::FindMethod("/tempokey.v1.MotionService/GetJob"), "", missing);
  const JsonBridge::Outcome c =
      bridge.Call(*JsonBridge::FindMethod("/tempokey.v1.MotionService/GetJob"), "", mistyped);

  ASSERT_TRUE(a.status.ok()) << a.status;
  ASSERT_EQ(info.responses.size(), 1u);
  v1::ServerInfo parsed;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(info.responses[0], &parsed).ok());
  EXPECT_EQ(parsed.operations_size(), static_cast<int>(server->operations().size()));
  EXPECT_EQ(b.status.code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(missing.responses.empty());
  EXPECT_EQ(c.status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(c.status.message()),
              HasSubstr("request message 1 is not a tempokey.v1.GetJobRequest in JSON"));
}

// protobuf's JSON parser takes the last of a repeated name without a word: a probe's
// {"jobId":"a","jobId":"b"} looked up "b", and {"text":"0s:1","text":"0s:2"} read "0s:2". A name
// given twice in one object is refused, decoded ("\u0061" is "a"); the same name in two objects,
// or as a value, is not a repeat.
TEST(JsonBridgeTest, AMemberNamedTwiceInOneObjectIsRefused) {
  std::unique_ptr<Server> server = testing::StartServer(testing::TestServerOptions());
  ASSERT_NE(server, nullptr);
  JsonBridge bridge(server->InProcessChannel(), 1 << 20);
  const google::protobuf::MethodDescriptor& get_job =
      *JsonBridge::FindMethod("/tempokey.v1.MotionService/GetJob");
  MemoryStream twice({R"({"jobId":"job-a","jobId":"job-b"})"});
  MemoryStream escaped({R"({"jobId":"job-a","\u006aobId":"job-b"})"});

  const JsonBridge::Outcome a = bridge.Call(get_job, "", twice);
  const JsonBridge::Outcome b = bridge.Call(get_job, "", escaped);

  EXPECT_EQ(a.status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(a.status.message()),
            "request message 1: member \"jobId\" is named twice in one object (at byte 18); a "
            "JSON request names each field once");
  EXPECT_EQ(b.status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(b.status.message()), HasSubstr("member \"jobId\" is named twice"));
  for (const char* json :
       {R"({"a":{"x":1},"b":{"x":2}})", R"({"a":"a","b":["a","a"],"c":{"a":{"a":1}}})",
        R"({"a":"x\"y","b":1})", R"([{"a":1},{"a":2}])", "not json", R"({"a":)"}) {
    EXPECT_TRUE(CheckNoRepeatedNames(json).ok()) << json;
  }
  EXPECT_FALSE(CheckNoRepeatedNames(R"({"a":1,"b":{"c":1,"c":2}})").ok());
  EXPECT_FALSE(CheckNoRepeatedNames(R"({"\ud83d\ude00":1,"\ud83d\ude00":2})").ok());
}

// civetweb's timeout is per read, and mg_read() waits for the whole block it asked for: a client
// sending its body a byte at a time held a worker thread for as long as it liked (every thread,
// with as many such clients). A body must now arrive within the I/O timeout plus its length at
// 64 KiB/s, or its connection is shut down; the front end goes on serving. The bytes here come
// every 10 ms, far inside the per-read timeout, so only the guard can end the request.
TEST(HttpFrontEndTest, ARequestBodyTrickledInIsCutOffAndThePageStillServed) {
  std::unique_ptr<Server> server = testing::StartServer(testing::TestServerOptions());
  ASSERT_NE(server, nullptr);
  HttpOptions options = Options("127.0.0.1:0");
  options.web_root = testing::MakeTempDir();
  // civetweb's per-read timeout far beyond the test (a loaded machine may stall the sender for
  // seconds), the body's own 2 s: only the guard can end these requests.
  options.io_timeout = std::chrono::milliseconds(600000);
  options.body_timeout = std::chrono::milliseconds(2000);
  absl::StatusOr<std::unique_ptr<HttpFrontEnd>> front_end = HttpFrontEnd::Start(options, *server);
  ASSERT_TRUE(front_end.ok()) << front_end.status();
  const int port = (*front_end)->port();
  const int fd = testing::ConnectLoopback(port);
  ASSERT_GE(fd, 0);
  const std::string head =
      "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: application/json\r\nContent-Length: 100000\r\nConnection: close\r\n\r\n";
  ASSERT_EQ(::send(fd, head.data(), head.size(), MSG_NOSIGNAL), static_cast<ssize_t>(head.size()));

  // A space at a time (JSON whitespace) until the connection ends; 60 s at most.
  bool ended = false;
  for (int sent = 0; sent < 6000 && !ended; ++sent) {
    if (::send(fd, " ", 1, MSG_NOSIGNAL) != 1) {
      ended = true;
      break;
    }
    pollfd ready{.fd = fd, .events = POLLIN, .revents = 0};
    ended = ::poll(&ready, 1, 10) > 0;  // readable: the end of the stream (or an answer)
  }
  const std::string response = testing::ReadToEnd(fd);
  ::close(fd);
  const std::optional<std::string> page = testing::HttpGet(port, "/");

  EXPECT_TRUE(ended);
  EXPECT_EQ(response, "");  // no answer: the connection was shut down
  EXPECT_EQ((*front_end)->cut_off_bodies(), 1);
  ASSERT_TRUE(page.has_value());
  EXPECT_THAT(*page, ::testing::StartsWith("HTTP/1.1 404"));  // an empty web root, served

  // A call refused at once (a form's content type) is answered at once, and what its client goes
  // on sending is read under the same watch (DiscardBody()'s linger): trickled, it is cut off by
  // the guard as the first was; civetweb would read it after the handler, unwatched.
  const int refused = testing::ConnectLoopback(port);
  ASSERT_GE(refused, 0);
  const std::string form =
      "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: text/plain\r\nContent-Length: 100000\r\n\r\n";
  ASSERT_EQ(::send(refused, form.data(), form.size(), MSG_NOSIGNAL),
            static_cast<ssize_t>(form.size()));
  std::string refusal;
  bool refused_ended = false;  // a send failed: the server stopped taking the body
  for (int sent = 0; sent < 6000 && !refused_ended; ++sent) {  // 60 s at most
    refused_ended = ::send(refused, " ", 1, MSG_NOSIGNAL) != 1;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    char buffer[4096];
    const ssize_t n = ::recv(refused, buffer, sizeof buffer, MSG_DONTWAIT);
    if (n > 0) refusal.append(buffer, static_cast<std::size_t>(n));
  }
  ::close(refused);

  EXPECT_TRUE(refused_ended);
  EXPECT_EQ((*front_end)->cut_off_bodies(), 2);
  EXPECT_THAT(refusal, ::testing::StartsWith("HTTP/1.1 4"));
}

// A Process call over HTTP: the clip and its start as NDJSON lines, one message each.
std::string ProcessRequestOverHttp(const core::Clip& clip) {
  std::vector<v1::ProcessRequest> requests = testing::ProcessClipRequests(clip);
  *requests.emplace_back().mutable_start()->mutable_operations() = testing::WrapOperations();
  std::string body;
  for (const v1::ProcessRequest& request : requests) {
    absl::StatusOr<std::string> json = MessageToJson(request);
    EXPECT_TRUE(json.ok()) << json.status();
    body += json.value_or("") + "\n";
  }
  return absl::StrCat(
      "POST /tempokey.v1.MotionService/Process HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: application/x-ndjson\r\nContent-Length: ", body.size(),
      "\r\nConnection: close\r\n\r\n", body);
}

// A front end on a fresh server whose messages are at most `max_message_bytes`, with `tokens`.
struct FrontEnd {
  std::unique_ptr<Server> server;
  std::unique_ptr<HttpFrontEnd> http;
};
// `timeouts`, when given, replaces the front end's socket and body timeouts; `edit`, when given,
// changes its options last.
FrontEnd StartFrontEnd(std::int64_t max_message_bytes = 64 << 20,
                       std::vector<std::string> tokens = {},
                       std::optional<std::chrono::milliseconds> timeouts = std::nullopt,
                       void (*edit)(HttpOptions&) = nullptr) {
  ServerOptions server_options = testing::TestServerOptions();
  server_options.max_message_bytes = max_message_bytes;
  server_options.auth_tokens = std::move(tokens);
  FrontEnd front_end{testing::StartServer(server_options), nullptr};
  if (front_end.server == nullptr) return front_end;
  HttpOptions options = Options("127.0.0.1:0");
  options.web_root = testing::MakeTempDir();
  if (timeouts) options.io_timeout = options.body_timeout = *timeouts;
  if (edit != nullptr) edit(options);
  std::ofstream(options.web_root + "/index.html") << "<!doctype html>";
  absl::StatusOr<std::unique_ptr<HttpFrontEnd>> http = HttpFrontEnd::Start(options, *front_end.server);
  EXPECT_TRUE(http.ok()) << http.status();
  if (http.ok()) front_end.http = *std::move(http);
  return front_end;
}

// Sends `bytes` on a new connection and reads everything until the server closes it.
std::string Exchange(int port, const std::string& bytes) {
  return testing::Exchange(port, bytes).value_or("no connection");
}

// How many HTTP responses `answer` holds.
int Responses(const std::string& answer) {
  int count = 0;
  for (std::size_t at = answer.find("HTTP/1."); at != std::string::npos;
       at = answer.find("HTTP/1.", at + 1)) {
    ++count;
  }
  return count;
}

// A connection on which a GetServerInfo call declares `declared_length` bytes of body and sends
// only "{}"; -1 when it cannot connect or send. The caller reads the answer and closes it.
int SendShortBody(int port, const std::string& declared_length) {
  const int fd = testing::ConnectLoopback(port);
  if (fd < 0) return -1;
  const std::string request =
      "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: application/json\r\nContent-Length: " + declared_length + "\r\n\r\n{}";
  if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) !=
      static_cast<ssize_t>(request.size())) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// A probe with a client of its own (2026-12-02) found a refused call holding a thread for as long
// as its client kept the connection: 16 requests declaring 99999999999 bytes and sending 2 had
// their 413s at once, but their bodies were read to their declared ends, and the front end
// answered nothing else for 90 s. Here civetweb's own read timeout is 600 s, so only the linger
// after the answer can end such a call: the refusal ends with the server's FIN, and the one
// thread answers the next request while the refused client still holds its connection.
TEST(HttpFrontEndTest, ARefusedCallWhoseBodyNeverComesHoldsNoThread) {
  const FrontEnd front_end = StartFrontEnd(64 << 20, {}, std::nullopt, [](HttpOptions& options) {
    options.threads = 1;
    options.io_timeout = options.body_timeout = std::chrono::milliseconds(600000);
  });
  ASSERT_NE(front_end.http, nullptr);
  const int port = front_end.http->port();

  const int holder = SendShortBody(port, "99999999999");
  ASSERT_GE(holder, 0);
  bool closed_by_server = false;
  const std::string refusal = testing::ReadToEnd(holder, &closed_by_server);
  // The refused client still holds its connection, sending nothing: the one thread is free once
  // the linger has seen a pause (not the test's 60 s hang guard).
  const std::optional<std::string> page = testing::HttpGet(port, "/");
  ::close(holder);

  EXPECT_THAT(refusal, ::testing::StartsWith("HTTP/1.1 413"));
  EXPECT_THAT(refusal, HasSubstr("a request message is over the limit of"));
  EXPECT_TRUE(closed_by_server);  // not the test's 60 s hang guard
  ASSERT_TRUE(page.has_value());
  EXPECT_THAT(*page, ::testing::StartsWith("HTTP/1.1 200"));  // the page, served
}

// A client that sends its whole body before it reads (most HTTP libraries do) gets the whole
// refusal: the review of the linger found a 3 MB body sent at 1 MB/s answered with a reset, its
// 401 lost, when the linger had a total of 2 s. Here a refused body (a form's content type) of
// 3 MiB comes in 48 pieces 50 ms apart, each taken, and the refusal is read after it.
TEST(HttpFrontEndTest, AClientSendingItsWholeRefusedBodyAtAModestPaceReadsTheWholeAnswer) {
  const FrontEnd front_end = StartFrontEnd();
  ASSERT_NE(front_end.http, nullptr);
  const int fd = testing::ConnectLoopback(front_end.http->port());
  ASSERT_GE(fd, 0);
  const std::string piece(64 << 10, ' ');
  const std::string head = absl::StrCat(
      "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: text/plain\r\nContent-Length: ", 48 * piece.size(), "\r\n\r\n");
  ASSERT_EQ(::send(fd, head.data(), head.size(), MSG_NOSIGNAL), static_cast<ssize_t>(head.size()));
  int taken = 0;
  for (int i = 0; i < 48; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (::send(fd, piece.data(), piece.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(piece.size())) {
      break;
    }
    ++taken;
  }
  bool closed_by_server = false;
  const std::string answer = testing::ReadToEnd(fd, &closed_by_server);
  ::close(fd);

  EXPECT_EQ(taken, 48);
  EXPECT_THAT(answer, ::testing::StartsWith("HTTP/1.1 400"));
  EXPECT_THAT(answer, HasSubstr("\"status\":\"INVALID_ARGUMENT\""));
  EXPECT_TRUE(closed_by_server);
}

// RFC 9112 8: a body short of its Content-Length is incomplete and is not acted on. civetweb's
// read gives 0 when its I/O timeout passes, and the part that had come was run as the whole
// call (a probe's SubmitJob of 347 bytes declared as 4 000 000 was queued and ran). A chunked
// body whose framing is malformed is the client's error (400), not a cancellation (499).
TEST(HttpFrontEndTest, AnIncompleteOrMalformedBodyIsRefusedNotRun) {
  const FrontEnd front_end = StartFrontEnd(64 << 20, {}, std::nullopt, [](HttpOptions& options) {
    options.io_timeout = std::chrono::milliseconds(1000);     // civetweb's read gives up first
    options.body_timeout = std::chrono::milliseconds(600000);  // the guard never cuts here
  });
  ASSERT_NE(front_end.http, nullptr);
  const int port = front_end.http->port();

  const int fd = SendShortBody(port, "1000");
  ASSERT_GE(fd, 0);
  const std::string incomplete = testing::ReadToEnd(fd);  // the connection open meanwhile
  ::close(fd);
  const std::string malformed = Exchange(
      port,
      "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\nZZ\r\n{}\r\n0\r\n\r\n");

  EXPECT_THAT(incomplete, ::testing::StartsWith("HTTP/1.1 400"));
  EXPECT_THAT(incomplete, HasSubstr("the HTTP request body ended after 2 of the 1000 bytes its "
                                    "Content-Length declares; nothing was done"));
  EXPECT_THAT(incomplete, ::testing::Not(HasSubstr("\"version\"")));  // no ServerInfo
  EXPECT_THAT(malformed, ::testing::StartsWith("HTTP/1.1 400"));
  EXPECT_THAT(malformed, HasSubstr("its chunked framing is malformed"));
}

// A probe with an HTTP client of its own found civetweb reading a body as a second request when
// the framing was ambiguous (request smuggling, behind any proxy that reads it otherwise), and
// dropping header fields past the 64th, an Origin among them. Each such request is refused and
// its connection closed: the body smuggled in is never answered.
TEST(HttpFrontEndTest, AmbiguousFramingIsRefusedAndNothingSmuggledIsAnswered) {
  FrontEnd front_end = StartFrontEnd();
  ASSERT_NE(front_end.http, nullptr);
  const int port = front_end.http->port();
  const std::string smuggled =
      "POST /tempokey.v1.MotionService/ParseSpeedKnots HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: application/json\r\nContent-Length: 2\r\n\r\n{}";
  const std::string api = "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\n";
  std::string many = api + "Host: 127.0.0.1\r\nContent-Type: application/json\r\n";
  for (int i = 0; i < 70; ++i) many += absl::StrCat("X-Filler-", i, ": x\r\n");
  many += "Origin: http://evil.example\r\nContent-Length: 0\r\n\r\n";

  const std::string two_lengths = Exchange(
      port, absl::StrCat(api, "Host: 127.0.0.1\r\nContent-Type: application/json\r\n"
                              "Content-Length: 2\r\nContent-Length: ", 2 + smuggled.size(),
                         "\r\n\r\n{}", smuggled));
  const std::string length_and_chunks = Exchange(
      port, absl::StrCat(api, "Host: 127.0.0.1\r\nContent-Type: application/json\r\n"
                              "Content-Length: 2\r\nTransfer-Encoding: chunked\r\n\r\n{}",
                         smuggled));
  const std::string too_many = Exchange(port, many);
  // A folded header line ends civetweb's header parsing, the Content-Length after it dropped:
  // the body would have been the connection's next request.
  const std::string folded = Exchange(
      port, absl::StrCat(api, "Host: 127.0.0.1\r\nContent-Type: application/json\r\n"
                              "X-Folded: a\r\n b\r\nContent-Length: ", smuggled.size(),
                         "\r\n\r\n", smuggled));
  // civetweb reads the first Transfer-Encoding only: this body read as empty.
  const std::string two_encodings = Exchange(
      port, absl::StrCat(api, "Host: 127.0.0.1\r\nContent-Type: application/json\r\n"
                              "Transfer-Encoding: identity\r\nTransfer-Encoding: chunked\r\n"
                              "\r\n2\r\n{}\r\n0\r\n\r\n"));
  const std::string signed_length = Exchange(
      port, api + "Host: 127.0.0.1\r\nContent-Type: application/json\r\nContent-Length: +2\r\n"
                  "\r\n{}");
  const std::string no_host =
      Exchange(port, "GET / HTTP/1.1\r\nConnection: close\r\n\r\n");
  const std::string two_hosts = Exchange(
      port, "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nHost: evil.example\r\nConnection: close\r\n\r\n");

  EXPECT_THAT(two_lengths, ::testing::StartsWith("HTTP/1.1 400"));
  EXPECT_THAT(two_lengths, HasSubstr("a request carries one Content-Length"));
  EXPECT_THAT(length_and_chunks, ::testing::StartsWith("HTTP/1.1 400"));
  EXPECT_THAT(length_and_chunks, HasSubstr("Content-Length or Transfer-Encoding, not both"));
  EXPECT_THAT(too_many, ::testing::StartsWith("HTTP/1.1 431"));
  EXPECT_THAT(two_encodings, HasSubstr("Transfer-Encoding is one \"chunked\""));
  EXPECT_THAT(signed_length, HasSubstr("Content-Length is a decimal number"));
  EXPECT_THAT(no_host, ::testing::StartsWith("HTTP/1.1 400"));
  EXPECT_THAT(two_hosts, ::testing::StartsWith("HTTP/1.1 400"));
  // Every connection ends after its one request: nothing smuggled is answered.
  for (const std::string* answer : {&two_lengths, &length_and_chunks, &too_many, &folded}) {
    EXPECT_EQ(Responses(*answer), 1) << *answer;
  }
  EXPECT_THAT(folded, HasSubstr("Connection: close"));
}

// civetweb answered CORS preflights itself for any origin ("Access-Control-Allow-Origin: *") and
// put that header on static files; it answered "Expect: 100-continue" only for its own uploads,
// so a client waited a second before sending each body; an HTTP/1.0 client (nginx's default
// to its upstreams) got chunk sizes in its NDJSON; a line over the size limit passed when it came with the line before; a body over
// it got 429 "Too Many Requests"; a 401 named no scheme.
TEST(HttpFrontEndTest, CorsExpectHttp10SizeAndAuthAnswersFollowHttp) {
  FrontEnd front_end = StartFrontEnd(4096);
  ASSERT_NE(front_end.http, nullptr);
  const int port = front_end.http->port();
  const std::string preflight = Exchange(
      port, "OPTIONS /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            "Origin: http://evil.example\r\nAccess-Control-Request-Method: POST\r\n"
            "Connection: close\r\n\r\n");
  const std::string page =
      Exchange(port, "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n");

  const int waiting = testing::ConnectLoopback(port);
  ASSERT_GE(waiting, 0);
  const std::string head =
      "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: application/json\r\nContent-Length: 2\r\nExpect: 100-continue\r\n"
      "Connection: close\r\n\r\n";
  ::send(waiting, head.data(), head.size(), MSG_NOSIGNAL);
  std::string interim;
  char byte = 0;
  while (interim.find("\r\n\r\n") == std::string::npos && ::recv(waiting, &byte, 1, 0) == 1) {
    interim += byte;
  }
  ::send(waiting, "{}", 2, MSG_NOSIGNAL);  // the body, once continued
  const std::string continued = testing::ReadToEnd(waiting);
  ::close(waiting);

  std::string process = ProcessRequestOverHttp(testing::MakeClip(1, 20));
  process.replace(process.find("HTTP/1.1"), 8, "HTTP/1.0");
  const std::string old_client = Exchange(port, process);
  const std::string line = "{\"header\":{\"name\":\"" + std::string(6000, 'a') + "\"}}";
  const std::string lines = "{}\n" + line + "\n";
  const std::string second_line_too_long = Exchange(
      port, absl::StrCat("POST /tempokey.v1.MotionService/UploadClip HTTP/1.1\r\n"
                         "Host: 127.0.0.1\r\nContent-Type: application/x-ndjson\r\n"
                         "Content-Length: ", lines.size(), "\r\nConnection: close\r\n\r\n",
                         lines));
  const std::string body = "{\"text\":\"" + std::string(6000, ' ') + "\"}";
  const std::string too_long = Exchange(
      port, absl::StrCat("POST /tempokey.v1.MotionService/ParseSpeedKnots HTTP/1.1\r\n"
                         "Host: 127.0.0.1\r\nContent-Type: application/json\r\n"
                         "Content-Length: ", body.size(), "\r\nConnection: close\r\n\r\n", body));
  FrontEnd guarded = StartFrontEnd(64 << 20, {"s3cret"});
  ASSERT_NE(guarded.http, nullptr);
  const std::string unauthenticated = Exchange(
      guarded.http->port(),
      "POST /tempokey.v1.MotionService/GetServerInfo HTTP/1.1\r\nHost: 127.0.0.1\r\n"
      "Content-Type: application/json\r\nContent-Length: 2\r\nConnection: close\r\n\r\n{}");

  EXPECT_THAT(preflight, ::testing::StartsWith("HTTP/1.1 405"));
  EXPECT_THAT(page, ::testing::StartsWith("HTTP/1.1 200"));
  for (const std::string* answer : {&preflight, &page}) {
    EXPECT_THAT(*answer, ::testing::Not(HasSubstr("Access-Control-Allow")));
  }
  EXPECT_EQ(interim, "HTTP/1.1 100 Continue\r\n\r\n");
  EXPECT_THAT(continued, ::testing::StartsWith("HTTP/1.1 200"));
  EXPECT_THAT(old_client, ::testing::StartsWith("HTTP/1.0 200"));
  EXPECT_THAT(old_client, ::testing::Not(HasSubstr("chunked")));
  EXPECT_THAT(old_client, HasSubstr("\r\n\r\n{\"result\":"));  // NDJSON lines, no chunk sizes
  EXPECT_THAT(second_line_too_long, ::testing::StartsWith("HTTP/1.1 413"));
  EXPECT_THAT(second_line_too_long, HasSubstr("over the limit of 4096 bytes of JSON"));
  EXPECT_THAT(too_long, ::testing::StartsWith("HTTP/1.1 413"));
  EXPECT_THAT(unauthenticated, ::testing::StartsWith("HTTP/1.1 401"));
  EXPECT_THAT(unauthenticated, HasSubstr("WWW-Authenticate: Bearer\r\n"));
}


// A client that sends "Expect: 100-continue" waits with its body until asked for it. The
// front end asked for it before looking at the token or the declared length, so a client
// without a token, or with a body over the limit, sent it all only to be refused. Now it gets
// the final answer instead of "100 Continue" (RFC 9110, 10.1.1) and sends nothing; a streamed
// upload, whose limit is per line, is still asked for its body whatever its length. And the
// answer to a refusal whose body was never asked for ends at once: civetweb waited for that
// body until its socket timeout (30 s), holding one of its threads; here the timeouts are 10
// minutes, so a wait would outlast the client's 60 s hang guard. A client that sends its body
// without waiting (RFC 9110 allows it; Python's http.client does) and an HTTP/1.0 client, whose
// expectation the server must ignore, still get the whole refusal: the review of the first
// version of this found them reset (BrokenPipeError) before they could read it.
TEST(HttpFrontEndTest, AnExpectingClientThatWouldBeRefusedGetsTheRefusalInsteadOfContinue) {
  FrontEnd guarded = StartFrontEnd(4096, {"s3cret"}, std::chrono::minutes(10));
  ASSERT_NE(guarded.http, nullptr);
  const int port = guarded.http->port();
  // The head alone: the body would follow a 100 Continue, which these must never get.
  auto head = [](const std::string& method, const std::string& type, std::size_t length,
                 const std::string& token) {
    return absl::StrCat("POST /tempokey.v1.MotionService/", method, " HTTP/1.1\r\n",
                        "Host: 127.0.0.1\r\nContent-Type: ", type, "\r\nContent-Length: ",
                        length, "\r\nExpect: 100-continue\r\n", token,
                        "Connection: close\r\n\r\n");
  };
  const std::string with_token = "Authorization: Bearer s3cret\r\n";
  const testing::ExchangeEnding no_token =
      testing::ExchangeWithEnding(port, head("GetServerInfo", "application/json", 2, ""));
  const testing::ExchangeEnding wrong_token = testing::ExchangeWithEnding(
      port, head("GetServerInfo", "application/json", 2, "Authorization: Bearer guess\r\n"));
  const testing::ExchangeEnding too_long = testing::ExchangeWithEnding(
      port, head("ParseSpeedKnots", "application/json", 5000, with_token));
  const testing::ExchangeEnding no_method =
      testing::ExchangeWithEnding(port, head("NoSuchMethod", "application/json", 2, with_token));
  constexpr std::size_t kBody = 16 << 20;
  const testing::ExchangeEnding impatient = testing::ExchangeWithEnding(
      port, head("GetServerInfo", "application/json", kBody, "") + std::string(kBody, ' '));
  std::string old_head = head("GetServerInfo", "application/json", kBody, "");
  old_head.replace(old_head.find("HTTP/1.1"), 8, "HTTP/1.0");
  const testing::ExchangeEnding old_client =
      testing::ExchangeWithEnding(port, old_head + std::string(kBody, ' '));

  const int uploading = testing::ConnectLoopback(port);
  ASSERT_GE(uploading, 0);
  const std::string upload_head = head("UploadClip", "application/x-ndjson", 5000, with_token);
  ::send(uploading, upload_head.data(), upload_head.size(), MSG_NOSIGNAL);
  std::string interim;
  char byte = 0;
  while (interim.find("\r\n\r\n") == std::string::npos && ::recv(uploading, &byte, 1, 0) == 1) {
    interim += byte;
  }
  ::close(uploading);

  for (const testing::ExchangeEnding* ending : {&no_token, &wrong_token, &impatient}) {
    EXPECT_THAT(ending->answer, ::testing::StartsWith("HTTP/1.1 401")) << ending->answer;
    EXPECT_THAT(ending->answer, HasSubstr("WWW-Authenticate: Bearer\r\n"));
  }
  EXPECT_THAT(no_token.answer, HasSubstr("missing \\\"Authorization: Bearer <token>\\\" header"));
  EXPECT_THAT(wrong_token.answer, HasSubstr("the bearer token is not accepted"));
  EXPECT_THAT(too_long.answer, ::testing::StartsWith("HTTP/1.1 413"));
  EXPECT_THAT(too_long.answer, HasSubstr("over the limit of 4096 bytes of JSON"));
  EXPECT_THAT(no_method.answer, ::testing::StartsWith("HTTP/1.1 501"));
  EXPECT_THAT(old_client.answer, ::testing::StartsWith("HTTP/1.0 401"));
  EXPECT_THAT(old_client.answer, ::testing::Not(HasSubstr("100 Continue")));
  for (const testing::ExchangeEnding* ending :
       {&no_token, &wrong_token, &too_long, &no_method, &impatient, &old_client}) {
    EXPECT_TRUE(ending->closed) << ending->answer;
  }
  EXPECT_TRUE(impatient.all_sent) << "the body sent without waiting was reset";
  EXPECT_TRUE(old_client.all_sent) << "the HTTP/1.0 body was reset";
  EXPECT_EQ(interim, "HTTP/1.1 100 Continue\r\n\r\n");
}

// A Process call writes nothing while its pipeline runs, so a client that left used to be
// noticed only at the end: the work ran on for nobody (10 s in the probe that found it). Now
// the bridge looks at the connection while it waits and cancels the call. The worker is held
// at the departed call's start, so the server can only see the cancel from the front end's
// look, never from a write; a client that stays behind it gets its answer.
TEST(HttpFrontEndTest, AProcessCallWhoseClientLeavesIsCancelledWhileItRuns) {
  ServerOptions server_options = testing::TestServerOptions();
  server_options.workers = 1;
  server_options.metrics_address = "127.0.0.1:0";
  testing::GatedServer gated(std::move(server_options));
  ASSERT_NE(gated.server, nullptr);
  HttpOptions options = Options("127.0.0.1:0");
  options.web_root = testing::MakeTempDir();
  absl::StatusOr<std::unique_ptr<HttpFrontEnd>> front_end =
      HttpFrontEnd::Start(options, *gated.server);
  ASSERT_TRUE(front_end.ok()) << front_end.status();
  const int port = (*front_end)->port();
  const std::string request = ProcessRequestOverHttp(testing::MakeClip(2, 60));
  const int streams_before = gated.server->open_streams();

  const int leaving = testing::ConnectLoopback(port);
  ASSERT_GE(leaving, 0);
  ASSERT_EQ(::send(leaving, request.data(), request.size(), MSG_NOSIGNAL),
            static_cast<ssize_t>(request.size()));
  ASSERT_TRUE(gated.gate->WaitArrivals(1));  // its pipeline is about to run, held
  ASSERT_EQ(gated.server->open_streams(), streams_before + 1);
  ::close(leaving);
  // The server sees the call cancelled (its stream slot freed) while the worker is still held.
  const auto deadline = std::chrono::steady_clock::now() + testing::StartGate::kWaitLimit;
  while (gated.server->open_streams() > streams_before &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(gated.server->open_streams(), streams_before);

  // A client that stays: queued behind the held call, its looks find it there. (The pause only
  // gives them time to run; what is asserted holds either way.)
  const int staying = testing::ConnectLoopback(port);
  ASSERT_GE(staying, 0);
  ASSERT_EQ(::send(staying, request.data(), request.size(), MSG_NOSIGNAL),
            static_cast<ssize_t>(request.size()));
  std::this_thread::sleep_for(3 * JsonBridge::kDepartureLook);
  gated.gate->Open();
  const std::string answer = testing::ReadToEnd(staying);
  ::close(staying);
  const std::optional<std::string> scrape = testing::HttpGet(gated.server->metrics_port(), "/metrics");

  EXPECT_THAT(answer, ::testing::StartsWith("HTTP/1.1 200"));
  EXPECT_THAT(answer, HasSubstr("{\"result\":{\"result\":"));
  EXPECT_THAT(answer, ::testing::Not(HasSubstr("\"error\"")));
  EXPECT_EQ((*front_end)->departed_clients(), 1);
  ASSERT_TRUE(scrape.has_value());
  const auto samples = testing::ParseSamples(*scrape);
  EXPECT_EQ(testing::Sample(samples, R"(tempokey_jobs_total{kind="process",outcome="cancelled"})"), 1.0);
  EXPECT_EQ(testing::Sample(samples, R"(tempokey_jobs_total{kind="process",outcome="succeeded"})"), 1.0);
}

TEST(SlowBodyGuardTest, ABodyMayTakeTheTimeoutPlusItsLengthAtTheMinimumRate) {
  using std::chrono::milliseconds;
  EXPECT_EQ(SlowBodyGuard::Allowance(milliseconds(30000), 0, 1 << 20), milliseconds(30000));
  EXPECT_EQ(SlowBodyGuard::Allowance(milliseconds(30000), 64 * 1024 * 10, 1 << 20),
            milliseconds(40000));
  // Unknown length (chunked): as long as the largest message.
  EXPECT_EQ(SlowBodyGuard::Allowance(milliseconds(30000), -1, 64 * 1024 * 4), milliseconds(34000));
  // A declared length beyond the largest message counts as that: 10^15 bytes bought years (and
  // 10^18 overflowed into a deadline already past).
  EXPECT_EQ(SlowBodyGuard::Allowance(milliseconds(30000), 1'000'000'000'000'000, 64 * 1024 * 16),
            milliseconds(46000));
  EXPECT_EQ(SlowBodyGuard::Allowance(milliseconds(30000), INT64_MAX, 64 * 1024 * 16),
            milliseconds(46000));
}

}  // namespace
}  // namespace tempokey::server::http
