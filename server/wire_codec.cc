#include "server/wire_codec.h"

#include "absl/strings/str_cat.h"
#include "grpcpp/impl/codegen/proto_utils.h"
#include "grpcpp/support/proto_buffer_reader.h"
#include "grpcpp/support/proto_buffer_writer.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {

absl::Status ParseMessage(const grpc::ByteBuffer& buffer, std::string_view what,
                          google::protobuf::Message* message) {
  message->Clear();
  grpc::ByteBuffer copy(buffer);  // shares the slices; the reader consumes its own view
  bool parsed = false;
  {
    grpc::ProtoBufferReader reader(&copy);
    if (reader.status().ok()) parsed = message->ParseFromZeroCopyStream(&reader);
  }
  if (parsed) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      core::AsAbsl(what), ": ", buffer.Length(), " bytes are not a valid ",
      message->GetDescriptor()->full_name(), " message"));
}

void SerializeMessage(const google::protobuf::Message& message, grpc::ByteBuffer* buffer) {
  buffer->Clear();  // the writer wants an empty buffer
  bool own_buffer = false;
  // Cannot fail for a message we built (its size is below gRPC's 2 GiB limit by construction).
  (void)grpc::GenericSerialize<grpc::ProtoBufferWriter, google::protobuf::Message>(
      message, buffer, &own_buffer);
}

}  // namespace tempokey::server
