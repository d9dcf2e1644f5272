// glTF 2.0 export of clips and keyed clips (SPEC 2): a skin-less node hierarchy and one animation.
//
// The scene: one node per joint, in file order, with the joint's name and its BVH offset as rest
// translation (no rotation, no scale), children as in the skeleton; each End Site is a child node
// named "<joint>_end" (numbered when a joint has several; made unique against joint names) with
// its offset, so viewers can draw the last bones. Units are the file's as they are (BVH files
// are often centimetres; glTF means metres: scale the scene by 0.01 on import, README).
// Channels without a joint are not written (glTF animates nodes only).
//
// The animation ("<clip name>", one per file):
//   - translation: for a joint with position channels, a VEC3 sampler whose components are the
//     position channels (each replaces the offset's component on its axis, as in BVH) and the
//     offset on axes without a channel;
//   - rotation: for a joint with rotation channels, a VEC4 quaternion (x, y, z, w) sampler of
//     the rotation its channels compose in their listed order (BVH: intrinsic, left to right,
//     `Zrotation Xrotation Yrotation` is Rz·Rx·Ry; rotation.h), axes without a channel being 0.
// Sampled clips (FormatGltfSampled): LINEAR samplers with one key per frame.
// Keyed clips (FormatGltfKeyed): CUBICSPLINE samplers (in-tangent, value, out-tangent per key;
// tangents per second, multiplied by the key interval when evaluated, glTF 2.0 "Animation
// Samplers"; a sampler of one key, from a one-frame clip, is LINEAR with its value alone: glTF
// requires at least two keyframes of a CUBICSPLINE sampler):
//   - translation: the keyed position curves, exactly: one time list, the union of the joint's
//     position curves' key times; a curve is split at the times it lacks (splitting a cubic is
//     exact: value and slope there). Weighted segments (`paper` keys: a Bezier whose time is not
//     linear in its parameter, which CUBICSPLINE cannot hold) get a key at every source frame
//     they span, with the curve's exact value and slope there.
//   - rotation: the Euler curves do not carry over (glTF interpolates quaternion components and
//     normalises), so rotation keys are fitted again against the SOURCE rotations
//     (quaternion_fit.h) within `max_rotation_error_degrees` at every source frame. The source
//     clip is therefore part of the call: export where the source is at hand (the CLI has the
//     input file; a server job returns the keyed clip and the client writes the glTF).
//   - under a joint bound (GltfKeyedOptions::joint_tolerance, the reduction's `--joint-tolerance`)
//     each joint's rotation bound comes from it too, and the file as glTF evaluates it is
//     measured against the source by forward kinematics (below).
//
// The joint bound in glTF. The reduction's joint bound holds for its Euler curves; the glTF's
// rotations are other curves, so the file is measured on its own: at every source frame every
// joint and end site is placed from the file's data (its float32 translation keys and rest
// translations, its quaternion keys evaluated as glTF does, EvaluateQuaternionCurve()) and
// compared with its position under the source's samples (ForwardKinematics, the measure the
// reduction's joint bound and world-error report use). The fit:
//   1. Each joint's rotation bound starts at the angle whose chord at its lever is the bound
//      (the largest distance, over the source's frames, from the joint to a point its rotation
//      moves, and at least kMinLeverHeightFraction of the figure's height: joint_bound.h), capped
//      by `max_rotation_error_degrees`.
//   2. Fit, measure; for each point over the bound, the rotations that move it (its joint's for
//      an end site, and every joint above) are tightened by the factor its error asks for (0.9 x
//      bound / error, in [0.25, 0.9]), and refitted; repeat.
//   3. After kGltfJointBoundRounds refits, every rotation moving a point still over the bound
//      takes a key at every source frame (the source's rotation there, to float32), and the file
//      is measured once more. A point still over the bound then (its error comes from the keyed
//      translations or float32 rounding, which no rotation keys change) is an error: no file is
//      written that breaks the bound.
// The bytes are the same for any thread count, and a file without a joint bound is as before.
// Times, values and tangents are float32 in the file (the glTF accessor type); key times are
// i x frame time.
//
// Containers: .gltf is the JSON with the buffer embedded as a base64 data URI (one file, written
// atomically); .glb is the binary container (JSON chunk, BIN chunk).
#ifndef TEMPOKEY_CORE_IO_GLTF_H_
#define TEMPOKEY_CORE_IO_GLTF_H_

