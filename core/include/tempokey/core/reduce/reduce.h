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
#include "tempokey/core/reduce/joint_bound.h"
#include "tempokey/core/reduce/world_error.h"

namespace tempokey::core {

enum class ReduceMethod { kTolerance, kPaper, kNoise };

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

// Default per-channel bounds (SPEC 4.2, 4.4). They are scale-aware: the same motion in
// centimetres, metres or inches gets the same keys. Rotations in degrees; positions a fraction of
// the figure's height (FigureHeight(): the vertical extent of every joint and end site at the
// first frame; 0.3 % is 0.49 cm on a 162-cm figure, about the 0.5 file units the bound used to
// be on centimetre captures), or kDefaultMaxPositionErrorWithoutFigure file units for a clip
// without a skeleton or with a figure of height 0; scalars in their own units.
inline constexpr double kDefaultMaxRotationErrorDegrees = 0.5;
inline constexpr double kDefaultPositionErrorHeightFraction = 0.003;
inline constexpr double kDefaultMaxPositionErrorWithoutFigure = 0.5;
inline constexpr double kDefaultMaxScalarError = 0.5;

// The error-bounded method (SPEC 4.2). Unset bounds take the defaults above. With
// `joint_tolerance` (SPEC 4.4, joint_bound.h) every joint and end site stays within it at every
// frame; the rotation and position bounds then apply only when set (the tighter of a set bound and
// the channel's joint budget wins), unset ones leave the choice to the joint bound.
struct ToleranceParams {
  std::optional<double> max_rotation_error_degrees;
  std::optional<double> max_position_error;  // file units
  double max_scalar_error = kDefaultMaxScalarError;
  std::optional<std::int64_t> key_budget;
  PoseAlignment pose_alignment = PoseAlignment::kNone;
  std::optional<JointTolerance> joint_tolerance;
  // Keys placed by the fewest-keys search (ToleranceFitOptions::fewest_keys): the same curves
  // and bounds with about 15 % fewer keys on the shared captures, for hundreds of times the
  // fit's time.
  bool fewest_keys = false;
};

// The noise-aware method (SPEC 4.3; noise_fit.h). Noise levels are standard deviations in value
// units: degrees for rotation channels, file units for position and scalar channels; unset means
// estimated per channel from the data (EstimateNoiseSigma()).
struct NoiseParams {
  std::optional<double> rotation_sigma_degrees;  // finite, > 0 when set
  std::optional<double> position_sigma;          // position and scalar channels
  // An estimate below this is raised to it, so a noiseless channel still gets a fit. An estimate
  // of exactly 0 (the estimate's verdict that the motion makes up all of the third differences)
  // is not smoothed: min_sigma then sets only its key bound, key_sigmas * min_sigma. A small
  // estimate above 0 (white noise found, below this) is smoothed at min_sigma. Value units;
  // finite, > 0.
  double min_sigma = 1e-4;
  double guard_sigmas = 5.0;  // [2, 100], NoiseFitOptions
  double key_sigmas = 0.2;    // [0.01, 10], NoiseFitOptions
};

struct ReduceOptions {
  ReduceMethod method = ReduceMethod::kTolerance;
  PaperParams paper;
  ToleranceParams tolerance;
  NoiseParams noise;
  // The Euler filter (euler_filter.h) on the input before fitting; unset: the method's default,
  // on for `noise` (an Euler flip is not noise and costs keys), off for `tolerance` and `paper`
  // (their curves keep the input's angles unless asked, but for whole turns: rotations are fitted
  // unwrapped, see ReduceKeys()).
  std::optional<bool> euler_filter;
};

// Quality of one channel against its input samples (ACL style: keep the worst frame).
struct ChannelReduction {
  int channel_index = 0;
  std::int64_t key_count = 0;
  std::int64_t sample_count = 0;
  double rms_error = 0.0;
  double max_error = 0.0;
  std::int64_t max_error_frame = 0;
  // noise: the channel's noise level (value units) the fit used, and whether it was estimated
  // from the data (else given); 0 and false for other methods.
  double noise_sigma = 0.0;
  bool noise_sigma_estimated = false;
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
  // Joint world-position error through the skeleton (SPEC 4.4); unset for a clip without one.
  std::optional<WorldErrorReport> world;
  // (joint, frame) pairs the Euler filter rewrote on the input (0 when it was off).
  std::int64_t euler_filtered_frames = 0;

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
// known pose alignment, a joint tolerance finite and > 0 when set (ValidateJointTolerance());
// noise: given sigmas and min_sigma finite and > 0, guard_sigmas in [2, 100], key_sigmas in
// [0.01, 10].
// Errors: kInvalidArgument naming the field and value, e.g.
//   "paper.step_y must be > 0, got -1", "paper.max_iterations must be in [1, 1000], got 0".
// Thread-safe.
absl::Status ValidateReduceOptions(const ReduceOptions& options);

// ValidateReduceOptions(), then what can be checked against the layout of the clip to reduce
// (its samples are not read): a joint tolerance needs a skeleton.
// Errors: as ValidateReduceOptions(); kFailedPrecondition "tolerance.joint_tolerance needs a
// skeleton, the clip has none". Thread-safe.
absl::Status ValidateReduceOptionsForClip(const Clip& layout, const ReduceOptions& options);
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
//   `tolerance`: FitWithinTolerance() (tolerance_fit.h) with the bound of each channel's kind
//     (defaults resolved against the clip's figure height, see ToleranceParams):
//     every channel stays within it at every source frame; keys on integer frames, non-weighted,
//     C1 (in and out tangents equal). Channels share key frames per pose_alignment (each alone, a
//     joint's channels, or all). With key_budget, every bound is scaled by one common factor,
//     the smallest (to a ratio of 2^-12) whose fit keeps at most that many keys in all. The
//     search doubles the factor from 1 up to the one at which every channel's bound covers the
//     range (max - min) of its fitted samples; there two keys per channel always suffice (if the
//     fit keeps more, each channel takes two flat keys at the middle of its range), so every
//     budget of at least 2 keys per channel is met.
//     With joint_tolerance the channels' bounds come from the joint bound (joint_bound.h): every
//     joint and end site stays within it at every source frame, verified by forward kinematics.
//     A key budget scales the joint bound too (the covering scale is then the one at which the
//     guaranteed budgets cover every channel's range).
//   `paper`: initial keys, DP passes and the conversion to weighted keys as in hermite_dp.h;
//     keys land at fractional frames.
//   `noise`: per channel, the given noise level of its kind or EstimateNoiseSigma() of its
//     (filtered, unwrapped) samples, at least min_sigma, then FitToNoise() (noise_fit.h); keys on
//     integer frames, non-weighted, C1. A channel whose estimate is exactly 0 (no white noise in
//     its third differences: the motion makes up all of them) has nothing to take out and is not
//     smoothed: its keys are fitted to its samples, within key_sigmas * min_sigma of each. The
//     report carries each channel's level.
// With the Euler filter on (ReduceOptions::euler_filter), the input is filtered first and the
// curves and errors refer to the filtered angles (the same rotations).
// A lone channel whose samples are all equal gets two flat keys at the first and last frame (one
// key for a one-frame clip).
//
// Errors:
//   kInvalidArgument  `clip` fails ValidateClip(), `options` fail ValidateReduceForLayout()
//                     ("tolerance.key_budget 5 is below the 18 keys any fit of 9 channels needs
//                     (2 per channel)").
//   kFailedPrecondition  a joint tolerance on a clip without a skeleton ("tolerance.joint_tolerance
//                     needs a skeleton, the clip has none"), or in percent of a figure whose height
//                     is 0 (ResolveJointTolerance()).
//   kCancelled        `stop` was requested; checked between channels (between groups of
//                     pose-aligned channels) and inside each channel's fit: every DP pass and
//                     every few dozen segments of one (paper), every insertion round and every
//                     few hundred keys (tolerance), so a request is seen within milliseconds.
//   kInternal         a fit produced a curve outside the keyed clip's ranges (a bug).
// The report's `world` measures every joint and end site through the skeleton
// (MeasureWorldError()) for every method, when the clip has a skeleton.
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
// against a known truth. With a skeleton, `world` is MeasureWorldError()'s.
// Errors: kInvalidArgument when either fails validation or the channel count or kinds differ.
// Thread-safe.
absl::StatusOr<ReductionReport> MeasureReduction(const Clip& clip, const KeyedClip& keyed);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_REDUCE_H_
