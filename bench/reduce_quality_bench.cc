// Quality table of both reduction methods (SPEC 4, 8) on the rotation channels of the shared
// captures, per file set: keys kept as a percentage of samples, RMS and max error (degrees, against
// the unwrapped input, at every frame, measured by MeasureReduction()), the worst channel, and the
// fitting time per million samples on one core.
//
//   reduce_quality_bench [paper|tolerance|both] [max_iterations | max_error_degrees]
//   reduce_quality_bench world
//   reduce_quality_bench fewest [max_error_degrees ...]
//
// `paper` counts every rotation channel (constant ones keep two keys). `tolerance` excludes
// constant channels, as SPEC 8's key-count targets do (CMU <= 5 %, Bandai <= 15 % at 0.5°).
// `world` prints every shared clip's joint world-position error at the default settings, then the
// joint bound against the per-channel 0.5° reduction (SPEC 8: at 1 cm on the Bandai clips, every
// joint within 1 cm with no more keys): keys %, worst joint error, RMS rotation error, at bounds
// from 4 cm to 0.25 cm (Bandai) and from 3 % to 0.25 % of the height (CMU), so that a change to
// the fit shows its keys at every bound, not only at the one the target names.
// `fewest` sets the `tolerance` method's keys beside the fewest any curve with keys on frames and
// cubic pieces could keep (bench/cubic_minimax.h; SPEC 8's key-count targets), per clip and per
// set, at each bound given (default 0.1, 0.25, 0.5 and 1 degree); it fails when a channel's
// keys are fewer than that, which neither the fit nor the bound may allow.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "bench/cubic_minimax.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/rotation.h"
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

// ---- world error (SPEC 4.4, 8) -------------------------------------------------------------------

// Every shared clip's world error at the default settings.
bool PrintWorldReports() {
  const std::string root = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/";
  std::printf("world error at the default settings (0.5 deg, positions 0.3 %% of the height)\n");
  std::printf("%-50s %8s %7s %9s %8s %9s %8s  %s\n", "clip", "height", "keys %", "max", "max %",
              "RMS", "RMS %", "worst joint, frame");
  for (const char* set : {"cmu", "bandai"}) {
    for (const std::string& file : BvhFiles(root + set)) {
      absl::StatusOr<Clip> clip = ReadBvhFile(file);
      if (!clip.ok()) return false;
      absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, ReduceOptions{});
      if (!result.ok() || !result->report.world) {
        std::fprintf(stderr, "%s\n", std::string(result.status().message()).c_str());
        return false;
      }
      const WorldErrorReport& w = *result->report.world;
      std::printf("%-50s %8.2f %7.2f %9.4f %8.3f %9.4f %8.4f  %s, %lld\n",
                  (std::string(set) + "/" + std::filesystem::path(file).filename().string()).c_str(),
                  w.figure_height, result->report.key_percent(), w.max_error,
                  w.max_error_percent(), w.rms_error, w.rms_error_percent(),
                  w.worst_point_name.c_str(), static_cast<long long>(w.worst_frame));
    }
  }
  std::printf("\n");
  return true;
}

struct WorldSetting {
  const char* name;
  std::optional<JointTolerance> joint;
};

