// The real tempokey-server binary, spawned as a child process: start-up output, refusal of
// unsafe addresses, and SIGTERM draining with a client connected and a job running.
#include <signal.h>

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

// Starts the server with info logging (the drain tests read its log lines).
std::unique_ptr<ServerProcess> StartInfoServer(const std::vector<std::string>& flags) {
  std::vector<std::string> all = {"--log_level", "info"};
  all.insert(all.end(), flags.begin(), flags.end());
  absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(MakeTempDir(), all);
  EXPECT_TRUE(server.ok()) << server.status();
  return server.ok() ? *std::move(server) : nullptr;
}

// Runs the server binary with `flags` to its exit (for flags it must refuse).
ProcessResult RunServer(const std::vector<std::string>& flags) {
  std::vector<std::string> argv = {ServerBinary()};
  argv.insert(argv.end(), flags.begin(), flags.end());
  return RunProcess(argv, MakeTempDir(), {}, std::chrono::seconds(60));
}

TEST(ServerBinaryTest, AnnouncesTheBoundPortOnStdoutAndInThePortFile) {
  std::unique_ptr<ServerProcess> server = StartInfoServer({"--workers=1"});
  ASSERT_NE(server, nullptr);

  const int port = server->port();
  server->Signal(SIGTERM);
  const std::optional<int> code = server->WaitExit(std::chrono::seconds(60));

  EXPECT_GT(port, 0);
  EXPECT_THAT(server->output(),
              HasSubstr("tempokey-server listening on 127.0.0.1:" + std::to_string(port) + "\n"));
  EXPECT_EQ(code, 0) << server->log();
}

TEST(ServerBinaryTest, HelpListsTheServersOwnFlagsOneLineEach) {
  const ProcessResult run = RunServer({"--help"});

  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_THAT(run.out, HasSubstr("usage: tempokey-server [flags]\n"));
  for (const char* flag : {"address", "workers", "queue_capacity", "drain_grace_seconds",
                           "metrics_address", "auth_token_file", "tls_cert", "log_level"}) {
    EXPECT_THAT(run.out, HasSubstr(std::string("\n  --") + flag + " ")) << flag;
  }
  EXPECT_THAT(run.out, HasSubstr("(default: 127.0.0.1:50051)\n"));
  // gRPC's and Abseil's own flags are not the server's interface.
  EXPECT_THAT(run.out, Not(HasSubstr("--flagfile")));
  EXPECT_THAT(run.out, Not(HasSubstr("No flags matched")));
}

TEST(ServerBinaryTest, RefusesANonLoopbackAddressWithoutTls) {
  const ProcessResult run = RunServer({"--address=0.0.0.0:0"});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_THAT(run.err,
              HasSubstr("refusing to listen on non-loopback address 0.0.0.0:0 without TLS "
                        "(0.0.0.0 is not a loopback address): give --tls_cert and --tls_key, or "
                        "--allow_insecure_remote"));
}

// The loopback rule reads resolved addresses, not the spelling: a name that merely starts with
// "127." is not loopback, while a v4-mapped loopback literal and an upper-case LOCALHOST are.
TEST(ServerBinaryTest, LoopbackIsDecidedByTheResolvedAddresses) {
  const ProcessResult look_alike = RunServer({"--address=127.attacker.invalid:0"});
  absl::StatusOr<std::unique_ptr<ServerProcess>> mapped =
      ServerProcess::Start(MakeTempDir(), {"--address=[::ffff:127.0.0.1]:0"});
  absl::StatusOr<std::unique_ptr<ServerProcess>> upper =
      ServerProcess::Start(MakeTempDir(), {"--address=LOCALHOST:0"});

  EXPECT_EQ(look_alike.exit_code, 2);
  EXPECT_THAT(look_alike.err,
              HasSubstr("refusing to listen on non-loopback address 127.attacker.invalid:0 "
                        "without TLS (127.attacker.invalid does not resolve ("));
  ASSERT_TRUE(mapped.ok()) << mapped.status();
  ASSERT_TRUE(upper.ok()) << upper.status();
  // Both serve on loopback: a client on 127.0.0.1 reaches them.
  for (const auto* server : {&*mapped, &*upper}) {
    const absl::StatusOr<int> live = CheckHealth(Connect((*server)->target()), "");
    ASSERT_TRUE(live.ok()) << live.status();
    EXPECT_EQ(*live, 1);
  }
}

