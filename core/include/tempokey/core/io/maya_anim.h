// Maya .anim export of keyed clips (SPEC 2), in the semantics Maya itself reads them with.
//
// Sources (each fact below was checked against them):
//   [ANIM]  Autodesk, "ANIM file format" (animVersion 1.1), Maya help: header lines, `anim` and
//           `animData` blocks, and the key line
//             time value inTangentType outTangentType tanLock weightLock breakdown
//             [inAngle inWeight] [outAngle outWeight]
//           where an angle/weight pair follows only a `fixed` tangent.
//   [DEVKIT] Maya devkit plug-in animImportExport (animFileImport / its C# port): the reader sets
//           MTime::uiUnit and MDistance::uiUnit to the file's timeUnit and linearUnit before it
//           calls MFnAnimCurve::setTangent(index, MAngle(angle, angularUnit), weight), "so that
//           fixed tangent data is read in properly": angle and weight are in UI space.
//   [HOUDINI] SideFX, "Converting animation key values between Houdini and Maya": Maya's angle and
//           weight are frame based: tan(Angle) = DV / DF with DF in frames, Weight^2 = DF^2 +
//           DV^2; Maya weighted keys are Bezier keys, non-weighted keys are plain cubic (slope
//           only) keys.
//   [ANIMX] Autodesk AnimX (github.com/Autodesk/animx, src/animx.cpp, internal/interpolators.h):
//           a weighted curve evaluates each segment as the 2D Bezier through the two keys and
//           their handles; a non-weighted curve evaluates the cubic Hermite in time whose end
//           slopes are the tangents' dy/dx (the handle length plays no part).
//   [XFORM] Autodesk, Maya node reference "transform": points are row vectors and rotateOrder
//           `xyz` applies X first, then Y, then Z; the enum is xyz 0, yzx 1, zxy 2, xzy 3, yxz 4,
//           zyx 5.
//
// What is written:
//   - Header: animVersion 1.1, timeUnit (below), linearUnit cm, angularUnit deg (values are
//     written as they are: degrees, and the clip's file units declared as cm), startTime 0,
//     endTime = the last source frame in file frames. Then comment lines (`//`, which [ANIM]
//     allows) giving each joint's Maya rotateOrder for its BVH channel order (see below).
//   - One `anim` block per channel: attribute rotate.rotateX / translate.translateX ... on the
//     node named after the joint (a plain channel: its name on a node of that name), input time,
//     output angular / linear / unitless, pre and post infinity constant.
//   - Time: timeUnit is one of the units every version of Maya's reader accepts: game 15,
//     film 24, pal 25, ntsc 30, show 48, palf 50, ntscf 60 ([ANIM] lists these; [DEVKIT]'s
//     animUnitNames::setFromName() refuses any other name, "'120fps' is not a valid time unit",
//     so the numbered units of later Maya versions are not used). The unit is the clip's rate
//     (within 1e-4, relative): a file frame is one source frame and key times are the source's
//     frame numbers; else the fastest unit whose rate divides the clip's n times (120 Hz: ntscf,
//     n = 2; 100 Hz: palf): source frame f is file frame f / n (a BVH's 0.0083333 s frames are
//     120 Hz, so key 995 is at 497.5); else the slowest unit whose rate is m times the clip's
//     (12 Hz: film, m = 2; 10 Hz: ntsc): f is file frame m f; else the unit nearest in ratio, with
//     time = seconds x unit rate (keys may fall between frames). Maya turns the file's times into
//     the scene's on import, so a 120 fps scene shows a 120 Hz clip's keys on whole frames.
//     Call the file frames per second k (m / (n x frame time), or the unit's rate).
//   - Tangents: every key's in and out tangents are `fixed`, given as angle (degrees) and weight
//     in UI space: x in file frames, y in the channel's value unit.
//       * A curve none of whose keys carries a weight (the `tolerance` method's C1 Hermite keys)
//         is written `weighted 0`: angle = atan(slope / k), the slope per file frame; Maya then
//         evaluates the same cubic Hermite in time [ANIMX], [HOUDINI]. The weight is written as
//         1 (Maya ignores it on non-weighted curves; Maya's own exports write 1 too).
//       * A curve with any weighted key (the `paper` method) is written `weighted 1`. A key
//         side's Bezier handle spans dt = weight x T seconds (T the segment's duration, unset
//         weights 1/3, keyed_clip.h) and dv = slope x dt; in UI space that is DF = dt x k
//         frames and DV = dv: angle = atan2(DV, DF), weight = hypot(DF, DV), the handle's length
//         with no factor 3 and no normalisation (a flat default handle on a 30-frame segment
//         has weight 10). Maya puts the out handle of a key at (F + w cos(angle), V + w
//         sin(angle)) and the in handle at (F - w cos(angle), V - w sin(angle)) [HOUDINI].
//     The first key's in side and the last key's out side have no segment; they mirror the
//     other side's duration. tanLock is 1 when in and out slopes are equal, weightLock 0,
//     breakdown 0.
//   - Rotation order. A .anim file holds curves only: Maya's reader pastes them onto existing
//     nodes and never sets a node's rotateOrder (it is not keyable on joints, [DEVKIT] pastes
//     keyable attributes). The rotation curves are right only on a joint whose rotateOrder
//     matches the BVH channel order, so the header lists, per joint with rotation channels,
//       // tempokey rotateOrder <joint> <maya order> <enum>;  e.g. "Hips yxz 4"
//     BVH channels `Zrotation Xrotation Yrotation` mean R = Rz·Rx·Ry on column vectors: Y acts
//     first, then X, then Z, so Maya's order is the BVH list reversed ("yxz") [XFORM]. A joint
//     with one or two rotation channels gets a line too: its missing axes (angle 0) are listed
//     first, so `Xrotation Zrotation` (Z acts first) is "zxy"; Maya's default "xyz" would turn X
//     first.
//     README "Opening results" has the Maya step that applies these lines before the import.
#ifndef TEMPOKEY_CORE_IO_MAYA_ANIM_H_
#define TEMPOKEY_CORE_IO_MAYA_ANIM_H_

#include <array>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/keyed_clip.h"

namespace tempokey::core {

// The Maya .anim text of `keyed` (conventions above).
// Errors: kInvalidArgument from ValidateKeyedClip(), or for a joint's or scalar channel's name
// that cannot be one word of a .anim line (empty, or holding whitespace, a control character,
// ';', a brace, '#' or '//': the format's separators and comment marks). Thread-safe.
absl::StatusOr<std::string> FormatMayaAnim(const KeyedClip& keyed);

// FormatMayaAnim() then WriteFileAtomically().
absl::Status WriteMayaAnimFile(const std::string& path, const KeyedClip& keyed);

// Maya's rotateOrder name for BVH rotation channels listed in `order` (axes 0 = X, 1 = Y,
// 2 = Z): the list reversed, lower case ("yxz" for {Z, X, Y}), and its enum value (xyz 0, yzx 1,
// zxy 2, xzy 3, yxz 4, zyx 5). Precondition: a valid order (three distinct axes).
struct MayaRotateOrder {
  std::string name;
  int value = 0;
};
MayaRotateOrder MayaRotateOrderOf(const std::array<int, 3>& order);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_MAYA_ANIM_H_
