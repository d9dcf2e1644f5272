// The world-space bound (SPEC 4.4, joint_bound.h) on synthetic chains with analytic answers. The
// checks evaluate the keyed curves and place the points with closed forms (planar chains turning
// about Z), not with the library's forward kinematics.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/reduce.h"

#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// Closed forms of sums of a few products of doubles.
constexpr double kTolerance = 1e-9;
constexpr int kFrames = 240;

double Radians(double degrees) { return degrees * std::numbers::pi / 180.0; }

// Smooth motion with a deterministic jitter, so fits keep errors up to their bounds.
std::vector<double> Motion(double base, double amplitude, double rate, double jitter,
                           int frames = kFrames) {
  std::vector<double> out;
  unsigned state = 12345;
  for (int f = 0; f < frames; ++f) {
    state = state * 1103515245u + 12345u;
    const double noise = (static_cast<double>((state >> 8) % 2001) / 1000.0 - 1.0) * jitter;
    out.push_back(base + amplitude * std::sin(rate * f) + 0.3 * amplitude * std::sin(2.7 * rate * f) +
                  noise);
  }
  return out;
}

// Root "A" (X position, Z rotation) at the origin; "B" at (l1, 0, 0) turning about Z; B's end
// site at (l2, 0, 0). Without `b`, B has no channel.
Clip PlanarChain(double l1, double l2, const std::vector<double>& x, const std::vector<double>& a,
                 const std::vector<double>* b) {
  Clip clip;
  clip.name = "chain";
  clip.frame_count = static_cast<std::int64_t>(x.size());
  clip.skeleton.joints = {{.name = "A", .parent = -1, .channels = {0, 1}},
                          {.name = "B", .parent = 0, .offset = {l1, 0, 0},
                           .end_sites = {{l2, 0, 0}}}};
  clip.channels = {{.joint = 0, .kind = ChannelKind::kXPosition, .samples = x},
                   {.joint = 0, .kind = ChannelKind::kZRotation, .samples = a}};
  if (b != nullptr) {
    clip.skeleton.joints[1].channels = {2};
    clip.channels.push_back({.joint = 1, .kind = ChannelKind::kZRotation, .samples = *b});
  }
  return clip;
}

// Channel c's values at every frame: samples for the source, the curve for the keyed clip.
double Value(const Clip& clip, const KeyedClip* keyed, std::size_t c, int f) {
  if (keyed == nullptr) return clip.channels[c].samples[static_cast<std::size_t>(f)];
  return EvaluateCurve(keyed->curves[c], f * clip.frame_time_seconds);
}

// B and its end site at frame f, closed form.
std::array<Vec3, 2> ChainPoints(const Clip& clip, const KeyedClip* keyed, double l1, double l2,
                                int f) {
  const double x = Value(clip, keyed, 0, f);
  const double a = Radians(Value(clip, keyed, 1, f));
  const double b = clip.channels.size() > 2 ? Radians(Value(clip, keyed, 2, f)) : 0.0;
  const Vec3 joint = {x + l1 * std::cos(a), l1 * std::sin(a), 0};
  return {joint, Vec3{joint[0] + l2 * std::cos(a + b), joint[1] + l2 * std::sin(a + b), 0}};
}

// The largest distance of B or its end site from the source, over every frame of the clip (A moves
// only with the X channel, whose error is at most the end site's too).
double WorstChainError(const Clip& clip, const KeyedClip& keyed, double l1, double l2) {
  double worst = 0.0;
  for (int f = 0; f < static_cast<int>(clip.frame_count); ++f) {
    const auto source = ChainPoints(clip, nullptr, l1, l2, f);
    const auto fitted = ChainPoints(clip, &keyed, l1, l2, f);
    for (int p = 0; p < 2; ++p) {
      worst = std::max(worst, std::hypot(fitted[p][0] - source[p][0], fitted[p][1] - source[p][1]));
    }
    worst = std::max(worst, std::abs(Value(clip, &keyed, 0, f) - Value(clip, nullptr, 0, f)));
  }
  return worst;
}

std::vector<double> KeyTimes(const Curve& curve) {
  std::vector<double> times;
  for (const Key& key : curve.keys) times.push_back(key.time_seconds);
  return times;
}

