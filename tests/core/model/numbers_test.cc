// Shortest round-trip number text and the strict whole-token parser.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>

#include "gtest/gtest.h"
#include "tempokey/core/model/numbers.h"
#include "tests/testing/bit_digest.h"

namespace tempokey::core {
namespace {

using ::tempokey::testing::SameBits;

TEST(FormatDoubleTest, WritesShortestRoundTripText) {
  EXPECT_EQ(FormatDouble(0.1), "0.1");
  EXPECT_EQ(FormatDouble(0.1 + 0.2), "0.30000000000000004");
  EXPECT_EQ(FormatDouble(-0.0), "-0");
  EXPECT_EQ(FormatDouble(100.0), "100");
  EXPECT_EQ(FormatDouble(1e-07), "1e-07");
  EXPECT_EQ(FormatDouble(5e-324), "5e-324");
  EXPECT_EQ(FormatDouble(0.0083333), "0.0083333");
}

TEST(FormatDoubleTest, LongestOutputFitsTheDeclaredBound) {
  const std::string longest = FormatDouble(-2.2250738585072014e-308);

  EXPECT_EQ(longest, "-2.2250738585072014e-308");
  EXPECT_EQ(longest.size(), kMaxDoubleChars);
}

TEST(FormatDoubleTest, RandomBitPatternsRoundTripExactly) {
  std::mt19937_64 random(20240611);  // fixed seed: reproducible
  std::string text;
  for (int i = 0; i < 100000; ++i) {
    const std::uint64_t bits = random();
    double value;
    std::memcpy(&value, &bits, sizeof(value));
    if (!std::isfinite(value)) continue;

    text.clear();
    AppendDouble(text, value);
    absl::StatusOr<double> parsed = ParseDouble(text);

    ASSERT_TRUE(parsed.ok()) << text << ": " << parsed.status();
    ASSERT_TRUE(SameBits(*parsed, value)) << text;
    ASSERT_LE(text.size(), kMaxDoubleChars) << text;
  }
}

TEST(ParseDoubleTest, AcceptsTheSpellingsWritersUse) {
  EXPECT_TRUE(SameBits(*ParseDouble("1.2e-05"), 1.2e-05));
  EXPECT_TRUE(SameBits(*ParseDouble("-3E+02"), -300.0));
  EXPECT_TRUE(SameBits(*ParseDouble(".0083333"), 0.0083333));
  EXPECT_TRUE(SameBits(*ParseDouble("5."), 5.0));
  EXPECT_TRUE(SameBits(*ParseDouble("+7.5"), 7.5));
  EXPECT_TRUE(SameBits(*ParseDouble("-0"), -0.0));
  EXPECT_TRUE(SameBits(*ParseDouble("1.7976931348623157e308"), 1.7976931348623157e308));
}

TEST(ParseDoubleTest, RefusesPartialAndNonFiniteNumbersWithReasons) {
  auto message = [](const std::string& text) {
    absl::StatusOr<double> parsed = ParseDouble(text);
    return parsed.ok() ? std::string("parsed") : std::string(parsed.status().message());
  };

  EXPECT_EQ(message(""), "expected a number, got an empty field");
  EXPECT_EQ(message("abc"), "expected a number, got \"abc\"");
  EXPECT_EQ(message("+"), "expected a number, got \"+\"");
  EXPECT_EQ(message("+-1"), "expected a number, got \"+-1\"");
  EXPECT_EQ(message("1.2.3"), "malformed number \"1.2.3\"");
  EXPECT_EQ(message("1e"), "malformed number \"1e\"");
  EXPECT_EQ(message("0x10"), "malformed number \"0x10\"");
  EXPECT_EQ(message(" 1"), "expected a number, got \" 1\"");
  EXPECT_EQ(message("1 "), "malformed number \"1 \"");
  EXPECT_EQ(message("nan"), "expected a finite number, got \"nan\"");
  EXPECT_EQ(message("-Infinity"), "expected a finite number, got \"-Infinity\"");
  EXPECT_EQ(message("1e999"), "number \"1e999\" is out of range for a double");
  EXPECT_EQ(message("1e-400"), "number \"1e-400\" is out of range for a double");
}

TEST(ParseDoubleTokenTest, LeavesValueUntouchedOnError) {
  double value = 42.0;

  const NumberError error = ParseDoubleToken("1.2.3", value);

  EXPECT_EQ(error, NumberError::kMalformed);
  EXPECT_EQ(value, 42.0);
}

TEST(DescribeDoubleTest, NamesNonFiniteValuesAndWritesFiniteOnesInSixDigits) {
  EXPECT_EQ(DescribeDouble(std::numeric_limits<double>::quiet_NaN()), "NaN");
  EXPECT_EQ(DescribeDouble(-std::numeric_limits<double>::quiet_NaN()), "NaN");
  EXPECT_EQ(DescribeDouble(std::numeric_limits<double>::infinity()), "+infinity");
  EXPECT_EQ(DescribeDouble(-std::numeric_limits<double>::infinity()), "-infinity");
  EXPECT_EQ(DescribeDouble(-0.5), "-0.5");
  EXPECT_EQ(DescribeDouble(0.0), "0");
  EXPECT_EQ(DescribeDouble(1e6), "1e+06");
  EXPECT_EQ(DescribeDouble(0.1 + 0.2), "0.3");
}

TEST(QuoteForMessageTest, EscapesControlBytesAndCutsLongText) {
  EXPECT_EQ(QuoteForMessage(std::string("a\0z", 3)), "\"a\\x00z\"");
  // A hex digit after an escape is escaped too, so the escape cannot swallow it.
  EXPECT_EQ(QuoteForMessage(std::string("a\0b", 3)), "\"a\\x00\\x62\"");
  EXPECT_EQ(QuoteForMessage("tab\there"), "\"tab\\there\"");
  EXPECT_EQ(QuoteForMessage(std::string(50, 'x')), "\"" + std::string(40, 'x') + "...\"");
}

}  // namespace
}  // namespace tempokey::core
