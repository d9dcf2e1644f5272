// How long a stop request takes to end the slowest work core does (one core, this machine): each
// pipeline below runs on a thread, a stop is requested after a delay (so it lands inside a
// channel's inner loops), and the time from the request to RunPipeline's return is printed, for
// several delays. The target is ~0.1 s; these are the figures behind the server's cancel,
// Process-disconnect and drain-deadline behaviour.
//
//   cancel_bench [filter]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <future>
#include <memory>
#include <random>
#include <stop_token>
#include <string>
#include <thread>
#include <utility>
#include <variant>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "tempokey/core/io/file_formats.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/core/reduce/reduce.h"

namespace tempokey::core {
namespace {

using Clock = std::chrono::steady_clock;

Clip NoiseClip(int channels, std::int64_t frames, bool rotations) {
  Clip clip;
  clip.name = "noise";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = frames;
  std::mt19937_64 random(5);
  std::normal_distribution<double> noise(0.0, 10.0);
  if (rotations) {
    Joint joint;
    joint.name = "J";
    clip.skeleton.joints.push_back(joint);
  }
  for (int c = 0; c < channels; ++c) {
    Channel channel;
    if (rotations) {
      channel.joint = 0;
      channel.kind = static_cast<ChannelKind>(static_cast<int>(ChannelKind::kZRotation) - c % 3);
      clip.skeleton.joints[0].channels.push_back(c);
    } else {
      channel.name = absl::StrCat("c", c);
    }
    channel.samples.resize(static_cast<std::size_t>(frames));
    for (double& v : channel.samples) v = noise(random);
    clip.channels.push_back(std::move(channel));
  }
  return clip;
}

// A slow sine (amplitude 10) under Gaussian noise of sigma 0.1, one scalar channel: the noise
// method smooths it block by block with levels far from the extremes.
Clip NoisySineClip(std::int64_t frames) {
  Clip clip = NoiseClip(1, frames, false);
  std::mt19937_64 random(1);
  std::normal_distribution<double> noise(0.0, 0.1);
  std::vector<double>& samples = clip.channels[0].samples;
  for (std::size_t f = 0; f < samples.size(); ++f) {
    samples[f] = 10.0 * std::sin(static_cast<double>(f) * 0.01) + noise(random);
  }
  return clip;
}

// One joint turning slowly about three axes (a few degrees a second): calm motion whose
// rotation fits merge segments up to their length limit.
Clip CalmJointClip(std::int64_t frames) {
  Clip clip = NoiseClip(3, frames, true);
  for (int c = 0; c < 3; ++c) {
    std::vector<double>& samples = clip.channels[static_cast<std::size_t>(c)].samples;
    for (std::size_t f = 0; f < samples.size(); ++f) {
      samples[f] = 40.0 * std::sin(static_cast<double>(f) * (0.0007 + 0.0002 * c) + c);
    }
  }
  return clip;
}

// A chain of `joints` joints, each turning slowly about its three axes: a skeleton whose world
// error (forward kinematics of every joint at every frame) a reduction measures.
Clip ChainClip(int joints, std::int64_t frames) {
  Clip clip = NoiseClip(3 * joints, frames, true);
  clip.skeleton.joints.assign(static_cast<std::size_t>(joints), Joint{});
  for (int j = 0; j < joints; ++j) {
    Joint& joint = clip.skeleton.joints[static_cast<std::size_t>(j)];
    joint.name = absl::StrCat("J", j);
    joint.parent = j - 1;
    joint.offset = {0.0, 10.0, 0.0};
    for (int a = 0; a < 3; ++a) {
      const int c = 3 * j + a;
      joint.channels.push_back(c);
      Channel& channel = clip.channels[static_cast<std::size_t>(c)];
      channel.joint = j;
      std::vector<double>& samples = channel.samples;
      for (std::size_t f = 0; f < samples.size(); ++f) {
        samples[f] = 30.0 * std::sin(static_cast<double>(f) * (0.001 + 0.0001 * a) + j);
      }
    }
  }
  clip.skeleton.joints.back().end_sites.push_back({0.0, 10.0, 0.0});
  return clip;
}

struct Workload {
  std::string name;
  // The work, stopped by the token: a pipeline on a clip, or (export) a file formatted.
  std::function<absl::Status(std::stop_token)> run;
  // When the stop is requested, ms after the start.
  std::vector<int> delays_ms = {50, 200, 500};
  // Whether the row also times the whole work once, not stopped.
  bool time_whole = false;
};

Workload PipelineWorkload(std::string name, Clip clip, std::vector<PipelineStep> steps,
                          std::vector<int> delays_ms = {50, 200, 500}) {
  auto shared = std::make_shared<const Clip>(std::move(clip));
  return {std::move(name),
          [shared, steps = std::move(steps)](std::stop_token stop) {
            return RunPipeline(*shared, steps, {}, std::move(stop)).status();
          },
          std::move(delays_ms)};
}

// One joint with three position and three rotation channels of noise, and its curves keyed at
// every frame (what a reduction of noise gives, without the fit's time): a keyed glTF's
// translation sampler then has a key per frame, and its rotation a fit on noise.
std::pair<Clip, KeyedClip> NoisyJointKeyedEveryFrame(std::int64_t frames) {
  Clip clip = NoiseClip(6, frames, true);
  KeyedClip keyed;
  for (int c = 0; c < 6; ++c) {
    Channel& channel = clip.channels[static_cast<std::size_t>(c)];
    channel.kind = static_cast<ChannelKind>(c);  // X, Y, Z position, then X, Y, Z rotation
    Curve curve;
    curve.keys.reserve(channel.samples.size());
    for (std::size_t f = 0; f < channel.samples.size(); ++f) {
      Key key;
      key.time_seconds = static_cast<double>(f) * clip.frame_time_seconds;
      key.value = channel.samples[f];
      curve.keys.push_back(key);
    }
    keyed.curves.push_back(std::move(curve));
  }
  keyed.layout = clip;
  for (Channel& channel : keyed.layout.channels) channel.samples.clear();
  return {std::move(clip), std::move(keyed)};
}

// ExportFile's keyed glb of `keyed`, the curves of `source`: every joint's rotation fitted again.
Workload GltfExportWorkload(std::string name, Clip source_clip, KeyedClip keyed_clip,
                            std::vector<int> delays_ms = {50, 200, 500}) {
  auto source = std::make_shared<const Clip>(std::move(source_clip));
  auto keyed = std::make_shared<const std::variant<Clip, KeyedClip>>(std::move(keyed_clip));
  return {std::move(name),
          [source, keyed](std::stop_token stop) {
            return FormatOutput(*keyed, *FindExportFormat("glb"), {},
                                {.clip = source.get(), .max_rotation_error_degrees = 0.5},
                                std::move(stop))
                .status();
          },
          std::move(delays_ms), /*time_whole=*/true};
}

// ExportFile's keyed glb of a reduction of `clip`.
Workload ReducedGltfExportWorkload(std::string name, Clip clip) {
  KeyedClip keyed = ReduceKeys(clip, {})->keyed;
  return GltfExportWorkload(std::move(name), std::move(clip), std::move(keyed));
}

int Run(const std::string& filter) {
  ReduceStep paper;
  paper.options.method = ReduceMethod::kPaper;
  paper.options.paper.max_iterations = 1000;
  paper.options.paper.accuracy = 1e-300;
  ReduceStep smooth_only = paper;
  smooth_only.options.paper.smoothing_sigma_frames = 1000.0;
  smooth_only.options.paper.max_iterations = 1;
  ReduceStep clip_aligned;
  clip_aligned.options.tolerance.pose_alignment = PoseAlignment::kClip;
  RetimeStep lanczos;
  lanczos.warp.domain = WarpDomain::kSpeedOverSource;
  lanczos.warp.speed = {SpeedKnot{{0.0, false}, 3.0}};
  lanczos.options.filter = ResampleFilter::kLanczos3;
  RetimeStep paper_retime;
  paper_retime.warp.domain = WarpDomain::kSpeedOverSource;
  paper_retime.warp.speed = {SpeedKnot{{0.0, false}, 0.5}, SpeedKnot{{10000.0, false}, 0.9}};
  paper_retime.options.method = RetimeMethod::kPaper;
  ReduceStep noise;
  noise.options.method = ReduceMethod::kNoise;
  noise.options.noise.position_sigma = 0.1;
  ReduceStep two_keys;
  two_keys.options.tolerance.max_scalar_error = 1e9;

  std::vector<Workload> workloads;
  workloads.push_back(
      PipelineWorkload("paper fit, 1 x 16000 frames, 1000 passes, accuracy 1e-300",
                       NoiseClip(1, 16000, false), {paper}));
  workloads.push_back(PipelineWorkload("paper smoothing, 1 x 1M frames, sigma 1000",
                                       NoiseClip(1, 1'000'000, false), {smooth_only}));
  workloads.push_back(PipelineWorkload("tolerance fit, 1 x 4M frames of noise",
                                       NoiseClip(1, 4'000'000, false), {ReduceStep{}}));
  workloads.push_back(PipelineWorkload("noise fit, 1 x 1M frames of a noisy sine, sigma 0.1",
                                       NoisySineClip(1'000'000), {noise}));
  workloads.push_back(PipelineWorkload("tolerance fit, pose-aligned clip, 64 x 60000 frames",
                                       NoiseClip(64, 60'000, false), {clip_aligned}));
  workloads.push_back(PipelineWorkload("retime lanczos3 x3, rotation-aware joint, 3 x 3M frames",
                                       NoiseClip(3, 3'000'000, true), {lanczos}));
  // The longest clip the default limits admit, compressed by 1.3: the stops land in the
  // resampling plan (a few seconds), the rotation schedule made from it, the joint's conversions
  // before its first batch, or its batches.
  RetimeStep lanczos_long = lanczos;
  lanczos_long.warp.speed = {SpeedKnot{{0.0, false}, 1.3}};
  workloads.push_back(
      PipelineWorkload("retime lanczos3 x1.3, rotation-aware joint, 3 x 10M frames (2-7 s)",
                       NoiseClip(3, 10'000'000, true), {lanczos_long},
                       {2000, 3000, 3500, 4000, 5000, 7000}));
  workloads.push_back(PipelineWorkload("retime paper method, 1 x 4M frames",
                                       NoiseClip(1, 4'000'000, false), {paper_retime}));
  workloads.push_back(PipelineWorkload("bake, 1 channel to 10M frames",
                                       NoiseClip(1, 83'000, false),
                                       {two_keys, BakeStep{FrameRate{100000, 1}}}));
  // The world error's forward kinematics: the source placed first (about 0.4 s), before any fit.
  workloads.push_back(PipelineWorkload("reduce, world error of a 36-joint chain, 400000 frames",
                                       ChainClip(36, 400'000), {ReduceStep{}}, {20, 100, 250}));
  // ExportFile's work for a reduce job of this clip (the reduction itself about 0.5 s).
  workloads.push_back(ReducedGltfExportWorkload(
      "export keyed glb, calm joint, 3 x 400000 frames (refits)", CalmJointClip(400'000)));
  // Stops land in the translation sampler's times and keys (about 0.5 s), then in the rotation's
  // checks, fits and error passes.
  auto [noisy, noisy_keyed] = NoisyJointKeyedEveryFrame(1'000'000);
  workloads.push_back(GltfExportWorkload(
      "export keyed glb, noisy joint keyed every frame, 6 x 1M (10 ms-2 s)", std::move(noisy),
      std::move(noisy_keyed), {10, 50, 200, 500, 1000, 2000}));

  std::printf("%-60s %s\n", "work",
              "stop -> return, ms (stop requested after 50 / 200 / 500 ms, or as the row says)");
  for (const Workload& w : workloads) {
    if (w.name.find(filter) == std::string::npos) continue;
    std::string row;
    double worst = 0.0;
    for (int delay : w.delays_ms) {
      std::stop_source stop;
      std::future<absl::Status> run =
          std::async(std::launch::async, [&] { return w.run(stop.get_token()); });
      const bool finished_early =
          run.wait_for(std::chrono::milliseconds(delay)) == std::future_status::ready;
      const Clock::time_point requested = Clock::now();
      stop.request_stop();
      const absl::Status result = run.get();
      const double ms = std::chrono::duration<double, std::milli>(Clock::now() - requested).count();
      if (finished_early) {
        absl::StrAppend(&row, "  (done before the stop)");
        continue;
      }
      if (result.code() != absl::StatusCode::kCancelled) {
        absl::StrAppend(&row, "  NOT CANCELLED: ", result.ToString());
        continue;
      }
      worst = std::max(worst, ms);
      absl::StrAppend(&row, absl::StrFormat("  %7.2f", ms));
    }
    if (w.time_whole) {
      const Clock::time_point start = Clock::now();
      const absl::Status whole = w.run({});
      absl::StrAppend(&row, absl::StrFormat(
                                "   (not stopped: %.2f s, %s)",
                                std::chrono::duration<double>(Clock::now() - start).count(),
                                whole.ok() ? "ok" : whole.ToString()));
    }
    std::printf("%-60s%s   worst %.2f ms\n", w.name.c_str(), row.c_str(), worst);
    std::fflush(stdout);
  }
  return 0;
}

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) { return tempokey::core::Run(argc > 1 ? argv[1] : ""); }
