// Retiming (SPEC 3): a speed curve, time-map keys, holds or a reverse compile into one exact time
// map t(τ); each channel is resampled at the output times through it, anti-aliased where the
// motion is compressed and rotation-aware.
#ifndef TEMPOKEY_CORE_RETIME_RETIME_H_
#define TEMPOKEY_CORE_RETIME_RETIME_H_

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <stop_token>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/progress.h"

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
// same time (within 1e-9 frames of their timeline) make a step.
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
// Speeds are ratios: source seconds played per output second (1 normal, 0.5 half speed).
enum class WarpDomain {
  kIdentity,         // no speed change (frame-rate change, fit or reverse alone)
  kSpeedOverSource,  // the paper's velocity curve: v(τ), t(τ) = ∫ dσ / v(σ); knot times (and
                     // "f" frames) are source times
  kSpeedOverOutput,  // NLE / Unreal style ramps: s(t), τ(t) = ∫ s; knot times are output times
                     // ("f" = output frames); integrated from t = 0 until the clip ends. A fit
                     // scaling speeds by c also compresses this curve in time by c (each
                     // segment keeps the source span it covers).
  kTimeMapKeys,      // direct (t_k, τ_k) keys, linear between; τ non-decreasing (equal τ is a
                     // hold), t increasing; must cover source 0..T_s (the part inside the clip
                     // is used, shifted to start at output 0)
};

struct TimeWarpSpec {
  WarpDomain domain = WarpDomain::kIdentity;
  std::vector<SpeedKnot> speed;   // kSpeedOverSource / kSpeedOverOutput
  std::vector<TimeMapKey> keys;   // kTimeMapKeys
  // Freeze frames at source times inside the clip; they add their duration to the output and
  // keep it under fits.
  std::vector<Hold> holds;
  // Play the whole retimed result backwards: output time t shows τ(T_o - t).
  bool reverse = false;
};

// How each channel is resampled (SPEC 3.3; see resample.h for the kernels).
enum class ResampleFilter {
  kTent,      // default: linear interpolation where ρ <= 1, exact triangle filter when compressing
  kLinear,    // point sampling of the linear reconstruction, no anti-aliasing
  kBox,       // area average over the output footprint
  kCubic,     // Catmull-Rom (squad for rotations) where a = 0, the tent elsewhere
  kLanczos3,  // Lanczos-3 scaled by max(1, ρ)
};
// kExact: the one exact time map (default). kPaper: the published region / ratio-of-areas
// procedure, for comparison (speed over source time only; no holds, pins, fit or output rate;
// fit_to_grid and filter are ignored: it rounds per region and averages with the box).
enum class RetimeMethod { kExact, kPaper };
// kQuaternion: a joint's three rotation channels are resampled as one rotation (default).
// kEuler: every angle is unwrapped and resampled as a scalar. Joints with fewer than three
// rotation channels always take the Euler path.
enum class RotationMode { kQuaternion, kEuler };

// An exact frame rate numerator / denominator in Hz (30000/1001 for 29.97).
struct FrameRate {
  std::int64_t numerator = 30;
  std::int64_t denominator = 1;

  double hz() const { return static_cast<double>(numerator) / static_cast<double>(denominator); }
};

struct RetimeOptions {
  // At most one of the two: scale every speed by one constant c so the output lasts this long
  // (holds keep their length). fit_seconds > 0; with fit_to_grid on it is rounded to a whole
  // number of output frames. fit_frames >= 2 is the exact output frame count.
  std::optional<double> fit_seconds;
  std::optional<std::int64_t> fit_frames;
  // Scale speeds by c ≈ 1 so T_o is a whole number of output frames and the last output sample
  // is exactly the last source pose.
  bool fit_to_grid = true;
  // Output rate; unset keeps the source's frame time exactly. Output sample j is at
  // t_j = j·denominator/numerator seconds.
  std::optional<FrameRate> output_rate;
  ResampleFilter filter = ResampleFilter::kTent;
  RetimeMethod method = RetimeMethod::kExact;
  RotationMode rotation_mode = RotationMode::kQuaternion;
  // Source times that must land exactly on output frames, increasing in both; each interval
  // between pins is scaled by its own constant, the part after the last pin by the fit (or
  // fit to grid). Not combinable with reverse.
  std::vector<Pin> pins;
  // Allowed speeds (after any fit scaling), 0 < min_speed <= max_speed.
  double min_speed = 0.01;
  double max_speed = 100.0;
};

struct RetimeReport {
  double output_duration_seconds = 0.0;    // T_o
  std::int64_t output_frame_count = 0;     // M = floor(T_o·f_o + 1e-9) + 1
  double fit_factor = 1.0;                 // c: the constant the (last pin interval's) speeds
                                           // were scaled by; 1 without fit or grid
  double max_decimation_ratio = 0.0;       // max ρ over output samples
  std::int64_t filtered_sample_count = 0;  // output samples whose kernel had a > 0
};

struct RetimeResult {
  Clip clip;
  RetimeReport report;
};

