// Loopback addresses (loopback.h).
#include "proto/loopback.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "tempokey/core/model/status.h"

namespace tempokey::wire {
namespace {

// `text` without `prefix` when it starts with it (case-insensitive, as URI schemes are).
bool Consume(std::string_view& text, std::string_view prefix) {
  if (text.size() < prefix.size() ||
      !absl::EqualsIgnoreCase(core::AsAbsl(text.substr(0, prefix.size())),
                              core::AsAbsl(prefix))) {
    return false;
  }
  text.remove_prefix(prefix.size());
  return true;
}

// The port of "host:port" or "[v6]:port"; empty when the address names none (a bare host, or a
// bare IPv6 address, whose several colons are its own).
std::string_view PortOf(std::string_view address) {
  if (!address.empty() && address.front() == '[') {
    const std::size_t close = address.find(']');
    if (close == std::string_view::npos) return {};
    const std::string_view rest = address.substr(close + 1);
    return rest.starts_with(":") ? rest.substr(1) : std::string_view();
  }
  const std::size_t colon = address.rfind(':');
  if (colon == std::string_view::npos || address.find(':') != colon) return {};
  return address.substr(colon + 1);
}

// A port of digits must be a TCP port. Others (none, a service name) are left to the resolver.
absl::Status CheckPort(std::string_view address) {
  const std::string_view port = PortOf(address);
  if (port.empty() || port.find_first_not_of("0123456789") != std::string_view::npos) {
    return absl::OkStatus();
  }
  std::uint32_t value = 0;  // digits past 2^32 do not parse: not a port either
  if (absl::SimpleAtoi(core::AsAbsl(port), &value) && value <= 65535) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      "port ", core::AsAbsl(port), " is not a TCP port (0 to 65535)"));
}

// What a gRPC channel target names, in gRPC's name syntax (doc/naming.md): a unix-domain socket,
// a list of addresses ("ipv4:", "ipv6:"; "dns:[//authority/]host[:port]" and a bare
// "host[:port]" are one), or something else (another scheme: xds:///name, vsock:...; a dns
// authority without a name).
struct TargetAddresses {
  enum class Kind { kUnixSocket, kAddresses, kOther } kind = Kind::kOther;
  std::vector<std::string_view> addresses;  // kAddresses: each "host[:port]", views of the target
};

TargetAddresses AddressesOf(std::string_view target) {
  using Kind = TargetAddresses::Kind;
  if (Consume(target, "unix:") || Consume(target, "unix-abstract:")) return {Kind::kUnixSocket, {}};
  if (Consume(target, "ipv4:") || Consume(target, "ipv6:")) {
    TargetAddresses list{Kind::kAddresses, {}};
    if (target.empty()) return list;
    for (const absl::string_view address : absl::StrSplit(core::AsAbsl(target), ',')) {
      list.addresses.emplace_back(address.data(), address.size());
    }
    return list;
  }
  if (Consume(target, "dns:")) {
    if (Consume(target, "//")) {  // an authority (the DNS server to ask), then the name
      const std::size_t slash = target.find('/');
      if (slash == std::string_view::npos) return {};
      target.remove_prefix(slash + 1);
    }
  } else if (const std::size_t colon = target.find(':');
             colon != std::string_view::npos && target.substr(colon).starts_with("://")) {
    return {};
  }
  return {Kind::kAddresses, {target}};
}

}  // namespace

absl::Status CheckTargetPorts(std::string_view target) {
  for (std::string_view address : AddressesOf(target).addresses) {
    TEMPOKEY_RETURN_IF_ERROR(CheckPort(address));
  }
  return absl::OkStatus();
}

bool IsLoopbackSockaddr(const sockaddr* address) {
  if (address->sa_family == AF_INET) {
    const auto* v4 = reinterpret_cast<const sockaddr_in*>(address);
    return (ntohl(v4->sin_addr.s_addr) >> 24) == 127;
  }
  if (address->sa_family == AF_INET6) {
    const in6_addr& v6 = reinterpret_cast<const sockaddr_in6*>(address)->sin6_addr;
    if (IN6_IS_ADDR_LOOPBACK(&v6)) return true;
    return IN6_IS_ADDR_V4MAPPED(&v6) && v6.s6_addr[12] == 127;  // ::ffff:127.x.y.z
  }
  return false;
}

std::string HostOf(std::string_view address) {
  if (!address.empty() && address.front() == '[') {
    const std::size_t close = address.find(']');
    return std::string(address.substr(1, close == std::string_view::npos ? address.npos : close - 1));
  }
  const std::size_t colon = address.rfind(':');
  if (colon != std::string_view::npos && address.find(':') == colon) {
    return std::string(address.substr(0, colon));  // "host:port"; a bare IPv6 address has several
  }
  return std::string(address);
}

bool IsLoopbackLiteral(std::string_view host) {
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  const std::string name = absl::AsciiStrToLower(std::string(host));
  if (name == "localhost") return true;
  sockaddr_in v4{};
  if (inet_pton(AF_INET, name.c_str(), &v4.sin_addr) == 1) {
    v4.sin_family = AF_INET;
    return IsLoopbackSockaddr(reinterpret_cast<const sockaddr*>(&v4));
  }
  sockaddr_in6 v6{};
  if (inet_pton(AF_INET6, name.c_str(), &v6.sin6_addr) == 1) {
    v6.sin6_family = AF_INET6;
    return IsLoopbackSockaddr(reinterpret_cast<const sockaddr*>(&v6));
  }
  return false;
}

bool IsLoopbackTarget(std::string_view target) {
  const TargetAddresses named = AddressesOf(target);
  if (named.kind == TargetAddresses::Kind::kUnixSocket) return true;
  return named.kind == TargetAddresses::Kind::kAddresses && !named.addresses.empty() &&
         std::all_of(named.addresses.begin(), named.addresses.end(), [](std::string_view address) {
           const std::string host = HostOf(address);
           return !host.empty() && IsLoopbackLiteral(host);
         });
}

}  // namespace tempokey::wire
