#include "proto/bearer_token.h"

#include <cstddef>
#include <string>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace tempokey::wire {
namespace {

// A byte as a message names it: "a line break", "byte 0xc3 (not ASCII)", ...
std::string Describe(unsigned char byte) {
  if (byte == '\n' || byte == '\r') return "a line break";
  if (byte == '\t') return "a tab";
  if (byte >= 0x80) return absl::StrFormat("byte 0x%02x (not ASCII)", byte);
  return absl::StrFormat("control character 0x%02x", byte);
}

}  // namespace

absl::Status CheckBearerToken(std::string_view token) {
  for (std::size_t i = 0; i < token.size(); ++i) {
    const auto byte = static_cast<unsigned char>(token[i]);
    if (byte < 0x20 || byte > 0x7e) {
      return absl::InvalidArgumentError(absl::StrCat(
          "the token holds ", Describe(byte), " at byte ", i + 1,
          "; a bearer token is one line of printable ASCII (it travels in an HTTP header)"));
    }
  }
  if (!token.empty() && (token.front() == ' ' || token.back() == ' ')) {
    return absl::InvalidArgumentError(
        "the token starts or ends with a space; tokens are trimmed where they are read, so this "
        "one could never match");
  }
  return absl::OkStatus();
}

std::string_view TokenFileText(std::string_view text) {
  constexpr std::string_view kByteOrderMark = "\xEF\xBB\xBF";
  return text.starts_with(kByteOrderMark) ? text.substr(kByteOrderMark.size()) : text;
}

}  // namespace tempokey::wire
