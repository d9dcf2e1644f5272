#include "tempokey/core/model/kinematics.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <cmath>
#include <numbers>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/src/simd/instruction_set.h"
#include "core/src/simd/vector_trig.h"
#include "core/src/simd/vectors.h"
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
  std::size_t rotation_count = 0;  // rotation channels over every joint
  for (const JointPlan& plan : fk.joints_) rotation_count += plan.rotations.size();
  fk.block_.resize(fk.joints_.size() * 12 * kBlockFrames);
  fk.trig_.resize(rotation_count * 2 * kBlockFrames);
  fk.rotation_cos_.resize(rotation_count);
  fk.rotation_sin_.resize(rotation_count);
  return fk;
}

namespace {

constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;
constexpr std::size_t kB = ForwardKinematics::kBlockFrames;

// The block kernels run on vectors of frames, built for each instruction set and the running
// machine's chosen at run time (simd::RunForInstructionSet(): every build agrees bit for bit).
// A joint's block: its world rotation, row-major (entry (row, col) is the array at
// (row * 3 + col) * kB), then its world position (axis a at (9 + a) * kB).
constexpr std::size_t kBlockStride = 12 * kB;

double* RotationEntry(double* block, std::size_t row, std::size_t col) {
  return block + (row * 3 + col) * kB;
}
const double* RotationEntry(const double* block, std::size_t row, std::size_t col) {
  return block + (row * 3 + col) * kB;
}
double* PositionAxis(double* block, std::size_t axis) { return block + (9 + axis) * kB; }
const double* PositionAxis(const double* block, std::size_t axis) {
  return block + (9 + axis) * kB;
}

// rotation = rotation · AxisMatrix(axis, angle) per frame, in place, the angle given by its cosine
// c[f] and sine s[f]. Right-multiplying by a rotation about one axis mixes only the other two
// columns: with (i, k) the axes after `axis` in cyclic order, column i becomes c·i + s·k and
// column k becomes c·k - s·i (12 products instead of 27).
[[gnu::always_inline]] inline void RotateColumnsOnVectors(double* block, int axis,
                                                          const double* c, const double* s,
                                                          std::size_t n) {
  static constexpr std::array<std::size_t, 3> kNext = {1, 2, 0};
  static constexpr std::array<std::size_t, 3> kAfterNext = {2, 0, 1};
  const std::size_t i = kNext[static_cast<std::size_t>(axis)];
  const std::size_t k = kAfterNext[static_cast<std::size_t>(axis)];
  for (std::size_t row = 0; row < 3; ++row) {
    double* __restrict column_i = RotationEntry(block, row, i);
    double* __restrict column_k = RotationEntry(block, row, k);
    for (std::size_t f = 0; f < n; ++f) {
      const double a = column_i[f];
      const double b = column_k[f];
      column_i[f] = c[f] * a + s[f] * b;
      column_k[f] = c[f] * b - s[f] * a;
    }
  }
}

// out[axis][f] = position[axis][f] + (rotation · v[f])[axis] (MatVec() of rotation.h, summed
// left to right), v[f] given per axis by v[axis * kB + f].
[[gnu::always_inline]] inline void MoveOnVectors(const double* block, const double* v, double* out,
                                                 std::size_t n) {
  for (std::size_t row = 0; row < 3; ++row) {
    const double* __restrict m0 = RotationEntry(block, row, 0);
    const double* __restrict m1 = RotationEntry(block, row, 1);
    const double* __restrict m2 = RotationEntry(block, row, 2);
    const double* __restrict base = PositionAxis(block, row);
    double* __restrict moved = out + row * kB;
    for (std::size_t f = 0; f < n; ++f) {
      moved[f] = base[f] + (m0[f] * v[f] + m1[f] * v[kB + f] + m2[f] * v[2 * kB + f]);
    }
  }
}

void RotateColumnsBlock(double* block, int axis, const double* c, const double* s,
                        std::size_t n) {
  simd::RunForInstructionSet(
      [&]() __attribute__((always_inline)) { RotateColumnsOnVectors(block, axis, c, s, n); });
}

void MoveBlock(const double* block, const double* v, double* out, std::size_t n) {
  simd::RunForInstructionSet(
      [&]() __attribute__((always_inline)) { MoveOnVectors(block, v, out, n); });
}

// The frames' points of one axis-major array (axis a of frame f at a * kB + f) written to point
// `point` of each frame of `out` (frame-major, `stride` points a frame).
void ScatterPoint(const double* axes, std::size_t n, std::size_t point, std::size_t stride,
                  std::span<Vec3> out) {
  for (std::size_t f = 0; f < n; ++f) {
    out[f * stride + point] = {axes[f], axes[kB + f], axes[2 * kB + f]};
  }
}

// Eight angles' RotationTrig(), from radians: the vector kernels' sine and cosine, within 2.5
// units in the last place of the exact values (libm's are within one), at about a quarter of the
// cost of libm's sincos (forward kinematics of every frame is most of a world-space measurement).
// Every lane is computed alone, so an angle's values do not depend on the other lanes. Kept from
// the scalar definition: sin(-0) = -0, and libm's values where the kernels do not reduce
// accurately (|radians| >= kMaxReducedRadians, infinities and NaN), whose lanes the kernels see
// as 0 (no NaN or infinity enters their integer quadrant arithmetic).
[[gnu::always_inline]] inline void SinCosOfEight(const double* radians, double* cosines,
                                                 double* sines) {
  using V = vector_trig::V4;
  constexpr int kChains = 2;
  V x[kChains], s[kChains], c[kChains];
  vector_trig::MaskOf<V> reduced[kChains];
  bool all_reduced = true;
  bool all_small = true;
  for (int k = 0; k < kChains; ++k) {
    x[k] = simd::Load(radians + 4 * k);
    const V magnitude = vector_trig::Abs(x[k]);
    reduced[k] = magnitude < vector_trig::kMaxReducedRadians;
    all_reduced = all_reduced && simd::All(reduced[k]);
    all_small = all_small && simd::All(magnitude < vector_trig::kMaxUnreducedRadians);
  }
  if (!all_reduced) {
    for (int k = 0; k < kChains; ++k) x[k] = reduced[k] ? x[k] : V{};
  }
  // Most joints turn less than 44 degrees: their groups skip the reduction, which leaves such
  // angles as they are (SinCosSmall(): the same bits).
  if (all_small) {
    vector_trig::SinCosSmall<kChains>(x, s, c);
  } else {
    vector_trig::SinCos<kChains>(x, s, c);
  }
  for (int k = 0; k < kChains; ++k) {
    s[k] = x[k] == 0.0 ? x[k] : s[k];  // the kernel's sine of -0 is +0
  }
  for (int k = 0; k < kChains; ++k) {
    simd::Store(cosines + 4 * k, c[k]);
    simd::Store(sines + 4 * k, s[k]);
  }
  if (all_reduced) return;
  for (int i = 0; i < 4 * kChains; ++i) {
    if (!(std::abs(radians[i]) < vector_trig::kMaxReducedRadians)) {
      sines[i] = std::sin(radians[i]);
      cosines[i] = std::cos(radians[i]);
    }
  }
}

// RotationTrig() on the angles [0, n), eight at a time, the last group padded with zeros.
TEMPOKEY_CLONES_AVX2 void SinCosOfDegrees(const double* degrees, double* cosines, double* sines,
                                          std::size_t n) {
  constexpr std::size_t kLanes = 8;
  std::array<double, kLanes> radians, sine, cosine;
  std::size_t f = 0;
  for (; f + kLanes <= n; f += kLanes) {
    for (std::size_t i = 0; i < kLanes; ++i) radians[i] = degrees[f + i] * kRadiansPerDegree;
    SinCosOfEight(radians.data(), cosines + f, sines + f);
  }
  if (f == n) return;
  radians.fill(0.0);
  for (std::size_t i = 0; f + i < n; ++i) radians[i] = degrees[f + i] * kRadiansPerDegree;
  SinCosOfEight(radians.data(), cosine.data(), sine.data());
  for (std::size_t i = 0; f + i < n; ++i) {
    cosines[f + i] = cosine[i];
    sines[f + i] = sine[i];
  }
}

}  // namespace

