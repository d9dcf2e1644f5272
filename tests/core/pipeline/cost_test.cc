// The pipeline's up-front validation walk and cost prediction (cost.h): every step checked
// against the exact shape its input will have, and the work predicted from the options alone.
#include "tempokey/core/pipeline/cost.h"

#include <cmath>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/core/reduce/joint_bound.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

using ::testing::HasSubstr;

Clip ScalarClip(int channels, std::int64_t frames, double frame_time = 1.0 / 120.0) {
  Clip clip;
  clip.name = "scalars";
  clip.frame_time_seconds = frame_time;
  clip.frame_count = frames;
  for (int c = 0; c < channels; ++c) {
    Channel channel;
    channel.name = "c" + std::to_string(c);
    for (std::int64_t f = 0; f < frames; ++f) {
      channel.samples.push_back(std::sin(0.01 * static_cast<double>(f * (c + 1))));
    }
    clip.channels.push_back(std::move(channel));
  }
  return clip;
}

RetimeStep ConstantSpeed(double speed) {
  RetimeStep step;
  step.warp.domain = WarpDomain::kSpeedOverSource;
  step.warp.speed = {SpeedKnot{{0.0, false}, speed}};
  return step;
}

ReduceStep Paper(int iterations, double accuracy) {
  ReduceStep step;
  step.options.method = ReduceMethod::kPaper;
  step.options.paper.max_iterations = iterations;
  step.options.paper.accuracy = accuracy;
  return step;
}

ReduceStep Budget(std::int64_t keys) {
  ReduceStep step;
  step.options.tolerance.key_budget = keys;
  return step;
}

TEST(ValidatePipelineTest, ChainedRetimesOverTheOutputCapAreRefusedBeforeAnyResampling) {
  // Each retime at speed 0.01 makes the clip 100 times longer; only the second is over the cap.
  const Clip clip = ScalarClip(96, 994);
  const std::vector<PipelineStep> steps = {ConstantSpeed(0.01), ConstantSpeed(0.01)};

  const absl::Status status = ValidatePipeline(clip, steps);

  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(),
            "operation 2 (retime): the retimed clip would have 9930001 frames x 96 channels, over "
            "the limit of 200000000 samples");
}

TEST(ValidatePipelineTest, LaterRetimesAreCheckedAgainstWhatTheFirstProduces) {
  // A pin at frame 500 of the second retime lies outside a clip the first made 5 s long.
  const Clip clip = ScalarClip(2, 121);  // 1 s at 120 fps
  RetimeStep stretch = ConstantSpeed(0.2);
  RetimeStep pinned;
  pinned.options.pins = {Pin{{9.0, false}, 500}};
  const std::vector<PipelineStep> steps = {stretch, pinned};

  const absl::Status status = ValidatePipeline(clip, steps);

  EXPECT_EQ(status.message(),
            "operation 2 (retime): pin 1 (9s -> frame 500): outside the clip's source time "
            "0s..5s");
}

TEST(ValidatePipelineTest, KeyBudgetBelowTwoKeysPerChannelIsRefusedBeforeAnyFit) {
  const Clip clip = ScalarClip(96, 200);
  const std::vector<PipelineStep> steps = {Budget(2)};

  const absl::Status status = ValidatePipeline(clip, steps);

  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(),
            "operation 1 (reduce): tolerance.key_budget 2 is below the 192 keys any fit of 96 "
            "channels needs (2 per channel)");
  EXPECT_TRUE(ValidatePipeline(clip, std::vector<PipelineStep>{Budget(192)}).ok());
}