TEST(JointBoundTest, LoneRotatingBoneGetsExactlyTheKeysOfItsChordAngle) {
  // One rotation channel moves the end site, at r = 50 from the root, by 2 r sin(e / 2): a bound
  // D on the points is exactly a bound of 2 asin(D / 2r) on the angle, which each channel alone
  // is given first, and which verification then accepts.
  constexpr double kL1 = 35.0;
  constexpr double kL2 = 15.0;
  constexpr double kBound = 0.4;
  const std::vector<double> still(kFrames, 0.0);
  const Clip clip = PlanarChain(kL1, kL2, still, Motion(90, 50, 0.05, 0.3), nullptr);
  ReduceOptions joint;
  joint.tolerance.joint_tolerance = JointTolerance{.value = kBound};
  ReduceOptions angle;
  angle.tolerance.max_rotation_error_degrees =
      2.0 * std::asin(kBound / (2.0 * (kL1 + kL2))) * 180.0 / std::numbers::pi;

  const absl::StatusOr<ReduceResult> by_joint = ReduceKeys(clip, joint);
  const absl::StatusOr<ReduceResult> by_angle = ReduceKeys(clip, angle);

  ASSERT_TRUE(by_joint.ok()) << by_joint.status();
  ASSERT_TRUE(by_angle.ok()) << by_angle.status();
  EXPECT_GT(by_joint->keyed.curves[1].keys.size(), 4u);
  EXPECT_EQ(KeyTimes(by_joint->keyed.curves[1]), KeyTimes(by_angle->keyed.curves[1]));
  const double worst = WorstChainError(clip, by_joint->keyed, kL1, kL2);
  EXPECT_LE(worst, kBound);
  EXPECT_GT(worst, 0.5 * kBound);  // the bound is used, not wasted
  ASSERT_TRUE(by_joint->report.world.has_value());
  EXPECT_NEAR(by_joint->report.world->max_error, worst, kTolerance);
  EXPECT_EQ(by_joint->report.world->worst_point_name, "B end site");
  EXPECT_EQ(by_joint->report.world->joint_tolerance, kBound);
}

TEST(JointBoundTest, TwoBoneChainWithTranslationStaysWithinTheBoundAtEveryFrame) {
  // Each channel alone may use the whole bound, so together they first break it; the chains over
  // it are tightened until verification passes.
  constexpr double kL1 = 30.0;
  constexpr double kL2 = 20.0;
  constexpr double kBound = 0.5;
  const std::vector<double> b = Motion(20, 35, 0.08, 0.4);
  const Clip clip =
      PlanarChain(kL1, kL2, Motion(0, 40, 0.02, 0.2), Motion(90, 30, 0.05, 0.3), &b);
  ReduceOptions options;
  options.tolerance.joint_tolerance = JointTolerance{.value = kBound};

  const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);

  ASSERT_TRUE(result.ok()) << result.status();
  const double worst = WorstChainError(clip, result->keyed, kL1, kL2);
  EXPECT_LE(worst, kBound);
  ASSERT_TRUE(result->report.world.has_value());
  EXPECT_NEAR(result->report.world->max_error, worst, kTolerance);
  // Alone, each channel's budget would have let the end site move further.
  ReduceOptions alone;
  alone.tolerance.max_position_error = kBound;
  alone.tolerance.max_rotation_error_degrees =
      2.0 * std::asin(kBound / (2.0 * kL2)) * 180.0 / std::numbers::pi;
  const absl::StatusOr<ReduceResult> loose = ReduceKeys(clip, alone);
  ASSERT_TRUE(loose.ok());
  EXPECT_GT(WorstChainError(clip, loose->keyed, kL1, kL2), kBound);
}