void ForwardKinematics::RotationTrig(std::span<const double> degrees, std::span<double> cosines,
                                     std::span<double> sines) {
  SinCosOfDegrees(degrees.data(), cosines.data(), sines.data(), degrees.size());
}

void ForwardKinematics::PlaceBlock(std::span<const std::span<const double>> samples,
                                   std::size_t first, std::size_t count, std::span<Vec3> out) {
  const std::size_t stride = points_.size();
  std::array<double, 3 * kB> local{};  // the joint's translation, then an end site's offset
  std::array<double, 3 * kB> site{};   // an end site's position
  std::size_t rotation = 0;
  for (std::size_t j = 0; j < joints_.size(); ++j) {
    const JointPlan& plan = joints_[j];
    double* block = block_.data() + j * kBlockStride;
    // The joint's local translation: its offset, each position channel replacing one axis.
    for (std::size_t axis = 0; axis < 3; ++axis) {
      double* t = local.data() + axis * kB;
      const int c = plan.position_channel[axis];
      if (c >= 0) {
        std::copy_n(samples[static_cast<std::size_t>(c)].data() + first, count, t);
      } else {
        std::fill_n(t, count, plan.offset[axis]);
      }
    }
    // The joint's world rotation: its parent's, then each rotation channel in listed order.
    if (plan.parent < 0) {
      for (std::size_t row = 0; row < 3; ++row) {
        for (std::size_t col = 0; col < 3; ++col) {
          std::fill_n(RotationEntry(block, row, col), count, row == col ? 1.0 : 0.0);
        }
        std::copy_n(local.data() + row * kB, count, PositionAxis(block, row));
      }
    } else {
      const double* parent = block_.data() + static_cast<std::size_t>(plan.parent) * kBlockStride;
      MoveBlock(parent, local.data(), PositionAxis(block, 0), count);
      for (std::size_t e = 0; e < 9; ++e) std::copy_n(parent + e * kB, count, block + e * kB);
    }
    ScatterPoint(PositionAxis(block, 0), count, j, stride, out);
    for (const auto& [axis, c] : plan.rotations) {
      RotateColumnsBlock(block, axis, rotation_cos_[rotation], rotation_sin_[rotation], count);
      ++rotation;
    }
    for (std::size_t e = 0; e < plan.end_sites.size(); ++e) {
      for (std::size_t axis = 0; axis < 3; ++axis) {
        std::fill_n(local.data() + axis * kB, count, plan.end_sites[e][axis]);
      }
      MoveBlock(block, local.data(), site.data(), count);
      ScatterPoint(site.data(), count, plan.first_end_site_point + e, stride, out);
    }
  }
}

