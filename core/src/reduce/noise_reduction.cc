// The `noise` method over a clip: noise levels per channel, FitToNoise(), curves in seconds.
#include "noise_reduction.h"

#include <algorithm>
#include <cmath>
#include <string_view>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"
#include "noise_smoother.h"
#include "tempokey/core/reduce/noise_fit.h"

namespace tempokey::core::reduce_internal {
namespace {

// Noise levels: the range of the error bounds (reduce.cc), for the same reasons: below 1e-9 no
// double near the largest sample magnitude (1e9, clip.h) resolves the level, and above 1e9 it
// smooths every channel flat. (1e-300 was taken, and kept a key at 599 of 600 frames; 1e308
// too.)
constexpr double kMinSigma = 1e-9;
constexpr double kMaxSigma = 1e9;

absl::Status CheckSigma(std::string_view field, double value) {
  if (!(value >= kMinSigma && value <= kMaxSigma)) {
    return absl::InvalidArgumentError(absl::StrCat(AsAbsl(field), " must be in [", kMinSigma,
                                                   ", ", kMaxSigma, "], got ",
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
  // Channels fitted as they are: all samples equal (two flat keys), or an estimate of exactly 0,
  // no white noise at all in the third differences (the motion makes up all of them, or there
  // are fewer than 7 samples): nothing for the smoother to take out.
  std::vector<bool> flat;
  std::vector<bool> noiseless;
  for (int c = 0; c < count; ++c) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const std::span<const double> samples = inputs[c];
    const std::optional<double> given = IsRotation(clip.channels[c].kind)
                                            ? params.rotation_sigma_degrees
                                            : params.position_sigma;
    const double estimate = given ? *given : EstimateNoiseSigma(samples);
    out.sigmas.push_back(given ? *given : std::max(params.min_sigma, estimate));
    out.estimated.push_back(!given.has_value());
    flat.push_back(std::all_of(samples.begin(), samples.end(),
                               [&](double v) { return v == samples.front(); }));
    noiseless.push_back(!given && estimate == 0.0);
  }
  // The channels to smooth are smoothed a few at a time (SmoothGroupToNoise()): `group` holds
  // the next ones, `smooth` their curves.
  std::vector<int> group;
  std::vector<std::vector<double>> smooth;
  std::size_t next_in_group = 0;
  for (int c = 0; c < count; ++c) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const std::span<const double> samples = inputs[c];
    const double sigma = out.sigmas[static_cast<std::size_t>(c)];
    if (flat[static_cast<std::size_t>(c)]) {
      out.curves.push_back(FlatCurve(samples.size(), samples.front(), clip.frame_time_seconds));
    } else {
      std::span<const double> curve = samples;
      if (noiseless[static_cast<std::size_t>(c)]) {
        TEMPOKEY_RETURN_IF_ERROR(
            Annotate(CheckNoiseFit(samples, sigma, options), ChannelLabel(clip, c)));
      } else {
        if (next_in_group == group.size()) {
          TEMPOKEY_RETURN_IF_ERROR(
              Annotate(CheckNoiseFit(samples, sigma, options), ChannelLabel(clip, c)));
          group.assign(1, c);
          std::vector<std::span<const double>> spans = {samples};
          std::vector<double> sigmas = {sigma};
          // The following channels to smooth join while they pass the checks (one that fails
          // reports its error in its turn, after the channels before it).
          for (int d = c + 1; d < count && group.size() < kSmootherGroup; ++d) {
            const auto ud = static_cast<std::size_t>(d);
            if (flat[ud] || noiseless[ud]) continue;
            if (!CheckNoiseFit(inputs[d], out.sigmas[ud], options).ok()) break;
            group.push_back(d);
            spans.push_back(inputs[d]);
            sigmas.push_back(out.sigmas[ud]);
          }
          absl::StatusOr<std::vector<std::vector<double>>> smoothed =
              SmoothGroupToNoise(spans, sigmas, options, factors, stop);
          if (!smoothed.ok()) return Annotate(smoothed.status(), ChannelLabel(clip, c));
          smooth = *std::move(smoothed);
          next_in_group = 0;
        }
        curve = smooth[next_in_group++];
      }
      absl::StatusOr<SplineFit> fit = FitKeysToNoise(curve, sigma, options, stop);
      if (!fit.ok()) return Annotate(fit.status(), ChannelLabel(clip, c));
      out.curves.push_back(CurveOf(*fit, clip.frame_time_seconds));
    }
    ReportProgressOf(progress, static_cast<double>(c + 1) / count, "reduce ", c + 1, "/", count);
  }
  return out;
}

}  // namespace tempokey::core::reduce_internal
