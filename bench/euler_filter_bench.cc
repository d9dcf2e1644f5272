// What the Euler filter (euler_filter.h) costs or saves in keys: every shared clip reduced by
// `tolerance` at 0.5 degrees with the filter on and off, total keys, and per channel where the
// two differ (the filtered frames of that channel beside it).
//
//   euler_filter_bench [BVH ...]     (default: every shared clip)
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/euler_filter.h"
#include "tempokey/core/reduce/reduce.h"

namespace tempokey::core {
namespace {

std::vector<std::string> SharedClips() {
  std::vector<std::string> files;
  for (const char* dir : {"/data/bvh/bandai", "/data/bvh/cmu"}) {
    for (const auto& entry :
         std::filesystem::directory_iterator(std::string(TEMPOKEY_SHARED_DIR) + dir)) {
      if (entry.path().extension() == ".bvh") files.push_back(entry.path().string());
    }
  }
  std::sort(files.begin(), files.end());
  return files;
}

int Report(const std::string& path) {
  absl::StatusOr<Clip> clip = ReadBvhFile(path);
  if (!clip.ok()) {
    std::fprintf(stderr, "%s\n", std::string(clip.status().message()).c_str());
    return 1;
  }
  ReduceOptions on;
  on.tolerance.max_rotation_error_degrees = 0.5;
  on.euler_filter = true;
  ReduceOptions off = on;
  off.euler_filter = false;
  absl::StatusOr<ReduceResult> with = ReduceKeys(*clip, on);
  absl::StatusOr<ReduceResult> without = ReduceKeys(*clip, off);
  Clip filtered = *clip;
  if (!with.ok() || !without.ok() || !ApplyEulerFilter(filtered).ok()) return 1;
  std::printf("%-40s keys with filter %6lld, without %6lld (filtered frames %lld)\n",
              std::filesystem::path(path).stem().string().c_str(),
              static_cast<long long>(with->report.key_count),
              static_cast<long long>(without->report.key_count),
              static_cast<long long>(with->report.euler_filtered_frames));
  for (std::size_t c = 0; c < clip->channels.size(); ++c) {
    const std::size_t a = with->keyed.curves[c].keys.size();
    const std::size_t b = without->keyed.curves[c].keys.size();
    if (a == b) continue;
    int changed = 0;
    for (std::size_t f = 0; f < clip->channels[c].samples.size(); ++f) {
      changed += filtered.channels[c].samples[f] != clip->channels[c].samples[f];
    }
    std::printf("  channel %3zu (joint %s): keys with %zu, without %zu; frames rewritten %d\n", c,
                clip->channels[c].joint >= 0
                    ? clip->skeleton.joints[static_cast<std::size_t>(clip->channels[c].joint)]
                          .name.c_str()
                    : "-",
                a, b, changed);
  }
  return 0;
}

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) {
  std::vector<std::string> files(argv + 1, argv + argc);
  if (files.empty()) files = tempokey::core::SharedClips();
  for (const std::string& file : files) {
    if (tempokey::core::Report(file) != 0) return 1;
  }
  return 0;
}
