// Number text for the file formats (BVH, CSV, JSON): shortest round-trip formatting of doubles
// and a strict parser that accepts a whole token or nothing; and how error messages show
// numbers and text.
#ifndef TEMPOKEY_CORE_MODEL_NUMBERS_H_
#define TEMPOKEY_CORE_MODEL_NUMBERS_H_

#include <cstddef>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace tempokey::core {

// The most characters WriteDouble() writes for one double: "-2.2250738585072014e-308".
inline constexpr std::size_t kMaxDoubleChars = 24;

// Writes the shortest decimal text that reads back to exactly `value` (std::to_chars without a
// precision): "0.1", "-0", "1e-07", "5e-324", "0.30000000000000004". No locale, no padding.
// Precondition: `out` has room for kMaxDoubleChars characters. Non-finite values come out as
// "nan", "inf" or "-inf", which ParseDouble() refuses: callers write finite numbers only.
// Returns one past the last character written. Thread-safe.
char* WriteDouble(char* out, double value);

// WriteDouble() appended to `out`.
void AppendDouble(std::string& out, double value);

// WriteDouble() as a string.
std::string FormatDouble(double value);

// Why a token is not a number.
enum class NumberError {
  kNone,         // parsed
  kEmpty,        // the token is empty
  kNotANumber,   // no number at its start: "abc", "-", "+"
  kMalformed,    // a number followed by more text: "1.2.3", "1e", "0x10", "12abc"
  kNonFinite,    // "nan", "inf", "-Infinity" (std::from_chars reads them; we do not)
  kOutOfRange,   // magnitude over DBL_MAX or under the smallest subnormal: "1e999", "1e-400"
};

// Parses all of `token` as one finite double: std::from_chars (general format, correctly
// rounded, no locale) plus an optional leading '+'. No leading or trailing whitespace, no hex.
// Sets `value` only when the result is kNone. Thread-safe, allocates nothing.
NumberError ParseDoubleToken(std::string_view token, double& value);

// The message for `error` on `token`, as format readers embed it after their location:
//   kEmpty       expected a number, got an empty field
//   kNotANumber  expected a number, got "abc"
//   kMalformed   malformed number "1.2.3"
//   kNonFinite   expected a finite number, got "nan"
//   kOutOfRange  number "1e999" is out of range for a double
// Precondition: error != kNone.
std::string DescribeNumberError(NumberError error, std::string_view token);

// ParseDoubleToken() with its error as a status.
// Errors: kInvalidArgument with DescribeNumberError()'s message.
absl::StatusOr<double> ParseDouble(std::string_view text);

// How messages name a double: "NaN", "+infinity" or "-infinity" when it is not finite, else as
// absl::StrCat() writes it (6 significant digits: "0.5", "-1", "1e+06"). Thread-safe.
std::string DescribeDouble(double value);

// `text` in double quotes for an error message, with control and non-ASCII bytes escaped
// (C style: "\x00", "\t") and cut to its first 40 bytes ("..." marks the cut).
std::string QuoteForMessage(std::string_view text);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_NUMBERS_H_
