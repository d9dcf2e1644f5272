// What the Euler filter (euler_filter.h) costs or saves in keys: every shared clip reduced by
// `tolerance` at 0.5 degrees with the filter on and off, total keys, and per channel where the
// two differ (the filtered frames of that channel beside it). For each joint whose keys differ,
// the best any choice of branches could do: at every frame where both branches jump (a real
// rotation change: each equivalent triple moves the three angles by more than 90 degrees in
// all), every assignment of the two branches is tried (up to 2^12), the other frames filtered as
// the filter does, and the joint's keys of the best one printed.
//
//   euler_filter_bench [BVH ...]     (default: every shared clip)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/euler_filter.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/reduce/tolerance_fit.h"

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

constexpr double kJumpDegrees = 90.0;

double AbsoluteStep(const Vec3& a, const Vec3& b) {
  return std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
}

// The joint's channels filtered frame by frame as the filter does, except at the frames of
// `jumps`, where bit i of `mask` picks the other branch (1) or the same one (0).
void FilterWithChoices(Clip& clip, const JointRotation& joint,
                       const std::vector<std::size_t>& jumps, unsigned mask) {
  std::vector<double>& a = clip.channels[static_cast<std::size_t>(joint.channels[0])].samples;
  std::vector<double>& b = clip.channels[static_cast<std::size_t>(joint.channels[1])].samples;
  std::vector<double>& c = clip.channels[static_cast<std::size_t>(joint.channels[2])].samples;
  for (std::size_t f = 1; f < a.size(); ++f) {
    const Vec3 previous = {a[f - 1], b[f - 1], c[f - 1]};
    const Vec3 same = {NearestTurn(a[f], previous[0]), NearestTurn(b[f], previous[1]),
                       NearestTurn(c[f], previous[2])};
    const Vec3 other = {NearestTurn(a[f] + 180.0, previous[0]),
                        NearestTurn(180.0 - b[f], previous[1]),
                        NearestTurn(c[f] + 180.0, previous[2])};
    const auto jump = std::find(jumps.begin(), jumps.end(), f);
    const bool flip = jump != jumps.end()
                          ? ((mask >> (jump - jumps.begin())) & 1u) != 0
                          : AbsoluteStep(other, previous) < AbsoluteStep(same, previous);
    const Vec3& chosen = flip ? other : same;
    a[f] = chosen[0];
    b[f] = chosen[1];
    c[f] = chosen[2];
  }
}

// Keys of the joint's channels each fitted alone within 0.5 degrees (what `tolerance` does per
// channel), unwrapped as the reduction unwraps them.
std::size_t FittedJointKeys(const Clip& clip, const JointRotation& joint) {
  std::size_t keys = 0;
  constexpr double kBound = 0.5;
  for (int c : joint.channels) {
    std::vector<double> samples = clip.channels[static_cast<std::size_t>(c)].samples;
    UnwrapDegrees(samples);
    const std::span<const double> channel(samples);
    absl::StatusOr<SplineFit> fit = FitWithinTolerance({&channel, 1}, {&kBound, 1});
    if (fit.ok()) keys += fit->frames.size();
  }
  return keys;
}

std::size_t JointKeys(const ReduceResult& result, const JointRotation& joint) {
  std::size_t keys = 0;
  for (int c : joint.channels) keys += result.keyed.curves[static_cast<std::size_t>(c)].keys.size();
  return keys;
}

// The best branch assignment at the joint's real jumps (see the top).
void BestChoice(const Clip& clip, const Clip& filtered, const JointRotation& joint) {
  std::vector<std::size_t> jumps;
  const auto& a = filtered.channels[static_cast<std::size_t>(joint.channels[0])].samples;
  const auto& b = filtered.channels[static_cast<std::size_t>(joint.channels[1])].samples;
  const auto& c = filtered.channels[static_cast<std::size_t>(joint.channels[2])].samples;
  for (std::size_t f = 1; f < a.size(); ++f) {
    if (AbsoluteStep({a[f], b[f], c[f]}, {a[f - 1], b[f - 1], c[f - 1]}) > kJumpDegrees) {
      jumps.push_back(f);
    }
  }
  if (jumps.size() > 12) {
    std::printf("    %zu real jumps: too many to try every assignment\n", jumps.size());
    return;
  }
  std::size_t best = 0;
  unsigned best_mask = 0;
  for (unsigned mask = 0; mask < (1u << jumps.size()); ++mask) {
    Clip trial = clip;
    FilterWithChoices(trial, joint, jumps, mask);
    const std::size_t keys = FittedJointKeys(trial, joint);
    if (mask == 0 || keys < best) {
      best = keys;
      best_mask = mask;
    }
  }
  std::printf("    real jumps at frames");
  for (std::size_t f : jumps) std::printf(" %zu", f);
  std::printf(": the best of all %u branch assignments keeps %zu keys on the joint (mask %#x)\n",
              1u << jumps.size(), best, best_mask);
  {
    Clip trial = clip;
    FilterWithChoices(trial, joint, jumps, best_mask);
    const auto& ta = trial.channels[static_cast<std::size_t>(joint.channels[0])].samples;
    const auto& tb = trial.channels[static_cast<std::size_t>(joint.channels[1])].samples;
    const auto& tc = trial.channels[static_cast<std::size_t>(joint.channels[2])].samples;
    for (std::size_t f : jumps) {
      std::printf("      frame %4zu: steps of the filter %8.2f %8.2f %8.2f, of the best %8.2f "
                  "%8.2f %8.2f\n",
                  f, a[f] - a[f - 1], b[f] - b[f - 1], c[f] - c[f - 1], ta[f] - ta[f - 1],
                  tb[f] - tb[f - 1], tc[f] - tc[f - 1]);
    }
  }
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
  for (const JointRotation& joint : JointRotations(*clip)) {
    if (joint.channels.size() != 3) continue;
    const std::size_t keys_with = JointKeys(*with, joint);
    const std::size_t keys_without = JointKeys(*without, joint);
    if (keys_with == keys_without) continue;
    std::printf("  joint %s: keys with %zu, without %zu\n",
                clip->skeleton.joints[static_cast<std::size_t>(joint.joint)].name.c_str(),
                keys_with, keys_without);
    BestChoice(*clip, filtered, joint);
  }
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
