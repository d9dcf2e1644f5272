// Character classes shared by the text readers (BVH, CSV). Internal to tempokey_core.
#ifndef TEMPOKEY_CORE_SRC_IO_TEXT_SCAN_H_
#define TEMPOKEY_CORE_SRC_IO_TEXT_SCAN_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace tempokey::core::text_scan {

// Whitespace: ' ', '\t', '\v', '\f', '\r', '\n'. A line ends at "\n", "\r\n" or a lone "\r",
// so CRLF, LF and mixed files count lines alike and report the same columns.
inline constexpr std::array<bool, 256> kIsSpace = [] {
  std::array<bool, 256> table{};
  for (unsigned char c : {' ', '\t', '\v', '\f', '\r', '\n'}) table[c] = true;
  return table;
}();

inline bool IsSpace(char c) { return kIsSpace[static_cast<unsigned char>(c)]; }
inline bool IsLineBreak(char c) { return c == '\n' || c == '\r'; }
// Whitespace that does not end a line.
inline bool IsBlank(char c) { return IsSpace(c) && !IsLineBreak(c); }
// Bytes that never occur in text: C0 controls other than whitespace, and DEL.
inline bool IsControl(unsigned char c) { return (c < 0x20 && !kIsSpace[c]) || c == 0x7f; }

// Offset of the first byte of `text` that cannot be text (a control byte or invalid UTF-8),
// or npos.
std::size_t FindNonText(std::string_view text);

// Bytes of the valid UTF-8 character that starts `text` (1 for ASCII), 0 when none does.
std::size_t Utf8CharLength(std::string_view text);

// `text` with every byte that does not start a valid UTF-8 sequence replaced by U+FFFD (a clip
// name from a Latin-1 file name must go into protobuf strings and JSON, which hold UTF-8).
std::string ValidUtf8(std::string_view text);

// The file name of `path` without directory and last extension: "data/walk.bvh" -> "walk"; as
// ValidUtf8().
std::string FileStem(std::string_view path);

}  // namespace tempokey::core::text_scan

#endif  // TEMPOKEY_CORE_SRC_IO_TEXT_SCAN_H_
