#include "tempokey/core/io/printable_text.h"

#include "absl/strings/str_cat.h"
#include "tempokey/core/io/json.h"

namespace tempokey::core {
namespace {

// Appends `text` escaped; `quoted` also escapes `\` and `"`.
void AppendPrintable(std::string& out, std::string_view text, LineBreaks line_breaks,
                     bool quoted) {
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if ((c == '\n' || c == '\r') && line_breaks == LineBreaks::kAsSpaces) {
      out += ' ';
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c < 0x20 || c == 0x7f) {
      // A control byte would act on the terminal.
      absl::StrAppend(&out, "\\x", absl::Hex(c, absl::kZeroPad2));
    } else if (quoted && (c == '\\' || c == '"')) {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c < 0x80) {
      out += static_cast<char>(c);
    } else if (const std::size_t length = Utf8CharLength(text.substr(i)); length == 0) {
      // Not UTF-8 (a Latin-1 file name; a lone 0x9b is a terminal sequence on 8-bit terminals).
      absl::StrAppend(&out, "\\x", absl::Hex(c, absl::kZeroPad2));
    } else if (c == 0xc2 && static_cast<unsigned char>(text[i + 1]) <= 0x9f) {
      // A C1 control character in UTF-8 (U+0080 to U+009F; U+009B starts a terminal sequence).
      absl::StrAppend(&out, "\\u00",
                      absl::Hex(static_cast<unsigned char>(text[i + 1]), absl::kZeroPad2));
      ++i;
    } else {
      out.append(text.substr(i, length));
      i += length - 1;
    }
  }
}

}  // namespace

std::string PrintableText(std::string_view text, LineBreaks line_breaks) {
  std::string out;
  out.reserve(text.size());
  AppendPrintable(out, text, line_breaks, /*quoted=*/false);
  return out;
}

std::string LogValue(std::string_view text) {
  std::string out = "\"";
  out.reserve(text.size() + 2);
  AppendPrintable(out, text, LineBreaks::kEscaped, /*quoted=*/true);
  out += '"';
  return out;
}

}  // namespace tempokey::core
