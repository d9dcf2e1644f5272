#include "server/http/slow_body_guard.h"

#include <sys/socket.h>

#include <algorithm>

#include "server/http/connection_socket.h"
#include "spdlog/spdlog.h"

namespace tempokey::server::http {

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
  std::unique_lock<std::mutex> lock(mutex_);
  watched_.erase(id);
  // A cut of this connection under way finishes first: its descriptor is still this
  // connection's while the handler (the caller) holds it, and could be another's once it ends.
  changed_.wait(lock, [&] { return cutting_ != id; });
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
      // A copy: wait_until() reads its deadline again once woken, and the watch may have ended
      // (its map node freed) meanwhile, as AddressSanitizer saw in CI.
      const Clock::time_point deadline = earliest->second.deadline;
      changed_.wait_until(lock, deadline);
      continue;
    }
    const Watched late = earliest->second;
    cutting_ = earliest->first;
    watched_.erase(earliest);
    lock.unlock();
    const int socket =
        FindConnectionSocket(local_port_, late.remote_address, late.remote_port);
    if (socket >= 0) {
      // Counted before the shutdown, so that whoever sees the connection end sees the count.
      {
        std::lock_guard<std::mutex> count_lock(mutex_);
        ++cut_off_;
      }
      // Aborted, not closed: the descriptor stays civetweb's, so it is not reused under it. A
      // shutdown left the socket taking what the peer went on sending (AbortConnection()).
      AbortConnection(socket);
    }
    lock.lock();
    cutting_ = 0;
    changed_.notify_all();
    lock.unlock();
    spdlog::warn("http: a request body from {}:{} did not arrive in time; its connection was {}",
                 late.remote_address, late.remote_port,
                 socket >= 0 ? "shut down" : "not found alone");
    lock.lock();
  }
}

}  // namespace tempokey::server::http
