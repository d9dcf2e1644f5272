// JobPool: fixed workers, bounded queue, drain behaviour. No gRPC: runs under ThreadSanitizer.
#include "server/job_pool.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <latch>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/retry_hint.h"

namespace tempokey::server {
namespace {

using ::testing::HasSubstr;

// Deadline for waits that succeed on a working pool; reaching it fails the test, not CI.
constexpr auto kHangGuard = std::chrono::seconds(60);

auto Deadline() { return std::chrono::steady_clock::now() + kHangGuard; }

// A gate tasks block on until the test opens it.
class Gate {
 public:
  void Wait() {
    std::unique_lock lock(mu_);
    cv_.wait(lock, [&] { return open_; });
  }
  void Open() {
    {
      std::lock_guard lock(mu_);
      open_ = true;
    }
    cv_.notify_all();
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  bool open_ = false;
};

TEST(JobPoolTest, RunsEveryTaskOnItsOwnWorkers) {
  JobPool pool(3, 100);
  std::atomic<int> ran{0};
  std::mutex mu;
  std::set<std::thread::id> threads;

  for (int i = 0; i < 100; ++i) {
    ASSERT_TRUE(pool.TrySubmit([&](std::stop_token) {
                      ran.fetch_add(1);
                      std::lock_guard lock(mu);
                      threads.insert(std::this_thread::get_id());
                    })
                    .ok());
  }
  ASSERT_TRUE(pool.WaitIdle(Deadline()));

  EXPECT_EQ(ran.load(), 100);
  EXPECT_EQ(pool.workers(), 3);
  EXPECT_LE(threads.size(), 3u);
  EXPECT_FALSE(threads.contains(std::this_thread::get_id()));
}

TEST(JobPoolTest, FullQueueRefusesWithRetryHintAndRecovers) {
  JobPool pool(1, 2);
  Gate gate;
  std::latch started(1);
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token) {
                    started.count_down();
                    gate.Wait();
                  })
                  .ok());
  started.wait();  // the worker holds task 1; the queue is empty
  ASSERT_TRUE(pool.TrySubmit([](std::stop_token) {}).ok());
  ASSERT_TRUE(pool.TrySubmit([](std::stop_token) {}).ok());

  absl::Status full = pool.TrySubmit([](std::stop_token) {});

  EXPECT_EQ(full.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(full.message()), HasSubstr("the job queue is full (2 waiting for 1 workers)"));
  ASSERT_TRUE(wire::GetRetryAfter(full).has_value());
  EXPECT_GE(wire::GetRetryAfter(full)->count(), 10);
  EXPECT_EQ(pool.queue_depth(), 2);
  EXPECT_EQ(pool.running(), 1);
  gate.Open();
  ASSERT_TRUE(pool.WaitIdle(Deadline()));
  EXPECT_TRUE(pool.TrySubmit([](std::stop_token) {}).ok());
}

// A clock the test moves by hand, so durations are exact and no test waits for time to pass.
class ManualClock {
 public:
  JobPool::Clock AsClock() {
    return [this] {
      return std::chrono::steady_clock::time_point(std::chrono::nanoseconds(now_ns_.load()));
    };
  }
  void Advance(std::chrono::milliseconds by) {
    now_ns_.fetch_add(std::chrono::duration_cast<std::chrono::nanoseconds>(by).count());
  }

