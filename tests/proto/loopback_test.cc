// Loopback names and gRPC channel targets (proto/loopback.h): what the server's bind checks and
// the clients' refusal to send a token in cleartext take as staying on this machine.
#include "proto/loopback.h"

#include <string>
#include <utility>
#include <vector>

#include "gtest/gtest.h"

namespace tempokey::wire {
namespace {

TEST(IsLoopbackLiteralTest, AcceptsLoopbackNamesWithoutResolvingAnything) {
  for (const char* host : {"localhost", "LOCALHOST", "127.0.0.1", "127.9.8.7", "::1", "[::1]",
                           "::ffff:127.0.0.1", "[::ffff:127.0.0.1]"}) {
    EXPECT_TRUE(IsLoopbackLiteral(host)) << host;
  }
  // A name that resolves to 127.0.0.1 is still not a loopback name (DNS rebinding).
  for (const char* host : {"127.attacker.invalid", "localhost.attacker.invalid", "10.0.0.1",
                           "0.0.0.0", "::", "", "localhost:80"}) {
    EXPECT_FALSE(IsLoopbackLiteral(host)) << host;
  }
}

// Every form of gRPC's name syntax (doc/naming.md) the CLI and the package pass through.
TEST(IsLoopbackTargetTest, EveryAddressOfTheTargetMustStayOnThisMachine) {
  for (const char* target :
       {"127.0.0.1:50051", "localhost:50051", "LOCALHOST", "[::1]:50051", "::1",
        "dns:///localhost:50051", "dns:localhost:50051", "dns://8.8.8.8/127.0.0.1:50051",
        "ipv4:127.0.0.1:50051,127.0.0.2:50052", "ipv6:[::1]:50051", "unix:/run/tempokey.sock",
        "unix:///run/tempokey.sock", "unix-abstract:tempokey", "UNIX:/run/tempokey.sock"}) {
    EXPECT_TRUE(IsLoopbackTarget(target)) << target;
  }
  for (const char* target :
       {"10.0.0.1:50051", "tempokey.example.com:50051", "dns:///tempokey.svc:50051",
        "ipv4:127.0.0.1:50051,10.0.0.2:50051", "ipv4:", "ipv6:[2001:db8::1]:50051",
        "dns://127.0.0.1/example.com:50051", "dns://127.0.0.1", "xds:///tempokey",
        "vsock:3:50051", "127.attacker.invalid:50051", ":50051", ""}) {
    EXPECT_FALSE(IsLoopbackTarget(target)) << target;
  }
}

// gRPC takes a port modulo 65536 (127.0.0.1:99999 reached :34463, a server asked for :70000
// listened on :4464): a port of digits past 65535 is refused in every form of target.
TEST(CheckTargetPortsTest, APortPast65535IsRefusedInEveryFormOfTarget) {
  for (const char* target :
       {"127.0.0.1:50051", "127.0.0.1:65535", "127.0.0.1:0", "127.0.0.1:000065535", "localhost",
        "[::1]:443", "::1", "2001:db8::1", "dns:///localhost:50051", "dns://8.8.8.8/host:1",
        "ipv4:127.0.0.1:1,127.0.0.2:2", "ipv6:[::1]:65535", "unix:/run/tempokey.sock:99999",
        "xds:///tempokey:99999", "example.com:https", ""}) {
    EXPECT_TRUE(CheckTargetPorts(target).ok()) << target;
  }
  for (const auto& [target, port] : std::vector<std::pair<const char*, const char*>>{
           {"127.0.0.1:65536", "65536"}, {"127.0.0.1:99999", "99999"},
           {"localhost:4294967346", "4294967346"}, {"[::1]:70000", "70000"},
           {"dns:///localhost:100000", "100000"}, {"dns://8.8.8.8/host:65536", "65536"},
           {"ipv4:127.0.0.1:1,127.0.0.2:65537", "65537"}, {"ipv6:[::1]:1,[::1]:99999", "99999"},
           {"host:0000070000", "0000070000"}}) {
    const absl::Status status = CheckTargetPorts(target);
    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << target;
    EXPECT_EQ(status.message(), std::string("port ") + port + " is not a TCP port (0 to 65535)")
        << target;
  }
}

}  // namespace
}  // namespace tempokey::wire
