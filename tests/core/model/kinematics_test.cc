#include "tempokey/core/model/kinematics.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <span>
#include <vector>

#include "gtest/gtest.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// A handful of products of exact axis matrices: rounding of a few ulps.
constexpr double kTolerance = 1e-12;

// Root "R" (positions + Zrotation Xrotation Yrotation) with a child "C" (Xrotation) at offset
// (1, 0, 0) and a grandchild "T" (no channels) at offset (0, 2, 0).
Clip Chain(double root_z, double root_x, double child_x) {
  Clip clip;
  clip.frame_time_seconds = 1.0 / 30;
  clip.frame_count = 1;
  clip.skeleton.joints = {{.name = "R", .parent = -1, .offset = {9, 9, 9}},
                          {.name = "C", .parent = 0, .offset = {1, 0, 0}},
                          {.name = "T", .parent = 1, .offset = {0, 2, 0}}};
  const std::vector<std::pair<ChannelKind, double>> root = {
      {ChannelKind::kXPosition, 1}, {ChannelKind::kYPosition, 2}, {ChannelKind::kZPosition, 3},
      {ChannelKind::kZRotation, root_z}, {ChannelKind::kXRotation, root_x},
      {ChannelKind::kYRotation, 0}};
  for (const auto& [kind, value] : root) {
    clip.skeleton.joints[0].channels.push_back(static_cast<int>(clip.channels.size()));
    clip.channels.push_back({.joint = 0, .kind = kind, .samples = {value}});
  }
  clip.skeleton.joints[1].channels.push_back(static_cast<int>(clip.channels.size()));
  clip.channels.push_back({.joint = 1, .kind = ChannelKind::kXRotation, .samples = {child_x}});
  return clip;
}

void ExpectPosition(const Vec3& got, const Vec3& expected) {
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], expected[k], kTolerance) << k;
}

TEST(KinematicsTest, PositionChannelsReplaceTheOffsetAndRotationsTurnTheChildren) {
  // Root at (1, 2, 3) (its offset 9, 9, 9 replaced); Rz(90) turns the child's +X offset to +Y,
  // so C is at (1, 3, 3); C's Rx(90) turns T's +Y offset to +Z, then Rz(90) leaves +Z: T at
  // (1, 3, 5).
  const Clip clip = Chain(90, 0, 90);

  const absl::StatusOr<std::vector<Vec3>> world = JointWorldPositions(clip, 0);

  ASSERT_TRUE(world.ok()) << world.status();
  ExpectPosition((*world)[0], {1, 2, 3});
  ExpectPosition((*world)[1], {1, 3, 3});
  ExpectPosition((*world)[2], {1, 3, 5});
}

TEST(KinematicsTest, RotationChannelsComposeInListedOrder) {
  // Root ZXY = Rz(90)·Rx(90): the child's +X offset goes to +Y under Rz (Rx first leaves +X
  // alone). With the opposite order, Rx(90)·Rz(90), +X -> +Y -> +Z.
  const Clip zxy = Chain(90, 90, 0);

  const absl::StatusOr<std::vector<Vec3>> world = JointWorldPositions(zxy, 0);

  ASSERT_TRUE(world.ok());
  ExpectPosition((*world)[1], {1, 3, 3});
  // T's offset +Y: Rz(90)·Rx(90)·(0, 2, 0) = Rz(90)·(0, 0, 2) = (0, 0, 2).
  ExpectPosition((*world)[2], {1, 3, 5});
}

TEST(KinematicsTest, RefusesFramesOutsideTheClipAndClipsWithoutSkeleton) {
  Clip plain;
  plain.frame_count = 1;
  plain.channels.push_back({.name = "x", .samples = {1.0}});

  EXPECT_EQ(JointWorldPositions(Chain(0, 0, 0), 1).status().message(),
            "frame 1 is outside the clip's 1 frames");
  EXPECT_EQ(JointWorldPositions(plain, 0).status().message(),
            "forward kinematics needs a skeleton, the clip has none");
}

TEST(KinematicsTest, JointRotationsListRotationChannelsAndTheirOrder) {
  const Clip clip = Chain(0, 0, 0);

  const std::vector<JointRotation> rotations = JointRotations(clip);

  ASSERT_EQ(rotations.size(), 2u);
  EXPECT_EQ(rotations[0].channels, (std::vector<int>{3, 4, 5}));
  EXPECT_EQ(rotations[0].order, (EulerOrder{2, 0, 1}));
  EXPECT_EQ(rotations[1].channels, (std::vector<int>{6}));
}

// RotationTrig() against libm: 4 units in the last place of 1, absolute (sines and cosines are at
// most 1 in size, and near their zeros the argument's own rounding is of that size).
constexpr double kTrigTolerance = 4 * std::numeric_limits<double>::epsilon();

