// Quality table of the paper method (SPEC 4.1) on rotation channels, per file set: keys kept as a
// percentage of samples, RMS and max error (degrees, against the unwrapped input, at every frame,
// measured by MeasureReduction()). Constant channels (two keys, no error) are included.
//
//   reduce_quality_bench [max_iterations]
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "tempokey/core/bvh.h"
#include "tempokey/core/reduce.h"

namespace tempokey::core {
namespace {

struct Totals {
  std::int64_t keys = 0;
  std::int64_t samples = 0;
  double squared = 0.0;
  double max_error = 0.0;
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

bool AddFile(const std::string& path, const ReduceOptions& options, Totals& totals) {
  absl::StatusOr<Clip> clip = ReadBvhFile(path);
  if (!clip.ok()) {
    std::fprintf(stderr, "%s\n", std::string(clip.status().message()).c_str());
    return false;
  }
  absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);
  if (!result.ok()) {
    std::fprintf(stderr, "%s\n", std::string(result.status().message()).c_str());
    return false;
  }
  for (const ChannelReduction& channel : result->report.channels) {
    if (!IsRotation(clip->channels[channel.channel_index].kind)) continue;
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

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) {
  using namespace tempokey::core;
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  if (argc > 1) options.paper.max_iterations = std::atoi(argv[1]);
  const std::string root = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/";
  std::printf("paper method, rotation channels, max_iterations %d\n",
              options.paper.max_iterations);
  std::printf("%-8s %10s %10s %8s %10s %10s  %s\n", "set", "samples", "keys", "keys %", "RMS deg",
              "max deg", "worst");
  for (const char* set : {"cmu", "bandai"}) {
    Totals totals;
    for (const std::string& file : BvhFiles(root + set)) {
      if (!AddFile(file, options, totals)) return 1;
    }
    std::printf("%-8s %10lld %10lld %8.2f %10.4f %10.3f  %s\n", set,
                static_cast<long long>(totals.samples), static_cast<long long>(totals.keys),
                100.0 * static_cast<double>(totals.keys) / static_cast<double>(totals.samples),
                std::sqrt(totals.squared / static_cast<double>(totals.samples)), totals.max_error,
                totals.worst.c_str());
  }
  return 0;
}
