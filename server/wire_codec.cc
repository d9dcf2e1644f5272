#include "server/wire_codec.h"

#include <cstdint>

#include "absl/strings/str_cat.h"
#include "google/protobuf/descriptor.h"
#include "google/protobuf/io/coded_stream.h"
#include "google/protobuf/wire_format_lite.h"
#include "grpcpp/impl/codegen/proto_utils.h"
#include "grpcpp/support/proto_buffer_reader.h"
#include "grpcpp/support/proto_buffer_writer.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {

namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::internal::WireFormatLite;

// Nesting deeper than this is left to the parser, which refuses it (protobuf's recursion limit).
constexpr int kMaxNesting = 100;

bool IsStringOrBytes(const FieldDescriptor& field) {
  return field.type() == FieldDescriptor::TYPE_STRING ||
         field.type() == FieldDescriptor::TYPE_BYTES;
}

// Adds to `count` the values a parse of the bytes `in` as a `type` (null: an unknown group's
// contents) builds as objects of their own: a message field's value, a string or bytes value,
// and an unknown field or a known one sent with another wire type (kept as an unknown field; an
// unknown group's fields counted too). Scalars, one by one or packed, are not counted: they cost
// no more than their bytes. Stops once `count` passes `limit`. Returns false on bytes that do not
// scan (the parser then refuses them itself). Only tags and lengths are read: packed samples and
// strings are skipped whole.
bool CountItems(google::protobuf::io::CodedInputStream& in, const Descriptor* type, int depth,
                std::int64_t limit, std::int64_t& count) {
  while (const std::uint32_t tag = in.ReadTag()) {
    const WireFormatLite::WireType wire = WireFormatLite::GetTagWireType(tag);
    if (wire == WireFormatLite::WIRETYPE_END_GROUP) return type == nullptr;  // the group's end
    const FieldDescriptor* field =
        type == nullptr
            ? nullptr
            : type->FindFieldByNumber(static_cast<int>(WireFormatLite::GetTagFieldNumber(tag)));
    const bool delimited = wire == WireFormatLite::WIRETYPE_LENGTH_DELIMITED;
    if (field != nullptr && field->type() == FieldDescriptor::TYPE_MESSAGE && delimited) {
      std::uint32_t length = 0;
      if (!in.ReadVarint32(&length) || length > INT32_MAX || depth >= kMaxNesting) return false;
      if (++count > limit) return true;
      const auto outer = in.PushLimit(static_cast<int>(length));
      if (!CountItems(in, field->message_type(), depth + 1, limit, count)) return false;
      if (count > limit) return true;
      if (in.BytesUntilLimit() != 0) return false;
      in.PopLimit(outer);
      continue;
    }
    const bool scalar =
        field != nullptr && !IsStringOrBytes(*field) &&
        (wire == WireFormatLite::WireTypeForFieldType(
                     static_cast<WireFormatLite::FieldType>(field->type())) ||
         (field->is_packable() && delimited));
    if (!scalar && ++count > limit) return true;
    if (wire == WireFormatLite::WIRETYPE_START_GROUP) {
      if (depth >= kMaxNesting || !CountItems(in, nullptr, depth + 1, limit, count)) return false;
      if (count > limit) return true;
      continue;
    }
    if (!WireFormatLite::SkipField(&in, tag)) return false;
  }
  return type != nullptr && in.ConsumedEntireMessage();
}

}  // namespace

absl::Status CheckMessageItems(const grpc::ByteBuffer& buffer, std::string_view what,
                               const Descriptor& type) {
  // Every item counted takes at least two bytes (a tag and a length or value): a message of
  // fewer bytes cannot pass the limit, and is not scanned (sample slices, most requests).
  if (static_cast<std::int64_t>(buffer.Length()) / 2 <= kMaxMessageItems) return absl::OkStatus();
  grpc::ByteBuffer copy(buffer);
  grpc::ProtoBufferReader reader(&copy);
  if (!reader.status().ok()) return absl::OkStatus();  // the parse says what is wrong
  google::protobuf::io::CodedInputStream in(&reader);
  std::int64_t count = 0;
  CountItems(in, &type, 0, kMaxMessageItems, count);
  if (count <= kMaxMessageItems) return absl::OkStatus();
  return core::OverLimitError(absl::StrCat(
      core::AsAbsl(what), ": more than ", kMaxMessageItems, " items inside one ",
      type.full_name(), " (joints, channels, markers, knots, names, unknown fields...), over the "
      "limit"));
}

absl::Status ParseMessage(const grpc::ByteBuffer& buffer, std::string_view what,
                          google::protobuf::Message* message) {
  message->Clear();
  TEMPOKEY_RETURN_IF_ERROR(CheckMessageItems(buffer, what, *message->GetDescriptor()));
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
