// The `tempokey` binary against real servers with TLS, mutual TLS and bearer tokens. The test
// certificates are made for each test by the openssl command-line tool (installed by
// deploy/install-deps.sh) in the test's temporary directory.
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "client/client.h"
#include "client/tls_diagnosis.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::EndsWith;
using ::testing::StartsWith;

constexpr char kOpenssl[] = "/usr/bin/openssl";

// A CA, a server certificate for localhost / 127.0.0.1 and a client certificate, all signed by
// the CA, as PEM files in `dir`: ca.pem, server.pem + server.key, client.pem + client.key.
::testing::AssertionResult MakeCertificates(const std::string& dir) {
  if (!core::WriteFileAtomically(dir + "/server.ext", "subjectAltName=DNS:localhost,IP:127.0.0.1\n").ok() ||
      !core::WriteFileAtomically(dir + "/client.ext", "extendedKeyUsage=clientAuth\n").ok()) {
    return ::testing::AssertionFailure() << "cannot write the extension files";
  }
  const std::vector<std::string> ec = {"-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
                                       "-nodes"};
  std::vector<std::vector<std::string>> commands;
  std::vector<std::string> ca = {kOpenssl, "req", "-x509"};
  ca.insert(ca.end(), ec.begin(), ec.end());
  ca.insert(ca.end(), {"-keyout", dir + "/ca.key", "-out", dir + "/ca.pem", "-days", "2", "-subj",
                       "/CN=tempokey test CA"});
  commands.push_back(ca);
  for (const std::string name : {"server", "client"}) {
    std::vector<std::string> request = {kOpenssl, "req"};
    request.insert(request.end(), ec.begin(), ec.end());
    request.insert(request.end(), {"-keyout", dir + "/" + name + ".key", "-out",
                                   dir + "/" + name + ".csr", "-subj",
                                   name == "server" ? "/CN=localhost" : "/CN=tempokey client"});
    commands.push_back(request);
    commands.push_back({kOpenssl, "x509", "-req", "-in", dir + "/" + name + ".csr", "-CA",
                        dir + "/ca.pem", "-CAkey", dir + "/ca.key", "-set_serial",
                        name == "server" ? "1" : "2", "-days", "2", "-out", dir + "/" + name + ".pem",
                        "-extfile", dir + "/" + name + ".ext"});
  }
  for (const std::vector<std::string>& command : commands) {
    ProcessResult run = RunProcess(command, dir);
    if (run.exit_code != 0) {
      return ::testing::AssertionFailure() << "openssl " << command[1] << " failed: " << run.err;
    }
  }
  return ::testing::AssertionSuccess();
}

// Runs each openssl command in `dir`.
::testing::AssertionResult RunOpenssl(const std::string& dir,
                                      const std::vector<std::vector<std::string>>& commands) {
  for (std::vector<std::string> command : commands) {
    command.insert(command.begin(), kOpenssl);
    ProcessResult run = RunProcess(command, dir);
    if (run.exit_code != 0) {
      return ::testing::AssertionFailure() << "openssl " << command[1] << " failed: " << run.err;
    }
  }
  return ::testing::AssertionSuccess();
}

