// The `tempokey` binary against real servers with TLS, mutual TLS and bearer tokens. The test
// certificates are made for each test by the openssl command-line tool (installed by
// deploy/install-deps.sh) in the test's temporary directory.
#include <sys/stat.h>

#include <memory>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

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
