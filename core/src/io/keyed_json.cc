// JSON reading and writing of keyed clips (schema in keyed_json.h).
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
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr std::string_view kFormatName = "tempokey.keyed_clip";

// ---- writing ------------------------------------------------------------------------------------

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

// ---- from values to a keyed clip ----------------------------------------------------------------

class Decoder {
 public:
  explicit Decoder(std::string_view source) : source_(source) {}

  absl::Status Fail(const JsonValue& at, std::string_view what) const {
    return JsonErrorAt(source_, at, what);
  }

  // The members of `object` by name, refusing unknown or repeated ones.
  absl::StatusOr<std::map<std::string, const JsonValue*>> Members(
      const JsonValue& object, std::string_view what, std::initializer_list<std::string_view> known) {
    if (object.type != JsonValue::Type::kObject) {
      return Fail(object, absl::StrCat(AsAbsl(what), " must be an object"));
    }
    std::map<std::string, const JsonValue*> members;
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

  absl::StatusOr<const JsonValue*> Required(const std::map<std::string, const JsonValue*>& members,
                                        const JsonValue& owner, std::string_view what,
                                        std::string_view name) {
    const auto it = members.find(std::string(name));
    if (it == members.end()) {
      return Fail(owner, absl::StrCat(AsAbsl(what), " is missing \"", AsAbsl(name), "\""));
    }
    return it->second;
  }

  absl::StatusOr<double> Number(const JsonValue& value, std::string_view what) {
    if (value.type != JsonValue::Type::kNumber) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be a number"));
    }
    return value.number;
  }

  // A key weight: a number, or null for an unset one.
  absl::StatusOr<std::optional<double>> Weight(const JsonValue& value, std::string_view what) {
    if (value.type == JsonValue::Type::kNull) return std::optional<double>();
    if (value.type != JsonValue::Type::kNumber) {
      return Fail(value, absl::StrCat(AsAbsl(what), " weight must be a number or null"));
    }
    return std::optional<double>(value.number);
  }