// A certificate for localhost / 127.0.0.1, `name`.pem + `name`.key in `dir`, valid from `start` to
// `end` (openssl's YYYYMMDDHHMMSSZ), signed by the CA `issuer` (ca for ca.pem + ca.key, as
// MakeCertificates() leaves them) or, with an empty `issuer`, by itself. Fixed dates make the
// explanations exact; `openssl ca` is the tool of OpenSSL 3.0 that takes them.
::testing::AssertionResult MakeCertificateWithDates(const std::string& dir, const std::string& name,
                                                    const std::string& issuer,
                                                    const std::string& start,
                                                    const std::string& end) {
  const std::string config = "[ca]\ndefault_ca = test_ca\n[test_ca]\ndatabase = " + dir +
                             "/index.txt\nnew_certs_dir = " + dir + "\nserial = " + dir +
                             "/serial\ndefault_md = sha256\npolicy = any_name\nunique_subject = "
                             "no\n[any_name]\ncommonName = supplied\n";
  if (!core::WriteFileAtomically(dir + "/ca.cnf", config).ok() ||
      !core::WriteFileAtomically(dir + "/index.txt", "").ok() ||
      !core::WriteFileAtomically(dir + "/serial", "1000\n").ok() ||
      !core::WriteFileAtomically(dir + "/" + name + ".ext",
                                 "subjectAltName=DNS:localhost,IP:127.0.0.1\n")
           .ok()) {
    return ::testing::AssertionFailure() << "cannot write the openssl ca files";
  }
  std::vector<std::string> sign = {"ca", "-batch", "-notext", "-config", dir + "/ca.cnf", "-in",
                                   dir + "/" + name + ".csr", "-out", dir + "/" + name + ".pem",
                                   "-startdate", start, "-enddate", end, "-extfile",
                                   dir + "/" + name + ".ext"};
  if (issuer.empty()) {
    sign.insert(sign.end(), {"-selfsign", "-keyfile", dir + "/" + name + ".key"});
  } else {
    sign.insert(sign.end(), {"-cert", dir + "/" + issuer + ".pem", "-keyfile",
                             dir + "/" + issuer + ".key"});
  }
  return RunOpenssl(dir, {{"req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1",
                           "-nodes", "-keyout", dir + "/" + name + ".key", "-out",
                           dir + "/" + name + ".csr", "-subj", "/CN=localhost"},
                          sign});
}

// A second CA, "CN=other CA" (other-ca.pem + other-ca.key), and a client certificate it signed
// for the key of MakeCertificates()'s client (stranger.pem, with client.key).
::testing::AssertionResult MakeOtherCaAndItsClient(const std::string& dir) {
  return RunOpenssl(
      dir, {{"req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
             "-keyout", dir + "/other-ca.key", "-out", dir + "/other-ca.pem", "-days", "2", "-subj",
             "/CN=other CA"},
            {"x509", "-req", "-in", dir + "/client.csr", "-CA", dir + "/other-ca.pem", "-CAkey",
             dir + "/other-ca.key", "-set_serial", "3", "-days", "2", "-out",
             dir + "/stranger.pem", "-extfile", dir + "/client.ext"}});
}

class CliSecurityTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = MakeTempDir();
    struct stat info;
    ASSERT_EQ(stat(kOpenssl, &info), 0) << "needs " << kOpenssl << " (deploy/install-deps.sh)";
  }

  void StartServer(const std::vector<std::string>& flags) {
    absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(dir_, flags);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = *std::move(server);
  }

  ProcessResult Tempokey(std::vector<std::string> args, const std::vector<std::string>& env = {}) {
    args.insert(args.begin(), {"--server", server_->target(), "--timeout", "20"});
    return RunTempokey(args, dir_, env);
  }

  std::string Path(const std::string& name) const { return dir_ + "/" + name; }

  // A failed `tempokey health` with `flags` must print gRPC's UNAVAILABLE text and then, on the
  // same and only line, "; <explanation>".
  void ExpectUnavailableExplainedAs(const std::vector<std::string>& flags,
                                    const std::string& explanation) {
    std::vector<std::string> args = flags;
    args.push_back("health");

    const ProcessResult run = Tempokey(args);

    EXPECT_EQ(run.exit_code, 1);
    EXPECT_THAT(run.err, IsOneErrorLine());
    EXPECT_THAT(run.err, StartsWith("error: server: UNAVAILABLE: "));
    EXPECT_THAT(run.err, EndsWith("; " + explanation + "\n"));
  }

  std::string dir_;
  std::unique_ptr<ServerProcess> server_;
};

