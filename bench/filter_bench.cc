// The jitter benchmark of SPEC 8 (filtering): how close key-reduced curves of noisy captures come
// to the clean motion, against the standard zero-lag Butterworth low-pass and an adaptive-knot
// smoothing spline (FITPACK's criterion), side by side in one run.
//
// Clean motion: each shared Bandai clip, rotation channels unwrapped, upsampled 30 -> 120 fps by
// cubic (Catmull-Rom) interpolation. Noisy input: the clean motion plus Gaussian noise of
// sigma 0.5 degrees on every rotation channel (fixed seed). Measured on the rotation channels of
// all seven clips together: RMS error against the clean motion (degrees) and keys kept as a
// percentage of samples.
//
//   filter_bench [BOUND_DEGREES ...]     (default bounds: 0.75 1.0 1.25 1.5)
//
// Rows, each with RMS and max error against the clean motion (degrees) and keys kept:
//   - the noisy input itself;
//   - the zero-lag 2nd-order Butterworth at 10/15/20/25 Hz (filtfilt: forward and backward, so no
//     phase lag; every sample kept);
//   - the smoothing-spline anchor: a C2 cubic spline with knots on frames, knots added where the
//     residual is largest until the least-squares spline's residual is at most s = N sigma^2
//     (FITPACK's criterion, sigma the true 0.5; keys = knots), written here;
//   - `tolerance` at each bound (within the bound of the *noisy* input at every frame);
//   - `paper` with its defaults;
//   - `noise` with sigma known (0.5) and estimated per channel.
// Then, at matched key counts: each reducing method refitted to keep about as many keys as
// `noise` (sigma estimated): `tolerance` through its key budget per clip, the spline anchor by
// scaling s, `paper` by the spacing of its initial keys.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "bench/smoothing_spline.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/noise_fit.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/model/rotation.h"

namespace tempokey::core {
namespace {

using ::tempokey::bench::SmoothingSpline;

constexpr double kNoiseSigmaDegrees = 0.5;
constexpr unsigned kSeed = 20261123;
constexpr std::int64_t kCleanRate = 120;

struct Capture {
  Clip clean;
  Clip noisy;
};

std::vector<std::string> BandaiFiles() {
  std::vector<std::string> files;
  const std::string dir = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/bandai";
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() == ".bvh") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

bool MakeCapture(const std::string& path, std::mt19937& random, Capture& capture) {
  absl::StatusOr<Clip> clip = ReadBvhFile(path);
  if (!clip.ok()) {
    std::fprintf(stderr, "%s\n", std::string(clip.status().message()).c_str());
    return false;
  }
  for (Channel& channel : clip->channels) {
    if (IsRotation(channel.kind)) UnwrapDegrees(channel.samples);
  }
  RetimeOptions upsample;
  upsample.output_rate = FrameRate{kCleanRate, 1};
  upsample.filter = ResampleFilter::kCubic;
  upsample.rotation_mode = RotationMode::kEuler;  // unwrapped angles as scalars: plain cubic
  absl::StatusOr<RetimeResult> clean = Retime(*clip, TimeWarpSpec{}, upsample);
  if (!clean.ok()) {
    std::fprintf(stderr, "%s: %s\n", path.c_str(), std::string(clean.status().message()).c_str());
    return false;
  }
  capture.clean = std::move(clean->clip);
  capture.noisy = capture.clean;
  std::normal_distribution<double> noise(0.0, kNoiseSigmaDegrees);
  for (Channel& channel : capture.noisy.channels) {
    if (!IsRotation(channel.kind)) continue;
    for (double& v : channel.samples) v += noise(random);
  }
  return true;
}

// Accumulates squared and largest error against the clean motion over rotation channels.
struct ErrorSum {
  double squared = 0.0;
  double max = 0.0;
  std::int64_t samples = 0;
  std::int64_t keys = 0;