 private:
  std::atomic<std::int64_t> now_ns_{std::int64_t{3'600} * 1'000'000'000};
};

std::int64_t HintMs(const absl::Status& status) {
  return wire::GetRetryAfter(status).value_or(std::chrono::milliseconds(-1)).count();
}

TEST(JobPoolTest, RetryHintFollowsHowLongTheRunningTasksHaveRunAndTake) {
  ManualClock clock;
  JobPool pool(2, 1, clock.AsClock());
  // History: one task that took 20 s.
  Gate first_gate;
  std::latch first_started(1);
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token) {
                    first_started.count_down();
                    first_gate.Wait();
                  })
                  .ok());
  first_started.wait();
  clock.Advance(std::chrono::seconds(20));
  first_gate.Open();
  ASSERT_TRUE(pool.WaitIdle(Deadline()));
  // Now both workers hold a task: one started 16 s ago, one 25 s ago; the queue is full.
  Gate gate;
  std::latch first(1);
  std::latch second(1);
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token) {
                    first.count_down();
                    gate.Wait();
                  })
                  .ok());
  first.wait();  // started at the clock's time now
  clock.Advance(std::chrono::seconds(9));
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token) {
                    second.count_down();
                    gate.Wait();
                  })
                  .ok());
  second.wait();
  ASSERT_TRUE(pool.TrySubmit([](std::stop_token) {}).ok());  // queued
  clock.Advance(std::chrono::seconds(16));

  const absl::Status busy = pool.TrySubmit([](std::stop_token) {});
  clock.Advance(std::chrono::seconds(10));  // 26 s and 35 s: both past the usual 20 s
  const absl::Status overdue = pool.TrySubmit([](std::stop_token) {});
  gate.Open();
  ASSERT_TRUE(pool.WaitIdle(Deadline()));

  // The 16 s task should end in 4 s (finished tasks took 20 s): the first slot frees then.
  EXPECT_EQ(busy.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(HintMs(busy), 4'000);
  // Past the usual duration, a task is expected to run as long again: 26 s more at least.
  EXPECT_EQ(HintMs(overdue), 26'000);
}

TEST(JobPoolTest, RetryHintWithoutHistoryIsHowLongTheTaskHasRun) {
  ManualClock clock;
  JobPool pool(1, 1, clock.AsClock());
  Gate gate;
  std::latch started(1);
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token) {
                    started.count_down();
                    gate.Wait();
                  })
                  .ok());
  started.wait();
  ASSERT_TRUE(pool.TrySubmit([](std::stop_token) {}).ok());

  const absl::Status fresh = pool.TrySubmit([](std::stop_token) {});
  clock.Advance(std::chrono::seconds(16));
  const absl::Status long_running = pool.TrySubmit([](std::stop_token) {});
  clock.Advance(std::chrono::minutes(5));
  const absl::Status very_long = pool.TrySubmit([](std::stop_token) {});
  gate.Open();
  ASSERT_TRUE(pool.WaitIdle(Deadline()));

  EXPECT_EQ(HintMs(fresh), 10);  // the floor
  EXPECT_EQ(HintMs(long_running), 16'000);
  EXPECT_EQ(HintMs(very_long), 60'000);  // the ceiling
}

TEST(JobPoolTest, ShutdownRunsQueuedTasksThenRefusesNewOnes) {
  std::atomic<int> ran{0};
  auto pool = std::make_unique<JobPool>(1, 10);
  Gate gate;
  ASSERT_TRUE(pool->TrySubmit([&](std::stop_token) { gate.Wait(); }).ok());
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(pool->TrySubmit([&](std::stop_token) { ran++; }).ok());

  std::thread opener([&] { gate.Open(); });
  pool->Shutdown();
  opener.join();

  EXPECT_EQ(ran.load(), 5);
  EXPECT_EQ(pool->TrySubmit([](std::stop_token) {}).code(), absl::StatusCode::kUnavailable);
}

TEST(JobPoolTest, RequestStopAllReachesRunningAndLaterTasks) {
  JobPool pool(1, 10);
  std::latch started(1);
  std::atomic<bool> running_saw_stop{false};
  std::atomic<bool> later_saw_stop{false};
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token stop) {
                    started.count_down();
                    while (!stop.stop_requested()) std::this_thread::yield();
                    running_saw_stop = true;
                  })
                  .ok());
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token stop) { later_saw_stop = stop.stop_requested(); })
                  .ok());
  started.wait();

  pool.RequestStopAll();
  ASSERT_TRUE(pool.WaitIdle(Deadline()));

  EXPECT_TRUE(running_saw_stop.load());
  EXPECT_TRUE(later_saw_stop.load());
}

TEST(JobPoolTest, ConcurrentSubmittersNeverExceedTheQueueAndLoseNothing) {
  constexpr int kThreads = 8;
  constexpr int kPerThread = 500;
  JobPool pool(2, 16);
  std::atomic<int> accepted{0};
  std::atomic<int> refused{0};
  std::atomic<int> ran{0};
  std::atomic<int> max_depth{0};

  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < kPerThread; ++i) {
        absl::Status status = pool.TrySubmit([&](std::stop_token) { ran++; });
        if (status.ok()) {
          accepted++;
        } else {
          EXPECT_EQ(status.code(), absl::StatusCode::kResourceExhausted);
          refused++;
        }
        int depth = pool.queue_depth();
        int seen = max_depth.load();
        while (depth > seen && !max_depth.compare_exchange_weak(seen, depth)) {
        }
      }
    });
  }
  for (std::thread& t : threads) t.join();
  ASSERT_TRUE(pool.WaitIdle(Deadline()));

  EXPECT_EQ(accepted.load() + refused.load(), kThreads * kPerThread);
  EXPECT_EQ(ran.load(), accepted.load());
  EXPECT_LE(max_depth.load(), 16);
}

TEST(JobPoolTest, WaitIdleTimesOutWhileATaskRuns) {
  JobPool pool(1, 1);
  Gate gate;
  ASSERT_TRUE(pool.TrySubmit([&](std::stop_token) { gate.Wait(); }).ok());

  const bool idle = pool.WaitIdle(std::chrono::steady_clock::now());

  EXPECT_FALSE(idle);
  gate.Open();
  EXPECT_TRUE(pool.WaitIdle(Deadline()));
}

}  // namespace
}  // namespace tempokey::server
