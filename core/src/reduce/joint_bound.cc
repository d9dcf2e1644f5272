// The world-space bound (SPEC 4.4); the method is described in joint_bound.h.
#include "tempokey/core/reduce/joint_bound.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

#include "absl/strings/str_cat.h"
#include "joint_bound_fit.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
// The largest joint bound, in file units or in percent of the figure's height.
constexpr double kMaxJointTolerance = 1e9;
constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;
// Guaranteed budgets aim this hair inside the bound, so that rounding in forward kinematics and
// in the fit's own margin can never carry a point over it.
constexpr double kGuaranteeMargin = 1e-6;
// A point over the bound by a factor e / D tightens its chain by about D / e, aiming this much
// further inside (errors do not shrink exactly in proportion to the budgets) ...
constexpr double kTightenAim = 0.9;
// ... by at least this factor and at most this one per round.
constexpr double kMinTightenFactor = 0.25;
constexpr double kMaxTightenFactor = 0.9;

bool IsConstant(std::span<const double> samples) {
  return std::all_of(samples.begin(), samples.end(),
                     [&](double v) { return v == samples.front(); });
}

double SquaredDistance(const Vec3& a, const Vec3& b) {
  const double dx = a[0] - b[0];
  const double dy = a[1] - b[1];
  const double dz = a[2] - b[2];
  return dx * dx + dy * dy + dz * dz;
}

}  // namespace

std::string FormatJointTolerance(const JointTolerance& tolerance) {
  return absl::StrCat(FormatDouble(tolerance.value), tolerance.percent_of_height ? "%" : "");
}

absl::Status ValidateJointTolerance(const JointTolerance& tolerance) {
  if (!(tolerance.value > 0.0) || !std::isfinite(tolerance.value)) {
    return absl::InvalidArgumentError(
        absl::StrCat("tolerance.joint_tolerance must be finite and > 0, got ",
                     DescribeDouble(tolerance.value), tolerance.percent_of_height ? "%" : ""));
  }
  // As every other error bound (reduce.cc: kMaxErrorBound): past it every channel fits with two
  // keys, and a bound of 1.7e308 (of a height, or a clip's reach) came back as infinity.
  if (tolerance.value > kMaxJointTolerance) {
    return absl::InvalidArgumentError(absl::StrCat(
        "tolerance.joint_tolerance must be at most ", kMaxJointTolerance, ", got ",
        DescribeDouble(tolerance.value), tolerance.percent_of_height ? "%" : ""));
  }
  return absl::OkStatus();
}

absl::StatusOr<double> ResolveJointTolerance(const JointTolerance& tolerance,
                                             double figure_height) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateJointTolerance(tolerance));
  if (!tolerance.percent_of_height) return tolerance.value;
  if (!(figure_height > 0.0)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "tolerance.joint_tolerance ", FormatJointTolerance(tolerance),
        " is relative to the figure's height, which is 0 (every joint and end site at one "
        "height at the first frame)"));
  }
  return tolerance.value / 100.0 * figure_height;
}

namespace {

// OK when `bound` is at least `fraction` of `reach`; the refusal says what `reach` is ("its
// joints reach" from the origin).
absl::Status CheckAboveFloor(const JointTolerance& tolerance, double bound, double fraction,
                             double reach, std::string_view reached) {
  const double least = fraction * reach;
  if (bound >= least) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      "tolerance.joint_tolerance ", FormatJointTolerance(tolerance),
      " is below what this clip's joint positions can be computed to: at least ",
      DescribeDouble(least), " file units (", DescribeDouble(fraction), " of the ",
      DescribeDouble(reach), " file units ", AsAbsl(reached), " from the origin)"));
}

}  // namespace

absl::Status CheckJointBoundAboveRounding(const JointTolerance& tolerance, double bound,
                                          const PointTrajectories& source) {
  double reach = 0.0;
  for (const Vec3& p : source.positions) {
    reach = std::max({reach, std::abs(p[0]), std::abs(p[1]), std::abs(p[2])});
  }
  return CheckAboveFloor(tolerance, bound, kMinJointBoundOfReach, reach, "its joints reach");
}

