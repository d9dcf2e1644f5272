// The options of each pipeline step spelled as flags: what `tempokey retime` and `tempokey reduce`
// accept on the command line, and what the operations of a batch pipeline file say (pipeline_file.h
// turns `{"retime": {"speed": "0s:1", "fps": 30}}` into `--speed 0s:1 --fps 30`). One parser per
// step, so a pipeline file and a command line can never mean different things.
#ifndef TEMPOKEY_CLIENT_STEP_FLAGS_H_
#define TEMPOKEY_CLIENT_STEP_FLAGS_H_

#include <algorithm>
#include <array>
#include <cstddef>

#include "absl/status/statusor.h"
#include "client/args.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::client {

inline constexpr FlagSpec kRetimeStepFlags[] = {
    {"--speed", "", "KNOTS",
     "time:speed knots, e.g. \"0s:1,2.5s:0.5,4s:2\" (times in s or f)"},
    {"--speed-over", "", "source|output",
     "timeline of the knot times (default source: the paper's)"},
    {"--time-map", "", "KEYS", "direct time-map keys OUT:SRC, e.g. \"0s:0s,2s:1s\" (instead of --speed)"},
    {"--hold", "", "T:DURATION", "freeze the pose at source time T for DURATION seconds",
     true},
    {"--pin", "", "T:FRAME", "make source time T land exactly on output frame FRAME",
     true},
    {"--reverse", "", "", "play the clip backwards"},
    {"--fit-frames", "", "N", "scale all speeds so the output has N frames"},
    {"--fit-seconds", "", "S",
     "scale all speeds so the output lasts S seconds (a whole number of frames unless "
     "--no-fit-to-grid)"},
    {"--no-fit-to-grid", "", "", "do not nudge speeds so the last output frame is the last pose"},
    {"--fps", "", "RATE", "output frame rate: 30, 29.97, 30000/1001 (default: the source's)"},
    {"--filter", "", "NAME", "resampling filter: tent (default), linear, box, cubic, lanczos3"},
    {"--method", "", "NAME", "exact (default) or paper (the published region procedure)"},
    {"--rotation", "", "MODE", "quaternion (default) or euler (angles as scalars)"},
    {"--min-speed", "", "V", "lowest speed allowed (default 0.01)"},
    {"--max-speed", "", "V", "highest speed allowed (default 100)"},
    {"--euler-filter", "", "", "rewrite Euler flips of the output as the nearest equivalent angles"},
};

inline constexpr FlagSpec kReduceStepFlags[] = {
    {"--method", "", "NAME",
     "tolerance (default: fewest keys within a bound), paper (Hermite DP) or noise (noise-aware)"},
    {"--tolerance", "", "DEG", "tolerance: max rotation error in degrees (default 0.5)"},
    {"--position-tolerance", "", "UNITS",
     "tolerance: max position error in file units (default 0.3% of the figure's height)"},
    {"--scalar-tolerance", "", "V", "tolerance: max error of scalar channels (default 0.5)"},
    {"--key-budget", "", "N", "tolerance: at most N keys in all instead of an error bound"},
    {"--pose-align", "", "MODE", "tolerance: keys shared per none (default), joint or clip"},
    {"--joint-tolerance", "", "D|D%",
     "tolerance: every joint within D file units (or D% of the figure's height) of its source"},
    {"--fewest-keys", "", "",
     "tolerance: search harder for fewer keys (about 15% fewer, hundreds of times slower)"},
    {"--step-x", "", "FRAMES", "paper: initial search step of key times (default 1)"},
    {"--step-y", "", "V", "paper: initial search step of key values (default 0.5)"},
    {"--step-tangent-x", "", "FRAMES", "paper: initial step of tangent x (default 1)"},
    {"--step-tangent-y", "", "V", "paper: initial step of tangent y (default 0.5)"},
    {"--accuracy", "", "A", "paper: stop when every step is below A (default 0.01)"},
    {"--iterations", "", "N", "paper: at most N refinement iterations (default 8)"},
    {"--smoothing-sigma", "", "FRAMES", "paper: smoothing used to find initial keys (default 2)"},
    {"--min-key-spacing", "", "FRAMES", "paper: minimum spacing of initial keys (default 4)"},
    {"--noise", "", "auto|DEG",
     "noise: noise level of rotation channels, estimated per channel (default auto) or given"},
    {"--position-noise", "", "auto|UNITS",
     "noise: noise level of position and scalar channels (default auto)"},
    {"--euler-filter", "", "on|off",
     "Euler filter on the input (default: on for --method noise, off otherwise)"},
};

inline constexpr FlagSpec kBakeStepFlags[] = {
    {"--fps", "", "RATE", "rate of the baked samples (default: the source's)"},
};

inline constexpr FlagSpec kConvertStepFlags[] = {
    {"--wrap-rotations", "", "", "wrap rotation angles into (-180, 180] on the way"},
    {"--euler-filter", "", "", "rewrite Euler flips as the nearest equivalent angles (before a wrap)"},
};

// The flag lists of a command from its parts, in order: JoinFlags(kCommon, kRetimeStepFlags).
template <std::size_t... N>
constexpr std::array<FlagSpec, (N + ...)> JoinFlags(const FlagSpec (&... parts)[N]) {
  std::array<FlagSpec, (N + ...)> joined{};
  std::size_t at = 0;
  ((std::copy(std::begin(parts), std::end(parts), joined.begin() + at), at += N), ...);
  return joined;
}

// Each step from the flags of `args` (parsed against the step's flag list above).
// Errors: usage errors naming the flag: "--fps: expected a frame rate, got 'abc'",
// "--speed and --time-map exclude each other", "--step-x does not apply to --method tolerance".
// Values that parse but are out of range (a speed of 0) are left to core's validation.
absl::StatusOr<core::RetimeStep> RetimeStepFromArgs(const ParsedArgs& args);
absl::StatusOr<core::ReduceStep> ReduceStepFromArgs(const ParsedArgs& args);
absl::StatusOr<core::BakeStep> BakeStepFromArgs(const ParsedArgs& args);
absl::StatusOr<core::ConvertStep> ConvertStepFromArgs(const ParsedArgs& args);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_STEP_FLAGS_H_
