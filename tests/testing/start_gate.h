// Holds jobs at the start of their pipeline (the server's on_job_start test hook) until the test
// opens it: a real worker, really blocked, so a test can cancel or drain while a job runs.
// Every wait is bounded, so a broken test fails instead of hanging.
#ifndef TEMPOKEY_TESTS_TESTING_START_GATE_H_
#define TEMPOKEY_TESTS_TESTING_START_GATE_H_

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <string_view>

namespace tempokey::testing {

class StartGate {
 public:
  static constexpr std::chrono::seconds kWaitLimit{60};

  // Called by the worker (the hook): counts the arrival, then waits for Open().
  void Arrive(std::string_view /*job_id*/ = {}) {
    std::unique_lock lock(mutex_);
    ++arrived_;
    changed_.notify_all();
    changed_.wait_for(lock, kWaitLimit, [&] { return open_; });
  }
  // True once `count` jobs have arrived, false if that takes longer than kWaitLimit.
  bool WaitArrivals(int count) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, kWaitLimit, [&] { return arrived_ >= count; });
  }
  void Open() {
    std::lock_guard lock(mutex_);
    open_ = true;
    changed_.notify_all();
  }
  int arrived() {
    std::lock_guard lock(mutex_);
    return arrived_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  int arrived_ = 0;
  bool open_ = false;
};

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_TESTING_START_GATE_H_
