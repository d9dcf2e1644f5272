#include "client/json_members.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {

using core::AsAbsl;
using core::JsonValue;

absl::StatusOr<const JsonValue*> JsonMember(const JsonPlace& place, const JsonValue& object,
                                            std::string_view name, JsonValue::Type type,
                                            bool required) {
  const JsonValue* value = nullptr;
  if (object.type == JsonValue::Type::kObject) {
    for (const auto& [member, member_value] : *object.object) {
      if (member != name) continue;
      if (value != nullptr) {
        return place.Fail(member_value, absl::StrCat("\"", AsAbsl(name), "\" given twice"));
      }
      value = &member_value;
    }
  }
  if (value == nullptr) {
    if (!required) return nullptr;
    return place.Fail(object, absl::StrCat("missing \"", AsAbsl(name), "\""));
  }
  if (value->type != type) {
    static constexpr std::string_view kTypeNames[] = {"null",     "true or false", "a number",
                                                      "a string", "an array",      "an object"};
    return place.Fail(*value, absl::StrCat("\"", AsAbsl(name), "\" must be ",
                                           AsAbsl(kTypeNames[static_cast<int>(type)])));
  }
  return value;
}

absl::StatusOr<std::int64_t> JsonCount(const JsonPlace& place, const JsonValue& object,
                                       std::string_view name, std::int64_t max) {
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* value,
                            JsonMember(place, object, name, JsonValue::Type::kNumber, false));
  if (value == nullptr) return 0;
  // Compared as doubles before any conversion: a cast of 1e300 to an integer is undefined.
  if (!(value->number >= 0 && value->number <= static_cast<double>(max) &&
        value->number == std::floor(value->number))) {
    return place.Fail(*value, absl::StrCat("\"", AsAbsl(name),
                                           "\" must be a whole number from 0 to ", max));
  }
  return static_cast<std::int64_t>(value->number);
}

absl::StatusOr<std::optional<double>> JsonNonNegative(const JsonPlace& place,
                                                      const JsonValue& object,
                                                      std::string_view name) {
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* value,
                            JsonMember(place, object, name, JsonValue::Type::kNumber, false));
  if (value == nullptr) return std::optional<double>();
  if (!(value->number >= 0)) {
    return place.Fail(*value, absl::StrCat("\"", AsAbsl(name), "\" must be >= 0"));
  }
  return std::optional<double>(value->number);
}

}  // namespace tempokey::client
