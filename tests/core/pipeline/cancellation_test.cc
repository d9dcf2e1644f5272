// Cancellation reaches inside a channel's work: a stop requested once a long step has begun ends
// it with kCancelled, where checks between channels alone would let a one-channel step run to
// completion (tens of seconds for the paper's fit below). The step signals that it has begun
// through the pipeline's progress callback, which runs right before the step; the stop is
// requested only then, so what these tests pin is the outcome (CANCELLED, never a finished
// result), not a duration. How long the stop takes to be seen is printed, not asserted
// (bench/cancel_bench measures it).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <future>
#include <random>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::core {
namespace {

Clip NoiseClip(int channels, std::int64_t frames, ChannelKind kind) {
  Clip clip;
  clip.name = "noise";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = frames;
  std::mt19937_64 random(3);
  std::normal_distribution<double> noise(0.0, 10.0);
  if (IsRotation(kind) || IsPosition(kind)) {
    Joint joint;
    joint.name = "J";
    clip.skeleton.joints.push_back(std::move(joint));
  }
  for (int c = 0; c < channels; ++c) {
    Channel channel;
    channel.kind = kind;
    if (!clip.skeleton.empty()) {
      channel.joint = 0;
      clip.skeleton.joints[0].channels.push_back(c);
      // A joint's three rotations in quaternion mode (the slow retime path).
      channel.kind = static_cast<ChannelKind>(static_cast<int>(kind) + c % 3);
    } else {
      channel.name = "c" + std::to_string(c);
    }
    channel.samples.resize(static_cast<std::size_t>(frames));
    for (double& v : channel.samples) v = noise(random);
    clip.channels.push_back(std::move(channel));
  }
  return clip;
}

// Runs `steps` on `clip`, requesting a stop as soon as the last step reports its start, and
// returns the pipeline's status. Prints how long the stop took to be seen.
absl::Status RunAndStopWhenTheLastStepBegins(const Clip& clip,
                                             const std::vector<PipelineStep>& steps) {
  std::stop_source stop;
  std::chrono::steady_clock::time_point requested;
  const std::string last_stage(StepName(steps.back()));
  const std::size_t last = steps.size() - 1;
  const double last_start = static_cast<double>(last) / static_cast<double>(steps.size());
  ProgressFn progress = [&](double fraction, std::string_view stage) {
    if (stage == last_stage && fraction == last_start && !stop.stop_requested()) {
      requested = std::chrono::steady_clock::now();
      stop.request_stop();
    }
  };
  // The stop is requested on the pipeline's own thread, right before the step's work: the
  // step's first look at the token sees it. A second thread then repeats it while the step is
  // under way (a stop from a cancel call arrives while work is in progress).
  std::future<absl::StatusOr<PipelineResult>> run = std::async(std::launch::async, [&] {
    return RunPipeline(clip, steps, progress, stop.get_token());
  });
  const absl::StatusOr<PipelineResult> result = run.get();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - requested).count();
  std::printf("stop to return: %.4f s\n", seconds);
  return result.status();
}

TEST(CancellationTest, PaperFitOfOneLongChannelStopsInsideTheChannel) {
  // 1000 passes at accuracy 1e-300 on 16000 frames: about half a minute of work uncancelled.
  const Clip clip = NoiseClip(1, 16000, ChannelKind::kScalar);
  ReduceStep reduce;
  reduce.options.method = ReduceMethod::kPaper;
  reduce.options.paper.max_iterations = 1000;
  reduce.options.paper.accuracy = 1e-300;

  const absl::Status status = RunAndStopWhenTheLastStepBegins(clip, {ConvertStep{}, reduce});

  EXPECT_EQ(status.code(), absl::StatusCode::kCancelled) << status;
}

TEST(CancellationTest, ToleranceFitOfOneLongNoisyChannelStops) {
  const Clip clip = NoiseClip(1, 1'000'000, ChannelKind::kScalar);

  const absl::Status status = RunAndStopWhenTheLastStepBegins(clip, {ConvertStep{}, ReduceStep{}});

  EXPECT_EQ(status.code(), absl::StatusCode::kCancelled) << status;
}

TEST(CancellationTest, RotationAwareRetimeOfALongJointStops) {
  const Clip clip = NoiseClip(3, 2'000'000, ChannelKind::kXRotation);
  RetimeStep retime;
  retime.warp.domain = WarpDomain::kSpeedOverSource;
  retime.warp.speed = {SpeedKnot{{0.0, false}, 3.0}};
  retime.options.filter = ResampleFilter::kLanczos3;

  const absl::Status status = RunAndStopWhenTheLastStepBegins(clip, {ConvertStep{}, retime});

  EXPECT_EQ(status.code(), absl::StatusCode::kCancelled) << status;
}

TEST(CancellationTest, BakeOfALongChannelStops) {
  const Clip clip = NoiseClip(1, 10'000, ChannelKind::kScalar);
  ReduceStep reduce;
  reduce.options.tolerance.max_scalar_error = 1e9;  // two keys: the reduce is instant
  // Baked at 100 kHz: 8.3 million samples.
  const std::vector<PipelineStep> steps = {reduce, BakeStep{FrameRate{100000, 1}}};

  const absl::Status status = RunAndStopWhenTheLastStepBegins(clip, steps);

  EXPECT_EQ(status.code(), absl::StatusCode::kCancelled) << status;
}

TEST(CancellationTest, StopBeforeAnyStepEndsTheRunAtOnce) {
  const Clip clip = NoiseClip(2, 100, ChannelKind::kScalar);
  std::stop_source stop;
  stop.request_stop();

  const absl::StatusOr<PipelineResult> result =
      RunPipeline(clip, std::vector<PipelineStep>{ReduceStep{}}, {}, stop.get_token());

  EXPECT_EQ(result.status().code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(result.status().message(), "cancelled");
}

}  // namespace
}  // namespace tempokey::core
