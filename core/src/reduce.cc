// Key reduction entry points: option checks and the per-channel driver (SPEC 4).
#include "tempokey/core/reduce.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "tempokey/core/hermite_dp.h"
#include "tempokey/core/rotation.h"
#include "tempokey/core/status.h"

namespace tempokey::core {
namespace {

constexpr double kMaxStep = 1e6;
constexpr int kMaxIterations = 1000;
constexpr double kMaxSigmaFrames = 1000.0;
constexpr int kMaxSpacingFrames = 1'000'000;
// Squares of larger samples overflow the squared error.
constexpr double kMaxSampleMagnitude = 1e100;

std::string Describe(double value) {
  if (std::isnan(value)) return "NaN";
  if (std::isinf(value)) return value > 0 ? "+infinity" : "-infinity";
  return absl::StrCat(value);
}

// "paper.step_y must be > 0, got -1" for a value that must lie in (0, max].
absl::Status CheckPositive(std::string_view field, double value, double max) {
  if (!(value > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(field), " must be > 0, got ", Describe(value)));
  }
  if (!(value <= max)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(field), " must be <= ", max, ", got ", Describe(value)));
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
  if (!(p.smoothing_sigma_frames >= 0.0 && p.smoothing_sigma_frames <= kMaxSigmaFrames)) {
    return absl::InvalidArgumentError(
        absl::StrCat("paper.smoothing_sigma_frames must be in [0, ", kMaxSigmaFrames, "], got ",
                     Describe(p.smoothing_sigma_frames)));
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
        absl::StrCat(AsAbsl(field), " must be > 0, got ", Describe(value)));
  }
  if (!std::isfinite(value)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(field), " must be finite, got ", Describe(value)));
  }
  return absl::OkStatus();
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

// The samples a channel is fitted to: unwrapped when it is a rotation.
std::vector<double> FitInput(const Channel& channel) {
  std::vector<double> samples = channel.samples;
  if (IsRotation(channel.kind)) UnwrapDegrees(samples);
  return samples;
}

absl::Status CheckMagnitudes(const Clip& clip, int c, const std::vector<double>& samples) {
  for (std::size_t f = 0; f < samples.size(); ++f) {
    if (std::abs(samples[f]) > kMaxSampleMagnitude) {
      return absl::InvalidArgumentError(absl::StrCat(
          ChannelLabel(clip, c), ": sample ", f, " is ", samples[f],
          ", beyond the +-1e100 that curve fitting supports"));
    }
  }
  return absl::OkStatus();
}

bool IsConstant(const std::vector<double>& samples) {
  return std::all_of(samples.begin(), samples.end(),
                     [&](double v) { return v == samples.front(); });
}

struct ChannelFit {
  Curve curve;
  std::vector<double> history;
  int iterations = 0;
};

// Two flat keys at the ends (one for a single frame).
ChannelFit FlatFit(const std::vector<double>& samples, double frame_time) {
  const double last = static_cast<double>(samples.size() - 1);
  std::vector<HermiteKey2D> keys = {{0.0, samples.front(), last, 0.0}};
  if (samples.size() > 1) keys.push_back({last, samples.front(), last, 0.0});
  return {HermiteKeysToCurve(keys, frame_time), {}, 0};
}

absl::StatusOr<ChannelFit> PaperFit(const std::vector<double>& samples, double frame_time,
                                    const PaperParams& params) {
  if (IsConstant(samples)) return FlatFit(samples, frame_time);
  HermiteFitOptions options;
  options.steps = {params.step_x_frames, params.step_y, params.step_tangent_x,
                   params.step_tangent_y};
  options.accuracy = params.accuracy;
  options.max_iterations = params.max_iterations;
  TEMPOKEY_ASSIGN_OR_RETURN(
      HermiteFitResult fit,
      FitHermiteDp(samples,
                   InitialHermiteKeys(samples, params.smoothing_sigma_frames,
                                      params.min_key_spacing_frames),
                   options));
  return ChannelFit{HermiteKeysToCurve(fit.keys, frame_time),
                    std::move(fit.squared_error_history), fit.iterations};
}

}  // namespace

absl::Status ValidateReduceOptions(const ReduceOptions& options) {
  switch (options.method) {
    case ReduceMethod::kPaper:
      return ValidatePaperParams(options.paper);
    case ReduceMethod::kTolerance:
      TEMPOKEY_RETURN_IF_ERROR(ValidateToleranceParams(options.tolerance));
      return absl::UnimplementedError(
          "reduce method 'tolerance' is not implemented yet; use method 'paper'");
  }
  return absl::InvalidArgumentError(
      absl::StrCat("reduce method ", static_cast<int>(options.method), " is not a known method"));
}

absl::StatusOr<ReduceResult> ReduceKeys(const Clip& clip, const ReduceOptions& options,
                                        const ProgressFn& progress, std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  TEMPOKEY_RETURN_IF_ERROR(ValidateReduceOptions(options));

  ReduceResult result;
  result.keyed.layout = clip;
  for (Channel& channel : result.keyed.layout.channels) {
    channel.samples.clear();
    channel.samples.shrink_to_fit();
  }
  const int channel_count = static_cast<int>(clip.channels.size());
  result.keyed.curves.reserve(clip.channels.size());
  result.squared_error_history.reserve(clip.channels.size());
  int iterations = 0;
  for (int c = 0; c < channel_count; ++c) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const std::vector<double> samples = FitInput(clip.channels[c]);
    TEMPOKEY_RETURN_IF_ERROR(CheckMagnitudes(clip, c, samples));
    absl::StatusOr<ChannelFit> fit = PaperFit(samples, clip.frame_time_seconds, options.paper);
    if (!fit.ok()) return Annotate(fit.status(), ChannelLabel(clip, c));
    iterations = std::max(iterations, fit->iterations);
    result.keyed.curves.push_back(std::move(fit->curve));
    result.squared_error_history.push_back(std::move(fit->history));
    ReportProgress(progress, static_cast<double>(c + 1) / channel_count,
                   absl::StrCat("reduce ", c + 1, "/", channel_count));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(result.report, MeasureReduction(clip, result.keyed));
  result.report.iterations = iterations;
  return result;
}

}  // namespace tempokey::core
