#include "server/http/slow_body_guard.h"

#include <arpa/inet.h>
#include <dirent.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdlib>
#include <string_view>

#include "spdlog/spdlog.h"

namespace tempokey::server::http {
namespace {

// The IPv4 address and port of `address` when it is one.
bool Ipv4Of(const sockaddr_storage& address, in_addr* host, int* port) {
  if (address.ss_family != AF_INET) return false;
  const auto* v4 = reinterpret_cast<const sockaddr_in*>(&address);
  *host = v4->sin_addr;
  *port = ntohs(v4->sin_port);
  return true;
}

}  // namespace

SlowBodyGuard::Watch& SlowBodyGuard::Watch::operator=(Watch&& other) noexcept {
  if (this != &other) {
    End();
    guard_ = other.guard_;
    id_ = other.id_;
    other.guard_ = nullptr;
  }
  return *this;
}

void SlowBodyGuard::Watch::End() {
  if (guard_ == nullptr) return;
  guard_->End(id_);
  guard_ = nullptr;
}

SlowBodyGuard::SlowBodyGuard(int local_port)
    : local_port_(local_port), thread_([this] { Run(); }) {}

SlowBodyGuard::~SlowBodyGuard() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  thread_.join();
}

SlowBodyGuard::Watch SlowBodyGuard::Start(const std::string& remote_address, int remote_port,
                                          Clock::time_point deadline) {
  std::uint64_t id = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    id = next_id_++;
    watched_[id] = {remote_address, remote_port, deadline};
  }
  changed_.notify_all();
  return Watch(this, id);
}

SlowBodyGuard::Clock::duration SlowBodyGuard::Allowance(std::chrono::milliseconds io_timeout,
                                                        std::int64_t content_length,
                                                        std::int64_t max_bytes) {
  // No more than the largest message counts: a body declaring more is refused at that size
  // anyway, and a declared 10^15 bytes must not buy years (or overflow).
  const std::int64_t bytes =
      content_length >= 0 ? std::min(content_length, max_bytes) : max_bytes;
  return io_timeout + std::chrono::milliseconds(bytes / kMinBytesPerSecond * 1000 +
                                                bytes % kMinBytesPerSecond * 1000 /
                                                    kMinBytesPerSecond);
}

std::int64_t SlowBodyGuard::cut_off() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return cut_off_;
}

void SlowBodyGuard::End(std::uint64_t id) {
  std::lock_guard<std::mutex> lock(mutex_);
  watched_.erase(id);
}

void SlowBodyGuard::Run() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stopping_) {
    if (watched_.empty()) {
      changed_.wait(lock);
      continue;
    }
    const auto earliest = std::min_element(
        watched_.begin(), watched_.end(),
        [](const auto& a, const auto& b) { return a.second.deadline < b.second.deadline; });
    if (Clock::now() < earliest->second.deadline) {
      changed_.wait_until(lock, earliest->second.deadline);
      continue;
    }
    const Watched late = earliest->second;
    watched_.erase(earliest);
    lock.unlock();
    const int socket = FindSocket(late);
    if (socket >= 0) {
      // Counted before the shutdown, so that whoever sees the connection end sees the count.
      {
        std::lock_guard<std::mutex> count_lock(mutex_);
        ++cut_off_;
      }
      // Shut down, not closed: the descriptor stays civetweb's, so it is not reused under it.
      ::shutdown(socket, SHUT_RDWR);
    }
    spdlog::warn("http: a request body from {}:{} did not arrive in time; its connection was {}",
                 late.remote_address, late.remote_port,
                 socket >= 0 ? "shut down" : "not found alone");
    lock.lock();
  }
}

int SlowBodyGuard::FindSocket(const Watched& watched) const {
  in_addr peer{};
  if (inet_pton(AF_INET, watched.remote_address.c_str(), &peer) != 1) return -1;
  DIR* fds = opendir("/proc/self/fd");
  if (fds == nullptr) return -1;
  // The one socket from that peer to the front end's port: with the front end on 0.0.0.0 one
  // peer address and port may reach two local addresses, and then none is cut.
  int found = -1;
  ino_t found_socket = 0;
  bool ambiguous = false;
  while (const dirent* entry = readdir(fds)) {
    char* end = nullptr;
    const long fd = std::strtol(entry->d_name, &end, 10);
    if (end == entry->d_name || *end != '\0') continue;
    sockaddr_storage local{};
    sockaddr_storage remote{};
    socklen_t local_size = sizeof local;
    socklen_t remote_size = sizeof remote;
    in_addr local_host{}, remote_host{};
    int local_port = 0, remote_port = 0;
    if (getsockname(static_cast<int>(fd), reinterpret_cast<sockaddr*>(&local), &local_size) != 0 ||
        !Ipv4Of(local, &local_host, &local_port) || local_port != local_port_ ||
        getpeername(static_cast<int>(fd), reinterpret_cast<sockaddr*>(&remote),
                    &remote_size) != 0 ||
        !Ipv4Of(remote, &remote_host, &remote_port) || remote_port != watched.remote_port ||
        remote_host.s_addr != peer.s_addr) {
      continue;
    }
    // Descriptors duplicated from one socket (civetweb keeps such) are one connection.
    struct stat info {};
    if (fstat(static_cast<int>(fd), &info) != 0) continue;
    if (found >= 0 && info.st_ino != found_socket) ambiguous = true;
    found = static_cast<int>(fd);
    found_socket = info.st_ino;
  }
  closedir(fds);
  return ambiguous ? -1 : found;
}

}  // namespace tempokey::server::http
