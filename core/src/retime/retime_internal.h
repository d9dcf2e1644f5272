// Pieces shared by the time map, the retime entry points and the paper's method: how knots,
// keys, holds and pins are named in messages, and the checks every warp shares.
#ifndef TEMPOKEY_CORE_SRC_RETIME_RETIME_INTERNAL_H_
#define TEMPOKEY_CORE_SRC_RETIME_RETIME_INTERNAL_H_

#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::core::retime_internal {

// Most knots, keys, holds or pins one warp may carry (server input is untrusted).
inline constexpr std::size_t kMaxWarpItems = 100'000;
// Most output frames a retime may produce (ClipLimits' default frame cap).
inline constexpr std::int64_t kMaxOutputFrames = 10'000'000;
// Highest output rate accepted, as in the pipeline's bake step.
inline constexpr double kMaxOutputRateHz = 100'000.0;

// "%g" of a double: 2 -> "2", 0.5 -> "0.5", 8275.3 -> "8275.3".
std::string FormatNumber(double value);
// "2.5s" or "75f".
std::string DescribeTimePoint(const TimePoint& time);
// "speed knot 3 (2s:-0.5)"; `index` is 0-based, printed 1-based.
std::string DescribeSpeedKnot(std::size_t index, const SpeedKnot& knot);
// "time-map key 2 (1s -> 0.5s)".
std::string DescribeKey(std::size_t index, const TimeMapKey& key);
// "hold 1 at 2s".
std::string DescribeHold(std::size_t index, const Hold& hold);
// "pin 2 (3s -> frame 100)".
std::string DescribePin(std::size_t index, const Pin& pin);

// Allowed speed ranges lie within [kMinSpeedBound, kMaxSpeedBound]: output durations (source
// span / speed) stay within 1e13 frames, and speeds in frame units finite.
inline constexpr double kMinSpeedBound = 1e-6;
inline constexpr double kMaxSpeedBound = 1e6;
// Lowest output rate accepted: one frame an hour (kMaxFrameTimeSeconds, clip.h).
inline constexpr double kMinOutputRateHz = 1.0 / 3600.0;
// The largest |value| of a time given in frames ("75f"): kMaxTimeSeconds at the smallest frame
// time, exactly convertible to a 64-bit frame index.
inline constexpr double kMaxTimeFrames = 1e17;

// min_speed and max_speed in [kMinSpeedBound, kMaxSpeedBound], max_speed >= min_speed.
absl::Status ValidateSpeedRange(const RetimeOptions& options);
// Numerator and denominator > 0, rate in [kMinOutputRateHz, kMaxOutputRateHz].
absl::Status ValidateOutputRate(const FrameRate& rate);
// `time` finite and within +-kMaxTimeSeconds (seconds) or +-kMaxTimeFrames (frames).
// Errors: kInvalidArgument "<what>: time is NaN", "<what>: time 1e+300s is outside
// [-1e+11, 1e+11] s".
absl::Status ValidateTimePoint(std::string_view what, const TimePoint& time);
// A duration in (0, kMaxTimeSeconds]. Errors: "<what> must be in (0, 1e+11] seconds, got -1".
absl::Status ValidateDuration(std::string_view what, double seconds);
// Every knot: time and speed finite, speed > 0 and in [min_speed, max_speed], times (converted
// to seconds with `frame_time_seconds` for times in frames) non-decreasing.
absl::Status ValidateSpeedKnots(std::span<const SpeedKnot> knots, double frame_time_seconds,
                                const RetimeOptions& options);

}  // namespace tempokey::core::retime_internal

#endif  // TEMPOKEY_CORE_SRC_RETIME_RETIME_INTERNAL_H_