// Per setting, over the clips of `set`: keys of the non-constant channels (all, and rotations
// alone) as a percentage of their samples, the worst joint error (file units and % of the
// height) with the bound it kept, the RMS error of the rotation channels (degrees), time.
bool PrintJointBoundTable(const char* set, const std::vector<WorldSetting>& settings) {
  const std::string root = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/";
  std::printf("joint bound, %s clips, channels without constant ones\n", set);
  std::printf("%-20s %7s %7s %10s %9s %10s %10s %9s\n", "setting", "keys %", "rot %",
              "worst jnt", "worst %", "bound", "RMS rot", "ms per M");
  for (const WorldSetting& setting : settings) {
    std::int64_t keys = 0, samples = 0, rotation_keys = 0, rotation_samples = 0, all = 0;
    double rotation_squared = 0.0, worst = 0.0, worst_percent = 0.0, seconds = 0.0;
    double bound = 0.0;
    for (const std::string& file : BvhFiles(root + set)) {
      absl::StatusOr<Clip> clip = ReadBvhFile(file);
      if (!clip.ok()) return false;
      ReduceOptions options;
      options.tolerance.joint_tolerance = setting.joint;
      const auto start = std::chrono::steady_clock::now();
      absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);
      seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      all += clip->sample_count();
      if (!result.ok()) {
        std::fprintf(stderr, "%s: %s\n", file.c_str(),
                     std::string(result.status().message()).c_str());
        return false;
      }
      for (const ChannelReduction& channel : result->report.channels) {
        const Channel& source = clip->channels[channel.channel_index];
        if (IsConstantChannel(source)) continue;
        keys += channel.key_count;
        samples += channel.sample_count;
        if (!IsRotation(source.kind)) continue;
        rotation_keys += channel.key_count;
        rotation_samples += channel.sample_count;
        rotation_squared +=
            channel.rms_error * channel.rms_error * static_cast<double>(channel.sample_count);
      }
      const WorldErrorReport& w = *result->report.world;
      worst = std::max(worst, w.max_error);
      worst_percent = std::max(worst_percent, w.max_error_percent());
      bound = std::max(bound, w.joint_tolerance);
    }
    std::printf("%-20s %7.2f %7.2f %10.4f %9.3f %10.4f %10.4f %9.1f\n", setting.name,
                100.0 * static_cast<double>(keys) / static_cast<double>(samples),
                100.0 * static_cast<double>(rotation_keys) / static_cast<double>(rotation_samples),
                worst, worst_percent, bound,
                std::sqrt(rotation_squared / static_cast<double>(rotation_samples)),
                1e9 * seconds / static_cast<double>(all));
  }
  std::printf("\n");
  return true;
}

// ---- the fewest keys possible (SPEC 8's key counts) ---------------------------------------------

struct KeyFloor {
  std::int64_t samples = 0;
  std::int64_t keys = 0;      // the tolerance method's, default search
  std::int64_t searched = 0;  // the tolerance method's, the fewest-keys search
  std::int64_t fewest = 0;    // no curve with cubic pieces between keys on frames has fewer
  std::int64_t undecided = 0;

  void Add(const KeyFloor& other) {
    samples += other.samples;
    keys += other.keys;
    searched += other.searched;
    fewest += other.fewest;
    undecided += other.undecided;
  }
  void Print(const std::string& name) const {
    const double n = static_cast<double>(samples);
    std::printf("%-46s %9lld %8.3f %8.3f %8.3f %7.3f %7.3f %9lld\n", name.c_str(),
                static_cast<long long>(samples), 100.0 * static_cast<double>(keys) / n,
                100.0 * static_cast<double>(searched) / n,
                100.0 * static_cast<double>(fewest) / n,
                static_cast<double>(keys) / static_cast<double>(fewest),
                static_cast<double>(searched) / static_cast<double>(fewest),
                static_cast<long long>(undecided));
  }
};