  absl::StatusOr<std::int64_t> Integer(const JsonValue& value, std::string_view what) {
    TEMPOKEY_ASSIGN_OR_RETURN(double number, Number(value, what));
    if (number != std::floor(number) || std::abs(number) > 9e15) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be an integer, got ", number));
    }
    return static_cast<std::int64_t>(number);
  }

  absl::StatusOr<std::string> String(const JsonValue& value, std::string_view what) {
    if (value.type != JsonValue::Type::kString) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be a string"));
    }
    return value.text;
  }

  absl::StatusOr<const JsonArray*> ArrayOf(const JsonValue& value, std::string_view what) {
    if (value.type != JsonValue::Type::kArray) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must be an array"));
    }
    return value.array.get();
  }

  absl::StatusOr<Vec3> Vector(const JsonValue& value, std::string_view what) {
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* items, ArrayOf(value, what));
    if (items->size() != 3) {
      return Fail(value, absl::StrCat(AsAbsl(what), " must have 3 numbers, got ", items->size()));
    }
    Vec3 out;
    for (int i = 0; i < 3; ++i) {
      TEMPOKEY_ASSIGN_OR_RETURN(out[i], Number((*items)[i], what));
    }
    return out;
  }

  absl::StatusOr<Joint> DecodeJoint(const JsonValue& value, std::size_t index) {
    const std::string what = absl::StrCat("joint ", index);
    TEMPOKEY_ASSIGN_OR_RETURN(
        auto members, Members(value, what, {"name", "parent", "offset", "end_sites", "channels"}));
    Joint joint;
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* name, Required(members, value, what, "name"));
    TEMPOKEY_ASSIGN_OR_RETURN(joint.name, String(*name, what + " name"));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* parent, Required(members, value, what, "parent"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t parent_index, Integer(*parent, what + " parent"));
    joint.parent = static_cast<int>(std::clamp<std::int64_t>(parent_index, -2, 1 << 30));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* offset, Required(members, value, what, "offset"));
    TEMPOKEY_ASSIGN_OR_RETURN(joint.offset, Vector(*offset, what + " offset"));
    if (auto it = members.find("end_sites"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* sites, ArrayOf(*it->second, what + " end_sites"));
      for (const JsonValue& site : *sites) {
        TEMPOKEY_ASSIGN_OR_RETURN(Vec3 v, Vector(site, what + " end site"));
        joint.end_sites.push_back(v);
      }
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* channels, Required(members, value, what, "channels"));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* list, ArrayOf(*channels, what + " channels"));
    for (const JsonValue& item : *list) {
      TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t c, Integer(item, what + " channel index"));
      joint.channels.push_back(static_cast<int>(std::clamp<std::int64_t>(c, -1, 1 << 30)));
    }
    return joint;
  }

  absl::StatusOr<Key> DecodeKey(const JsonValue& value, const std::string& what) {
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* fields, ArrayOf(value, what));
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

  absl::Status DecodeChannel(const JsonValue& value, std::size_t index, KeyedClip& keyed) {
    const std::string what = absl::StrCat("channel ", index);
    TEMPOKEY_ASSIGN_OR_RETURN(auto members,
                              Members(value, what, {"joint", "kind", "name", "keys"}));
    Channel channel;
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* joint, Required(members, value, what, "joint"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t joint_index, Integer(*joint, what + " joint"));
    channel.joint = static_cast<int>(std::clamp<std::int64_t>(joint_index, -2, 1 << 30));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* kind, Required(members, value, what, "kind"));
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
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* keys, Required(members, value, what, "keys"));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* list, ArrayOf(*keys, what + " keys"));
    Curve curve;
    for (std::size_t k = 0; k < list->size(); ++k) {
      TEMPOKEY_ASSIGN_OR_RETURN(Key key, DecodeKey((*list)[k], absl::StrCat(what, " key ", k)));
      curve.keys.push_back(key);
    }
    keyed.layout.channels.push_back(std::move(channel));
    keyed.curves.push_back(std::move(curve));
    return absl::OkStatus();
  }

  absl::StatusOr<KeyedClip> Decode(const JsonValue& root) {
    const std::string what = "keyed clip";
    TEMPOKEY_ASSIGN_OR_RETURN(
        auto members, Members(root, what, {"format", "version", "name", "frame_time_seconds",
                                           "frame_count", "joints", "channels", "markers"}));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* format, Required(members, root, what, "format"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::string format_name, String(*format, "format"));
    if (format_name != kFormatName) {
      return Fail(*format, absl::StrCat("format must be \"", AsAbsl(kFormatName), "\", got \"",
                                        format_name, "\""));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* version, Required(members, root, what, "version"));
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t version_number, Integer(*version, "version"));
    if (version_number != 1) {
      return Fail(*version, absl::StrCat("version ", version_number, " is not supported (1 is)"));
    }
    KeyedClip keyed;
    if (auto it = members.find("name"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(keyed.layout.name, String(*it->second, "name"));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* frame_time,
                              Required(members, root, what, "frame_time_seconds"));
    TEMPOKEY_ASSIGN_OR_RETURN(keyed.layout.frame_time_seconds,
                              Number(*frame_time, "frame_time_seconds"));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* frame_count,
                              Required(members, root, what, "frame_count"));
    TEMPOKEY_ASSIGN_OR_RETURN(keyed.layout.frame_count, Integer(*frame_count, "frame_count"));
    if (auto it = members.find("joints"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* joints, ArrayOf(*it->second, "joints"));
      for (std::size_t j = 0; j < joints->size(); ++j) {
        TEMPOKEY_ASSIGN_OR_RETURN(Joint joint, DecodeJoint((*joints)[j], j));
        keyed.layout.skeleton.joints.push_back(std::move(joint));
      }
    }
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* channels, Required(members, root, what, "channels"));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* list, ArrayOf(*channels, "channels"));
    for (std::size_t c = 0; c < list->size(); ++c) {
      TEMPOKEY_RETURN_IF_ERROR(DecodeChannel((*list)[c], c, keyed));
    }
    if (auto it = members.find("markers"); it != members.end()) {
      TEMPOKEY_ASSIGN_OR_RETURN(const JsonArray* markers, ArrayOf(*it->second, "markers"));
      for (std::size_t m = 0; m < markers->size(); ++m) {
        const std::string marker_what = absl::StrCat("marker ", m);
        const JsonValue& item = (*markers)[m];
        TEMPOKEY_ASSIGN_OR_RETURN(
            auto fields, Members(item, marker_what, {"name", "time_seconds", "duration_seconds"}));
        Marker marker;
        TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* name, Required(fields, item, marker_what, "name"));
        TEMPOKEY_ASSIGN_OR_RETURN(marker.name, String(*name, marker_what + " name"));
        TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* time,
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
  AppendJsonString(out, layout.name);
  out += ",\n  \"frame_time_seconds\": ";
  AppendDouble(out, layout.frame_time_seconds);
  out += ",\n  \"frame_count\": ";
  out += std::to_string(layout.frame_count);
  out += ",\n  \"joints\": [";
  for (std::size_t j = 0; j < layout.skeleton.joints.size(); ++j) {
    const Joint& joint = layout.skeleton.joints[j];
    out += j == 0 ? "\n    " : ",\n    ";
    out += "{\"name\": ";
    AppendJsonString(out, joint.name);
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
    AppendJsonString(out, ChannelKindName(channel.kind));
    out += ", \"name\": ";
    AppendJsonString(out, channel.name);
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
    AppendJsonString(out, marker.name);
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
  TEMPOKEY_ASSIGN_OR_RETURN(JsonValue root, ParseJson(text, source_name));
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
