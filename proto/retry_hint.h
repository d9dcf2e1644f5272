// A retry hint carried by an absl::Status (a payload), so a RESOURCE_EXHAUSTED from the job
// queue tells the client how long to wait. On the wire it travels as trailing metadata
// kRetryAfterMetadataKey: the server's ToGrpcStatus() writes it, the client library reads it
// back onto the status it returns, so callers on both sides use GetRetryAfter().
#ifndef TEMPOKEY_PROTO_RETRY_HINT_H_
#define TEMPOKEY_PROTO_RETRY_HINT_H_

#include <chrono>
#include <optional>
#include <string_view>

#include "absl/status/status.h"

namespace tempokey::wire {

// Trailing metadata key of the hint, in whole milliseconds ("retry-after-ms: 250").
inline constexpr char kRetryAfterMetadataKey[] = "retry-after-ms";

// Attaches a retry hint to `status` (no effect on an OK status).
void SetRetryAfter(absl::Status& status, std::chrono::milliseconds delay);
// The hint attached by SetRetryAfter(), if any.
std::optional<std::chrono::milliseconds> GetRetryAfter(const absl::Status& status);
// Parses a metadata value: a non-negative whole number of milliseconds; nullopt otherwise.
std::optional<std::chrono::milliseconds> ParseRetryAfter(std::string_view text);

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_RETRY_HINT_H_
