// Loopback names and gRPC channel targets (proto/loopback.h): what the server's bind checks and
// the clients' refusal to send a token in cleartext take as staying on this machine.
#include "proto/loopback.h"

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

}  // namespace
}  // namespace tempokey::wire