TEST_F(CliSecurityTest, TlsServerIsReachedWithItsCaAndRefusesPlaintextInOneLine) {
  ASSERT_TRUE(MakeCertificates(dir_));
  StartServer({"--tls_cert", Path("server.pem"), "--tls_key", Path("server.key")});

  ProcessResult with_ca = Tempokey({"--ca", Path("ca.pem"), "health"});
  ProcessResult by_name = RunTempokey(
      {"--server", "localhost:" + std::to_string(server_->port()), "--ca", Path("ca.pem"), "health"},
      dir_);
  ProcessResult plaintext = Tempokey({"health"});
  ProcessResult system_roots = Tempokey({"--tls", "health"});

  EXPECT_EQ(with_ca.exit_code, 0) << with_ca.err;
  EXPECT_EQ(with_ca.out, kHealthyOutput);
  EXPECT_EQ(by_name.exit_code, 0) << by_name.err;
  EXPECT_EQ(plaintext.exit_code, 1);
  EXPECT_THAT(plaintext.err, IsOneErrorLine());
  EXPECT_THAT(plaintext.err, StartsWith("error: server: UNAVAILABLE: "));
  EXPECT_EQ(system_roots.exit_code, 1);
  EXPECT_THAT(system_roots.err, IsOneErrorLine());
  EXPECT_THAT(system_roots.err, StartsWith("error: server: UNAVAILABLE: "));
}

TEST_F(CliSecurityTest, MutualTlsServerNeedsTheClientCertificate) {
  ASSERT_TRUE(MakeCertificates(dir_));
  StartServer({"--tls_cert", Path("server.pem"), "--tls_key", Path("server.key"), "--tls_client_ca",
               Path("ca.pem")});
  const std::string clip = SharedBvh("bandai/dataset-1_bow_active_001.bvh");

  ProcessResult anonymous = Tempokey({"--ca", Path("ca.pem"), "upload", clip});
  ProcessResult certified = Tempokey({"--ca", Path("ca.pem"), "--cert", Path("client.pem"), "--key",
                                      Path("client.key"), "upload", clip});

  EXPECT_EQ(anonymous.exit_code, 1);
  EXPECT_THAT(anonymous.err, IsOneErrorLine());
  EXPECT_THAT(anonymous.err, StartsWith("error: server: UNAVAILABLE: "));
  EXPECT_EQ(certified.exit_code, 0) << certified.err;
  EXPECT_THAT(certified.out, StartsWith("clip id:         sha256:"));
}

// gRPC says only "certificate verify failed": the explanation names the certificate, its issuer,
// its dates, the --ca file and OpenSSL's reason.
TEST_F(CliSecurityTest, ACaThatDidNotSignTheServerCertificateIsExplainedWithBoth) {
  ASSERT_TRUE(MakeCertificates(dir_));
  ASSERT_TRUE(MakeCertificateWithDates(dir_, "self", "", "20200101000000Z", "20991231235959Z"));
  StartServer({"--tls_cert", Path("self.pem"), "--tls_key", Path("self.key")});

  ExpectUnavailableExplainedAs(
      {"--ca", Path("ca.pem")},
      "the server's certificate (CN=localhost, issued by CN=localhost, valid 2020-01-01 to "
      "2099-12-31) is not signed by a CA in --ca " +
          Path("ca.pem") + " (OpenSSL: self-signed certificate)");
}

TEST_F(CliSecurityTest, AnExpiredServerCertificateIsExplainedWithItsEndDate) {
  ASSERT_TRUE(MakeCertificates(dir_));
  ASSERT_TRUE(MakeCertificateWithDates(dir_, "expired", "ca", "20200101000000Z", "20200201000000Z"));
  StartServer({"--tls_cert", Path("expired.pem"), "--tls_key", Path("expired.key")});

  ExpectUnavailableExplainedAs({"--ca", Path("ca.pem")},
                               "the server's certificate (CN=localhost, issued by CN=tempokey test "
                               "CA) expired on 2020-02-01 00:00 UTC");
}

// gRPC says "wrong version number".
TEST_F(CliSecurityTest, TlsToAPlaintextServerIsExplainedAsTheServerNotSpeakingTls) {
  StartServer({});

  ExpectUnavailableExplainedAs(
      {"--tls"}, "the server does not speak TLS: connect without --tls, --ca, --cert and --key");
}