TEST(JointBoundTest, PercentIsOfTheFigureHeightAtTheFirstFrame) {
  // At frame 0 the chain stands upright (A turned by 90, B straight): 50 tall.
  std::vector<double> b = Motion(0, 10, 0.05, 0.0);
  b[0] = 0.0;
  std::vector<double> a = Motion(90, 20, 0.05, 0.0);
  a[0] = 90.0;
  const Clip clip = PlanarChain(30, 20, std::vector<double>(kFrames, 0.0), a, &b);
  ReduceOptions options;
  options.tolerance.joint_tolerance = JointTolerance{.value = 0.5, .percent_of_height = true};

  const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);

  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_TRUE(result->report.world.has_value());
  EXPECT_NEAR(result->report.world->figure_height, 50.0, kTolerance);
  EXPECT_NEAR(result->report.world->joint_tolerance, 0.25, kTolerance);
  EXPECT_LE(WorstChainError(clip, result->keyed, 30, 20), 0.25);
}

TEST(JointBoundTest, SetPerChannelBoundsStillApply) {
  const std::vector<double> b = Motion(20, 35, 0.08, 0.4);
  const Clip clip = PlanarChain(30, 20, Motion(0, 40, 0.02, 0.2), Motion(90, 30, 0.05, 0.3), &b);
  ReduceOptions options;
  options.tolerance.joint_tolerance = JointTolerance{.value = 5.0};
  options.tolerance.max_rotation_error_degrees = 0.2;
  options.tolerance.max_position_error = 0.1;

  const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);

  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_LE(result->report.channels[0].max_error, 0.1);
  EXPECT_LE(result->report.channels[1].max_error, 0.2);
  EXPECT_LE(result->report.channels[2].max_error, 0.2);
}

TEST(JointBoundTest, CombinesWithPoseAlignmentAndKeyBudgets) {
  const std::vector<double> b = Motion(20, 35, 0.08, 0.4);
  const Clip clip = PlanarChain(30, 20, Motion(0, 40, 0.02, 0.2), Motion(90, 30, 0.05, 0.3), &b);
  ReduceOptions aligned;
  aligned.tolerance.joint_tolerance = JointTolerance{.value = 0.5};
  aligned.tolerance.pose_alignment = PoseAlignment::kClip;
  ReduceOptions budgeted;
  budgeted.tolerance.joint_tolerance = JointTolerance{.value = 0.5};
  budgeted.tolerance.key_budget = 30;

  const absl::StatusOr<ReduceResult> by_alignment = ReduceKeys(clip, aligned);
  const absl::StatusOr<ReduceResult> by_budget = ReduceKeys(clip, budgeted);

  ASSERT_TRUE(by_alignment.ok()) << by_alignment.status();
  EXPECT_LE(WorstChainError(clip, by_alignment->keyed, 30, 20), 0.5);
  EXPECT_EQ(KeyTimes(by_alignment->keyed.curves[0]), KeyTimes(by_alignment->keyed.curves[2]));
  ASSERT_TRUE(by_budget.ok()) << by_budget.status();
  EXPECT_LE(by_budget->report.key_count, 30);
  // The budget scales the joint bound; the scaled bound holds.
  const double kept = by_budget->report.world->joint_tolerance;
  EXPECT_GT(kept, 0.5);
  EXPECT_LE(WorstChainError(clip, by_budget->keyed, 30, 20), kept);
}

TEST(JointBoundTest, AKeyBudgetUnderTheMergeLimitOfALongClipKeepsTheBoundItReports) {
  // 9 000 frames: each moving channel keeps at least four keys whatever the bound (no removal
  // merges past 4096 frames), over a budget of 9. The search starts from three keys per
  // channel, evenly spaced, and looks from there for the tightest joint bound within budget.
  const std::vector<double> b = Motion(20, 35, 0.0008, 0.4, 9000);
  const Clip clip = PlanarChain(30, 20, Motion(0, 40, 0.0002, 0.2, 9000),
                                Motion(90, 30, 0.0005, 0.3, 9000), &b);
  ReduceOptions budgeted;
  budgeted.tolerance.joint_tolerance = JointTolerance{.value = 0.5};
  budgeted.tolerance.pose_alignment = PoseAlignment::kJoint;
  budgeted.tolerance.key_budget = 9;

  const absl::StatusOr<ReduceResult> result = ReduceKeys(clip, budgeted);

  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_LE(result->report.key_count, 9);
  EXPECT_EQ(KeyTimes(result->keyed.curves[0]), KeyTimes(result->keyed.curves[1]));
  const double kept = result->report.world->joint_tolerance;
  EXPECT_LE(WorstChainError(clip, result->keyed, 30, 20), kept);
  // The search tightened the bound from the one at which two flat keys per channel keep it
  // (170 here) to well within the chain's reach.
  EXPECT_LT(kept, 30.0 + 20.0);
}