TEST(ValidatePipelineTest, BakeRateOutsideAFrameAnHourToOneHundredKilohertzIsRefused) {
  const Clip clip = ScalarClip(1, 10);
  const std::vector<PipelineStep> slow = {ReduceStep{}, BakeStep{FrameRate{1, 7200}}};
  const std::vector<PipelineStep> fast = {ReduceStep{}, BakeStep{FrameRate{200000, 1}}};

  EXPECT_EQ(ValidatePipeline(clip, slow).message(),
            "operation 2 (bake): frame rate 1/7200 is under the limit of one frame an hour");
  EXPECT_EQ(ValidatePipeline(clip, fast).message(),
            "operation 2 (bake): frame rate 200000 Hz is over the limit of 100000 Hz");
}

TEST(ValidatePipelineTest, TheFirstOperationAtFaultIsNamed) {
  const Clip clip = ScalarClip(1, 10);
  ReduceStep bad = Paper(0, 0.01);
  const std::vector<PipelineStep> steps = {bad, BakeStep{}, BakeStep{}};

  EXPECT_EQ(ValidatePipeline(clip, steps).message(),
            "operation 1 (reduce): paper.max_iterations must be in [1, 1000], got 0");
}

TEST(EstimatePipelineCostTest, PaperWorkGrowsWithPassesAndFrames) {
  const Clip short_clip = ScalarClip(1, 1000);
  const Clip long_clip = ScalarClip(1, 16000);

  const absl::StatusOr<PipelineCost> few = EstimatePipelineCost(short_clip, {{Paper(8, 0.01)}});
  const absl::StatusOr<PipelineCost> many =
      EstimatePipelineCost(short_clip, {{Paper(1000, 0.01)}});
  const absl::StatusOr<PipelineCost> longer =
      EstimatePipelineCost(long_clip, {{Paper(1000, 1e-300)}});

  ASSERT_TRUE(few.ok() && many.ok() && longer.ok());
  EXPECT_GT(many->seconds, 100.0 * few->seconds);
  EXPECT_GT(longer->seconds, 15.0 * many->seconds);
  EXPECT_EQ(longer->steps.size(), 1u);
  EXPECT_EQ(longer->steps[0].work, "reduce (paper): 1 channel x 16000 frames x up to 1000 passes");
  EXPECT_THAT(longer->Describe(),
              ::testing::MatchesRegex("predicted [0-9.]+ s of work \\(operation 1, reduce "
                                      "\\(paper\\): 1 channel x 16000 frames x up to 1000 "
                                      "passes: [0-9.]+ s\\)"));
}

TEST(EstimatePipelineCostTest, RetimeWorkFollowsTheOutputTheTimeMapGives) {
  const Clip clip = ScalarClip(10, 1000);

  const absl::StatusOr<PipelineCost> same = EstimatePipelineCost(clip, {{ConstantSpeed(1.0)}});
  const absl::StatusOr<PipelineCost> slow = EstimatePipelineCost(clip, {{ConstantSpeed(0.1)}});

  // What one knot adds (each step has one), known from a second knot that changes nothing.
  RetimeStep two_knots = ConstantSpeed(1.0);
  two_knots.warp.speed.push_back({.time = {1.0, false}, .speed = 1.0});
  const absl::StatusOr<PipelineCost> same_twice = EstimatePipelineCost(clip, {{two_knots}});

  ASSERT_TRUE(same.ok() && slow.ok() && same_twice.ok());
  EXPECT_EQ(slow->steps[0].work, "retime: 10 channels x (1000 source + 9991 output frames)");
  // (1000 + 9991) / (1000 + 1000) times the work, the knot's aside.
  const double knot = same_twice->seconds - same->seconds;
  constexpr double kRatioTolerance = 1e-9;  // a few products and sums of doubles
  EXPECT_NEAR((slow->seconds - knot) / (same->seconds - knot), 10991.0 / 2000.0,
              kRatioTolerance);
}