// gRPC says "Socket closed".
TEST_F(CliSecurityTest, PlaintextToATlsServerIsExplainedAsTheServerSpeakingTls) {
  ASSERT_TRUE(MakeCertificates(dir_));
  StartServer({"--tls_cert", Path("server.pem"), "--tls_key", Path("server.key")});

  ExpectUnavailableExplainedAs({}, "the server speaks TLS: connect with --tls (and --ca FILE if a "
                                   "private CA signed its certificate)");
}

// gRPC says "Socket closed": the server sends no alert.
TEST_F(CliSecurityTest, MutualTlsWithoutAClientCertificateIsExplainedAsRequiringOne) {
  ASSERT_TRUE(MakeCertificates(dir_));
  StartServer({"--tls_cert", Path("server.pem"), "--tls_key", Path("server.key"), "--tls_client_ca",
               Path("ca.pem")});

  ExpectUnavailableExplainedAs(
      {"--ca", Path("ca.pem")},
      "the server requires a client certificate (mutual TLS): pass --cert FILE and --key FILE");
}

// gRPC says "Socket closed": with TLS 1.3 the client's handshake completes before the server
// refuses its certificate.
TEST_F(CliSecurityTest, MutualTlsWithACertificateOfAnotherCaIsExplainedAsRefusedNamingTheCa) {
  ASSERT_TRUE(MakeCertificates(dir_));
  ASSERT_TRUE(MakeOtherCaAndItsClient(dir_));
  StartServer({"--tls_cert", Path("server.pem"), "--tls_key", Path("server.key"), "--tls_client_ca",
               Path("ca.pem")});

  ExpectUnavailableExplainedAs(
      {"--ca", Path("ca.pem"), "--cert", Path("stranger.pem"), "--key", Path("client.key")},
      "the server closed the connection after the handshake: it does not accept the client "
      "certificate in --cert " +
          Path("stranger.pem") + " (it asks for certificates from: CN=tempokey test CA)");
}

// gRPC says "Peer name other.example is not in peer certificate"; the names it holds follow.
TEST_F(CliSecurityTest, AServerNameTheCertificateLacksIsExplainedWithTheNamesItHolds) {
  ASSERT_TRUE(MakeCertificates(dir_));
  StartServer({"--tls_cert", Path("server.pem"), "--tls_key", Path("server.key")});

  ExpectUnavailableExplainedAs({"--ca", Path("ca.pem"), "--tls-server-name", "other.example"},
                               "the server's certificate (CN=localhost, issued by CN=tempokey test "
                               "CA) holds the names localhost, 127.0.0.1, not other.example: "
                               "connect by a name it holds, or give the one it was issued for "
                               "with --tls-server-name NAME");
}

// The probe tells a refused client certificate by the server closing the connection after the
// handshake: one it accepts must not read as refused (the server then sends HTTP/2 SETTINGS).
TEST_F(CliSecurityTest, TheProbeFindsAnAcceptedClientCertificateAccepted) {
  ASSERT_TRUE(MakeCertificates(dir_));
  StartServer({"--tls_cert", Path("server.pem"), "--tls_key", Path("server.key"), "--tls_client_ca",
               Path("ca.pem")});
  const absl::StatusOr<std::string> ca = core::ReadFile(Path("ca.pem"));
  const absl::StatusOr<std::string> cert = core::ReadFile(Path("client.pem"));
  const absl::StatusOr<std::string> key = core::ReadFile(Path("client.key"));
  ASSERT_TRUE(ca.ok() && cert.ok() && key.ok());
  client::ClientOptions options;
  options.tls = {.enabled = true, .root_ca_pem = *ca, .cert_chain_pem = *cert,
                 .private_key_pem = *key, .target_name_override = ""};

  const client::TlsProbeFindings findings =
      client::ProbeTls({.host = "127.0.0.1", .port = server_->port()}, options,
                       std::chrono::seconds(10));

  EXPECT_EQ(findings.handshake, client::TlsProbeFindings::Handshake::kCompleted);
  EXPECT_EQ(findings.verification, client::TlsProbeFindings::Verification::kOk);
  EXPECT_TRUE(findings.name_matches);
  EXPECT_TRUE(findings.client_certificate_requested);
  EXPECT_EQ(findings.after_handshake, client::TlsProbeFindings::AfterHandshake::kAccepted);
  EXPECT_EQ(client::ExplainTlsProbe(findings, options.tls, {}), "");
}

