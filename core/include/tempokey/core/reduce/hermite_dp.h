// The paper's Hermite curve fit by dynamic programming on one channel (SPEC 4.1).
//
// The curve is a 2D cubic Hermite spline in (x = frame, y = value). Segment i joins keys i and
// i+1; for s in [0, 1]
//   v(s) = h00(s) p_i + h10(s) r_i + h01(s) p_{i+1} + h11(s) r_{i+1},
//   h00 = 2s^3 - 3s^2 + 1, h10 = s^3 - 2s^2 + s, h01 = -2s^3 + 3s^2, h11 = s^3 - s^2,
// with p = (x, y) the key position and r = (tx, ty) the key's one tangent, shared by both its
// segments. The curve's value at frame f is y(s) at the s where x(s) = f.
//
// Definitions every implementation of the fit follows, so that the optimized pass below and the
// brute-force reference in tests/core/reduce/hermite_reference.h choose the same keys:
//
//   Feasible segment (monotonic time): with a, b its keys, m = kMinTangentXFrames,
//       a.tx >= m  &&  b.tx >= m  &&  a.x < b.x  &&  a.tx + b.tx <= 3.0 * (b.x - a.x)
//     evaluated exactly as written, and, in a pass, both keys inside the clip:
//     0 <= a.x  &&  b.x <= samples - 1 (an x offset can move an interior key past an end). It says the Bezier x-controls x_a, x_a + tx_a/3,
//     x_b - tx_b/3, x_b are non-decreasing (so x(s) is monotonic), keys are in order, and each
//     tangent has a slope (tx = 0 would be a vertical tangent, which no keyed curve can carry;
//     a tx under a billionth of a frame is one in all but name, and its slope ty / tx would
//     overflow once divided by the frame time: the published tx > 0 with a floor).
//   Frames of a segment: the integers f with a.x <= f < b.x; the last segment also takes b.x.
//   Segment error: sum over its frames of (y(s_f) - sample[f])^2 with x(s_f) = f.
//   Search grid of one pass: each key offers x + {-1, 0, +1} * step.x (first and last key: x
//     fixed), y + {-1, 0, +1} * step.y, tx + ... * step.tangent_x, ty + ... * step.tangent_y: 81
//     states per key, index s = ((ix * 3 + itx) * 3 + iy) * 3 + ity with i* in {0, 1, 2} for the
//     offsets -1, 0, +1. State 40 is the current estimate.
//   Dynamic programming (Viterbi): cost(key 0, s) = 0 for its states with x offset 0; then
//     cost(key i+1, t) = the chosen candidate among cost(key i, s) + error(segment i, s, t) over
//     feasible s. Ties: let m be the smallest candidate and tol(m) = kDpTieRelative * m +
//     kDpTieAbsolute * scale, scale = sum over frames of (sample[f] - sample[0])^2; among the
//     candidates <= m + tol(m) choose state 40 if it is one, else the lowest index. Rounding can
//     then not split a tie differently in two implementations. The last key's state is chosen by
//     the same rule, and the path is read back through the kept predecessors.
//   Iteration: a pass whose path differs from the estimate and whose error does not exceed the
//     estimate's (recomputed with CurveSquaredError) becomes the new estimate; otherwise every
//     step is halved. Iterations stop when every step is below `accuracy` or after
//     `max_iterations` passes. The recorded error therefore never increases.
//     Consequence for the end keys (x fixed): their error at the first and last frame is exactly
//     y - sample, and y moves on the grid sample + k * step.y; on a real channel some key moves
//     in every one of the default 8 passes, so the steps never halve and those errors are whole
//     multiples of step.y. That is the published iteration stopped before its accuracy is
//     reached, not a defect of the end keys: with passes to converge (max_iterations 64 on a
//     Bandai walk) the steps halve, the ends leave the coarse grid and the error falls 2.4x.
#ifndef TEMPOKEY_CORE_REDUCE_HERMITE_DP_H_
#define TEMPOKEY_CORE_REDUCE_HERMITE_DP_H_

#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/keyed_clip.h"

namespace tempokey::core {

// One key of the 2D Hermite spline: position (x frames, y value units) and tangent (tx frames,
// ty value units, both per unit of the segment parameter s).
struct HermiteKey2D {
  double x = 0.0;
  double y = 0.0;
  double tx = 0.0;
  double ty = 0.0;

  friend bool operator==(const HermiteKey2D&, const HermiteKey2D&) = default;
};

// Search steps: x in frames, y in value units, tangents in their own units.
struct HermiteSteps {
  double x = 1.0;
  double y = 0.5;
  double tangent_x = 1.0;
  double tangent_y = 0.5;

