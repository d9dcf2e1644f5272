// The joint bound of a keyed glTF (gltf.h, "The joint bound in glTF"): the file measured as glTF
// evaluates it. Every joint and end site is placed from the file's own float32 translation keys
// and its quaternion curves through the node hierarchy and compared, at every source frame, with
// its source position by forward kinematics; the rotations moving a point over the bound are
// fitted again within tighter bounds, up to kGltfJointBoundRounds times, then keyed at every
// frame. gltf.cc writes the file; the rotation fit itself is its FitRotations(), passed in.
// Internal to tempokey_core.
#ifndef TEMPOKEY_CORE_SRC_IO_GLTF_JOINT_BOUND_H_
#define TEMPOKEY_CORE_SRC_IO_GLTF_JOINT_BOUND_H_

#include <functional>
#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/io/gltf.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/reduce/quaternion_fit.h"

namespace tempokey::core::gltf_internal {

// A joint's keyed translation sampler as the file holds it: float32 key times and, per key, the
// in-tangent, value and out-tangent (three floats each).
struct TranslationKeys {
  int joint = -1;
  std::vector<float> input;
  std::vector<float> output;
};

// Fits rotations[i] as glTF keys within max_angle_degrees[i] degrees of the source at every
// source frame: one curve per rotation, in order, or the first error in that order.
using RotationFitter = std::function<absl::StatusOr<std::vector<QuaternionCurve>>(
    const std::vector<JointRotation>& rotations, std::span<const double> max_angle_degrees)>;
// The source's rotation of `rotation`'s joint at every frame, signs continuous.
using SourceRotations =
    std::function<absl::StatusOr<std::vector<Quat>>(const JointRotation& rotation)>;

// Every joint's rotation keyed under a joint bound (gltf.h, "The joint bound in glTF"); the
// translations are the file's. Sets the stats' joint_bound, max_joint_error and
// joint_bound_rounds.
//
// `rotations` and `translations` as the file writes them (joint order); `options` gives the joint
// bound (its joint_tolerance, which the caller has validated) and the rotation bound;
// `fit_rotations` fits the rotations (gltf.cc's FitRotations(), on the options' threads) and
// `source_rotations` gives the source's rotations for those keyed at every frame.
//
// Errors: kFailedPrecondition when a point stays over the bound with every rotation moving it
// keyed at every frame, or when no rotation moves it (the message names the point, its error
// and frame); kCancelled when `stop` is requested; any error of ForwardKinematics::ForLayout(),
// ResolveJointTolerance(), `fit_rotations` or `source_rotations`.
absl::StatusOr<std::vector<QuaternionCurve>> FitRotationsWithinJointBound(
    const Clip& source, const std::vector<JointRotation>& rotations,
    const std::vector<TranslationKeys>& translations, const GltfKeyedOptions& options,
    const RotationFitter& fit_rotations, const SourceRotations& source_rotations,
    GltfStats& stats, const std::stop_token& stop);

}  // namespace tempokey::core::gltf_internal

#endif  // TEMPOKEY_CORE_SRC_IO_GLTF_JOINT_BOUND_H_
