#include "tempokey/core/model/numbers.h"

#include <charconv>
#include <cmath>
#include <system_error>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr std::size_t kMaxQuotedBytes = 40;

}  // namespace

char* WriteDouble(char* out, double value) {
  return std::to_chars(out, out + kMaxDoubleChars, value).ptr;
}

void AppendDouble(std::string& out, double value) {
  char buffer[kMaxDoubleChars];
  const char* end = WriteDouble(buffer, value);
  out.append(buffer, static_cast<std::size_t>(end - buffer));
}

std::string FormatDouble(double value) {
  std::string out;
  AppendDouble(out, value);
  return out;
}

NumberError ParseDoubleToken(std::string_view token, double& value) {
  if (token.empty()) return NumberError::kEmpty;
  const char* first = token.data();
  const char* const last = first + token.size();
  // std::from_chars refuses a leading '+', which other writers (and people) produce.
  if (*first == '+' && token.size() > 1 && first[1] != '+' && first[1] != '-') ++first;
  double parsed = 0.0;
  const auto [end, ec] = std::from_chars(first, last, parsed);
  if (ec == std::errc::invalid_argument) return NumberError::kNotANumber;
  if (end != last) return NumberError::kMalformed;
  if (ec == std::errc::result_out_of_range) return NumberError::kOutOfRange;
  if (!std::isfinite(parsed)) return NumberError::kNonFinite;
  value = parsed;
  return NumberError::kNone;
}

std::string DescribeNumberError(NumberError error, std::string_view token) {
  switch (error) {
    case NumberError::kNone:
      break;
    case NumberError::kEmpty:
      return "expected a number, got an empty field";
    case NumberError::kNotANumber:
      return absl::StrCat("expected a number, got ", QuoteForMessage(token));
    case NumberError::kMalformed:
      return absl::StrCat("malformed number ", QuoteForMessage(token));
    case NumberError::kNonFinite:
      return absl::StrCat("expected a finite number, got ", QuoteForMessage(token));
    case NumberError::kOutOfRange:
      return absl::StrCat("number ", QuoteForMessage(token), " is out of range for a double");
  }
  return "not a number error";
}

absl::StatusOr<double> ParseDouble(std::string_view text) {
  double value = 0.0;
  const NumberError error = ParseDoubleToken(text, value);
  if (error != NumberError::kNone) {
    return absl::InvalidArgumentError(DescribeNumberError(error, text));
  }
  return value;
}

std::string DescribeDouble(double value) {
  if (std::isnan(value)) return "NaN";
  if (std::isinf(value)) return value > 0 ? "+infinity" : "-infinity";
  return absl::StrCat(value);
}

std::string QuoteForMessage(std::string_view text) {
  const bool cut = text.size() > kMaxQuotedBytes;
  if (cut) text = text.substr(0, kMaxQuotedBytes);
  return absl::StrCat("\"", absl::CHexEscape(AsAbsl(text)), cut ? "...\"" : "\"");
}

}  // namespace tempokey::core
