#include "server/http/json_names.h"

#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/io/printable_text.h"

namespace tempokey::server::http {
namespace {

constexpr std::size_t kMaxScannedDepth = 64;

// One open object or array: an object's names so far, and whether its next string is a name.
struct Level {
  bool object = false;
  bool expect_name = false;
  std::set<std::string> names;
};

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// The string starting at json[*at] (its opening quote), decoded into `decoded` unless it is null
// (a value: only names are compared); *at left after its closing quote. False when it does not
// end or an escape is malformed (left to the parser).
bool ReadString(std::string_view json, std::size_t* at, std::string* decoded) {
  auto put = [decoded](char c) {
    if (decoded != nullptr) *decoded += c;
  };
  std::size_t i = *at + 1;
  while (i < json.size()) {
    const char c = json[i];
    if (c == '"') {
      *at = i + 1;
      return true;
    }
    if (c != '\\') {
      put(c);
      ++i;
      continue;
    }
    if (i + 1 >= json.size()) return false;
    const char e = json[i + 1];
    i += 2;
    switch (e) {
      case '"': put('"'); break;
      case '\\': put('\\'); break;
      case '/': put('/'); break;
      case 'b': put('\b'); break;
      case 'f': put('\f'); break;
      case 'n': put('\n'); break;
      case 'r': put('\r'); break;
      case 't': put('\t'); break;
      case 'u': {
        std::uint32_t code = 0;
        for (int k = 0; k < 4; ++k) {
          if (i >= json.size() || HexValue(json[i]) < 0) return false;
          code = code * 16 + static_cast<std::uint32_t>(HexValue(json[i++]));
        }
        // A surrogate pair is one character.
        if (code >= 0xD800 && code < 0xDC00 && i + 5 < json.size() && json[i] == '\\' &&
            json[i + 1] == 'u') {
          std::uint32_t low = 0;
          bool hex = true;
          for (int k = 0; k < 4; ++k) {
            const int v = HexValue(json[i + 2 + k]);
            hex = hex && v >= 0;
            low = low * 16 + static_cast<std::uint32_t>(v < 0 ? 0 : v);
          }
          if (hex && low >= 0xDC00 && low < 0xE000) {
            code = 0x10000 + ((code - 0xD800) << 10) + (low - 0xDC00);
            i += 6;
          }
        }
        if (decoded != nullptr) core::AppendUtf8(*decoded, code);
        break;
      }
      default:
        return false;
    }
  }
  return false;
}

}  // namespace

absl::Status CheckNoRepeatedNames(std::string_view json) {
  std::vector<Level> open;
  std::size_t i = 0;
  while (i < json.size()) {
    const char c = json[i];
    if (c == '"') {
      const std::size_t start = i;
      const bool name = !open.empty() && open.back().object && open.back().expect_name;
      std::string decoded;
      if (!ReadString(json, &i, name ? &decoded : nullptr)) return absl::OkStatus();
      if (name) {
        open.back().expect_name = false;
        if (!open.back().names.insert(decoded).second) {
          return absl::InvalidArgumentError(absl::StrCat(
              "member \"", core::PrintableText(decoded, core::LineBreaks::kEscaped),
              "\" is named twice in one object (at byte ", start + 1,
              "); a JSON request names each field once"));
        }
      }
      continue;
    }
    if (c == '{' || c == '[') {
      if (open.size() >= kMaxScannedDepth) return absl::OkStatus();
      open.push_back(Level{.object = c == '{', .expect_name = c == '{', .names = {}});
    } else if (c == '}' || c == ']') {
      if (open.empty()) return absl::OkStatus();
      open.pop_back();
    } else if (c == ',' && !open.empty() && open.back().object) {
      open.back().expect_name = true;
    }
    ++i;
  }
  return absl::OkStatus();
}

}  // namespace tempokey::server::http
