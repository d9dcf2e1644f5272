// The pure parts of tls_diagnosis.h: which targets are probed, which messages call for a probe,
// and the sentence each finding makes. The probe against real servers is pinned through the CLI
// in cli_security_test.cc.
#include "client/tls_diagnosis.h"

#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

using Findings = TlsProbeFindings;

MATCHER_P2(IsAddress, host, port, "") {
  return arg.has_value() && arg->host == host && arg->port == port;
}

TEST(TlsDiagnosisTest, SingleAddressOfAcceptsEveryFormOfOneHostAndPort) {
  EXPECT_THAT(SingleAddressOf("localhost:50051"), IsAddress("localhost", 50051));
  EXPECT_THAT(SingleAddressOf("dns:///tempokey.example:443"), IsAddress("tempokey.example", 443));
  EXPECT_THAT(SingleAddressOf("DNS:tempokey.example:443"), IsAddress("tempokey.example", 443));
  EXPECT_THAT(SingleAddressOf("ipv4:127.0.0.1:8080"), IsAddress("127.0.0.1", 8080));
  EXPECT_THAT(SingleAddressOf("ipv6:[::1]:8080"), IsAddress("::1", 8080));
  EXPECT_THAT(SingleAddressOf("[::1]:65535"), IsAddress("::1", 65535));
}

TEST(TlsDiagnosisTest, SingleAddressOfRefusesListsSocketsSchemesAndBadPorts) {
  for (const char* target :
       {"ipv4:127.0.0.1:1,127.0.0.1:2", "unix:/tmp/tempokey.sock", "unix-abstract:tempokey",
        "vsock:3:50051", "xds:///tempokey", "dns://8.8.8.8/tempokey.example:443", "localhost",
        "localhost:", "localhost:0", "localhost:65536", "localhost:+80", "localhost:http", "::1",
        "[::1]", "[::1]8080", ":50051", ""}) {
    EXPECT_EQ(SingleAddressOf(target), std::nullopt) << target;
  }
}

TEST(TlsDiagnosisTest, OnlyMessagesThatMayComeFromTlsSetUpCallForAProbe) {
  EXPECT_TRUE(MayBeTransportSecurityFailure(
      "connections to all backends failing; last error: UNKNOWN: ipv4:127.0.0.1:1: Ssl "
      "handshake failed: SSL_ERROR_SSL: error:0A000086:SSL routines::certificate verify failed"));
  EXPECT_TRUE(MayBeTransportSecurityFailure(
      "connections to all backends failing; last error: UNAVAILABLE: ipv4:127.0.0.1:1: Socket "
      "closed"));
  EXPECT_TRUE(MayBeTransportSecurityFailure("Peer name other.example is not in peer certificate"));
  EXPECT_FALSE(MayBeTransportSecurityFailure(
      "failed to connect to all addresses; last error: UNKNOWN: ipv4:127.0.0.1:1: Failed to "
      "connect to remote host: Connection refused"));
  EXPECT_FALSE(MayBeTransportSecurityFailure("job 42 is still RUNNING: the server ended the "
                                             "watch early"));
  // Words alone are no sign: a local file's error whose path holds them.
  EXPECT_FALSE(MayBeTransportSecurityFailure(
      "/tmp/tls-handshake-certificate/out.bvh: cannot create a temporary file: file name too "
      "long"));
}

// 2026-12-01 00:00 UTC and 2026-12-03 00:00 UTC.
constexpr std::int64_t kDecemberFirst = 1796083200;
constexpr std::int64_t kDecemberThird = kDecemberFirst + 2 * 86400;

Findings CompletedWithCertificate(Findings::Verification verification) {
  Findings findings;
  findings.handshake = Findings::Handshake::kCompleted;
  findings.certificate = Findings::Certificate{.subject = "CN=localhost",
                                               .issuer = "CN=tempokey test CA",
                                               .not_before_unix_seconds = kDecemberFirst,
                                               .not_after_unix_seconds = kDecemberThird,
                                               .names = {"localhost", "127.0.0.1"}};
  findings.verification = verification;
  findings.expected_name = "localhost";
  return findings;
}

// A TLS client with --ca roots.
TlsOptions TlsWithRoots() {
  TlsOptions tls;
  tls.enabled = true;
  tls.root_ca_pem = "PEM";
  return tls;
}

const TlsOptions kTls = TlsWithRoots();

