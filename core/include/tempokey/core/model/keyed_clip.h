// Key-reduced clips: per channel a cubic Hermite curve of keys (SPEC 1, 4.3).
//
// Evaluation semantics (Maya weighted / non-weighted tangents, glTF CUBICSPLINE):
// between keys a and b, with dt = b.time_seconds - a.time_seconds > 0,
//   wa = a.out_weight (1/3 when unset), wb = b.in_weight (1/3 when unset),
// the curve is the 2D cubic Bezier in (time, value) with controls
//   time:  a.t,  a.t + wa*dt,                  b.t - wb*dt,                 b.t
//   value: a.v,  a.v + a.out_tangent*wa*dt,    b.v - b.in_tangent*wb*dt,    b.v
// evaluated at the parameter s where its time coordinate equals the query time. When neither key
// of a segment carries a weight, time is linear in s and this is exactly the standard cubic
// Hermite in time with tangents scaled by dt (glTF CUBICSPLINE). Before the first key and after
// the last the curve holds the end key's value.
#ifndef TEMPOKEY_CORE_MODEL_KEYED_CLIP_H_
#define TEMPOKEY_CORE_MODEL_KEYED_CLIP_H_

#include <cmath>
#include <cstdint>
#include <optional>
#include <span>
#include <stop_token>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::core {

// One key. Tangents are slopes in value units per second. Weights, when set, make the tangent
// 2D (Maya weighted tangents): the Bezier handle spans weight × (segment length in time) along
// the time axis, i.e. non-weighted keys behave as weights of 1/3. `in_*` applies to the segment
// ending at this key, `out_*` to the segment starting at it.
struct Key {
  double time_seconds = 0.0;
  double value = 0.0;
  double in_tangent = 0.0;
  double out_tangent = 0.0;
  std::optional<double> in_weight;
  std::optional<double> out_weight;

  friend bool operator==(const Key&, const Key&) = default;
};

struct Curve {
  std::vector<Key> keys;  // sorted by strictly increasing time

  friend bool operator==(const Curve&, const Curve&) = default;
};

// The layout of the clip the curves came from (its samples empty; frame_count and
// frame_time_seconds describe that source) and one curve per channel, in channel order.
struct KeyedClip {
  Clip layout;
  std::vector<Curve> curves;

  friend bool operator==(const KeyedClip&, const KeyedClip&) = default;
};

// Slack allowed on the sum of a segment's two weights above 1, so weights computed from a
// monotonic 2D tangent pair survive the rounding of the division.
inline constexpr double kWeightSumSlack = 1e-9;

// Checks a keyed clip: ValidateClipLayout() on the layout; one curve per channel; each curve has
// at least one key; every time, value, tangent and weight is finite, times within
// +-kMaxTimeSeconds, values within +-kMaxKeyValueMagnitude and tangents within +-kMaxKeyTangent
// (clip.h); times strictly increase;
// weights, when present, are in (0, 1]; within each segment out_weight(a) + in_weight(b) <= 1
// (+ kWeightSumSlack), unset weights counting as 1/3, which keeps time monotonic in s.
//
// Errors: kInvalidArgument naming channel and key, e.g.
//   "channel 3 (Hips.Xrotation): key 5: time 0.5 s is not after the previous key's 0.5 s".
// Thread-safe.
absl::Status ValidateKeyedClip(const KeyedClip& keyed);

// The same checks on one curve; `label` prefixes messages ("channel 3 (Hips.Xrotation)").
absl::Status ValidateCurve(const Curve& curve, std::string_view label);

// The parameter s in [0, 1] at which the cubic Bezier with controls x0 <= x1 <= x2 <= x3 reaches
// `x` (0 at or below x0, 1 at or above x3). Safeguarded Newton on the cubic: the result is the
// root to within a few ulps of s wherever the curve is not flat (|s - s*| <= 1e-12 for the
// weights ValidateCurve() admits). `guess` in (0, 1), when given, starts the search there (a
// neighbouring solution); otherwise it starts at the chord's estimate. Precondition: the
// controls are non-decreasing; they are not checked here. Thread-safe.
double SolveBezierParameter(double x0, double x1, double x2, double x3, double x,
                            std::optional<double> guess = std::nullopt);

