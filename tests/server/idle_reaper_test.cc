// IdleReaper: an armed timer fires once after the timeout, a disarmed or closed one never does,
// Close() waits for a handler running on the reaper's thread. The waits are bounded by a hang
// guard; what is asserted never depends on how fast the machine is.
#include "server/idle_reaper.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include "gtest/gtest.h"

namespace tempokey::server {
namespace {

constexpr auto kHangGuard = std::chrono::seconds(60);

// Counts handler runs and lets a test wait for one.
class Fired {
 public:
  void Record() {
    std::lock_guard lock(mu_);
    ++count_;
    cv_.notify_all();
  }
  bool WaitFor(int count) {
    std::unique_lock lock(mu_);
    return cv_.wait_for(lock, kHangGuard, [&] { return count_ >= count; });
  }
  int count() {
    std::lock_guard lock(mu_);
    return count_;
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  int count_ = 0;
};

TEST(IdleReaperTest, ArmedTimerFiresOnceAfterTheTimeout) {
  IdleReaper reaper(std::chrono::milliseconds(20));
  Fired fired;
  std::shared_ptr<IdleReaper::Timer> timer = reaper.NewTimer([&] { fired.Record(); });
  const auto armed_at = std::chrono::steady_clock::now();

  timer->Arm();
  ASSERT_TRUE(fired.WaitFor(1));
  const auto fired_after = std::chrono::steady_clock::now() - armed_at;
  timer->Arm();  // a fired timer stays fired
  timer->Close();

  EXPECT_GE(fired_after, std::chrono::milliseconds(20));  // never early
  EXPECT_EQ(timer->fired(), 1);
  EXPECT_EQ(fired.count(), 1);
}

TEST(IdleReaperTest, DisarmedOrClosedTimersNeverFire) {
  Fired fired;
  std::shared_ptr<IdleReaper::Timer> disarmed;
  std::shared_ptr<IdleReaper::Timer> closed;
  {
    IdleReaper reaper(std::chrono::milliseconds(10));
    disarmed = reaper.NewTimer([&] { fired.Record(); });
    closed = reaper.NewTimer([&] { fired.Record(); });
    // A third timer that does fire tells when the reaper has looked past the others' deadlines.
    Fired witness;
    std::shared_ptr<IdleReaper::Timer> later = reaper.NewTimer([&] { witness.Record(); });

    disarmed->Arm();
    closed->Arm();
    disarmed->Disarm();
    closed->Close();
    later->Arm();
    ASSERT_TRUE(witness.WaitFor(1));
    later->Close();
  }

  EXPECT_EQ(fired.count(), 0);
  EXPECT_EQ(disarmed->fired(), 0);
  EXPECT_EQ(closed->fired(), 0);
}

TEST(IdleReaperTest, CloseWaitsForARunningHandler) {
  IdleReaper reaper(std::chrono::milliseconds(1));
  std::mutex mu;
  std::condition_variable cv;
  bool entered = false;
  bool release = false;
  std::atomic<bool> handler_done{false};
  std::shared_ptr<IdleReaper::Timer> timer = reaper.NewTimer([&] {
    std::unique_lock lock(mu);
    entered = true;
    cv.notify_all();
    cv.wait(lock, [&] { return release; });
    handler_done = true;
  });
  timer->Arm();
  {
    std::unique_lock lock(mu);
    ASSERT_TRUE(cv.wait_for(lock, kHangGuard, [&] { return entered; }));
  }

  std::thread releaser([&] {
    std::lock_guard lock(mu);
    release = true;
    cv.notify_all();
  });
  timer->Close();  // returns only once the handler has
  const bool done_when_closed = handler_done.load();
  releaser.join();

  EXPECT_TRUE(done_when_closed);
}

TEST(IdleReaperTest, ZeroTimeoutDisablesEveryTimer) {
  IdleReaper reaper(std::chrono::milliseconds(0));
  Fired fired;
  std::shared_ptr<IdleReaper::Timer> timer = reaper.NewTimer([&] { fired.Record(); });

  timer->Arm();
  timer->Close();

  EXPECT_EQ(fired.count(), 0);
}

}  // namespace
}  // namespace tempokey::server
