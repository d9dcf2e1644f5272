// The HTTP/JSON face of MotionService: a call is named by its gRPC path
// ("/tempokey.v1.MotionService/GetJob"), its messages travel in protobuf's JSON mapping, and it is
// made through a gRPC channel to the server itself (an in-process channel, no socket). So every
// HTTP call runs the very handler the same gRPC call runs, with the same validation, limits,
// queue, metrics, bearer-token check and drain: the two interfaces cannot drift, and a method
// added to the service is on HTTP the moment it is in the proto.
#ifndef TEMPOKEY_SERVER_HTTP_JSON_BRIDGE_H_
#define TEMPOKEY_SERVER_HTTP_JSON_BRIDGE_H_

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "google/protobuf/descriptor.h"
#include "grpcpp/channel.h"

namespace tempokey::server::http {

// The one service bridged.
inline constexpr char kBridgedService[] = "tempokey.v1.MotionService";

class JsonBridge {
 public:
  // Calls go through `channel` (Server::InProcessChannel()). Request messages larger than
  // `max_message_bytes` of JSON are refused before they are parsed.
  JsonBridge(std::shared_ptr<grpc::Channel> channel, std::int64_t max_message_bytes);

  // The method at `path` ("/tempokey.v1.MotionService/GetJob"), or null when `path` names no
  // method of the bridged service.
  static const google::protobuf::MethodDescriptor* FindMethod(std::string_view path);

  // Both ends of one call, implemented by the HTTP handler over its connection.
  class Stream {
   public:
    virtual ~Stream() = default;
    // The next request message as JSON text; nullopt after the last one. An error (unreadable
    // body, a message over the size limit) ends the call with that status.
    virtual absl::StatusOr<std::optional<std::string>> NextRequest() = 0;
    // One response message as JSON text. False when the client went away: the call is
    // cancelled.
    virtual bool WriteResponse(std::string_view json) = 0;
    // True once the client has gone. Asked every kDepartureLook while a response is awaited
    // (every request has been read by then): a long call whose client left is cancelled, not
    // run to its end for nobody (a Process writes nothing while its pipeline runs).
    virtual bool ClientGone() { return false; }
  };
  static constexpr std::chrono::milliseconds kDepartureLook{250};

  struct Outcome {
    // The call's status (gRPC's code and message), or the bridge's own INVALID_ARGUMENT for a
    // request that is not the method's message in JSON ("request message 1: ...").
    absl::Status status;
    // The server's retry hint (trailing metadata retry-after-ms), on RESOURCE_EXHAUSTED.
    std::optional<std::chrono::milliseconds> retry_after;
    std::int64_t responses = 0;
    // The call was cancelled because the client had gone (Stream::ClientGone()).
    bool client_gone = false;
  };

  // Runs one call of `method`: every request `stream` gives (one for unary and server-streaming
  // methods), then every response to `stream` in order. `authorization` (the HTTP header's
  // value, may be empty) is sent as the call's "authorization" metadata.
  // Blocks the calling thread until the call ends. Thread-safe.
  Outcome Call(const google::protobuf::MethodDescriptor& method, std::string_view authorization,
               Stream& stream) const;

  // The max_message_bytes given at construction.
  std::int64_t max_message_bytes() const { return max_message_bytes_; }

 private:
  std::shared_ptr<grpc::Channel> channel_;
  std::int64_t max_message_bytes_;
};

// Protobuf's JSON mapping as the bridge writes it: lowerCamelCase names, every scalar and repeated
// field printed even when it holds its default (so clients need no defaults table), enums by
// name, 64-bit integers as strings, bytes as base64.
absl::StatusOr<std::string> MessageToJson(const google::protobuf::Message& message);

}  // namespace tempokey::server::http

#endif  // TEMPOKEY_SERVER_HTTP_JSON_BRIDGE_H_
