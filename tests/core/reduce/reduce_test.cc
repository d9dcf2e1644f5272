#include "tempokey/core/reduce/reduce.h"
#include "tests/core/reduce/reduce_invalid_cases.h"

#include <algorithm>
#include <cmath>
#include <stop_token>
#include <string>
#include <vector>

#include "gtest/gtest.h"

namespace tempokey::core {
namespace {

// Channels below are written with designated initializers naming only what matters.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

Clip ScalarClip(std::vector<std::vector<double>> channels, double frame_time = 1.0 / 30.0) {
  Clip clip;
  clip.name = "test";
  clip.frame_time_seconds = frame_time;
  clip.frame_count = static_cast<std::int64_t>(channels.front().size());
  for (std::size_t c = 0; c < channels.size(); ++c) {
    clip.channels.push_back(Channel{.joint = -1, .kind = ChannelKind::kScalar,
                                    .name = "c" + std::to_string(c),
                                    .samples = std::move(channels[c])});
  }
  return clip;
}

ReduceOptions PaperOptions() {
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  return options;
}

TEST(ValidateReduceOptionsTest, MalformedPaperParamsAreNamed) {
  for (const reduce_cases::BadPaperParams& c : reduce_cases::BadPaperParamsTable()) {
    ReduceOptions options = PaperOptions();
    c.mutate(options.paper);

    const absl::Status status = ValidateReduceOptions(options);

    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << c.message;
    EXPECT_EQ(status.message(), c.message);
  }
}

TEST(ValidateReduceOptionsTest, MalformedToleranceParamsAreNamed) {
  ReduceOptions zero_bound;
  zero_bound.tolerance.max_rotation_error_degrees = 0;
  ReduceOptions nan_bound;
  nan_bound.tolerance.max_position_error = NAN;
  ReduceOptions infinite_bound;
  infinite_bound.tolerance.max_scalar_error = INFINITY;
  ReduceOptions tiny_budget;
  tiny_budget.tolerance.key_budget = 1;

  EXPECT_EQ(ValidateReduceOptions(zero_bound).message(),
            "tolerance.max_rotation_error_degrees must be > 0, got 0");
  EXPECT_EQ(ValidateReduceOptions(nan_bound).message(),
            "tolerance.max_position_error must be > 0, got NaN");
  EXPECT_EQ(ValidateReduceOptions(infinite_bound).message(),
            "tolerance.max_scalar_error must be in [1e-09, 1e+09], got +infinity");
  EXPECT_EQ(ValidateReduceOptions(tiny_budget).message(),
            "tolerance.key_budget must be >= 2 when set, got 1");
  EXPECT_TRUE(ValidateReduceOptions(ReduceOptions{}).ok());
  EXPECT_TRUE(ValidateReduceOptions(PaperOptions()).ok());
}

// A joint "Arm" with a position and two rotations, and a plain scalar channel: 300 frames of
// smooth motion at 30 fps.
Clip MixedClip() {
  Clip clip;
  clip.name = "mixed";
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = 300;
  clip.skeleton.joints = {Joint{.name = "Arm", .parent = -1, .channels = {0, 1, 2}}};
  std::vector<double> position(300), rotation_z(300), rotation_x(300), scalar(300);
  for (int f = 0; f < 300; ++f) {
    const double t = f / 30.0;
    position[f] = 12.0 * std::sin(0.9 * t) + 0.3 * t * t;
    rotation_z[f] = 80.0 * std::sin(2.1 * t + 0.3) + 20.0 * std::cos(5.0 * t);
    rotation_x[f] = 35.0 * std::sin(0.7 * t);
    scalar[f] = std::exp(-0.2 * t) * std::cos(3.0 * t);
  }
  clip.channels = {Channel{.joint = 0, .kind = ChannelKind::kXPosition, .samples = position},
                   Channel{.joint = 0, .kind = ChannelKind::kZRotation, .samples = rotation_z},
                   Channel{.joint = 0, .kind = ChannelKind::kXRotation, .samples = rotation_x},
                   Channel{.joint = -1, .kind = ChannelKind::kScalar, .name = "blend",
                           .samples = scalar}};
  return clip;
}

ReduceOptions ToleranceOptions(double rotation, double position, double scalar) {
  ReduceOptions options;
  options.tolerance.max_rotation_error_degrees = rotation;
  options.tolerance.max_position_error = position;
  options.tolerance.max_scalar_error = scalar;
  return options;
}

TEST(ReduceKeysTest, ToleranceKeepsEachKindWithinItsOwnBound) {
  const Clip clip = MixedClip();
  const ReduceOptions options = ToleranceOptions(0.2, 0.05, 0.001);

  const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);

