// Key reduction entry points: option checks and the per-channel driver (SPEC 4).
#include "tempokey/core/reduce/reduce.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "joint_bound_fit.h"
#include "noise_reduction.h"
#include "reduction_internal.h"
#include "world_error_internal.h"
#include "tempokey/core/model/euler_filter.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/reduce/hermite_dp.h"
#include "tempokey/core/reduce/tolerance_fit.h"

namespace tempokey::core {
namespace {

constexpr double kMaxStep = 1e6;
// Steps and accuracy stay normal doubles: halving a step below this would only reach subnormal
// numbers (every key already moves by less than one ulp long before).
constexpr double kMinStep = 1e-300;
constexpr int kMaxIterations = 1000;
constexpr double kMaxSigmaFrames = 1000.0;
constexpr double kMinSigmaFrames = 0.01;
constexpr int kMaxSpacingFrames = 1'000'000;
// Error bounds: below 1e-9 no double near the largest sample magnitude (1e9, clip.h) resolves
// the bound; above 1e9 every channel fits with two keys. Within it, a key budget's search scales
// the bounds by at most 2^62.
constexpr double kMinErrorBound = 1e-9;
constexpr double kMaxErrorBound = 1e9;

// "paper.step_y must be > 0, got -1" for a value that must lie in [min, max] with min > 0.
absl::Status CheckPositive(std::string_view field, double value, double max,
                           double min = kMinStep) {
  if (!(value > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(field), " must be > 0, got ", DescribeDouble(value)));
  }
  if (!(value <= max)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(field), " must be <= ", max, ", got ", DescribeDouble(value)));
  }
  if (!(value >= min)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(field), " must be >= ", min, ", got ", DescribeDouble(value)));
  }
  return absl::OkStatus();
}

absl::Status ValidatePaperParams(const PaperParams& p) {
  TEMPOKEY_RETURN_IF_ERROR(CheckPositive("paper.step_x_frames", p.step_x_frames, kMaxStep));
  TEMPOKEY_RETURN_IF_ERROR(CheckPositive("paper.step_y", p.step_y, kMaxStep));
  TEMPOKEY_RETURN_IF_ERROR(CheckPositive("paper.step_tangent_x", p.step_tangent_x, kMaxStep));
  TEMPOKEY_RETURN_IF_ERROR(CheckPositive("paper.step_tangent_y", p.step_tangent_y, kMaxStep));
  TEMPOKEY_RETURN_IF_ERROR(CheckPositive("paper.accuracy", p.accuracy, kMaxStep));
  if (p.max_iterations < 1 || p.max_iterations > kMaxIterations) {
    return absl::InvalidArgumentError(absl::StrCat("paper.max_iterations must be in [1, ",
                                                   kMaxIterations, "], got ", p.max_iterations));
  }
  // 0 turns smoothing off; a positive sigma below kMinSigmaFrames would square to nothing and
  // make the Gaussian's centre weight 0/0.
  const double sigma = p.smoothing_sigma_frames;
  if (!(sigma == 0.0 || (sigma >= kMinSigmaFrames && sigma <= kMaxSigmaFrames))) {
    return absl::InvalidArgumentError(absl::StrCat(
        "paper.smoothing_sigma_frames must be 0 or in [", kMinSigmaFrames, ", ", kMaxSigmaFrames,
        "], got ", DescribeDouble(sigma)));
  }
  if (p.min_key_spacing_frames < 1 || p.min_key_spacing_frames > kMaxSpacingFrames) {
    return absl::InvalidArgumentError(
        absl::StrCat("paper.min_key_spacing_frames must be in [1, ", kMaxSpacingFrames,
                     "], got ", p.min_key_spacing_frames));
  }
  return absl::OkStatus();
}

absl::Status CheckBound(std::string_view field, double value) {
  if (!(value > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(field), " must be > 0, got ", DescribeDouble(value)));
  }
  if (!(value >= kMinErrorBound && value <= kMaxErrorBound)) {
    return absl::InvalidArgumentError(absl::StrCat(AsAbsl(field), " must be in [",
                                                   kMinErrorBound, ", ", kMaxErrorBound,
                                                   "], got ", DescribeDouble(value)));
  }
  return absl::OkStatus();
}

