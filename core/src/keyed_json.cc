// JSON reading and writing of keyed clips (schema in keyed_io.h).
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/file_io.h"
#include "tempokey/core/keyed_io.h"
#include "tempokey/core/numbers.h"
#include "tempokey/core/status.h"

namespace tempokey::core {
namespace {

constexpr std::string_view kFormatName = "tempokey.keyed_clip";
constexpr int kMaxDepth = 64;

// ---- writing ------------------------------------------------------------------------------------

void AppendString(std::string& out, std::string_view text) {
  out += '"';
  for (char ch : text) {
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

void AppendVec3(std::string& out, const Vec3& v) {
  out += '[';
  for (int i = 0; i < 3; ++i) {
    if (i > 0) out += ", ";
    AppendDouble(out, v[i]);
  }
  out += ']';
}

void AppendWeight(std::string& out, const std::optional<double>& weight) {
  if (weight) {
    AppendDouble(out, *weight);
  } else {
    out += "null";
  }
}

void AppendKey(std::string& out, const Key& key) {
  out += '[';
  AppendDouble(out, key.time_seconds);
  out += ", ";
  AppendDouble(out, key.value);
  out += ", ";
  AppendDouble(out, key.in_tangent);
  out += ", ";
  AppendDouble(out, key.out_tangent);
  if (key.in_weight || key.out_weight) {
    // A key weighted on one side only writes null for the other, which reads back unset (an
    // explicit 1/3 would evaluate the same but read back set).
    out += ", ";
    AppendWeight(out, key.in_weight);
    out += ", ";
    AppendWeight(out, key.out_weight);
  }
  out += ']';
}

// ---- a small JSON reader ------------------------------------------------------------------------

struct Value;
using Object = std::vector<std::pair<std::string, Value>>;
using Array = std::vector<Value>;

struct Value {
  enum class Type { kNull, kBool, kNumber, kString, kArray, kObject } type = Type::kNull;
  double number = 0.0;
  bool boolean = false;
  std::string text;
  std::shared_ptr<Array> array;
  std::shared_ptr<Object> object;
  int line = 1;
  int column = 1;
};

class JsonReader {
 public:
  JsonReader(std::string_view text, std::string_view source) : text_(text), source_(source) {}

  absl::StatusOr<Value> ReadDocument() {
    TEMPOKEY_ASSIGN_OR_RETURN(Value value, ReadValue(0));
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

  absl::StatusOr<Value> ReadValue(int depth) {
    if (depth > kMaxDepth) return Error("nesting deeper than 64 levels");
    SkipSpace();
    Value value;
    value.line = line_;
    value.column = column_;
    if (pos_ >= text_.size()) return Error("expected a value");
    const char ch = text_[pos_];
    if (ch == '{') return ReadObject(std::move(value), depth);
    if (ch == '[') return ReadArray(std::move(value), depth);
    if (ch == '"') {
      value.type = Value::Type::kString;
      TEMPOKEY_ASSIGN_OR_RETURN(value.text, ReadString());
      return value;
    }
    for (std::string_view word : {"true", "false", "null"}) {
      if (text_.substr(pos_, word.size()) == word) {
        value.type = word == "null" ? Value::Type::kNull : Value::Type::kBool;
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
    value.type = Value::Type::kNumber;
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
          if (code >= 0x80) return Error("expected an ASCII \\u escape");
          out += static_cast<char>(code);
          for (int i = 0; i < 4; ++i) Advance();
          break;
        }
        default:
          return Error("expected a valid escape");
      }
      Advance();
    }
  }

  absl::StatusOr<Value> ReadArray(Value value, int depth) {
    Advance();
    value.type = Value::Type::kArray;
    value.array = std::make_shared<Array>();
    if (Consume(']')) return value;
    while (true) {
      TEMPOKEY_ASSIGN_OR_RETURN(Value item, ReadValue(depth + 1));
      value.array->push_back(std::move(item));
      if (Consume(']')) return value;
      if (!Consume(',')) return Error("expected ',' or ']'");
    }
  }

  absl::StatusOr<Value> ReadObject(Value value, int depth) {
    Advance();
    value.type = Value::Type::kObject;
    value.object = std::make_shared<Object>();
    if (Consume('}')) return value;
    while (true) {
      SkipSpace();
      if (pos_ >= text_.size() || text_[pos_] != '"') return Error("expected a member name");
      TEMPOKEY_ASSIGN_OR_RETURN(std::string name, ReadString());
      if (!Consume(':')) return Error("expected ':'");
      TEMPOKEY_ASSIGN_OR_RETURN(Value item, ReadValue(depth + 1));
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

// ---- from values to a keyed clip ----------------------------------------------------------------

class Decoder {
 public:
  explicit Decoder(std::string_view source) : source_(source) {}

  absl::Status Fail(const Value& at, std::string_view what) const {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(source_), ":", at.line, ":", at.column, ": ", AsAbsl(what)));
  }

  // The members of `object` by name, refusing unknown or repeated ones.
  absl::StatusOr<std::map<std::string, const Value*>> Members(
      const Value& object, std::string_view what, std::initializer_list<std::string_view> known) {
    if (object.type != Value::Type::kObject) {
      return Fail(object, absl::StrCat(AsAbsl(what), " must be an object"));
    }
    std::map<std::string, const Value*> members;
    for (const auto& [name, value] : *object.object) {
      bool is_known = false;
      for (std::string_view k : known) is_known = is_known || k == name;
      if (!is_known) {
        return Fail(value, absl::StrCat(AsAbsl(what), " has an unknown member \"", name, "\""));
      }
      if (!members.emplace(name, &value).second) {
        return Fail(value, absl::StrCat(AsAbsl(what), " repeats member \"", name, "\""));
      }
    }
    return members;
  }

  absl::StatusOr<const Value*> Required(const std::map<std::string, const Value*>& members,
                                        const Value& owner, std::string_view what,
                                        std::string_view name) {
    const auto it = members.find(std::string(name));
    if (it == members.end()) {
      return Fail(owner, absl::StrCat(AsAbsl(what), " is missing \"", AsAbsl(name), "\""));
    }
    return it->second;
  }

  absl::StatusOr<double> Number(const Value& value, std::string_view what) {
    if (value.type != Value::Type::kNumber) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be a number"));
    }
    return value.number;
  }

  // A key weight: a number, or null for an unset one.
  absl::StatusOr<std::optional<double>> Weight(const Value& value, std::string_view what) {
    if (value.type == Value::Type::kNull) return std::optional<double>();
    if (value.type != Value::Type::kNumber) {
      return Fail(value, absl::StrCat(AsAbsl(what), " weight must be a number or null"));
    }
    return std::optional<double>(value.number);
  }

  absl::StatusOr<std::int64_t> Integer(const Value& value, std::string_view what) {
    TEMPOKEY_ASSIGN_OR_RETURN(double number, Number(value, what));
    if (number != std::floor(number) || std::abs(number) > 9e15) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be an integer, got ", number));
    }
    return static_cast<std::int64_t>(number);
  }

  absl::StatusOr<std::string> String(const Value& value, std::string_view what) {
    if (value.type != Value::Type::kString) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be a string"));
    }
    return value.text;
  }

  absl::StatusOr<const Array*> ArrayOf(const Value& value, std::string_view what) {
    if (value.type != Value::Type::kArray) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be an array"));
    }
    return value.array.get();
  }

