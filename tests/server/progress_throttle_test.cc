// ProgressThrottle with chosen times: the first report always goes out; later ones need a new
// stage or a percent of movement, and the interval since the last one sent.
#include "server/progress_throttle.h"

#include <chrono>

#include "gtest/gtest.h"

namespace tempokey::server {
namespace {

using std::chrono::milliseconds;
using Clock = ProgressThrottle::Clock;

const Clock::time_point kStart = Clock::time_point() + std::chrono::hours(1);

TEST(ProgressThrottleTest, TheFirstReportIsSentWhateverTheInterval) {
  ProgressThrottle throttle(std::chrono::hours(1));

  EXPECT_TRUE(throttle.ShouldSend(0.0, "retime", kStart));
}

TEST(ProgressThrottleTest, ReportsInsideTheIntervalAreDroppedAndTheNextOnePastItIsSent) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_TRUE(throttle.ShouldSend(0.0, "retime", kStart));

  EXPECT_FALSE(throttle.ShouldSend(0.5, "retime", kStart + milliseconds(10)));
  EXPECT_FALSE(throttle.ShouldSend(0.0, "reduce", kStart + milliseconds(99)));
  EXPECT_TRUE(throttle.ShouldSend(0.2, "reduce", kStart + milliseconds(100)));
  // The interval counts from the last report sent, not from the last one made.
  EXPECT_FALSE(throttle.ShouldSend(0.3, "reduce", kStart + milliseconds(199)));
  EXPECT_TRUE(throttle.ShouldSend(0.3, "reduce", kStart + milliseconds(200)));
}

TEST(ProgressThrottleTest, ARepeatOfTheLastReportSentIsDroppedHoweverLateItComes) {
  ProgressThrottle throttle(milliseconds(100));
  ASSERT_TRUE(throttle.ShouldSend(0.5, "reduce", kStart));

  EXPECT_FALSE(throttle.ShouldSend(0.509, "reduce", kStart + std::chrono::hours(2)));
  EXPECT_TRUE(throttle.ShouldSend(0.51, "reduce", kStart + std::chrono::hours(2)));
}

TEST(ProgressThrottleTest, AZeroIntervalSendsEveryNewStageAndEveryPercent) {
  ProgressThrottle throttle(milliseconds(0));
  ASSERT_TRUE(throttle.ShouldSend(0.0, "retime", kStart));

  EXPECT_FALSE(throttle.ShouldSend(0.005, "retime", kStart));
  EXPECT_TRUE(throttle.ShouldSend(0.01, "retime", kStart));
  EXPECT_TRUE(throttle.ShouldSend(0.01, "reduce", kStart));
  EXPECT_FALSE(throttle.ShouldSend(0.015, "reduce", kStart));
}

}  // namespace
}  // namespace tempokey::server
