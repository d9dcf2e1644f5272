// Forward kinematics and the rotation layout of a skeleton's channels.
#ifndef TEMPOKEY_CORE_MODEL_KINEMATICS_H_
#define TEMPOKEY_CORE_MODEL_KINEMATICS_H_

#include <cstdint>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/rotation.h"

namespace tempokey::core {

// The rotation channels of one joint, in the joint's listed (file) order.
struct JointRotation {
  int joint = -1;
  std::vector<int> channels;  // indices into Clip::channels, rotation channels only
  // The Euler order when `channels` has three entries (their axes in listed order); meaningless
  // otherwise.
  EulerOrder order{0, 1, 2};
};

// Every joint that has at least one rotation channel, in joint order.
// Precondition: `clip` passes ValidateClipLayout() (rotation axes of a joint are distinct).
std::vector<JointRotation> JointRotations(const Clip& clip);

// World-space positions (file units) of every joint at `frame`, BVH conventions: a joint's
// local transform is a translation (its offset, with each position channel replacing the
// offset's component on that axis) followed by its rotation (EulerToMatrix of its three
// rotation channels in listed order; missing axes are 0); world = parent world · local.
// Rotations are built from axis matrices directly, not from quaternions.
//
// Errors: kInvalidArgument when the clip has no skeleton, fails ValidateClip(), or `frame` is
// outside [0, frame_count).
// Thread-safe: a pure function of its arguments.
absl::StatusOr<std::vector<Vec3>> JointWorldPositions(const Clip& clip, std::int64_t frame);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_KINEMATICS_H_
