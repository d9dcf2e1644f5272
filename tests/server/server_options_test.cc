// Server settings: the worker count a container's CPU quota allows, loopback detection, token
// files, and the values no server can run with.
#include "server/server_options.h"

#include <sched.h>

#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/test_paths.h"

namespace tempokey::server {
namespace {

TEST(CpuQuotaLimitTest, ReadsCgroupV2AndFallsBackToV1) {
  struct Case {
    const char* v2;
    const char* v1_quota;
    const char* v1_period;
    int cpus;
  } cases[] = {
      {"max 100000\n", "", "", 0},                // no quota
      {"200000 100000\n", "", "", 2},
      {"150000 100000\n", "", "", 2},             // 1.5 CPUs: rounded up
      {"50000 100000\n", "", "", 1},              // half a CPU still runs one worker
      {"", "300000\n", "100000\n", 3},            // v1
      {"", "-1\n", "100000\n", 0},                // v1 without quota
      {"", "", "", 0},                            // no cgroup files at all
      {"garbage here\n", "", "", 0},
      {"100000 0\n", "", "", 0},                  // a zero period is no quota
      {"max 100000\n", "400000\n", "100000\n", 0},  // v2 says none: v1 is not consulted
  };
  for (const Case& c : cases) {
    EXPECT_EQ(CpuQuotaLimit(c.v2, c.v1_quota, c.v1_period), c.cpus)
        << "v2 \"" << c.v2 << "\" v1 \"" << c.v1_quota << "\"/\"" << c.v1_period << "\"";
  }
}

TEST(DefaultWorkerCountTest, FollowsTheCpusThisThreadMayUse) {
  int workers_with_one_cpu = 0;
  bool pinned = false;
  // A thread of its own, so the test's main thread keeps its affinity.
  std::thread probe([&] {
    cpu_set_t one;
    CPU_ZERO(&one);
    CPU_SET(0, &one);
    pinned = sched_setaffinity(0, sizeof one, &one) == 0;
    workers_with_one_cpu = DefaultWorkerCount();
  });
  probe.join();

  ASSERT_TRUE(pinned);
  EXPECT_EQ(workers_with_one_cpu, 1);
  EXPECT_GE(DefaultWorkerCount(), 1);
}

TEST(IsLoopbackAddressTest, KnowsLoopbackHostsAndUnixSockets) {
  for (const char* address :
       {"127.0.0.1:50051", "127.8.9.10:1", "localhost:50051", "LOCALHOST:50051", "LocalHost:1",
        "[::1]:50051", "[::ffff:127.0.0.1]:50051", "[::ffff:127.1.2.3]:0", "::1",
        "unix:/tmp/tempokey.sock", "unix-abstract:tempokey"}) {
    EXPECT_TRUE(IsLoopbackAddress(address)) << address;
  }
  for (const char* address :
       {"0.0.0.0:50051", "[::]:50051", "10.0.0.7:50051", "tempokey.example:443", "128.0.0.1:1",
        "127.attacker.invalid:50051", "127.0.0.1.attacker.invalid:1", "[::ffff:10.0.0.1]:1",
        ":50051", "[::ffff:128.0.0.1]:1"}) {
    EXPECT_FALSE(IsLoopbackAddress(address)) << address;
  }
}

TEST(CheckLoopbackAddressTest, SaysWhyAnAddressIsNotLoopback) {
  EXPECT_EQ(CheckLoopbackAddress("0.0.0.0:1").message(), "0.0.0.0 is not a loopback address");
  EXPECT_EQ(CheckLoopbackAddress("[::ffff:10.0.0.1]:1").message(),
            "::ffff:10.0.0.1 is not a loopback address");
  // .invalid never resolves (RFC 6761 section 6.4): a name that only looks like 127.x.
  EXPECT_THAT(std::string(CheckLoopbackAddress("127.attacker.invalid:1").message()),
              ::testing::StartsWith("127.attacker.invalid does not resolve ("));
  EXPECT_EQ(CheckLoopbackAddress(":50051").message(),
            "\":50051\" has no host: it listens on every interface");
}

TEST(MemoryLimitFromTest, TakesTheSmallestOfCgroupAndPhysicalMemory) {
  constexpr std::int64_t kGiB = std::int64_t{1} << 30;

  EXPECT_EQ(MemoryLimitFrom("2147483648\n", "", 8 * kGiB), 2 * kGiB);
  EXPECT_EQ(MemoryLimitFrom("max\n", "", 8 * kGiB), 8 * kGiB);
  EXPECT_EQ(MemoryLimitFrom("", "1073741824\n", 8 * kGiB), kGiB);
  EXPECT_EQ(MemoryLimitFrom("", "9223372036854771712\n", 8 * kGiB), 8 * kGiB);  // v1: no limit
  EXPECT_EQ(MemoryLimitFrom("17179869184", "", 8 * kGiB), 8 * kGiB);  // above the machine
  EXPECT_EQ(MemoryLimitFrom("", "", 0), 0);
  EXPECT_EQ(MemoryLimitFrom("536870912", "", 0), 512 << 20);
}

TEST(ReadTokenFileTest, SkipsCommentsAndBlankLinesAndTrims) {
  const std::string dir = testing::MakeTempDir();
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/tokens",
                                        "# pipeline tokens\n\n  first-token  \nsecond\n")
                  .ok());
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/empty", "# nothing here\n\n").ok());

