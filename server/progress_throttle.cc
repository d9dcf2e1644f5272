#include "server/progress_throttle.h"

#include <cmath>

namespace tempokey::server {

bool ProgressThrottle::ShouldSend(double fraction, std::string_view stage, Clock::time_point now) {
  if (sent_any_) {
    if (stage == last_stage_ && std::abs(fraction - last_fraction_) < 0.01) return false;
    if (now - last_sent_at_ < interval_) return false;
  }
  sent_any_ = true;
  last_stage_ = std::string(stage);
  last_fraction_ = fraction;
  last_sent_at_ = now;
  return true;
}

}  // namespace tempokey::server
