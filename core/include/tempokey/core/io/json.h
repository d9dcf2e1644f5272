// A small, strict JSON reader for tempokey's own files (keyed clips, batch pipelines), with the
// line and column of every value so that callers can point at what they refuse, and the string
// quoting its writers share.
#ifndef TEMPOKEY_CORE_IO_JSON_H_
#define TEMPOKEY_CORE_IO_JSON_H_

#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tempokey::core {

struct JsonValue;
using JsonArray = std::vector<JsonValue>;
// Members in document order; repeated names are kept (callers refuse them where it matters).
using JsonObject = std::vector<std::pair<std::string, JsonValue>>;

struct JsonValue {
  enum class Type { kNull, kBool, kNumber, kString, kArray, kObject } type = Type::kNull;
  double number = 0.0;  // kNumber: the value (finite; see ParseJson())
  bool boolean = false;  // kBool
  // kString: the decoded string; kNumber: the number exactly as written ("29.97", "1e-3").
  std::string text;
  std::shared_ptr<JsonArray> array;    // kArray
  std::shared_ptr<JsonObject> object;  // kObject
  int line = 1;    // where the value starts in the document, 1-based
  int column = 1;

  // The first member called `name` of an object; nullptr when absent or not an object.
  const JsonValue* Find(std::string_view name) const;
};

// Parses one JSON document. `source` names it in messages.
// Accepts RFC 8259 JSON with these limits: nesting at most 64 levels, numbers must be finite
// doubles, strings of UTF-8 text (RFC 8259 8.1), \u escapes only for the Basic Multilingual
// Plane outside the surrogates.
// Errors: kInvalidArgument "<source>:<line>:<column>: expected ',' or '}', got 'x'".
// Thread-safe: a pure function.
absl::StatusOr<JsonValue> ParseJson(std::string_view text, std::string_view source);

// The error of a reader that refuses `at`: kInvalidArgument "<source>:<line>:<column>: <what>",
// the place of the value in the document it was parsed from.
absl::Status JsonErrorAt(std::string_view source, const JsonValue& at, std::string_view what);

// Bytes of the valid UTF-8 character that starts `text` (1 for ASCII), 0 when none does (a
// Latin-1 byte, a stray continuation byte): what a JSON string can hold.
std::size_t Utf8CharLength(std::string_view text);
// Whether all of `text` is valid UTF-8.
bool IsUtf8(std::string_view text);

// Appends `text` to `out` as a JSON string literal (quotes, escapes of '"', '\\' and controls;
// a byte that does not start valid UTF-8, as in a Latin-1 file name, as U+FFFD: JSON is UTF-8;
// the C1 controls U+0080 to U+009F as \u0080 to \u009f, so the text cannot act on a terminal).
void AppendJsonString(std::string& out, std::string_view text);

// Appends code point `code` (at most U+10FFFF, not a surrogate) to `out` as UTF-8.
void AppendUtf8(std::string& out, char32_t code);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_JSON_H_