// A key given as --ca, or another certificate's key as --key, ended as "error: server:
// UNAVAILABLE: empty address list:" (gRPC's channel without credentials), blaming the server and
// naming no file. The files are checked before any channel is made.
TEST_F(CliSecurityTest, TlsFilesThatCannotWorkAreNamedBeforeAnyConnection) {
  ASSERT_TRUE(MakeCertificates(dir_));

  const ProcessResult key_as_ca =
      RunTempokey({"--server", "127.0.0.1:1", "--ca", Path("ca.key"), "health"}, dir_);
  const ProcessResult other_key = RunTempokey(
      {"--server", "127.0.0.1:1", "--ca", Path("ca.pem"), "--cert", Path("client.pem"), "--key",
       Path("server.key"), "health"},
      dir_);

  EXPECT_EQ(key_as_ca.exit_code, 1);
  EXPECT_EQ(key_as_ca.err, "error: --ca " + Path("ca.key") + ": holds no PEM certificate\n");
  EXPECT_EQ(other_key.exit_code, 1);
  EXPECT_EQ(other_key.err, "error: --key " + Path("server.key") +
                               " is not the private key of the certificate in --cert " +
                               Path("client.pem") + "\n");
}

TEST_F(CliSecurityTest, AnEmptyTlsServerNameIsAUsageError) {
  const ProcessResult run = RunTempokey(
      {"--server", "127.0.0.1:1", "--tls-server-name", "", "health"}, dir_);

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "error: --tls-server-name: expected a host name, got ''\n");
}

TEST_F(CliSecurityTest, MissingCaFileIsOneLineNamingIt) {
  StartServer({});

  ProcessResult run = Tempokey({"--ca", Path("nope.pem"), "health"});

  EXPECT_EQ(run.exit_code, 1);
  EXPECT_EQ(run.err, "error: " + Path("nope.pem") + ": no such file\n");
}

TEST_F(CliSecurityTest, BearerTokenComesFromAFileOrTheEnvironment) {
  ASSERT_TRUE(core::WriteFileAtomically(Path("tokens.txt"), "# accepted\ns3cret\n").ok());
  ASSERT_TRUE(core::WriteFileAtomically(Path("token"), "s3cret\n").ok());
  ASSERT_TRUE(core::WriteFileAtomically(Path("wrong"), "guess\n").ok());
  StartServer({"--auth_token_file", Path("tokens.txt")});
  const std::string clip = SharedBvh("bandai/dataset-1_bow_active_001.bvh");

  ProcessResult anonymous = Tempokey({"upload", clip});
  ProcessResult wrong = Tempokey({"--token-file", Path("wrong"), "upload", clip});
  ProcessResult from_file = Tempokey({"--token-file", Path("token"), "upload", clip});
  ProcessResult from_env = Tempokey({"upload", clip}, {"TEMPOKEY_TOKEN=s3cret"});

  EXPECT_EQ(anonymous.exit_code, 1);
  EXPECT_EQ(anonymous.err,
            "error: server: UNAUTHENTICATED: missing \"authorization: Bearer <token>\" metadata\n");
  EXPECT_EQ(wrong.exit_code, 1);
  EXPECT_EQ(wrong.err, "error: server: UNAUTHENTICATED: the bearer token is not accepted\n");
  EXPECT_EQ(from_file.exit_code, 0) << from_file.err;
  EXPECT_THAT(from_file.out, StartsWith("clip id:         sha256:"));
  EXPECT_EQ(from_env.exit_code, 0) << from_env.err;
}

