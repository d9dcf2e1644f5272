// The one place absl::Status becomes grpc::Status.
#ifndef TEMPOKEY_SERVER_STATUS_UTIL_H_
#define TEMPOKEY_SERVER_STATUS_UTIL_H_

#include <cstddef>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "grpcpp/server_context.h"
#include "grpcpp/support/status.h"
#include "proto/retry_hint.h"

namespace tempokey::server {

// Messages sent to clients are at most this long (plus a note of what was cut): a status travels
// in a header, percent-encoded (up to 3 bytes a byte), and gRPC clients refuse headers over 8 KiB
// by default, so a message quoting a long input (a 100 KB page token or channel name) reached
// them as "received initial metadata size exceeds limit" instead of the server's message.
inline constexpr std::size_t kMaxStatusMessageBytes = 2048;

// `message`, cut to kMaxStatusMessageBytes at a UTF-8 character boundary, with " ... (N more
// bytes not shown)" when cut.
std::string CappedStatusMessage(std::string_view message);

// Same code and message (absl codes are the gRPC codes; the message capped by
// CappedStatusMessage()). When `context` is given and `status`
// carries a retry hint (wire::SetRetryAfter()), adds it as trailing metadata
// wire::kRetryAfterMetadataKey.
// Call before the call is finished.
grpc::Status ToGrpcStatus(const absl::Status& status,
                          grpc::ServerContextBase* context = nullptr);

// How a Process call or an export ended, for its log line and the jobs metrics: "succeeded",
// "cancelled" (kCancelled) or "failed".
std::string_view OutcomeOf(const absl::Status& status);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_STATUS_UTIL_H_