// gRPC sets SO_REUSEPORT on Linux by default: a second server on a busy port started and took a
// share of the first one's connections without a word. It now fails to listen, and says so.
TEST(ServerBinaryTest, ASecondServerOnAPortInUseFailsToStartInsteadOfSharingIt) {
  std::unique_ptr<ServerProcess> first = StartInfoServer({"--workers=1"});
  ASSERT_NE(first, nullptr);

  const ProcessResult second = RunServer({"--address", first->target(), "--workers=1"});

  EXPECT_EQ(second.exit_code, 1);
  EXPECT_THAT(second.err, HasSubstr("cannot listen on " + first->target() +
                                    " (address in use or invalid?)"));
  EXPECT_EQ(first->Stop(), 0) << first->log();
}

TEST(ServerBinaryTest, BadFlagValueExitsWithUsageError) {
  const ProcessResult run = RunServer({"--address=127.0.0.1:0", "--queue_capacity=0"});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_THAT(run.err, HasSubstr("--queue_capacity must be > 0, got 0"));
}

// SIGTERM with a client watching a running job: the job still runs to completion (its log line
// says so) and the process exits 0; the watch ends UNAVAILABLE if the drain found the job still
// running, or with the SUCCEEDED snapshot if the job ended first. Which of the two happens
// depends on how fast the machine is, so both are checked, each completely.
TEST(ServerBinaryTest, SigtermWithAClientConnectedDrainsAndExitsZero) {
  std::unique_ptr<ServerProcess> server =
      StartInfoServer({"--workers=1", "--drain_grace_seconds=300"});
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  // 2.6 M samples through 64 wrap passes: a fifth of a second of real work or more (1 ns a
  // sample and pass in vectors), so SIGTERM, sent as the job starts, lands mid-job.
  UploadOutcome upload = UploadClip(*stub, MakeClip(130, 6700));
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  JobOutcome submitted = Submit(*stub, SubmitRequest(upload.response.clip_id(), WrapOperations(64)));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);

  bool signalled = false;
  WatchOutcome watch = WatchJob(*stub, submitted.job.job_id(), [&](const v1::Job& job) {
    if (job.state() == v1::JOB_STATE_RUNNING && !signalled) {
      signalled = true;
      server->Signal(SIGTERM);
    }
  });
  const std::optional<int> code = server->WaitExit(std::chrono::seconds(600));
  const std::string log = server->log();
  const bool caught_running = !watch.status.ok();
  RecordProperty("drain_found_the_job_running", caught_running ? 1 : 0);

  EXPECT_TRUE(signalled);
  if (caught_running) {
    EXPECT_THAT(watch.status,
                GrpcStatusIs(grpc::StatusCode::UNAVAILABLE, HasSubstr("shutting down")));
    EXPECT_THAT(log, HasSubstr("0 queued and 1 running get 300 s to finish"));
  } else {
    ASSERT_FALSE(watch.updates.empty());
    EXPECT_EQ(watch.updates.back().state(), v1::JOB_STATE_SUCCEEDED);
  }
  EXPECT_EQ(code, 0) << log;
  EXPECT_THAT(log, HasSubstr("received SIGTERM, draining"));
  EXPECT_THAT(log, HasSubstr("job id=" + submitted.job.job_id()));
  EXPECT_THAT(log, HasSubstr("outcome=succeeded"));
}

