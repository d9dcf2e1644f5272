// Loopback addresses (loopback.h).
#include "proto/loopback.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <algorithm>
#include <string>
#include <string_view>
#include <vector>

#include "absl/strings/ascii.h"
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
  const std::string_view significant =
      port.substr(std::min(port.find_first_not_of('0'), port.size()));
  if (significant.size() <= 5) {
    int value = 0;
    for (char c : significant) value = value * 10 + (c - '0');
    if (value <= 65535) return absl::OkStatus();
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "port ", core::AsAbsl(port), " is not a TCP port (0 to 65535)"));
}

}  // namespace

absl::Status CheckTargetPorts(std::string_view target) {
  if (Consume(target, "unix:") || Consume(target, "unix-abstract:")) return absl::OkStatus();
  if (Consume(target, "ipv4:") || Consume(target, "ipv6:")) {
    for (const absl::string_view address : absl::StrSplit(core::AsAbsl(target), ',')) {
      TEMPOKEY_RETURN_IF_ERROR(CheckPort(std::string_view(address.data(), address.size())));
    }
    return absl::OkStatus();
  }
  if (Consume(target, "dns:")) {
    if (Consume(target, "//")) {  // an authority (the DNS server to ask), then the name
      const std::size_t slash = target.find('/');
      if (slash == std::string_view::npos) return absl::OkStatus();
      target.remove_prefix(slash + 1);
    }
  } else if (const std::size_t colon = target.find(':');
             colon != std::string_view::npos && target.substr(colon).starts_with("://")) {
    return absl::OkStatus();  // another scheme's syntax (xds:///name, ...): its own resolver's
  }
  return CheckPort(target);
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
  if (Consume(target, "unix:") || Consume(target, "unix-abstract:")) return true;
  if (Consume(target, "ipv4:") || Consume(target, "ipv6:")) {
    if (target.empty()) return false;
    for (const absl::string_view address : absl::StrSplit(core::AsAbsl(target), ',')) {
      if (!IsLoopbackLiteral(HostOf(std::string_view(address.data(), address.size())))) {
        return false;
      }
    }
    return true;
  }
  if (Consume(target, "dns:")) {
    if (Consume(target, "//")) {  // an authority (the DNS server to ask), then the name
      const std::size_t slash = target.find('/');
      if (slash == std::string_view::npos) return false;
      target.remove_prefix(slash + 1);
    }
  } else if (const std::size_t colon = target.find(':');
             colon != std::string_view::npos && target.substr(colon).starts_with("://")) {
    return false;  // another scheme with an authority: xds:///name, ...
  }
  const std::string host = HostOf(target);
  return !host.empty() && IsLoopbackLiteral(host);
}

}  // namespace tempokey::wire
