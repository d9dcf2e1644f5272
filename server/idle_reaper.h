// Ends streaming calls whose peer went quiet. A call arms its timer while it waits on the client
// (a read outstanding: the client must send its next message; a write outstanding: the client
// must take the message) and disarms it when that completes; a timer left armed for the whole
// timeout fires once, calling the call's idle handler on the reaper's thread.
//
// No gRPC in here, so it is unit-tested under ThreadSanitizer.
#ifndef TEMPOKEY_SERVER_IDLE_REAPER_H_
#define TEMPOKEY_SERVER_IDLE_REAPER_H_

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include "absl/base/thread_annotations.h"

namespace tempokey::server {

class IdleReaper {
 public:
  using Clock = std::chrono::steady_clock;

  // One call's countdown. Thread-safe.
  class Timer : public std::enable_shared_from_this<Timer> {
   public:
    // Starts the countdown again from now.
    void Arm();
    // Stops the countdown.
    void Disarm();
    // The call ended: the handler never runs again; if it is running on another thread, waits
    // for it to return. Idempotent.
    void Close();
    // Times the handler ran (0 or 1).
    int fired() const;

   private:
    friend class IdleReaper;
    Timer(IdleReaper* reaper, std::function<void()> on_idle)
        : reaper_(reaper), on_idle_(std::move(on_idle)) {}

    IdleReaper* const reaper_;
    const std::function<void()> on_idle_;
    mutable std::mutex mu_;
    std::condition_variable done_cv_;
    bool armed_ ABSL_GUARDED_BY(mu_) = false;
    bool scheduled_ ABSL_GUARDED_BY(mu_) = false;  // has an entry in the reaper's queue
    bool closed_ ABSL_GUARDED_BY(mu_) = false;
    bool firing_ ABSL_GUARDED_BY(mu_) = false;
    std::thread::id firing_thread_ ABSL_GUARDED_BY(mu_);
    int fired_ ABSL_GUARDED_BY(mu_) = 0;
    Clock::time_point deadline_ ABSL_GUARDED_BY(mu_);
  };

  // `timeout` <= 0 disables it: timers never fire and no thread runs.
  explicit IdleReaper(std::chrono::milliseconds timeout);
  // Stops the thread; pending timers never fire.
  ~IdleReaper();
  IdleReaper(const IdleReaper&) = delete;
  IdleReaper& operator=(const IdleReaper&) = delete;

  // A disarmed timer whose handler `on_idle` must not call the timer's Arm/Disarm/Close (it may
  // end the call, whose teardown then calls Close() from another thread).
  std::shared_ptr<Timer> NewTimer(std::function<void()> on_idle);

  std::chrono::milliseconds timeout() const { return timeout_; }

 private:
  void Schedule(const std::shared_ptr<Timer>& timer, Clock::time_point deadline);
  void Loop();

  const std::chrono::milliseconds timeout_;
  std::mutex mu_;
  std::condition_variable wake_;
  // Deadlines to look at, at most one per timer; a timer re-armed since its entry was queued is
  // queued again at its new deadline.
  std::multimap<Clock::time_point, std::weak_ptr<Timer>> due_ ABSL_GUARDED_BY(mu_);
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  std::thread thread_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_IDLE_REAPER_H_
