// Key reduction with filtering (SPEC 4): fit few-key Hermite curves to sampled channels.
#ifndef TEMPOKEY_CORE_REDUCE_REDUCE_H_
#define TEMPOKEY_CORE_REDUCE_REDUCE_H_

#include <cstdint>
#include <optional>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/model/progress.h"

namespace tempokey::core {

enum class ReduceMethod { kTolerance, kPaper };

// The paper's Hermite DP fit (SPEC 4.1; definitions in hermite_dp.h). Steps are in frames (x)
// and value units (y: degrees for rotations, file units for positions); tangent steps in the 2D
// (frame, value) tangent space (per unit of the segment parameter).
struct PaperParams {
  double step_x_frames = 1.0;    // (0, 1e6]
  double step_y = 0.5;           // (0, 1e6]
  double step_tangent_x = 1.0;   // (0, 1e6]
  double step_tangent_y = 0.5;   // (0, 1e6]
  // Stop when every step has been halved below this. (0, 1e6].
  double accuracy = 0.01;
  // DP passes at most, [1, 1000].
  int max_iterations = 8;
  // Gaussian sigma (frames) of the smoothed copy whose first and second central differences
  // give the initial keys at their zero crossings. Raw captures have a zero crossing at almost
  // every frame; 2 frames removes the jitter without moving real extrema. 0 = none, else
  // [0.01, 1000].
  double smoothing_sigma_frames = 2.0;
  // Minimum distance between initial keys, in frames; candidates closer to an already kept key
  // are dropped (extrema are kept before inflections). [1, 1000000].
  int min_key_spacing_frames = 4;
};

enum class PoseAlignment { kNone, kJoint, kClip };

// The error-bounded method (SPEC 4.2).
struct ToleranceParams {
  double max_rotation_error_degrees = 0.5;
  double max_position_error = 0.5;
  double max_scalar_error = 0.5;
  std::optional<std::int64_t> key_budget;
  PoseAlignment pose_alignment = PoseAlignment::kNone;
};

struct ReduceOptions {
  ReduceMethod method = ReduceMethod::kTolerance;
  PaperParams paper;
  ToleranceParams tolerance;
};

// Quality of one channel against its input samples (ACL style: keep the worst frame).
struct ChannelReduction {
  int channel_index = 0;
  std::int64_t key_count = 0;
  std::int64_t sample_count = 0;
  double rms_error = 0.0;
  double max_error = 0.0;
  std::int64_t max_error_frame = 0;
};

// Errors are in value units (degrees for rotations, unwrapped), measured at every source frame.
struct ReductionReport {
  std::vector<ChannelReduction> channels;
  std::int64_t key_count = 0;
  std::int64_t sample_count = 0;
  double rms_error = 0.0;
  double max_error = 0.0;
  int worst_channel_index = 0;
  std::int64_t worst_frame = 0;
  int iterations = 0;  // paper: the most refinement iterations any channel ran

  // Keys kept as a percentage of samples (0 for an empty report).
  double key_percent() const {
    return sample_count > 0
               ? 100.0 * static_cast<double>(key_count) / static_cast<double>(sample_count)
               : 0.0;
  }
};

struct ReduceResult {
  KeyedClip keyed;
  ReductionReport report;
  // paper: per channel, the fit's total squared error (value units squared, against the
  // unwrapped input) before the first DP pass and after each pass; never increasing. Empty
  // for constant channels, which take two flat keys without a fit.
  std::vector<std::vector<double>> squared_error_history;
};

// Checks `options` for the chosen method: the method is known; paper: steps and accuracy in
// [1e-300, 1e6] (normal doubles), 1 <= max_iterations <= 1000, sigma 0 or in [0.01, 1000],
// 1 <= spacing <= 1000000; tolerance: error bounds in [1e-9, 1e9], key budget >= 2 when set, a
// known pose alignment.
// Errors: kInvalidArgument naming the field and value, e.g.
//   "paper.step_y must be > 0, got -1", "paper.max_iterations must be in [1, 1000], got 0".
// Thread-safe.
absl::Status ValidateReduceOptions(const ReduceOptions& options);

// ValidateReduceOptions() plus what depends on the layout of the clip to reduce: a key budget
// covers the keys any fit needs (2 per channel, 1 per channel of a one-frame clip).
// Errors: those of ValidateReduceOptions(); kInvalidArgument "tolerance.key_budget 2 is below
// the 192 keys any fit of 96 channels needs (2 per channel)".
// Thread-safe.
absl::Status ValidateReduceForLayout(const ReduceOptions& options, std::int64_t channel_count,
                                     std::int64_t frame_count);

// Fits every channel of `clip` and reports the error against the input (MeasureReduction()).
// Rotation channels are unwrapped first (UnwrapDegrees()), so the curves carry unwrapped angles;
// re-wrap after baking if wanted.
//   `tolerance`: FitWithinTolerance() (tolerance_fit.h) with the bound of each channel's kind:
//     every channel stays within it at every source frame; keys on integer frames, non-weighted,
//     C1 (in and out tangents equal). Channels share key frames per pose_alignment (each alone, a
//     joint's channels, or all). With key_budget, every bound is scaled by one common factor,
//     the smallest (to a ratio of 2^-12) whose fit keeps at most that many keys in all. The
//     search doubles the factor from 1 up to the one at which every channel's bound covers the
//     range (max - min) of its fitted samples; there two keys per channel always suffice (if the
//     fit keeps more, each channel takes two flat keys at the middle of its range), so every
//     budget of at least 2 keys per channel is met.
//   `paper`: initial keys, DP passes and the conversion to weighted keys as in hermite_dp.h;
//     keys land at fractional frames.
// A lone channel whose samples are all equal gets two flat keys at the first and last frame (one
// key for a one-frame clip).
//
// Errors:
//   kInvalidArgument  `clip` fails ValidateClip(), `options` fail ValidateReduceForLayout()
//                     ("tolerance.key_budget 5 is below the 18 keys any fit of 9 channels needs
//                     (2 per channel)").
//   kCancelled        `stop` was requested; checked between channels (between groups of
//                     pose-aligned channels) and inside each channel's fit: every DP pass and
//                     every few dozen segments of one (paper), every insertion round and every
//                     few hundred keys (tolerance), so a request is seen within milliseconds.
//   kInternal         a fit produced a curve outside the keyed clip's ranges (a bug).
// Progress: once per channel or group, "reduce 12/96".
//
// Thread-safe: a pure function of its arguments.
absl::StatusOr<ReduceResult> ReduceKeys(const Clip& clip, const ReduceOptions& options,
                                        const ProgressFn& progress = {},
                                        std::stop_token stop = {});

// Measures `keyed` against `clip` at every source frame f (one error metric for reduction, tests
// and benchmarks): error = EvaluateCurve(curve, f * clip.frame_time_seconds) - sample, with
// rotation samples unwrapped first. Per channel: keys, RMS and max |error| and its frame; per
// clip: totals, RMS over all samples, the worst channel and frame. Pass a clean clip to measure
// against a known truth.
// Errors: kInvalidArgument when either fails validation or the channel count or kinds differ.
// Thread-safe.
absl::StatusOr<ReductionReport> MeasureReduction(const Clip& clip, const KeyedClip& keyed);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_REDUCE_H_
