// How `tempokey batch` shows its progress on stderr: on a terminal, one self-rewriting bar with
// the files done, skipped and failed, the throughput and the time left; without one (CI logs),
// one line per finished file. The texts are pure functions of the counts, tested as such.
#ifndef TEMPOKEY_CLIENT_PROGRESS_BAR_H_
#define TEMPOKEY_CLIENT_PROGRESS_BAR_H_

#include <chrono>
#include <ostream>
#include <string>
#include <string_view>

#include "client/batch.h"

namespace tempokey::client {

// Files of a batch so far.
struct BatchCounts {
  int total = 0;
  int done = 0;     // processed and written
  int skipped = 0;  // up to date from an earlier run
  int failed = 0;

  int finished() const { return done + skipped + failed; }
  bool operator==(const BatchCounts&) const = default;
};

// "1:02:03" for 3723 s, "2:03" under an hour, "--:--" for a negative or non-finite value.
std::string FormatDuration(double seconds);

// The terminal bar, exactly `width` columns when width >= 60 (narrower terminals get the text
// without the bar):
//   "[#######-----------]  52/200  40 done  10 skipped  2 failed  3.1 files/s  0:48 left"
// Throughput counts the files sent to a server (done + failed) over `elapsed_seconds`; the time
// left is the files not finished yet at that rate ("--:--" before the first such file, "0:00"
// once all are finished). Thread-safe: a pure function.
std::string RenderBatchBar(const BatchCounts& counts, double elapsed_seconds, int width);

// The log line of one finished file, the `finished`-th of `total`, with no line break:
//   "[ 52/200] ok walk.bvh -> out/walk.json (1 attempt, 0.412 s)"
//   "[ 53/200] skipped run.bvh -> out/run.json (up to date)"
//   "[ 54/200] failed broken.bvh (0 attempts, 0.001 s): in/broken.bvh:96:24: expected ..."
// The count is padded to the width of `total`. Thread-safe: a pure function.
std::string FormatBatchLogLine(const BatchFileResult& file, int finished, int total);

enum class ProgressMode { kNone, kLines, kBar };

// Shows a batch's progress on `err` in `mode`. FileDone() is called once per finished file, one
// call at a time (RunBatch's BatchFileDoneFn); Finish() erases the bar. Not thread-safe.
class BatchProgressDisplay {
 public:
  BatchProgressDisplay(std::ostream& err, ProgressMode mode, int total, int width);
  ~BatchProgressDisplay() { Finish(); }
  BatchProgressDisplay(const BatchProgressDisplay&) = delete;
  BatchProgressDisplay& operator=(const BatchProgressDisplay&) = delete;

  void FileDone(const BatchFileResult& file);
  void Finish();

  const BatchCounts& counts() const { return counts_; }

 private:
  std::ostream& err_;
  const ProgressMode mode_;
  const int width_;
  const std::chrono::steady_clock::time_point start_;
  BatchCounts counts_;
  std::size_t drawn_ = 0;  // columns of the bar on screen
};

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_PROGRESS_BAR_H_
