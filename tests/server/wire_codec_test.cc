// Reading request messages: how many items (messages, strings, unknown fields) one may hold is
// counted from its tags before it is parsed (a message of empty markers took 33 times its size to
// read, one of empty unknown fields 35 times), up to the limit and not one past it; bytes that do
// not scan are left to the parse, which names them.
#include <string>

#include "gmock/gmock.h"
#include "grpcpp/support/byte_buffer.h"
#include "gtest/gtest.h"
#include "server/wire_codec.h"
#include "tempokey/v1/motion_service.pb.h"

namespace tempokey::server {
namespace {

grpc::ByteBuffer BufferOf(const google::protobuf::Message& message) {
  grpc::ByteBuffer buffer;
  SerializeMessage(message, &buffer);
  return buffer;
}

// An upload's header holding `markers` empty markers: 1 + markers messages inside the request.
v1::UploadClipRequest HeaderWithMarkers(std::int64_t markers) {
  v1::UploadClipRequest request;
  v1::ClipHeader* header = request.mutable_header();
  header->mutable_markers()->Reserve(static_cast<int>(markers));
  for (std::int64_t m = 0; m < markers; ++m) header->add_markers();
  return request;
}

TEST(CheckMessageItemsTest, AllowsTheLimitAndRefusesOneMessageMore) {
  const grpc::ByteBuffer at_limit = BufferOf(HeaderWithMarkers(kMaxMessageItems - 1));
  const grpc::ByteBuffer over = BufferOf(HeaderWithMarkers(kMaxMessageItems));
  v1::UploadClipRequest parsed;

  EXPECT_TRUE(CheckMessageItems(at_limit, "upload message 1", *parsed.GetDescriptor()).ok());
  const absl::Status refused = ParseMessage(over, "upload message 1", &parsed);
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(refused.message(),
            "upload message 1: more than 1000000 items inside one tempokey.v1.UploadClipRequest "
            "(joints, channels, markers, knots, names, unknown fields...), over the limit");
  EXPECT_EQ(parsed.header().markers_size(), 0);  // nothing was built
}

// An upload's header of `joints` joints with `end_sites` End Sites each: 1 + joints x (1 +
// end_sites) messages inside the request (an unset offset is not on the wire).
v1::UploadClipRequest HeaderWithEndSites(int joints, int end_sites) {
  v1::UploadClipRequest request;
  for (int j = 0; j < joints; ++j) {
    v1::Joint* joint = request.mutable_header()->add_joints();
    for (int e = 0; e < end_sites; ++e) joint->add_end_site_offsets();
  }
  return request;
}

TEST(CheckMessageItemsTest, CountsMessagesAtEveryDepthButNotPackedSamples) {
  const grpc::ByteBuffer at_limit = BufferOf(HeaderWithEndSites(111'111, 8));    // 1 000 000
  const grpc::ByteBuffer over = BufferOf(HeaderWithEndSites(100'000, 9));        // 1 000 001
  v1::UploadClipRequest samples;
  for (int s = 0; s < 2'000'000; ++s) samples.mutable_samples()->add_samples(s);
  const google::protobuf::Descriptor& type = *samples.GetDescriptor();

  EXPECT_TRUE(CheckMessageItems(at_limit, "header", type).ok());
  EXPECT_EQ(CheckMessageItems(over, "header", type).code(),
            absl::StatusCode::kResourceExhausted);
  EXPECT_TRUE(CheckMessageItems(BufferOf(samples), "samples", type).ok());  // 1 item
}

// `count` unknown fields of each wire type the parser keeps: varints, empty length-delimited
// fields, and empty groups (a start and an end tag), field 99 of nothing.
grpc::ByteBuffer UnknownFields(std::int64_t count) {
  std::string bytes;
  for (std::int64_t i = 0; i < count; ++i) {
    switch (i % 3) {
      case 0: bytes += std::string("\x98\x06\x00", 3); break;  // field 99, varint 0
      case 1: bytes += std::string("\x9a\x06\x00", 3); break;  // field 99, 0 bytes
      default: bytes += "\x9b\x06\x9c\x06"; break;            // field 99, an empty group
    }
  }
  grpc::Slice slice(bytes);
  return grpc::ByteBuffer(&slice, 1);
}

// The parser keeps unknown fields as objects too (3 M empty ones took 201 MB): they count.
TEST(CheckMessageItemsTest, UnknownFieldsOfEveryWireTypeCount) {
  const google::protobuf::Descriptor& type = *v1::UploadClipRequest::descriptor();

  EXPECT_TRUE(CheckMessageItems(UnknownFields(kMaxMessageItems), "m", type).ok());
  EXPECT_EQ(CheckMessageItems(UnknownFields(kMaxMessageItems + 1), "m", type).code(),
            absl::StatusCode::kResourceExhausted);
}

TEST(CheckMessageItemsTest, BytesThatDoNotScanAreLeftToTheParseWhichNamesThem) {
  const std::string bytes = "\x0a\x7f\x01";  // a header claiming 127 bytes, holding one
  grpc::Slice slice(bytes);
  const grpc::ByteBuffer buffer(&slice, 1);
  v1::UploadClipRequest parsed;

  EXPECT_TRUE(CheckMessageItems(buffer, "upload message 1", *parsed.GetDescriptor()).ok());
  EXPECT_EQ(ParseMessage(buffer, "upload message 1", &parsed).message(),
            "upload message 1: 3 bytes are not a valid tempokey.v1.UploadClipRequest message");
}

}  // namespace
}  // namespace tempokey::server
