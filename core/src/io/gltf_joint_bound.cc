// The joint bound of a keyed glTF, the file measured as glTF evaluates it (gltf_joint_bound.h).
#include "gltf_joint_bound.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <span>
#include <stop_token>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/src/model/hermite_basis.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/reduce/joint_bound.h"

namespace tempokey::core::gltf_internal {
namespace {

// The sampler's translation at `time_seconds` as glTF evaluates it: the cubic Hermite of the two
// keys around it (tangents per second times the key interval), the end keys' values outside
// them; a sampler of one key (written LINEAR) is its value.
Vec3 EvaluateTranslation(const TranslationKeys& keys, double time_seconds) {
  const std::vector<float>& times = keys.input;
  const std::vector<float>& out = keys.output;
  auto value = [&](std::size_t k) {
    return Vec3{out[9 * k + 3], out[9 * k + 4], out[9 * k + 5]};
  };
  if (times.size() < 2 || !(time_seconds > static_cast<double>(times.front()))) return value(0);
  if (!(time_seconds < static_cast<double>(times.back()))) return value(times.size() - 1);
  const auto next =
      std::upper_bound(times.begin(), times.end(), time_seconds,
                       [](double t, float key) { return t < static_cast<double>(key); });
  const auto k = static_cast<std::size_t>(next - times.begin()) - 1;
  const double t0 = times[k];
  const double td = static_cast<double>(times[k + 1]) - t0;
  const double s = (time_seconds - t0) / td;
  const auto [h00, h10, h01, h11] = HermiteBasis(s, td);
  Vec3 p{};
  for (std::size_t axis = 0; axis < 3; ++axis) {
    p[axis] = h00 * out[9 * k + 3 + axis] + h10 * out[9 * k + 6 + axis] +
              h01 * out[9 * (k + 1) + 3 + axis] + h11 * out[9 * (k + 1) + axis];
  }
  return p;
}

// A key at every source frame: the source's rotations (unit, signs continuous) with
// central-difference tangents, in float32: the closest a glTF curve gets to the source at its
// frames (quaternion_fit.cc's own last resort, which this file cannot call: it keys a joint no
// bound of its ladder fits).
QuaternionCurve EveryFrameCurve(std::vector<Quat> rotations, double frame_time) {
  for (Quat& q : rotations) q = Normalized(q);
  MakeSignContinuous(rotations);
  auto to_float = [](const Quat& q) {
    return Quat{static_cast<float>(q.w), static_cast<float>(q.x), static_cast<float>(q.y),
                static_cast<float>(q.z)};
  };
  QuaternionCurve curve;
  const std::size_t n = rotations.size();
  curve.keys.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t before = i > 0 ? i - 1 : i;
    const std::size_t after = i + 1 < n ? i + 1 : i;
    Quat slope{0, 0, 0, 0};
    if (after > before) {
      const double f = 1.0 / (static_cast<double>(after - before) * frame_time);
      const Quat& a = rotations[before];
      const Quat& b = rotations[after];
      slope = {(b.w - a.w) * f, (b.x - a.x) * f, (b.y - a.y) * f, (b.z - a.z) * f};
    }
    QuaternionKey key;
    key.time_seconds = static_cast<float>(static_cast<double>(i) * frame_time);
    key.value = to_float(rotations[i]);
    key.in_tangent = key.out_tangent = to_float(slope);
    curve.keys.push_back(key);
  }
  return curve;
}

// Frames placed together when the file is measured: the source's by ForwardKinematics in blocks.
constexpr std::size_t kMeasureFrames = 4 * ForwardKinematics::kBlockFrames;

// Places every point (SkeletonPoints() order) of the source at every frame, kMeasureFrames at a
// time, and calls visit(first, count, placed) with them (placed[(f - first) * points + p]).
// kCancelled when `stop` is requested (looked at before each piece).
template <class Visit>
absl::Status ForEachSourcePiece(const Clip& source, ForwardKinematics& fk,
                                const std::stop_token& stop, Visit visit) {
  std::vector<std::span<const double>> samples;
  samples.reserve(source.channels.size());
  for (const Channel& channel : source.channels) samples.emplace_back(channel.samples);
  const std::size_t n = fk.point_count();
  std::vector<Vec3> placed(kMeasureFrames * n);
  const auto frames = static_cast<std::size_t>(source.frame_count);
  for (std::size_t first = 0; first < frames; first += kMeasureFrames) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const std::size_t count = std::min(kMeasureFrames, frames - first);
    const std::span<Vec3> piece = std::span<Vec3>(placed).first(count * n);
    fk.PoseFrames(samples, first, count, piece);
    visit(first, count, std::span<const Vec3>(piece));
  }
  return absl::OkStatus();
}

// Per point: the largest distance of the file's position from the source's over every frame,
// and the first frame where it is.
struct FilePointErrors {
  std::vector<double> max_error;
  std::vector<std::int64_t> worst_frame;
};

