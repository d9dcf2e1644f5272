// Forward kinematics and the rotation layout of a skeleton's channels: the one implementation
// that places joints and end sites in the world, used by the world-error report, the joint-bound
// reduction, tests and benchmarks alike.
#ifndef TEMPOKEY_CORE_MODEL_KINEMATICS_H_
#define TEMPOKEY_CORE_MODEL_KINEMATICS_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
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

// A point forward kinematics places: a joint (end_site -1) or one of a joint's end sites (an
// index into Joint::end_sites).
struct SkeletonPoint {
  int joint = -1;
  int end_site = -1;

  friend bool operator==(const SkeletonPoint&, const SkeletonPoint&) = default;
};

// The points of `skeleton`: every joint in joint order (point i is joint i), then every end site,
// in joint order and each joint's end sites in file order.
std::vector<SkeletonPoint> SkeletonPoints(const Skeleton& skeleton);

// How reports name a point: the joint's name ("LeftToe"), "LeftToe end site" for the only end
// site of a joint, "LeftToe end site 2" (1-based) when the joint has several.
// Precondition: the point's indices are valid for `skeleton`.
std::string SkeletonPointName(const Skeleton& skeleton, const SkeletonPoint& point);

// Forward kinematics of one clip layout, planned once and evaluated per frame, BVH conventions: a
// joint's local transform is a translation (its offset, with each position channel replacing the
// offset's component on that axis) followed by its rotation (the axis matrices of its rotation
// channels multiplied in listed order: `Zrotation Xrotation Yrotation` is Rz·Rx·Ry, degrees);
// world = parent world · local; an end site sits at its offset in its joint's frame. Rotations
// are built from axis matrices directly, not from quaternions. Positions are in file units.
//
// Not thread-safe: Pose(), PoseFrames() and PoseFramesFromTrig() use scratch space held here; use
// one instance per thread (a copy carries its own scratch, a few KB per joint).
class ForwardKinematics {
 public:
  // Frames PoseFrames() places together: each joint's transform is held per frame in arrays of
  // this many, so that the arithmetic runs on vectors of frames.
  static constexpr std::size_t kBlockFrames = 32;

  // Errors: kInvalidArgument when `layout` has no skeleton ("forward kinematics needs a
  // skeleton, the clip has none") or fails ValidateClipLayout(). Samples are not read.
  static absl::StatusOr<ForwardKinematics> ForLayout(const Clip& layout);

  // SkeletonPoints() of the layout's skeleton.
  const std::vector<SkeletonPoint>& points() const { return points_; }
  std::size_t point_count() const { return points_.size(); }
  std::size_t joint_count() const { return joints_.size(); }

  // World positions of every point at `frame`, channel c's value read as samples[c][frame].
  // Preconditions: one span per channel of the layout, each longer than `frame`;
  // out.size() == point_count().
  void Pose(std::span<const std::span<const double>> samples, std::size_t frame,
            std::span<Vec3> out);

  // Pose() of frames [first, first + count), frame-major: out[(f - first) * point_count() + p].
  // Every value is Pose()'s at that frame, bit for bit (the same operations in the same order,
  // on vectors of frames). Preconditions: one span per channel of the layout, each at least
  // first + count long; out.size() == count * point_count().
  void PoseFrames(std::span<const std::span<const double>> samples, std::size_t first,
                  std::size_t count, std::span<Vec3> out);

  // PoseFrames() with the cosine and sine of every rotation channel's angle at every frame given:
  // cosines[c][f] and sines[c][f], as RotationTrig() computes them from samples[c] (position
  // channels are read from `samples`; the spans of other channels are not read). For callers
  // that place the same angles more than once.
  void PoseFramesFromTrig(std::span<const std::span<const double>> samples,
                          std::span<const std::span<const double>> cosines,
                          std::span<const std::span<const double>> sines, std::size_t first,
                          std::size_t count, std::span<Vec3> out);

  // The cosine and sine of each angle (degrees) exactly as forward kinematics turns by it: vector
  // kernels within 2.5 units in the last place of the exact values (libm's are within one), each
  // angle's values the same wherever it sits in the span. Preconditions: the three spans have one
  // size.
  static void RotationTrig(std::span<const double> degrees, std::span<double> cosines,
                           std::span<double> sines);

 private:
  struct JointPlan {
    int parent = -1;
    Vec3 offset{};
    std::array<int, 3> position_channel{-1, -1, -1};  // by axis, -1 keeps the offset's
    std::vector<std::pair<int, int>> rotations;        // (axis, channel) in listed order
    std::vector<Vec3> end_sites;
    std::size_t first_end_site_point = 0;
  };

  ForwardKinematics() = default;

  // Places frames [first, first + count) (count <= kBlockFrames): the angles of the r-th rotation
  // channel (joint order, then listed order) by rotation_cos_[r][f], rotation_sin_[r][f].
  void PlaceBlock(std::span<const std::span<const double>> samples, std::size_t first,
                  std::size_t count, std::span<Vec3> out);

  // PlaceBlock() over frames [first, first + count), block by block: set_trig(r, channel,
  // block_first, n) first points rotation_cos_[r] and rotation_sin_[r] at the block's cosines and
  // sines of the r-th rotation channel (its channel index given).
  template <class SetTrig>
  void PlaceBlocks(std::span<const std::span<const double>> samples, std::size_t first,
                   std::size_t count, std::span<Vec3> out, SetTrig set_trig);

  std::vector<JointPlan> joints_;
  std::vector<SkeletonPoint> points_;
  // Scratch: per joint, its world rotation (row-major, nine arrays) and position (three arrays),
  // kBlockFrames values each.
  std::vector<double> block_;
  std::vector<double> trig_;  // per rotation channel, kBlockFrames cosines then sines
  std::vector<const double*> rotation_cos_;
  std::vector<const double*> rotation_sin_;
};

// The world positions of every point (SkeletonPoints() order) at every frame of a clip.
struct PointTrajectories {
  std::vector<SkeletonPoint> points;
  std::int64_t frame_count = 0;
  std::vector<Vec3> positions;  // frame-major: positions[frame * points.size() + point]

  const Vec3& at(std::int64_t frame, std::size_t point) const {
    return positions[static_cast<std::size_t>(frame) * points.size() + point];
  }
};

// ForwardKinematics over every frame of `clip`.
// Errors: kInvalidArgument when the clip has no skeleton or fails ValidateClip().
// Thread-safe: a pure function of its arguments.
absl::StatusOr<PointTrajectories> WorldTrajectories(const Clip& clip);

// World-space positions (file units) of every joint at `frame` (ForwardKinematics; end sites
// left out).
//
// Errors: kInvalidArgument when the clip has no skeleton, fails ValidateClip(), or `frame` is
// outside [0, frame_count).
// Thread-safe: a pure function of its arguments.
absl::StatusOr<std::vector<Vec3>> JointWorldPositions(const Clip& clip, std::int64_t frame);

// The figure's height, the length every relative (percent) measure of a clip refers to: the
// extent along Y, BVH's up axis, of every joint and end site at the clip's first frame (max y -
// min y), file units. The first frame rather than the rest pose because BVH rest poses need not
// stand up (the Bandai captures' offsets all point along X and only the motion turns them
// upright). 0 for a figure flat in Y at its first frame.
//
// Errors: kInvalidArgument when the clip has no skeleton or fails ValidateClip().
// Thread-safe: a pure function of its arguments.
absl::StatusOr<double> FigureHeight(const Clip& clip);

// FigureHeight()'s measure of one pose: max y - min y over `points` (0 when empty).
double VerticalExtent(std::span<const Vec3> points);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_KINEMATICS_H_
