// ProgressThrottle with chosen times: the first report goes out at once; a repeat of the last one
// sent is dropped; any other report inside the interval is deferred, the latest one kept and due
// when the interval ends.
#include "server/progress_throttle.h"

#include <chrono>

#include "gtest/gtest.h"

namespace tempokey::server {
namespace {

using std::chrono::milliseconds;
using Clock = ProgressThrottle::Clock;
using Verdict = ProgressThrottle::Verdict;

const Clock::time_point kStart = Clock::time_point() + std::chrono::hours(1);

// On a throttle of 100 ms: sends "retime" 0.0 at kStart, defers 0.2 at kStart + `deferred_at`
// and flushes it when due, at kStart + 100 ms.
void SendDeferAndFlush(ProgressThrottle& throttle, milliseconds deferred_at) {
  ASSERT_EQ(throttle.Offer(0.0, "retime", kStart), Verdict::kSend);
  ASSERT_EQ(throttle.Offer(0.2, "retime", kStart + deferred_at), Verdict::kDefer);
  ASSERT_TRUE(throttle.TakeDeferred(kStart + milliseconds(100)).has_value());
}

TEST(ProgressThrottleTest, TheFirstReportIsSentWhateverTheInterval) {
  ProgressThrottle throttle(std::chrono::hours(1));

  EXPECT_EQ(throttle.Offer(0.0, "retime", kStart), Verdict::kSend);
  EXPECT_FALSE(throttle.deferred_due().has_value());
}

TEST(ProgressThrottleTest, ReportsInsideTheIntervalAreDeferredAndTheLatestIsDueWhenItEnds) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_EQ(throttle.Offer(0.0, "retime 1/2", kStart), Verdict::kSend);

  EXPECT_EQ(throttle.Offer(0.5, "retime 2/2", kStart + milliseconds(10)), Verdict::kDefer);
  EXPECT_EQ(throttle.Offer(0.5, "reduce", kStart + milliseconds(20)), Verdict::kDefer);
  ASSERT_EQ(throttle.deferred_due(), kStart + milliseconds(100));
  const std::optional<ProgressReport> due = throttle.TakeDeferred(kStart + milliseconds(100));

  ASSERT_TRUE(due.has_value());
  EXPECT_EQ(due->stage, "reduce");
  EXPECT_EQ(due->fraction, 0.5);
  EXPECT_FALSE(throttle.deferred_due().has_value());
  EXPECT_FALSE(throttle.TakeDeferred(kStart + milliseconds(150)).has_value());
}

TEST(ProgressThrottleTest, TheIntervalCountsFromTheLastReportSentEvenAFlushedOne) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_NO_FATAL_FAILURE(SendDeferAndFlush(throttle, milliseconds(50)));

  EXPECT_EQ(throttle.Offer(0.3, "retime", kStart + milliseconds(150)), Verdict::kDefer);
  EXPECT_EQ(throttle.deferred_due(), kStart + milliseconds(200));
  EXPECT_EQ(throttle.Offer(0.4, "retime", kStart + milliseconds(200)), Verdict::kSend);
  // Sent at once: nothing is left to flush.
  EXPECT_FALSE(throttle.deferred_due().has_value());
}

TEST(ProgressThrottleTest, ADeferredReportIsNotTakenBeforeItIsDue) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_EQ(throttle.Offer(0.0, "channel 1", kStart), Verdict::kSend);
  ASSERT_EQ(throttle.Offer(0.1, "channel 2", kStart + milliseconds(10)), Verdict::kDefer);
  // The worker reaches the due time first and sends; then it defers another report.
  ASSERT_EQ(throttle.Offer(0.2, "channel 3", kStart + milliseconds(100)), Verdict::kSend);
  ASSERT_EQ(throttle.Offer(0.3, "channel 4", kStart + milliseconds(101)), Verdict::kDefer);

  // A timer set for the first due time fires late.
  EXPECT_FALSE(throttle.TakeDeferred(kStart + milliseconds(102)).has_value());
  EXPECT_EQ(throttle.deferred_due(), kStart + milliseconds(200));
  const std::optional<ProgressReport> due = throttle.TakeDeferred(kStart + milliseconds(200));
  ASSERT_TRUE(due.has_value());
  EXPECT_EQ(due->stage, "channel 4");
}

TEST(ProgressThrottleTest, AFlushedReportCountsAsTheLastOneSent) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_NO_FATAL_FAILURE(SendDeferAndFlush(throttle, milliseconds(10)));

  EXPECT_EQ(throttle.Offer(0.205, "retime", kStart + milliseconds(300)), Verdict::kDrop);
}

TEST(ProgressThrottleTest, ARepeatOfTheLastReportSentIsDroppedHoweverLateItComes) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_EQ(throttle.Offer(0.5, "reduce", kStart), Verdict::kSend);

  EXPECT_EQ(throttle.Offer(0.509, "reduce", kStart + std::chrono::hours(2)), Verdict::kDrop);
  EXPECT_EQ(throttle.Offer(0.51, "reduce", kStart + std::chrono::hours(2)), Verdict::kSend);
}

TEST(ProgressThrottleTest, ARepeatOfTheLastReportSentCancelsTheDeferredOne) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_EQ(throttle.Offer(0.5, "reduce", kStart), Verdict::kSend);
  ASSERT_EQ(throttle.Offer(0.6, "reduce", kStart + milliseconds(10)), Verdict::kDefer);

  // The latest state is what the client already shows.
  EXPECT_EQ(throttle.Offer(0.5, "reduce", kStart + milliseconds(20)), Verdict::kDrop);
  EXPECT_FALSE(throttle.TakeDeferred(kStart + milliseconds(100)).has_value());
}

TEST(ProgressThrottleTest, AZeroIntervalSendsEveryReportButRepeats) {
  ProgressThrottle throttle(milliseconds(0));
  ASSERT_EQ(throttle.Offer(0.0, "retime", kStart), Verdict::kSend);

  EXPECT_EQ(throttle.Offer(0.005, "retime", kStart), Verdict::kDrop);
  EXPECT_EQ(throttle.Offer(0.01, "retime", kStart), Verdict::kSend);
  EXPECT_EQ(throttle.Offer(0.01, "reduce", kStart), Verdict::kSend);
  EXPECT_EQ(throttle.Offer(0.015, "reduce", kStart), Verdict::kDrop);
}

}  // namespace
}  // namespace tempokey::server
