#include "server/status_util.h"

#include <string>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {

grpc::Status ToGrpcStatus(const absl::Status& status, grpc::ServerContextBase* context) {
  if (status.ok()) return grpc::Status::OK;
  if (context != nullptr) {
    if (std::optional<std::chrono::milliseconds> retry = wire::GetRetryAfter(status)) {
      context->AddTrailingMetadata(wire::kRetryAfterMetadataKey, std::to_string(retry->count()));
    }
  }
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()),
                      CappedStatusMessage(core::AsStd(status.message())));
}

std::string CappedStatusMessage(std::string_view message) {
  if (message.size() <= kMaxStatusMessageBytes) return std::string(message);
  // Cut at the start of a UTF-8 character, never inside one.
  std::size_t cut = kMaxStatusMessageBytes;
  while (cut > 0 && (static_cast<unsigned char>(message[cut]) & 0xC0) == 0x80) --cut;
  return absl::StrCat(core::AsAbsl(message.substr(0, cut)), " ... (", message.size() - cut,
                      " more bytes not shown)");
}

std::string_view OutcomeOf(const absl::Status& status) {
  if (status.ok()) return "succeeded";
  return status.code() == absl::StatusCode::kCancelled ? "cancelled" : "failed";
}

}  // namespace tempokey::server