  absl::StatusOr<Vec3> Vector(const Value& value, std::string_view what) {
    TEMPOKEY_ASSIGN_OR_RETURN(const Array* items, ArrayOf(value, what));
    if (items->size() != 3) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must have 3 numbers, got ", items->size()));
    }
    Vec3 out;
    for (int i = 0; i < 3; ++i) {
      TEMPOKEY_ASSIGN_OR_RETURN(out[i], Number((*items)[i], what));
    }
    return out;
  }

  absl::StatusOr<Joint> DecodeJoint(const Value& value, std::size_t index) {
    const std::string what = absl::StrCat("joint ", index);
    TEMPOKEY_ASSIGN_OR_RETURN(
        auto members, Members(value, what, {"name", "parent", "offset", "end_sites", "channels"}));
    Joint joint;
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* name, Required(members, value, what, "name"));
    TEMPOKEY_ASSIGN_OR_RETURN(joint.name, String(*name, what + " name"));
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* parent, Required(members, value, what, "parent"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t parent_index, Integer(*parent, what + " parent"));
    joint.parent = static_cast<int>(std::clamp<std::int64_t>(parent_index, -2, 1 << 30));
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* offset, Required(members, value, what, "offset"));
    TEMPOKEY_ASSIGN_OR_RETURN(joint.offset, Vector(*offset, what + " offset"));
    if (auto it = members.find("end_sites"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(const Array* sites, ArrayOf(*it->second, what + " end_sites"));
      for (const Value& site : *sites) {
        TEMPOKEY_ASSIGN_OR_RETURN(Vec3 v, Vector(site, what + " end site"));
        joint.end_sites.push_back(v);
      }
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* channels, Required(members, value, what, "channels"));
    TEMPOKEY_ASSIGN_OR_RETURN(const Array* list, ArrayOf(*channels, what + " channels"));
    for (const Value& item : *list) {
      TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t c, Integer(item, what + " channel index"));
      joint.channels.push_back(static_cast<int>(std::clamp<std::int64_t>(c, -1, 1 << 30)));
    }
    return joint;
  }

  absl::StatusOr<Key> DecodeKey(const Value& value, const std::string& what) {
    TEMPOKEY_ASSIGN_OR_RETURN(const Array* fields, ArrayOf(value, what));
    if (fields->size() != 4 && fields->size() != 6) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must have 4 or 6 numbers, got ",
                                      fields->size()));
    }
    std::array<double, 4> numbers{};
    for (std::size_t i = 0; i < 4; ++i) {
      TEMPOKEY_ASSIGN_OR_RETURN(numbers[i], Number((*fields)[i], what));
    }
    Key key{numbers[0], numbers[1], numbers[2], numbers[3], std::nullopt, std::nullopt};
    if (fields->size() == 6) {
      TEMPOKEY_ASSIGN_OR_RETURN(key.in_weight, Weight((*fields)[4], what));
      TEMPOKEY_ASSIGN_OR_RETURN(key.out_weight, Weight((*fields)[5], what));
    }
    return key;
  }

  absl::Status DecodeChannel(const Value& value, std::size_t index, KeyedClip& keyed) {
    const std::string what = absl::StrCat("channel ", index);
    TEMPOKEY_ASSIGN_OR_RETURN(auto members,
                              Members(value, what, {"joint", "kind", "name", "keys"}));
    Channel channel;
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* joint, Required(members, value, what, "joint"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t joint_index, Integer(*joint, what + " joint"));
    channel.joint = static_cast<int>(std::clamp<std::int64_t>(joint_index, -2, 1 << 30));
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* kind, Required(members, value, what, "kind"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::string kind_name, String(*kind, what + " kind"));
    if (kind_name == "scalar") {
      channel.kind = ChannelKind::kScalar;
    } else if (std::optional<ChannelKind> parsed = ParseChannelKind(kind_name)) {
      channel.kind = *parsed;
    } else {
      return Fail(*kind, absl::StrCat(what, " kind \"", kind_name, "\" is not a channel kind"));
    }
    if (auto it = members.find("name"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(channel.name, String(*it->second, what + " name"));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* keys, Required(members, value, what, "keys"));
    TEMPOKEY_ASSIGN_OR_RETURN(const Array* list, ArrayOf(*keys, what + " keys"));
    Curve curve;
    for (std::size_t k = 0; k < list->size(); ++k) {
      TEMPOKEY_ASSIGN_OR_RETURN(Key key, DecodeKey((*list)[k], absl::StrCat(what, " key ", k)));
      curve.keys.push_back(key);
    }
    keyed.layout.channels.push_back(std::move(channel));
    keyed.curves.push_back(std::move(curve));
    return absl::OkStatus();
  }

  absl::StatusOr<KeyedClip> Decode(const Value& root) {
    const std::string what = "keyed clip";
    TEMPOKEY_ASSIGN_OR_RETURN(
        auto members, Members(root, what, {"format", "version", "name", "frame_time_seconds",
                                           "frame_count", "joints", "channels", "markers"}));
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* format, Required(members, root, what, "format"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::string format_name, String(*format, "format"));
    if (format_name != kFormatName) {
      return Fail(*format, absl::StrCat("format must be \"", AsAbsl(kFormatName), "\", got \"",
                                        format_name, "\""));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* version, Required(members, root, what, "version"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t version_number, Integer(*version, "version"));
    if (version_number != 1) {
      return Fail(*version, absl::StrCat("version ", version_number, " is not supported (1 is)"));
    }
    KeyedClip keyed;
    if (auto it = members.find("name"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(keyed.layout.name, String(*it->second, "name"));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* frame_time,
                              Required(members, root, what, "frame_time_seconds"));
    TEMPOKEY_ASSIGN_OR_RETURN(keyed.layout.frame_time_seconds,
                              Number(*frame_time, "frame_time_seconds"));
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* frame_count,
                              Required(members, root, what, "frame_count"));
    TEMPOKEY_ASSIGN_OR_RETURN(keyed.layout.frame_count, Integer(*frame_count, "frame_count"));
    if (auto it = members.find("joints"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(const Array* joints, ArrayOf(*it->second, "joints"));
      for (std::size_t j = 0; j < joints->size(); ++j) {
        TEMPOKEY_ASSIGN_OR_RETURN(Joint joint, DecodeJoint((*joints)[j], j));
        keyed.layout.skeleton.joints.push_back(std::move(joint));
      }
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const Value* channels, Required(members, root, what, "channels"));
    TEMPOKEY_ASSIGN_OR_RETURN(const Array* list, ArrayOf(*channels, "channels"));
    for (std::size_t c = 0; c < list->size(); ++c) {
      TEMPOKEY_RETURN_IF_ERROR(DecodeChannel((*list)[c], c, keyed));
    }
    if (auto it = members.find("markers"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(const Array* markers, ArrayOf(*it->second, "markers"));
      for (std::size_t m = 0; m < markers->size(); ++m) {
        const std::string marker_what = absl::StrCat("marker ", m);
        const Value& item = (*markers)[m];
        TEMPOKEY_ASSIGN_OR_RETURN(
            auto fields, Members(item, marker_what, {"name", "time_seconds", "duration_seconds"}));
        Marker marker;
        TEMPOKEY_ASSIGN_OR_RETURN(const Value* name, Required(fields, item, marker_what, "name"));
        TEMPOKEY_ASSIGN_OR_RETURN(marker.name, String(*name, marker_what + " name"));
        TEMPOKEY_ASSIGN_OR_RETURN(const Value* time,
                                  Required(fields, item, marker_what, "time_seconds"));
        TEMPOKEY_ASSIGN_OR_RETURN(marker.time_seconds, Number(*time, marker_what + " time"));
        if (auto d = fields.find("duration_seconds"); d != fields.end()) {
          TEMPOKEY_ASSIGN_OR_RETURN(marker.duration_seconds,
                                    Number(*d->second, marker_what + " duration"));
        }
        keyed.layout.markers.push_back(std::move(marker));
      }
    }
    return keyed;
  }

 private:
  std::string_view source_;
};

}  // namespace

absl::StatusOr<std::string> FormatKeyedClipJson(const KeyedClip& keyed) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateKeyedClip(keyed));
  const Clip& layout = keyed.layout;
  std::string out = "{\n  \"format\": \"tempokey.keyed_clip\",\n  \"version\": 1,\n  \"name\": ";
  AppendString(out, layout.name);
  out += ",\n  \"frame_time_seconds\": ";
  AppendDouble(out, layout.frame_time_seconds);
  out += ",\n  \"frame_count\": ";
  out += std::to_string(layout.frame_count);
  out += ",\n  \"joints\": [";
  for (std::size_t j = 0; j < layout.skeleton.joints.size(); ++j) {
    const Joint& joint = layout.skeleton.joints[j];
    out += j == 0 ? "\n    " : ",\n    ";
    out += "{\"name\": ";
    AppendString(out, joint.name);
    out += ", \"parent\": " + std::to_string(joint.parent) + ", \"offset\": ";
    AppendVec3(out, joint.offset);
    out += ", \"end_sites\": [";
    for (std::size_t e = 0; e < joint.end_sites.size(); ++e) {
      if (e > 0) out += ", ";
      AppendVec3(out, joint.end_sites[e]);
    }
    out += "], \"channels\": [";
    for (std::size_t c = 0; c < joint.channels.size(); ++c) {
      if (c > 0) out += ", ";
      out += std::to_string(joint.channels[c]);
    }
    out += "]}";
  }
  out += layout.skeleton.joints.empty() ? "],\n" : "\n  ],\n";
  out += "  \"channels\": [";
  for (std::size_t c = 0; c < layout.channels.size(); ++c) {
    const Channel& channel = layout.channels[c];
    out += c == 0 ? "\n    " : ",\n    ";
    out += "{\"joint\": " + std::to_string(channel.joint) + ", \"kind\": ";
    AppendString(out, ChannelKindName(channel.kind));
    out += ", \"name\": ";
    AppendString(out, channel.name);
    out += ", \"keys\": [";
    const std::vector<Key>& keys = keyed.curves[c].keys;
    for (std::size_t k = 0; k < keys.size(); ++k) {
      if (k > 0) out += ", ";
      AppendKey(out, keys[k]);
    }
    out += "]}";
  }
  out += "\n  ],\n  \"markers\": [";
  for (std::size_t m = 0; m < layout.markers.size(); ++m) {
    const Marker& marker = layout.markers[m];
    out += m == 0 ? "\n    " : ",\n    ";
    out += "{\"name\": ";
    AppendString(out, marker.name);
    out += ", \"time_seconds\": ";
    AppendDouble(out, marker.time_seconds);
    out += ", \"duration_seconds\": ";
    AppendDouble(out, marker.duration_seconds);
    out += '}';
  }
  out += layout.markers.empty() ? "]\n}\n" : "\n  ]\n}\n";
  return out;
}

absl::StatusOr<KeyedClip> ParseKeyedClipJson(std::string_view text, std::string_view source_name) {
  JsonReader reader(text, source_name);
  TEMPOKEY_ASSIGN_OR_RETURN(Value root, reader.ReadDocument());
  Decoder decoder(source_name);
  TEMPOKEY_ASSIGN_OR_RETURN(KeyedClip keyed, decoder.Decode(root));
  absl::Status valid = ValidateKeyedClip(keyed);
  if (!valid.ok()) return Annotate(valid, source_name);
  return keyed;
}

absl::Status WriteKeyedClipJsonFile(const std::string& path, const KeyedClip& keyed) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::string text, FormatKeyedClipJson(keyed));
  return WriteFileAtomically(path, text);
}

absl::StatusOr<KeyedClip> ReadKeyedClipJsonFile(const std::string& path) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::string text, ReadFile(path));
  return ParseKeyedClipJson(text, path);
}

}  // namespace tempokey::core
