#include "tempokey/core/io/keyed_json.h"

#include <cmath>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/reduce/reduce.h"
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
  b.in_tangent = 1e100;  // the largest tangent a keyed clip may hold (clip.h)
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

TEST(KeyedJsonTest, RoundTripKeepsOneSidedWeightsUnset) {
  KeyedClip keyed = SmallKeyed();
  Curve& curve = keyed.curves[0];
  curve.keys[0].out_weight = 0.5;  // in weight unset
  curve.keys[1].in_weight = 0.25;
  curve.keys[1].out_weight.reset();
  Key last;
  last.time_seconds = 2.0;
  last.value = 4.0;
  curve.keys.push_back(last);
  keyed.layout.frame_count = 61;

  const absl::StatusOr<std::string> text = FormatKeyedClipJson(keyed);
  ASSERT_TRUE(text.ok()) << text.status();
  const absl::StatusOr<KeyedClip> back = ParseKeyedClipJson(*text, "one_sided.json");

  EXPECT_NE(text->find("[0, 0.1, 0, 0.30000000000000004, null, 0.5]"), std::string::npos)
      << *text;
  EXPECT_NE(text->find("[1, -2.5e-300, 1e+100, 0, 0.25, null]"), std::string::npos) << *text;
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, keyed);
  EXPECT_FALSE(back->curves[0].keys[0].in_weight.has_value());
  EXPECT_FALSE(back->curves[0].keys[1].out_weight.has_value());
}

TEST(KeyedJsonTest, ClipWithABadMarkerIsRefusedBeforeWriting) {
  KeyedClip nan_time = SmallKeyed();
  nan_time.layout.markers[0].time_seconds = std::nan("");
  KeyedClip negative = SmallKeyed();
  negative.layout.markers[0].duration_seconds = -0.5;

  const absl::StatusOr<std::string> nan_text = FormatKeyedClipJson(nan_time);
  const absl::StatusOr<std::string> negative_text = FormatKeyedClipJson(negative);

  EXPECT_EQ(nan_text.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(nan_text.status().message(),
            "marker 0 (\"contact\"): time_seconds must be in [-1e+11, 1e+11], got NaN");
  EXPECT_EQ(negative_text.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(negative_text.status().message(),
            "marker 0 (\"contact\"): duration_seconds must be in [0, 1e+11], got -0.5");
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
      {replaced("[1, -2.5e-300", "[1, 1.2.3"), "k.json:9:101: malformed number \"1.2.3\""},
      {replaced("[1, -2.5e-300", "[1, -1e999"),
       "k.json:9:101: number \"-1e999\" is out of range for a double"},
      {replaced("0.2, 0.7]", "0.2, true]"),
       "k.json:9:128: channel 0 key 1 weight must be a number or null"},
      {replaced("\"duration_seconds\": 0.25", "\"duration_seconds\": -1"),
       "k.json: marker 0 (\"contact\"): duration_seconds must be in [0, 1e+11], got -1"},
      {replaced("\"kind\": \"scalar\"", "\"kind\": \"Wrotation\""),
       "k.json:9:27: channel 0 kind \"Wrotation\" is not a channel kind"},
      {replaced("0.2, 0.7]", "0.2]"), "k.json:9:97: channel 0 key 1 must have 4 or 6 numbers, got 5"},
      {replaced("\"frame_time_seconds\": 0.03333333333333333", "\"frame_time_seconds\": -1"),
       "k.json: frame time must be in [1e-06, 3600] seconds, got -1"},
      {replaced("\"frame_time_seconds\": 0.03333333333333333", "\"frame_time_seconds\": 1e-320"),
       "k.json: frame time must be in [1e-06, 3600] seconds, got 9.99989e-321"},
      {replaced("1e+100", "1e+101"),
       "k.json: channel 0 (blend): key 1: in tangent 1e+101 is beyond the +-1e+100 a keyed clip "
       "may hold"},
      {replaced("[1, -2.5e-300", "[0, -2.5e-300"),
       "k.json: channel 0 (blend): key 1: time 0 s is not after the previous key's 0 s"},
  };
  for (const Case& c : cases) {
    const absl::StatusOr<KeyedClip> result = ParseKeyedClipJson(c.text, "k.json");

    EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument) << c.message;
    EXPECT_EQ(std::string(result.status().message()), c.message);
  }
}

TEST(KeyedJsonTest, ConstantChannelsCarryNoWeights) {
  // The README: unweighted curves carry no weights. A constant channel gets two flat keys with
  // none, whichever method fitted the clip (the paper's other channels are weighted).
  Clip clip;
  clip.frame_time_seconds = 0.1;
  clip.frame_count = 20;
  Channel constant;
  constant.name = "constant";
  constant.samples.assign(20, 3.5);
  Channel ramp;
  ramp.name = "ramp";
  for (int i = 0; i < 20; ++i) ramp.samples.push_back(std::sin(0.3 * i));
  clip.channels = {constant, ramp};
  ReduceOptions paper;
  paper.method = ReduceMethod::kPaper;
  paper.paper.max_iterations = 1;
  absl::StatusOr<ReduceResult> result = ReduceKeys(clip, paper);
  ASSERT_TRUE(result.ok()) << result.status();

  const absl::StatusOr<std::string> text = FormatKeyedClipJson(result->keyed);

  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_NE(text->find("\"name\": \"constant\", \"keys\": [[0, 3.5, 0, 0], [1.9000000000000001, 3.5, 0, 0]]"),
            std::string::npos)
      << *text;
  EXPECT_TRUE(result->keyed.curves[1].keys[0].out_weight.has_value());
}

}  // namespace
}  // namespace tempokey::core
