// Which of a pipeline's progress reports a Process call streams to its client. A pipeline reports
// progress per channel and per stage; a message per report would make a short call's client read
// more progress than result, and each message costs the server a write and a hand-off between
// the worker and gRPC's threads (paired runs of bench/service_bench: a 132-channel x 128-frame
// retime's round trip p50 fell from 1.6-2.0 ms to 1.2-1.4 ms with one message instead of 6-7).
// So:
//   - the first report is always sent: it tells the client its pipeline left the queue;
//   - after it, a report is sent only if its stage differs or its fraction moved by at least a
//     percent since the last one sent (latest wins, never a backlog), and at least `interval`
//     after the last one sent. A report inside the interval is dropped, not delayed: the next
//     report past it carries the newer state, and the result supersedes them all.
//
// No gRPC and no clock of its own (the caller passes the time), so it is unit-tested with
// chosen times. Not thread-safe: the caller serializes reports.
#ifndef TEMPOKEY_SERVER_PROGRESS_THROTTLE_H_
#define TEMPOKEY_SERVER_PROGRESS_THROTTLE_H_

#include <chrono>
#include <string>
#include <string_view>

namespace tempokey::server {

class ProgressThrottle {
 public:
  using Clock = std::chrono::steady_clock;

  // `interval` >= 0; 0 sends every report that moved by a stage or a percent.
  explicit ProgressThrottle(Clock::duration interval) : interval_(interval) {}

  // Whether a report of `fraction` (0..1) at `stage`, made at `now`, is to be sent; if so it
  // becomes the last one sent. `now` never goes back between calls.
  bool ShouldSend(double fraction, std::string_view stage, Clock::time_point now);

 private:
  Clock::duration interval_;
  bool sent_any_ = false;
  std::string last_stage_;
  double last_fraction_ = 0.0;
  Clock::time_point last_sent_at_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_PROGRESS_THROTTLE_H_