  ASSERT_TRUE(result.ok()) << result.status();
  const std::vector<double> bounds = {0.05, 0.2, 0.2, 0.001};
  for (const ChannelReduction& channel : result->report.channels) {
    EXPECT_LE(channel.max_error, bounds[channel.channel_index]) << channel.channel_index;
    EXPECT_LT(channel.key_count, 300 / 3) << channel.channel_index;
  }
  // Keys sit on frames, with one slope per key (C1) and no weights.
  for (const Curve& curve : result->keyed.curves) {
    for (const Key& key : curve.keys) {
      const double frame = key.time_seconds * 30.0;
      EXPECT_NEAR(frame, std::round(frame), 1e-9);
      EXPECT_EQ(key.in_tangent, key.out_tangent);
      EXPECT_FALSE(key.in_weight.has_value());
    }
  }
}

TEST(ReduceKeysTest, PoseAlignmentSharesKeyTimesPerJointOrClip) {
  const Clip clip = MixedClip();
  ReduceOptions joint = ToleranceOptions(0.2, 0.05, 0.001);
  joint.tolerance.pose_alignment = PoseAlignment::kJoint;
  ReduceOptions whole = joint;
  whole.tolerance.pose_alignment = PoseAlignment::kClip;
  auto times = [](const Curve& curve) {
    std::vector<double> t;
    for (const Key& key : curve.keys) t.push_back(key.time_seconds);
    return t;
  };

  const absl::StatusOr<ReduceResult> per_joint = ReduceKeys(clip, joint);
  const absl::StatusOr<ReduceResult> per_clip = ReduceKeys(clip, whole);
  const absl::StatusOr<ReduceResult> free = ReduceKeys(clip, ToleranceOptions(0.2, 0.05, 0.001));

  ASSERT_TRUE(per_joint.ok()) << per_joint.status();
  ASSERT_TRUE(per_clip.ok()) << per_clip.status();
  ASSERT_TRUE(free.ok()) << free.status();
  // The joint's three channels share times; the scalar channel has its own.
  EXPECT_EQ(times(per_joint->keyed.curves[0]), times(per_joint->keyed.curves[1]));
  EXPECT_EQ(times(per_joint->keyed.curves[0]), times(per_joint->keyed.curves[2]));
  EXPECT_NE(times(per_joint->keyed.curves[0]), times(per_joint->keyed.curves[3]));
  for (int c = 1; c < 4; ++c) {
    EXPECT_EQ(times(per_clip->keyed.curves[0]), times(per_clip->keyed.curves[c]));
  }
  const std::vector<double> bounds = {0.05, 0.2, 0.2, 0.001};
  for (const ReduceResult* result : {&*per_joint, &*per_clip}) {
    for (const ChannelReduction& channel : result->report.channels) {
      EXPECT_LE(channel.max_error, bounds[channel.channel_index]);
    }
  }
  // Sharing costs keys: never fewer than each channel alone.
  EXPECT_GE(per_joint->report.key_count, free->report.key_count);
  EXPECT_GE(per_clip->report.key_count, per_joint->report.key_count);
}

TEST(ReduceKeysTest, KeyBudgetIsKeptWithTheTightestBoundsThatFit) {
  const Clip clip = MixedClip();
  ReduceOptions unlimited = ToleranceOptions(0.2, 0.05, 0.001);
  const absl::StatusOr<ReduceResult> reference = ReduceKeys(clip, unlimited);
  ASSERT_TRUE(reference.ok()) << reference.status();
  ReduceOptions half = unlimited;
  half.tolerance.key_budget = reference->report.key_count / 2;
  ReduceOptions generous = unlimited;
  generous.tolerance.key_budget = reference->report.key_count * 4;

  const absl::StatusOr<ReduceResult> tight = ReduceKeys(clip, half);
  const absl::StatusOr<ReduceResult> loose = ReduceKeys(clip, generous);

  ASSERT_TRUE(tight.ok()) << tight.status();
  ASSERT_TRUE(loose.ok()) << loose.status();
  EXPECT_LE(tight->report.key_count, *half.tolerance.key_budget);
  EXPECT_GT(tight->report.max_error, reference->report.max_error);  // fewer keys, looser fit
  EXPECT_LE(loose->report.key_count, *generous.tolerance.key_budget);
  EXPECT_GT(loose->report.key_count, reference->report.key_count);  // more keys, tighter fit
  EXPECT_LT(loose->report.max_error, reference->report.max_error);
}

// A scalar channel of magnitude 1e6 under a 1e-9 bound: the budget's scale must reach about
// 2e15 (the channel's range over its bound), far beyond any fixed cap.
Clip HugeScalarClip() {
  std::vector<double> huge(200), small(200);
  for (int f = 0; f < 200; ++f) {
    huge[f] = 1e6 * std::sin(f / 7.0) + 3e5 * std::cos(f / 2.3);
    small[f] = 0.25 * std::sin(f / 5.0);
  }
  return ScalarClip({huge, small});
}

TEST(ReduceKeysTest, KeyBudgetOfTwoKeysPerChannelIsMetHoweverSmallTheBound) {
  const Clip clip = HugeScalarClip();
  ReduceOptions options = ToleranceOptions(0.5, 0.5, 1e-9);
  options.tolerance.key_budget = 4;
  ReduceOptions aligned = options;
  aligned.tolerance.pose_alignment = PoseAlignment::kClip;

  const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);
  const absl::StatusOr<ReduceResult> shared = ReduceKeys(clip, aligned);

