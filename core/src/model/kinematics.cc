#include "tempokey/core/model/kinematics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <utility>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

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

std::vector<SkeletonPoint> SkeletonPoints(const Skeleton& skeleton) {
  std::vector<SkeletonPoint> points;
  const int joint_count = static_cast<int>(skeleton.joints.size());
  for (int j = 0; j < joint_count; ++j) points.push_back({.joint = j, .end_site = -1});
  for (int j = 0; j < joint_count; ++j) {
    const int sites = static_cast<int>(skeleton.joints[static_cast<std::size_t>(j)].end_sites.size());
    for (int e = 0; e < sites; ++e) points.push_back({.joint = j, .end_site = e});
  }
  return points;
}

std::string SkeletonPointName(const Skeleton& skeleton, const SkeletonPoint& point) {
  const Joint& joint = skeleton.joints[static_cast<std::size_t>(point.joint)];
  if (point.end_site < 0) return joint.name;
  if (joint.end_sites.size() == 1) return absl::StrCat(joint.name, " end site");
  return absl::StrCat(joint.name, " end site ", point.end_site + 1);
}

absl::StatusOr<ForwardKinematics> ForwardKinematics::ForLayout(const Clip& layout) {
  if (layout.skeleton.empty()) {
    return absl::InvalidArgumentError("forward kinematics needs a skeleton, the clip has none");
  }
  TEMPOKEY_RETURN_IF_ERROR(ValidateClipLayout(layout));
  ForwardKinematics fk;
  fk.points_ = SkeletonPoints(layout.skeleton);
  fk.joints_.reserve(layout.skeleton.joints.size());
  std::size_t next_end_site = layout.skeleton.joints.size();
  for (const Joint& joint : layout.skeleton.joints) {
    JointPlan& plan = fk.joints_.emplace_back();
    plan.parent = joint.parent;
    plan.offset = joint.offset;
    for (int c : joint.channels) {
      const ChannelKind kind = layout.channels[static_cast<std::size_t>(c)].kind;
      if (IsPosition(kind)) {
        plan.position_channel[static_cast<std::size_t>(Axis(kind))] = c;
      } else if (IsRotation(kind)) {
        plan.rotations.emplace_back(Axis(kind), c);
      }
    }
    plan.end_sites = joint.end_sites;
    plan.first_end_site_point = next_end_site;
    next_end_site += joint.end_sites.size();
  }
  fk.world_rotation_.resize(fk.joints_.size());
  return fk;
}

namespace {

constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;

// MatVec() of rotation.h, here where every frame's pose calls it for every point.
inline Vec3 Rotated(const Mat3& m, const Vec3& v) {
  return {m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
          m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
          m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]};
}

// m = m · AxisMatrix(axis, degrees), in place. Right-multiplying by a rotation about one axis
// mixes only the other two columns: with (i, k) the axes after `axis` in cyclic order,
// column i becomes c·i + s·k and column k becomes c·k - s·i (12 products instead of 27).
// A zero angle (common: a captured skeleton's unused axes) takes cos 0 = 1 and sin ±0 = ±0
// without the library call, which returns exactly those.
void RotateColumns(Mat3& m, int axis, double degrees) {
  static constexpr std::array<std::size_t, 3> kNext = {1, 2, 0};
  static constexpr std::array<std::size_t, 3> kAfterNext = {2, 0, 1};
  const double r = degrees * kRadiansPerDegree;
  double c = 1.0;
  double s = r;
  if (r != 0.0) {
    c = std::cos(r);
    s = std::sin(r);
  }
  const std::size_t i = kNext[static_cast<std::size_t>(axis)];
  const std::size_t k = kAfterNext[static_cast<std::size_t>(axis)];
  for (std::size_t row = 0; row < 3; ++row) {
    const double a = m[row][i];
    const double b = m[row][k];
    m[row][i] = c * a + s * b;
    m[row][k] = c * b - s * a;
  }
}

}  // namespace