  void Add(std::span<const double> clean, std::span<const double> estimate) {
    for (std::size_t i = 0; i < clean.size(); ++i) {
      const double e = estimate[i] - clean[i];
      squared += e * e;
      max = std::max(max, std::abs(e));
    }
    samples += static_cast<std::int64_t>(clean.size());
  }
  double Rms() const { return std::sqrt(squared / static_cast<double>(samples)); }
  double KeyPercent() const {
    return 100.0 * static_cast<double>(keys) / static_cast<double>(samples);
  }
};

// One pass of the 2nd-order Butterworth low-pass (bilinear transform, pre-warped cut-off), its
// state started at the first sample so a constant signal passes unchanged.
std::vector<double> ButterworthPass(std::span<const double> x, double cutoff_hz, double rate_hz) {
  const double k = std::tan(std::numbers::pi * cutoff_hz / rate_hz);
  const double q = std::numbers::sqrt2;
  const double norm = 1.0 / (1.0 + q * k + k * k);
  const double b0 = k * k * norm;
  const double b1 = 2.0 * b0;
  const double b2 = b0;
  const double a1 = 2.0 * (k * k - 1.0) * norm;
  const double a2 = (1.0 - q * k + k * k) * norm;
  std::vector<double> y(x.size());
  double x1 = x[0], x2 = x[0], y1 = x[0], y2 = x[0];
  for (std::size_t i = 0; i < x.size(); ++i) {
    y[i] = b0 * x[i] + b1 * x1 + b2 * x2 - a1 * y1 - a2 * y2;
    x2 = x1;
    x1 = x[i];
    y2 = y1;
    y1 = y[i];
  }
  return y;
}

// Zero-lag: forward, then backward over the forward result.
std::vector<double> FiltFilt(std::span<const double> x, double cutoff_hz, double rate_hz) {
  std::vector<double> forward = ButterworthPass(x, cutoff_hz, rate_hz);
  std::reverse(forward.begin(), forward.end());
  std::vector<double> both = ButterworthPass(forward, cutoff_hz, rate_hz);
  std::reverse(both.begin(), both.end());
  return both;
}

void PrintRow(const std::string& name, const ErrorSum& sum, bool keyed) {
  if (keyed) {
    std::printf("%-36s %9.4f %9.3f %8.2f\n", name.c_str(), sum.Rms(), sum.max, sum.KeyPercent());
  } else {
    std::printf("%-36s %9.4f %9.3f %8s\n", name.c_str(), sum.Rms(), sum.max, "100");
  }
  std::fflush(stdout);
}

using Captures = std::vector<Capture>;

// Each rotation channel of every capture through `fit` (noisy samples in, estimate out, keys
// added to the sum).
template <typename Fit>
ErrorSum PerChannel(const Captures& captures, Fit fit) {
  ErrorSum sum;
  for (const Capture& capture : captures) {
    for (std::size_t c = 0; c < capture.clean.channels.size(); ++c) {
      if (!IsRotation(capture.clean.channels[c].kind)) continue;
      std::int64_t keys = 0;
      const std::vector<double> estimate = fit(capture.noisy.channels[c].samples, &keys);
      sum.Add(capture.clean.channels[c].samples, estimate);
      sum.keys += keys;
    }
  }
  return sum;
}

ErrorSum SplineAnchor(const Captures& captures, double scale) {
  return PerChannel(captures, [&](std::span<const double> noisy, std::int64_t* keys) {
    const double target =
        scale * static_cast<double>(noisy.size()) * kNoiseSigmaDegrees * kNoiseSigmaDegrees;
    return SmoothingSpline(noisy, target, keys);
  });
}

// A reduction of every capture with `options(capture index)`, measured on rotation channels.
template <typename Options>
absl::StatusOr<ErrorSum> Reduced(const Captures& captures, Options options) {
  ErrorSum sum;
  for (std::size_t i = 0; i < captures.size(); ++i) {
    const Capture& capture = captures[i];
    absl::StatusOr<ReduceResult> reduced = ReduceKeys(capture.noisy, options(i));
    if (!reduced.ok()) return reduced.status();
    std::vector<double> fitted(static_cast<std::size_t>(capture.clean.frame_count));
    for (std::size_t c = 0; c < capture.clean.channels.size(); ++c) {
      if (!IsRotation(capture.clean.channels[c].kind)) continue;
      SampleCurve(reduced->keyed.curves[c], capture.clean.frame_time_seconds, fitted);
      sum.Add(capture.clean.channels[c].samples, fitted);
      sum.keys += static_cast<std::int64_t>(reduced->keyed.curves[c].keys.size());
    }
  }
  return sum;
}

// Keys of every channel (all kinds) of a reduction of each capture, for key budgets.
std::vector<std::int64_t> KeysPerCapture(const Captures& captures, const ReduceOptions& options) {
  std::vector<std::int64_t> keys;
  for (const Capture& capture : captures) {
    absl::StatusOr<ReduceResult> reduced = ReduceKeys(capture.noisy, options);
    keys.push_back(reduced.ok() ? reduced->report.key_count : 0);
  }
  return keys;
}

int Fail(const absl::Status& status) {
  std::fprintf(stderr, "%s\n", std::string(status.message()).c_str());
  return 1;
}

int Main(int argc, char** argv) {
  std::vector<double> bounds;
  for (int i = 1; i < argc; ++i) bounds.push_back(std::atof(argv[i]));
  if (bounds.empty()) bounds = {0.75, 1.0, 1.25, 1.5};

  std::mt19937 random(kSeed);
  Captures captures;
  for (const std::string& file : BandaiFiles()) {
    Capture capture;
    if (!MakeCapture(file, random, capture)) return 1;
    captures.push_back(std::move(capture));
  }
  std::printf("jitter benchmark: %zu Bandai clips at %lld fps, noise sigma %.2f deg, seed %u\n",
              captures.size(), static_cast<long long>(kCleanRate), kNoiseSigmaDegrees, kSeed);

  // The noise estimate per rotation channel (the method's own estimator).
  std::vector<double> estimates;
  for (const Capture& capture : captures) {
    for (const Channel& channel : capture.noisy.channels) {
      if (IsRotation(channel.kind)) estimates.push_back(EstimateNoiseSigma(channel.samples));
    }
  }
  std::sort(estimates.begin(), estimates.end());
  double mean = 0.0;
  for (double e : estimates) mean += e;
  mean /= static_cast<double>(estimates.size());
  std::printf("noise estimate over %zu rotation channels: median %.4f, mean %.4f, 5-95 %% "
              "%.4f-%.4f, min %.4f, max %.4f (true %.2f)\n",
              estimates.size(), estimates[estimates.size() / 2], mean,
              estimates[estimates.size() / 20], estimates[estimates.size() * 19 / 20],
              estimates.front(), estimates.back(), kNoiseSigmaDegrees);

  std::printf("%-36s %9s %9s %8s\n", "method", "RMS deg", "max deg", "keys %");
  PrintRow("noisy input", PerChannel(captures, [](std::span<const double> noisy, std::int64_t*) {
             return std::vector<double>(noisy.begin(), noisy.end());
           }), false);
  for (double cutoff : {10.0, 15.0, 20.0, 25.0}) {
    PrintRow(absl::StrFormat("butterworth 2nd, %.0f Hz", cutoff),
             PerChannel(captures,
                        [&](std::span<const double> noisy, std::int64_t*) {
                          return FiltFilt(noisy, cutoff, kCleanRate);
                        }),
             false);
  }
  PrintRow("smoothing spline, s = N sigma^2", SplineAnchor(captures, 1.0), true);

  ErrorSum best_tolerance;
  double best_bound = 0.0;
  for (double bound : bounds) {
    ReduceOptions options;
    options.tolerance.max_rotation_error_degrees = bound;
    absl::StatusOr<ErrorSum> sum = Reduced(captures, [&](std::size_t) { return options; });
    if (!sum.ok()) return Fail(sum.status());
    PrintRow(absl::StrFormat("tolerance, bound %.2f deg", bound), *sum, true);
    if (best_bound == 0.0 || sum->Rms() < best_tolerance.Rms()) {
      best_tolerance = *sum;
      best_bound = bound;
    }
  }
  ReduceOptions paper;
  paper.method = ReduceMethod::kPaper;
  absl::StatusOr<ErrorSum> paper_sum = Reduced(captures, [&](std::size_t) { return paper; });
  if (!paper_sum.ok()) return Fail(paper_sum.status());
  PrintRow("paper, defaults", *paper_sum, true);

  ReduceOptions known;
  known.method = ReduceMethod::kNoise;
  known.noise.rotation_sigma_degrees = kNoiseSigmaDegrees;
  absl::StatusOr<ErrorSum> known_sum = Reduced(captures, [&](std::size_t) { return known; });
  if (!known_sum.ok()) return Fail(known_sum.status());
  PrintRow("noise, sigma known (0.5)", *known_sum, true);
  ReduceOptions estimated;
  estimated.method = ReduceMethod::kNoise;
  absl::StatusOr<ErrorSum> noise_sum = Reduced(captures, [&](std::size_t) { return estimated; });
  if (!noise_sum.ok()) return Fail(noise_sum.status());
  PrintRow("noise, sigma estimated", *noise_sum, true);
  std::printf("best tolerance bound: %.2f deg\n", best_bound);

  // ---- matched key counts: as many keys as `noise` (sigma estimated) -------------------------
  std::printf("\nat the key count of noise, sigma estimated (%.2f %%):\n", noise_sum->KeyPercent());
  std::printf("%-36s %9s %9s %8s\n", "method", "RMS deg", "max deg", "keys %");
  PrintRow("noise, sigma estimated", *noise_sum, true);
  // tolerance: the key budget of each clip is what `noise` kept on it (all channels).
  const std::vector<std::int64_t> budgets = KeysPerCapture(captures, estimated);
  absl::StatusOr<ErrorSum> tolerance_matched = Reduced(captures, [&](std::size_t i) {
    ReduceOptions options;
    options.tolerance.key_budget = budgets[i];
    return options;
  });
  if (!tolerance_matched.ok()) return Fail(tolerance_matched.status());
  PrintRow("tolerance, key budget", *tolerance_matched, true);
  // The spline anchor: s scaled (bisection in ratio) until its knots match.
  double low = 0.25, high = 4.0;
  ErrorSum spline_matched = SplineAnchor(captures, 1.0);
  for (int step = 0; step < 10; ++step) {
    const double scale = std::sqrt(low * high);
    spline_matched = SplineAnchor(captures, scale);
    if (spline_matched.keys > noise_sum->keys) {
      low = scale;  // more knots than wanted: allow more residual
    } else {
      high = scale;
    }
  }
  PrintRow(absl::StrFormat("smoothing spline, s = %.3f N sigma^2", std::sqrt(low * high)),
           spline_matched, true);
  // paper: its keys follow its initial keys; spacing them as the matched count does.
  ReduceOptions paper_matched = paper;
  paper_matched.paper.min_key_spacing_frames =
      std::max(1, static_cast<int>(std::lround(100.0 / noise_sum->KeyPercent())));
  paper_matched.paper.smoothing_sigma_frames =
      0.5 * static_cast<double>(paper_matched.paper.min_key_spacing_frames);
  absl::StatusOr<ErrorSum> paper_matched_sum =
      Reduced(captures, [&](std::size_t) { return paper_matched; });
  if (!paper_matched_sum.ok()) return Fail(paper_matched_sum.status());
  PrintRow(absl::StrFormat("paper, initial keys %d frames apart",
                           paper_matched.paper.min_key_spacing_frames),
           *paper_matched_sum, true);
  std::printf("\nSPEC 8 target: RMS <= 0.20 deg with <= 8 %% keys\n");
  return 0;
}

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) { return tempokey::core::Main(argc, argv); }
