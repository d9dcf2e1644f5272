// The `noise` method of ReduceKeys() over a whole clip (reduce.h, noise_fit.h).
#ifndef TEMPOKEY_CORE_SRC_REDUCE_NOISE_REDUCTION_H_
#define TEMPOKEY_CORE_SRC_REDUCE_NOISE_REDUCTION_H_

#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/reduce/reduce.h"

namespace tempokey::core::reduce_internal {

// Checks NoiseParams (ValidateReduceOptions() for the `noise` method).
absl::Status ValidateNoiseParams(const NoiseParams& params);

// Curves of every channel of `clip` from its prepared `inputs` (unwrapped, one span per channel),
// and per channel the noise level used and whether it was estimated. Errors name the channel;
// kCancelled between channels. Progress once per channel.
struct NoiseCurves {
  std::vector<Curve> curves;
  std::vector<double> sigmas;
  std::vector<bool> estimated;
};
absl::StatusOr<NoiseCurves> FitNoiseCurves(const Clip& clip,
                                           std::span<const std::span<const double>> inputs,
                                           const NoiseParams& params, const ProgressFn& progress,
                                           std::stop_token stop);

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_NOISE_REDUCTION_H_