absl::Status CheckJointBoundForClip(const JointTolerance& tolerance, const Clip& clip) {
  if (clip.skeleton.empty()) return absl::OkStatus();
  double height = 0.0;
  if (tolerance.percent_of_height) {
    TEMPOKEY_ASSIGN_OR_RETURN(height, FigureHeight(clip));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(const double bound, ResolveJointTolerance(tolerance, height));
  const std::vector<Joint>& joints = clip.skeleton.joints;
  std::vector<double> chain(joints.size(), 0.0);
  double reach = 0.0;
  for (std::size_t j = 0; j < joints.size(); ++j) {
    const Joint& joint = joints[j];
    double link = std::hypot(joint.offset[0], joint.offset[1], joint.offset[2]);
    for (int c : joint.channels) {
      const Channel& channel = clip.channels[static_cast<std::size_t>(c)];
      if (!IsPosition(channel.kind)) continue;
      double largest = 0.0;
      for (double v : channel.samples) largest = std::max(largest, std::abs(v));
      link += largest;
    }
    chain[j] = (joint.parent < 0 ? 0.0 : chain[static_cast<std::size_t>(joint.parent)]) + link;
    reach = std::max(reach, chain[j]);
    for (const Vec3& end : joint.end_sites) {
      reach = std::max(reach, chain[j] + std::hypot(end[0], end[1], end[2]));
    }
  }
  return CheckAboveFloor(tolerance, bound, 2.0 * kMinJointBoundOfReach, reach,
                         "its skeleton can reach");
}

namespace reduce_internal {

JointBoundPlan::JointBoundPlan(WorldErrorMeter& meter,
                               std::span<const std::span<const double>> inputs)
    : meter_(meter) {
  const Clip& clip = meter.clip();
  const PointTrajectories& source = meter.source();
  const std::size_t joint_count = clip.skeleton.joints.size();
  const std::size_t point_count = source.points.size();

  // The largest distance, over every frame, from each point to each joint above it.
  std::vector<std::vector<std::pair<int, double>>> above(point_count);  // (joint, distance)
  for (std::size_t p = 0; p < point_count; ++p) {
    const SkeletonPoint& point = source.points[p];
    int joint = point.end_site >= 0 ? point.joint : clip.skeleton.joints[point.joint].parent;
    for (; joint >= 0; joint = clip.skeleton.joints[static_cast<std::size_t>(joint)].parent) {
      // The square root of the largest squared distance: the largest distance, since the
      // correctly rounded square root is monotonic (one root instead of one per frame).
      double farthest_squared = 0.0;
      for (std::int64_t f = 0; f < source.frame_count; ++f) {
        farthest_squared = std::max(
            farthest_squared,
            SquaredDistance(source.at(f, p), source.at(f, static_cast<std::size_t>(joint))));
      }
      above[p].emplace_back(joint, std::sqrt(farthest_squared));
    }
  }
  std::vector<double> reach(joint_count, 0.0);  // per joint: its rotation's farthest point
  for (const auto& joints : above) {
    for (const auto& [joint, distance] : joints) {
      reach[static_cast<std::size_t>(joint)] = std::max(reach[static_cast<std::size_t>(joint)], distance);
    }
  }

  const double min_lever = kMinLeverHeightFraction * meter.figure_height();
  lever_.assign(clip.channels.size(), 0.0);
  std::vector<char> moves(clip.channels.size(), 0);
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    const Channel& channel = clip.channels[c];
    if (channel.joint < 0 || IsConstant(inputs[c])) continue;
    if (IsPosition(channel.kind)) {
      lever_[c] = 1.0;
      moves[c] = 1;
    } else if (IsRotation(channel.kind)) {
      lever_[c] = std::max(reach[static_cast<std::size_t>(channel.joint)], min_lever) *
                  kRadiansPerDegree;
      moves[c] = 1;
    }
  }

  // Each point's chain: the position channels of its joint and the joints above, the rotation
  // channels of the joints above it at a distance > 0. Per chain entry the point's own lever
  // would be tighter, but one lever per channel keeps the guarantee simple and it only matters
  // once a chain is snapped.
  chain_.resize(point_count);
  for (std::size_t p = 0; p < point_count; ++p) {
    const SkeletonPoint& point = source.points[p];
    auto add_channels = [&](int joint, bool positions, bool rotations) {
      for (int c : clip.skeleton.joints[static_cast<std::size_t>(joint)].channels) {
        const auto ch = static_cast<std::size_t>(c);
        if (!moves[ch]) continue;
        const ChannelKind kind = clip.channels[ch].kind;
        if ((positions && IsPosition(kind)) || (rotations && IsRotation(kind))) {
          chain_[p].push_back(c);
        }
      }
    };
    if (point.end_site < 0) add_channels(point.joint, true, false);
    for (const auto& [joint, distance] : above[p]) {
      add_channels(joint, true, distance > 0.0);
    }
  }
}

std::vector<double> JointBoundPlan::GuaranteedBudgets(double bound) const {
  std::vector<double> budgets(lever_.size(), kInfinity);
  const double aim = bound * (1.0 - kGuaranteeMargin);
  for (const std::vector<int>& chain : chain_) {
    const auto n = static_cast<double>(chain.size());
    for (int c : chain) {
      const auto ch = static_cast<std::size_t>(c);
      budgets[ch] = std::min(budgets[ch], aim / (lever_[ch] * n));
    }
  }
  return budgets;
}

std::vector<double> JointBoundPlan::InitialBudgets(double bound) const {
  const Clip& clip = meter_.clip();
  std::vector<double> budgets(lever_.size(), kInfinity);
  for (std::size_t c = 0; c < lever_.size(); ++c) {
    if (lever_[c] <= 0.0) continue;
    if (IsPosition(clip.channels[c].kind)) {
      budgets[c] = bound;
    } else {
      // The exact angle whose chord at the lever's distance is the bound.
      const double distance = lever_[c] / kRadiansPerDegree;
      budgets[c] = 2.0 * std::asin(std::min(1.0, bound / (2.0 * distance))) / kRadiansPerDegree;
    }
  }
  return budgets;
}

absl::StatusOr<JointBoundCurves> JointBoundPlan::Fit(
    double bound, std::span<const double> caps, std::span<const double> fallback,
    const std::vector<std::vector<int>>& groups, const GroupFitter& fit, std::stop_token stop) {
  const Clip& clip = meter_.clip();
  const std::size_t channel_count = clip.channels.size();
  const std::vector<double> guaranteed = GuaranteedBudgets(bound);
  std::vector<double> budgets = InitialBudgets(bound);
  for (std::size_t c = 0; c < channel_count; ++c) {
    budgets[c] = std::min(budgets[c], caps[c]);
    if (!std::isfinite(budgets[c])) budgets[c] = fallback[c];
  }
  std::vector<std::size_t> group_of(channel_count, 0);
  for (std::size_t g = 0; g < groups.size(); ++g) {
    for (int c : groups[g]) group_of[static_cast<std::size_t>(c)] = g;
  }

  std::vector<Curve> curves(channel_count);
  std::vector<std::vector<double>> fitted(channel_count);
  std::vector<std::size_t> dirty(groups.size());
  for (std::size_t g = 0; g < groups.size(); ++g) dirty[g] = g;
  for (int round = 0;; ++round) {
    TEMPOKEY_RETURN_IF_ERROR(fit(dirty, budgets, curves));
    // Only the refitted channels change after the first round: the meter keeps what it
    // computed of the others (a new fit starts from other samples: all change).
    std::vector<char> refitted(channel_count, round == 0 ? 1 : 0);
    for (std::size_t g : dirty) {
      for (int c : groups[g]) {
        const auto ch = static_cast<std::size_t>(c);
        fitted[ch].resize(static_cast<std::size_t>(clip.frame_count));
        SampleCurve(curves[ch], clip.frame_time_seconds, fitted[ch]);
        refitted[ch] = 1;
      }
    }
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    PointErrors errors = meter_.MeasureChanged(Spans(fitted), refitted);
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));

    // Per channel, the factor the worst point over the bound on its chain asks for.
    std::vector<double> factor(channel_count, 1.0);
    bool over = false;
    for (std::size_t p = 0; p < chain_.size(); ++p) {
      if (!(errors.max_error[p] > bound)) continue;
      over = true;
      const double wanted =
          round >= kJointBoundSnapRound
              ? 0.0
              : std::clamp(kTightenAim * bound / errors.max_error[p], kMinTightenFactor,
                           kMaxTightenFactor);
      for (int c : chain_[p]) {
        factor[static_cast<std::size_t>(c)] = std::min(factor[static_cast<std::size_t>(c)], wanted);
      }
    }
    if (!over) {
      return JointBoundCurves{std::move(curves), std::move(fitted), std::move(errors)};
    }

    std::vector<char> refit(groups.size(), 0);
    bool changed = false;
    for (std::size_t c = 0; c < channel_count; ++c) {
      if (factor[c] >= 1.0) continue;
      const double tightened =
          std::min(budgets[c], std::max(guaranteed[c], budgets[c] * factor[c]));
      if (tightened < budgets[c]) {
        budgets[c] = tightened;
        refit[group_of[c]] = 1;
        changed = true;
      }
    }
    if (!changed) {
      // Every chain over the bound already sits at its guaranteed budgets, which the triangle
      // inequality says cannot happen.
      return absl::InternalError(absl::StrCat(
          "joint bound ", bound, ": a chain at its guaranteed budgets is still over the bound"));
    }
    dirty.clear();
    for (std::size_t g = 0; g < groups.size(); ++g) {
      if (refit[g]) dirty.push_back(g);
    }
  }
}

}  // namespace reduce_internal
}  // namespace tempokey::core
