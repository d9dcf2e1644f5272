// Key reduction with filtering (SPEC 4): fit few-key Hermite curves to sampled channels.
#ifndef TEMPOKEY_CORE_REDUCE_H_
#define TEMPOKEY_CORE_REDUCE_H_

#include <cstdint>
#include <optional>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/clip.h"
#include "tempokey/core/keyed_clip.h"
#include "tempokey/core/progress.h"

namespace tempokey::core {

enum class ReduceMethod { kTolerance, kPaper };

// The paper's Hermite DP fit (SPEC 4.1). Steps are in frames (x) and value units (y); tangent
// steps in the 2D (frame, value) tangent space.
struct PaperParams {
  double step_x_frames = 1.0;
  double step_y = 0.5;
  double step_tangent_x = 1.0;
  double step_tangent_y = 0.5;
  // Stop when every step has been halved below this.
  double accuracy = 0.01;
  int max_iterations = 8;
  // Gaussian sigma (frames) of the smoothed copy used to find derivative zero crossings.
  double smoothing_sigma_frames = 2.0;
  // Minimum distance between initial keys, in frames.
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

struct ReductionReport {
  std::vector<ChannelReduction> channels;
  std::int64_t key_count = 0;
  std::int64_t sample_count = 0;
  double rms_error = 0.0;
  double max_error = 0.0;
  int worst_channel_index = 0;
  std::int64_t worst_frame = 0;
  int iterations = 0;  // paper: the most refinement iterations any channel ran
};

struct ReduceResult {
  KeyedClip keyed;
  ReductionReport report;
};

// Checks `options` for the chosen method (steps > 0, accuracy > 0, 1 <= max_iterations <= 1000,
// sigma >= 0, spacing >= 1, bounds > 0, ...). Errors: kInvalidArgument naming the field and value.
absl::Status ValidateReduceOptions(const ReduceOptions& options);

// Fits every channel of `clip` (angles unwrapped first) and reports the error against the input.
//
// Errors:
//   kInvalidArgument  `clip` fails ValidateClip() or `options` fail ValidateReduceOptions().
//   kUnimplemented    a method this build does not have yet.
//   kCancelled        `stop` was requested; checked between channels.
//
// Thread-safe: a pure function of its arguments.
absl::StatusOr<ReduceResult> ReduceKeys(const Clip& clip, const ReduceOptions& options,
                                        const ProgressFn& progress = {},
                                        std::stop_token stop = {});

// Measures `keyed` against `clip` at every source frame (one error metric for reduction, tests
// and benchmarks). Errors: kInvalidArgument when the two do not have the same channels.
absl::StatusOr<ReductionReport> MeasureReduction(const Clip& clip, const KeyedClip& keyed);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_H_