  friend bool operator==(const HermiteSteps&, const HermiteSteps&) = default;
};

struct HermiteFitOptions {
  HermiteSteps steps;
  double accuracy = 0.01;   // stop once every step is below this
  int max_iterations = 8;   // DP passes at most
};

// The smallest tangent x-component (frames) of a feasible segment (definition above).
inline constexpr double kMinTangentXFrames = 1e-9;

inline constexpr double kDpTieRelative = 1e-10;
inline constexpr double kDpTieAbsolute = 1e-13;

// What a fit did.
struct HermiteFitResult {
  std::vector<HermiteKey2D> keys;
  // squared_error_history[0] is the initial estimate's error, [k] the estimate's after pass k.
  std::vector<double> squared_error_history;
  int iterations = 0;          // DP passes run
  double squared_error = 0.0;  // of `keys`, = squared_error_history.back()
  HermiteSteps final_steps;
};

// One DP pass.
struct HermiteDpPass {
  std::vector<HermiteKey2D> keys;  // the chosen path
  bool moved = false;              // the path differs from the estimate
  double squared_error = 0.0;      // its error as the DP summed it
};

// Initial key frames (step 1): frame 0, the last frame, and the zero crossings of the first
// (extrema) and second (inflections) central differences of a copy smoothed by a Gaussian of
// `sigma_frames` (truncated at 3 sigma, renormalized at the ends; 0 = no smoothing). A crossing
// between f and f+1 (or an exact zero at f) puts a candidate at whichever of the two has the
// smaller |derivative|. Candidates are taken extrema first, then inflections, each in frame order,
// and kept when at least `min_spacing_frames` from every frame kept so far (the first and last
// frame are kept first). Returns sorted frames; {0} for one sample.
// Preconditions: samples non-empty and finite, sigma_frames >= 0, min_spacing_frames >= 1.
// Thread-safe.
std::vector<int> InitialKeyFrames(std::span<const double> samples, double sigma_frames,
                                  int min_spacing_frames);

// Keys at InitialKeyFrames(): p = (f, sample[f]); tangent tx = the shorter adjacent key gap (so
// the start is feasible), ty = tx * the smoothed copy's central difference at f (one-sided at the
// ends). Preconditions as InitialKeyFrames(), at least 2 samples. The smoothing looks at `stop`
// every few thousand frames and returns early, the keys incomplete, when it is requested (the
// caller checks it). Thread-safe.
std::vector<HermiteKey2D> InitialHermiteKeys(std::span<const double> samples, double sigma_frames,
                                             int min_spacing_frames, std::stop_token stop = {});

// True when the segment from `a` to `b` is feasible (definition above).
inline bool SegmentIsFeasible(double ax, double atx, double bx, double btx) {
  return atx >= kMinTangentXFrames && btx >= kMinTangentXFrames && ax < bx &&
         atx + btx <= 3.0 * (bx - ax);
}

// The curve's value at `frame`, which must lie in [a.x, b.x] of a feasible segment.
double HermiteValueAtFrame(const HermiteKey2D& a, const HermiteKey2D& b, double frame);

// Sum of the segment errors (definition above) over all segments: the error of the whole curve
// at every frame. x(s_f) = f is solved frame by frame, each solve starting from a Newton step off
// the previous frame's solution, and the solutions are kept per segment shape in a per-thread
// table that the DP passes share, so the error of a path is evaluated on exactly the basis values
// its DP costs were built from. The table is bounded and changes no value: results depend on the
// arguments alone. Precondition: every segment feasible and inside the samples.
double CurveSquaredError(std::span<const double> samples, std::span<const HermiteKey2D> keys);

// The tie scale of the definition above.
double DpTieScale(std::span<const double> samples);

// Checks that `keys` can start a fit of `samples`: at least 2 samples and 2 keys, all finite,
// first key at x = 0, last at x = samples - 1, every segment feasible.
// Errors: kInvalidArgument "key 3: segment to key 4 is not monotonic in time (tx 2 + 3 > 3 * 1)".
absl::Status ValidateHermiteKeys(std::span<const double> samples,
                                 std::span<const HermiteKey2D> keys);

// One DP pass over the search grid around `keys` (steps 2 to 5). Returns the Viterbi path.
// Uses, for each segment and each of its 81 x-combinations, the quadratic form of the error in
// the four y-components (one x(s) = f solve per frame, not per y-combination) and skips
// x-combinations whose cheapest predecessor already costs more than every target's best
// candidate plus its tie tolerance, which cannot change the choice. The result equals the
// brute force over all 6561 combinations under the rules above.
// Preconditions: ValidateHermiteKeys() passed; steps finite and > 0. Thread-safe.
HermiteDpPass RunHermiteDpPass(std::span<const double> samples,
                               std::span<const HermiteKey2D> keys, const HermiteSteps& steps);

// The iteration (step 6) from `initial` keys.
// Errors: kInvalidArgument from ValidateHermiteKeys(), non-finite samples, steps not finite and
// > 0, accuracy not finite and > 0, max_iterations outside [0, 1000]; kCancelled when `stop` is
// requested, checked before every pass and, inside one, after every kDpStopCheckFrames frames of
// basis solves and data sums (a few milliseconds of work on any input).
// Thread-safe.
inline constexpr std::int64_t kDpStopCheckFrames = 8192;
absl::StatusOr<HermiteFitResult> FitHermiteDp(std::span<const double> samples,
                                              std::vector<HermiteKey2D> initial,
                                              const HermiteFitOptions& options,
                                              std::stop_token stop = {});

// The fitted spline as keys of a Curve over time = x * frame_time_seconds, such that
// EvaluateCurve() reproduces the 2D Hermite (to rounding): value = y; in and out tangent =
// ty / (tx * frame_time_seconds) (slope per second); out weight = tx / (3 * (next x - x)), in
// weight = tx / (3 * (x - previous x)), i.e. the Bezier handle p + r/3 as a fraction of the
// segment. The first key's in weight mirrors its out weight and the last key's out weight its
// in weight (unused by evaluation; tools want both). One key gives a flat key.
// Precondition: keys feasible, frame_time_seconds > 0.
Curve HermiteKeysToCurve(std::span<const HermiteKey2D> keys, double frame_time_seconds);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_HERMITE_DP_H_