  for (const absl::StatusOr<ReduceResult>* r : {&result, &shared}) {
    ASSERT_TRUE(r->ok()) << r->status();
    EXPECT_EQ((*r)->report.key_count, 4);
    // Two keys are within the scale at which the bound covers the range: 2.6e6 or so.
    const auto [low, high] =
        std::minmax_element(clip.channels[0].samples.begin(), clip.channels[0].samples.end());
    EXPECT_LE((*r)->report.max_error, *high - *low);
  }
}

// Four slow sines of range 60 over 10 000 frames, and a constant when asked for: a moving
// channel keeps at least four keys whatever the bound (no removal merges past 4096 frames).
Clip LongSlowSines(bool with_constant) {
  std::vector<std::vector<double>> channels(with_constant ? 5 : 4,
                                            std::vector<double>(10'000, 1.5));
  for (int c = 0; c < 4; ++c) {
    for (int f = 0; f < 10'000; ++f) channels[c][f] = 30.0 * std::sin(2.0 * M_PI * f / 9000.0 + c);
  }
  return ScalarClip(channels);
}

TEST(ReduceKeysTest, KeyBudgetBelowAKeyPerMergeLimitSpreadsItsKeysEvenly) {
  // A budget of 14 (18 when the constant shares the others' frames) is under the four keys a
  // moving channel keeps: the search starts from the budget's share, three keys per channel,
  // evenly spaced. Two flat keys per channel would miss by half the range, 30.
  constexpr double kFollowsTheMotion = 5.0;
  const Clip clip = LongSlowSines(/*with_constant=*/true);
  ReduceOptions options = ToleranceOptions(0.5, 0.5, 0.01);
  options.tolerance.key_budget = 14;
  ReduceOptions aligned = options;
  aligned.tolerance.pose_alignment = PoseAlignment::kClip;
  aligned.tolerance.key_budget = 18;

  const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);
  const absl::StatusOr<ReduceResult> shared = ReduceKeys(clip, aligned);

  for (const absl::StatusOr<ReduceResult>* r : {&result, &shared}) {
    ASSERT_TRUE(r->ok()) << r->status();
    EXPECT_EQ((*r)->report.key_count, r == &result ? 14 : 15);
    EXPECT_LT((*r)->report.max_error, kFollowsTheMotion);
    const std::vector<Key>& keys = (*r)->keyed.curves[0].keys;
    ASSERT_EQ(keys.size(), 3u);
    EXPECT_DOUBLE_EQ(keys[1].time_seconds, 5000.0 / 30.0);
  }
}

TEST(ReduceKeysTest, KeyBudgetSearchFromAnEvenStartSpendsWhatTheStartLeaves) {
  // Budgets of 12 and 15: three keys per channel to start from either way, the three left of 15
  // inserted where the scale the search settles on needs them.
  const Clip clip = LongSlowSines(/*with_constant=*/false);
  ReduceOptions start_only = ToleranceOptions(0.5, 0.5, 0.01);
  start_only.tolerance.key_budget = 12;
  ReduceOptions more = start_only;
  more.tolerance.key_budget = 15;

  const absl::StatusOr<ReduceResult> start = ReduceKeys(clip, start_only);
  const absl::StatusOr<ReduceResult> spent = ReduceKeys(clip, more);

  ASSERT_TRUE(start.ok()) << start.status();
  ASSERT_TRUE(spent.ok()) << spent.status();
  EXPECT_EQ(start->report.key_count, 12);
  EXPECT_EQ(spent->report.key_count, 15);
  EXPECT_LT(spent->report.max_error, start->report.max_error);
  EXPECT_LT(spent->report.rms_error, start->report.rms_error);
}

TEST(ReduceKeysTest, ReportIsMeasureReductionOfTheKeysItReturns) {
  const Clip clip = MixedClip();
  ReduceOptions tolerance = ToleranceOptions(0.2, 0.05, 0.001);
  tolerance.tolerance.pose_alignment = PoseAlignment::kJoint;

  for (const ReduceOptions& options : {tolerance, PaperOptions()}) {
    const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);
    ASSERT_TRUE(result.ok()) << result.status();
    const absl::StatusOr<ReductionReport> measured = MeasureReduction(clip, result->keyed);

    ASSERT_TRUE(measured.ok()) << measured.status();
    const ReductionReport& report = result->report;
    EXPECT_EQ(report.key_count, measured->key_count);
    EXPECT_EQ(report.sample_count, measured->sample_count);
    EXPECT_EQ(report.rms_error, measured->rms_error);
    EXPECT_EQ(report.max_error, measured->max_error);
    EXPECT_EQ(report.worst_channel_index, measured->worst_channel_index);
    EXPECT_EQ(report.worst_frame, measured->worst_frame);
    ASSERT_EQ(report.channels.size(), measured->channels.size());
    for (std::size_t c = 0; c < report.channels.size(); ++c) {
      EXPECT_EQ(report.channels[c].key_count, measured->channels[c].key_count) << c;
      EXPECT_EQ(report.channels[c].rms_error, measured->channels[c].rms_error) << c;
      EXPECT_EQ(report.channels[c].max_error, measured->channels[c].max_error) << c;
      EXPECT_EQ(report.channels[c].max_error_frame, measured->channels[c].max_error_frame) << c;
    }
  }
}

TEST(ReduceKeysTest, KeyBudgetBelowTwoKeysPerChannelIsRefused) {
  ReduceOptions options;
  options.tolerance.key_budget = 5;

  const absl::StatusOr<ReduceResult> result = ReduceKeys(MixedClip(), options);

  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(result.status().message(),
            "tolerance.key_budget 5 is below the 8 keys any fit of 4 channels needs (2 per "
            "channel)");
}

TEST(ReduceKeysTest, BadClipsAreRefusedWithTheirChannel) {
  Clip with_nan = ScalarClip({{0, 1, 2, 3}, {0, 1, NAN, 3}});
  Clip empty = ScalarClip({{0.0}});
  empty.channels.clear();
  Clip huge = ScalarClip({{0, 1e10, 2}});

  EXPECT_EQ(ReduceKeys(with_nan, PaperOptions()).status().message(),
            "channel 1 (c1): sample 2 is NaN");
  EXPECT_EQ(ReduceKeys(empty, PaperOptions()).status().message(), "clip has no channels");
  EXPECT_EQ(ReduceKeys(huge, PaperOptions()).status().message(),
            "channel 0 (c0): sample 1 is 1e+10, beyond the +-1e+09 a clip may hold");
}

TEST(ReduceKeysTest, ExtremeValidClipsGiveFiniteKeysWithBothMethods) {
  // The smallest frame time and the largest samples a clip may hold, alternating: the steepest
  // slopes any valid input has (2e9 per microsecond). Paper's accuracy at its floor lets its
  // steps shrink to nothing, which without a floor on tangent x made slopes overflow.
  std::vector<double> zigzag;
  for (int f = 0; f < 40; ++f) zigzag.push_back(f % 2 == 0 ? 1e9 : -1e9);
  const Clip clip = ScalarClip({zigzag}, 1e-6);
  ReduceOptions paper = PaperOptions();
  paper.paper.accuracy = 1e-300;
  paper.paper.max_iterations = 200;
  paper.paper.min_key_spacing_frames = 1;

  for (const ReduceOptions& options : {ReduceOptions{}, paper}) {
    const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);

    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_TRUE(ValidateKeyedClip(result->keyed).ok()) << ValidateKeyedClip(result->keyed);
    for (const Key& key : result->keyed.curves[0].keys) {
      EXPECT_TRUE(std::isfinite(key.in_tangent) && std::isfinite(key.out_tangent));
      EXPECT_TRUE(std::isfinite(key.time_seconds));
    }
    EXPECT_TRUE(std::isfinite(result->report.rms_error));
  }
}