TEST(EstimatePipelineCostTest, EveryKnotKeyHoldAndPinAddsTheSameWorkToEitherMethod) {
  // Five items of each kind (with the one knot a speed curve needs), every warp the identity or
  // within a frame of it, so that every step has the same 121 output frames: only the items
  // tell the predictions apart, each adding the same.
  const Clip clip = ScalarClip(1, 121);
  constexpr double kInstantSeconds = 1e-9;  // a hold that adds an item but no output frame
  auto step = [](RetimeMethod method) {
    RetimeStep s = ConstantSpeed(1.0);
    s.options.method = method;
    return s;
  };
  const RetimeStep one = step(RetimeMethod::kExact);
  RetimeStep knots = one;
  RetimeStep keys = one;
  keys.warp.domain = WarpDomain::kTimeMapKeys;
  keys.warp.speed.clear();
  RetimeStep holds = one;
  RetimeStep pins = one;
  const RetimeStep paper_one = step(RetimeMethod::kPaper);
  RetimeStep paper_knots = paper_one;
  for (int k = 1; k <= 4; ++k) {
    const double t = 0.2 * k;
    knots.warp.speed.push_back({.time = {t, false}, .speed = 1.0});
    paper_knots.warp.speed.push_back({.time = {t, false}, .speed = 1.0});
    holds.warp.holds.push_back({.at = {t, false}, .duration_seconds = kInstantSeconds});
    pins.options.pins.push_back({.source = {24.0 * k, true}, .output_frame = 24 * k});
  }
  for (int k = 0; k <= 4; ++k) {
    keys.warp.keys.push_back({.output = {0.25 * k, false}, .source = {0.25 * k, false}});
  }
  auto seconds = [&](const RetimeStep& s) {
    const absl::StatusOr<PipelineCost> cost = EstimatePipelineCost(clip, {{s}});
    EXPECT_TRUE(cost.ok()) << cost.status();
    if (!cost.ok()) return 0.0;
    EXPECT_EQ(cost->steps[0].work, "retime: 1 channel x (121 source + 121 output frames)");
    return cost->seconds;
  };

  const double four_items = seconds(knots) - seconds(one);

  EXPECT_GT(four_items, 0.0);
  EXPECT_DOUBLE_EQ(seconds(keys) - seconds(one), four_items);
  EXPECT_DOUBLE_EQ(seconds(holds) - seconds(one), four_items);
  EXPECT_DOUBLE_EQ(seconds(pins) - seconds(one), four_items);
  EXPECT_DOUBLE_EQ(seconds(paper_knots) - seconds(paper_one), four_items);
}

