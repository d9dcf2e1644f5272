#include "server/service_context.h"

#include <openssl/crypto.h>

#include <string_view>

#include "absl/strings/str_cat.h"

namespace tempokey::server {
namespace {

bool ConstantTimeEquals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  return CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

}  // namespace

absl::Status ServiceContext::CheckAuth(const grpc::CallbackServerContext& context) const {
  if (options.auth_tokens.empty()) return absl::OkStatus();
  const auto& metadata = context.client_metadata();
  auto it = metadata.find("authorization");
  if (it == metadata.end()) {
    return absl::UnauthenticatedError("missing \"authorization: Bearer <token>\" metadata");
  }
  const std::string_view value(it->second.data(), it->second.size());
  constexpr std::string_view kBearer = "Bearer ";
  if (value.size() <= kBearer.size() || value.substr(0, kBearer.size()) != kBearer) {
    return absl::UnauthenticatedError("authorization metadata is not \"Bearer <token>\"");
  }
  const std::string_view token = value.substr(kBearer.size());
  bool accepted = false;
  for (const std::string& known : options.auth_tokens) accepted |= ConstantTimeEquals(token, known);
  if (!accepted) return absl::UnauthenticatedError("the bearer token is not accepted");
  return absl::OkStatus();
}

bool ServiceContext::TryOpenStream() {
  int open = open_streams.load(std::memory_order_relaxed);
  do {
    if (open >= options.max_concurrent_streams) return false;
  } while (!open_streams.compare_exchange_weak(open, open + 1, std::memory_order_acq_rel));
  return true;
}

void ServiceContext::CloseStream() { open_streams.fetch_sub(1, std::memory_order_acq_rel); }

absl::Status ServiceContext::AdmitStream(bool allow_while_draining) {
  if (!allow_while_draining && draining.load()) return absl::UnavailableError("the server is shutting down");
  if (!TryOpenStream()) {
    return absl::ResourceExhaustedError(
        absl::StrCat("too many streaming calls open (limit ", options.max_concurrent_streams,
                     "); retry later"));
  }
  return absl::OkStatus();
}

}  // namespace tempokey::server
