#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/retime/retime.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

TEST(SpeedKnotsTest, ParsesTheHalfSpeedExampleIntoFiveKnots) {
  const absl::StatusOr<std::vector<SpeedKnot>> knots =
      ParseSpeedKnots("0s:1,2s:1,2s:0.5,4s:0.5,4s:1");

  ASSERT_TRUE(knots.ok()) << knots.status();
  ASSERT_EQ(knots->size(), 5u);
  const double times[] = {0, 2, 2, 4, 4};
  const double speeds[] = {1, 1, 0.5, 0.5, 1};
  for (std::size_t k = 0; k < 5; ++k) {
    EXPECT_EQ((*knots)[k].time.value, times[k]);
    EXPECT_FALSE((*knots)[k].time.in_frames);
    EXPECT_EQ((*knots)[k].speed, speeds[k]);
  }
}

TEST(SpeedKnotsTest, HalfSpeedExamplePlaysTwoToFourSecondsAtHalfSpeed) {
  // A 6 s clip: 2 s + 2 s at half speed (4 s) + 2 s = 8 s.
  Clip clip;
  clip.frame_time_seconds = 1.0 / 32;
  clip.frame_count = 193;
  clip.channels.push_back({.name = "x", .samples = std::vector<double>(193, 0.0)});
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverSource,
                             .speed = *ParseSpeedKnots("0s:1,2s:1,2s:0.5,4s:0.5,4s:1")};

  const absl::StatusOr<RetimeResult> result = Retime(clip, warp, {});

  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->report.output_duration_seconds, 8.0);
  EXPECT_EQ(result->clip.frame_count, 257);
}

TEST(SpeedKnotsTest, SingleKnotIsAConstantSpeed) {
  const absl::StatusOr<std::vector<SpeedKnot>> knots = ParseSpeedKnots("0s:1");

  ASSERT_TRUE(knots.ok());
  ASSERT_EQ(knots->size(), 1u);
  EXPECT_EQ((*knots)[0].speed, 1.0);
}

TEST(SpeedKnotsTest, AcceptsFramesExponentsNegativeTimesAndSpaces) {
  const absl::StatusOr<std::vector<SpeedKnot>> knots =
      ParseSpeedKnots(" -1s : 2 ,75f:0.5,\t2.5e1s:1e-1 ");

  ASSERT_TRUE(knots.ok()) << knots.status();
  ASSERT_EQ(knots->size(), 3u);
  EXPECT_EQ((*knots)[0].time.value, -1.0);
  EXPECT_EQ((*knots)[0].speed, 2.0);
  EXPECT_EQ((*knots)[1].time.value, 75.0);
  EXPECT_TRUE((*knots)[1].time.in_frames);
  EXPECT_EQ((*knots)[2].time.value, 25.0);
  EXPECT_EQ((*knots)[2].speed, 0.1);
}

TEST(SpeedKnotsTest, AcceptsALeadingPlusLikeEveryNumberReader) {
  const absl::StatusOr<std::vector<SpeedKnot>> knots = ParseSpeedKnots("0s:1,+2s:+0.5");

  ASSERT_TRUE(knots.ok()) << knots.status();
  ASSERT_EQ(knots->size(), 2u);
  EXPECT_EQ((*knots)[1].time.value, 2.0);
  EXPECT_EQ((*knots)[1].speed, 0.5);
}

struct BadText {
  std::string text;
  std::string message;
};

class SpeedKnotsErrorTest : public ::testing::TestWithParam<BadText> {};

TEST_P(SpeedKnotsErrorTest, NamesTheKnotAndWhatIsWrong) {
  const absl::StatusOr<std::vector<SpeedKnot>> knots = ParseSpeedKnots(GetParam().text);

  ASSERT_FALSE(knots.ok());
  EXPECT_EQ(knots.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(knots.status().message(), GetParam().message);
}

INSTANTIATE_TEST_SUITE_P(
    Table, SpeedKnotsErrorTest,
    ::testing::Values(
        BadText{"", "speed knots: empty, expected comma-separated time:speed knots such as 0s:1,2s:0.5"},
        BadText{"  ", "speed knots: empty, expected comma-separated time:speed knots such as 0s:1,2s:0.5"},
        BadText{"0s:1,,2s:1", "speed knot 2 '': expected time:speed, e.g. 2s:0.5"},
        BadText{"0s:1,2s:1,", "speed knot 3 '': expected time:speed, e.g. 2s:0.5"},
        BadText{"0s:1,1s", "speed knot 2 '1s': expected time:speed, e.g. 2s:0.5"},
        BadText{"0s:1,1s:2,2x:0.5", "speed knot 3 '2x:0.5': time needs a unit, s or f"},
        BadText{"2:0.5", "speed knot 1 '2:0.5': time needs a unit, s or f"},
        BadText{"0s:1:2", "speed knot 1 '0s:1:2': expected one ':' between time and speed"},
        BadText{":1", "speed knot 1 ':1': time is missing"},
        BadText{"abcs:1", "speed knot 1 'abcs:1': time: expected a number, got \"abc\""},
        BadText{"s:1", "speed knot 1 's:1': time: expected a number, got an empty field"},
        BadText{"0s:fast", "speed knot 1 '0s:fast': speed: expected a number, got \"fast\""},
        BadText{"0s:", "speed knot 1 '0s:': speed: expected a number, got an empty field"},
        BadText{"0s:1x", "speed knot 1 '0s:1x': speed: malformed number \"1x\""},
        BadText{"0s:1,1.2.3s:1", "speed knot 2 '1.2.3s:1': time: malformed number \"1.2.3\""},
        BadText{"infs:1", "speed knot 1 'infs:1': time: expected a finite number, got \"inf\""},
        BadText{"0s:nan", "speed knot 1 '0s:nan': speed: expected a finite number, got \"nan\""},
        BadText{"1e999s:1",
                "speed knot 1 '1e999s:1': time: number \"1e999\" is out of range for a double"},
        BadText{"0s:1e-400",
                "speed knot 1 '0s:1e-400': speed: number \"1e-400\" is out of range for a "
                "double"}));

TEST(SpeedKnotsTest, ParsedNegativeSpeedIsRefusedByRetimeNamingTheKnot) {
  Clip clip;
  clip.frame_time_seconds = 1.0 / 30;
  clip.frame_count = 91;
  clip.channels.push_back({.name = "x", .samples = std::vector<double>(91, 0.0)});
  const absl::StatusOr<std::vector<SpeedKnot>> knots = ParseSpeedKnots("0s:1,1s:1,2s:-0.5");
  ASSERT_TRUE(knots.ok());

  const absl::StatusOr<RetimeResult> result =
      Retime(clip, {.domain = WarpDomain::kSpeedOverSource, .speed = *knots}, {});

  EXPECT_EQ(result.status().message(), "speed knot 3 (2s:-0.5): speed must be > 0");
}

}  // namespace
}  // namespace tempokey::core
