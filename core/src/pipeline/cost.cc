// The pipeline's up-front validation and cost prediction (cost.h): one walk over the steps with
// the exact shape each leaves.
#include "tempokey/core/pipeline/cost.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <variant>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/reduce/joint_bound.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::core {
namespace {

// Seconds per unit of inner-loop work on one core of the reference machine, measured by
// bench/cost_bench (which prints each against the real run) and rounded up.
// Retime: one kernel tap of one channel on the rotation-aware path (quaternion means, squad,
// the Euler solution per output sample), the slowest; scalar channels cost a tenth of it.
constexpr double kRetimeSecondsPerTap = 80e-9;
// The paper's retime: one step of its discrete integral, about sixty bisection passes of it.
constexpr double kPaperRetimeSecondsPerStep = 10e-9;
constexpr double kPaperRetimeBisections = 64.0;
// Compiling a time map: one speed knot, time-map key, hold or pin (its segment, its checks and
// the label its messages would name it by). About 1 us measured at the limit of 100 000 of each
// kind, on a clip of a few frames where they are all the work.
constexpr double kTimeMapSecondsPerItem = 2.5e-6;
// Tolerance fit: one sample of one fit on white noise (every frame ends up keyed: the worst).
constexpr double kToleranceSecondsPerSample = 2.5e-6;
// The fewest-keys search (and the usual fit beside it): one sample of one fit, twice the slowest
// input measured (24-41 us on the shared captures, 47-61 on sines offset by 1e8 or scaled to
// 1e300 or 1e-300, 6-29 on white noise, steps and calm channels).
constexpr double kFewestKeysSecondsPerSample = 120e-6;
// Noise-aware method: one sample of one channel (its noise estimate, Euler filter, smoothing
// and the fit of the smoothed curve) on white noise, the worst input measured (about 1.6 us).
constexpr double kNoiseSecondsPerSample = 4e-6;
// Paper fit: one x(s) = frame solve and data term of one x-combination in one pass (no cached
// shape: fractional steps), one DP state pair of one segment in one pass, one smoothing tap.
constexpr double kPaperSecondsPerSolve = 70e-9;
constexpr double kPaperSecondsPerStatePair = 2e-9;
constexpr double kSmoothSecondsPerTap = 2.5e-9;
// Measuring a fit: one weighted-Bezier evaluation; bake the same.
constexpr double kEvaluateSecondsPerSample = 60e-9;
// A reduction's world error: one joint or end site placed by forward kinematics at one frame,
// for the source and again for the fitted curves (about 25 ns each measured, rounded up).
constexpr double kPlaceSecondsPerPoint = 40e-9;
// Convert: a copy of each sample and its wrap (WrapDegrees(), about 1 ns); the copy's new pages
// dominate where a first write to a page costs some 10 us (a process's first convert of CMU
// 131_01 in cost_bench: 19-21 ns a sample on the machine of 2026-12-03). The Euler filter's pass
// adds about 5 ns a sample (the same convert with it: 23-28 ns, first in its process).
constexpr double kConvertSecondsPerSample = 25e-9;
constexpr double kEulerFilterSecondsPerSample = 10e-9;

// The x-combinations of a segment and DP state pairs per segment (hermite_dp.h).
constexpr double kPaperCombinations = 81.0;
constexpr double kPaperStatePairs = 81.0 * 81.0;
// The key budget search (reduce.cc): halvings down to 1e-6 of the bounds, then bisections.
constexpr double kBudgetHalvings = 19.0;
constexpr double kBudgetBisections = 12.0;

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

std::string StepContext(std::size_t index, const PipelineStep& step) {
  return absl::StrCat("operation ", index + 1, " (", AsAbsl(StepName(step)), ")");
}

std::string Plural(std::int64_t n, std::string_view one, std::string_view many) {
  return absl::StrCat(n, " ", AsAbsl(n == 1 ? one : many));
}

// What a step takes: the shape of the clip the previous step left.
struct Shape {
  bool keyed = false;
  double frame_time = 0.0;
  std::int64_t frames = 0;
  std::int64_t channels = 0;
  // Joints and end sites of the skeleton (which every step keeps).
  std::int64_t points = 0;
  // The caller's clip, while no step has changed the samples (a key budget reads its ranges).
  const Clip* data = nullptr;
  double samples() const { return static_cast<double>(frames) * static_cast<double>(channels); }
  // Positions the world error places: every point at every frame, source and fit.
  double placements() const {
    return 2.0 * static_cast<double>(frames) * static_cast<double>(points);
  }
};

absl::Status ValidateBakeRate(const std::optional<FrameRate>& rate) {
  if (!rate) return absl::OkStatus();
  if (rate->numerator <= 0 || rate->denominator <= 0) {
    return absl::InvalidArgumentError(absl::StrCat("frame rate ", rate->numerator, "/",
                                                   rate->denominator,
                                                   " must have a positive numerator and denominator"));
  }
  if (rate->hz() > 100'000.0) {
    return absl::InvalidArgumentError(absl::StrCat("frame rate ", rate->hz(),
                                                   " Hz is over the limit of 100000 Hz"));
  }
  if (rate->hz() < 1.0 / kMaxFrameTimeSeconds) {
    return absl::InvalidArgumentError(absl::StrCat(
        "frame rate ", rate->numerator, "/", rate->denominator,
        " is under the limit of one frame an hour"));
  }
  return absl::OkStatus();
}

// Kernel taps per source or output frame: a tent or box footprint covers each source frame
// about twice over, Catmull-Rom reads four neighbours, Lanczos-3 six lobes.
double Taps(ResampleFilter filter) {
  switch (filter) {
    case ResampleFilter::kLanczos3:
      return 6.0;
    case ResampleFilter::kCubic:
      return 4.0;
    default:
      return 2.0;
  }
}

// The range (max - min) of a channel's samples as the fit sees them: rotations unwrapped
// (UnwrapDegrees()'s rule, followed without a copy).
double FittedRange(const Channel& channel) {
  const std::vector<double>& s = channel.samples;
  if (s.empty()) return 0.0;
  double low = s[0];
  double high = s[0];
  double shift = 0.0;
  for (std::size_t i = 1; i < s.size(); ++i) {
    double v = s[i];
    if (IsRotation(channel.kind)) {
      shift -= 360.0 * std::round((s[i] - s[i - 1]) / 360.0);
      v += shift;
    }
    low = std::min(low, v);
    high = std::max(high, v);
  }
  return high - low;
}

// The bound of a channel of `kind`; an unset one at its default (for positions, the default of a
// clip without a figure: the estimate only needs the order of magnitude of the search).
double ToleranceBound(const ToleranceParams& t, ChannelKind kind) {
  if (IsRotation(kind)) return t.max_rotation_error_degrees.value_or(kDefaultMaxRotationErrorDegrees);
  if (kind == ChannelKind::kScalar) return t.max_scalar_error;
  return t.max_position_error.value_or(kDefaultMaxPositionErrorWithoutFigure);
}

// Fits a key budget's search may run: 1 at the given bounds, then up to kBudgetHalvings
// halvings or the doublings up to the scale whose bounds cover every channel's range (and there,
// when no fit keeps to the budget, fits from evenly spread keys, as many as the budget allows a
// channel and then half as many, down to two: at most 1 + log2(frames)), then the bisections.
double BudgetFits(const Shape& in, const ToleranceParams& t) {
  double ceiling = 1.0;
  const bool known = in.data != nullptr && !in.data->channels.empty() &&
                     static_cast<std::int64_t>(in.data->channels.front().samples.size()) == in.frames;
  if (known) {
    for (const Channel& channel : in.data->channels) {
      ceiling = std::max(ceiling, FittedRange(channel) / ToleranceBound(t, channel.kind));
    }
  } else {
    // Any channel's range: twice the largest sample, plus half a turn a frame for an unwrapped
    // rotation; over the smallest bound.
    const double range =
        2.0 * kMaxSampleMagnitude + 180.0 * static_cast<double>(std::max<std::int64_t>(in.frames, 1));
    const double bound = std::min({ToleranceBound(t, ChannelKind::kXRotation),
                                   ToleranceBound(t, ChannelKind::kXPosition),
                                   t.max_scalar_error});
    ceiling = std::max(1.0, range / bound);
  }
  const double doublings = std::ceil(std::log2(std::min(ceiling, 1e300)));
  const double spread_starts =
      1.0 + std::ceil(std::log2(std::max(2.0, static_cast<double>(in.frames))));
  return 1.0 + std::max(kBudgetHalvings, doublings + spread_starts) + kBudgetBisections;
}

StepCost RetimeCost(const Shape& in, const Shape& out, const RetimeStep& step) {
  const double frames = static_cast<double>(in.frames + out.frames);
  const std::size_t items = step.warp.speed.size() + step.warp.keys.size() +
                            step.warp.holds.size() + step.options.pins.size();
  StepCost cost;
  if (step.options.method == RetimeMethod::kPaper) {
    // The box filter over the schedule its bisections place.
    cost.seconds = static_cast<double>(in.channels) * frames * Taps(ResampleFilter::kBox) *
                       kRetimeSecondsPerTap +
                   static_cast<double>(out.frames) * kPaperRetimeBisections *
                       kPaperRetimeSecondsPerStep;
  } else {
    cost.seconds = static_cast<double>(in.channels) * frames * Taps(step.options.filter) *
                   kRetimeSecondsPerTap;
  }
  cost.work = absl::StrCat("retime: ", Plural(in.channels, "channel", "channels"), " x (",
                           in.frames, " source + ", out.frames, " output frames)");
  // The time map's own work, named when it is the larger part (a short clip, a long warp).
  const double map_seconds = static_cast<double>(items) * kTimeMapSecondsPerItem;
  if (map_seconds > cost.seconds) {
    absl::StrAppend(&cost.work, " and ", items, " knots, keys, holds and pins");
  }
  cost.seconds += map_seconds;
  return cost;
}

StepCost ReduceCost(const Shape& in, const ReduceStep& step) {
  StepCost cost;
  const double frames = static_cast<double>(in.frames);
  const double channels = static_cast<double>(in.channels);
  const double measure =
      in.samples() * kEvaluateSecondsPerSample + in.placements() * kPlaceSecondsPerPoint;
  if (step.options.method == ReduceMethod::kTolerance) {
    const double fits = step.options.tolerance.key_budget
                            ? BudgetFits(in, step.options.tolerance)
                            : 1.0;
    const double per_sample = step.options.tolerance.fewest_keys ? kFewestKeysSecondsPerSample
                                                                 : kToleranceSecondsPerSample;
    cost.seconds = fits * in.samples() * per_sample + measure;
    cost.work = absl::StrCat("reduce (tolerance", step.options.tolerance.fewest_keys ? ", fewest keys" : "",
                             "): ", Plural(in.channels, "channel", "channels"), " x ", in.frames,
                             " frames");
    if (fits > 1.0) absl::StrAppend(&cost.work, " x up to ", fits, " fits (key budget)");
    return cost;
  }
  if (step.options.method == ReduceMethod::kNoise) {
    cost.seconds = in.samples() * kNoiseSecondsPerSample + measure;
    cost.work = absl::StrCat("reduce (noise): ", Plural(in.channels, "channel", "channels"),
                             " x ", in.frames, " frames");
    return cost;
  }
  const PaperParams& p = step.options.paper;
  const double taps =
      p.smoothing_sigma_frames > 0.0 ? 2.0 * std::ceil(3.0 * p.smoothing_sigma_frames) + 1.0 : 0.0;
  const double keys = std::floor(frames / p.min_key_spacing_frames) + 2.0;
  const double passes = p.max_iterations;
  const double per_pass =
      frames * kPaperCombinations * kPaperSecondsPerSolve + keys * kPaperStatePairs * kPaperSecondsPerStatePair;
  cost.seconds = channels * (frames * taps * kSmoothSecondsPerTap + passes * per_pass) + measure;
  cost.work = absl::StrCat("reduce (paper): ", Plural(in.channels, "channel", "channels"), " x ",
                           in.frames, " frames x up to ", Plural(p.max_iterations, "pass", "passes"));
  return cost;
}

}  // namespace

