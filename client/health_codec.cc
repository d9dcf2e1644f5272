#include "client/health_codec.h"

#include <cstdint>
#include <optional>

#include "absl/strings/str_cat.h"

namespace tempokey::client {
namespace {

constexpr int kVarint = 0;
constexpr int kFixed64 = 1;
constexpr int kLengthDelimited = 2;
constexpr int kFixed32 = 5;

void AppendVarint(std::uint64_t value, std::string& out) {
  while (value >= 0x80) {
    out.push_back(static_cast<char>((value & 0x7f) | 0x80));
    value >>= 7;
  }
  out.push_back(static_cast<char>(value));
}

// Reads a varint at `pos`, advancing it; nullopt when truncated or longer than 10 bytes.
std::optional<std::uint64_t> ReadVarint(std::string_view bytes, std::size_t& pos) {
  std::uint64_t value = 0;
  for (int shift = 0; shift < 70 && pos < bytes.size(); shift += 7) {
    const auto byte = static_cast<std::uint8_t>(bytes[pos++]);
    value |= static_cast<std::uint64_t>(byte & 0x7f) << shift;
    if ((byte & 0x80) == 0) return value;
  }
  return std::nullopt;
}

absl::Status Malformed(std::string_view what) {
  return absl::InvalidArgumentError(
      absl::StrCat("health response: ", absl::string_view(what.data(), what.size())));
}

}  // namespace

std::string_view HealthStateName(HealthState state) {
  switch (state) {
    case HealthState::kUnknown: return "UNKNOWN";
    case HealthState::kServing: return "SERVING";
    case HealthState::kNotServing: return "NOT_SERVING";
    case HealthState::kServiceUnknown: return "SERVICE_UNKNOWN";
  }
  return "UNKNOWN";
}

std::string EncodeHealthCheckRequest(std::string_view service) {
  std::string out;
  if (service.empty()) return out;  // proto3 omits default values
  AppendVarint((1 << 3) | kLengthDelimited, out);
  AppendVarint(service.size(), out);
  out.append(service);
  return out;
}

absl::StatusOr<HealthState> DecodeHealthCheckResponse(std::string_view bytes) {
  std::uint64_t status = 0;
  std::size_t pos = 0;
  while (pos < bytes.size()) {
    const std::optional<std::uint64_t> tag = ReadVarint(bytes, pos);
    if (!tag) return Malformed("truncated field tag");
    const std::uint64_t field = *tag >> 3;
    const int wire_type = static_cast<int>(*tag & 7);
    if (field == 0) return Malformed("field number 0");
    switch (wire_type) {
      case kVarint: {
        const std::optional<std::uint64_t> value = ReadVarint(bytes, pos);
        if (!value) return Malformed("truncated varint");
        if (field == 1) status = *value;  // the last occurrence wins, as in protobuf
        break;
      }
      case kFixed64:
      case kFixed32: {
        const std::size_t size = wire_type == kFixed64 ? 8 : 4;
        if (bytes.size() - pos < size) return Malformed("truncated fixed-width field");
        pos += size;
        break;
      }
      case kLengthDelimited: {
        const std::optional<std::uint64_t> size = ReadVarint(bytes, pos);
        if (!size || *size > bytes.size() - pos) return Malformed("truncated length-delimited field");
        pos += static_cast<std::size_t>(*size);
        break;
      }
      default:
        return Malformed(absl::StrCat("unsupported wire type ", wire_type));
    }
  }
  if (status > 3) return Malformed(absl::StrCat("serving status ", status, " is not 0..3"));
  return static_cast<HealthState>(status);
}

}  // namespace tempokey::client
