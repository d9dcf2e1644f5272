// The small JSON reader and string writer of tempokey's file formats (keyed clips, pipelines).
//
// Why our own and not nlohmann-json3-dev (Debian 12 ships 3.11.2): every value we return carries
// the line and column where it starts, so a refusal that is about a value's meaning, not its
// syntax ("ops.json:2:39: operation 1 (retime): no option 'fsp'"), points at it; nlohmann's DOM
// keeps no positions (only its parse errors carry a byte offset). We also keep each number's text
// exactly as written, which pipeline files need for rates such as "29.97" and which makes the keyed
// clip round trip exact by construction, and we refuse non-finite numbers and nesting beyond 64
// levels up front (untrusted input). The reader is about 200 lines and fuzzed.
#include "tempokey/core/io/json.h"

#include <cctype>
#include <memory>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"
#include "text_scan.h"

namespace tempokey::core {
namespace {

constexpr int kMaxDepth = 64;


class JsonReader {
 public:
  JsonReader(std::string_view text, std::string_view source) : text_(text), source_(source) {}

  absl::StatusOr<JsonValue> ReadDocument() {
    TEMPOKEY_ASSIGN_OR_RETURN(JsonValue value, ReadValue(0));
    SkipSpace();
    if (pos_ < text_.size()) return Error("expected the end of the document");
    return value;
  }

 private:
  // "<source>:<line>:<column>: <expected>, got <the character here>".
  absl::Status Error(std::string_view expected) const {
    const std::string found = pos_ < text_.size() ? QuoteForMessage(text_.substr(pos_, 1))
                                                  : std::string("the end of the text");
    return ErrorHere(absl::StrCat(AsAbsl(expected), ", got ", found));
  }

  // "<source>:<line>:<column>: <what>", for messages that already say what was found (a number
  // error quotes its whole token).
  absl::Status ErrorHere(std::string_view what) const {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(source_), ":", line_, ":", column_, ": ", AsAbsl(what)));
  }

  void Advance() {
    if (text_[pos_] == '\n') {
      ++line_;
      column_ = 1;
    } else {
      ++column_;
    }
    ++pos_;
  }

  void SkipSpace() {
    while (pos_ < text_.size() && (text_[pos_] == ' ' || text_[pos_] == '\t' ||
                                   text_[pos_] == '\n' || text_[pos_] == '\r')) {
      Advance();
    }
  }

  bool Consume(char ch) {
    SkipSpace();
    if (pos_ < text_.size() && text_[pos_] == ch) {
      Advance();
      return true;
    }
    return false;
  }

  absl::StatusOr<JsonValue> ReadValue(int depth) {
    if (depth > kMaxDepth) return ErrorHere("nesting deeper than 64 levels");
    SkipSpace();
    JsonValue value;
    value.line = line_;
    value.column = column_;
    if (pos_ >= text_.size()) return Error("expected a value");
    const char ch = text_[pos_];
    if (ch == '{') return ReadObject(std::move(value), depth);
    if (ch == '[') return ReadArray(std::move(value), depth);
    if (ch == '"') {
      value.type = JsonValue::Type::kString;
      TEMPOKEY_ASSIGN_OR_RETURN(value.text, ReadString());
      return value;
    }
    for (std::string_view word : {"true", "false", "null"}) {
      if (text_.substr(pos_, word.size()) == word) {
        value.type = word == "null" ? JsonValue::Type::kNull : JsonValue::Type::kBool;
        value.boolean = word == "true";
        for (std::size_t i = 0; i < word.size(); ++i) Advance();
        return value;
      }
    }
    std::size_t end = pos_;
    while (end < text_.size() && (std::isdigit(static_cast<unsigned char>(text_[end])) ||
                                  text_[end] == '-' || text_[end] == '+' || text_[end] == '.' ||
                                  text_[end] == 'e' || text_[end] == 'E')) {
      ++end;
    }
    if (end == pos_) return Error("expected a value");
    const std::string_view token = text_.substr(pos_, end - pos_);
    const NumberError error = ParseDoubleToken(token, value.number);
    if (error != NumberError::kNone) return ErrorHere(DescribeNumberError(error, token));
    value.type = JsonValue::Type::kNumber;
    value.text = std::string(token);
    while (pos_ < end) Advance();
    return value;
  }

