// The Euler filter (what Maya's `filterCurve -f euler` does, SPEC 4.3): a joint's Euler triple
// that jumps to another solution of the same rotation between frames is rewritten as the
// equivalent triple nearest the previous frame, so the curves are continuous and the rotations
// unchanged.
//
// For Euler angles (a, b, c) in any of the six Tait-Bryan orders R = R_i(a) R_j(b) R_k(c), the
// triples of the same rotation are (a + 360 p, b + 360 q, c + 360 s) and the other branch
// (a + 180 + 360 p, 180 - b + 360 q, c + 180 + 360 s) for all integers p, q, s (away from gimbal
// lock, b = +-90, where infinitely many triples share the rotation and only these are
// considered). Frame by frame from the first, which is kept, each frame's triple becomes the one
// of these nearest the previous frame's filtered triple in the sum of absolute differences of
// the three angles; on a tie the unflipped branch is kept. Each angle of a branch is first
// brought within 180 of the previous one (whole turns), so a frame already continuous with the
// previous one is left as it is (unless the other branch is nearer still, which only happens
// near gimbal lock). This is what Maya's Euler filter does (`filterCurve -f euler`: "demangles
// discontinuous rotation anim curves into smooth curves", Autodesk Maya command reference,
// https://help.autodesk.com/cloudhelp/2016/ENU/Maya-Tech-Docs/Commands/filterCurve.html); the
// reference names no distance, and the absolute one is the choice that keeps a real rotation
// jump in as few curves as it can (the squared one spreads it over all three; euler_filter.cc).
// Each angle is only moved by adding 180 or 360 multiples or negated around 90, so the rotation
// matrices agree to rounding (about 1e-13 for angles below a few thousand degrees).
#ifndef TEMPOKEY_CORE_MODEL_EULER_FILTER_H_
#define TEMPOKEY_CORE_MODEL_EULER_FILTER_H_

#include <cstdint>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/rotation.h"

namespace tempokey::core {

// The triple of the rotation `degrees` (in `order`) nearest `previous` (definition above).
// Precondition: valid order, finite angles. Thread-safe.
Vec3 NearestEquivalentEuler(const Vec3& degrees, const Vec3& previous);

// What ApplyEulerFilter() changed.
struct EulerFilterReport {
  std::int64_t frames_changed = 0;  // (joint, frame) pairs whose triple was rewritten
  int joints_filtered = 0;          // joints with three rotation channels
};

// Filters every joint of `clip` that has three rotation channels, in place. Joints with fewer
// rotation channels have each angle unwrapped instead (UnwrapDegrees(): whole turns only), the
// only equivalent values a lone angle has. Other channels are untouched.
//
// Errors: kInvalidArgument when `clip` fails ValidateClip().
// Thread-safe: touches only `clip`.
absl::StatusOr<EulerFilterReport> ApplyEulerFilter(Clip& clip);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_EULER_FILTER_H_