TEST(ReduceKeysTest, ConstantChannelsGetTwoFlatKeys) {
  const Clip constant = ScalarClip({std::vector<double>(50, 4.25)}, 0.5);
  const Clip one_frame = ScalarClip({{7.0}});

  for (const ReduceOptions& options : {PaperOptions(), ReduceOptions{}}) {
    absl::StatusOr<ReduceResult> flat = ReduceKeys(constant, options);
    absl::StatusOr<ReduceResult> single = ReduceKeys(one_frame, options);

    ASSERT_TRUE(single.ok()) << single.status();
    EXPECT_EQ(single->keyed.curves[0].keys.size(), 1u);
    ASSERT_TRUE(flat.ok()) << flat.status();
    const Curve& curve = flat->keyed.curves[0];
    ASSERT_EQ(curve.keys.size(), 2u);
    EXPECT_EQ(curve.keys[0].time_seconds, 0.0);
    EXPECT_EQ(curve.keys[1].time_seconds, 24.5);
    EXPECT_EQ(curve.keys[0].value, 4.25);
    EXPECT_EQ(curve.keys[1].value, 4.25);
    EXPECT_EQ(curve.keys[0].out_tangent, 0.0);
    EXPECT_EQ(flat->report.max_error, 0.0);
  }
}

TEST(ReduceKeysTest, RotationSeamIsFittedUnwrapped) {
  // 150 -> 180 -> -170 ... wrapped: a steady 2 degrees per frame once unwrapped.
  Clip clip;
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = 60;
  clip.skeleton.joints = {Joint{.name = "Hips", .parent = -1, .channels = {0}}};
  std::vector<double> samples(60);
  for (int f = 0; f < 60; ++f) samples[f] = std::remainder(120.0 + 2.0 * f, 360.0);
  clip.channels = {Channel{.joint = 0, .kind = ChannelKind::kZRotation, .samples = samples}};

  for (const ReduceOptions& options : {PaperOptions(), ReduceOptions{}}) {
    absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);

    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_LT(result->report.max_error, 0.5);
    EXPECT_NEAR(EvaluateCurve(result->keyed.curves[0], 59.0 / 30.0), 238.0, 0.5);
  }
}

