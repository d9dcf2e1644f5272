#include "server/job_pool.h"

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/retry_hint.h"

namespace tempokey::server {

JobPool::JobPool(int workers, int queue_capacity) : queue_capacity_(std::max(1, queue_capacity)) {
  workers = std::max(1, workers);
  threads_.reserve(static_cast<std::size_t>(workers));
  for (int i = 0; i < workers; ++i) threads_.emplace_back([this] { WorkerLoop(); });
}

JobPool::~JobPool() { Shutdown(); }

absl::Status JobPool::TrySubmit(Task task) {
  {
    std::lock_guard lock(mu_);
    if (shutting_down_) return absl::UnavailableError("the server is shutting down");
    if (static_cast<int>(queue_.size()) >= queue_capacity_) {
      absl::Status full = absl::ResourceExhaustedError(absl::StrCat(
          "the job queue is full (", queue_.size(), " waiting for ", threads_.size(),
          " workers); retry later"));
      wire::SetRetryAfter(full, RetryAfterHintLocked());
      return full;
    }
    queue_.push_back(std::move(task));
  }
  work_cv_.notify_one();
  return absl::OkStatus();
}

int JobPool::queue_depth() const {
  std::lock_guard lock(mu_);
  return static_cast<int>(queue_.size());
}

int JobPool::running() const {
  std::lock_guard lock(mu_);
  return running_;
}

bool JobPool::WaitIdle(std::chrono::steady_clock::time_point deadline) const {
  std::unique_lock lock(mu_);
  return idle_cv_.wait_until(lock, deadline, [&] { return queue_.empty() && running_ == 0; });
}

void JobPool::RequestStopAll() { stop_all_.request_stop(); }

void JobPool::Shutdown() {
  {
    std::lock_guard lock(mu_);
    shutting_down_ = true;
  }
  work_cv_.notify_all();
  std::call_once(join_once_, [&] {
    for (std::thread& t : threads_) t.join();
  });
}

std::chrono::milliseconds JobPool::RetryAfterHintLocked() const {
  // A full queue drains at about workers / average_task per second; half of it is a fair wait.
  const double ms = average_task_ms_ * static_cast<double>(queue_capacity_) /
                    (2.0 * static_cast<double>(threads_.size()));
  return std::chrono::milliseconds(static_cast<std::int64_t>(std::clamp(ms, 10.0, 10'000.0)));
}

void JobPool::WorkerLoop() {
  std::unique_lock lock(mu_);
  for (;;) {
    work_cv_.wait(lock, [&] { return shutting_down_ || !queue_.empty(); });
    if (queue_.empty()) return;  // shutting down with nothing left to run
    Task task = std::move(queue_.front());
    queue_.pop_front();
    ++running_;
    lock.unlock();

    const auto start = std::chrono::steady_clock::now();
    task(stop_all_.get_token());
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    task = nullptr;  // release captured state before reporting idle

    lock.lock();
    --running_;
    average_task_ms_ = average_task_ms_ == 0.0 ? ms : 0.9 * average_task_ms_ + 0.1 * ms;
    if (queue_.empty() && running_ == 0) idle_cv_.notify_all();
  }
}

}  // namespace tempokey::server