  const absl::StatusOr<std::vector<std::string>> tokens = ReadTokenFile(dir + "/tokens");
  const absl::StatusOr<std::vector<std::string>> none = ReadTokenFile(dir + "/empty");
  const absl::StatusOr<std::vector<std::string>> missing = ReadTokenFile(dir + "/missing");

  ASSERT_TRUE(tokens.ok()) << tokens.status();
  EXPECT_EQ(*tokens, (std::vector<std::string>{"first-token", "second"}));
  EXPECT_EQ(none.status().message(), dir + "/empty: holds no token");
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
}

// A token no client could send (wire::CheckBearerToken()) stops the server at its start with the
// file's line, rather than sitting in the list never matched; a byte order mark is no token's.
TEST(ReadTokenFileTest, ABomIsSkippedAndATokenNoHeaderCanCarryIsRefusedByItsLine) {
  const std::string dir = testing::MakeTempDir();
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/bom", "\xEF\xBB\xBF" "first\r\nsecond\n").ok());
  ASSERT_TRUE(core::WriteFileAtomically(dir + "/latin", "# tokens\nfine\ncaf\xE9\n").ok());

  const absl::StatusOr<std::vector<std::string>> bom = ReadTokenFile(dir + "/bom");
  const absl::StatusOr<std::vector<std::string>> latin = ReadTokenFile(dir + "/latin");

  ASSERT_TRUE(bom.ok()) << bom.status();
  EXPECT_EQ(*bom, (std::vector<std::string>{"first", "second"}));
  EXPECT_EQ(latin.status().message(),
            dir + "/latin:3: the token holds byte 0xe9 (not ASCII) at byte 4; a bearer token is "
                  "one line of printable ASCII (it travels in an HTTP header)");
}