template <class SetTrig>
void ForwardKinematics::PlaceBlocks(std::span<const std::span<const double>> samples,
                                    std::size_t first, std::size_t count, std::span<Vec3> out,
                                    SetTrig set_trig) {
  const std::size_t stride = points_.size();
  for (std::size_t done = 0; done < count; done += kB) {
    const std::size_t n = std::min(kB, count - done);
    std::size_t rotation = 0;
    for (const JointPlan& plan : joints_) {
      for (const auto& [axis, c] : plan.rotations) {
        set_trig(rotation, static_cast<std::size_t>(c), first + done, n);
        ++rotation;
      }
    }
    PlaceBlock(samples, first + done, n, out.subspan(done * stride, n * stride));
  }
}

void ForwardKinematics::PoseFrames(std::span<const std::span<const double>> samples,
                                   std::size_t first, std::size_t count, std::span<Vec3> out) {
  PlaceBlocks(samples, first, count, out,
              [&](std::size_t rotation, std::size_t channel, std::size_t from, std::size_t n) {
                double* cosines = trig_.data() + 2 * rotation * kB;
                double* sines = cosines + kB;
                RotationTrig(samples[channel].subspan(from, n), {cosines, n}, {sines, n});
                rotation_cos_[rotation] = cosines;
                rotation_sin_[rotation] = sines;
              });
}

void ForwardKinematics::PoseFramesFromTrig(std::span<const std::span<const double>> samples,
                                           std::span<const std::span<const double>> cosines,
                                           std::span<const std::span<const double>> sines,
                                           std::size_t first, std::size_t count,
                                           std::span<Vec3> out) {
  PlaceBlocks(samples, first, count, out,
              [&](std::size_t rotation, std::size_t channel, std::size_t from, std::size_t) {
                rotation_cos_[rotation] = cosines[channel].data() + from;
                rotation_sin_[rotation] = sines[channel].data() + from;
              });
}

void ForwardKinematics::Pose(std::span<const std::span<const double>> samples, std::size_t frame,
                             std::span<Vec3> out) {
  PoseFrames(samples, frame, 1, out);
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
  fk.PoseFrames(samples, 0, static_cast<std::size_t>(clip.frame_count), out.positions);
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
