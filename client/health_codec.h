// The two grpc.health.v1 messages, encoded by hand. Debian ships no generated health stubs for
// clients, and the messages are tiny: HealthCheckRequest { string service = 1; } and
// HealthCheckResponse { ServingStatus status = 1; }.
#ifndef TEMPOKEY_CLIENT_HEALTH_CODEC_H_
#define TEMPOKEY_CLIENT_HEALTH_CODEC_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace tempokey::client {

// grpc.health.v1.HealthCheckResponse.ServingStatus, same numbers.
enum class HealthState {
  kUnknown = 0,
  kServing = 1,
  kNotServing = 2,
  kServiceUnknown = 3,  // only sent by Watch, listed for completeness
};

// "UNKNOWN", "SERVING", "NOT_SERVING", "SERVICE_UNKNOWN".
std::string_view HealthStateName(HealthState state);

// The full gRPC method name of the unary check.
inline constexpr char kHealthCheckMethod[] = "/grpc.health.v1.Health/Check";

// Protobuf wire bytes of HealthCheckRequest { service: `service` }. Precondition: `service` is
// shorter than 2^28 bytes (service names are short). Thread-safe.
std::string EncodeHealthCheckRequest(std::string_view service);

// Parses HealthCheckResponse wire bytes, skipping unknown fields as protobuf does; a missing
// status field means kUnknown (proto3 default).
// Errors: kInvalidArgument "health response: ..." for truncated or malformed bytes or a status
// value outside 0..3.
absl::StatusOr<HealthState> DecodeHealthCheckResponse(std::string_view bytes);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_HEALTH_CODEC_H_
