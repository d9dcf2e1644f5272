#include "client/args.h"

#include <string>
#include <vector>

#include "client/cli_errors.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

using ::testing::ElementsAre;

constexpr FlagSpec kFlags[] = {
    {"--output", "-o", "FILE", "output"},
    {"--speed", "", "KNOTS", "speed"},
    {"--hold", "", "T:D", "hold", true},
    {"--reverse", "", "", "reverse"},
};

absl::StatusOr<ParsedArgs> Parse(std::vector<std::string> args) {
  return ParseArgs(args, kFlags, "retime");
}

TEST(ParseArgsTest, SeparatesFlagsFromPositionalsInAnyOrder) {
  absl::StatusOr<ParsedArgs> parsed =
      Parse({"in.bvh", "-o", "out.bvh", "--speed=0s:1", "--reverse", "extra"});

  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_THAT(parsed->positionals(), ElementsAre("in.bvh", "extra"));
  EXPECT_EQ(parsed->Value("--output"), "out.bvh");
  EXPECT_EQ(parsed->Value("--speed"), "0s:1");
  EXPECT_TRUE(parsed->Has("--reverse"));
  EXPECT_FALSE(parsed->Has("--hold"));
}

TEST(ParseArgsTest, KeepsEveryValueOfARepeatableFlagInOrder) {
  absl::StatusOr<ParsedArgs> parsed = Parse({"--hold", "1s:0.5", "--hold=2s:1"});

  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_THAT(parsed->Values("--hold"), ElementsAre("1s:0.5", "2s:1"));
}

TEST(ParseArgsTest, TakesAValueThatLooksLikeAFlagVerbatim) {
  absl::StatusOr<ParsedArgs> parsed = Parse({"--speed", "-1"});

  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->Value("--speed"), "-1");
}

TEST(ParseArgsTest, DoubleDashEndsFlags) {
  absl::StatusOr<ParsedArgs> parsed = Parse({"--", "--reverse"});

  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_THAT(parsed->positionals(), ElementsAre("--reverse"));
  EXPECT_FALSE(parsed->Has("--reverse"));
}

TEST(ParseArgsTest, RefusesMistakesAsUsageErrorsNamingTheFlag) {
  struct Case {
    std::vector<std::string> args;
    std::string message;
  };
  const Case cases[] = {
      {{"--fsp", "30"}, "unknown flag --fsp for 'retime' (see tempokey retime --help)"},
      {{"--speed"}, "--speed needs a value (KNOTS)"},
      {{"--speed", "a", "--speed", "b"}, "--speed given twice"},
      {{"--reverse=yes"}, "--reverse takes no value"},
  };
  for (const Case& c : cases) {
    absl::StatusOr<ParsedArgs> parsed = Parse(c.args);

    ASSERT_FALSE(parsed.ok()) << c.message;
    EXPECT_TRUE(IsUsageError(parsed.status()));
    EXPECT_EQ(parsed.status().message(), c.message);
  }
}

TEST(ParseValueTest, ParsesNumbers) {
  EXPECT_EQ(*ParseDouble("--x", "2.5"), 2.5);
  EXPECT_EQ(*ParseDouble("--x", "-1e-3"), -1e-3);
  EXPECT_EQ(*ParseInt64("--n", "120"), 120);
  EXPECT_EQ(*ParseSeconds("--s", "0.5s"), 0.5);
  EXPECT_EQ(*ParseSeconds("--s", "3"), 3.0);
}

TEST(ParseValueTest, RefusesBadNumberSyntaxAsUsageError) {
  const absl::Status bad_double = ParseDouble("--tolerance", "abc").status();
  const absl::Status not_finite = ParseDouble("--tolerance", "nan").status();
  const absl::Status bad_int = ParseInt64("--fit-frames", "12.5").status();
  const absl::Status not_positive = ParsePositiveDouble("--max-speed", "0").status();

  EXPECT_EQ(bad_double.message(), "--tolerance: expected a number, got 'abc'");
  EXPECT_EQ(not_finite.message(), "--tolerance: expected a number, got 'nan'");
  EXPECT_EQ(bad_int.message(), "--fit-frames: expected an integer, got '12.5'");
  EXPECT_EQ(not_positive.message(), "--max-speed: expected a number > 0, got '0'");
  EXPECT_TRUE(IsUsageError(bad_double));
  EXPECT_TRUE(IsUsageError(bad_int));
}