// Resamples every channel of `clip` along the time map of `warp` (SPEC 3): the warp, fit,
// pins and output rate compile into one exact map (time_map.h), the kernels are planned once
// for all channels (resample.h), then every channel is resampled: positions and scalars as
// scalars, each joint's three rotation channels as one rotation (RotationMode), other angles
// unwrapped. Markers are mapped through t(τ). The result keeps the clip's name, skeleton and
// channel layout, with the output frame time and frame count. The identity warp returns the
// samples bit for bit.
//
// Errors:
//   kInvalidArgument  `clip` fails ValidateClip(); `warp` or `options` are invalid (speed <= 0 or
//                     outside [min_speed, max_speed], times decreasing, NaN, both fits set, a fit
//                     needing a speed outside the range, ...): the message names the knot; the
//                     output would exceed `limits` (frames, or frames x channels).
//   kResourceExhausted more than 100 000 speed knots, time-map keys, holds or pins (each), as
//                     every request over a size limit (OverLimitError()).
//   kCancelled        `stop` was requested; checked between channels (and joints) and inside
//                     long channels every kResampleStopCheckTaps kernel taps (resample.h).
// Progress: `progress` is called after each channel (or joint) with the fraction done.
//
// Thread-safe: a pure function of its arguments.
absl::StatusOr<RetimeResult> Retime(const Clip& clip, const TimeWarpSpec& warp,
                                    const RetimeOptions& options, const ProgressFn& progress = {},
                                    std::stop_token stop = {}, const ClipLimits& limits = {});

// Everything Retime() would refuse before resampling, checked against `clip`'s timing only
// (frame time and frame count; samples are not read): cheap enough to run before queueing.
absl::Status ValidateRetime(const Clip& clip, const TimeWarpSpec& warp,
                            const RetimeOptions& options, const ClipLimits& limits = {});

// What a retime produces, known from the time map (or the paper's regions) before any sample is
// resampled.
struct RetimeOutputShape {
  std::int64_t frame_count = 0;
  double frame_time_seconds = 0.0;
};

// ValidateRetime() for a clip of `frame_count` frames `frame_time_seconds` apart with
// `channel_count` channels, returning the output's frame count and frame time: what a pipeline
// needs to check the next step (a chain of retimes) before anything runs. Cost: compiling the
// time map, O(knots + keys + holds + pins).
// Errors: those of ValidateRetime().
// Thread-safe.
absl::StatusOr<RetimeOutputShape> PlanRetimeOutput(double frame_time_seconds,
                                                   std::int64_t frame_count,
                                                   std::size_t channel_count,
                                                   const TimeWarpSpec& warp,
                                                   const RetimeOptions& options,
                                                   const ClipLimits& limits = {});

// Parses the CLI / pipeline speed syntax: comma-separated `time:speed` knots, time in seconds or
// frames ("2.5s", "75f"), e.g. "0s:1,2s:1,2s:0.5,4s:0.5,4s:1" (2 s to 4 s at half speed);
// "0s:1" alone is the identity. Spaces around tokens are allowed; numbers as ParseDoubleToken()
// reads them (numbers.h: finite, exponents and a leading '+' allowed). Only the syntax is checked
// here (finite numbers, a unit): speed ranges and ordering are Retime()'s, whose messages name
// the knot too.
// Errors: kInvalidArgument naming the knot ("speed knot 3 '2x:0.5': time needs a unit, s or f",
// "speed knot 1 '0s:1x': speed: malformed number \"1x\""); kResourceExhausted over 100 000
// knots.
// Thread-safe.
absl::StatusOr<std::vector<SpeedKnot>> ParseSpeedKnots(std::string_view text);

// The inverse of ParseSpeedKnots(): "0s:1,2.5s:0.5,75f:2", each number in the shortest form
// that reads back to the same double (FormatDouble()), so
// ParseSpeedKnots(FormatSpeedKnots(k)) == k bit for bit for finite values. An empty list gives
// "" (which ParseSpeedKnots() refuses: a curve needs a knot). Thread-safe.
std::string FormatSpeedKnots(std::span<const SpeedKnot> knots);

// Where a retime puts every output sample, computed without reading or resampling any sample:
// what an editor shows live while the speed curve is dragged (SPEC 3.1-3.3).
struct RetimePlan {
  // Exactly what Retime() reports for a clip of this timing and channel count.
  RetimeReport report;
  double output_frame_time_seconds = 0.0;
  // Per output sample j = 0..M-1: the source position read, in source frames (x_j = τ_j·f_s),
  // and the local decimation ratio ρ_j (0 inside a hold).
  std::vector<double> source_frames;
  std::vector<double> decimation_ratios;
  // Speed over source time: each knot's output time t(τ_k) in seconds, in knot order.
  // Speed over output time (exact method, no pins): each knot's source time in seconds, its
  // output time taken after the fit (t_k / fit factor). Empty otherwise.
  std::vector<double> knot_output_seconds;
  std::vector<double> knot_source_seconds;
};

// Compiles the time map (or the paper's schedule) and the resampling kernels Retime() would use
// on `clip`, reading only its frame time, frame count and channel count.
// Errors: those of ValidateRetime() (the same messages Retime() gives).
// Thread-safe: a pure function of its arguments.
absl::StatusOr<RetimePlan> PlanRetime(const Clip& clip, const TimeWarpSpec& warp,
                                      const RetimeOptions& options, const ClipLimits& limits = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_RETIME_RETIME_H_