TEST(JointBoundTest, RefusesWhatItCannotMeasure) {
  Clip plain;
  plain.frame_count = 3;
  plain.channels.push_back({.name = "x", .samples = {1.0, 2.0, 4.0}});
  ReduceOptions joint;
  joint.tolerance.joint_tolerance = JointTolerance{.value = 1.0};
  // Every point at height 0 at the first frame: a percentage has nothing to refer to.
  const Clip flat = PlanarChain(30, 20, std::vector<double>(kFrames, 0.0),
                                std::vector<double>(kFrames, 0.0), nullptr);
  ReduceOptions percent;
  percent.tolerance.joint_tolerance = JointTolerance{.value = 1.0, .percent_of_height = true};
  ReduceOptions negative;
  negative.tolerance.joint_tolerance = JointTolerance{.value = -1.0};

  const absl::Status no_skeleton = ReduceKeys(plain, joint).status();
  const absl::Status no_height = ReduceKeys(flat, percent).status();

  EXPECT_EQ(no_skeleton.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(no_skeleton.message(), "tolerance.joint_tolerance needs a skeleton, the clip has none");
  EXPECT_EQ(no_height.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(no_height.message(),
            "tolerance.joint_tolerance 1% is relative to the figure's height, which is 0 (every "
            "joint and end site at one height at the first frame)");
  EXPECT_EQ(ValidateReduceOptions(negative).message(),
            "tolerance.joint_tolerance must be finite and > 0, got -1");
  // An absurd bound is refused as every other bound is past 1e9; 1.7e308% of a height came back
  // as an infinite bound in the report.
  ReduceOptions huge = percent;
  huge.tolerance.joint_tolerance->value = 1.7e308;
  ReduceOptions huge_units = joint;
  huge_units.tolerance.joint_tolerance->value = 1e300;
  ReduceOptions largest = joint;
  largest.tolerance.joint_tolerance->value = 1e9;
  EXPECT_EQ(ValidateReduceOptions(huge).message(),
            "tolerance.joint_tolerance must be at most 1e+09, got 1.7e+308%");
  EXPECT_EQ(ValidateReduceOptions(huge_units).message(),
            "tolerance.joint_tolerance must be at most 1e+09, got 1e+300");
  EXPECT_TRUE(ValidateReduceOptions(largest).ok());
}

// World positions are doubles: a bound near their rounding at the clip's reach cannot be held,
// and once ended in an INTERNAL error ("a chain at its guaranteed budgets is still over the
// bound"). It is refused up front; at the floor itself the bound is held. The chain lies along
// X (bones of 30 and 20 from the origin): it reaches 50 file units, so the floor is 5e-11.
TEST(JointBoundTest, ABoundBelowWhatPositionsCanBeComputedToIsRefusedAndTheFloorIsHeld) {
  const Clip chain = PlanarChain(30, 20, std::vector<double>(kFrames, 0.0),
                                 std::vector<double>(kFrames, 0.0), nullptr);
  ReduceOptions tiny;
  tiny.tolerance.joint_tolerance = JointTolerance{.value = 1e-15};
  ReduceOptions floor;
  floor.tolerance.joint_tolerance = JointTolerance{.value = 5.0001e-11};

  const absl::StatusOr<ReduceResult> refused = ReduceKeys(chain, tiny);
  const absl::StatusOr<ReduceResult> held = ReduceKeys(chain, floor);

  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(refused.status().message(),
            "tolerance.joint_tolerance 1e-15 is below what this clip's joint positions can be "
            "computed to: at least 5e-11 file units (1e-12 of the 50 file units its joints reach "
            "from the origin)");
  ASSERT_TRUE(held.ok()) << held.status();
  ASSERT_TRUE(held->report.world.has_value());
  EXPECT_LE(held->report.world->max_error, 5.0001e-11);
}

}  // namespace
}  // namespace tempokey::core
