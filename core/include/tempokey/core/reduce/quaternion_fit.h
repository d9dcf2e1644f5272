// Quaternion key reduction for glTF CUBICSPLINE rotation samplers (SPEC 2).
//
// glTF evaluates a CUBICSPLINE rotation by interpolating the four quaternion components with the
// cubic Hermite of its keys, then normalising (glTF 2.0 specification, "Animation Samplers" and
// Appendix C): between keys k and k+1, t_d = t_{k+1} - t_k, s = (t - t_k) / t_d,
//   p(s) = (2s³-3s²+1) v_k + t_d (s³-2s²+s) b_k + (-2s³+3s²) v_{k+1} + t_d (s³-s²) a_{k+1},
//   rotation = p / |p|,
// with v the key values, b_k the out-tangent of key k and a_{k+1} the in-tangent of key k+1, per
// second. Euler Hermite keys do not carry over to that, so rotations are fitted again, in that
// semantics, against the source rotations.
//
// The fit: the four components are fitted together with the error-bounded Hermite fit
// (tolerance_fit.h: shared key frames, least-squares values and slopes, C1) within a per-component
// bound e; a component error vector |d| <= 2e turns the rotation by at most 2 asin(2e), so
// e = sin(bound / 2) / 2 is safe, and larger e (fewer keys) is often still within the bound
// once measured. Key values are normalised (glTF validators require unit key values; each key's
// tangents are scaled with its value). The result is then measured exactly as glTF evaluates it,
// with the values, tangents and times rounded to float32 as a file stores them, at every source
// frame; the largest e of a descending ladder that stays within the bound is kept, and a joint
// no ladder step fits gets a key at every frame (exact at every frame but for float32 rounding).
#ifndef TEMPOKEY_CORE_REDUCE_QUATERNION_FIT_H_
#define TEMPOKEY_CORE_REDUCE_QUATERNION_FIT_H_

#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/rotation.h"

namespace tempokey::core {

// One key of a glTF CUBICSPLINE quaternion curve: value (unit) and in/out tangents (component
// derivatives per second). Times are float32-representable (a file stores them so).
struct QuaternionKey {
  double time_seconds = 0.0;
  Quat in_tangent{0, 0, 0, 0};
  Quat value;
  Quat out_tangent{0, 0, 0, 0};
};

struct QuaternionCurve {
  std::vector<QuaternionKey> keys;  // strictly increasing times
};

// The rotation of `curve` at `time_seconds`, as glTF evaluates it (above); the end keys' values
// before the first and after the last key. Precondition: at least one key. Thread-safe.
Quat EvaluateQuaternionCurve(const QuaternionCurve& curve, double time_seconds);

// Fits `rotations` (one per source frame, frame i at i * frame_time_seconds) with the fewest keys
// this fit finds such that EvaluateQuaternionCurve() at every source frame is within
// `max_angle_degrees` of the source rotation (angle of the rotation between them; a bound of 180
// or more allows any rotation, and gives the fit of 180). Values, tangents and times of the
// result are already rounded to float32.
//
// Errors: kInvalidArgument for no rotations, a non-finite or zero quaternion, a frame time or
// bound that is not finite and > 0, or a frame time too small for float32 key times to stay
// distinct; kCancelled when `stop` is requested.
// Thread-safe: a pure function of its arguments.
absl::StatusOr<QuaternionCurve> FitQuaternionCurve(std::span<const Quat> rotations,
                                                   double frame_time_seconds,
                                                   double max_angle_degrees,
                                                   std::stop_token stop = {});

// The largest angle (degrees) between `curve` and `rotations` over the source frames.
double MaxQuaternionCurveError(const QuaternionCurve& curve, std::span<const Quat> rotations,
                               double frame_time_seconds);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_QUATERNION_FIT_H_
