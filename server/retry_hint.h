// A retry hint carried by an absl::Status (a payload), so a RESOURCE_EXHAUSTED from the job
// queue tells the client how long to wait. ToGrpcStatus() turns it into trailing metadata.
#ifndef TEMPOKEY_SERVER_RETRY_HINT_H_
#define TEMPOKEY_SERVER_RETRY_HINT_H_

#include <chrono>
#include <optional>

#include "absl/status/status.h"

namespace tempokey::server {

// Attaches a retry hint to `status` (no effect on an OK status).
void SetRetryAfter(absl::Status& status, std::chrono::milliseconds delay);
// The hint attached by SetRetryAfter(), if any.
std::optional<std::chrono::milliseconds> GetRetryAfter(const absl::Status& status);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_RETRY_HINT_H_