// A file name is the client's text: written raw, one with line breaks forged whole log lines
// ("... outcome=cancelled", the line operators and tests read). It is now one quoted field.
TEST(ServerBinaryTest, AFileNameCannotForgeALogLine) {
  std::unique_ptr<ServerProcess> server = StartInfoServer({"--workers=1"});
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const std::string forged =
      "[2026-11-30 21:00:00.000] [tempokey] [info] job id=forged outcome=cancelled";
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ParseClipFileRequest parse;
  parse.set_file_name("walk\n" + forged + "\n\x1b[2J\" x=\"y.bvh");
  parse.set_content(
      "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n"
      "  End Site\n  {\n    OFFSET 0 1 0\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.0333333\n"
      "0 0 0\n1 1 1\n");
  v1::ParseClipFileResponse parsed;
  TEMPOKEY_ASSERT_GRPC_OK(stub->ParseClipFile(&context, parse, &parsed));
  server->Signal(SIGTERM);
  ASSERT_EQ(server->WaitExit(std::chrono::seconds(60)), 0);
  const std::string log = server->log();

  EXPECT_THAT(log, Not(HasSubstr("\n" + forged)));
  EXPECT_THAT(log, Not(HasSubstr("\x1b")));
  EXPECT_THAT(log, HasSubstr("parse clip file=\"walk\\n" + forged +
                             "\\n\\x1b[2J\\\" x=\\\"y.bvh\" clip="));
}

TEST(ServerBinaryTest, SigintAlsoDrainsAndExitsZero) {
  std::unique_ptr<ServerProcess> server = StartInfoServer({"--workers=1"});
  ASSERT_NE(server, nullptr);

  server->Signal(SIGINT);
  const std::optional<int> code = server->WaitExit(std::chrono::seconds(60));

  EXPECT_EQ(code, 0) << server->log();
  EXPECT_THAT(server->log(), HasSubstr("received SIGINT, draining"));
}

// A unix socket has no port: the server announced "listening on unix:1" and wrote 1 into
// --port_file. It now announces the socket's address, and refuses a port file for it.
TEST(ServerBinaryTest, AUnixSocketIsAnnouncedByItsAddressAndHasNoPortFile) {
  const std::string dir = MakeTempDir();
  const std::string socket = "unix:" + dir + "/tempokey.sock";

  const ProcessResult refused = RunServer({"--address", socket, "--port_file", dir + "/port"});
  EXPECT_EQ(refused.exit_code, 2);
  EXPECT_THAT(refused.err, HasSubstr("--port_file: " + socket +
                                     " is a unix socket, which has no port; the socket is the "
                                     "address itself, and \"tempokey-server listening on " +
                                     socket + "\" on stdout says when it serves"));
  EXPECT_EQ(ReadOrEmpty(dir + "/port"), "");

  absl::StatusOr<pid_t> pid = Spawn({ServerBinary(), "--address", socket,
                                     "--drain_grace_seconds", "2"},
                                    dir + "/server.out", dir + "/server.err");
  ASSERT_TRUE(pid.ok()) << pid.status();
  const std::string announced = "tempokey-server listening on " + socket + "\n";
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  std::optional<int> early_exit;
  while (!absl::StrContains(ReadOrEmpty(dir + "/server.out"), announced) &&
         std::chrono::steady_clock::now() < deadline && !early_exit) {
    early_exit = WaitFor(*pid, std::chrono::milliseconds(10));
  }
  ASSERT_FALSE(early_exit) << ReadOrEmpty(dir + "/server.err");
  EXPECT_EQ(ReadOrEmpty(dir + "/server.out"), announced);
  // gRPC removes a socket file before it binds: a second server on the path took it over and the
  // first ran on unreachable. The second is refused now, and the first still answers.
  const ProcessResult second = RunServer({"--address", socket});
  const absl::StatusOr<int> live = CheckHealth(Connect(socket), "");
  kill(*pid, SIGTERM);
  const std::optional<int> code = WaitFor(*pid, std::chrono::seconds(60));
  if (!code) kill(*pid, SIGKILL);

  EXPECT_EQ(second.exit_code, 1);
  EXPECT_THAT(second.err, HasSubstr("cannot start: cannot listen on " + socket +
                                    ": another server is listening on this socket"));
  ASSERT_TRUE(live.ok()) << live.status();
  EXPECT_EQ(*live, 1);
  EXPECT_EQ(code, 0) << ReadOrEmpty(dir + "/server.err");
}

}  // namespace
}  // namespace tempokey::testing
