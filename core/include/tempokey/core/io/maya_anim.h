// Maya .anim export of keyed clips (SPEC 2).
//
// Maya .anim (ASCII, animVersion 1.1): one `anim` block per channel, attribute
// rotate.rotateX / translate.translateX ... (plain channels use their name), node = the joint
// name; `weighted 1`.
// Time: timeUnit is the Maya unit whose rate is nearest the clip's (in ratio): game 15, film 24,
// pal 25, ntsc 30, show 48, palf 50, ntscf 60, 23.976fps / 29.97fps / 47.952fps / 59.94fps (24,
// 30, 48, 60 x 1000/1001), or "<N>fps" for N in 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 40, 75, 80,
// 100, 120, 125, 150, 200, 240, 250, 300, 375, 400, 500, 600, 750, 1200, 1500, 2000, 3000, 6000
// (so 30000/1001 Hz is 29.97fps, and a BVH's 0.0083333 s frames are 120fps). Key times and
// endTime are in frames of that unit, time_seconds * unit rate, so Maya plays every key at its
// time whatever the clip's rate; keys of a clip off the unit's rate land between whole frames.
// Tangents: every key has fixed in and out tangents as angle and weight. A key side's Bezier
// handle spans dt = weight * T seconds (T the segment's duration, unset weights 1/3) and
// dv = slope * dt; Maya's tangent vector is (x, y) = (3 dt, 3 dv), time in seconds:
// angle = atan2(y, x) in degrees, weight = hypot(x, y). tanLock is 1 when in and out slopes are
// equal. Angular curves are degrees (angularUnit deg), linear ones the file's units written as
// linearUnit cm.
#ifndef TEMPOKEY_CORE_IO_MAYA_ANIM_H_
#define TEMPOKEY_CORE_IO_MAYA_ANIM_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/keyed_clip.h"

namespace tempokey::core {

// The Maya .anim text of `keyed` (conventions above).
// Errors: kInvalidArgument from ValidateKeyedClip(). Thread-safe.
absl::StatusOr<std::string> FormatMayaAnim(const KeyedClip& keyed);

// FormatMayaAnim() then WriteFileAtomically().
absl::Status WriteMayaAnimFile(const std::string& path, const KeyedClip& keyed);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_MAYA_ANIM_H_