#include <cstdint>
#include <optional>
#include <stop_token>
#include <string>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/joint_bound.h"

namespace tempokey::core {

enum class GltfContainer {
  kText,    // .gltf: JSON, buffer embedded as a data URI
  kBinary,  // .glb
};

// Counts of what a file holds, for reports and benchmarks.
struct GltfStats {
  int animated_joints = 0;               // joints with a rotation sampler
  std::int64_t rotation_keys = 0;        // keys over all rotation samplers
  std::int64_t rotation_samples = 0;     // source frames x joints with a rotation sampler
  std::int64_t translation_keys = 0;     // keys over all translation samplers
  // Under a joint bound (GltfKeyedOptions::joint_tolerance; all 0 without one): the bound in file
  // units, the largest distance of any joint or end site from its source position over every
  // source frame as the file evaluates (<= joint_bound), and the rounds measured (1 when the
  // first fit kept the bound, one more per refit; kGltfJointBoundRounds + 2 when some rotations
  // took a key at every frame).
  double joint_bound = 0.0;
  double max_joint_error = 0.0;
  int joint_bound_rounds = 0;
};

struct GltfFile {
  std::string bytes;
  GltfStats stats;
};

// A sampled clip: LINEAR samplers, one key per frame.
// Errors: kInvalidArgument from ValidateClip(), a clip without a skeleton ("glTF export needs a
// skeleton: ..."), or a frame time too small for distinct float32 key times. Thread-safe.
absl::StatusOr<GltfFile> FormatGltfSampled(const Clip& clip, GltfContainer container);

struct GltfKeyedOptions {
  // Largest angle between a glTF rotation and the source rotation at any source frame, degrees,
  // finite and > 0: use the reduction's rotation tolerance (GltfRotationBoundDegrees(),
  // file_formats.h). kNoRotationBoundDegrees: none (a joint bound alone then bounds them).
  double max_rotation_error_degrees = 0.5;
  // A world-space bound (joint_bound.h; a percentage is of the source's figure height, as the
  // reduction resolves it): every joint and end site of the file, as glTF evaluates it, within it
  // of its source position at every source frame (the joint bound above). Unset: none, and the
  // rotations are fitted within `max_rotation_error_degrees` alone.
  std::optional<JointTolerance> joint_tolerance = std::nullopt;
  // Joints whose rotations are fitted at once, each on a thread (the calling one among them):
  // the same bytes for any count. <= 1: the calling thread alone. Fewer on long clips, so that
  // the fits' working memory (about 128 bytes a frame each) stays within about 1 GiB.
  int threads = 1;
};

// The largest angle between two rotations: as a rotation bound, no bound at all.
inline constexpr double kNoRotationBoundDegrees = 180.0;

// Refits of the rotations under a joint bound before the rotations moving a point still over it
// take a key at every frame (the joint bound above).
inline constexpr int kGltfJointBoundRounds = 8;

// A keyed clip, with `source` the clip it was reduced from (same layout, frame time and frame
// count): CUBICSPLINE samplers as above.
// Errors: kInvalidArgument from ValidateClip() / ValidateKeyedClip(), a source whose layout, frame
// time or frame count differs from the keyed clip's, no skeleton, a rotation bound that is not
// finite and > 0, a joint tolerance that is not (ValidateJointTolerance()); kFailedPrecondition
// for a joint tolerance in percent of a figure of height 0 (ResolveJointTolerance()), or a point
// the file cannot keep within the joint bound, not even with every rotation moving it keyed at
// every frame or when none moves it: its error is then the keyed translations' or float32's
// ("glTF cannot keep every joint within the joint bound 1e-09 file units: LeftHand is 2.1e-06
// from its source position at frame 40 with every rotation moving it keyed at every frame (the
// keyed translations' error and float32 rounding remain)"); kCancelled when `stop` is requested
// (looked at between joints, in the translation key times and keys, in each joint's rotations
// and inside its rotation fits, FitQuaternionCurve(), and every 128 frames of a joint-bound
// measure).
// Thread-safe.
absl::StatusOr<GltfFile> FormatGltfKeyed(const Clip& source, const KeyedClip& keyed,
                                         const GltfKeyedOptions& options, GltfContainer container,
                                         std::stop_token stop = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_GLTF_H_
