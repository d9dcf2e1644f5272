// Messages in and out of raw (ByteBuffer) gRPC methods. MotionService parses its requests
// itself, so bytes that are not a valid message get INVALID_ARGUMENT with a message instead of
// gRPC's own UNIMPLEMENTED with none (what its typed handlers answer to a parse failure).
#ifndef TEMPOKEY_SERVER_WIRE_CODEC_H_
#define TEMPOKEY_SERVER_WIRE_CODEC_H_

#include <string_view>

#include "absl/status/status.h"
#include "google/protobuf/message.h"
#include "grpcpp/support/byte_buffer.h"

namespace tempokey::server {

// Parses `buffer` into `message` (cleared first). `what` names the message in the error
// ("SubmitJob request", "upload message 3").
// Errors: kInvalidArgument "SubmitJob request: 117 bytes are not a valid
// tempokey.v1.SubmitJobRequest message".
absl::Status ParseMessage(const grpc::ByteBuffer& buffer, std::string_view what,
                          google::protobuf::Message* message);

// `message` serialized into `buffer` (replacing what it held).
void SerializeMessage(const google::protobuf::Message& message, grpc::ByteBuffer* buffer);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_WIRE_CODEC_H_
