// The batch's progress texts (client/progress_bar.h) as pure functions of the counts: the
// terminal bar, the per-file log line of CI logs, and the display that chooses between them.
#include "client/progress_bar.h"

#include <limits>
#include <sstream>
#include <string>

#include "absl/status/status.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

TEST(ProgressBarTest, DurationsReadAsClockTime) {
  EXPECT_EQ(FormatDuration(0), "0:00");
  EXPECT_EQ(FormatDuration(49.4), "0:49");
  EXPECT_EQ(FormatDuration(123), "2:03");
  EXPECT_EQ(FormatDuration(3723), "1:02:03");
  EXPECT_EQ(FormatDuration(-1), "--:--");
  EXPECT_EQ(FormatDuration(std::numeric_limits<double>::infinity()), "--:--");
}

// 52 of 200 finished after 14 s, 42 of them sent: 3 files/s, 148 left, 49.3 s.
TEST(ProgressBarTest, BarShowsCountsThroughputAndTimeLeftInExactlyTheWidth) {
  const BatchCounts counts{.total = 200, .done = 40, .skipped = 10, .failed = 2};

  const std::string bar = RenderBatchBar(counts, 14.0, 100);

  EXPECT_EQ(bar,
            "[########--------------------------]   52/200  40 done  10 skipped  2 failed  "
            "3.0 files/s  0:49 left");
  EXPECT_EQ(bar.size(), 100u);
}

TEST(ProgressBarTest, OnlySkippedFilesSoFarGiveNoEstimate) {
  const BatchCounts counts{.total = 200, .skipped = 30};

  EXPECT_EQ(RenderBatchBar(counts, 2.0, 80),
            "[#------------]   30/200  0 done  30 skipped  0 failed  0.00 files/s  --:-- left");
}

TEST(ProgressBarTest, FinishedBatchIsFullWithNothingLeft) {
  const BatchCounts counts{.total = 5, .done = 5};

  EXPECT_EQ(RenderBatchBar(counts, 3.0, 70),
            "[##########]  5/5  5 done  0 skipped  0 failed  1.7 files/s  0:00 left");
}

TEST(ProgressBarTest, NarrowTerminalGetsTheTextWithoutTheBar) {
  const BatchCounts counts{.total = 200, .done = 40, .skipped = 10, .failed = 2};

  EXPECT_EQ(RenderBatchBar(counts, 14.0, 59),
            " 52/200  40 done  10 skipped  2 failed  3.0 files/s  0:49 left");
}

TEST(ProgressBarTest, SlowStartEstimatesHours) {
  const BatchCounts counts{.total = 10000, .done = 1};

  EXPECT_EQ(RenderBatchBar(counts, 3600.0, 100),
            "[-------------------------]      1/10000  1 done  0 skipped  0 failed  0.00 files/s  "
            "9999:00:00 left");
}

TEST(ProgressBarTest, LogLinesNameTheFileItsOutputAndOutcome) {
  BatchFileResult ok{.name = "walk.bvh", .output_path = "out/walk.json", .attempts = 1,
                     .seconds = 0.4124};
  BatchFileResult retried = ok;
  retried.attempts = 3;
  BatchFileResult skipped{.name = "run.bvh", .output_path = "out/run.json", .skipped = true};
  BatchFileResult failed{.name = "broken.bvh",
                         .status = absl::InvalidArgumentError(
                             "in/broken.bvh:96:24: expected 3 numbers after OFFSET, found 1"),
                         .seconds = 0.0009};

  EXPECT_EQ(FormatBatchLogLine(ok, 52, 200),
            "[ 52/200] ok walk.bvh -> out/walk.json (1 attempt, 0.412 s)");
  EXPECT_EQ(FormatBatchLogLine(retried, 200, 200),
            "[200/200] ok walk.bvh -> out/walk.json (3 attempts, 0.412 s)");
  EXPECT_EQ(FormatBatchLogLine(skipped, 7, 12), "[ 7/12] skipped run.bvh -> out/run.json (up to date)");
  EXPECT_EQ(FormatBatchLogLine(failed, 1, 1),
            "[1/1] failed broken.bvh (0 attempts, 0.001 s): in/broken.bvh:96:24: expected 3 "
            "numbers after OFFSET, found 1");
}

// A file name may hold any byte: a line break would split the line, an escape sequence act on
// the terminal. They are shown as the error line shows them.
TEST(ProgressBarTest, LogLinesShowControlCharactersInNamesEscaped) {
  BatchFileResult odd{.name = "a\nb\x1b[2J.bvh", .output_path = "out/a\nb\x1b[2J.json",
                      .attempts = 1, .seconds = 0.5};

  EXPECT_EQ(FormatBatchLogLine(odd, 1, 1),
            "[1/1] ok a b\\x1b[2J.bvh -> out/a b\\x1b[2J.json (1 attempt, 0.500 s)");
}

TEST(ProgressBarTest, LinesModeWritesOneLinePerFileAndCounts) {
  std::ostringstream err;
  BatchProgressDisplay display(err, ProgressMode::kLines, 3, 0);

  display.FileDone({.name = "a.bvh", .output_path = "o/a.json", .attempts = 1, .seconds = 0.25});
  display.FileDone({.name = "b.bvh", .output_path = "o/b.json", .skipped = true});
  display.FileDone({.name = "c.bvh", .status = absl::UnavailableError("c.bvh: server: gone"),
                    .attempts = 5, .seconds = 2.0});
  display.Finish();

  EXPECT_EQ(err.str(),
            "[1/3] ok a.bvh -> o/a.json (1 attempt, 0.250 s)\n"
            "[2/3] skipped b.bvh -> o/b.json (up to date)\n"
            "[3/3] failed c.bvh (5 attempts, 2.000 s): c.bvh: server: gone\n");
  EXPECT_EQ(display.counts(), (BatchCounts{.total = 3, .done = 1, .skipped = 1, .failed = 1}));
}

TEST(ProgressBarTest, BarModeRewritesOneLineAndErasesIt) {
  std::ostringstream err;
  BatchProgressDisplay display(err, ProgressMode::kBar, 2, 81);

  display.FileDone({.name = "a.bvh", .skipped = true});
  display.Finish();

  const std::string text = err.str();
  ASSERT_FALSE(text.empty());
  EXPECT_EQ(text.front(), '\r');
  EXPECT_EQ(text.find('\n'), std::string::npos);
  // The bar (80 columns: the terminal's last one is left free), then spaces over it.
  const std::string bar = text.substr(1, 80);
  EXPECT_THAT(bar, ::testing::StartsWith("[#"));
  EXPECT_THAT(bar, ::testing::EndsWith("1/2  0 done  1 skipped  0 failed  0.00 files/s  --:-- left"));
  EXPECT_EQ(text.substr(81), "\r" + std::string(80, ' ') + "\r");
}

TEST(ProgressBarTest, NoneModeWritesNothing) {
  std::ostringstream err;
  BatchProgressDisplay display(err, ProgressMode::kNone, 1, 80);

  display.FileDone({.name = "a.bvh"});

  EXPECT_EQ(err.str(), "");
  EXPECT_EQ(display.counts().done, 1);
}

}  // namespace
}  // namespace tempokey::client
