// Messages in and out of raw (ByteBuffer) gRPC methods. MotionService parses its requests
// itself, so bytes that are not a valid message get INVALID_ARGUMENT with a message instead of
// gRPC's own UNIMPLEMENTED with none (what its typed handlers answer to a parse failure).
#ifndef TEMPOKEY_SERVER_WIRE_CODEC_H_
#define TEMPOKEY_SERVER_WIRE_CODEC_H_

#include <cstdint>
#include <string_view>

#include "absl/status/status.h"
#include "google/protobuf/descriptor.h"
#include "google/protobuf/message.h"
#include "grpcpp/support/byte_buffer.h"

namespace tempokey::server {

// Items one request message may hold, at any depth: values a parse builds as objects of their
// own (each joint, channel, marker, speed knot, offset, name, unknown field...). Reading a message
// costs about 66 bytes per such item: a header of 3 M empty markers (6 MB on the wire) took
// 198 MB to read, and 3 M empty unknown fields 201 MB, before any limit of ours could look at
// them, so a 64 MiB message would have taken 2.2 GB. With this limit reading takes at most about
// 66 MB besides the message's own bytes. The limit binds: a pipeline whose operations hold more
// (64 retimes each with 100 000 knots would) must be sent in parts.
inline constexpr std::int64_t kMaxMessageItems = 1'000'000;

// OK unless `buffer`, read as a `type`, holds more than kMaxMessageItems items, counted from its
// tags alone (nothing is built; a buffer under 2 * kMaxMessageItems bytes is not even scanned);
// bytes that do not scan are left to the parse to refuse.
// Errors: kResourceExhausted "upload message 1: more than 1000000 items inside one
// tempokey.v1.UploadClipRequest (joints, channels, markers, knots, names, unknown fields...),
// over the limit".
absl::Status CheckMessageItems(const grpc::ByteBuffer& buffer, std::string_view what,
                               const google::protobuf::Descriptor& type);

// Parses `buffer` into `message` (cleared first), after CheckMessageItems(). `what` names the
// message in the error ("SubmitJob request", "upload message 3").
// Errors: kInvalidArgument "SubmitJob request: 117 bytes are not a valid
// tempokey.v1.SubmitJobRequest message"; kResourceExhausted as CheckMessageItems().
absl::Status ParseMessage(const grpc::ByteBuffer& buffer, std::string_view what,
                          google::protobuf::Message* message);

// `message` serialized into `buffer` (replacing what it held).
void SerializeMessage(const google::protobuf::Message& message, grpc::ByteBuffer* buffer);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_WIRE_CODEC_H_
