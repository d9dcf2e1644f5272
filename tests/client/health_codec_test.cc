#include "client/health_codec.h"

#include <string>

#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

TEST(HealthCodecTest, EncodesTheServiceNameAsField1) {
  const std::string bytes = EncodeHealthCheckRequest("tempokey.v1.MotionService");

  ASSERT_EQ(bytes.size(), 2u + 25u);
  EXPECT_EQ(bytes[0], '\x0a');  // field 1, length-delimited
  EXPECT_EQ(bytes[1], static_cast<char>(25));
  EXPECT_EQ(bytes.substr(2), "tempokey.v1.MotionService");
}

TEST(HealthCodecTest, EncodesTheOverallServiceAsAnEmptyMessage) {
  EXPECT_EQ(EncodeHealthCheckRequest(""), "");
}

TEST(HealthCodecTest, EncodesLongNamesWithAMultiByteLength) {
  const std::string name(300, 'a');

  const std::string bytes = EncodeHealthCheckRequest(name);

  ASSERT_EQ(bytes.size(), 3u + 300u);
  EXPECT_EQ(static_cast<unsigned char>(bytes[1]), 0xac);  // 300 = 0b10'0101100
  EXPECT_EQ(static_cast<unsigned char>(bytes[2]), 0x02);
}

TEST(HealthCodecTest, DecodesEveryServingStatus) {
  EXPECT_EQ(*DecodeHealthCheckResponse(std::string("\x08\x01", 2)), HealthState::kServing);
  EXPECT_EQ(*DecodeHealthCheckResponse(std::string("\x08\x02", 2)), HealthState::kNotServing);
  EXPECT_EQ(*DecodeHealthCheckResponse(std::string("\x08\x03", 2)), HealthState::kServiceUnknown);
  EXPECT_EQ(*DecodeHealthCheckResponse(""), HealthState::kUnknown);
}

TEST(HealthCodecTest, SkipsUnknownFields) {
  // field 2 (string "ab"), field 3 (fixed32), then status SERVING.
  constexpr char kBytes[] = "\x12\x02" "ab" "\x1d\x01\x02\x03\x04" "\x08\x01";
  const std::string bytes(kBytes, sizeof(kBytes) - 1);

  ASSERT_EQ(bytes.size(), 11u);
  EXPECT_EQ(*DecodeHealthCheckResponse(bytes), HealthState::kServing);
}

TEST(HealthCodecTest, RefusesTruncatedAndOutOfRangeResponses) {
  EXPECT_EQ(DecodeHealthCheckResponse(std::string("\x08", 1)).status().message(),
            "health response: truncated varint");
  EXPECT_EQ(DecodeHealthCheckResponse(std::string("\x12\x05" "ab", 4)).status().message(),
            "health response: truncated length-delimited field");
  EXPECT_EQ(DecodeHealthCheckResponse(std::string("\x08\x07", 2)).status().message(),
            "health response: serving status 7 is not 0..3");
}

TEST(HealthCodecTest, NamesStatesAsGrpcDoes) {
  EXPECT_EQ(HealthStateName(HealthState::kServing), "SERVING");
  EXPECT_EQ(HealthStateName(HealthState::kNotServing), "NOT_SERVING");
}

}  // namespace
}  // namespace tempokey::client