// A key budget of at least the keys any fit of the layout needs: 2 per channel (1 for one frame).
absl::Status CheckKeyBudget(const ToleranceParams& t, std::int64_t channel_count,
                            std::int64_t frame_count) {
  if (!t.key_budget) return absl::OkStatus();
  const std::int64_t per_channel = frame_count > 1 ? 2 : 1;
  const std::int64_t minimum = channel_count * per_channel;
  if (*t.key_budget >= minimum) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      "tolerance.key_budget ", *t.key_budget, " is below the ", minimum, " keys any fit of ",
      channel_count, " channels needs (", per_channel, " per channel)"));
}

absl::Status ValidateToleranceParams(const ToleranceParams& t) {
  if (t.max_rotation_error_degrees) {
    TEMPOKEY_RETURN_IF_ERROR(
        CheckBound("tolerance.max_rotation_error_degrees", *t.max_rotation_error_degrees));
  }
  if (t.max_position_error) {
    TEMPOKEY_RETURN_IF_ERROR(CheckBound("tolerance.max_position_error", *t.max_position_error));
  }
  TEMPOKEY_RETURN_IF_ERROR(CheckBound("tolerance.max_scalar_error", t.max_scalar_error));
  if (t.joint_tolerance) TEMPOKEY_RETURN_IF_ERROR(ValidateJointTolerance(*t.joint_tolerance));
  if (t.key_budget && *t.key_budget < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("tolerance.key_budget must be >= 2 when set, got ", *t.key_budget));
  }
  switch (t.pose_alignment) {
    case PoseAlignment::kNone:
    case PoseAlignment::kJoint:
    case PoseAlignment::kClip:
      return absl::OkStatus();
  }
  return absl::InvalidArgumentError(absl::StrCat("tolerance.pose_alignment ",
                                                 static_cast<int>(t.pose_alignment),
                                                 " is not a known alignment"));
}

bool IsConstant(std::span<const double> samples) {
  return std::all_of(samples.begin(), samples.end(),
                     [&](double v) { return v == samples.front(); });
}

struct ChannelFit {
  Curve curve;
  std::vector<double> history;
  int iterations = 0;
};

// Two flat keys at `value` at the ends of `frame_count` frames (one for a single frame), with no
// weights: a constant needs none, and the files say so (README: unweighted curves carry none).
ChannelFit FlatFit(std::size_t frame_count, double value, double frame_time) {
  Curve curve;
  Key first;
  first.value = value;
  curve.keys.push_back(first);
  if (frame_count > 1) {
    Key last = first;
    last.time_seconds = static_cast<double>(frame_count - 1) * frame_time;
    curve.keys.push_back(last);
  }
  return {std::move(curve), {}, 0};
}

absl::StatusOr<ChannelFit> PaperFit(std::span<const double> samples, double frame_time,
                                    const PaperParams& params, std::stop_token stop) {
  if (IsConstant(samples)) return FlatFit(samples.size(), samples.front(), frame_time);
  HermiteFitOptions options;
  options.steps = {params.step_x_frames, params.step_y, params.step_tangent_x,
                   params.step_tangent_y};
  options.accuracy = params.accuracy;
  options.max_iterations = params.max_iterations;
  std::vector<HermiteKey2D> initial = InitialHermiteKeys(
      samples, params.smoothing_sigma_frames, params.min_key_spacing_frames, stop);
  // The initial keys are incomplete when a stop cut the smoothing short.
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  TEMPOKEY_ASSIGN_OR_RETURN(HermiteFitResult fit,
                            FitHermiteDp(samples, std::move(initial), options, stop));
  return ChannelFit{HermiteKeysToCurve(fit.keys, frame_time),
                    std::move(fit.squared_error_history), fit.iterations};
}

// ---- tolerance ----------------------------------------------------------------------------------

// Bounds below this fraction of the requested ones are not searched for a key budget: the fit
// would key every frame long before.
constexpr double kMinBudgetScale = 1e-6;
// Bisection steps of the budget search on the bounds' scale (a factor 2^-12 apart at the end).
constexpr int kBudgetBisections = 12;

// The bounds of a tolerance fit before any key-budget scaling (SPEC 4.2, 4.4).
struct ToleranceBounds {
  // Per channel (value units): its bound; with a joint bound, only the bounds that were set
  // (+infinity for the others: the joint bound chooses those).
  std::vector<double> channel;
  // Per channel: the default of its kind, for a channel the joint bound leaves unbounded.
  std::vector<double> fallback;
  // The joint bound (file units), when asked for.
  std::optional<double> joint;
};

