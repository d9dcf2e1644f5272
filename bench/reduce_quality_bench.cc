// Quality table of both reduction methods (SPEC 4, 8) on the rotation channels of the shared
// captures, per file set: keys kept as a percentage of samples, RMS and max error (degrees, against
// the unwrapped input, at every frame, measured by MeasureReduction()), the worst channel, and the
// fitting time per million samples on one core.
//
//   reduce_quality_bench [paper|tolerance|both] [max_iterations | max_error_degrees]
//
// `paper` counts every rotation channel (constant ones keep two keys). `tolerance` excludes
// constant channels, as SPEC 8's key-count targets do (CMU <= 5 %, Bandai <= 15 % at 0.5°).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/reduce/reduce.h"

namespace tempokey::core {
namespace {

struct Totals {
  std::int64_t keys = 0;
  std::int64_t samples = 0;
  double squared = 0.0;
  double max_error = 0.0;
  double seconds = 0.0;
  std::int64_t fitted_samples = 0;  // all channels of the files, what the time covers
  std::string worst;
};

std::vector<std::string> BvhFiles(const std::string& dir) {
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() == ".bvh") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

bool IsConstantChannel(const Channel& channel) {
  return std::all_of(channel.samples.begin(), channel.samples.end(),
                     [&](double v) { return v == channel.samples.front(); });
}

bool AddFile(const std::string& path, const ReduceOptions& options, bool skip_constant,
             Totals& totals) {
  absl::StatusOr<Clip> clip = ReadBvhFile(path);
  if (!clip.ok()) {
    std::fprintf(stderr, "%s\n", std::string(clip.status().message()).c_str());
    return false;
  }
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);
  totals.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  totals.fitted_samples += clip->sample_count();
  if (!result.ok()) {
    std::fprintf(stderr, "%s\n", std::string(result.status().message()).c_str());
    return false;
  }
  for (const ChannelReduction& channel : result->report.channels) {
    const Channel& source = clip->channels[channel.channel_index];
    if (!IsRotation(source.kind)) continue;
    if (skip_constant && IsConstantChannel(source)) continue;
    totals.keys += channel.key_count;
    totals.samples += channel.sample_count;
    totals.squared +=
        channel.rms_error * channel.rms_error * static_cast<double>(channel.sample_count);
    if (channel.max_error > totals.max_error) {
      totals.max_error = channel.max_error;
      totals.worst = std::filesystem::path(path).filename().string() + " " +
                     ChannelLabel(*clip, channel.channel_index) + " frame " +
                     std::to_string(channel.max_error_frame);
    }
  }
  return true;
}

bool PrintTable(const ReduceOptions& options, const char* title, bool skip_constant) {
  const std::string root = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/";
  std::printf("%s\n", title);
  std::printf("%-8s %9s %8s %7s %9s %9s %11s  %s\n", "set", "samples", "keys", "keys %",
              "RMS deg", "max deg", "ms per M", "worst");
  for (const char* set : {"cmu", "bandai"}) {
    Totals totals;
    for (const std::string& file : BvhFiles(root + set)) {
      if (!AddFile(file, options, skip_constant, totals)) return false;
    }
    std::printf("%-8s %9lld %8lld %7.2f %9.4f %9.3f %11.1f  %s\n", set,
                static_cast<long long>(totals.samples), static_cast<long long>(totals.keys),
                100.0 * static_cast<double>(totals.keys) / static_cast<double>(totals.samples),
                std::sqrt(totals.squared / static_cast<double>(totals.samples)), totals.max_error,
                1e9 * totals.seconds / static_cast<double>(totals.fitted_samples),
                totals.worst.c_str());
  }
  std::printf("\n");
  return true;
}

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) {
  using namespace tempokey::core;
  const std::string which = argc > 1 ? argv[1] : "both";
  if (which == "paper" || which == "both") {
    ReduceOptions options;
    options.method = ReduceMethod::kPaper;
    if (which == "paper" && argc > 2) options.paper.max_iterations = std::atoi(argv[2]);
    const std::string title = "paper method, rotation channels, max_iterations " +
                              std::to_string(options.paper.max_iterations);
    if (!PrintTable(options, title.c_str(), false)) return 1;
  }
  if (which == "tolerance" || which == "both") {
    ReduceOptions options;
    options.method = ReduceMethod::kTolerance;
    if (which == "tolerance" && argc > 2) {
      options.tolerance.max_rotation_error_degrees = std::atof(argv[2]);
    }
    const std::string title =
        "tolerance method, rotation channels without constant ones, bound " +
        std::to_string(options.tolerance.max_rotation_error_degrees) + " deg";
    if (!PrintTable(options, title.c_str(), true)) return 1;
  }
  return 0;
}
