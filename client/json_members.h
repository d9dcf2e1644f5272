// Reading tempokey's own JSON records (batch manifests, batch summaries): a place that names the
// document in every refusal, and a member looked up by name and type. The messages point at the
// value refused, "out/.tempokey-batch.json:4:12: \"frames\" must be a number".
#ifndef TEMPOKEY_CLIENT_JSON_MEMBERS_H_
#define TEMPOKEY_CLIENT_JSON_MEMBERS_H_

#include <cstdint>
#include <optional>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/io/json.h"

namespace tempokey::client {

// The document a value came from; Fail() locates a refusal at the value (core::JsonErrorAt()).
class JsonPlace {
 public:
  explicit JsonPlace(std::string_view source) : source_(source) {}

  absl::Status Fail(const core::JsonValue& at, std::string_view what) const {
    return core::JsonErrorAt(source_, at, what);
  }

 private:
  std::string_view source_;
};

// The member `name` of `object`, which must have `type`; nullptr when absent and not `required`.
// A name given twice is refused (a reader taking the first would silently drop the second).
// Errors: kInvalidArgument "...: missing \"name\"", "...: \"name\" must be a string",
// "...: \"name\" given twice" (at the second).
absl::StatusOr<const core::JsonValue*> JsonMember(const JsonPlace& place,
                                                  const core::JsonValue& object,
                                                  std::string_view name,
                                                  core::JsonValue::Type type, bool required);

// An optional whole number in [0, max] (0 when absent), e.g. a count of frames or attempts.
// Errors: those of JsonMember(); kInvalidArgument "...: \"frames\" must be a whole number from
// 0 to 9007199254740992".
absl::StatusOr<std::int64_t> JsonCount(const JsonPlace& place, const core::JsonValue& object,
                                       std::string_view name,
                                       std::int64_t max = std::int64_t{1} << 53);

// An optional number >= 0 (nullopt when absent), e.g. seconds or an error.
// Errors: those of JsonMember(); kInvalidArgument "...: \"seconds\" must be >= 0".
absl::StatusOr<std::optional<double>> JsonNonNegative(const JsonPlace& place,
                                                      const core::JsonValue& object,
                                                      std::string_view name);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_JSON_MEMBERS_H_
