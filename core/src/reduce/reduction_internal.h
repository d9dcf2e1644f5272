// Pieces shared by ReduceKeys() and MeasureReduction(): the samples a reduction fits and the one
// error metric over them, for callers that have already validated and prepared their inputs.
#ifndef TEMPOKEY_CORE_SRC_REDUCE_REDUCTION_INTERNAL_H_
#define TEMPOKEY_CORE_SRC_REDUCE_REDUCTION_INTERNAL_H_

#include <span>
#include <stop_token>
#include <vector>

#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/reduce.h"

namespace tempokey::core::reduce_internal {

// The samples key reduction fits and measures, one span per channel of `clip`: a rotation
// channel's samples unwrapped (UnwrapDegrees()) into a copy held here when that changes any of
// their bits, any other channel's samples (and a rotation's that unwrapping leaves as they are)
// where the clip holds them. Borrows `clip`, which must outlive this; neither copyable
// nor movable, since the spans point into it.
class FittedSamples {
 public:
  explicit FittedSamples(const Clip& clip);
  FittedSamples(const FittedSamples&) = delete;
  FittedSamples& operator=(const FittedSamples&) = delete;

  std::span<const std::span<const double>> channels() const { return channels_; }

 private:
  std::vector<std::vector<double>> unwrapped_;     // one per rotation channel unwrapping changed
  std::vector<std::span<const double>> channels_;  // one per channel
};

// MeasureReduction()'s report of `curves` against `samples` (one curve per channel, sampled at
// f * frame_time_seconds), without its checks. Precondition: as many curves as channels, each
// valid (ValidateCurve()). Thread-safe.
// Returns early, the report incomplete, when `stop` is requested (the caller checks it).
ReductionReport MeasureFitted(std::span<const std::span<const double>> samples,
                              std::span<const Curve> curves, double frame_time_seconds,
                              std::stop_token stop = {});

// Checks that `keyed` holds one curve per channel of `clip`, of the same kinds.
// Errors: kInvalidArgument "keyed clip has 1 channels, the clip has 2", "channel 3 (Hips.Xrotation):
// the keyed clip's channel is Yrotation, not Xrotation".
absl::Status CheckCurvesFitClip(const Clip& clip, const KeyedClip& keyed);

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_REDUCTION_INTERNAL_H_