// Each channel's bound from `t`, defaults resolved against the figure's height (the meter's, when
// there is one: it measured the same pose).
absl::StatusOr<ToleranceBounds> ResolveBounds(const Clip& clip, const ToleranceParams& t,
                                              const reduce_internal::WorldErrorMeter* meter) {
  double height = 0.0;
  if (meter != nullptr) {
    height = meter->figure_height();
  } else if (!clip.skeleton.empty()) {
    TEMPOKEY_ASSIGN_OR_RETURN(height, FigureHeight(clip));
  }
  ToleranceBounds bounds;
  if (t.joint_tolerance) {  // on a skeleton: ValidateReduceOptionsForClip()
    TEMPOKEY_ASSIGN_OR_RETURN(bounds.joint, ResolveJointTolerance(*t.joint_tolerance, height));
    if (meter != nullptr) {
      TEMPOKEY_RETURN_IF_ERROR(
          CheckJointBoundAboveRounding(*t.joint_tolerance, *bounds.joint, meter->source()));
    }
  }
  const double position_default = height > 0.0 ? kDefaultPositionErrorHeightFraction * height
                                               : kDefaultMaxPositionErrorWithoutFigure;
  for (const Channel& channel : clip.channels) {
    double fallback = t.max_scalar_error;
    std::optional<double> set = t.max_scalar_error;
    if (IsRotation(channel.kind)) {
      fallback = kDefaultMaxRotationErrorDegrees;
      set = t.max_rotation_error_degrees;
    } else if (IsPosition(channel.kind)) {
      fallback = position_default;
      set = t.max_position_error;
    }
    bounds.fallback.push_back(set.value_or(fallback));
    bounds.channel.push_back(set                ? *set
                             : bounds.joint.has_value() ? std::numeric_limits<double>::infinity()
                                                        : fallback);
  }
  return bounds;
}

// Channels whose keys share frames: each alone, a joint's (channels off joints alone), or all.
std::vector<std::vector<int>> AlignmentGroups(const Clip& clip, PoseAlignment alignment) {
  const int count = static_cast<int>(clip.channels.size());
  std::vector<std::vector<int>> groups;
  if (alignment == PoseAlignment::kClip) {
    groups.emplace_back(static_cast<std::size_t>(count));
    for (int c = 0; c < count; ++c) groups.back()[c] = c;
    return groups;
  }
  std::vector<int> group_of_joint(clip.skeleton.joints.size(), -1);
  for (int c = 0; c < count; ++c) {
    const int joint = clip.channels[c].joint;
    if (alignment == PoseAlignment::kJoint && joint >= 0) {
      int& group = group_of_joint[joint];
      if (group < 0) {
        group = static_cast<int>(groups.size());
        groups.emplace_back();
      }
      groups[group].push_back(c);
    } else {
      groups.push_back({c});
    }
  }
  return groups;
}

// The keys of channel `index` of `fit` as a curve in seconds: non-weighted Hermite keys whose
// tangents are the slopes per second.
Curve SplineCurve(const SplineFit& fit, std::size_t index, double frame_time) {
  Curve curve;
  curve.keys.reserve(fit.frames.size());
  for (std::size_t k = 0; k < fit.frames.size(); ++k) {
    const double slope = fit.slopes[index][k] / frame_time;
    Key key;
    key.time_seconds = static_cast<double>(fit.frames[k]) * frame_time;
    key.value = fit.values[index][k];
    key.in_tangent = slope;
    key.out_tangent = slope;
    curve.keys.push_back(key);
  }
  return curve;
}

// The scale at which every channel's bound (`bounds`, +infinity for none) covers the range
// (max - min) of its fitted samples: there two flat keys at mid-range keep every channel within
// half its bound, so every group fits with two keys. At least 1; at most the largest double (for
// absurdly small bounds).
double CoveringScale(std::span<const std::span<const double>> inputs,
                     std::span<const double> bounds) {
  double scale = 1.0;
  for (std::size_t c = 0; c < inputs.size(); ++c) {
    const auto [low, high] = std::minmax_element(inputs[c].begin(), inputs[c].end());
    scale = std::max(scale, (*high - *low) / bounds[c]);
  }
  return std::min(scale, std::numeric_limits<double>::max());
}

