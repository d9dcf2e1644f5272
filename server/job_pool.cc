#include "server/job_pool.h"

#include <algorithm>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/retry_hint.h"

namespace tempokey::server {

JobPool::JobPool(int workers, int queue_capacity, Clock clock)
    : queue_capacity_(std::max(1, queue_capacity)), clock_(std::move(clock)) {
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

std::chrono::steady_clock::time_point JobPool::Now() const {
  return clock_ ? clock_() : std::chrono::steady_clock::now();
}

std::chrono::milliseconds JobPool::RetryAfterHintLocked() const {
  // A queue slot frees when the first running task ends and a worker takes the next one.
  const auto now = Now();
  double soonest_ms = started_.empty() ? average_task_ms_ : std::numeric_limits<double>::max();
  for (const auto& start : started_) {
    const double elapsed_ms = std::chrono::duration<double, std::milli>(now - start).count();
    // Past the usual duration (or with none known yet), a task is expected to run about as
    // long again: how long it has run is the best guess of how long it takes.
    const double remaining_ms =
        average_task_ms_ > elapsed_ms ? average_task_ms_ - elapsed_ms : elapsed_ms;
    soonest_ms = std::min(soonest_ms, remaining_ms);
  }
  return std::chrono::milliseconds(
      static_cast<std::int64_t>(std::clamp(soonest_ms, 10.0, 60'000.0)));
}

void JobPool::WorkerLoop() {
  std::unique_lock lock(mu_);
  for (;;) {
    work_cv_.wait(lock, [&] { return shutting_down_ || !queue_.empty(); });
    if (queue_.empty()) return;  // shutting down with nothing left to run
    Task task = std::move(queue_.front());
    queue_.pop_front();
    ++running_;
    const auto start = Now();
    const auto started = started_.insert(started_.end(), start);
    lock.unlock();

    task(stop_all_.get_token());
    const double ms = std::chrono::duration<double, std::milli>(Now() - start).count();
    task = nullptr;  // release captured state before reporting idle

    lock.lock();
    started_.erase(started);
    --running_;
    average_task_ms_ = average_task_ms_ == 0.0 ? ms : 0.9 * average_task_ms_ + 0.1 * ms;
    if (queue_.empty() && running_ == 0) idle_cv_.notify_all();
  }
}

}  // namespace tempokey::server
