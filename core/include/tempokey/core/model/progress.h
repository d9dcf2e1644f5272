// Progress reporting and cancellation shared by long-running core functions.
#ifndef TEMPOKEY_CORE_MODEL_PROGRESS_H_
#define TEMPOKEY_CORE_MODEL_PROGRESS_H_

#include <functional>
#include <stop_token>
#include <string_view>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace tempokey::core {

// Called with the fraction done in [0, 1] and a short stage label ("reduce 12/96"). May be
// called from the thread running the job; must be cheap and must not throw.
using ProgressFn = std::function<void(double fraction, std::string_view stage)>;

// Calls `fn` when it is set.
inline void ReportProgress(const ProgressFn& fn, double fraction, std::string_view stage) {
  if (fn) fn(fraction, stage);
}

// Calls `fn` when it is set, with the label absl::StrCat(parts...) made only then (the core
// reports once per channel; a label made for no listener costs a short clip's retime about 2 %).
template <class... Parts>
void ReportProgressOf(const ProgressFn& fn, double fraction, const Parts&... parts) {
  if (fn) fn(fraction, absl::StrCat(parts...));
}

// kCancelled "cancelled" if a stop was requested, OK otherwise. Core functions call it between
// channels.
inline absl::Status CheckNotCancelled(const std::stop_token& stop) {
  if (stop.stop_requested()) return absl::CancelledError("cancelled");
  return absl::OkStatus();
}

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_PROGRESS_H_