// Two flat keys per channel at the middle of its range: within every bound at CoveringScale().
std::vector<Curve> MidRangeCurves(const Clip& clip,
                                  std::span<const std::span<const double>> inputs) {
  std::vector<Curve> curves;
  curves.reserve(inputs.size());
  for (std::span<const double> samples : inputs) {
    const auto [low, high] = std::minmax_element(samples.begin(), samples.end());
    curves.push_back(
        FlatFit(samples.size(), *low + 0.5 * (*high - *low), clip.frame_time_seconds).curve);
  }
  return curves;
}

// Per alignment group, the key frames of its last fit (empty before its first, and for a constant
// channel's two flat keys).
using GroupKeyFrames = std::vector<std::vector<std::int64_t>>;

// The tolerance fit of the groups `which` (indices into `groups`), channel c within bounds[c];
// writes their curves into `curves` (one per channel of the clip). Each group's fit starts from
// its entry of `last_frames` when it has one, and leaves its new key frames there.
absl::Status FitGroups(const Clip& clip, std::span<const std::span<const double>> inputs,
                       const std::vector<std::vector<int>>& groups,
                       std::span<const std::size_t> which, std::span<const double> bounds,
                       std::vector<Curve>& curves, GroupKeyFrames& last_frames,
                       bool fewest_keys, const ProgressFn& progress, std::stop_token stop) {
  for (std::size_t i = 0; i < which.size(); ++i) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const std::vector<int>& group = groups[which[i]];
    if (group.size() == 1 && IsConstant(inputs[group[0]])) {
      curves[group[0]] =
          FlatFit(inputs[group[0]].size(), inputs[group[0]].front(), clip.frame_time_seconds)
              .curve;
      continue;
    }
    std::vector<std::span<const double>> channels;
    std::vector<double> group_bounds;
    channels.reserve(group.size());
    group_bounds.reserve(group.size());
    for (int c : group) {
      channels.emplace_back(inputs[c]);
      // Capped: a huge bound times a huge scale must not become infinite (the fit refuses it).
      group_bounds.push_back(std::min(bounds[c], std::numeric_limits<double>::max()));
    }
    std::vector<std::int64_t>& frames = last_frames[which[i]];
    absl::StatusOr<SplineFit> fit = FitWithinTolerance(
        channels, group_bounds,
        {.initial_frames = std::move(frames), .fewest_keys = fewest_keys}, stop);
    if (!fit.ok()) return Annotate(fit.status(), ChannelLabel(clip, group.front()));
    for (std::size_t k = 0; k < group.size(); ++k) {
      curves[group[k]] = SplineCurve(*fit, k, clip.frame_time_seconds);
    }
    frames = std::move(fit->frames);
    ReportProgressOf(progress, static_cast<double>(i + 1) / static_cast<double>(which.size()),
                     "reduce ", group.back() + 1, "/", clip.channels.size());
  }
  return absl::OkStatus();
}

std::int64_t KeyCount(const std::vector<Curve>& curves) {
  std::int64_t keys = 0;
  for (const Curve& curve : curves) keys += static_cast<std::int64_t>(curve.keys.size());
  return keys;
}

std::vector<double> Scaled(std::span<const double> values, double scale) {
  std::vector<double> out(values.begin(), values.end());
  for (double& v : out) v *= scale;
  return out;
}

// A tolerance fit and the joint bound it kept (file units, 0 without one).
struct ToleranceCurves {
  std::vector<Curve> curves;
  double joint_bound = 0.0;
  // With a joint bound, what its verification measured of `curves` (the report reuses it): every
  // channel's curve at every frame, and the points' errors.
  std::vector<std::vector<double>> samples;
  std::optional<reduce_internal::PointErrors> world_errors;
};

// One tolerance fit: the channels' bounds and the joint bound, each multiplied by a scale.
class ToleranceFitter {
 public:
  // `meter` is needed (non-null) when `bounds` has a joint bound; it must outlive the fitter.
  ToleranceFitter(const Clip& clip, std::span<const std::span<const double>> inputs,
                  const ToleranceParams& params, ToleranceBounds bounds,
                  reduce_internal::WorldErrorMeter* meter)
      : clip_(clip),
        inputs_(inputs),
        groups_(AlignmentGroups(clip, params.pose_alignment)),
        bounds_(std::move(bounds)),
        fewest_keys_(params.fewest_keys) {
    if (bounds_.joint) joint_plan_.emplace(*meter, inputs);
  }

