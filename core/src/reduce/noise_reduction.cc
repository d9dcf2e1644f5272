// The `noise` method over a clip: noise levels per channel, FitToNoise(), curves in seconds.
#include "noise_reduction.h"

#include <algorithm>
#include <cmath>
#include <string_view>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"
#include "noise_smoother.h"
#include "tempokey/core/reduce/noise_fit.h"

namespace tempokey::core::reduce_internal {
namespace {

absl::Status CheckSigma(std::string_view field, double value) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    return absl::InvalidArgumentError(absl::StrCat(AsAbsl(field), " must be finite and > 0, got ",
                                                   DescribeDouble(value)));
  }
  return absl::OkStatus();
}

// Keys of `fit` as a curve in seconds: non-weighted Hermite keys, slopes per second.
Curve CurveOf(const SplineFit& fit, double frame_time) {
  Curve curve;
  curve.keys.reserve(fit.frames.size());
  for (std::size_t k = 0; k < fit.frames.size(); ++k) {
    Key key;
    key.time_seconds = static_cast<double>(fit.frames[k]) * frame_time;
    key.value = fit.values[0][k];
    key.in_tangent = key.out_tangent = fit.slopes[0][k] / frame_time;
    curve.keys.push_back(key);
  }
  return curve;
}

Curve FlatCurve(std::size_t frame_count, double value, double frame_time) {
  Curve curve;
  curve.keys.push_back({0.0, value, 0.0, 0.0, {}, {}});
  if (frame_count > 1) {
    curve.keys.push_back({static_cast<double>(frame_count - 1) * frame_time, value, 0.0, 0.0, {}, {}});
  }
  return curve;
}

}  // namespace

absl::Status ValidateNoiseParams(const NoiseParams& params) {
  if (params.rotation_sigma_degrees) {
    TEMPOKEY_RETURN_IF_ERROR(
        CheckSigma("noise.rotation_sigma_degrees", *params.rotation_sigma_degrees));
  }
  if (params.position_sigma) {
    TEMPOKEY_RETURN_IF_ERROR(CheckSigma("noise.position_sigma", *params.position_sigma));
  }
  TEMPOKEY_RETURN_IF_ERROR(CheckSigma("noise.min_sigma", params.min_sigma));
  if (!(params.guard_sigmas >= 2.0 && params.guard_sigmas <= 100.0)) {
    return absl::InvalidArgumentError(absl::StrCat("noise.guard_sigmas must be in [2, 100], got ",
                                                   DescribeDouble(params.guard_sigmas)));
  }
  if (!(params.key_sigmas >= 0.01 && params.key_sigmas <= 10.0)) {
    return absl::InvalidArgumentError(absl::StrCat("noise.key_sigmas must be in [0.01, 10], got ",
                                                   DescribeDouble(params.key_sigmas)));
  }
  return absl::OkStatus();
}

absl::StatusOr<NoiseCurves> FitNoiseCurves(const Clip& clip,
                                           std::span<const std::span<const double>> inputs,
                                           const NoiseParams& params, const ProgressFn& progress,
                                           std::stop_token stop) {
  NoiseCurves out;
  const int count = static_cast<int>(inputs.size());
  NoiseFitOptions options;
  SmootherFactors factors;  // shared by the channels: they have the same length
  options.guard_sigmas = params.guard_sigmas;
  options.key_sigmas = params.key_sigmas;
  for (int c = 0; c < count; ++c) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const std::span<const double> samples = inputs[c];
    const std::optional<double> given = IsRotation(clip.channels[c].kind)
                                            ? params.rotation_sigma_degrees
                                            : params.position_sigma;
    const double sigma = given ? *given : std::max(params.min_sigma, EstimateNoiseSigma(samples));
    out.sigmas.push_back(sigma);
    out.estimated.push_back(!given.has_value());
    if (std::all_of(samples.begin(), samples.end(),
                    [&](double v) { return v == samples.front(); })) {
      out.curves.push_back(FlatCurve(samples.size(), samples.front(), clip.frame_time_seconds));
    } else {
      absl::StatusOr<SplineFit> fit = FitToNoise(samples, sigma, options, stop, factors);
      if (!fit.ok()) return Annotate(fit.status(), ChannelLabel(clip, c));
      out.curves.push_back(CurveOf(*fit, clip.frame_time_seconds));
    }
    ReportProgress(progress, static_cast<double>(c + 1) / count,
                   absl::StrCat("reduce ", c + 1, "/", count));
  }
  return out;
}

}  // namespace tempokey::core::reduce_internal
