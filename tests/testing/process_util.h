// Running the real binaries from tests: the `tempokey` CLI as a child process with its output
// captured to files, and a real `tempokey-server` child on 127.0.0.1 with a free port. Every wait
// is bounded, and only the processes started here are ever signalled.
#ifndef TEMPOKEY_TESTS_TESTING_PROCESS_UTIL_H_
#define TEMPOKEY_TESTS_TESTING_PROCESS_UTIL_H_

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "gmock/gmock.h"
#include "absl/strings/str_cat.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/test_paths.h"

extern char** environ;

namespace tempokey::testing {

// Long enough never to matter on a working machine, short enough that a hang fails one test
// instead of the CI job.
inline constexpr std::chrono::seconds kProcessTimeout{120};

struct ProcessResult {
  int exit_code = -1;     // -1 when killed by a signal or timed out
  bool timed_out = false;
  std::string out;
  std::string err;
};

// What `tempokey health` prints for a server that is live and ready.
inline constexpr char kHealthyOutput[] =
    "overall:         SERVING\n"
    "tempokey.v1.MotionService: SERVING\n";

// "error: ..." and nothing else: exactly one line on stderr, as the CLI reports every failure.
MATCHER(IsOneErrorLine, "is exactly one line starting with \"error: \"") {
  return arg.rfind("error: ", 0) == 0 && arg.find('\n') == arg.size() - 1;
}

inline std::string TempokeyBinary() { return BinaryDir() + "/client/tempokey"; }
inline std::string ServerBinary() { return BinaryDir() + "/server/tempokey-server"; }

// Starts `argv` with stdin from /dev/null and stdout / stderr into the given files.
inline absl::StatusOr<pid_t> Spawn(const std::vector<std::string>& argv, const std::string& out_path,
                                   const std::string& err_path,
                                   const std::vector<std::string>& extra_env = {}) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::vector<char*> args;
  for (const std::string& arg : argv) args.push_back(const_cast<char*>(arg.c_str()));
  args.push_back(nullptr);
  std::vector<std::string> env_strings;
  for (char** e = environ; *e != nullptr; ++e) {
    // The tests choose tokens explicitly; an inherited one would change what they check.
    if (std::strncmp(*e, "TEMPOKEY_TOKEN=", 15) == 0) continue;
    env_strings.emplace_back(*e);
  }
  env_strings.insert(env_strings.end(), extra_env.begin(), extra_env.end());
  std::vector<char*> env;
  for (std::string& e : env_strings) env.push_back(e.data());
  env.push_back(nullptr);

  pid_t pid = 0;
  const int error = posix_spawn(&pid, args[0], &actions, nullptr, args.data(), env.data());
  posix_spawn_file_actions_destroy(&actions);
  if (error != 0) {
    return absl::InternalError(absl::StrCat("posix_spawn ", argv[0], ": ", std::strerror(error)));
  }
  return pid;
}