  // `start_keys` (> 0): every group's fit starts from StartFrames(start_keys) instead of its
  // default start.
  absl::StatusOr<ToleranceCurves> Fit(double scale, const ProgressFn& progress,
                                      std::stop_token stop, std::int64_t start_keys = 0) {
    ToleranceCurves out;
    out.curves.resize(clip_.channels.size());
    if (!bounds_.joint) {
      std::vector<std::size_t> all(groups_.size());
      for (std::size_t g = 0; g < all.size(); ++g) all[g] = g;
      GroupKeyFrames start = StartFrames(start_keys);
      TEMPOKEY_RETURN_IF_ERROR(FitGroups(clip_, inputs_, groups_, all,
                                         Scaled(bounds_.channel, scale), out.curves, start,
                                         fewest_keys_, progress, stop));
      return out;
    }
    // Progress follows the first round, which fits every group; later rounds refit a few.
    bool first_round = true;
    const ProgressFn quiet;
    // A group refitted at tighter budgets starts from the keys of its last fit rather than from
    // keys initial_spacing_frames apart: its insertion has fewer rounds to go and its removal
    // fewer keys to try (measured, and its keys at other bounds, in the README's world-bound
    // profile).
    GroupKeyFrames last_frames = StartFrames(start_keys);
    const reduce_internal::GroupFitter fit_groups =
        [&](std::span<const std::size_t> which, std::span<const double> bounds,
            std::vector<Curve>& curves) {
          const absl::Status status =
              FitGroups(clip_, inputs_, groups_, which, bounds, curves, last_frames,
                        fewest_keys_, first_round ? progress : quiet, stop);
          first_round = false;
          return status;
        };
    out.joint_bound = *bounds_.joint * scale;
    TEMPOKEY_ASSIGN_OR_RETURN(
        reduce_internal::JointBoundCurves fit,
        joint_plan_->Fit(out.joint_bound, Scaled(bounds_.channel, scale),
                         Scaled(bounds_.fallback, scale), groups_, fit_groups, stop));
    out.curves = std::move(fit.curves);
    out.samples = std::move(fit.samples);
    out.world_errors = std::move(fit.errors);
    return out;
  }

  // The scale at which two flat keys per channel keep every bound (CoveringScale()); with a joint
  // bound, of the guaranteed budgets (capped by the set bounds), which keep it whatever the fit.
  double CoveringScale() const {
    if (!bounds_.joint) return tempokey::core::CoveringScale(inputs_, bounds_.channel);
    std::vector<double> bounds = joint_plan_->GuaranteedBudgets(*bounds_.joint);
    for (std::size_t c = 0; c < bounds.size(); ++c) {
      bounds[c] = std::min(bounds[c], bounds_.channel[c]);
      if (!std::isfinite(bounds[c])) bounds[c] = bounds_.fallback[c];
    }
    return tempokey::core::CoveringScale(inputs_, bounds);
  }

  std::optional<double> joint_bound() const { return bounds_.joint; }

  // Keys per moving channel of an evenly spaced start that keeps to `budget` (>= 2 per channel)
  // when the fit inserts none: a group whose channels are all constant keeps its two keys, the
  // first frame's and the last's; every other channel takes an equal share of the rest.
  std::int64_t BudgetShare(std::int64_t budget) const {
    std::int64_t still = 0;
    for (const std::vector<int>& group : groups_) {
      if (AllConstant(group)) still += static_cast<std::int64_t>(group.size());
    }
    const auto moving = static_cast<std::int64_t>(inputs_.size()) - still;
    return moving > 0 ? (budget - 2 * still) / moving : 2;
  }

 private:
  bool AllConstant(const std::vector<int>& group) const {
    return std::all_of(group.begin(), group.end(), [&](int c) { return IsConstant(inputs_[c]); });
  }