// Angles a capture holds and some it should not: small and large, exact quarter turns, zeros of
// either sign, and ones past the vector kernels' reduction (libm's then). The sweep's groups of
// eight within +-44 degrees take the kernels' path without reduction, the others the reduced one:
// alone, padded with zeros, each of its small angles takes the former.
std::vector<double> TrigAngles() {
  std::vector<double> degrees = {0.0,    -0.0,  1e-300, -1e-12, 0.5,   45.0,   89.999, 90.0,
                                 -90.0,  180.0, -180.0, 270.0,  359.9, 720.0,  -1234.5, 1e6,
                                 3e8,    -4e8,  5.7e8,  -5.8e8, 1e12,  -3e15,  1e300};
  for (int k = 0; k < 1000; ++k) degrees.push_back(-400.0 + 0.8137 * k);
  return degrees;
}

TEST(RotationTrigTest, AgreesWithLibmToAFewUnitsInTheLastPlaceOfOne) {
  const std::vector<double> degrees = TrigAngles();
  std::vector<double> cosines(degrees.size()), sines(degrees.size());

  ForwardKinematics::RotationTrig(degrees, cosines, sines);

  for (std::size_t i = 0; i < degrees.size(); ++i) {
    const double r = degrees[i] * (std::numbers::pi / 180.0);
    EXPECT_NEAR(cosines[i], std::cos(r), kTrigTolerance) << degrees[i];
    EXPECT_NEAR(sines[i], std::sin(r), kTrigTolerance) << degrees[i];
  }
}

TEST(RotationTrigTest, KeepsExactValuesAtZeroAndLibmsPastTheReduction) {
  // Nine angles: a full group of eight (the kernels and libm side by side) and a last one alone.
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<double> degrees = {-0.0, 0.0, 1e12, 30.0, -3e15, 1e300, inf, -inf, -0.0};
  std::vector<double> cosines(degrees.size()), sines(degrees.size());

  ForwardKinematics::RotationTrig(degrees, cosines, sines);

  for (std::size_t i : {0u, 1u, 8u}) {
    EXPECT_EQ(cosines[i], 1.0) << i;
    EXPECT_EQ(sines[i], 0.0) << i;
    EXPECT_EQ(std::signbit(sines[i]), std::signbit(degrees[i])) << i;
  }
  for (std::size_t i : {2u, 4u, 5u}) {
    const double r = degrees[i] * (std::numbers::pi / 180.0);
    EXPECT_EQ(cosines[i], std::cos(r)) << degrees[i];
    EXPECT_EQ(sines[i], std::sin(r)) << degrees[i];
  }
  for (std::size_t i : {6u, 7u}) {
    EXPECT_TRUE(std::isnan(cosines[i]) && std::isnan(sines[i])) << degrees[i];
  }
  EXPECT_NEAR(sines[3], 0.5, kTrigTolerance);
}

TEST(RotationTrigTest, NanGivesNanAndLeavesItsNeighboursAlone) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // NaN inside a full group of eight and in the last, shorter one.
  const std::vector<double> degrees = {1.0, nan, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, nan};
  std::vector<double> cosines(degrees.size()), sines(degrees.size());

  ForwardKinematics::RotationTrig(degrees, cosines, sines);

  for (std::size_t i = 0; i < degrees.size(); ++i) {
    if (std::isnan(degrees[i])) {
      EXPECT_TRUE(std::isnan(cosines[i]) && std::isnan(sines[i])) << i;
    } else {
      const double r = degrees[i] * (std::numbers::pi / 180.0);
      EXPECT_NEAR(cosines[i], std::cos(r), kTrigTolerance) << i;
      EXPECT_NEAR(sines[i], std::sin(r), kTrigTolerance) << i;
    }
  }
}

TEST(RotationTrigTest, NoAnglesWritesNothing) {
  const std::vector<double> degrees = {30.0};
  std::vector<double> cosines = {-7.0}, sines = {-7.0};

  ForwardKinematics::RotationTrig(std::span(degrees).first(0), std::span(cosines).first(0),
                                  std::span(sines).first(0));

  EXPECT_EQ(cosines[0], -7.0);
  EXPECT_EQ(sines[0], -7.0);
}

TEST(RotationTrigTest, AnAngleHasTheSameBitsWhereverItSitsInTheSpan) {
  const std::vector<double> degrees = TrigAngles();
  std::vector<double> cosines(degrees.size()), sines(degrees.size());
  ForwardKinematics::RotationTrig(degrees, cosines, sines);

  for (std::size_t i = 0; i < degrees.size(); ++i) {
    double c = 0.0, s = 0.0;
    ForwardKinematics::RotationTrig({&degrees[i], 1}, {&c, 1}, {&s, 1});
    EXPECT_EQ(std::bit_cast<std::uint64_t>(c), std::bit_cast<std::uint64_t>(cosines[i]));
    EXPECT_EQ(std::bit_cast<std::uint64_t>(s), std::bit_cast<std::uint64_t>(sines[i]));
  }
}

}  // namespace
}  // namespace tempokey::core
