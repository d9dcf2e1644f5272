// The jitter benchmark of SPEC 8 (filtering): how close key-reduced curves of noisy captures come
// to the clean motion, against the standard zero-lag Butterworth low-pass.
//
// Clean motion: each shared Bandai clip, rotation channels unwrapped, upsampled 30 -> 120 fps by
// cubic (Catmull-Rom) interpolation. Noisy input: the clean motion plus Gaussian noise of
// sigma 0.5 degrees on every rotation channel (fixed seed). Measured on the rotation channels of
// all seven clips together: RMS error against the clean motion (degrees) and keys kept as a
// percentage of samples.
//
//   filter_bench [BOUND_DEGREES ...]     (default bounds: 0.75 1.0 1.25 1.5)
//
// Rows: the noisy input itself, the zero-lag 2nd-order Butterworth at 10/15/20/25 Hz (filtfilt:
// forward and backward, so no phase lag; every sample kept), and the `tolerance` reduction at
// each bound (within the bound of the *noisy* input at every frame, as always).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/model/rotation.h"

namespace tempokey::core {
namespace {

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

// Accumulates squared error against the clean motion over rotation channels.
struct ErrorSum {
  double squared = 0.0;
  std::int64_t samples = 0;
  std::int64_t keys = 0;

  void Add(std::span<const double> clean, std::span<const double> estimate) {
    for (std::size_t i = 0; i < clean.size(); ++i) {
      const double e = estimate[i] - clean[i];
      squared += e * e;
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

void PrintRow(const char* name, const ErrorSum& sum, bool keyed) {
  if (keyed) {
    std::printf("%-28s %9.4f %8.2f\n", name, sum.Rms(), sum.KeyPercent());
  } else {
    std::printf("%-28s %9.4f %8s\n", name, sum.Rms(), "100");
  }
}

int Main(int argc, char** argv) {
  std::vector<double> bounds;
  for (int i = 1; i < argc; ++i) bounds.push_back(std::atof(argv[i]));
  if (bounds.empty()) bounds = {0.75, 1.0, 1.25, 1.5};

  std::mt19937 random(kSeed);
  std::vector<Capture> captures;
  for (const std::string& file : BandaiFiles()) {
    Capture capture;
    if (!MakeCapture(file, random, capture)) return 1;
    captures.push_back(std::move(capture));
  }
  std::printf("jitter benchmark: %zu Bandai clips at %lld fps, noise sigma %.2f deg, seed %u\n",
              captures.size(), static_cast<long long>(kCleanRate), kNoiseSigmaDegrees, kSeed);
  std::printf("%-28s %9s %8s\n", "method", "RMS deg", "keys %");

  ErrorSum input;
  for (const Capture& capture : captures) {
    for (std::size_t c = 0; c < capture.clean.channels.size(); ++c) {
      if (!IsRotation(capture.clean.channels[c].kind)) continue;
      input.Add(capture.clean.channels[c].samples, capture.noisy.channels[c].samples);
    }
  }
  PrintRow("noisy input", input, false);

  for (double cutoff : {10.0, 15.0, 20.0, 25.0}) {
    ErrorSum sum;
    for (const Capture& capture : captures) {
      for (std::size_t c = 0; c < capture.clean.channels.size(); ++c) {
        if (!IsRotation(capture.clean.channels[c].kind)) continue;
        sum.Add(capture.clean.channels[c].samples,
                FiltFilt(capture.noisy.channels[c].samples, cutoff, kCleanRate));
      }
    }
    const std::string name = "butterworth 2nd, " + std::to_string(static_cast<int>(cutoff)) + " Hz";
    PrintRow(name.c_str(), sum, false);
  }

  for (double bound : bounds) {
    ErrorSum sum;
    for (const Capture& capture : captures) {
      ReduceOptions options;
      options.tolerance.max_rotation_error_degrees = bound;
      absl::StatusOr<ReduceResult> reduced = ReduceKeys(capture.noisy, options);
      if (!reduced.ok()) {
        std::fprintf(stderr, "%s\n", std::string(reduced.status().message()).c_str());
        return 1;
      }
      std::vector<double> fitted(static_cast<std::size_t>(capture.clean.frame_count));
      for (std::size_t c = 0; c < capture.clean.channels.size(); ++c) {
        if (!IsRotation(capture.clean.channels[c].kind)) continue;
        SampleCurve(reduced->keyed.curves[c], capture.clean.frame_time_seconds, fitted);
        sum.Add(capture.clean.channels[c].samples, fitted);
        sum.keys += static_cast<std::int64_t>(reduced->keyed.curves[c].keys.size());
      }
    }
    const std::string name = "tolerance, bound " + std::to_string(bound).substr(0, 4) + " deg";
    PrintRow(name.c_str(), sum, true);
  }
  std::printf("SPEC 8 target: RMS <= 0.20 deg with <= 8 %% keys; anchors: noisy 0.50, "
              "Butterworth 20 Hz 0.276, FITPACK smoothing spline 0.236 at 9.8 %%\n");
  return 0;
}

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) { return tempokey::core::Main(argc, argv); }