// The same for a cubic already in power form measured from its start: the s in [0, 1] with
// ((a s + b) s + c) s = target, 0 for target <= 0, 1 for target >= span = a + b + c, starting
// from `guess` in (0, 1). Precondition: the cubic is non-decreasing on [0, 1]. Thread-safe.
// Inline: it is the innermost loop of curve fitting.
inline double SolveMonotonicCubic(double a, double b, double c, double span, double target,
                                  double guess) {
  if (!(target > 0.0)) return 0.0;
  if (!(target < span)) return 1.0;
  double lo = 0.0;
  double hi = 1.0;
  double s = guess > 0.0 && guess < 1.0 ? guess : target / span;
  for (int iteration = 0; iteration < 200; ++iteration) {
    const double f = ((a * s + b) * s + c) * s - target;
    if (f == 0.0) return s;
    if (f < 0.0) {
      lo = s;
    } else {
      hi = s;
    }
    const double slope = (3.0 * a * s + 2.0 * b) * s + c;
    double next = slope > 0.0 ? s - f / slope : lo - 1.0;
    // Newton leaving the bracket (or a flat spot) falls back to bisection, so the loop always
    // converges on a monotonic cubic.
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (std::abs(next - s) <= 1e-15 || hi - lo <= 1e-15) return next;
    s = next;
  }
  return s;
}

// The curve's value at `time_seconds` (semantics above); constant before the first and after the
// last key. Precondition: ValidateCurve() passed (an empty curve gives 0). O(log keys).
// Thread-safe.
double EvaluateCurve(const Curve& curve, double time_seconds);

// out[i] = EvaluateCurve(curve, (first_frame + i) * frame_time_seconds) for every i, bit for
// bit, in one pass over the keys (O(keys + out.size()) instead of a search per sample): what
// baking and error measurement use; a long channel is sampled in pieces by giving each piece's
// first frame. Precondition: ValidateCurve() passed; frame_time_seconds > 0; first_frame >= 0.
// Thread-safe.
void SampleCurve(const Curve& curve, double frame_time_seconds, std::span<double> out,
                 std::int64_t first_frame = 0);

// Samples every curve at i * frame_time_seconds for i = 0 .. floor(duration / frame_time + 1e-9),
// where duration is the layout's ((frame_count - 1) * layout frame time); unset
// `frame_time_seconds` keeps the layout's frame time. The result has the layout's skeleton,
// channels (with samples), name and markers.
//
// Errors: kInvalidArgument from ValidateKeyedClip(), a frame time outside CheckFrameTime()'s
// range, a result over `limits` ("bake at 0.001 s per frame gives 1000000001 frames x 96
// channels, over the limit of 200000000 samples"), or a baked sample beyond kMaxSampleMagnitude
// (curves whose tangents overshoot); kCancelled when `stop` is requested (checked every 65536
// samples).
// Thread-safe.
// How many frames Bake() gives for a keyed clip lasting `duration_seconds` with `channel_count`
// channels at `frame_time_seconds`: floor(duration / frame time + 1e-9) + 1, checked against
// CheckFrameTime() and `limits` (frames, and frames x channels). Errors: those of Bake() on
// sizes. Thread-safe.
absl::StatusOr<std::int64_t> BakedFrameCount(double duration_seconds, std::size_t channel_count,
                                             double frame_time_seconds,
                                             const ClipLimits& limits = {});

absl::StatusOr<Clip> Bake(const KeyedClip& keyed,
                          std::optional<double> frame_time_seconds = std::nullopt,
                          const ClipLimits& limits = {}, std::stop_token stop = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_KEYED_CLIP_H_
