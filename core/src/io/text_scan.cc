#include "text_scan.h"

#include <cstdint>
#include <filesystem>

namespace tempokey::core::text_scan {
namespace {

// Length of the valid UTF-8 sequence starting at `s` (of `n` bytes), or 0 if it is invalid.
std::size_t Utf8SequenceLength(const unsigned char* s, std::size_t n) {
  const unsigned char c = s[0];
  std::size_t length = 0;
  std::uint32_t min_code = 0;
  if (c >= 0xc2 && c <= 0xdf) {
    length = 2;
    min_code = 0x80;
  } else if (c >= 0xe0 && c <= 0xef) {
    length = 3;
    min_code = 0x800;
  } else if (c >= 0xf0 && c <= 0xf4) {
    length = 4;
    min_code = 0x10000;
  } else {
    return 0;
  }
  if (n < length) return 0;
  std::uint32_t code = c & (0xffu >> (length + 1));
  for (std::size_t i = 1; i < length; ++i) {
    if ((s[i] & 0xc0) != 0x80) return 0;
    code = (code << 6) | (s[i] & 0x3fu);
  }
  if (code < min_code || code > 0x10ffff || (code >= 0xd800 && code <= 0xdfff)) return 0;
  return length;
}

}  // namespace

std::size_t FindNonText(std::string_view text) {
  const auto* s = reinterpret_cast<const unsigned char*>(text.data());
  for (std::size_t i = 0; i < text.size();) {
    if (s[i] < 0x80) {
      if (IsControl(s[i])) return i;
      ++i;
      continue;
    }
    const std::size_t length = Utf8SequenceLength(s + i, text.size() - i);
    if (length == 0) return i;
    i += length;
  }
  return std::string_view::npos;
}

std::size_t Utf8CharLength(std::string_view text) {
  if (text.empty()) return 0;
  const auto* s = reinterpret_cast<const unsigned char*>(text.data());
  return s[0] < 0x80 ? 1 : Utf8SequenceLength(s, text.size());
}

std::string ValidUtf8(std::string_view text) {
  const auto* s = reinterpret_cast<const unsigned char*>(text.data());
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t length = s[i] < 0x80 ? 1 : Utf8SequenceLength(s + i, text.size() - i);
    if (length == 0) {
      out += "\xEF\xBF\xBD";  // U+FFFD REPLACEMENT CHARACTER
      ++i;
    } else {
      out.append(text.substr(i, length));
      i += length;
    }
  }
  return out;
}

std::string FileStem(std::string_view path) {
  return ValidUtf8(std::filesystem::path(std::string(path)).stem().string());
}

}  // namespace tempokey::core::text_scan