  // Every group's start: `keys` (>= 2) evenly spaced over the clip, the first frame's and the
  // last's among them, or those two for a group whose channels are all constant; none (the fit's
  // default start) for keys 0.
  GroupKeyFrames StartFrames(std::int64_t keys) const {
    GroupKeyFrames start(groups_.size());
    if (keys <= 0) return start;
    const std::int64_t last = clip_.frame_count - 1;
    const std::int64_t gaps = std::max<std::int64_t>(keys - 1, 1);
    const std::int64_t spacing = std::max<std::int64_t>((last + gaps - 1) / gaps, 1);
    std::vector<std::int64_t> frames;
    for (std::int64_t f = 0; f < last; f += spacing) frames.push_back(f);
    frames.push_back(last);
    const std::vector<std::int64_t> ends =
        last > 0 ? std::vector<std::int64_t>{0, last} : std::vector<std::int64_t>{0};
    for (std::size_t g = 0; g < groups_.size(); ++g) {
      start[g] = AllConstant(groups_[g]) ? ends : frames;
    }
    return start;
  }

  const Clip& clip_;
  std::span<const std::span<const double>> inputs_;
  std::vector<std::vector<int>> groups_;
  ToleranceBounds bounds_;
  bool fewest_keys_ = false;
  std::optional<reduce_internal::JointBoundPlan> joint_plan_;
};

// Curves within the bounds, or, with a key budget, within the smallest common scale of the bounds
// whose fit keeps at most that many keys (bisection on the scale, in ratio).
absl::StatusOr<ToleranceCurves> ToleranceFit(const Clip& clip,
                                             std::span<const std::span<const double>> inputs,
                                             const ToleranceParams& params,
                                             reduce_internal::WorldErrorMeter* meter,
                                             const ProgressFn& progress, std::stop_token stop) {
  TEMPOKEY_ASSIGN_OR_RETURN(ToleranceBounds bounds, ResolveBounds(clip, params, meter));
  ToleranceFitter fitter(clip, inputs, params, std::move(bounds), meter);
  if (!params.key_budget) return fitter.Fit(1.0, progress, stop);

  const std::int64_t budget = *params.key_budget;
  TEMPOKEY_RETURN_IF_ERROR(CheckKeyBudget(params, static_cast<std::int64_t>(clip.channels.size()),
                                          clip.frame_count));
  const ProgressFn quiet;
  std::int64_t start_keys = 0;  // the fits' default start (see below)
  auto fit = [&](double scale) { return fitter.Fit(scale, quiet, stop, start_keys); };
  // Bracket: `within` keeps to the budget, `over` does not.
  double within = 1.0;
  double over = 0.0;
  TEMPOKEY_ASSIGN_OR_RETURN(ToleranceCurves best, fit(1.0));
  if (KeyCount(best.curves) <= budget) {
    for (double scale = 0.5; scale >= kMinBudgetScale; scale *= 0.5) {
      TEMPOKEY_ASSIGN_OR_RETURN(ToleranceCurves curves, fit(scale));
      if (KeyCount(curves.curves) > budget) {
        over = scale;
        break;
      }
      within = scale;
      best = std::move(curves);
    }
    if (over == 0.0) return best;  // even the tightest bound searched fits the budget
  } else {
    // Doubling, up to the scale whose bounds cover every channel's range: there two keys per
    // channel, which the budget allows (checked above), are within every bound.
    over = 1.0;
    const double ceiling = fitter.CoveringScale();
    bool found = false;
    for (double scale = 2.0; !found && over < ceiling; scale *= 2.0) {
      const double capped = std::min(scale, ceiling);
      TEMPOKEY_ASSIGN_OR_RETURN(ToleranceCurves curves, fit(capped));
      if (KeyCount(curves.curves) <= budget) {
        within = capped;
        best = std::move(curves);
        found = true;
      } else {
        over = capped;
      }
    }
    if (!found) {
      // The fit keeps more keys than the budget even at the scale where two flat keys per
      // channel are within every bound: a removal merges no segment past
      // kMaxMergedSegmentFrames, so a moving channel of a long clip keeps a key per that many
      // frames; and with a joint bound the first round's budgets (capped at half a turn) may
      // miss where the covering scale's would not. Started from the budget's share of keys per
      // moving channel, evenly spaced, the fit at that scale keeps them unless a curve misses
      // somewhere and it inserts keys; then from half as many, down to two. The bisection below
      // looks from the start that kept to the budget for the smallest scale that still does.
      bool spread = false;
      for (std::int64_t keys = fitter.BudgetShare(budget); !spread; keys /= 2) {
        start_keys = std::max<std::int64_t>(keys, 2);
        TEMPOKEY_ASSIGN_OR_RETURN(ToleranceCurves curves, fit(ceiling));
        if (KeyCount(curves.curves) <= budget) {
          best = std::move(curves);
          spread = true;
        } else if (start_keys == 2) {
          break;
        }
      }
      if (!spread) {
        // Two flat keys per channel. With a joint bound they keep it too, since every channel
        // is then within its guaranteed budget.
        best.curves = MidRangeCurves(clip, inputs);
        best.samples.clear();
        best.world_errors.reset();
        best.joint_bound = fitter.joint_bound() ? *fitter.joint_bound() * ceiling : 0.0;
        ReportProgressOf(progress, 1.0, "reduce ", clip.channels.size(), "/",
                         clip.channels.size());
        return best;
      }
      within = ceiling;
      over = 1.0;  // the bounds asked for (where the default start kept too many keys)
    }
  }
  // (Nothing to bisect when the bounds asked for already covered every range.)
  for (int step = 0; step < kBudgetBisections && over < within; ++step) {
    const double scale = std::sqrt(within * over);
    TEMPOKEY_ASSIGN_OR_RETURN(ToleranceCurves curves, fit(scale));
    if (KeyCount(curves.curves) <= budget) {
      within = scale;
      best = std::move(curves);
    } else {
      over = scale;
    }
  }
  ReportProgressOf(progress, 1.0, "reduce ", clip.channels.size(), "/", clip.channels.size());
  return best;
}

}  // namespace

