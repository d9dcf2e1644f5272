// Key reduction entry points: option checks and the per-channel driver (SPEC 4).
#include "tempokey/core/reduce/reduce.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "reduction_internal.h"
#include "tempokey/core/reduce/hermite_dp.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/model/status.h"
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
  TEMPOKEY_RETURN_IF_ERROR(
      CheckBound("tolerance.max_rotation_error_degrees", t.max_rotation_error_degrees));
  TEMPOKEY_RETURN_IF_ERROR(CheckBound("tolerance.max_position_error", t.max_position_error));
  TEMPOKEY_RETURN_IF_ERROR(CheckBound("tolerance.max_scalar_error", t.max_scalar_error));
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

// Two flat keys at `value` at the ends of `frame_count` frames (one for a single frame).
ChannelFit FlatFit(std::size_t frame_count, double value, double frame_time) {
  const double last = static_cast<double>(frame_count - 1);
  std::vector<HermiteKey2D> keys = {{0.0, value, last, 0.0}};
  if (frame_count > 1) keys.push_back({last, value, last, 0.0});
  return {HermiteKeysToCurve(keys, frame_time), {}, 0};
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

double BoundOf(const ToleranceParams& t, ChannelKind kind) {
  if (IsRotation(kind)) return t.max_rotation_error_degrees;
  if (kind == ChannelKind::kScalar) return t.max_scalar_error;
  return t.max_position_error;
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

// The scale at which every channel's bound covers the range (max - min) of its fitted samples:
// there two flat keys at mid-range keep every channel within half its bound, so every group fits
// with two keys. At least 1; at most the largest double (for absurdly small bounds).
double CoveringScale(const Clip& clip, std::span<const std::span<const double>> inputs,
                     const ToleranceParams& params) {
  double scale = 1.0;
  for (std::size_t c = 0; c < inputs.size(); ++c) {
    const auto [low, high] = std::minmax_element(inputs[c].begin(), inputs[c].end());
    scale = std::max(scale, (*high - *low) / BoundOf(params, clip.channels[c].kind));
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

// The tolerance fit of every group with every bound multiplied by `scale`; curves in channel order.
absl::StatusOr<std::vector<Curve>> ToleranceCurves(
    const Clip& clip, std::span<const std::span<const double>> inputs,
    const std::vector<std::vector<int>>& groups, const ToleranceParams& params, double scale,
    const ProgressFn& progress, std::stop_token stop) {
  std::vector<Curve> curves(clip.channels.size());
  for (std::size_t g = 0; g < groups.size(); ++g) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const std::vector<int>& group = groups[g];
    if (group.size() == 1 && IsConstant(inputs[group[0]])) {
      curves[group[0]] =
          FlatFit(inputs[group[0]].size(), inputs[group[0]].front(), clip.frame_time_seconds)
              .curve;
      continue;
    }
    std::vector<std::span<const double>> channels;
    std::vector<double> bounds;
    for (int c : group) {
      channels.emplace_back(inputs[c]);
      // Capped: a huge bound times a huge scale must not become infinite (the fit refuses it).
      bounds.push_back(std::min(scale * BoundOf(params, clip.channels[c].kind),
                                std::numeric_limits<double>::max()));
    }
    absl::StatusOr<SplineFit> fit = FitWithinTolerance(channels, bounds, {}, stop);
    if (!fit.ok()) return Annotate(fit.status(), ChannelLabel(clip, group.front()));
    for (std::size_t k = 0; k < group.size(); ++k) {
      curves[group[k]] = SplineCurve(*fit, k, clip.frame_time_seconds);
    }
    ReportProgress(progress, static_cast<double>(g + 1) / static_cast<double>(groups.size()),
                   absl::StrCat("reduce ", group.back() + 1, "/", clip.channels.size()));
  }
  return curves;
}

std::int64_t KeyCount(const std::vector<Curve>& curves) {
  std::int64_t keys = 0;
  for (const Curve& curve : curves) keys += static_cast<std::int64_t>(curve.keys.size());
  return keys;
}

// Curves within the bounds, or, with a key budget, within the smallest common scale of the bounds
// whose fit keeps at most that many keys (bisection on the scale, in ratio).
absl::StatusOr<std::vector<Curve>> ToleranceFit(const Clip& clip,
                                                std::span<const std::span<const double>> inputs,
                                                const ToleranceParams& params,
                                                const ProgressFn& progress, std::stop_token stop) {
  const std::vector<std::vector<int>> groups = AlignmentGroups(clip, params.pose_alignment);
  if (!params.key_budget) return ToleranceCurves(clip, inputs, groups, params, 1.0, progress, stop);

  const std::int64_t budget = *params.key_budget;
  TEMPOKEY_RETURN_IF_ERROR(CheckKeyBudget(params, static_cast<std::int64_t>(clip.channels.size()),
                                          clip.frame_count));
  const ProgressFn quiet;
  auto fit = [&](double scale) {
    return ToleranceCurves(clip, inputs, groups, params, scale, quiet, stop);
  };
  // Bracket: `within` keeps to the budget, `over` does not.
  double within = 1.0;
  double over = 0.0;
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<Curve> best, fit(1.0));
  if (KeyCount(best) <= budget) {
    for (double scale = 0.5; scale >= kMinBudgetScale; scale *= 0.5) {
      TEMPOKEY_ASSIGN_OR_RETURN(std::vector<Curve> curves, fit(scale));
      if (KeyCount(curves) > budget) {
        over = scale;
        break;
      }
      within = scale;
      best = std::move(curves);
    }
    if (over == 0.0) return best;  // even the tightest bound searched fits the budget
  } else {
    // Doubling, up to the scale whose bounds cover every channel's range: the fit there keeps
    // two keys per channel, which the budget allows (checked above).
    over = 1.0;
    const double ceiling = CoveringScale(clip, inputs, params);
    bool found = false;
    for (double scale = 2.0; !found && over < ceiling; scale *= 2.0) {
      const double capped = std::min(scale, ceiling);
      TEMPOKEY_ASSIGN_OR_RETURN(std::vector<Curve> curves, fit(capped));
      if (KeyCount(curves) <= budget) {
        within = capped;
        best = std::move(curves);
        found = true;
      } else {
        over = capped;
      }
    }
    if (!found) {
      // The fit kept more than two keys per channel even where two flat keys are within every
      // bound (not seen in practice): take those.
      best = MidRangeCurves(clip, inputs);
      ReportProgress(progress, 1.0, absl::StrCat("reduce ", clip.channels.size(), "/",
                                                 clip.channels.size()));
      return best;
    }
  }
  for (int step = 0; step < kBudgetBisections; ++step) {
    const double scale = std::sqrt(within * over);
    TEMPOKEY_ASSIGN_OR_RETURN(std::vector<Curve> curves, fit(scale));
    if (KeyCount(curves) <= budget) {
      within = scale;
      best = std::move(curves);
    } else {
      over = scale;
    }
  }
  ReportProgress(progress, 1.0, absl::StrCat("reduce ", clip.channels.size(), "/",
                                             clip.channels.size()));
  return best;
}

}  // namespace

absl::Status ValidateReduceOptions(const ReduceOptions& options) {
  switch (options.method) {
    case ReduceMethod::kPaper:
      return ValidatePaperParams(options.paper);
    case ReduceMethod::kTolerance:
      return ValidateToleranceParams(options.tolerance);
  }
  return absl::InvalidArgumentError(
      absl::StrCat("reduce method ", static_cast<int>(options.method), " is not a known method"));
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
  TEMPOKEY_RETURN_IF_ERROR(ValidateReduceOptions(options));

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
  // Rotations unwrapped into copies, every other channel read in place.
  const reduce_internal::FittedSamples fitted(clip);
  const std::span<const std::span<const double>> inputs = fitted.channels();
  int iterations = 0;
  if (options.method == ReduceMethod::kTolerance) {
    TEMPOKEY_ASSIGN_OR_RETURN(result.keyed.curves,
                              ToleranceFit(clip, inputs, options.tolerance, progress, stop));
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
      ReportProgress(progress, static_cast<double>(c + 1) / channel_count,
                     absl::StrCat("reduce ", c + 1, "/", channel_count));
    }
  }
  // Every number a fit produces lies in the keyed clip's ranges (clip.h) for every input
  // ValidateClip() and ValidateReduceOptions() accept; a curve that does not is a broken
  // invariant, reported as such rather than handed on as infinite tangents or key times.
  for (int c = 0; c < channel_count; ++c) {
    if (absl::Status valid = ValidateCurve(result.keyed.curves[c], ChannelLabel(clip, c));
        !valid.ok()) {
      return absl::InternalError(absl::StrCat("the fit produced an invalid curve: ",
                                              valid.message()));
    }
  }
  // The clip was validated above and the curves are ours: measure without MeasureReduction()'s
  // checks and copies.
  result.report =
      reduce_internal::MeasureFitted(inputs, result.keyed.curves, clip.frame_time_seconds, stop);
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  result.report.iterations = iterations;
  return result;
}

}  // namespace tempokey::core
