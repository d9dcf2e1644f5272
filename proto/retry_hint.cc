#include "proto/retry_hint.h"

#include <cstdint>
#include <string>

#include "absl/strings/cord.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/types/optional.h"

namespace tempokey::wire {
namespace {

constexpr char kRetryAfterPayload[] = "tempokey/retry-after-ms";

}  // namespace

void SetRetryAfter(absl::Status& status, std::chrono::milliseconds delay) {
  status.SetPayload(kRetryAfterPayload, absl::Cord(absl::StrCat(delay.count())));
}

std::optional<std::chrono::milliseconds> GetRetryAfter(const absl::Status& status) {
  absl::optional<absl::Cord> payload = status.GetPayload(kRetryAfterPayload);
  if (!payload) return std::nullopt;
  return ParseRetryAfter(std::string(*payload));
}

std::optional<std::chrono::milliseconds> ParseRetryAfter(std::string_view text) {
  std::int64_t ms = 0;
  if (!absl::SimpleAtoi(absl::string_view(text.data(), text.size()), &ms) || ms < 0) {
    return std::nullopt;
  }
  return std::chrono::milliseconds(ms);
}

}  // namespace tempokey::wire