std::string PipelineCost::Describe() const {
  std::string text = absl::StrFormat("predicted %.3g s of work", seconds);
  const auto largest = std::max_element(
      steps.begin(), steps.end(),
      [](const StepCost& a, const StepCost& b) { return a.seconds < b.seconds; });
  if (largest != steps.end()) {
    absl::StrAppend(&text, absl::StrFormat(" (operation %d, %s: %.3g s)", largest->index + 1,
                                           largest->work, largest->seconds));
  }
  return text;
}

absl::StatusOr<PipelineCost> EstimatePipelineCost(const Clip& clip,
                                                  std::span<const PipelineStep> steps,
                                                  const ClipLimits& limits) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateStepCount(steps));
  Shape shape;
  shape.frame_time = clip.frame_time_seconds;
  shape.frames = clip.frame_count;
  shape.channels = static_cast<std::int64_t>(clip.channels.size());
  shape.points = clip.skeleton.point_count();
  shape.data = &clip;
  PipelineCost total;
  // Step by step, so the first operation at fault is the one named.
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const PipelineStep& step = steps[i];
    const bool takes_keyed = std::holds_alternative<BakeStep>(step);
    if (takes_keyed != shape.keyed) {
      return absl::InvalidArgumentError(absl::StrCat(
          StepContext(i, step), ": needs a ", takes_keyed ? "keyed" : "sampled", " clip, got a ",
          shape.keyed ? "keyed clip (add a bake operation first)" : "sampled clip"));
    }
    Shape next = shape;
    absl::StatusOr<StepCost> cost = std::visit(
        Overloaded{
            [&](const RetimeStep& s) -> absl::StatusOr<StepCost> {
              TEMPOKEY_ASSIGN_OR_RETURN(
                  RetimeOutputShape out,
                  PlanRetimeOutput(shape.frame_time, shape.frames,
                                   static_cast<std::size_t>(shape.channels), s.warp, s.options,
                                   limits));
              next.frames = out.frame_count;
              next.frame_time = out.frame_time_seconds;
              next.data = nullptr;
              return RetimeCost(shape, next, s);
            },
            [&](const ReduceStep& s) -> absl::StatusOr<StepCost> {
              // A retime keeps the skeleton: `clip`'s tells whether a joint tolerance can apply,
              // and how small it may be.
              TEMPOKEY_RETURN_IF_ERROR(ValidateReduceOptionsForClip(clip, s.options));
              if (s.options.method == ReduceMethod::kTolerance &&
                  s.options.tolerance.joint_tolerance) {
                TEMPOKEY_RETURN_IF_ERROR(
                    CheckJointBoundForClip(*s.options.tolerance.joint_tolerance, clip));
              }
              TEMPOKEY_RETURN_IF_ERROR(
                  ValidateReduceForLayout(s.options, shape.channels, shape.frames));
              next.keyed = true;
              next.data = nullptr;
              return ReduceCost(shape, s);
            },
            [&](const BakeStep& s) -> absl::StatusOr<StepCost> {
              TEMPOKEY_RETURN_IF_ERROR(ValidateBakeRate(s.rate));
              const double frame_time =
                  s.rate ? static_cast<double>(s.rate->denominator) /
                               static_cast<double>(s.rate->numerator)
                         : shape.frame_time;
              const double duration =
                  static_cast<double>(shape.frames - 1) * shape.frame_time;
              TEMPOKEY_ASSIGN_OR_RETURN(
                  next.frames, BakedFrameCount(duration, static_cast<std::size_t>(shape.channels),
                                               frame_time, limits));
              next.frame_time = frame_time;
              next.keyed = false;
              next.data = nullptr;
              StepCost c;
              c.seconds = next.samples() * kEvaluateSecondsPerSample;
              c.work = absl::StrCat("bake: ", Plural(shape.channels, "channel", "channels"), " x ",
                                    next.frames, " frames");
              return c;
            },
            [&](const ConvertStep& s) -> absl::StatusOr<StepCost> {
              if (s.wrap_rotations) next.data = nullptr;
              StepCost c;
              c.seconds = shape.samples() * (kConvertSecondsPerSample +
                                             (s.euler_filter ? kEulerFilterSecondsPerSample : 0.0));
              c.work = absl::StrCat("convert: ", Plural(shape.channels, "channel", "channels"),
                                    " x ", shape.frames, " frames");
              return c;
            },
        },
        step);
    if (cost.ok() && next.points > 0 && next.frames > limits.max_samples / next.points) {
      // As ValidateClipLayout() for the clip this step makes: its positions within the limit.
      cost = OverLimitError(absl::StrCat(
          "the clip it makes has ", next.points, " joints and end sites x ", next.frames,
          " frames, over the limit of ", limits.max_samples,
          " positions (as many as the sample limit: each is placed at every frame)"));
    }
    if (!cost.ok()) return Annotate(cost.status(), StepContext(i, step));
    cost->index = i;
    total.seconds += cost->seconds;
    total.steps.push_back(*std::move(cost));
    shape = next;
  }
  return total;
}

}  // namespace tempokey::core
