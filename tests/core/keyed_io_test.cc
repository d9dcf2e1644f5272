#include "tempokey/core/keyed_io.h"

#include <string>

#include "gtest/gtest.h"
#include "tempokey/core/bvh.h"
#include "tempokey/core/reduce.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

KeyedClip ReducedCmu() {
  absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  EXPECT_TRUE(clip.ok()) << clip.status();
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  options.paper.max_iterations = 1;
  absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);
  EXPECT_TRUE(result.ok()) << result.status();
  return result->keyed;
}

KeyedClip SmallKeyed() {
  KeyedClip keyed;
  keyed.layout.name = "walk \"quoted\"";
  keyed.layout.frame_time_seconds = 1.0 / 30.0;
  keyed.layout.frame_count = 31;
  Channel channel;
  channel.kind = ChannelKind::kScalar;
  channel.name = "blend";
  keyed.layout.channels = {channel};
  keyed.layout.markers = {Marker{"contact", 0.5, 0.25}};
  Key a;
  a.value = 0.1;
  a.out_tangent = 0.30000000000000004;
  Key b;
  b.time_seconds = 1.0;
  b.value = -2.5e-300;
  b.in_tangent = 1e300;
  b.in_weight = 0.2;
  b.out_weight = 0.7;
  keyed.curves = {Curve{{a, b}}};
  return keyed;
}

TEST(KeyedJsonTest, RoundTripIsBitExactOnAReducedClip) {
  const KeyedClip keyed = ReducedCmu();

  absl::StatusOr<std::string> text = FormatKeyedClipJson(keyed);
  ASSERT_TRUE(text.ok()) << text.status();
  absl::StatusOr<KeyedClip> back = ParseKeyedClipJson(*text, "cmu.json");

  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_TRUE(*back == keyed);
}

TEST(KeyedJsonTest, RoundTripKeepsMarkersNamesAndExtremeNumbers) {
  const KeyedClip keyed = SmallKeyed();

  absl::StatusOr<KeyedClip> back = ParseKeyedClipJson(*FormatKeyedClipJson(keyed), "small.json");

  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, keyed);
}

TEST(KeyedJsonTest, MalformedDocumentsAreRefusedWithPlaceAndReason) {
  const std::string good = *FormatKeyedClipJson(SmallKeyed());
  auto replaced = [&](const std::string& from, const std::string& to) {
    std::string text = good;
    text.replace(text.find(from), from.size(), to);
    return text;
  };
  struct Case {
    std::string text;
    const char* message;
  } cases[] = {
      {"", "k.json:1:1: expected a value, got the end of the text"},
      {"{\"format\": 1,}", "k.json:1:14: expected a member name, got \"}\""},
      {"{\"format\": 1}", "k.json:1:12: format must be a string"},
      {"[1, 2", "k.json:1:6: expected ',' or ']', got the end of the text"},
      {replaced("\"version\": 1", "\"version\": 2"),
       "k.json:3:14: version 2 is not supported (1 is)"},
      {replaced("\"frame_count\": 31", "\"frame_count\": 31, \"extra\": 0"),
       "k.json:6:31: keyed clip has an unknown member \"extra\""},
      {replaced("[1, -2.5e-300", "[1, nan"),
       "k.json:9:101: expected a value, got \"n\""},
      {replaced("\"kind\": \"scalar\"", "\"kind\": \"Wrotation\""),
       "k.json:9:27: channel 0 kind \"Wrotation\" is not a channel kind"},
      {replaced("0.2, 0.7]", "0.2]"), "k.json:9:97: channel 0 key 1 must have 4 or 6 numbers, got 5"},
      {replaced("\"frame_time_seconds\": 0.03333333333333333", "\"frame_time_seconds\": -1"),
       "k.json: frame time must be finite and > 0 seconds, got -1"},
      {replaced("[1, -2.5e-300", "[0, -2.5e-300"),
       "k.json: channel 0 (blend): key 1: time 0 s is not after the previous key's 0 s"},
  };
  for (const Case& c : cases) {
    const absl::StatusOr<KeyedClip> result = ParseKeyedClipJson(c.text, "k.json");

    EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument) << c.message;
    EXPECT_EQ(std::string(result.status().message()), c.message);
  }
}

TEST(MayaAnimTest, WritesOneWeightedBlockPerChannelWithMayaNames) {
  const KeyedClip keyed = ReducedCmu();

  absl::StatusOr<std::string> text = FormatMayaAnim(keyed);

  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_EQ(text->rfind("animVersion 1.1;\nmayaVersion 2020;\ntimeUnit 120fps;\n", 0), 0u);
  std::size_t blocks = 0;
  for (std::size_t at = text->find("animData {"); at != std::string::npos;
       at = text->find("animData {", at + 1)) {
    ++blocks;
  }
  EXPECT_EQ(blocks, keyed.curves.size());
  EXPECT_NE(text->find("anim translate.translateX translateX Hips 0 0 0;\n"), std::string::npos);
  EXPECT_NE(text->find("anim rotate.rotateZ rotateZ Hips 0 0 0;\n"), std::string::npos);
  EXPECT_NE(text->find("  output angular;\n  weighted 1;\n"), std::string::npos);
}

TEST(MayaAnimTest, TangentAnglesAndWeightsFollowTheHandle) {
  // Key 0: slope 0.3 /s, out weight 1/3 of a 1 s segment: handle (1/3 s, 0.1), so Maya's
  // vector is (1, 0.3): angle atan(0.3) = 16.69924423399362 degrees, weight hypot(1, 0.3).
  KeyedClip keyed = SmallKeyed();
  keyed.curves[0].keys[0].out_tangent = 0.3;
  keyed.curves[0].keys[0].in_tangent = 0.3;

  absl::StatusOr<std::string> text = FormatMayaAnim(keyed);

  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_NE(text->find("timeUnit ntsc;"), std::string::npos);
  EXPECT_NE(text->find("    0 0.1 fixed fixed 1 0 0 16.69924423399362 1.044030650891055 "
                       "16.69924423399362 1.044030650891055;\n"),
            std::string::npos)
      << *text;
  EXPECT_NE(text->find("    30 -2.5e-300 fixed fixed 0 0 0 "), std::string::npos) << *text;
}

}  // namespace
}  // namespace tempokey::core
