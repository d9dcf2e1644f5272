// The noise estimate (EstimateNoiseSigma(), noise_fit.h) where its answer is known:
//   1. every shared clip as it is (Bandai: clean; CMU 131_01: raw capture whose jitter is not white
//      at the frame scale), per channel kind, non-constant channels: median and max of the
//      estimate, beside the third-difference estimate it replaced (median |third difference| /
//      (0.6745 sqrt 20));
//   2. the jitter benchmark's noisy clips (bench/filter_bench: Bandai at 120 fps by cubic
//      interpolation plus 0.5 degree white noise, same seed and order): median and 5-95 %;
//   3. the Bandai clips at their own 30 fps plus white noise of known sigma: median and 5-95 %
//      (below the motion's own third differences the noise reads as motion);
//   4. the noise method (sigma estimated) on every shared clip: keys and error against the input;
//   5. CMU 131_01 with the rotation noise level given (0.05 to 0.5 degrees), beside `tolerance`.
//
//   noise_estimate_bench
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/reduce/noise_fit.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::core {
namespace {

std::vector<std::string> Clips(const char* folder) {
  std::vector<std::string> files;
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(TEMPOKEY_SHARED_DIR) + folder)) {
    if (entry.path().extension() == ".bvh") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// The estimator this one replaced, for comparison.
double ThirdDifferenceEstimate(std::span<const double> x) {
  if (x.size() < 4) return 0.0;
  std::vector<double> d;
  for (std::size_t f = 0; f + 3 < x.size(); ++f) {
    d.push_back(std::abs(x[f + 3] - 3.0 * x[f + 2] + 3.0 * x[f + 1] - x[f]));
  }
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
  return d[d.size() / 2] / (0.6744897501960817 * std::sqrt(20.0));
}

bool Constant(const std::vector<double>& x) {
  return std::all_of(x.begin(), x.end(), [&](double v) { return v == x.front(); });
}

struct Values {
  std::vector<double> v;
  double Quantile(double q) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
  }
};

void PrintKind(const std::string& name, Values now, Values before) {
  if (now.v.empty()) return;
  std::printf("%-46s %4zu  median %.4f  max %.4f   (third difference: median %.4f  max %.4f)\n",
              name.c_str(), now.v.size(), now.Quantile(0.5), now.Quantile(1.0),
              before.Quantile(0.5), before.Quantile(1.0));
}

void PrintSpread(const std::string& name, Values values) {
  std::printf("%-46s %4zu  median %.4f  5-95 %% %.4f-%.4f  min %.4f  max %.4f\n", name.c_str(),
              values.v.size(), values.Quantile(0.5), values.Quantile(0.05), values.Quantile(0.95),
              values.Quantile(0.0), values.Quantile(1.0));
}

// Section 1 for the clips of `files`, each alone and (with `pooled`) all together.
void AsTheyAre(const std::vector<std::string>& files, const std::string& pooled) {
  Values all_rot, all_rot_before, all_pos, all_pos_before;
  for (const std::string& file : files) {
    absl::StatusOr<Clip> clip = ReadBvhFile(file);
    if (!clip.ok()) continue;
    Values rot, rot_before, pos, pos_before;
    for (const Channel& channel : clip->channels) {
      if (Constant(channel.samples)) continue;
      std::vector<double> x = channel.samples;
      if (IsRotation(channel.kind)) UnwrapDegrees(x);
      const bool rotation = IsRotation(channel.kind);
      (rotation ? rot : pos).v.push_back(EstimateNoiseSigma(x));
      (rotation ? rot_before : pos_before).v.push_back(ThirdDifferenceEstimate(x));
    }
    const std::string stem = std::filesystem::path(file).stem().string();
    PrintKind(stem + " rotations (deg)", rot, rot_before);
    PrintKind(stem + " positions (units)", pos, pos_before);
    for (auto [to, from] : {std::pair{&all_rot, &rot}, std::pair{&all_rot_before, &rot_before},
                            std::pair{&all_pos, &pos}, std::pair{&all_pos_before, &pos_before}}) {
      to->v.insert(to->v.end(), from->v.begin(), from->v.end());
    }
  }
  if (!pooled.empty()) {
    PrintKind(pooled + " rotations (deg)", all_rot, all_rot_before);
    PrintKind(pooled + " positions (units)", all_pos, all_pos_before);
  }
}

int Main() {
  const std::vector<std::string> bandai = Clips("/data/bvh/bandai");
  const std::vector<std::string> cmu = Clips("/data/bvh/cmu");
  std::printf("1. shared clips as they are, non-constant channels: estimate (channels, median, "
              "max)\n");
  AsTheyAre(bandai, "all Bandai");
  AsTheyAre(cmu, "");

  std::printf("\n2. jitter benchmark (120 fps cubic, + 0.50 deg white noise, seed 20261123)\n");
  {
    std::mt19937 random(20261123);
    Values estimates, before;
    for (const std::string& file : bandai) {
      absl::StatusOr<Clip> clip = ReadBvhFile(file);
      if (!clip.ok()) return 1;
      for (Channel& channel : clip->channels) {
        if (IsRotation(channel.kind)) UnwrapDegrees(channel.samples);
      }
      RetimeOptions upsample;
      upsample.output_rate = FrameRate{120, 1};
      upsample.filter = ResampleFilter::kCubic;
      upsample.rotation_mode = RotationMode::kEuler;
      absl::StatusOr<RetimeResult> clean = Retime(*clip, TimeWarpSpec{}, upsample);
      if (!clean.ok()) return 1;
      std::normal_distribution<double> noise(0.0, 0.5);
      for (Channel& channel : clean->clip.channels) {
        if (!IsRotation(channel.kind)) continue;
        for (double& v : channel.samples) v += noise(random);
        estimates.v.push_back(EstimateNoiseSigma(channel.samples));
        before.v.push_back(ThirdDifferenceEstimate(channel.samples));
      }
    }
    PrintSpread("rotation channels (true 0.5)", estimates);
    PrintSpread("  third difference (true 0.5)", before);
  }

  std::printf("\n3. Bandai at 30 fps + white noise of known sigma, non-constant rotation "
              "channels\n");
  for (double sigma : {0.05, 0.1, 0.2, 0.5, 1.0}) {
    std::mt19937 random(5);
    std::normal_distribution<double> noise(0.0, sigma);
    Values estimates;
    for (const std::string& file : bandai) {
      absl::StatusOr<Clip> clip = ReadBvhFile(file);
      if (!clip.ok()) return 1;
      for (Channel& channel : clip->channels) {
        if (!IsRotation(channel.kind) || Constant(channel.samples)) continue;
        UnwrapDegrees(channel.samples);
        for (double& v : channel.samples) v += noise(random);
        estimates.v.push_back(EstimateNoiseSigma(channel.samples));
      }
    }
    char name[64];
    std::snprintf(name, sizeof name, "sigma %.2f deg", sigma);
    PrintSpread(name, estimates);
  }

  std::printf("\n4. noise method, sigma estimated, on the shared clips as they are\n");
  std::vector<std::string> all = bandai;
  all.insert(all.end(), cmu.begin(), cmu.end());
  for (const std::string& file : all) {
    absl::StatusOr<Clip> clip = ReadBvhFile(file);
    if (!clip.ok()) return 1;
    ReduceOptions options;
    options.method = ReduceMethod::kNoise;
    absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);
    if (!result.ok()) return 1;
    double largest_rotation_sigma = 0.0;
    for (const ChannelReduction& channel : result->report.channels) {
      if (IsRotation(clip->channels[static_cast<std::size_t>(channel.channel_index)].kind)) {
        largest_rotation_sigma = std::max(largest_rotation_sigma, channel.noise_sigma);
      }
    }
    std::printf("%-40s keys %6lld (%5.2f %%)  error rms %.4f max %.4f  largest rotation sigma "
                "%.4f\n",
                std::filesystem::path(file).stem().string().c_str(),
                static_cast<long long>(result->report.key_count), result->report.key_percent(),
                result->report.rms_error, result->report.max_error, largest_rotation_sigma);
  }

  // Where the estimate finds no white noise, a level given by the user is what decides: the raw
  // capture with the rotation level given, beside `tolerance` at its default bound.
  std::printf("\n5. CMU 131_01 (raw capture), the rotation noise level given, and tolerance 0.5 deg\n");
  for (const std::string& file : cmu) {
    absl::StatusOr<Clip> clip = ReadBvhFile(file);
    if (!clip.ok()) return 1;
    for (const double sigma : {0.05, 0.1, 0.25, 0.5, 0.0}) {
      ReduceOptions options;
      if (sigma > 0.0) {
        options.method = ReduceMethod::kNoise;
        options.noise.rotation_sigma_degrees = sigma;
      }
      absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);
      if (!result.ok()) return 1;
      char name[64];
      std::snprintf(name, sizeof name, sigma > 0.0 ? "noise, sigma %.2f deg" : "tolerance 0.5 deg",
                    sigma);
      std::printf("%-40s keys %6lld (%5.2f %%)  error rms %.4f max %.4f\n", name,
                  static_cast<long long>(result->report.key_count), result->report.key_percent(),
                  result->report.rms_error, result->report.max_error);
    }
  }
  return 0;
}

}  // namespace
}  // namespace tempokey::core

int main() { return tempokey::core::Main(); }
