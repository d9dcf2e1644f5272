#include "server/progress_throttle.h"

#include <cmath>
#include <utility>

namespace tempokey::server {

bool ProgressThrottle::IsRepeat(double fraction, std::string_view stage) const {
  return stage == last_sent_.stage && std::abs(fraction - last_sent_.fraction) < 0.01;
}

ProgressThrottle::Verdict ProgressThrottle::Offer(double fraction, std::string_view stage,
                                                  Clock::time_point now) {
  if (sent_any_) {
    if (IsRepeat(fraction, stage)) {
      deferred_.reset();  // the client already shows it
      return Verdict::kDrop;
    }
    if (now - last_sent_at_ < interval_) {
      deferred_ = ProgressReport{fraction, std::string(stage)};
      return Verdict::kDefer;
    }
  }
  sent_any_ = true;
  deferred_.reset();
  last_sent_ = ProgressReport{fraction, std::string(stage)};
  last_sent_at_ = now;
  return Verdict::kSend;
}

std::optional<ProgressThrottle::Clock::time_point> ProgressThrottle::deferred_due() const {
  if (!deferred_) return std::nullopt;
  return last_sent_at_ + interval_;
}

std::optional<ProgressReport> ProgressThrottle::TakeDeferred(Clock::time_point now) {
  // Not before it is due: a timer set for an earlier due time (the worker sent a report at that
  // time itself, then deferred another) must not send two within the interval.
  const std::optional<Clock::time_point> due = deferred_due();
  if (!due || now < *due) return std::nullopt;
  last_sent_ = *std::move(deferred_);
  deferred_.reset();
  last_sent_at_ = now;
  return last_sent_;
}

}  // namespace tempokey::server