// The rotations and translations of a keyed glTF under a joint bound, and how its points depend
// on them; measures the file's points against the source's.
class JointBoundFit {
 public:
  // `translations` and `rotations` as the file writes them (joint order); `curves` one per
  // rotation, set by the caller before each Measure().
  JointBoundFit(const Clip& source, ForwardKinematics fk,
                const std::vector<TranslationKeys>& translations,
                const std::vector<JointRotation>& rotations)
      : source_(source), fk_(std::move(fk)), curves_(rotations.size()) {
    const std::size_t joints = source.skeleton.joints.size();
    translation_of_joint_.assign(joints, nullptr);
    for (const TranslationKeys& keys : translations) {
      translation_of_joint_[static_cast<std::size_t>(keys.joint)] = &keys;
    }
    rotation_of_joint_.assign(joints, -1);
    for (std::size_t r = 0; r < rotations.size(); ++r) {
      rotation_of_joint_[static_cast<std::size_t>(rotations[r].joint)] = static_cast<int>(r);
    }
    // The rotations that can move each point: those of the joints above it, and its own joint's
    // for an end site.
    const std::vector<SkeletonPoint>& points = fk_.points();
    above_.resize(points.size());
    for (std::size_t p = 0; p < points.size(); ++p) {
      int joint = points[p].end_site >= 0
                      ? points[p].joint
                      : source.skeleton.joints[static_cast<std::size_t>(points[p].joint)].parent;
      for (; joint >= 0; joint = source.skeleton.joints[static_cast<std::size_t>(joint)].parent) {
        if (rotation_of_joint_[static_cast<std::size_t>(joint)] >= 0) {
          above_[p].push_back(joint);
        }
      }
    }
    world_rotation_.resize(joints);
    world_position_.resize(joints);
  }

  std::vector<QuaternionCurve>& curves() { return curves_; }
  const ForwardKinematics& fk() const { return fk_; }

  // One pass over the source: the figure's height (its first frame's vertical extent, as the
  // reduction measures it), and per point the rotations that move it at some frame (distance
  // > 0 from their joint) and per rotation its reach (the largest such distance).
  absl::Status PlanLevers(const std::stop_token& stop) {
    const std::size_t n = fk_.point_count();
    std::vector<std::vector<double>> farthest_squared(n);
    for (std::size_t p = 0; p < n; ++p) farthest_squared[p].assign(above_[p].size(), 0.0);
    auto visit = [&](std::size_t first, std::size_t count, std::span<const Vec3> placed) {
      if (first == 0) figure_height_ = VerticalExtent(placed.first(n));
      for (std::size_t i = 0; i < count; ++i) {
        const std::span<const Vec3> frame = placed.subspan(i * n, n);
        for (std::size_t p = 0; p < n; ++p) {
          for (std::size_t a = 0; a < above_[p].size(); ++a) {
            const Vec3& q = frame[static_cast<std::size_t>(above_[p][a])];
            const double dx = frame[p][0] - q[0];
            const double dy = frame[p][1] - q[1];
            const double dz = frame[p][2] - q[2];
            farthest_squared[p][a] = std::max(farthest_squared[p][a], dx * dx + dy * dy + dz * dz);
          }
        }
      }
    };
    TEMPOKEY_RETURN_IF_ERROR(ForEachSourcePiece(source_, fk_, stop, visit));
    reach_.assign(curves_.size(), 0.0);
    chain_.assign(n, {});
    for (std::size_t p = 0; p < n; ++p) {
      for (std::size_t a = 0; a < above_[p].size(); ++a) {
        if (!(farthest_squared[p][a] > 0.0)) continue;
        const int r = rotation_of_joint_[static_cast<std::size_t>(above_[p][a])];
        chain_[p].push_back(r);
        double& reach = reach_[static_cast<std::size_t>(r)];
        reach = std::max(reach, std::sqrt(farthest_squared[p][a]));
      }
    }
    return absl::OkStatus();
  }

  double figure_height() const { return figure_height_; }
  // Per point, the rotations (indices into the rotations) that move it (PlanLevers()).
  const std::vector<std::vector<int>>& chain() const { return chain_; }
  // Per rotation, the largest distance from its joint to a point it moves (PlanLevers()).
  const std::vector<double>& reach() const { return reach_; }

