// Retiming (SPEC 3): a speed curve, time-map keys, holds or a reverse compile into one exact time
// map t(τ); each channel is resampled at the output times through it, anti-aliased where the
// motion is compressed and rotation-aware.
#ifndef TEMPOKEY_CORE_RETIME_H_
#define TEMPOKEY_CORE_RETIME_H_

#include <cstdint>
#include <optional>
#include <stop_token>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/clip.h"
#include "tempokey/core/progress.h"

namespace tempokey::core {

// A time on a timeline, in seconds or in frames of that timeline's rate ("2.5s", "75f").
struct TimePoint {
  double value = 0.0;
  bool in_frames = false;

  // Seconds, given the timeline's frame time.
  double Seconds(double frame_time_seconds) const {
    return in_frames ? value * frame_time_seconds : value;
  }
};

// A knot of a piecewise-linear speed curve: linear between knots, flat outside; two knots at the
// same time make a step.
struct SpeedKnot {
  TimePoint time;
  double speed = 1.0;
};

// A direct key of the time map: output time `output` shows source time `source`.
struct TimeMapKey {
  TimePoint output;
  TimePoint source;
};

// A freeze frame at source time `at` lasting `duration_seconds` of output time.
struct Hold {
  TimePoint at;
  double duration_seconds = 0.0;
};

// Source time `source` lands exactly on output frame `output_frame`.
struct Pin {
  TimePoint source;
  std::int64_t output_frame = 0;
};

// Which timeline the speed knots are drawn over. Users confuse them, so the API names it.
enum class WarpDomain {
  kIdentity,         // no speed change (frame-rate change, fit or reverse alone)
  kSpeedOverSource,  // the paper's velocity curve: v(τ), t(τ) = ∫ dσ / v(σ)
  kSpeedOverOutput,  // NLE / Unreal style ramps: s(t), τ(t) = ∫ s
  kTimeMapKeys,      // direct (t_k, τ_k) keys, linear between
};

struct TimeWarpSpec {
  WarpDomain domain = WarpDomain::kIdentity;
  std::vector<SpeedKnot> speed;   // kSpeedOverSource / kSpeedOverOutput
  std::vector<TimeMapKey> keys;   // kTimeMapKeys
  std::vector<Hold> holds;
  bool reverse = false;
};

enum class ResampleFilter { kTent, kLinear, kBox, kCubic, kLanczos3 };
enum class RetimeMethod { kExact, kPaper };
enum class RotationMode { kQuaternion, kEuler };

// An exact frame rate numerator / denominator in Hz (30000/1001 for 29.97).
struct FrameRate {
  std::int64_t numerator = 30;
  std::int64_t denominator = 1;

  double hz() const { return static_cast<double>(numerator) / static_cast<double>(denominator); }
};

struct RetimeOptions {
  // At most one of the two: scale every speed by one constant so the output lasts this long.
  std::optional<double> fit_seconds;
  std::optional<std::int64_t> fit_frames;
  // Scale speeds by c ≈ 1 so the last output sample is exactly the last source pose.
  bool fit_to_grid = true;
  // Output rate; unset keeps the source's frame time exactly.
  std::optional<FrameRate> output_rate;
  ResampleFilter filter = ResampleFilter::kTent;
  RetimeMethod method = RetimeMethod::kExact;
  RotationMode rotation_mode = RotationMode::kQuaternion;
  std::vector<Pin> pins;
  double min_speed = 0.01;
  double max_speed = 100.0;
};

struct RetimeReport {
  double output_duration_seconds = 0.0;
  std::int64_t output_frame_count = 0;
  double fit_factor = 1.0;            // c: the constant all speeds were scaled by
  double max_decimation_ratio = 0.0;  // max ρ over output samples
  std::int64_t filtered_sample_count = 0;  // output samples whose kernel had a > 0
};

struct RetimeResult {
  Clip clip;
  RetimeReport report;
};

// Resamples every channel of `clip` along the time map of `warp` (SPEC 3).
//
// Errors:
//   kInvalidArgument  `clip` fails ValidateClip(); `warp` or `options` are invalid (speed <= 0 or
//                     outside [min_speed, max_speed], times decreasing, NaN, both fits set, a fit
//                     needing a speed outside the range, ...): the message names the knot.
//   kCancelled        `stop` was requested; checked between channels.
//
// Thread-safe: a pure function of its arguments.
absl::StatusOr<RetimeResult> Retime(const Clip& clip, const TimeWarpSpec& warp,
                                    const RetimeOptions& options, const ProgressFn& progress = {},
                                    std::stop_token stop = {});

// Everything Retime() would refuse before resampling, checked against `clip`'s timing only
// (frame time and frame count; samples are not read): cheap enough to run before queueing.
absl::Status ValidateRetime(const Clip& clip, const TimeWarpSpec& warp,
                            const RetimeOptions& options);

// Parses the CLI / pipeline speed syntax: comma-separated `time:speed` knots, time in seconds or
// frames ("2.5s", "75f"), e.g. "0s:1,2s:1,2s:0.5,4s:0.5,4s:1".
// Errors: kInvalidArgument naming the knot ("speed knot 3 '2x:0.5': time needs a unit, s or f").
absl::StatusOr<std::vector<SpeedKnot>> ParseSpeedKnots(std::string_view text);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_RETIME_H_
