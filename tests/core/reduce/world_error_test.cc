// The joint world-position error report (SPEC 4.4) against closed forms: a bone of length r on a
// joint turned by a wrong angle d moves its far end by the chord 2 r |sin(d / 2)|; a wrong root
// translation moves every point by the same vector.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/reduce/world_error.h"

#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// Sums over a few points and frames of products of exact axis matrices.
constexpr double kTolerance = 1e-12;
constexpr double kBone = 40.0;     // R to B
constexpr double kEndSite = 10.0;  // B to its end site

double Chord(double radius, double degrees) {
  return 2.0 * radius * std::abs(std::sin(0.5 * degrees * std::numbers::pi / 180.0));
}

// Root "R" with X position and Z rotation channels; child "B" (no channels) at (kBone, 0, 0)
// with an end site at (kEndSite, 0, 0). The first frame turns the chain upright (90 degrees),
// so the figure is kBone + kEndSite tall.
Clip Bone(const std::vector<double>& x, const std::vector<double>& angle) {
  Clip clip;
  clip.name = "bone";
  clip.frame_count = static_cast<std::int64_t>(angle.size());
  clip.skeleton.joints = {{.name = "R", .parent = -1, .channels = {0, 1}},
                          {.name = "B", .parent = 0, .offset = {kBone, 0, 0},
                           .end_sites = {{kEndSite, 0, 0}}}};
  clip.channels = {{.joint = 0, .kind = ChannelKind::kXPosition, .samples = x},
                   {.joint = 0, .kind = ChannelKind::kZRotation, .samples = angle}};
  return clip;
}

// Curves through `values[c][f]` at every frame (flat tangents): they evaluate to exactly those
// values at the source frames.
KeyedClip KeyedThrough(const Clip& clip, const std::vector<std::vector<double>>& values) {
  KeyedClip keyed;
  keyed.layout = clip;
  for (Channel& channel : keyed.layout.channels) channel.samples.clear();
  for (const std::vector<double>& channel : values) {
    Curve& curve = keyed.curves.emplace_back();
    for (std::size_t f = 0; f < channel.size(); ++f) {
      curve.keys.push_back({.time_seconds = static_cast<double>(f) * clip.frame_time_seconds,
                            .value = channel[f]});
    }
  }
  return keyed;
}

TEST(MeasureWorldErrorTest, WrongAngleMovesTheEndSiteByItsChord) {
  const std::vector<double> zero = {0, 0, 0, 0};
  const std::vector<double> angle = {90, 60, 30, 100};
  const std::vector<double> fitted = {90, 61, 27, 100.5};  // errors 0, 1, -3, 0.5 degrees
  const Clip clip = Bone(zero, angle);

  const absl::StatusOr<WorldErrorReport> report =
      MeasureWorldError(clip, KeyedThrough(clip, {zero, fitted}));

  ASSERT_TRUE(report.ok()) << report.status();
  const double tip = kBone + kEndSite;
  EXPECT_NEAR(report->max_error, Chord(tip, 3), kTolerance);
  EXPECT_EQ(report->worst_point_name, "B end site");
  EXPECT_EQ(report->worst_point, (SkeletonPoint{.joint = 1, .end_site = 0}));
  EXPECT_EQ(report->worst_frame, 2);
  // Three points (R never moves) over four frames.
  double squared = 0.0;
  for (double d : {0.0, 1.0, 3.0, 0.5}) {
    squared += std::pow(Chord(kBone, d), 2) + std::pow(Chord(tip, d), 2);
  }
  EXPECT_NEAR(report->rms_error, std::sqrt(squared / 12.0), kTolerance);
  EXPECT_NEAR(report->figure_height, tip, kTolerance);
  EXPECT_NEAR(report->max_error_percent(), 100.0 * Chord(tip, 3) / tip, 1e-10);
  EXPECT_EQ(report->joint_tolerance, 0.0);
}

TEST(MeasureWorldErrorTest, WrongRootTranslationMovesEveryPointAlike) {
  const std::vector<double> angle = {90, 45, 0};
  const Clip clip = Bone({0, 1, 2}, angle);

  const absl::StatusOr<WorldErrorReport> report =
      MeasureWorldError(clip, KeyedThrough(clip, {{0.25, 1.25, 2.25}, angle}));

  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_NEAR(report->max_error, 0.25, kTolerance);
  EXPECT_NEAR(report->rms_error, 0.25, kTolerance);
  // Ties go to the earliest frame, then the first point: the root at frame 0.
  EXPECT_EQ(report->worst_point_name, "R");
  EXPECT_EQ(report->worst_frame, 0);
}

TEST(MeasureWorldErrorTest, RefusesClipsWithoutSkeletonAndMismatchedCurves) {
  Clip plain;
  plain.frame_count = 2;
  plain.channels.push_back({.name = "x", .samples = {1.0, 2.0}});
  const Clip clip = Bone({0, 0}, {90, 90});
  KeyedClip short_keyed = KeyedThrough(clip, {{0, 0}, {90, 90}});
  short_keyed.layout.channels.pop_back();
  short_keyed.layout.skeleton.joints[0].channels = {0};
  short_keyed.curves.pop_back();

  EXPECT_EQ(MeasureWorldError(plain, KeyedThrough(plain, {{1, 2}})).status().message(),
            "forward kinematics needs a skeleton, the clip has none");
  EXPECT_EQ(MeasureWorldError(clip, short_keyed).status().message(),
            "keyed clip has 1 channels, the clip has 2");
}

TEST(ReduceWorldErrorTest, EveryMethodReportsItAndMeasureReductionAgrees) {
  std::vector<double> x, angle;
  for (int f = 0; f < 120; ++f) {
    x.push_back(0.01 * f * f);
    angle.push_back(90 + 40 * std::sin(0.1 * f) + 7 * std::sin(0.53 * f));
  }
  const Clip clip = Bone(x, angle);
  for (ReduceMethod method : {ReduceMethod::kTolerance, ReduceMethod::kPaper}) {
    ReduceOptions options;
    options.method = method;

    const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);
    ASSERT_TRUE(result.ok()) << result.status();
    const absl::StatusOr<ReductionReport> measured = MeasureReduction(clip, result->keyed);
    ASSERT_TRUE(measured.ok()) << measured.status();

    ASSERT_TRUE(result->report.world.has_value());
    EXPECT_EQ(result->report.world, measured->world);
    EXPECT_GT(result->report.world->max_error, 0.0);
    EXPECT_GE(result->report.world->max_error, result->report.world->rms_error);
    // No joint is moved further than the root's translation error plus the tip's chord of the
    // worst rotation error.
    const double rotation_error = result->report.channels[1].max_error;
    EXPECT_LE(result->report.world->max_error,
              result->report.channels[0].max_error + Chord(kBone + kEndSite, rotation_error) +
                  kTolerance);
  }
}

TEST(ReduceWorldErrorTest, PlainClipsHaveNone) {
  Clip plain;
  plain.frame_count = 3;
  plain.channels.push_back({.name = "x", .samples = {1.0, 2.0, 4.0}});

  const absl::StatusOr<ReduceResult> result = ReduceKeys(plain, ReduceOptions{});

  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_FALSE(result->report.world.has_value());
}

}  // namespace
}  // namespace tempokey::core