void ForwardKinematics::Pose(std::span<const std::span<const double>> samples, std::size_t frame,
                             std::span<Vec3> out) {
  for (std::size_t j = 0; j < joints_.size(); ++j) {
    const JointPlan& plan = joints_[j];
    Vec3 translation = plan.offset;
    for (std::size_t axis = 0; axis < 3; ++axis) {
      const int c = plan.position_channel[axis];
      if (c >= 0) translation[axis] = samples[static_cast<std::size_t>(c)][frame];
    }
    // The joint's world rotation: its parent's, then each rotation channel in listed order.
    Mat3& world = world_rotation_[j];
    if (plan.parent < 0) {
      world = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
      out[j] = translation;
    } else {
      const auto p = static_cast<std::size_t>(plan.parent);
      world = world_rotation_[p];
      const Vec3 moved = Rotated(world, translation);
      out[j] = {out[p][0] + moved[0], out[p][1] + moved[1], out[p][2] + moved[2]};
    }
    for (const auto& [axis, c] : plan.rotations) {
      RotateColumns(world, axis, samples[static_cast<std::size_t>(c)][frame]);
    }
    for (std::size_t e = 0; e < plan.end_sites.size(); ++e) {
      const Vec3 moved = Rotated(world_rotation_[j], plan.end_sites[e]);
      out[plan.first_end_site_point + e] = {out[j][0] + moved[0], out[j][1] + moved[1],
                                            out[j][2] + moved[2]};
    }
  }
}

namespace {

// The clip's samples as one span per channel.
std::vector<std::span<const double>> SampleSpans(const Clip& clip) {
  std::vector<std::span<const double>> spans;
  spans.reserve(clip.channels.size());
  for (const Channel& channel : clip.channels) spans.emplace_back(channel.samples);
  return spans;
}

absl::StatusOr<ForwardKinematics> CheckedKinematics(const Clip& clip) {
  if (clip.skeleton.empty()) {
    return absl::InvalidArgumentError("forward kinematics needs a skeleton, the clip has none");
  }
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  return ForwardKinematics::ForLayout(clip);
}

}  // namespace

absl::StatusOr<PointTrajectories> WorldTrajectories(const Clip& clip) {
  TEMPOKEY_ASSIGN_OR_RETURN(ForwardKinematics fk, CheckedKinematics(clip));
  const std::vector<std::span<const double>> samples = SampleSpans(clip);
  PointTrajectories out;
  out.points = fk.points();
  out.frame_count = clip.frame_count;
  const std::size_t n = fk.point_count();
  out.positions.resize(static_cast<std::size_t>(clip.frame_count) * n);
  for (std::size_t f = 0; f < static_cast<std::size_t>(clip.frame_count); ++f) {
    fk.Pose(samples, f, std::span<Vec3>(out.positions).subspan(f * n, n));
  }
  return out;
}

absl::StatusOr<std::vector<Vec3>> JointWorldPositions(const Clip& clip, std::int64_t frame) {
  TEMPOKEY_ASSIGN_OR_RETURN(ForwardKinematics fk, CheckedKinematics(clip));
  if (frame < 0 || frame >= clip.frame_count) {
    return absl::InvalidArgumentError(absl::StrCat("frame ", frame, " is outside the clip's ",
                                                   clip.frame_count, " frames"));
  }
  std::vector<Vec3> points(fk.point_count());
  fk.Pose(SampleSpans(clip), static_cast<std::size_t>(frame), points);
  points.resize(fk.joint_count());
  return points;
}

absl::StatusOr<double> FigureHeight(const Clip& clip) {
  TEMPOKEY_ASSIGN_OR_RETURN(ForwardKinematics fk, CheckedKinematics(clip));
  std::vector<Vec3> points(fk.point_count());
  fk.Pose(SampleSpans(clip), 0, points);
  return VerticalExtent(points);
}

double VerticalExtent(std::span<const Vec3> points) {
  if (points.empty()) return 0.0;
  const auto [low, high] = std::minmax_element(
      points.begin(), points.end(), [](const Vec3& a, const Vec3& b) { return a[1] < b[1]; });
  return (*high)[1] - (*low)[1];
}

}  // namespace tempokey::core
