// The one place absl::Status becomes grpc::Status.
#ifndef TEMPOKEY_SERVER_STATUS_UTIL_H_
#define TEMPOKEY_SERVER_STATUS_UTIL_H_

#include <string_view>

#include "absl/status/status.h"
#include "grpcpp/server_context.h"
#include "grpcpp/support/status.h"
#include "proto/retry_hint.h"

namespace tempokey::server {

// Same code and message (absl codes are the gRPC codes). When `context` is given and `status`
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