TEST(EstimatePipelineCostTest, ALongWarpIsCostedEvenOnAShortClip) {
  // 100 000 knots (the limit) over a clip of 10 frames: the knots are all the work.
  // About what one knot took, measured at the limit (bench/cost_bench retime/10frames/knots100k:
  // 0.07-0.09 s for 100 000): the prediction must not be under it.
  constexpr double kMeasuredSecondsPerKnot = 1e-6;
  const Clip clip = ScalarClip(1, 10);
  RetimeStep step;
  step.warp.domain = WarpDomain::kSpeedOverSource;
  for (int k = 0; k < 100'000; ++k) {
    step.warp.speed.push_back({.time = {9.0 * k / 100'000, true}, .speed = 1.0 + 0.5 * (k % 2)});
  }

  const absl::StatusOr<PipelineCost> cost = EstimatePipelineCost(clip, {{step}});

  ASSERT_TRUE(cost.ok()) << cost.status();
  EXPECT_GE(cost->seconds, 100'000 * kMeasuredSecondsPerKnot);
  EXPECT_THAT(cost->steps[0].work,
              ::testing::EndsWith(" and 100000 knots, keys, holds and pins"));
}

TEST(EstimatePipelineCostTest, KeyBudgetSearchCountsItsFitsFromTheChannelsRanges) {
  const Clip clip = ScalarClip(4, 500);  // sines of range 2, bound 0.5: scale 4 covers them

  const absl::StatusOr<PipelineCost> plain = EstimatePipelineCost(clip, {{ReduceStep{}}});
  const absl::StatusOr<PipelineCost> budget = EstimatePipelineCost(clip, {{Budget(100)}});

  ASSERT_TRUE(plain.ok() && budget.ok());
  // 1 + max(19 halvings, 2 doublings) + 12 bisections.
  EXPECT_EQ(budget->steps[0].work, "reduce (tolerance): 4 channels x 500 frames x up to 32 fits "
                                   "(key budget)");
  EXPECT_GT(budget->seconds, 20.0 * plain->seconds);
}

// The fewest-keys search: 24-61 us a sample on the shared captures and the slowest inputs
// measured (README), against the usual fit's 0.1-0.5: costed at 120 us, 48 times the usual 2.5.
TEST(EstimatePipelineCostTest, TheFewestKeysSearchIsCostedAtItsOwnRate) {
  const Clip clip = ScalarClip(4, 500);
  ReduceStep fewest;
  fewest.options.tolerance.fewest_keys = true;

  const absl::StatusOr<PipelineCost> plain = EstimatePipelineCost(clip, {{ReduceStep{}}});
  const absl::StatusOr<PipelineCost> searched = EstimatePipelineCost(clip, {{fewest}});

  ASSERT_TRUE(plain.ok() && searched.ok());
  EXPECT_EQ(searched->steps[0].work, "reduce (tolerance, fewest keys): 4 channels x 500 frames");
  EXPECT_GT(searched->seconds, 10.0 * plain->seconds);
  EXPECT_GE(searched->seconds, 4 * 500 * 120e-6);
}

TEST(EstimatePipelineCostTest, EveryStepIsCostedOnTheShapeItReceives) {
  const Clip clip = ScalarClip(3, 121);
  const std::vector<PipelineStep> steps = {ConstantSpeed(0.5), ReduceStep{},
                                           BakeStep{FrameRate{240, 1}}, ConvertStep{true}};

  const absl::StatusOr<PipelineCost> cost = EstimatePipelineCost(clip, steps);

  ASSERT_TRUE(cost.ok()) << cost.status();
  ASSERT_EQ(cost->steps.size(), 4u);
  EXPECT_EQ(cost->steps[0].work, "retime: 3 channels x (121 source + 241 output frames)");
  EXPECT_EQ(cost->steps[1].work, "reduce (tolerance): 3 channels x 241 frames");
  EXPECT_EQ(cost->steps[2].work, "bake: 3 channels x 481 frames");
  EXPECT_EQ(cost->steps[3].work, "convert: 3 channels x 481 frames");
  double sum = 0.0;
  for (const StepCost& step : cost->steps) sum += step.seconds;
  EXPECT_DOUBLE_EQ(cost->seconds, sum);
}

TEST(EstimatePipelineCostTest, TheNoiseMethodIsCostedAsItself) {
  const Clip clip = ScalarClip(4, 500);
  ReduceStep noise;
  noise.options.method = ReduceMethod::kNoise;

  const absl::StatusOr<PipelineCost> cost = EstimatePipelineCost(clip, {{noise}});
  const absl::StatusOr<PipelineCost> paper = EstimatePipelineCost(clip, {{Paper(8, 0.01)}});

  ASSERT_TRUE(cost.ok() && paper.ok());
  EXPECT_EQ(cost->steps[0].work, "reduce (noise): 4 channels x 500 frames");
  // The noise method runs in microseconds a sample; the paper's passes take tens.
  EXPECT_LT(cost->seconds, 0.2 * paper->seconds);
}

// A reduction measures its world error by placing every joint and end site at every frame, for
// the source and for the fit: end sites, which carry no samples, cost that work too (a clip of
// three channels and 140 000 end sites ran 34 s under a limit of 20 s, costed from its samples).
TEST(EstimatePipelineCostTest, AReductionCountsTheWorldErrorOfEveryJointAndEndSite) {
  Clip clip = ScalarClip(3, 500);
  clip.skeleton.joints = {Joint{.name = "root", .parent = -1, .channels = {0, 1, 2}, .end_sites = {}}};
  for (Channel& channel : clip.channels) channel.joint = 0;
  Clip many_ends = clip;
  many_ends.skeleton.joints[0].end_sites.assign(1000, Vec3{0, 1, 0});
  ClipLimits limits;
  limits.max_samples = 500 * 1001;

  const absl::StatusOr<PipelineCost> few = EstimatePipelineCost(clip, {{ReduceStep{}}}, limits);
  const absl::StatusOr<PipelineCost> many =
      EstimatePipelineCost(many_ends, {{ReduceStep{}}}, limits);
  // Twice as many frames would place 1001 points at 1000 frames: over the limit.
  const absl::StatusOr<PipelineCost> slowed =
      EstimatePipelineCost(many_ends, {{ConstantSpeed(0.5), ReduceStep{}}}, limits);

  ASSERT_TRUE(few.ok() && many.ok()) << few.status() << many.status();
  // 1000 more points, placed at 500 frames twice, about 40 ns each.
  EXPECT_NEAR(many->seconds - few->seconds, 2.0 * 500 * 1000 * 40e-9, 1e-9);
  EXPECT_EQ(slowed.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(slowed.status().message()),
              HasSubstr("operation 1 (retime): the clip it makes has 1001 joints and end sites x "));
}

// What validation accepts must run: a joint bound below what positions can be computed to is
// refused here, against an upper bound on the skeleton's reach (twice the run's own floor), not
// when the reduction runs (the pipeline fuzzer found 4.15e-322 accepted, then refused).
TEST(EstimatePipelineCostTest, AJointBoundBelowTheRoundingOfPositionsIsRefusedBeforeAnyWork) {
  absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  ReduceStep tiny;
  tiny.options.tolerance.joint_tolerance = JointTolerance{.value = 1e-15};

  const absl::StatusOr<PipelineCost> cost = EstimatePipelineCost(*clip, {{tiny}});

  EXPECT_EQ(cost.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(cost.status().message()),
              HasSubstr("operation 1 (reduce): tolerance.joint_tolerance 1e-15 is below what "
                        "this clip's joint positions can be computed to"));
}

TEST(EstimatePipelineCostTest, RealCaptureWithDefaultsIsFarBelowAMinute) {
  absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();

  const absl::StatusOr<PipelineCost> tolerance = EstimatePipelineCost(*clip, {{ReduceStep{}}});
  const absl::StatusOr<PipelineCost> paper = EstimatePipelineCost(*clip, {{Paper(8, 0.01)}});

  ASSERT_TRUE(tolerance.ok() && paper.ok());
  EXPECT_LT(tolerance->seconds, 1.0);
  EXPECT_LT(paper->seconds, 60.0);
  EXPECT_GT(paper->seconds, tolerance->seconds);
}

// tempokey-server's default --max_job_cost_seconds (server/main.cc).
constexpr double kServerDefaultLimitSeconds = 60.0;

TEST(EstimatePipelineCostTest, ANoiseReductionOfARealCaptureFitsTheServersDefaultLimit) {
  // The capture slowed to a tenth: 9 931 frames (83 s at 120 fps) of 96 channels, which the
  // noise method reduces in about half a second. Costed as the paper's method, it was refused
  // by a server at its default work limit.
  absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  ReduceStep noise;
  noise.options.method = ReduceMethod::kNoise;
  const std::vector<PipelineStep> steps = {ConstantSpeed(0.1), noise};

  const absl::StatusOr<PipelineCost> cost = EstimatePipelineCost(*clip, steps);

  ASSERT_TRUE(cost.ok()) << cost.status();
  EXPECT_EQ(cost->steps[1].work, "reduce (noise): 96 channels x 9931 frames");
  EXPECT_LT(cost->seconds, kServerDefaultLimitSeconds);
}

}  // namespace
}  // namespace tempokey::core
