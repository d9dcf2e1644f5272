// The server's own fixed pool of worker threads with a bounded queue: every pipeline (jobs and
// Process calls) runs here, never on a gRPC thread. No gRPC in here, so it is unit-tested under
// ThreadSanitizer.
#ifndef TEMPOKEY_SERVER_JOB_POOL_H_
#define TEMPOKEY_SERVER_JOB_POOL_H_

#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <list>
#include <mutex>
#include <stop_token>
#include <thread>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/functional/any_invocable.h"
#include "absl/status/status.h"

namespace tempokey::server {

class JobPool {
 public:
  // A unit of work. `pool_stop` is requested by RequestStopAll() (drain deadline); a task that
  // runs long should forward it to its own cancellation.
  using Task = absl::AnyInvocable<void(std::stop_token pool_stop)>;
  using Clock = std::function<std::chrono::steady_clock::time_point()>;

  // Starts `workers` threads (>= 1) over a queue of at most `queue_capacity` (>= 1) tasks.
  // `clock` (tests) replaces steady_clock::now() for task durations and the retry hint.
  JobPool(int workers, int queue_capacity, Clock clock = {});
  // Shutdown().
  ~JobPool();
  JobPool(const JobPool&) = delete;
  JobPool& operator=(const JobPool&) = delete;

  // Queues `task` for a worker; never blocks.
  // Errors: kResourceExhausted when the queue holds queue_capacity tasks, with a retry hint
  //         (wire::SetRetryAfter()): when the first running task should end, so a queue slot
  //         frees, from how long each has run and how long finished tasks took (a task already
  //         past the usual duration is expected to run as long again); 10 ms to 60 s.
  //         kUnavailable after Shutdown() began.
  absl::Status TrySubmit(Task task);

  int workers() const { return static_cast<int>(threads_.size()); }
  int queue_capacity() const { return queue_capacity_; }
  // Tasks waiting for a worker / running now.
  int queue_depth() const;
  int running() const;

  // Blocks until nothing is queued or running, or until `deadline`. True when idle.
  bool WaitIdle(std::chrono::steady_clock::time_point deadline) const;
  // Requests `pool_stop` of running and future tasks (they still run, to finish their calls).
  void RequestStopAll();
  // Refuses new tasks, lets the workers run every queued task, joins them. Idempotent.
  void Shutdown();

  // Thread-safety: every method may be called from any thread, except that Shutdown() and the
  // destructor must not run on a worker.

 private:
  void WorkerLoop();
  std::chrono::milliseconds RetryAfterHintLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  std::chrono::steady_clock::time_point Now() const;

  const int queue_capacity_;
  const Clock clock_;
  mutable std::mutex mu_;
  std::condition_variable work_cv_;          // a task was queued, or shutdown began
  mutable std::condition_variable idle_cv_;  // the pool became idle
  std::deque<Task> queue_ ABSL_GUARDED_BY(mu_);
  int running_ ABSL_GUARDED_BY(mu_) = 0;
  // When each running task started.
  std::list<std::chrono::steady_clock::time_point> started_ ABSL_GUARDED_BY(mu_);
  bool shutting_down_ ABSL_GUARDED_BY(mu_) = false;
  double average_task_ms_ ABSL_GUARDED_BY(mu_) = 0.0;  // exponential moving average
  std::stop_source stop_all_;                // thread-safe by itself
  std::vector<std::thread> threads_;         // set in the constructor, joined by Shutdown()
  std::once_flag join_once_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_JOB_POOL_H_