  absl::StatusOr<std::string> ReadString() {
    Advance();  // the opening quote
    std::string out;
    while (true) {
      if (pos_ >= text_.size()) return Error("expected '\"' to end the string");
      const char ch = text_[pos_];
      if (ch == '"') {
        Advance();
        return out;
      }
      if (static_cast<unsigned char>(ch) < 0x20) return Error("expected a string character");
      if (static_cast<unsigned char>(ch) >= 0x80) {
        // JSON text is UTF-8 (RFC 8259 8.1): a byte that does not start a valid sequence is
        // refused, so that every string read can be written back unchanged.
        const std::size_t length = text_scan::Utf8CharLength(text_.substr(pos_));
        if (length == 0) return Error("expected UTF-8 text in the string");
        out.append(text_.substr(pos_, length));
        for (std::size_t i = 0; i < length; ++i) Advance();
        continue;
      }
      if (ch != '\\') {
        out += ch;
        Advance();
        continue;
      }
      Advance();
      if (pos_ >= text_.size()) return Error("expected an escape");
      const char escape = text_[pos_];
      switch (escape) {
        case '"': out += '"'; break;
        case '\\': out += '\\'; break;
        case '/': out += '/'; break;
        case 'n': out += '\n'; break;
        case 't': out += '\t'; break;
        case 'r': out += '\r'; break;
        case 'b': out += '\b'; break;
        case 'f': out += '\f'; break;
        case 'u': {
          if (pos_ + 4 >= text_.size()) return Error("expected 4 hex digits");
          unsigned code = 0;
          for (int i = 1; i <= 4; ++i) {
            const char h = text_[pos_ + i];
            code <<= 4;
            if (h >= '0' && h <= '9') code |= static_cast<unsigned>(h - '0');
            else if (h >= 'a' && h <= 'f') code |= static_cast<unsigned>(h - 'a' + 10);
            else if (h >= 'A' && h <= 'F') code |= static_cast<unsigned>(h - 'A' + 10);
            else return Error("expected 4 hex digits");
          }
          // ASCII and the rest of the Basic Multilingual Plane, as UTF-8 (AppendJsonString()
          // writes the C1 controls so); not the surrogates, which pair up for other planes.
          if (code >= 0xd800 && code <= 0xdfff) {
            return Error("expected a \\u escape outside the surrogates (U+D800 to U+DFFF)");
          }
          AppendUtf8(out, code);
          for (int i = 0; i < 4; ++i) Advance();
          break;
        }
        default:
          return Error("expected a valid escape");
      }
      Advance();
    }
  }

  absl::StatusOr<JsonValue> ReadArray(JsonValue value, int depth) {
    Advance();
    value.type = JsonValue::Type::kArray;
    value.array = std::make_shared<JsonArray>();
    if (Consume(']')) return value;
    while (true) {
      TEMPOKEY_ASSIGN_OR_RETURN(JsonValue item, ReadValue(depth + 1));
      value.array->push_back(std::move(item));
      if (Consume(']')) return value;
      if (!Consume(',')) return Error("expected ',' or ']'");
    }
  }

  absl::StatusOr<JsonValue> ReadObject(JsonValue value, int depth) {
    Advance();
    value.type = JsonValue::Type::kObject;
    value.object = std::make_shared<JsonObject>();
    if (Consume('}')) return value;
    while (true) {
      SkipSpace();
      if (pos_ >= text_.size() || text_[pos_] != '"') return Error("expected a member name");
      TEMPOKEY_ASSIGN_OR_RETURN(std::string name, ReadString());
      if (!Consume(':')) return Error("expected ':'");
      TEMPOKEY_ASSIGN_OR_RETURN(JsonValue item, ReadValue(depth + 1));
      value.object->emplace_back(std::move(name), std::move(item));
      if (Consume('}')) return value;
      if (!Consume(',')) return Error("expected ',' or '}'");
    }
  }

