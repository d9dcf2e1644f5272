#include "tempokey/core/model/kinematics.h"

#include "absl/strings/str_cat.h"

namespace tempokey::core {

std::vector<JointRotation> JointRotations(const Clip& clip) {
  std::vector<JointRotation> out;
  const auto& joints = clip.skeleton.joints;
  for (std::size_t j = 0; j < joints.size(); ++j) {
    JointRotation rotation;
    rotation.joint = static_cast<int>(j);
    for (int c : joints[j].channels) {
      const ChannelKind kind = clip.channels[static_cast<std::size_t>(c)].kind;
      if (!IsRotation(kind)) continue;
      if (rotation.channels.size() < 3) {
        rotation.order[rotation.channels.size()] = Axis(kind);
      }
      rotation.channels.push_back(c);
    }
    if (!rotation.channels.empty()) out.push_back(std::move(rotation));
  }
  return out;
}

absl::StatusOr<std::vector<Vec3>> JointWorldPositions(const Clip& clip, std::int64_t frame) {
  if (clip.skeleton.empty()) {
    return absl::InvalidArgumentError("forward kinematics needs a skeleton, the clip has none");
  }
  if (absl::Status valid = ValidateClip(clip); !valid.ok()) return valid;
  if (frame < 0 || frame >= clip.frame_count) {
    return absl::InvalidArgumentError(absl::StrCat("frame ", frame, " is outside the clip's ",
                                                   clip.frame_count, " frames"));
  }
  const auto f = static_cast<std::size_t>(frame);
  const auto& joints = clip.skeleton.joints;
  std::vector<Mat3> world_rotation(joints.size());
  std::vector<Vec3> world_position(joints.size());
  for (std::size_t j = 0; j < joints.size(); ++j) {
    const Joint& joint = joints[j];
    Vec3 translation = joint.offset;
    Mat3 rotation{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
    for (int c : joint.channels) {
      const Channel& channel = clip.channels[static_cast<std::size_t>(c)];
      const double value = channel.samples[f];
      if (IsPosition(channel.kind)) {
        translation[static_cast<std::size_t>(Axis(channel.kind))] = value;
      } else if (IsRotation(channel.kind)) {
        rotation = MatMul(rotation, AxisMatrix(Axis(channel.kind), value));
      }
    }
    if (joint.parent < 0) {
      world_rotation[j] = rotation;
      world_position[j] = translation;
    } else {
      const auto p = static_cast<std::size_t>(joint.parent);
      const Vec3 moved = MatVec(world_rotation[p], translation);
      world_position[j] = {world_position[p][0] + moved[0], world_position[p][1] + moved[1],
                           world_position[p][2] + moved[2]};
      world_rotation[j] = MatMul(world_rotation[p], rotation);
    }
  }
  return world_position;
}

}  // namespace tempokey::core
