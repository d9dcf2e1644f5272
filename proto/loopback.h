// Loopback addresses, as the server's bind checks and the clients' token check see them, and the
// ports of addresses and targets. Pure string and socket-address logic, shared by the server and
// the client library.
#ifndef TEMPOKEY_PROTO_LOOPBACK_H_
#define TEMPOKEY_PROTO_LOOPBACK_H_

#include <string>
#include <string_view>

#include "absl/status/status.h"

struct sockaddr;

namespace tempokey::wire {

// An IPv4 address in 127.0.0.0/8, ::1, or an IPv4-mapped ::ffff:127.0.0.0/104.
bool IsLoopbackSockaddr(const sockaddr* address);

// The host part of "host:port", "[v6]:port" or a bare host (a bare IPv6 address, with several
// colons, is its own host).
std::string HostOf(std::string_view address);

// True when `host` (no port; "[::1]" brackets allowed) is itself a loopback name, without asking
// a resolver: "localhost" in any case, or an IPv4 / IPv6 literal in the loopback ranges above.
// For names a peer sends (an HTTP Host header) and for a client's own target: resolving them
// would let a name pointed at 127.0.0.1 pass (DNS rebinding), or a hosts-file alias stand for
// a machine it is not.
bool IsLoopbackLiteral(std::string_view host);

// True when every address a gRPC channel target names stays on this machine: a unix-domain
// socket ("unix:", "unix-abstract:"), or hosts that are all loopback literals, in the target
// forms of gRPC's name syntax (doc/naming.md: "dns:[//authority/]host[:port]", "ipv4:" and
// "ipv6:" address lists, and a bare "host[:port]", which is dns). Any other scheme (xds, vsock)
// is not known to stay here.
bool IsLoopbackTarget(std::string_view target);

// OK unless an address of `target` (the forms above; a server's listening address "host:port"
// too) has a port of digits that is no TCP port: gRPC takes such a port modulo 65536, so
// 127.0.0.1:99999 reached 127.0.0.1:34463 and a server asked for :70000 listened on 4464.
// InvalidArgument "port 99999 is not a TCP port (0 to 65535)". Other schemes' targets are their
// resolvers' to read.
absl::Status CheckTargetPorts(std::string_view target);

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_LOOPBACK_H_
