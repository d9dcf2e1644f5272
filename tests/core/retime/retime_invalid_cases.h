// The table of bad warps and options with their exact messages, shared by the core test
// (tests/core/retime_invalid_test.cc) and the service test (tests/server/retime_service_test.cc),
// which sends each one through a real server.
#ifndef TEMPOKEY_TESTS_CORE_RETIME_INVALID_CASES_H_
#define TEMPOKEY_TESTS_CORE_RETIME_INVALID_CASES_H_

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "tempokey/core/retime/retime.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core::retime_cases {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

inline SpeedKnot Knot(double seconds, double speed) { return {.time = {seconds, false}, .speed = speed}; }
inline TimeMapKey Key(double output_seconds, double source_seconds) {
  return {.output = {output_seconds, false}, .source = {source_seconds, false}};
}
inline TimeWarpSpec OverSource(std::vector<SpeedKnot> knots) {
  return {.domain = WarpDomain::kSpeedOverSource, .speed = std::move(knots)};
}
inline TimeWarpSpec Keys(std::vector<TimeMapKey> keys) {
  return {.domain = WarpDomain::kTimeMapKeys, .keys = std::move(keys)};
}

// 8 s at 30 fps (241 frames), two channels.
inline Clip EightSecondClip() {
  Clip clip;
  clip.name = "eight";
  clip.frame_time_seconds = 1.0 / 30;
  clip.frame_count = 241;
  clip.channels.push_back({.name = "a", .samples = std::vector<double>(241, 1.0)});
  clip.channels.push_back({.name = "b", .samples = std::vector<double>(241, 2.0)});
  return clip;
}

struct BadRetime {
  std::string name;
  TimeWarpSpec warp;
  RetimeOptions options;
  std::string message;
};

