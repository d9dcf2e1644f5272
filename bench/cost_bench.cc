// The cost model (core/pipeline/cost.h) against real runs: for pipelines that stress each inner
// loop (the paper's DP passes once steps are fractional, the tolerance fit on white noise and on
// long calm motion, the noise method, rotation-aware retimes, wide smoothing, baking), the
// predicted seconds next to the measured ones on this machine, one core. The model's constants
// are chosen so that the worst workload of each kind is predicted at or above its measured time
// (ratio >= 1) and typical ones are over-predicted by a bounded factor.
//
//   cost_bench [filter]      runs every workload whose name contains `filter`; those named
//                            slow/... (minutes) only when `filter` starts with slow/
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/pipeline/cost.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::core {
namespace {

Clip NoiseClip(int channels, std::int64_t frames, double amplitude, ChannelKind kind,
               double frame_time = 1.0 / 120.0) {
  Clip clip;
  clip.name = "noise";
  clip.frame_time_seconds = frame_time;
  clip.frame_count = frames;
  std::mt19937_64 random(7);
  std::normal_distribution<double> noise(0.0, amplitude);
  for (int c = 0; c < channels; ++c) {
    Channel channel;
    channel.kind = kind;
    channel.name = absl::StrCat("c", c);
    channel.samples.resize(static_cast<std::size_t>(frames));
    for (double& v : channel.samples) v = noise(random);
    clip.channels.push_back(std::move(channel));
  }
  return clip;
}

struct Workload {
  std::string name;
  const Clip* clip;
  std::vector<PipelineStep> steps;
};

ReduceStep Paper(int iterations, double accuracy, double sigma = 2.0) {
  ReduceStep step;
  step.options.method = ReduceMethod::kPaper;
  step.options.paper.max_iterations = iterations;
  step.options.paper.accuracy = accuracy;
  step.options.paper.smoothing_sigma_frames = sigma;
  return step;
}

ReduceStep Tolerance(double bound, std::optional<std::int64_t> budget = std::nullopt) {
  ReduceStep step;
  step.options.tolerance.max_rotation_error_degrees = bound;
  step.options.tolerance.max_position_error = bound;
  step.options.tolerance.max_scalar_error = bound;
  step.options.tolerance.key_budget = budget;
  return step;
}

ReduceStep Noise() {
  ReduceStep step;
  step.options.method = ReduceMethod::kNoise;
  return step;
}

ReduceStep JointBound(double percent_of_height) {
  ReduceStep step;
  step.options.tolerance.joint_tolerance = JointTolerance{percent_of_height, true};
  return step;
}

// Slow motion well within a bound of 0.5, with Gaussian jitter of `jitter`: the tolerance fit
// merges its keys into segments as long as a removal may make them (kMaxMergedSegmentFrames),
// the work of every merge growing with them; jitter near the bound makes more of the merges
// slide and reweight before they fit.
Clip CalmClip(std::int64_t frames, double jitter = 0.0) {
  Clip clip;
  clip.name = "calm";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = frames;
  Channel channel;
  channel.kind = ChannelKind::kXRotation;
  channel.name = "calm";
  channel.samples.resize(static_cast<std::size_t>(frames));
  std::mt19937_64 random(5);
  std::normal_distribution<double> noise(0.0, jitter);
  for (std::int64_t f = 0; f < frames; ++f) {
    channel.samples[static_cast<std::size_t>(f)] =
        0.2 * std::sin(2.0 * M_PI * static_cast<double>(f) / 150'000.0) +
        (jitter > 0.0 ? noise(random) : 0.0);
  }
  clip.channels.push_back(std::move(channel));
  return clip;
}

RetimeStep Speed(double speed, ResampleFilter filter = ResampleFilter::kTent,
                 RetimeMethod method = RetimeMethod::kExact) {
  RetimeStep step;
  step.warp.domain = WarpDomain::kSpeedOverSource;
  step.warp.speed = {SpeedKnot{{0.0, false}, speed}};
  step.options.filter = filter;
  step.options.method = method;
  return step;
}

RetimeStep Ramp(RetimeMethod method) {
  RetimeStep step;
  step.warp.domain = WarpDomain::kSpeedOverSource;
  step.warp.speed = {SpeedKnot{{0.0, false}, 0.25}, SpeedKnot{{8.0, false}, 4.0}};
  step.options.method = method;
  return step;
}

// The limit of 100 000 speed knots (alternating speeds 1 and 1.5) over `clip`, with as many
// pins (each source frame k on output frame 2k) and holds when asked: the time map's own work,
// all of it on a clip of a few frames.
RetimeStep LongWarp(const Clip& clip, bool pins, bool holds) {
  constexpr int kItems = 100'000;
  const auto last = static_cast<double>(clip.frame_count - 1);
  RetimeStep step;
  step.warp.domain = WarpDomain::kSpeedOverSource;
  for (int k = 0; k < kItems; ++k) {
    step.warp.speed.push_back(SpeedKnot{{last * k / kItems, true}, 1.0 + 0.5 * (k % 2)});
    if (holds) step.warp.holds.push_back(Hold{{last * (k + 0.5) / kItems, true}, 1e-3});
  }
  for (std::int64_t f = 1; pins && f < clip.frame_count - 1; ++f) {
    step.options.pins.push_back(Pin{{static_cast<double>(f), true}, 2 * f});
  }
  return step;
}

int Run(const std::string& filter) {
  const std::string cmu_path = std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/cmu/131_01.bvh";
  absl::StatusOr<Clip> cmu = ReadBvhFile(cmu_path);
  if (!cmu.ok()) {
    std::fprintf(stderr, "error: %s\n", std::string(cmu.status().message()).c_str());
    return 1;
  }
  const Clip noise_16k = NoiseClip(1, 16000, 10.0, ChannelKind::kXRotation);
  const Clip noise_4k = NoiseClip(1, 4000, 10.0, ChannelKind::kXRotation);
  const Clip noise_1m = NoiseClip(1, 1'000'000, 10.0, ChannelKind::kXPosition);
  const Clip noise_100k = NoiseClip(1, 100'000, 10.0, ChannelKind::kXPosition);
  const Clip calm_1m = CalmClip(1'000'000);
  const Clip jittery_calm_1m = CalmClip(1'000'000, 0.15);
  RetimeStep to_30fps;
  to_30fps.options.output_rate = FrameRate{30, 1};
  const Clip short_clip = NoiseClip(1, 10, 1.0, ChannelKind::kXRotation);
  const Clip pinned_clip = NoiseClip(1, 100'001, 1.0, ChannelKind::kXRotation);

  const std::vector<Workload> workloads = {
      {"paper/noise16k/30passes/acc1e-300", &noise_16k, {Paper(30, 1e-300)}},
      {"slow/paper/noise16k/1000passes/acc1e-300", &noise_16k, {Paper(1000, 1e-300)}},
      {"paper/noise4k/100passes/acc1e-300", &noise_4k, {Paper(100, 1e-300)}},
      {"paper/cmu/default", &*cmu, {Paper(8, 0.01)}},
      {"paper/cmu/50passes", &*cmu, {Paper(50, 0.01)}},
      {"paper/noise100k/sigma1000/1pass", &noise_100k, {Paper(1, 1e6, 1000.0)}},
      {"tolerance/cmu/0.5", &*cmu, {Tolerance(0.5)}},
      {"tolerance/noise1m/0.5", &noise_1m, {Tolerance(0.5)}},
      {"tolerance/noise1m/1e-9", &noise_1m, {Tolerance(1e-9)}},
      {"tolerance/cmu/budget3000", &*cmu, {Tolerance(0.5, 3000)}},
      {"tolerance/noise100k/budget1000", &noise_100k, {Tolerance(0.5, 1000)}},
      {"tolerance/calm1m/0.5", &calm_1m, {Tolerance(0.5)}},
      {"tolerance/calm1m+jitter0.15/0.5", &jittery_calm_1m, {Tolerance(0.5)}},
      {"tolerance/cmu/joint0.05%", &*cmu, {JointBound(0.05)}},
      {"tolerance/cmu-slowed40x/0.5", &*cmu, {Speed(0.025), Tolerance(0.5)}},
      {"noise/noise1m", &noise_1m, {Noise()}},
      {"noise/calm1m", &calm_1m, {Noise()}},
      {"noise/cmu", &*cmu, {Noise()}},
      {"retime/cmu/slow0.5", &*cmu, {Speed(0.5)}},
      {"retime/cmu/fast3", &*cmu, {Speed(3.0)}},
      {"retime/cmu/fast3/lanczos3", &*cmu, {Speed(3.0, ResampleFilter::kLanczos3)}},
      {"retime/cmu/slow0.1/cubic", &*cmu, {Speed(0.1, ResampleFilter::kCubic)}},
      {"retime/cmu/30fps", &*cmu, {to_30fps}},
      {"retime/cmu/ramp/paper", &*cmu, {Ramp(RetimeMethod::kPaper)}},
      {"retime/10frames/knots100k", &short_clip, {LongWarp(short_clip, false, false)}},
      {"retime/10frames/knots100k+holds100k", &short_clip, {LongWarp(short_clip, false, true)}},
      {"retime/100kframes/knots100k+pins100k", &pinned_clip, {LongWarp(pinned_clip, true, false)}},
      {"reduce+bake/cmu/paper", &*cmu, {Paper(8, 0.01), BakeStep{FrameRate{1000, 1}}}},
      {"convert/cmu", &*cmu, {ConvertStep{true}}},
      {"convert/cmu/euler_filter",
       &*cmu,
       {ConvertStep{.wrap_rotations = true, .euler_filter = true}}},
  };
  std::printf("%-40s %12s %12s %8s\n", "workload", "predicted s", "measured s", "ratio");
  for (const Workload& w : workloads) {
    // Workloads named slow/... run only when asked for by name (minutes each).
    if (w.name.find(filter) == std::string::npos) continue;
    if (w.name.rfind("slow/", 0) == 0 && filter.rfind("slow/", 0) != 0) continue;
    absl::StatusOr<PipelineCost> cost = EstimatePipelineCost(*w.clip, w.steps);
    if (!cost.ok()) {
      std::printf("%-40s error: %s\n", w.name.c_str(), std::string(cost.status().message()).c_str());
      continue;
    }
    const auto start = std::chrono::steady_clock::now();
    absl::StatusOr<PipelineResult> result = RunPipeline(*w.clip, w.steps);
    const double measured =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!result.ok()) {
      std::printf("%-40s run error: %s\n", w.name.c_str(),
                  std::string(result.status().message()).c_str());
      continue;
    }
    std::printf("%-40s %12.4f %12.4f %8.2f   %s\n", w.name.c_str(), cost->seconds, measured,
                cost->seconds / measured, cost->Describe().c_str());
    std::fflush(stdout);
  }
  return 0;
}

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) { return tempokey::core::Run(argc > 1 ? argv[1] : ""); }