// Waits for `pid` at most `timeout`; returns its exit code, -1 for a signal, nullopt on timeout.
inline std::optional<int> WaitFor(pid_t pid, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    int status = 0;
    const pid_t done = waitpid(pid, &status, WNOHANG);
    if (done == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    if (done < 0) return -1;
    if (std::chrono::steady_clock::now() >= deadline) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

// Waits (bounded by kProcessTimeout) until `pid` is stopped (SIGSTOP, as by a test hook);
// false if it ended or never stopped.
inline bool WaitUntilStopped(pid_t pid) {
  const auto deadline = std::chrono::steady_clock::now() + kProcessTimeout;
  while (std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    const pid_t changed = waitpid(pid, &status, WNOHANG | WUNTRACED);
    if (changed == pid) return WIFSTOPPED(status);
    if (changed < 0) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

inline std::string ReadOrEmpty(const std::string& path) {
  absl::StatusOr<std::string> text = core::ReadFile(path);
  return text.ok() ? *text : std::string();
}

// Runs `argv` to completion (killing it after `timeout`) and captures its output.
inline ProcessResult RunProcess(const std::vector<std::string>& argv, const std::string& dir,
                                const std::vector<std::string>& extra_env = {},
                                std::chrono::seconds timeout = kProcessTimeout) {
  static std::atomic<int> counter{0};
  const std::string stem = absl::StrCat(dir, "/run-", getpid(), "-", counter++);
  ProcessResult result;
  absl::StatusOr<pid_t> pid = Spawn(argv, stem + ".out", stem + ".err", extra_env);
  if (!pid.ok()) {
    result.err = std::string(pid.status().message());
    return result;
  }
  std::optional<int> code = WaitFor(*pid, timeout);
  if (!code) {
    kill(*pid, SIGKILL);
    WaitFor(*pid, std::chrono::seconds(10));
    result.timed_out = true;
  } else {
    result.exit_code = *code;
  }
  result.out = ReadOrEmpty(stem + ".out");
  result.err = ReadOrEmpty(stem + ".err");
  return result;
}

// `tempokey args...`.
inline ProcessResult RunTempokey(const std::vector<std::string>& args, const std::string& dir,
                                 const std::vector<std::string>& extra_env = {}) {
  std::vector<std::string> argv = {TempokeyBinary()};
  argv.insert(argv.end(), args.begin(), args.end());
  return RunProcess(argv, dir, extra_env);
}

// A tempokey-server child listening on 127.0.0.1 at a free port. Stopped with SIGTERM (its
// graceful drain) when destroyed; SIGKILL only if it does not exit in time. Later flags override
// the defaults (--drain_grace_seconds 2, --log_level warn).
class ServerProcess {
 public:
  // Starts the server with `flags` added and waits (bounded) until it has written its port.
  // Errors: kInternal with the server's log when it exits first (bad flags, a bind failure).
  static absl::StatusOr<std::unique_ptr<ServerProcess>> Start(
      const std::string& dir, const std::vector<std::string>& flags = {}) {
    static std::atomic<int> counter{0};
    auto server = std::unique_ptr<ServerProcess>(new ServerProcess());
    const std::string stem = absl::StrCat(dir, "/server-", getpid(), "-", counter++);
    server->log_path_ = stem + ".err";
    server->stdout_path_ = stem + ".out";
    const std::string port_file = stem + ".port";
    std::vector<std::string> argv = {ServerBinary(), "--address", "127.0.0.1:0", "--port_file",
                                     port_file, "--drain_grace_seconds", "2", "--log_level",
                                     "warn"};
    argv.insert(argv.end(), flags.begin(), flags.end());
    absl::StatusOr<pid_t> pid = Spawn(argv, server->stdout_path_, server->log_path_);
    if (!pid.ok()) return pid.status();
    server->pid_ = *pid;

    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
      const std::string port = ReadOrEmpty(port_file);
      if (!port.empty() && port.back() == '\n') {
        server->port_ = std::stoi(port);
        return server;
      }
      if (std::optional<int> code = WaitFor(server->pid_, std::chrono::milliseconds(10))) {
        server->pid_ = -1;
        return absl::InternalError(absl::StrCat("tempokey-server exited with ", *code, ": ",
                                                ReadOrEmpty(server->log_path_)));
      }
    }
    return absl::DeadlineExceededError("tempokey-server did not write its port within 60 s");
  }

  ~ServerProcess() { Stop(); }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  int port() const { return port_; }
  // The child's pid while it runs, -1 once it has been reaped.
  pid_t pid() const { return pid_; }
  std::string target() const { return absl::StrCat("127.0.0.1:", port_); }
  std::string log() const { return ReadOrEmpty(log_path_); }
  std::string output() const { return ReadOrEmpty(stdout_path_); }

  // Sends `signal` to the running child (no effect once it has exited).
  void Signal(int signal) const {
    if (pid_ > 0) kill(pid_, signal);
  }

  // Waits at most `timeout` for the child to exit by itself; its exit code (-1 for a signal),
  // nullopt while it still runs.
  std::optional<int> WaitExit(std::chrono::milliseconds timeout) {
    if (pid_ <= 0) return exit_code_;
    std::optional<int> code = WaitFor(pid_, timeout);
    if (code) {
      pid_ = -1;
      exit_code_ = *code;
    }
    return code;
  }

  // SIGTERM, then a bounded wait; returns the exit code (-1 for a signal or a kill).
  int Stop() {
    if (pid_ <= 0) return exit_code_;
    Signal(SIGTERM);
    if (!WaitExit(std::chrono::seconds(30))) {
      kill(pid_, SIGKILL);
      WaitFor(pid_, std::chrono::seconds(10));
      pid_ = -1;
      exit_code_ = -1;
    }
    return exit_code_;
  }

 private:
  ServerProcess() = default;

  pid_t pid_ = -1;
  int port_ = 0;
  int exit_code_ = -1;
  std::string log_path_;
  std::string stdout_path_;
};

// A test with its own temporary folder and a real tempokey-server child started in it.
class ServerProcessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = MakeTempDir();
    absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(dir_);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = *std::move(server);
  }

  // `name` inside the test's folder.
  std::string Path(const std::string& name) const { return dir_ + "/" + name; }

  std::string dir_;
  std::unique_ptr<ServerProcess> server_;
};

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_TESTING_PROCESS_UTIL_H_