TEST(TlsDiagnosisTest, AnUntrustedCertificateNamesTheRootsTheClientUsed) {
  Findings findings = CompletedWithCertificate(Findings::Verification::kUntrusted);
  findings.verify_error = "unable to get local issuer certificate";
  TlsOptions system_roots;
  system_roots.enabled = true;

  EXPECT_EQ(ExplainTlsProbe(findings, kTls, {.ca = "b.pem", .cert = ""}),
            "the server's certificate (CN=localhost, issued by CN=tempokey test CA, valid "
            "2026-12-01 to 2026-12-03) is not signed by a CA in --ca b.pem (OpenSSL: unable to "
            "get local issuer certificate)");
  EXPECT_THAT(ExplainTlsProbe(findings, system_roots, {}),
              ::testing::HasSubstr("is not signed by a CA in the system's roots"));
}

TEST(TlsDiagnosisTest, ACertificateOutsideItsDatesNamesTheDateItFailsOn) {
  EXPECT_EQ(ExplainTlsProbe(CompletedWithCertificate(Findings::Verification::kExpired), kTls, {}),
            "the server's certificate (CN=localhost, issued by CN=tempokey test CA) expired on "
            "2026-12-03 00:00 UTC");
  EXPECT_EQ(
      ExplainTlsProbe(CompletedWithCertificate(Findings::Verification::kNotYetValid), kTls, {}),
      "the server's certificate (CN=localhost, issued by CN=tempokey test CA) is not valid "
      "before 2026-12-01 00:00 UTC");
}

TEST(TlsDiagnosisTest, ACertificateThatPassesEverythingExplainsNothing) {
  const Findings findings = CompletedWithCertificate(Findings::Verification::kOk);

  EXPECT_EQ(ExplainTlsProbe(findings, kTls, {}), "");
}

TEST(TlsDiagnosisTest, APlaintextClientHearsOnlyWhetherTheServerSpeaksTls) {
  Findings not_tls;
  not_tls.handshake = Findings::Handshake::kNotTls;

  EXPECT_EQ(ExplainTlsProbe(CompletedWithCertificate(Findings::Verification::kUntrusted), {}, {}),
            "the server speaks TLS: connect with --tls (and --ca FILE if a private CA signed its "
            "certificate)");
  EXPECT_EQ(ExplainTlsProbe(not_tls, {}, {}), "");
}

TEST(TlsDiagnosisTest, AClientCertificateIsBlamedOnlyWhenAskedForAndRefused) {
  Findings refused = CompletedWithCertificate(Findings::Verification::kOk);
  refused.client_certificate_requested = true;
  refused.acceptable_client_cas = {"CN=A", "CN=B"};
  refused.after_handshake = Findings::AfterHandshake::kClosed;
  Findings accepted = refused;
  accepted.after_handshake = Findings::AfterHandshake::kAccepted;
  TlsOptions with_certificate = kTls;
  with_certificate.cert_chain_pem = "PEM";

  EXPECT_EQ(ExplainTlsProbe(refused, kTls, {}),
            "the server requires a client certificate (mutual TLS): pass --cert FILE and --key "
            "FILE");
  EXPECT_EQ(ExplainTlsProbe(refused, with_certificate, {.ca = "", .cert = "me.pem"}),
            "the server closed the connection after the handshake: it does not accept the client "
            "certificate in --cert me.pem (it asks for certificates from: CN=A or CN=B)");
  EXPECT_EQ(ExplainTlsProbe(accepted, with_certificate, {.ca = "", .cert = "me.pem"}), "");
}

// A listener that never answers (its backlog takes the connection, nobody reads): the probe
// gives up at its time-out and explains nothing.
TEST(TlsDiagnosisTest, ASilentServerExplainsNothing) {
  const int listener = socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(listener, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t size = sizeof(address);
  ASSERT_EQ(bind(listener, reinterpret_cast<sockaddr*>(&address), size), 0);
  ASSERT_EQ(listen(listener, 4), 0);
  ASSERT_EQ(getsockname(listener, reinterpret_cast<sockaddr*>(&address), &size), 0);
  ClientOptions options;
  options.target = "127.0.0.1:" + std::to_string(ntohs(address.sin_port));
  options.timeout_seconds = 0.2;
  options.tls.enabled = true;

  const std::string explanation =
      DiagnoseConnectionFailure(options, {}, "Ssl handshake failed: SSL_ERROR_SYSCALL");

  EXPECT_EQ(explanation, "");
  close(listener);
}

}  // namespace
}  // namespace tempokey::client
