#include "server/status_util.h"

#include <string>

namespace tempokey::server {

grpc::Status ToGrpcStatus(const absl::Status& status, grpc::ServerContextBase* context) {
  if (status.ok()) return grpc::Status::OK;
  if (context != nullptr) {
    if (std::optional<std::chrono::milliseconds> retry = wire::GetRetryAfter(status)) {
      context->AddTrailingMetadata(wire::kRetryAfterMetadataKey, std::to_string(retry->count()));
    }
  }
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), std::string(status.message()));
}

std::string_view OutcomeOf(const absl::Status& status) {
  if (status.ok()) return "succeeded";
  return status.code() == absl::StatusCode::kCancelled ? "cancelled" : "failed";
}

}  // namespace tempokey::server
