// The real tempokey-server binary, spawned as a child process: start-up output, refusal of
// unsafe addresses, and SIGTERM draining with a client connected and a job running.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fcntl.h>

#include <chrono>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/test_paths.h"

extern char** environ;

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// A tempokey-server child with stdout and stderr captured in files and --port_file set.
class ServerProcess {
 public:
  explicit ServerProcess(std::vector<std::string> flags) : dir_(MakeTempDir()) {
    const std::string binary = BinaryDir() + "/server/tempokey-server";
    std::vector<std::string> args = {binary, "--port_file=" + port_file()};
    args.insert(args.end(), flags.begin(), flags.end());
    std::vector<char*> argv;
    for (std::string& arg : args) argv.push_back(arg.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, stdout_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 2, stderr_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    spawned_ = posix_spawn(&pid_, binary.c_str(), &actions, nullptr, argv.data(), environ) == 0;
    posix_spawn_file_actions_destroy(&actions);
  }

  ~ServerProcess() {
    if (spawned_ && !exit_status_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }

  bool spawned() const { return spawned_; }
  pid_t pid() const { return pid_; }
  std::string dir() const { return dir_; }
  std::string port_file() const { return dir_ + "/port"; }
  std::string stdout_path() const { return dir_ + "/stdout"; }
  std::string stderr_path() const { return dir_ + "/stderr"; }

  // The port written to --port_file, waiting for it up to `timeout`; 0 if the child exited or
  // the time ran out.
  int WaitForPort(std::chrono::seconds timeout = std::chrono::seconds(60)) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      const std::string text = ReadText(port_file());
      if (!text.empty() && text.back() == '\n') return std::stoi(text);
      if (WaitExit(std::chrono::seconds(0))) return 0;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return 0;
  }

  // The raw wait status once the child exited, waiting up to `timeout`.
  std::optional<int> WaitExit(std::chrono::seconds timeout) {
    if (exit_status_) return exit_status_;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    do {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        exit_status_ = status;
        return exit_status_;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    } while (std::chrono::steady_clock::now() < deadline);
    return std::nullopt;
  }

 private:
  std::string dir_;
  pid_t pid_ = -1;
  bool spawned_ = false;
  std::optional<int> exit_status_;
};

bool ExitedWith(std::optional<int> status, int code) {
  return status.has_value() && WIFEXITED(*status) && WEXITSTATUS(*status) == code;
}

TEST(ServerBinaryTest, AnnouncesTheBoundPortOnStdoutAndInThePortFile) {
  ServerProcess server({"--address=127.0.0.1:0", "--workers=1"});
  ASSERT_TRUE(server.spawned());

  const int port = server.WaitForPort();
  ASSERT_GT(port, 0) << ReadText(server.stderr_path());
  kill(server.pid(), SIGTERM);
  const std::optional<int> status = server.WaitExit(std::chrono::seconds(60));

  EXPECT_THAT(ReadText(server.stdout_path()),
              HasSubstr("tempokey-server listening on 127.0.0.1:" + std::to_string(port) + "\n"));
  EXPECT_TRUE(ExitedWith(status, 0)) << ReadText(server.stderr_path());
}

TEST(ServerBinaryTest, RefusesANonLoopbackAddressWithoutTls) {
  ServerProcess server({"--address=0.0.0.0:0"});
  ASSERT_TRUE(server.spawned());

  const std::optional<int> status = server.WaitExit(std::chrono::seconds(60));

  EXPECT_TRUE(ExitedWith(status, 2));
  EXPECT_THAT(ReadText(server.stderr_path()),
              HasSubstr("refusing to listen on non-loopback address 0.0.0.0:0 without TLS: give "
                        "--tls_cert and --tls_key, or --allow_insecure_remote"));
}

TEST(ServerBinaryTest, BadFlagValueExitsWithUsageError) {
  ServerProcess server({"--address=127.0.0.1:0", "--queue_capacity=0"});
  ASSERT_TRUE(server.spawned());

  const std::optional<int> status = server.WaitExit(std::chrono::seconds(60));

  EXPECT_TRUE(ExitedWith(status, 2));
  EXPECT_THAT(ReadText(server.stderr_path()), HasSubstr("--queue_capacity must be > 0, got 0"));
}

// SIGTERM with a client watching a running job: the watch ends UNAVAILABLE, the job still runs
// to completion (its log line says so), and the process exits 0.
TEST(ServerBinaryTest, SigtermWithAClientConnectedDrainsAndExitsZero) {
  ServerProcess server({"--address=127.0.0.1:0", "--workers=1", "--drain_grace_seconds=300"});
  ASSERT_TRUE(server.spawned());
  const int port = server.WaitForPort();
  ASSERT_GT(port, 0) << ReadText(server.stderr_path());
  auto stub = v1::MotionService::NewStub(Connect("127.0.0.1:" + std::to_string(port)));
  // 2.6 M samples through 64 wrap passes: seconds of real work, so SIGTERM lands mid-job.
  UploadOutcome upload = UploadClip(*stub, MakeClip(130, 6700));
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  JobOutcome submitted = Submit(*stub, SubmitRequest(upload.response.clip_id(), WrapOperations(64)));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);

  bool signalled = false;
  WatchOutcome watch = WatchJob(*stub, submitted.job.job_id(), [&](const v1::Job& job) {
    if (job.state() == v1::JOB_STATE_RUNNING && !signalled) {
      signalled = true;
      kill(server.pid(), SIGTERM);
    }
  });
  const std::optional<int> status = server.WaitExit(std::chrono::seconds(600));
  const std::string log = ReadText(server.stderr_path());

  EXPECT_TRUE(signalled);
  EXPECT_THAT(watch.status, GrpcStatusIs(grpc::StatusCode::UNAVAILABLE, HasSubstr("shutting down")));
  EXPECT_TRUE(ExitedWith(status, 0)) << log;
  EXPECT_THAT(log, HasSubstr("received SIGTERM, draining"));
  EXPECT_THAT(log, HasSubstr("job id=" + submitted.job.job_id()));
  EXPECT_THAT(log, HasSubstr("outcome=succeeded"));
}

TEST(ServerBinaryTest, SigintAlsoDrainsAndExitsZero) {
  ServerProcess server({"--address=127.0.0.1:0", "--workers=1"});
  ASSERT_TRUE(server.spawned());
  ASSERT_GT(server.WaitForPort(), 0) << ReadText(server.stderr_path());

  kill(server.pid(), SIGINT);
  const std::optional<int> status = server.WaitExit(std::chrono::seconds(60));

  EXPECT_TRUE(ExitedWith(status, 0)) << ReadText(server.stderr_path());
  EXPECT_THAT(ReadText(server.stderr_path()), HasSubstr("received SIGINT, draining"));
}

}  // namespace
}  // namespace tempokey::testing
