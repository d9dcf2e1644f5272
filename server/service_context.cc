#include "server/service_context.h"

#include <openssl/crypto.h>
#include <openssl/sha.h>

#include <string_view>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "proto/retry_hint.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

bool ConstantTimeEquals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  return CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

}  // namespace

std::string OwnerIdOfToken(std::string_view token) {
  unsigned char digest[SHA256_DIGEST_LENGTH];
  SHA256(reinterpret_cast<const unsigned char*>(token.data()), token.size(), digest);
  std::string id = "token-";
  for (int i = 0; i < 8; ++i) absl::StrAppend(&id, absl::Hex(digest[i], absl::kZeroPad2));
  return id;
}

namespace {

// The owner id of `value` ("Bearer <token>"), or why it is refused.
absl::StatusOr<std::string> MatchBearer(const ServiceContext& service, std::string_view value) {
  // The scheme's name is case-insensitive (RFC 9110, 11.1): "bearer x" is "Bearer x".
  constexpr std::string_view kBearer = "Bearer ";
  if (value.size() <= kBearer.size() ||
      !absl::EqualsIgnoreCase(core::AsAbsl(value.substr(0, kBearer.size())), "bearer ")) {
    return absl::UnauthenticatedError("authorization is not \"Bearer <token>\"");
  }
  const std::string_view token = value.substr(kBearer.size());
  // Every token is compared, so the time taken does not say which one matched.
  int match = -1;
  for (std::size_t i = 0; i < service.options.auth_tokens.size(); ++i) {
    if (ConstantTimeEquals(token, service.options.auth_tokens[i]) && match < 0) {
      match = static_cast<int>(i);
    }
  }
  if (match < 0) return absl::UnauthenticatedError("the bearer token is not accepted");
  return service.owner_ids[static_cast<std::size_t>(match)];
}

}  // namespace

absl::StatusOr<std::string> ServiceContext::Authenticate(
    const grpc::ServerContextBase& context) const {
  if (options.auth_tokens.empty()) return std::string();
  const auto& metadata = context.client_metadata();
  auto it = metadata.find("authorization");
  if (it == metadata.end()) {
    return absl::UnauthenticatedError("missing \"authorization: Bearer <token>\" metadata");
  }
  return MatchBearer(*this, std::string_view(it->second.data(), it->second.size()));
}

absl::Status ServiceContext::CheckBearer(const char* header) const {
  if (options.auth_tokens.empty()) return absl::OkStatus();
  if (header == nullptr) {
    return absl::UnauthenticatedError("missing \"Authorization: Bearer <token>\" header");
  }
  return MatchBearer(*this, header).status();
}

bool ServiceContext::TryOpenStream() {
  int open = open_streams.load(std::memory_order_relaxed);
  do {
    if (open >= options.max_concurrent_streams) return false;
  } while (!open_streams.compare_exchange_weak(open, open + 1, std::memory_order_acq_rel));
  return true;
}

absl::Status StreamSlot::Claim(ServiceContext& service, bool allow_while_draining) {
  TEMPOKEY_RETURN_IF_ERROR(service.AdmitStream(allow_while_draining));
  service_.store(&service);
  return absl::OkStatus();
}

void StreamSlot::Release() {
  if (ServiceContext* service = service_.exchange(nullptr)) service->CloseStream();
}

void ServiceContext::CloseStream() { open_streams.fetch_sub(1, std::memory_order_acq_rel); }

absl::Status ServiceContext::AdmitStream(bool allow_while_draining) {
  if (!allow_while_draining && draining.load()) return absl::UnavailableError("the server is shutting down");
  if (!TryOpenStream()) {
    absl::Status refused = absl::ResourceExhaustedError(
        absl::StrCat("too many streaming calls open (limit ", options.max_concurrent_streams,
                     "); retry later"));
    wire::SetRetryAfter(refused, kStreamRetryAfter);
    return refused;
  }
  return absl::OkStatus();
}

}  // namespace tempokey::server