TEST(ValidateServerOptionsTest, RefusesWhatNoServerCanRunWith) {
  struct Case {
    void (*edit)(ServerOptions&);
    const char* message;
  } cases[] = {
      {[](ServerOptions& o) { o.address.clear(); }, "--address must not be empty"},
      {[](ServerOptions& o) { o.queue_capacity = 0; }, "--queue_capacity must be > 0, got 0"},
      {[](ServerOptions& o) { o.max_message_bytes = std::int64_t{3} << 30; },
       "--max_message_bytes must be below 2 GiB, got 3221225472"},
      {[](ServerOptions& o) { o.max_stored_results = -5; },
       "--max_stored_results must be > 0, got -5"},
      {[](ServerOptions& o) { o.drain_grace = std::chrono::seconds(-1); },
       "--drain_grace_seconds must be in [0, 31536000], got -1"},
      {[](ServerOptions& o) { o.job_ttl = std::chrono::seconds(std::int64_t{1} << 40); },
       "--job_ttl_seconds must be in [0, 31536000], got 1099511627776"},
      // gRPC's int of milliseconds: 30 days overflowed into a negative age, and every call
      // failed DEADLINE_EXCEEDED.
      {[](ServerOptions& o) { o.max_connection_age = std::chrono::seconds(2'592'000); },
       "--max_connection_age_seconds must be in [0, 2147483] (0: never), got 2592000"},
      {[](ServerOptions& o) { o.max_connection_age = std::chrono::seconds(-1); },
       "--max_connection_age_seconds must be in [0, 2147483] (0: never), got -1"},
      {[](ServerOptions& o) { o.min_client_ping_interval = std::chrono::hours(600); },
       "min_client_ping_interval must be in [0, 2147483647] ms, got 2160000000"},
      {[](ServerOptions& o) { o.tls_cert_file = "cert.pem"; },
       "--tls_cert and --tls_key must be given together"},
      {[](ServerOptions& o) { o.tls_client_ca_file = "ca.pem"; },
       "--tls_client_ca needs --tls_cert and --tls_key (mutual TLS is TLS first)"},
      {[](ServerOptions& o) { o.auth_tokens = {"ok", ""}; }, "an auth token is empty"},
      {[](ServerOptions& o) { o.address = "127.0.0.1:70000"; },
       "--address 127.0.0.1:70000: port 70000 is not a TCP port (0 to 65535)"},
      {[](ServerOptions& o) { o.metrics_address = "127.0.0.1:65536"; },
       "--metrics_address 127.0.0.1:65536: port 65536 is not a TCP port (0 to 65535)"},
      {[](ServerOptions& o) { o.auth_tokens = {"ok", "two\nlines"}; },
       "an auth token: the token holds a line break at byte 4; a bearer token is one line of "
       "printable ASCII (it travels in an HTTP header)"},
      {[](ServerOptions& o) { o.address = "0.0.0.0:50051"; },
       "refusing to listen on non-loopback address 0.0.0.0:50051 without TLS (0.0.0.0 is not a "
       "loopback address): give --tls_cert and --tls_key, or --allow_insecure_remote"},
      {[](ServerOptions& o) { o.metrics_address = "0.0.0.0:9464"; },
       "refusing to serve metrics on non-loopback address 0.0.0.0:9464 (0.0.0.0 is not a "
       "loopback address): metrics are plain HTTP; scrape over loopback, or give "
       "--allow_insecure_remote"},
      {[](ServerOptions& o) {
         o.metrics_address = "0.0.0.0:9464";
         o.tls_cert_file = "cert.pem";
         o.tls_key_file = "key.pem";
       },
       "refusing to serve metrics on non-loopback address 0.0.0.0:9464 (0.0.0.0 is not a "
       "loopback address): metrics are plain HTTP; scrape over loopback, or give "
       "--allow_insecure_remote"},
      {[](ServerOptions& o) { o.memory_budget_bytes = -1; },
       "--memory_budget_bytes must be >= 0 (0: half the memory the process may use), got -1"},
      {[](ServerOptions& o) { o.stream_idle_timeout = std::chrono::milliseconds(-1500); },
       "--stream_idle_timeout_seconds must be >= 0 (0: none), got -1.5"},
      {[](ServerOptions& o) { o.process_progress_interval = std::chrono::milliseconds(-5); },
       "--process_progress_interval_ms must be in [0, 3600000] (0: every new stage label or "
       "percent), got -5"},
      {[](ServerOptions& o) { o.process_progress_interval = std::chrono::hours(2); },
       "--process_progress_interval_ms must be in [0, 3600000] (0: every new stage label or "
       "percent), got 7200000"},
  };
  for (const Case& c : cases) {
    ServerOptions options;
    c.edit(options);

    const absl::Status status = ValidateServerOptions(options);

    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << c.message;
    EXPECT_EQ(status.message(), c.message);
  }
  ServerOptions longest;
  longest.job_ttl = std::chrono::seconds(kMaxDurationSeconds);
  longest.drain_grace = std::chrono::seconds(kMaxDurationSeconds);
  longest.max_connection_age = std::chrono::seconds(kMaxConnectionAgeSeconds);
  EXPECT_TRUE(ValidateServerOptions(longest).ok());
  ServerOptions remote;
  remote.address = "0.0.0.0:50051";
  remote.metrics_address = "0.0.0.0:9464";
  remote.allow_insecure_remote = true;
  EXPECT_TRUE(ValidateServerOptions(remote).ok());
  ServerOptions look_alike;
  look_alike.address = "127.attacker.invalid:50051";
  // The resolver's reason varies (no such name, or no DNS at all); the refusal does not.
  EXPECT_THAT(std::string(ValidateServerOptions(look_alike).message()),
              ::testing::StartsWith("refusing to listen on non-loopback address "
                                    "127.attacker.invalid:50051 without TLS (127.attacker.invalid "
                                    "does not resolve ("));
  ServerOptions local_names;
  local_names.address = "LOCALHOST:50051";
  local_names.metrics_address = "[::ffff:127.0.0.1]:9464";
  EXPECT_TRUE(ValidateServerOptions(local_names).ok());
  EXPECT_TRUE(ValidateServerOptions(ServerOptions{}).ok());
}

}  // namespace
}  // namespace tempokey::server
