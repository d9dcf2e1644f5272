// Pieces shared by the time map, the retime entry points and the paper's method: how knots,
// keys, holds and pins are named in messages, and the checks every warp shares.
#ifndef TEMPOKEY_CORE_SRC_RETIME_RETIME_INTERNAL_H_
#define TEMPOKEY_CORE_SRC_RETIME_RETIME_INTERNAL_H_

#include <cstdint>
#include <span>
#include <string>

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

// min_speed finite and > 0, max_speed finite and >= min_speed.
absl::Status ValidateSpeedRange(const RetimeOptions& options);
// Numerator and denominator > 0, rate <= kMaxOutputRateHz.
absl::Status ValidateOutputRate(const FrameRate& rate);
// Every knot: time and speed finite, speed > 0 and in [min_speed, max_speed], times (converted
// to seconds with `frame_time_seconds` for times in frames) non-decreasing.
absl::Status ValidateSpeedKnots(std::span<const SpeedKnot> knots, double frame_time_seconds,
                                const RetimeOptions& options);

}  // namespace tempokey::core::retime_internal

#endif  // TEMPOKEY_CORE_SRC_RETIME_RETIME_INTERNAL_H_