  // The file's points against the source's at every frame.
  absl::StatusOr<FilePointErrors> Measure(const std::stop_token& stop) {
    const std::size_t n = fk_.point_count();
    FilePointErrors errors;
    errors.max_error.assign(n, 0.0);
    errors.worst_frame.assign(n, 0);
    std::vector<Vec3> file_points(n);
    auto visit = [&](std::size_t first, std::size_t count, std::span<const Vec3> placed) {
      for (std::size_t i = 0; i < count; ++i) {
        const std::size_t frame = first + i;
        PlaceFilePoints(static_cast<double>(frame) * source_.frame_time_seconds, file_points);
        for (std::size_t p = 0; p < n; ++p) {
          const Vec3& a = file_points[p];
          const Vec3& b = placed[i * n + p];
          const double dx = a[0] - b[0];
          const double dy = a[1] - b[1];
          const double dz = a[2] - b[2];
          const double distance = std::sqrt(dx * dx + dy * dy + dz * dz);
          if (distance > errors.max_error[p]) {
            errors.max_error[p] = distance;
            errors.worst_frame[p] = static_cast<std::int64_t>(frame);
          }
        }
      }
    };
    TEMPOKEY_RETURN_IF_ERROR(ForEachSourcePiece(source_, fk_, stop, visit));
    return errors;
  }

