// Which of a pipeline's progress reports a Process call streams to its client, and when. A
// pipeline reports progress per channel and per stage; a message per report would make a short
// call's client read more progress than result, and each message costs the server a write and a
// hand-off between the worker and gRPC's threads (paired runs of bench/service_bench: a
// 132-channel x 128-frame retime's round trip p50 fell from 1.6-2.0 ms to 1.2-1.4 ms with one
// message instead of 6-7). So:
//   - the first report is sent at once: it tells the client its pipeline left the queue;
//   - a report that repeats the last one sent (same stage, fraction within a percent) is dropped;
//   - any other report is sent at once if `interval` has passed since the last one sent, and
//     otherwise deferred: the latest deferred report is sent when the interval ends (the caller
//     sets a timer for deferred_due()), unless a newer report or the result comes first. So the
//     client never keeps a stale stage for longer than the interval, and a short call's client
//     gets its first report and its result.
//
// No gRPC and no clock of its own (the caller passes the time), so it is unit-tested with chosen
// times. Not thread-safe: the caller serializes calls.
#ifndef TEMPOKEY_SERVER_PROGRESS_THROTTLE_H_
#define TEMPOKEY_SERVER_PROGRESS_THROTTLE_H_

#include <chrono>
#include <optional>
#include <string>
#include <string_view>

namespace tempokey::server {

struct ProgressReport {
  double fraction = 0.0;  // 0..1
  std::string stage;
};

class ProgressThrottle {
 public:
  using Clock = std::chrono::steady_clock;

  enum class Verdict {
    kSend,   // send it now; it is the last one sent
    kDefer,  // kept as the deferred report (replacing an older one), due at deferred_due()
    kDrop,   // a repeat of the last report sent
  };

  // `interval` >= 0; 0 sends every report that is not a repeat.
  explicit ProgressThrottle(Clock::duration interval) : interval_(interval) {}

  // What to do with a report of `fraction` at `stage`, made at `now` (never earlier than the
  // previous call's `now`).
  Verdict Offer(double fraction, std::string_view stage, Clock::time_point now);

  // When the deferred report is due (the last send plus the interval); nullopt without one.
  std::optional<Clock::time_point> deferred_due() const;

  // The deferred report, now the last one sent at `now`; nullopt without one, or before it is
  // due (then deferred_due() tells when).
  std::optional<ProgressReport> TakeDeferred(Clock::time_point now);

 private:
  bool IsRepeat(double fraction, std::string_view stage) const;

  Clock::duration interval_;
  bool sent_any_ = false;
  ProgressReport last_sent_;
  Clock::time_point last_sent_at_;
  std::optional<ProgressReport> deferred_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_PROGRESS_THROTTLE_H_
