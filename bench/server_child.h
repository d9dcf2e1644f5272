// A tempokey-server child process for the benchmarks: started on 127.0.0.1:0 with the flags given,
// its announced address read from its stdout, its log in a file, stopped with SIGTERM (its graceful
// drain, then SIGKILL after a bounded wait) when destroyed. Shared by service_bench and
// spec8_bench.
#ifndef TEMPOKEY_BENCH_SERVER_CHILD_H_
#define TEMPOKEY_BENCH_SERVER_CHILD_H_

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"

extern char** environ;

namespace tempokey::bench {

// A server that never announces itself within this long is broken, not slow.
inline constexpr std::chrono::seconds kServerStartTimeout{30};
inline constexpr std::chrono::seconds kServerStopTimeout{40};  // beyond the server's 25 s drain grace

// tempokey-server of the build tree this binary belongs to: ../server/tempokey-server.
inline std::string DefaultServerBinary() {
  std::error_code error;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
  return (self.parent_path().parent_path() / "server" / "tempokey-server").string();
}

// A tempokey-server child process on 127.0.0.1:0. Its stdout is a pipe we read the announcement
// from; its log goes to a file. Stopped with SIGTERM (its graceful drain) when destroyed.
class ServerChild {
 public:
  static absl::StatusOr<std::unique_ptr<ServerChild>> Start(const std::string& binary,
                                                            const std::vector<std::string>& flags,
                                                            const std::string& log_path) {
    auto child = std::unique_ptr<ServerChild>(new ServerChild());
    child->log_path_ = log_path;
    int out[2];
    if (pipe2(out, O_CLOEXEC) != 0) return absl::InternalError("pipe2 failed");
    child->stdout_fd_ = out[0];

    std::vector<std::string> argv = {binary, "--address", "127.0.0.1:0"};
    argv.insert(argv.end(), flags.begin(), flags.end());
    std::vector<char*> args;
    for (std::string& arg : argv) args.push_back(arg.data());
    args.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_adddup2(&actions, out[1], STDOUT_FILENO);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, log_path.c_str(),
                                     O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int error = posix_spawn(&child->pid_, binary.c_str(), &actions, nullptr, args.data(),
                                  environ);
    posix_spawn_file_actions_destroy(&actions);
    close(out[1]);  // only the child writes; EOF then means it exited
    if (error != 0) {
      child->pid_ = -1;
      return absl::InternalError(absl::StrCat("posix_spawn ", binary, ": ", std::strerror(error)));
    }
    absl::StatusOr<std::string> target = child->ReadAnnouncement();
    if (!target.ok()) return target.status();
    child->target_ = *std::move(target);
    return child;
  }

  ~ServerChild() {
    Stop();
    if (stdout_fd_ >= 0) close(stdout_fd_);
  }
  ServerChild(const ServerChild&) = delete;
  ServerChild& operator=(const ServerChild&) = delete;

  const std::string& target() const { return target_; }
  pid_t pid() const { return pid_; }
  const std::string& log_path() const { return log_path_; }

  // SIGTERM, then a bounded wait (SIGKILL after it). Returns the exit code, -1 for a signal.
  int Stop() {
    if (pid_ <= 0) return exit_code_;
    kill(pid_, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + kServerStopTimeout;
    int status = 0;
    pid_t done = 0;
    while ((done = waitpid(pid_, &status, WNOHANG)) == 0) {
      if (std::chrono::steady_clock::now() >= deadline) {
        kill(pid_, SIGKILL);
        done = waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    exit_code_ = done == pid_ && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    pid_ = -1;
    return exit_code_;
  }

 private:
  ServerChild() = default;

  // Reads stdout until "tempokey-server listening on HOST:PORT\n"; returns "HOST:PORT".
  absl::StatusOr<std::string> ReadAnnouncement() {
    constexpr std::string_view kPrefix = "tempokey-server listening on ";
    const auto deadline = std::chrono::steady_clock::now() + kServerStartTimeout;
    std::string text;
    while (std::chrono::steady_clock::now() < deadline) {
      pollfd fd{.fd = stdout_fd_, .events = POLLIN, .revents = 0};
      if (poll(&fd, 1, 100) <= 0) continue;
      char buffer[256];
      const ssize_t n = read(stdout_fd_, buffer, sizeof buffer);
      if (n <= 0) break;  // the child closed its stdout: it exited
      text.append(buffer, static_cast<std::size_t>(n));
      const auto start = text.find(kPrefix);
      const auto end = text.find('\n', start);
      if (start != std::string::npos && end != std::string::npos) {
        return text.substr(start + kPrefix.size(), end - start - kPrefix.size());
      }
    }
    return absl::InternalError(absl::StrCat("tempokey-server did not announce itself; see ",
                                            log_path_));
  }

  pid_t pid_ = -1;
  int exit_code_ = -1;
  int stdout_fd_ = -1;
  std::string target_;
  std::string log_path_;
};

}  // namespace tempokey::bench

#endif  // TEMPOKEY_BENCH_SERVER_CHILD_H_