 private:
  // Every point as the file places it at `time_seconds` (glTF: a node's matrix is its
  // translation times its rotation, world = parent world x local; end sites are nodes with their
  // offset as translation).
  void PlaceFilePoints(double time_seconds, std::span<Vec3> out) {
    const std::vector<Joint>& joints = source_.skeleton.joints;
    for (std::size_t j = 0; j < joints.size(); ++j) {
      const Vec3 translation = translation_of_joint_[j] != nullptr
                                   ? EvaluateTranslation(*translation_of_joint_[j], time_seconds)
                                   : joints[j].offset;
      const int r = rotation_of_joint_[j];
      const Mat3 local = r >= 0 ? QuatToMatrix(EvaluateQuaternionCurve(
                                      curves_[static_cast<std::size_t>(r)], time_seconds))
                                : Mat3{{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
      const int parent = joints[j].parent;
      if (parent < 0) {
        world_rotation_[j] = local;
        world_position_[j] = translation;
        continue;
      }
      const auto up = static_cast<std::size_t>(parent);
      const Vec3 moved = MatVec(world_rotation_[up], translation);
      world_rotation_[j] = MatMul(world_rotation_[up], local);
      for (std::size_t axis = 0; axis < 3; ++axis) {
        world_position_[j][axis] = world_position_[up][axis] + moved[axis];
      }
    }
    const std::vector<SkeletonPoint>& points = fk_.points();
    for (std::size_t p = 0; p < points.size(); ++p) {
      const auto j = static_cast<std::size_t>(points[p].joint);
      if (points[p].end_site < 0) {
        out[p] = world_position_[j];
        continue;
      }
      const Vec3 moved = MatVec(world_rotation_[j],
                                joints[j].end_sites[static_cast<std::size_t>(points[p].end_site)]);
      for (std::size_t axis = 0; axis < 3; ++axis) {
        out[p][axis] = world_position_[j][axis] + moved[axis];
      }
    }
  }

  const Clip& source_;
  ForwardKinematics fk_;
  std::vector<QuaternionCurve> curves_;
  std::vector<const TranslationKeys*> translation_of_joint_;  // null: the offset, unanimated
  std::vector<int> rotation_of_joint_;                        // -1: no rotation sampler
  std::vector<std::vector<int>> above_;  // per point, the joints with rotations above it
  std::vector<std::vector<int>> chain_;
  std::vector<double> reach_;
  double figure_height_ = 0.0;
  std::vector<Mat3> world_rotation_;  // per joint, scratch of PlaceFilePoints()
  std::vector<Vec3> world_position_;
};

// A point tightens the rotations on its chain by this much of what its error asks for (bound /
// error), errors not shrinking exactly with the bounds ...
constexpr double kTightenAim = 0.9;
// ... by at least this factor and at most this one per round (joint_bound.cc's).
constexpr double kMinTightenFactor = 0.25;
constexpr double kMaxTightenFactor = 0.9;

// The worst point of `errors`: the largest error, the earliest frame on ties.
std::size_t WorstPoint(const FilePointErrors& errors) {
  std::size_t worst = 0;
  for (std::size_t p = 1; p < errors.max_error.size(); ++p) {
    if (errors.max_error[p] > errors.max_error[worst] ||
        (errors.max_error[p] == errors.max_error[worst] &&
         errors.worst_frame[p] < errors.worst_frame[worst])) {
      worst = p;
    }
  }
  return worst;
}

}  // namespace

absl::StatusOr<std::vector<QuaternionCurve>> FitRotationsWithinJointBound(
    const Clip& source, const std::vector<JointRotation>& rotations,
    const std::vector<TranslationKeys>& translations, const GltfKeyedOptions& options,
    const RotationFitter& fit_rotations, const SourceRotations& source_rotations,
    GltfStats& stats, const std::stop_token& stop) {
  TEMPOKEY_ASSIGN_OR_RETURN(ForwardKinematics fk, ForwardKinematics::ForLayout(source));
  JointBoundFit fit(source, std::move(fk), translations, rotations);
  TEMPOKEY_RETURN_IF_ERROR(fit.PlanLevers(stop));
  TEMPOKEY_ASSIGN_OR_RETURN(const double bound,
                            ResolveJointTolerance(*options.joint_tolerance, fit.figure_height()));
  const double min_lever = kMinLeverHeightFraction * fit.figure_height();
  std::vector<double> budgets(rotations.size());
  for (std::size_t r = 0; r < rotations.size(); ++r) {
    // The angle whose chord at the lever is the bound, capped by the rotation bound.
    const double lever = std::max(fit.reach()[r], min_lever);
    const double chord_angle =
        lever > 0.0
            ? 2.0 * std::asin(std::min(1.0, bound / (2.0 * lever))) * 180.0 / std::numbers::pi
            : 180.0;
    budgets[r] = std::min(options.max_rotation_error_degrees, chord_angle);
  }

  std::vector<std::size_t> dirty(rotations.size());
  for (std::size_t r = 0; r < rotations.size(); ++r) dirty[r] = r;
  for (int round = 0;; ++round) {
    std::vector<JointRotation> refit;
    std::vector<double> refit_budgets;
    for (std::size_t r : dirty) {
      refit.push_back(rotations[r]);
      refit_budgets.push_back(budgets[r]);
    }
    TEMPOKEY_ASSIGN_OR_RETURN(std::vector<QuaternionCurve> fitted,
                              fit_rotations(refit, refit_budgets));
    for (std::size_t i = 0; i < dirty.size(); ++i) fit.curves()[dirty[i]] = std::move(fitted[i]);
    TEMPOKEY_ASSIGN_OR_RETURN(const FilePointErrors errors, fit.Measure(stop));
    stats.joint_bound_rounds = round + 1;

    // Per rotation, the factor the worst point over the bound on its chain asks for.
    std::vector<double> factor(rotations.size(), 1.0);
    bool over = false;
    for (std::size_t p = 0; p < errors.max_error.size(); ++p) {
      if (!(errors.max_error[p] > bound)) continue;
      over = true;
      const double wanted = std::clamp(kTightenAim * bound / errors.max_error[p],
                                       kMinTightenFactor, kMaxTightenFactor);
      for (int r : fit.chain()[p]) {
        factor[static_cast<std::size_t>(r)] = std::min(factor[static_cast<std::size_t>(r)], wanted);
      }
    }
    const std::size_t worst = WorstPoint(errors);
    if (!over) {
      stats.joint_bound = bound;
      stats.max_joint_error = errors.max_error[worst];
      return std::move(fit.curves());
    }
    dirty.clear();
    for (std::size_t r = 0; r < rotations.size(); ++r) {
      if (factor[r] < 1.0) dirty.push_back(r);
    }
    if (round < kGltfJointBoundRounds && !dirty.empty()) {
      for (std::size_t r : dirty) budgets[r] *= factor[r];
      continue;
    }
    // The last resort: every rotation moving a point still over the bound keyed at every
    // frame, measured once more.
    if (!dirty.empty()) {
      for (std::size_t r : dirty) {
        TEMPOKEY_ASSIGN_OR_RETURN(std::vector<Quat> quats, source_rotations(rotations[r]));
        fit.curves()[r] = EveryFrameCurve(std::move(quats), source.frame_time_seconds);
      }
      TEMPOKEY_ASSIGN_OR_RETURN(const FilePointErrors last, fit.Measure(stop));
      stats.joint_bound_rounds = round + 2;
      const std::size_t last_worst = WorstPoint(last);
      if (!(last.max_error[last_worst] > bound)) {
        stats.joint_bound = bound;
        stats.max_joint_error = last.max_error[last_worst];
        return std::move(fit.curves());
      }
      return absl::FailedPreconditionError(absl::StrCat(
          "glTF cannot keep every joint within the joint bound ", DescribeDouble(bound),
          " file units: ", SkeletonPointName(source.skeleton, fit.fk().points()[last_worst]),
          " is ", DescribeDouble(last.max_error[last_worst]),
          " from its source position at frame ", last.worst_frame[last_worst],
          " with every rotation moving it keyed at every frame (the keyed translations' error "
          "and float32 rounding remain)"));
    }
    // No rotation moves the point over the bound: its error is its translations'.
    return absl::FailedPreconditionError(absl::StrCat(
        "glTF cannot keep every joint within the joint bound ", DescribeDouble(bound),
        " file units: ", SkeletonPointName(source.skeleton, fit.fk().points()[worst]), " is ",
        DescribeDouble(errors.max_error[worst]), " from its source position at frame ",
        errors.worst_frame[worst],
        " and no rotation moves it (the keyed translations' error and float32 rounding)"));
  }
}

}  // namespace tempokey::core::gltf_internal
