#include "client/json_members.h"

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {

using core::AsAbsl;
using core::JsonValue;

absl::StatusOr<const JsonValue*> JsonMember(const JsonPlace& place, const JsonValue& object,
                                            std::string_view name, JsonValue::Type type,
                                            bool required) {
  const JsonValue* value = object.Find(name);
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

}  // namespace tempokey::client