TEST(ReduceKeysTest, ReportsProgressPerChannelAndStopsWhenCancelled) {
  std::vector<double> wave(40);
  for (int f = 0; f < 40; ++f) wave[f] = std::sin(f / 4.0);
  const Clip clip = ScalarClip({wave, wave, wave});
  std::vector<std::string> stages;
  std::stop_source stop;

  absl::StatusOr<ReduceResult> done =
      ReduceKeys(clip, PaperOptions(),
                 [&](double, std::string_view stage) { stages.emplace_back(stage); });
  absl::StatusOr<ReduceResult> cancelled = ReduceKeys(
      clip, PaperOptions(), [&](double, std::string_view) { stop.request_stop(); },
      stop.get_token());

  ASSERT_TRUE(done.ok());
  EXPECT_EQ(stages, (std::vector<std::string>{"reduce 1/3", "reduce 2/3", "reduce 3/3"}));
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
}

TEST(MeasureReductionTest, ReportsRmsMaxAndWorstFrame) {
  // A flat curve at 1 against samples 1, 1, 4, 1: errors 0, 0, 3, 0.
  const Clip clip = ScalarClip({{1, 1, 4, 1}, {2, 2, 2, 2}});
  KeyedClip keyed;
  keyed.layout = clip;
  for (Channel& channel : keyed.layout.channels) channel.samples.clear();
  keyed.curves = {Curve{{Key{.value = 1.0}}}, Curve{{Key{.value = 2.0}}}};

  absl::StatusOr<ReductionReport> report = MeasureReduction(clip, keyed);

  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_EQ(report->channels[0].max_error, 3.0);
  EXPECT_EQ(report->channels[0].max_error_frame, 2);
  EXPECT_DOUBLE_EQ(report->channels[0].rms_error, 1.5);
  EXPECT_EQ(report->channels[1].max_error, 0.0);
  EXPECT_EQ(report->key_count, 2);
  EXPECT_EQ(report->sample_count, 8);
  EXPECT_DOUBLE_EQ(report->key_percent(), 25.0);
  EXPECT_DOUBLE_EQ(report->rms_error, std::sqrt(9.0 / 8.0));
  EXPECT_EQ(report->worst_channel_index, 0);
  EXPECT_EQ(report->worst_frame, 2);
}

TEST(MeasureReductionTest, ChannelMismatchIsRefused) {
  const Clip clip = ScalarClip({{1, 2}});
  KeyedClip keyed;
  keyed.layout = ScalarClip({{1, 2}, {3, 4}});
  keyed.curves = {Curve{{Key{}}}, Curve{{Key{}}}};

  EXPECT_EQ(MeasureReduction(clip, keyed).status().message(),
            "keyed clip has 2 channels, the clip has 1");
}

}  // namespace
}  // namespace tempokey::core
