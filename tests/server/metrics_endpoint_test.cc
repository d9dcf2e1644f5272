// The Prometheus endpoint of the real tempokey-server binary: its port is reported (stdout, log,
// --metrics_port_file) when --metrics_address asks for port 0; with --auth_token_file a scrape
// needs the bearer token; slow clients holding half a request do not keep scrapes waiting and
// are dropped; a non-loopback metrics address needs --allow_insecure_remote like --address.
#include <unistd.h>

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/metrics.h"
#include "tempokey/core/io/file_io.h"
#include "tests/server/http_util.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

struct MetricsServer {
  std::unique_ptr<ServerProcess> process;
  int metrics_port = 0;
};

// A server with metrics on 127.0.0.1:0 and `flags`; its metrics port read from the port file.
MetricsServer StartMetricsServer(const std::string& dir, const std::vector<std::string>& flags = {}) {
  std::vector<std::string> all = {"--metrics_address=127.0.0.1:0",
                                  "--metrics_port_file=" + dir + "/metrics.port"};
  all.insert(all.end(), flags.begin(), flags.end());
  absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(dir, all);
  EXPECT_TRUE(server.ok()) << server.status();
  MetricsServer result;
  if (!server.ok()) return result;
  result.process = *std::move(server);
  // The metrics port file is written before the main port file the start waited for.
  result.metrics_port = std::stoi(ReadOrEmpty(dir + "/metrics.port"));
  return result;
}

TEST(MetricsEndpointTest, ChosenPortIsReportedAndServesTheGauges) {
  const std::string dir = MakeTempDir();
  MetricsServer server = StartMetricsServer(dir);
  ASSERT_NE(server.process, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server.process->target()));
  TEMPOKEY_ASSERT_GRPC_OK(UploadClip(*stub, MakeClip(1, 1000)).status);

  const std::optional<std::string> scrape = HttpGet(server.metrics_port, "/metrics");

  EXPECT_GT(server.metrics_port, 0);
  EXPECT_THAT(server.process->output(),
              HasSubstr("tempokey-server metrics on 127.0.0.1:" +
                        std::to_string(server.metrics_port) + "\n"));
  ASSERT_TRUE(scrape.has_value());
  EXPECT_THAT(*scrape, StartsWith("HTTP/1.1 200"));
  const auto samples = ParseSamples(*scrape);
  EXPECT_GT(Sample(samples, "tempokey_memory_budget_bytes"), 0.0);
  EXPECT_GE(Sample(samples, R"(tempokey_memory_used_bytes{use="stored_clip"})"), 6 * 1000 * 8);
}

TEST(MetricsEndpointTest, WithTokensAScrapeNeedsTheBearerToken) {
  const std::string dir = MakeTempDir();
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/tokens", "scrape-token-1\n").ok());
  MetricsServer server = StartMetricsServer(dir, {"--auth_token_file", dir + "/tokens"});
  ASSERT_NE(server.process, nullptr);

  const std::optional<std::string> none = HttpGet(server.metrics_port, "/metrics");
  const std::optional<std::string> wrong =
      HttpGet(server.metrics_port, "/metrics", "Authorization: Bearer guessed\r\n");
  const std::optional<std::string> right =
      HttpGet(server.metrics_port, "/metrics", "Authorization: Bearer scrape-token-1\r\n");

  ASSERT_TRUE(none.has_value() && wrong.has_value() && right.has_value());
  EXPECT_THAT(*none, StartsWith("HTTP/1.1 401"));
  EXPECT_THAT(*none, HasSubstr("missing \"Authorization: Bearer <token>\" header"));
  EXPECT_THAT(*none, ::testing::Not(HasSubstr("tempokey_")));
  EXPECT_THAT(*wrong, StartsWith("HTTP/1.1 401"));
  EXPECT_THAT(*wrong, HasSubstr("the bearer token is not accepted"));
  EXPECT_THAT(*right, StartsWith("HTTP/1.1 200"));
  EXPECT_THAT(*right, HasSubstr("tempokey_queue_depth"));
}

TEST(MetricsEndpointTest, SlowClientsHoldingHalfARequestDoNotBlockScrapesAndAreDropped) {
  const std::string dir = MakeTempDir();
  MetricsServer server = StartMetricsServer(dir);
  ASSERT_NE(server.process, nullptr);
  // Fewer slow clients than the endpoint has threads: each holds one with half a request line.
  constexpr int kSlow = server::kMetricsThreads / 2;
  std::vector<int> slow;
  for (int i = 0; i < kSlow; ++i) {
    const int fd = ConnectLoopback(server.metrics_port);
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::send(fd, "GET /metr", 9, 0), 9);
    slow.push_back(fd);
  }

  const std::optional<std::string> scrape = HttpGet(server.metrics_port, "/metrics");
  // The server gives up on each slow client (its request timeout) and closes the connection:
  // reading it returns its end (or an error status), bounded by the 60 s read guard.
  std::vector<std::string> endings;
  for (const int fd : slow) {
    endings.push_back(ReadToEnd(fd));
    char probe = 0;
    const ssize_t after = ::recv(fd, &probe, 1, 0);
    EXPECT_EQ(after, 0) << "the server kept a slow connection open";
    ::close(fd);
  }

  ASSERT_TRUE(scrape.has_value());
  EXPECT_THAT(*scrape, StartsWith("HTTP/1.1 200"));
  for (const std::string& ending : endings) {
    // CivetWeb answers "HTTP/1.0 400 Bad Request" to a request it gave up on.
    EXPECT_THAT(ending, ::testing::AnyOf(::testing::IsEmpty(),
                                         ::testing::ContainsRegex("^HTTP/1\\.[01] 4[0-9][0-9] ")));
  }
}