// One clip's rotation channels without constant ones at `bound` degrees: false (with a message)
// when a channel keeps fewer keys than the floor.
bool AddFloor(const std::string& path, double bound, KeyFloor& floor) {
  absl::StatusOr<Clip> clip = ReadBvhFile(path);
  if (!clip.ok()) {
    std::fprintf(stderr, "%s\n", std::string(clip.status().message()).c_str());
    return false;
  }
  ReduceOptions options;
  options.tolerance.max_rotation_error_degrees = bound;
  absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);
  options.tolerance.fewest_keys = true;
  absl::StatusOr<ReduceResult> searched = ReduceKeys(*clip, options);
  for (const absl::StatusOr<ReduceResult>* r : {&result, &searched}) {
    if (!r->ok()) {
      std::fprintf(stderr, "%s\n", std::string(r->status().message()).c_str());
      return false;
    }
  }
  const tempokey::bench::CubicMinimax minimax;
  for (std::size_t i = 0; i < result->report.channels.size(); ++i) {
    const ChannelReduction& channel = result->report.channels[i];
    const Channel& source = clip->channels[channel.channel_index];
    if (!IsRotation(source.kind) || IsConstantChannel(source)) continue;
    std::vector<double> samples = source.samples;
    UnwrapDegrees(samples);  // as the fit reads them
    const std::int64_t fewest = minimax.FewestKeys(samples, bound, &floor.undecided);
    const std::int64_t search = searched->report.channels[i].key_count;
    if (channel.key_count < fewest || search < fewest) {
      std::fprintf(stderr, "%s %s: %lld and %lld keys at %g degrees, below the floor of %lld\n",
                   path.c_str(), ChannelLabel(*clip, channel.channel_index).c_str(),
                   static_cast<long long>(channel.key_count), static_cast<long long>(search),
                   bound, static_cast<long long>(fewest));
      return false;
    }
    floor.samples += channel.sample_count;
    floor.keys += channel.key_count;
    floor.searched += search;
    floor.fewest += fewest;
  }
  return true;
}

bool PrintKeyFloors(const std::vector<double>& bounds) {
  const std::string root = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/";
  for (double bound : bounds) {
    std::printf("tolerance keys (default and fewest-keys search) against the floor, %g deg, "
                "rotation channels without constant ones\n", bound);
    std::printf("%-46s %9s %8s %8s %8s %7s %7s %9s\n", "clip", "samples", "keys %", "search %",
                "floor %", "ratio", "search", "undecided");
    for (const char* set : {"cmu", "bandai"}) {
      KeyFloor total;
      for (const std::string& file : BvhFiles(root + set)) {
        KeyFloor clip;
        if (!AddFloor(file, bound, clip)) return false;
        clip.Print(std::string(set) + "/" + std::filesystem::path(file).filename().string());
        total.Add(clip);
      }
      total.Print(std::string(set) + ", all");
    }
    std::printf("\n");
  }
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
        std::to_string(
            options.tolerance.max_rotation_error_degrees.value_or(kDefaultMaxRotationErrorDegrees)) +
        " deg";
    if (!PrintTable(options, title.c_str(), true)) return 1;
  }
  if (which == "fewest") {
    std::vector<double> bounds;
    for (int i = 2; i < argc; ++i) bounds.push_back(std::atof(argv[i]));
    if (bounds.empty()) bounds = {0.1, 0.25, 0.5, 1.0};
    return PrintKeyFloors(bounds) ? 0 : 1;
  }
  if (which == "world") {
    if (!PrintWorldReports()) return 1;
    if (!PrintJointBoundTable("bandai", {{"per-channel 0.5 deg", std::nullopt},
                                         {"joint 4 cm", JointTolerance{.value = 4.0}},
                                         {"joint 2 cm", JointTolerance{.value = 2.0}},
                                         {"joint 1 cm", JointTolerance{.value = 1.0}},
                                         {"joint 0.5 cm", JointTolerance{.value = 0.5}},
                                         {"joint 0.25 cm", JointTolerance{.value = 0.25}}})) {
      return 1;
    }
    auto of_height = [](double percent) {
      return JointTolerance{.value = percent, .percent_of_height = true};
    };
    if (!PrintJointBoundTable("cmu", {{"per-channel 0.5 deg", std::nullopt},
                                      {"joint 3 %", of_height(3.0)},
                                      {"joint 1 %", of_height(1.0)},
                                      {"joint 0.75 %", of_height(0.75)},
                                      {"joint 0.5 %", of_height(0.5)},
                                      {"joint 0.25 %", of_height(0.25)}})) {
      return 1;
    }
  }
  return 0;
}