  std::string_view text_;
  std::string_view source_;
  std::size_t pos_ = 0;
  int line_ = 1;
  int column_ = 1;
};

}  // namespace

absl::Status JsonErrorAt(std::string_view source, const JsonValue& at, std::string_view what) {
  return absl::InvalidArgumentError(
      absl::StrCat(AsAbsl(source), ":", at.line, ":", at.column, ": ", AsAbsl(what)));
}

std::size_t Utf8CharLength(std::string_view text) { return text_scan::Utf8CharLength(text); }

bool IsUtf8(std::string_view text) {
  for (std::size_t i = 0; i < text.size();) {
    const std::size_t length = text_scan::Utf8CharLength(text.substr(i));
    if (length == 0) return false;
    i += length;
  }
  return true;
}

void AppendUtf8(std::string& out, char32_t code) {
  if (code < 0x80) {
    out += static_cast<char>(code);
  } else if (code < 0x800) {
    out += static_cast<char>(0xc0 | (code >> 6));
    out += static_cast<char>(0x80 | (code & 0x3f));
  } else if (code < 0x10000) {
    out += static_cast<char>(0xe0 | (code >> 12));
    out += static_cast<char>(0x80 | ((code >> 6) & 0x3f));
    out += static_cast<char>(0x80 | (code & 0x3f));
  } else {
    out += static_cast<char>(0xf0 | (code >> 18));
    out += static_cast<char>(0x80 | ((code >> 12) & 0x3f));
    out += static_cast<char>(0x80 | ((code >> 6) & 0x3f));
    out += static_cast<char>(0x80 | (code & 0x3f));
  }
}

void AppendJsonString(std::string& out, std::string_view text) {
  out += '"';
  // JSON text is UTF-8: a byte that is not (a Latin-1 file name) becomes U+FFFD.
  const std::string valid = text_scan::FindNonText(text) == std::string_view::npos
                                ? std::string()
                                : text_scan::ValidUtf8(text);
  if (!valid.empty()) text = valid;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char ch = text[i];
    // A C1 control (U+0080 to U+009F: 0xC2 0x80..0x9F) escaped: U+009B starts a terminal
    // sequence, and a summary goes to the terminal.
    if (static_cast<unsigned char>(ch) == 0xc2 && i + 1 < text.size() &&
        static_cast<unsigned char>(text[i + 1]) >= 0x80 &&
        static_cast<unsigned char>(text[i + 1]) <= 0x9f) {
      static constexpr char kHex[] = "0123456789abcdef";
      const auto code = static_cast<unsigned char>(text[i + 1]);
      out += "\\u00";
      out += kHex[code >> 4];
      out += kHex[code & 0xf];
      ++i;
      continue;
    }
    switch (ch) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\t': out += "\\t"; break;
      case '\r': out += "\\r"; break;
      default:
        if (static_cast<unsigned char>(ch) < 0x20) {
          static constexpr char kHex[] = "0123456789abcdef";
          out += "\\u00";
          out += kHex[(ch >> 4) & 0xf];
          out += kHex[ch & 0xf];
        } else {
          out += ch;
        }
    }
  }
  out += '"';
}

absl::StatusOr<JsonValue> ParseJson(std::string_view text, std::string_view source) {
  JsonReader reader(text, source);
  return reader.ReadDocument();
}

const JsonValue* JsonValue::Find(std::string_view name) const {
  if (type != Type::kObject) return nullptr;
  for (const auto& [member, value] : *object) {
    if (member == name) return &value;
  }
  return nullptr;
}

}  // namespace tempokey::core