// The exposition as Prometheus itself reads it: `promtool check metrics` (Prometheus's own
// parser and linter, taken from Debian's prometheus package by deploy/install-deps.sh) after
// the server has uploaded, retimed, reduced and refused through the real CLI, so that the
// histograms, labelled counters and gauges are all filled. Nothing else here reads the format
// but our own ParseSamples(). The same checker, given one counter named against Prometheus's
// conventions, reports it: its silence on the server's is a verdict.
TEST(MetricsEndpointTest, TheExpositionPassesPrometheusOwnChecker) {
  const std::string promtool = SourceDir() + "/tests/server/tools/promtool";
  ASSERT_EQ(::access(promtool.c_str(), X_OK), 0)
      << promtool << " is missing: deploy/install-deps.sh puts it there";
  const std::string dir = MakeTempDir();
  MetricsServer server = StartMetricsServer(dir);
  ASSERT_NE(server.process, nullptr);
  const std::string walk = SharedBvh("bandai/dataset-1_walk_active_001.bvh");
  const std::string target = server.process->target();
  ASSERT_EQ(RunTempokey({"--server", target, "upload", walk}, dir).exit_code, 0);
  ASSERT_EQ(RunTempokey({"--server", target, "retime", walk, "-o", dir + "/slow.bvh", "--speed",
                         "0s:0.5"}, dir).exit_code, 0);
  ASSERT_EQ(RunTempokey({"--server", target, "reduce", walk, "-o", dir + "/walk.json"}, dir)
                .exit_code, 0);
  ASSERT_EQ(RunTempokey({"--server", target, "reduce", walk, "-o", dir + "/no.json",
                         "--tolerance", "-1"}, dir).exit_code, 1);

  const std::optional<std::string> scrape = HttpGet(server.metrics_port, "/metrics");

  ASSERT_TRUE(scrape.has_value());
  ASSERT_THAT(*scrape, StartsWith("HTTP/1.1 200"));
  const std::string body = scrape->substr(scrape->find("\r\n\r\n") + 4);
  EXPECT_THAT(body, HasSubstr("# TYPE tempokey_job_latency_seconds histogram"));
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/server.prom", body).ok());
  ASSERT_TRUE(core::WriteFileAtomically(
      dir + "/misnamed.prom",
      body + "# HELP tempokey_misnamed_bytes A counter without _total.\n"
             "# TYPE tempokey_misnamed_bytes counter\ntempokey_misnamed_bytes 1\n").ok());
  auto check = [&](const std::string& file) {
    return RunProcess({"/bin/sh", "-c", "exec \"$0\" check metrics < \"$1\"", promtool, file},
                      dir);
  };
  const ProcessResult ours = check(dir + "/server.prom");
  const ProcessResult misnamed = check(dir + "/misnamed.prom");

  EXPECT_EQ(ours.exit_code, 0) << ours.out << ours.err;
  EXPECT_EQ(ours.out + ours.err, "");
  EXPECT_NE(misnamed.exit_code, 0);
  EXPECT_THAT(misnamed.out + misnamed.err,
              HasSubstr("tempokey_misnamed_bytes counter metrics should have \"_total\" suffix"));
}

TEST(MetricsEndpointTest, NonLoopbackMetricsAddressNeedsAllowInsecureRemote) {
  const std::string dir = MakeTempDir();
  const ProcessResult refused = RunProcess(
      {ServerBinary(), "--address=127.0.0.1:0", "--metrics_address=0.0.0.0:0"}, dir, {},
      std::chrono::seconds(60));
  const ProcessResult look_alike = RunProcess(
      {ServerBinary(), "--address=127.0.0.1:0", "--metrics_address=127.attacker.invalid:0"}, dir,
      {}, std::chrono::seconds(60));
  absl::StatusOr<std::unique_ptr<ServerProcess>> allowed = ServerProcess::Start(
      dir, {"--metrics_address=0.0.0.0:0", "--allow_insecure_remote"});

  EXPECT_EQ(refused.exit_code, 2);
  EXPECT_THAT(refused.err, HasSubstr("refusing to serve metrics on non-loopback address "
                                     "0.0.0.0:0 (0.0.0.0 is not a loopback address): metrics are "
                                     "plain HTTP; scrape over loopback, or give "
                                     "--allow_insecure_remote"));
  EXPECT_EQ(look_alike.exit_code, 2);
  EXPECT_THAT(look_alike.err, HasSubstr("127.attacker.invalid does not resolve"));
  EXPECT_TRUE(allowed.ok()) << allowed.status();
}

}  // namespace
}  // namespace tempokey::testing