inline std::vector<BadRetime> BadRetimes() {
  // fit to 0.1 s of "0s:1,4s:50": the natural length is 4·ln(50)/49 + 4/50 s; on the grid the
  // target is 3 frames, so every speed is scaled by (natural·30)/3.
  const double natural_frames = (4.0 * std::log(50.0) / 49.0 + 4.0 / 50.0) * 30.0;
  const double ramp_scale = natural_frames / 3.0;
  return {
      {"NegativeSpeed", OverSource({Knot(0, 1), Knot(1, 1), Knot(2, -0.5)}), {},
       "speed knot 3 (2s:-0.5): speed must be > 0"},
      {"ZeroSpeed", OverSource({Knot(0, 0)}), {}, "speed knot 1 (0s:0): speed must be > 0"},
      {"SpeedOverMaximum", OverSource({Knot(0, 1), Knot(1, 200)}), {},
       "speed knot 2 (1s:200): speed 200 is outside the allowed range [0.01, 100]"},
      {"SpeedUnderCustomMinimum", OverSource({Knot(0, 0.05)}), {.min_speed = 0.1},
       "speed knot 1 (0s:0.05): speed 0.05 is outside the allowed range [0.1, 100]"},
      {"TimesDecreasing", OverSource({Knot(0, 1), Knot(2, 1), Knot(1, 0.5)}), {},
       "speed knot 3 (1s:0.5): time 1s is before the previous knot's 2s"},
      {"NaNSpeed", OverSource({Knot(0, 1), Knot(1, kNaN)}), {}, "speed knot 2: speed is NaN"},
      {"InfiniteTime", OverSource({Knot(kInf, 1)}), {}, "speed knot 1: time is +infinity"},
      {"NoKnots", OverSource({}), {}, "speed over source time needs at least one speed knot"},
      {"KnotsWithIdentityDomain", {.speed = {Knot(0, 1)}}, {},
       "speed knots are given but the warp domain is identity; set it to speed over source or "
       "over output time"},
      {"EmptySpeedRange", {}, {.min_speed = 5, .max_speed = 1},
       "speed range [5, 1] is empty: max_speed must be >= min_speed"},
      {"BothFits", {}, {.fit_seconds = 2.0, .fit_frames = 60},
       "fit_seconds and fit_frames are both set; give at most one"},
      {"FitFramesOne", {}, {.fit_frames = 1},
       "fit_frames must be >= 2 (one frame has no duration to fit), got 1"},
      {"FitNegativeSeconds", {}, {.fit_seconds = -1.0},
       "fit_seconds must be in (0, 1e+11] seconds, got -1"},
      {"FitHugeSeconds", {}, {.fit_seconds = 1e300},
       "fit_seconds must be in (0, 1e+11] seconds, got 1e+300"},
      {"HugeKnotTime", OverSource({Knot(0, 1), Knot(1e300, 1)}), {},
       "speed knot 2: time 1e+300s is outside [-1e+11, 1e+11] s"},
      {"MinimumSpeedTooSmall", {}, {.min_speed = 1e-300},
       "min_speed must be in [1e-06, 1e+06], got 1e-300"},
      {"MaximumSpeedTooLarge", {}, {.max_speed = 1e300},
       "max_speed must be in [1e-06, 1e+06], got 1e+300"},
      {"RateTooLow", {}, {.output_rate = FrameRate{1, 7200}},
       "output rate 1/7200 (0.000138889 Hz) is under the limit of one frame an hour "
       "(0.000277778 Hz)"},
      {"FitNeedsSpeedOverMaximum", {}, {.fit_seconds = 0.05},
       "fit to 0.05 s: needs speeds scaled by 120, so the clip would play at speed 120, over the "
       "maximum 100"},
      {"FitNeedsSpeedUnderMinimum", {}, {.fit_frames = 100000},
       "fit to 100000 frames: needs speeds scaled by 0.00240002, so the clip would play at speed "
       "0.00240002, under the minimum 0.01"},
      {"FitTakesARampKnotOverMaximum", OverSource({Knot(0, 1), Knot(4, 50)}), {.fit_seconds = 0.1},
       absl::StrFormat("fit to 0.1 s: needs speeds scaled by %g, so speed knot 2 (4s:50) would "
                       "play at speed %g, over the maximum 100",
                       ramp_scale, 50 * ramp_scale)},
      {"HoldsExceedFit", {.holds = {{.at = {1.0, false}, .duration_seconds = 5.0}}},
       {.fit_seconds = 4.0}, "fit to 4 s: the holds alone last 5 s, leaving 0 s for the motion"},
      {"ZeroDenominatorRate", {}, {.output_rate = FrameRate{30, 0}},
       "output rate 30/0 must have a positive numerator and denominator"},
      {"RateTooHigh", {}, {.output_rate = FrameRate{1000000, 1}},
       "output rate 1e+06 Hz is over the limit of 100000 Hz"},
      {"KeysNotCoveringTheClip", Keys({Key(0, 0), Key(2, 4)}), {},
       "time-map keys cover source 0s..4s, the clip spans 0s..8s"},
      // A hair short prints as the clip's span in seconds: the frames say what is missing.
      {"KeysEndingAHairShortOfTheClip", Keys({Key(0, 0), Key(2, 8 - 1e-7)}), {},
       "time-map keys cover source 0s..8s, the clip spans 0s..8s (source frames 0..239.999997 of "
       "0..240: the keys must reach both ends within 1e-09 frames)"},
      {"KeysOutputNotIncreasing", Keys({Key(0, 0), Key(2, 2), Key(2, 3), Key(5, 8)}), {},
       "time-map key 3 (2s -> 3s): output time must increase, the previous key is at 2s"},
      {"KeysSourceDecreasing", Keys({Key(0, 0), Key(2, 4), Key(3, 3), Key(9, 8)}), {},
       "time-map key 3 (3s -> 3s): source time must not decrease, the previous key is at 4s (use "
       "reverse to play backwards)"},
      {"KeysTooFast", Keys({Key(0, 0), Key(0.01, 8)}), {},
       "time-map keys 1..2: speed 800 is outside the allowed range [0.01, 100]"},
      {"HoldNegativeDuration", {.holds = {{.at = {2.0, false}, .duration_seconds = -1.0}}}, {},
       "hold 1 at 2s: duration must be in (0, 1e+11] seconds, got -1"},
      {"HoldForever", {.holds = {{.at = {2.0, false}, .duration_seconds = 1e308}}}, {},
       "hold 1 at 2s: duration must be in (0, 1e+11] seconds, got 1e+308"},
      {"HoldOutsideTheClip", {.holds = {{.at = {10.0, false}, .duration_seconds = 1.0}}}, {},
       "hold 1 at 10s: outside the clip's source time 0s..8s"},
      {"PinsOutOfOrder", {},
       {.pins = {{.source = {2.0, false}, .output_frame = 60},
                 {.source = {1.0, false}, .output_frame = 90}}},
       "pin 2 (1s -> frame 90): must come after pin 1 (2s -> frame 60) in both source time and "
       "output frame"},
      {"PinOutsideTheClip", {}, {.pins = {{.source = {9.0, false}, .output_frame = 10}}},
       "pin 1 (9s -> frame 10): outside the clip's source time 0s..8s"},
      {"PinNeedsSpeedOverMaximum", {}, {.pins = {{.source = {240.0, true}, .output_frame = 1}}},
       "pin 1 (240f -> frame 1): needs speeds scaled by 240, so the clip would play at speed "
       "240, over the maximum 100"},
      {"PinIntervalShorterThanItsHolds",
       {.holds = {{.at = {1.0, false}, .duration_seconds = 3.0}}},
       {.pins = {{.source = {4.0, false}, .output_frame = 60}}},
       "pin 1 (4s -> frame 60): the holds alone last 90 frames, leaving 0 frames for the motion"},
      {"PinsWithReverse", {.reverse = true},
       {.pins = {{.source = {4.0, false}, .output_frame = 60}}},
       "pins cannot be combined with reverse; pin the forward retime and reverse it in a second "
       "operation"},
      {"PaperMethodWithHolds", {.holds = {{.at = {1.0, false}, .duration_seconds = 1.0}}},
       {.method = RetimeMethod::kPaper}, "the paper method does not support holds"},
      {"PaperMethodWithOutputRate", {}, {.output_rate = FrameRate{24, 1}, .method = RetimeMethod::kPaper},
       "the paper method keeps the source frame rate: output_rate must be unset"},
  };
}

}  // namespace tempokey::core::retime_cases

#endif  // TEMPOKEY_TESTS_CORE_RETIME_INVALID_CASES_H_