// A token that cannot travel in an HTTP/2 header is refused in one line naming where it came from
// and the byte at fault (never the token: it is a secret), exit 1 as for any input the CLI
// cannot use; gRPC aborted the process on such
// metadata, exit 134 and not a word. A byte order mark and a CRLF ending, as editors write them,
// are no part of the token.
TEST_F(CliSecurityTest, ATokenThatCannotTravelInAHeaderIsOneLineNotACrash) {
  ASSERT_TRUE(core::WriteFileAtomically(Path("tokens.txt"), "# accepted\ns3cret\n").ok());
  ASSERT_TRUE(core::WriteFileAtomically(Path("bom"), "\xEF\xBB\xBFs3cret\r\n").ok());
  ASSERT_TRUE(core::WriteFileAtomically(Path("accent"), "s3cr\xC3\xA9t\n").ok());
  StartServer({"--auth_token_file", Path("tokens.txt")});

  ProcessResult bom = Tempokey({"--token-file", Path("bom"), "health"});
  ProcessResult server_file = Tempokey({"--token-file", Path("tokens.txt"), "health"});
  ProcessResult accent = Tempokey({"--token-file", Path("accent"), "health"});
  ProcessResult tab = Tempokey({"health"}, {"TEMPOKEY_TOKEN=s3\tcret"});
  ProcessResult control = Tempokey({"health"}, {"TEMPOKEY_TOKEN=s3\x01" "cret"});

  EXPECT_EQ(bom.exit_code, 0) << bom.err;
  EXPECT_EQ(server_file.exit_code, 1);
  EXPECT_EQ(server_file.err,
            "error: " + Path("tokens.txt") +
                ": holds 2 lines; the client sends one token (a server's --auth_token_file lists "
                "several: give the client a file with its own alone)\n");
  EXPECT_EQ(accent.exit_code, 1);
  EXPECT_EQ(accent.err, "error: " + Path("accent") +
                            ": the token holds byte 0xc3 (not ASCII) at byte 5; a bearer token is "
                            "one line of printable ASCII (it travels in an HTTP header)\n");
  EXPECT_EQ(tab.exit_code, 1);
  EXPECT_THAT(tab.err, StartsWith("error: $TEMPOKEY_TOKEN: the token holds a tab at byte 3; "));
  EXPECT_EQ(control.exit_code, 1);
  EXPECT_THAT(control.err,
              StartsWith("error: $TEMPOKEY_TOKEN: the token holds control character 0x01 at "));
  for (const ProcessResult* run : {&server_file, &accent, &tab, &control}) {
    EXPECT_EQ(std::count(run->err.begin(), run->err.end(), '\n'), 1) << run->err;
    EXPECT_EQ(run->err.find("s3"), std::string::npos) << "the token shown: " << run->err;
  }
}

// A token goes to another machine only over TLS: refused before any connection, one line, exit 2
// (192.0.2.2 is TEST-NET-1, never reached).
TEST_F(CliSecurityTest, ATokenIsNotSentInCleartextToAnotherMachine) {
  ASSERT_TRUE(core::WriteFileAtomically(Path("token"), "s3cret\n").ok());

  const ProcessResult refused = RunTempokey(
      {"--server", "192.0.2.2:50051", "--token-file", Path("token"), "server-info"}, dir_);
  const ProcessResult from_env =
      RunTempokey({"--server", "dns:///tempokey.example:50051", "server-info"}, dir_,
                  {"TEMPOKEY_TOKEN=s3cret"});

  EXPECT_EQ(refused.exit_code, 2);
  EXPECT_EQ(refused.err,
            "error: refusing to send the bearer token in cleartext to 192.0.2.2:50051, which is "
            "not on this machine: connect with TLS (the CLI's --tls or --ca), or allow it "
            "(--allow-plaintext-token) only where the network itself is trusted, as in a service "
            "mesh that encrypts it\n");
  EXPECT_EQ(from_env.exit_code, 2);
  EXPECT_THAT(from_env.err, StartsWith("error: refusing to send the bearer token in cleartext to "
                                       "dns:///tempokey.example:50051"));
}

}  // namespace
}  // namespace tempokey::testing