TEST(ParseFrameRateTest, AcceptsIntegersDecimalsFractionsAndNtscSpellings) {
  struct Case {
    std::string text;
    std::int64_t numerator;
    std::int64_t denominator;
  };
  const Case cases[] = {
      {"30", 30, 1},           {"12.5", 25, 2},        {"30000/1001", 30000, 1001},
      {"29.97", 30000, 1001},  {"23.976", 24000, 1001}, {"59.94", 60000, 1001},
      {"120", 120, 1},         {"24.0", 24, 1},
  };
  for (const Case& c : cases) {
    absl::StatusOr<core::FrameRate> rate = ParseFrameRate("--fps", c.text);

    ASSERT_TRUE(rate.ok()) << c.text << ": " << rate.status();
    EXPECT_EQ(rate->numerator, c.numerator) << c.text;
    EXPECT_EQ(rate->denominator, c.denominator) << c.text;
  }
}

TEST(ParseFrameRateTest, RefusesZeroAndGarbage) {
  EXPECT_EQ(ParseFrameRate("--fps", "0").status().message(),
            "--fps: expected a frame rate > 0, got '0'");
  EXPECT_EQ(ParseFrameRate("--fps", "30/0").status().message(),
            "--fps: expected a frame rate > 0, got '30/0'");
  EXPECT_EQ(ParseFrameRate("--fps", "thirty").status().message(),
            "--fps: expected a frame rate such as 30, 29.97 or 30000/1001, got 'thirty'");
  EXPECT_FALSE(ParseFrameRate("--fps", "-30").ok());
  EXPECT_FALSE(ParseFrameRate("--fps", "1/").ok());
}

TEST(ParseTimePointTest, ReadsSecondsAndFrames) {
  absl::StatusOr<core::TimePoint> seconds = ParseTimePoint("--hold", "2.5s");
  absl::StatusOr<core::TimePoint> frames = ParseTimePoint("--hold", "75f");
  absl::StatusOr<core::TimePoint> unitless = ParseTimePoint("--hold", "75");

  ASSERT_TRUE(seconds.ok());
  ASSERT_TRUE(frames.ok());
  EXPECT_EQ(seconds->value, 2.5);
  EXPECT_FALSE(seconds->in_frames);
  EXPECT_EQ(frames->value, 75.0);
  EXPECT_TRUE(frames->in_frames);
  EXPECT_EQ(unitless.status().message(),
            "--hold: expected a time with a unit, such as 2.5s or 75f, got '75'");
}

TEST(ParseValueTest, SplitsPairsAndLabels) {
  auto pair = SplitPair("--hold", "2s:0.5s", "T:DURATION");
  auto label = ParseLabel("--label", "shot=12=b");

  ASSERT_TRUE(pair.ok());
  ASSERT_TRUE(label.ok());
  EXPECT_EQ(pair->first, "2s");
  EXPECT_EQ(pair->second, "0.5s");
  EXPECT_EQ(label->first, "shot");
  EXPECT_EQ(label->second, "12=b");
  EXPECT_EQ(SplitPair("--hold", "2s", "T:DURATION").status().message(),
            "--hold: expected T:DURATION, got '2s'");
  EXPECT_EQ(ParseLabel("--label", "=x").status().message(),
            "--label: expected KEY=VALUE, got '=x'");
}

TEST(ParseChoiceTest, NamesTheChoicesWhenRefusing) {
  constexpr std::string_view kChoices[] = {"tent", "linear"};

  EXPECT_EQ(*ParseChoice("--filter", "linear", kChoices), "linear");
  EXPECT_EQ(ParseChoice("--filter", "gauss", kChoices).status().message(),
            "--filter: expected one of tent, linear, got 'gauss'");
}

}  // namespace
}  // namespace tempokey::client