absl::Status ValidateReduceOptions(const ReduceOptions& options) {
  switch (options.method) {
    case ReduceMethod::kPaper:
      return ValidatePaperParams(options.paper);
    case ReduceMethod::kTolerance:
      return ValidateToleranceParams(options.tolerance);
    case ReduceMethod::kNoise:
      return reduce_internal::ValidateNoiseParams(options.noise);
  }
  return absl::InvalidArgumentError(
      absl::StrCat("reduce method ", static_cast<int>(options.method), " is not a known method"));
}

absl::Status ValidateReduceOptionsForClip(const Clip& layout, const ReduceOptions& options) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateReduceOptions(options));
  if (options.method == ReduceMethod::kTolerance && options.tolerance.joint_tolerance &&
      layout.skeleton.empty()) {
    return absl::FailedPreconditionError(
        "tolerance.joint_tolerance needs a skeleton, the clip has none");
  }
  return absl::OkStatus();
}

absl::Status ValidateReduceForLayout(const ReduceOptions& options, std::int64_t channel_count,
                                     std::int64_t frame_count) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateReduceOptions(options));
  if (options.method != ReduceMethod::kTolerance) return absl::OkStatus();
  return CheckKeyBudget(options.tolerance, channel_count, frame_count);
}

absl::StatusOr<ReduceResult> ReduceKeys(const Clip& clip, const ReduceOptions& options,
                                        const ProgressFn& progress, std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  TEMPOKEY_RETURN_IF_ERROR(ValidateReduceOptionsForClip(clip, options));

  ReduceResult result;
  Clip& layout = result.keyed.layout;  // the clip without its samples
  layout.name = clip.name;
  layout.frame_time_seconds = clip.frame_time_seconds;
  layout.frame_count = clip.frame_count;
  layout.skeleton = clip.skeleton;
  layout.markers = clip.markers;
  layout.channels.reserve(clip.channels.size());
  for (const Channel& channel : clip.channels) {
    Channel& empty = layout.channels.emplace_back();
    empty.joint = channel.joint;
    empty.kind = channel.kind;
    empty.name = channel.name;
  }
  const int channel_count = static_cast<int>(clip.channels.size());
  // The Euler filter works on a copy; the fit reads that copy instead of the clip.
  const bool euler_filter =
      options.euler_filter.value_or(options.method == ReduceMethod::kNoise);
  std::optional<Clip> filtered;
  if (euler_filter) {
    filtered = clip;
    TEMPOKEY_ASSIGN_OR_RETURN(const EulerFilterReport euler, ApplyEulerFilter(*filtered));
    result.report.euler_filtered_frames = euler.frames_changed;
  }
  // Rotations that unwrapping changes unwrapped into copies, every other channel read in place.
  const reduce_internal::FittedSamples fitted(filtered ? *filtered : clip);
  const std::span<const std::span<const double>> inputs = fitted.channels();
  // Measures joints through the skeleton: the report's world error, and the joint bound's
  // verification.
  std::optional<reduce_internal::WorldErrorMeter> meter;
  if (!clip.skeleton.empty()) {
    TEMPOKEY_ASSIGN_OR_RETURN(meter,
                              reduce_internal::WorldErrorMeter::ForValidatedClip(clip, stop));
  }
  int iterations = 0;
  double joint_bound = 0.0;
  // The curves at every frame and their world errors, when the joint bound measured them.
  std::vector<std::vector<double>> baked;
  std::optional<reduce_internal::PointErrors> world_errors;
  reduce_internal::NoiseCurves noise;
  if (options.method == ReduceMethod::kNoise) {
    TEMPOKEY_ASSIGN_OR_RETURN(
        noise, reduce_internal::FitNoiseCurves(clip, inputs, options.noise, progress, stop));
    result.keyed.curves = std::move(noise.curves);
  } else if (options.method == ReduceMethod::kTolerance) {
    TEMPOKEY_ASSIGN_OR_RETURN(
        ToleranceCurves fit,
        ToleranceFit(clip, inputs, options.tolerance, meter ? &*meter : nullptr, progress, stop));
    result.keyed.curves = std::move(fit.curves);
    joint_bound = fit.joint_bound;
    baked = std::move(fit.samples);
    world_errors = std::move(fit.world_errors);
  } else {
    result.keyed.curves.reserve(clip.channels.size());
    result.squared_error_history.reserve(clip.channels.size());
    for (int c = 0; c < channel_count; ++c) {
      TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
      absl::StatusOr<ChannelFit> fit =
          PaperFit(inputs[c], clip.frame_time_seconds, options.paper, stop);
      if (!fit.ok()) return Annotate(fit.status(), ChannelLabel(clip, c));
      iterations = std::max(iterations, fit->iterations);
      result.keyed.curves.push_back(std::move(fit->curve));
      result.squared_error_history.push_back(std::move(fit->history));
      ReportProgressOf(progress, static_cast<double>(c + 1) / channel_count, "reduce ", c + 1,
                       "/", channel_count);
    }
  }
  // Every number a fit produces lies in the keyed clip's ranges (clip.h) for every input
  // ValidateClip() and ValidateReduceOptions() accept; a curve that does not is a broken
  // invariant, reported as such rather than handed on as infinite tangents or key times.
  for (int c = 0; c < channel_count; ++c) {
    // The channel's label is made only for the message (a string per channel otherwise).
    if (!ValidateCurve(result.keyed.curves[c], "").ok()) {
      return absl::InternalError(
          absl::StrCat("the fit produced an invalid curve: ",
                       ValidateCurve(result.keyed.curves[c], ChannelLabel(clip, c)).message()));
    }
  }
  // The clip was validated above and the curves are ours: measure without MeasureReduction()'s
  // checks and copies.
  const std::int64_t euler_filtered_frames = result.report.euler_filtered_frames;
  if (meter) {
    // The world error needs every channel's curve at every frame too: sampled once for both.
    if (baked.empty()) {
      baked = reduce_internal::SampleCurves(result.keyed.curves, clip.frame_count,
                                            clip.frame_time_seconds, stop);
    }
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    result.report = reduce_internal::MeasureBaked(inputs, result.keyed.curves,
                                                  reduce_internal::Spans(baked));
  } else {
    result.report =
        reduce_internal::MeasureFitted(inputs, result.keyed.curves, clip.frame_time_seconds, stop);
  }
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  result.report.iterations = iterations;
  result.report.euler_filtered_frames = euler_filtered_frames;
  for (std::size_t c = 0; c < noise.sigmas.size(); ++c) {
    result.report.channels[c].noise_sigma = noise.sigmas[c];
    result.report.channels[c].noise_sigma_estimated = noise.estimated[c];
  }
  if (meter) {
    if (!world_errors) {
      world_errors = meter->Measure(reduce_internal::Spans(baked));
      TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    }
    result.report.world = meter->Report(*world_errors, joint_bound);
  }
  return result;
}

}  // namespace tempokey::core
