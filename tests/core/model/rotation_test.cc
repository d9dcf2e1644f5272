#include "tempokey/core/model/rotation.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "gtest/gtest.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// Products of a few rotation matrices / quaternions in doubles agree to a few ulps of 1.
constexpr double kRoundingTolerance = 1e-13;
// Euler angles recovered through atan2 of matrix entries: a few ulps of 180 degrees, amplified
// by 1 / cos(middle angle) for middle angles up to 80 degrees.
constexpr double kAngleTolerance = 1e-9;

const EulerOrder kAllOrders[] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};

double MaxMatrixDifference(const Mat3& a, const Mat3& b) {
  double worst = 0.0;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) worst = std::max(worst, std::abs(a[i][j] - b[i][j]));
  }
  return worst;
}

TEST(RotationTest, EulerOrderIsComposedLeftToRightLikeBvh) {
  // ZXY with (90, 90, 0) is Rz(90)·Rx(90): +Y goes to +Z under Rx(90), which Rz leaves alone.
  const Vec3 y_axis = {0.0, 1.0, 0.0};

  const Vec3 zxy = MatVec(EulerToMatrix({2, 0, 1}, {90.0, 90.0, 0.0}), y_axis);
  // XZY with (90, 90, 0) is Rx(90)·Rz(90): +Y goes to -X under Rz(90), which Rx leaves alone.
  const Vec3 xzy = MatVec(EulerToMatrix({0, 2, 1}, {90.0, 90.0, 0.0}), y_axis);

  EXPECT_NEAR(zxy[0], 0.0, kRoundingTolerance);
  EXPECT_NEAR(zxy[1], 0.0, kRoundingTolerance);
  EXPECT_NEAR(zxy[2], 1.0, kRoundingTolerance);
  EXPECT_NEAR(xzy[0], -1.0, kRoundingTolerance);
  EXPECT_NEAR(xzy[1], 0.0, kRoundingTolerance);
  EXPECT_NEAR(xzy[2], 0.0, kRoundingTolerance);
}

TEST(RotationTest, QuaternionOfEulerAnglesMatchesMatrixForAllSixOrders) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> angle(-180.0, 180.0);

  for (const EulerOrder& order : kAllOrders) {
    for (int trial = 0; trial < 200; ++trial) {
      const Vec3 degrees = {angle(rng), angle(rng), angle(rng)};

      const Mat3 from_quat = QuatToMatrix(EulerToQuat(order, degrees));
      const Mat3 direct = EulerToMatrix(order, degrees);

      ASSERT_LT(MaxMatrixDifference(from_quat, direct), kRoundingTolerance)
          << EulerOrderName(order);
    }
  }
}

TEST(RotationTest, EulerAnglesRoundTripThroughQuaternionsForAllSixOrders) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> outer(-179.0, 179.0);
  std::uniform_real_distribution<double> middle(-80.0, 80.0);

  for (const EulerOrder& order : kAllOrders) {
    for (int trial = 0; trial < 200; ++trial) {
      const Vec3 degrees = {outer(rng), middle(rng), outer(rng)};

      const Vec3 back = QuatToEulerNearest(EulerToQuat(order, degrees), order, degrees);

      for (int k = 0; k < 3; ++k) {
        ASSERT_NEAR(back[k], degrees[k], kAngleTolerance) << EulerOrderName(order) << " " << k;
      }
    }
  }
}

TEST(RotationTest, NearestSolutionKeepsTheReferencesTurn) {
  const EulerOrder zxy = {2, 0, 1};
  const Quat q = EulerToQuat(zxy, {190.0, 10.0, -5.0});

  const Vec3 unwrapped = QuatToEulerNearest(q, zxy, {185.0, 12.0, 0.0});
  const Vec3 wrapped = QuatToEulerNearest(q, zxy, {-175.0, 12.0, 0.0});
  const Vec3 two_turns = QuatToEulerNearest(q, zxy, {900.0, 12.0, 0.0});

  EXPECT_NEAR(unwrapped[0], 190.0, kAngleTolerance);
  EXPECT_NEAR(wrapped[0], -170.0, kAngleTolerance);
  EXPECT_NEAR(two_turns[0], 910.0, kAngleTolerance);
  EXPECT_NEAR(unwrapped[1], 10.0, kAngleTolerance);
  EXPECT_NEAR(unwrapped[2], -5.0, kAngleTolerance);
}

TEST(RotationTest, NearestSolutionPicksTheOtherBranchWhenTheReferenceIsThere) {
  // (a, b, c) and (a + 180, 180 - b, c + 180) are the same rotation for every Tait-Bryan order.
  const EulerOrder xyz = {0, 1, 2};
  const Vec3 first = {20.0, 30.0, 40.0};
  const Vec3 second = {200.0, 150.0, 220.0};
  ASSERT_LT(MaxMatrixDifference(EulerToMatrix(xyz, first), EulerToMatrix(xyz, second)),
            kRoundingTolerance);

  const Vec3 near_second = QuatToEulerNearest(EulerToQuat(xyz, first), xyz, {195.0, 155.0, 215.0});

  EXPECT_NEAR(near_second[0], 200.0, kAngleTolerance);
  EXPECT_NEAR(near_second[1], 150.0, kAngleTolerance);
  EXPECT_NEAR(near_second[2], 220.0, kAngleTolerance);
}

TEST(RotationTest, GimbalLockKeepsTheReferenceFirstAngleAndSolvesTheLast) {
  // At a middle angle of 90 degrees only a + c (XYZ) is defined.
  const EulerOrder xyz = {0, 1, 2};
  const Quat q = EulerToQuat(xyz, {30.0, 90.0, 40.0});

  const Vec3 angles = QuatToEulerNearest(q, xyz, {50.0, 90.0, 0.0});

  EXPECT_NEAR(angles[0], 50.0, kAngleTolerance);
  EXPECT_NEAR(angles[1], 90.0, kAngleTolerance);
  EXPECT_NEAR(angles[2], 20.0, kAngleTolerance);
  EXPECT_LT(MaxMatrixDifference(EulerToMatrix(xyz, angles), QuatToMatrix(q)), kAngleTolerance);
}

TEST(RotationTest, SlerpHalfwayIsTheHalfAngleAndEndpointsAreExact) {
  const Quat a = AxisRotation(2, 0.0);
  const Quat b = AxisRotation(2, 90.0);

  const Quat half = Slerp(a, b, 0.5);
  const Quat from_negated = Slerp(a, Negated(b), 0.5);

  EXPECT_LT(AngleBetweenDegrees(half, AxisRotation(2, 45.0)), kAngleTolerance);
  EXPECT_LT(AngleBetweenDegrees(from_negated, AxisRotation(2, 45.0)), kAngleTolerance);
  EXPECT_EQ(Slerp(a, b, 0.0), a);
  EXPECT_EQ(Slerp(a, b, 1.0), b);
}

TEST(RotationTest, SlerpOfSmallStepsIsTheUniformRotationToRounding) {
  // Below half a radian the sin ratios come from a series; it must agree with the uniform
  // rotation to rounding, as the large-angle formula does.
  for (double degrees : {1e-7, 0.01, 3.0, 20.0, 28.0, 29.0, 60.0, 170.0}) {
    for (double t : {0.1, 0.37, 0.5, 0.93}) {
      const Quat q = Slerp(AxisRotation(1, 10.0), AxisRotation(1, 10.0 + degrees), t);
      const Quat expected = AxisRotation(1, 10.0 + t * degrees);

      EXPECT_NEAR(q.w, expected.w, 1e-15) << degrees << " " << t;
      EXPECT_NEAR(q.y, expected.y, 1e-15) << degrees << " " << t;
    }
  }
}

TEST(RotationTest, NearestTurnMovesByWholeTurnsToWithinHalfATurn) {
  EXPECT_EQ(NearestTurn(190.0, 0.0), -170.0);
  EXPECT_EQ(NearestTurn(-170.0, 185.0), 190.0);
  EXPECT_EQ(NearestTurn(10.0, 725.0), 730.0);
  EXPECT_EQ(NearestTurn(42.5, 42.0), 42.5);
}

TEST(RotationTest, SquadOnEvenlySpacedRotationsKeepsConstantAngularSpeed) {
  // Rotations 10 degrees apart about one axis: the spherical cubic is the uniform rotation.
  const Quat q0 = AxisRotation(0, 0.0);
  const Quat q1 = AxisRotation(0, 10.0);
  const Quat q2 = AxisRotation(0, 20.0);
  const Quat q3 = AxisRotation(0, 30.0);

  for (double t : {0.0, 0.25, 0.5, 0.9, 1.0}) {
    const Quat q = Squad(q0, q1, q2, q3, t);

    EXPECT_LT(AngleBetweenDegrees(q, AxisRotation(0, 10.0 + 10.0 * t)), kAngleTolerance) << t;
  }
}

TEST(RotationTest, WeightedMeanOfSymmetricRotationsIsTheCentre) {
  const std::vector<Quat> quats = {AxisRotation(1, -10.0), AxisRotation(1, 0.0),
                                   Negated(AxisRotation(1, 10.0))};
  const std::vector<double> weights = {0.25, 0.5, 0.25};

  const Quat mean = WeightedMeanRotation(quats, weights, 1);

  EXPECT_LT(AngleBetweenDegrees(mean, Quat{}), kAngleTolerance);
  EXPECT_GT(mean.w, 0.0);
}

TEST(RotationTest, WidelySpreadRotationsUseMarkleysMean) {
  // 80 degrees either side: beyond the 30-degree spread, so the eigenvector mean is used; by
  // symmetry it is the identity, and it agrees with the direct eigen-solution.
  const std::vector<Quat> quats = {AxisRotation(2, -80.0), AxisRotation(2, 80.0)};
  const std::vector<double> weights = {0.5, 0.5};

  const Quat mean = WeightedMeanRotation(quats, weights, 0);
  const Quat markley = MarkleyMean(quats, weights, 0);

  EXPECT_LT(AngleBetweenDegrees(mean, Quat{}), kAngleTolerance);
  EXPECT_LT(AngleBetweenDegrees(markley, Quat{}), kAngleTolerance);
}

TEST(RotationTest, MarkleyMeanOfUnevenWeightsLiesOnTheGeodesic) {
  // Markley maximizes Σ w (q·m)²; for unit 4-vectors at angles 0 and θ in one plane (θ the
  // half-angle of the second rotation) the maximizer is at φ with
  // tan(2φ) = w1 sin 2θ / (w0 + w1 cos 2θ), i.e. the rotation by 2φ about the same axis.
  const double theta = 50.0 * std::numbers::pi / 180.0;
  const std::vector<Quat> quats = {AxisRotation(0, 0.0), AxisRotation(0, 100.0)};
  const std::vector<double> weights = {0.7, 0.3};
  const double phi =
      0.5 * std::atan(0.3 * std::sin(2 * theta) / (0.7 + 0.3 * std::cos(2 * theta)));
  const Quat expected = AxisRotation(0, 2.0 * phi * 180.0 / std::numbers::pi);

  const Quat mean = MarkleyMean(quats, weights, 0);

  EXPECT_LT(AngleBetweenDegrees(mean, expected), kAngleTolerance);
}

TEST(RotationTest, SignContinuityNegatesOnlyFlippedNeighbours) {
  std::vector<Quat> quats = {AxisRotation(2, 170.0), Negated(AxisRotation(2, 190.0)),
                             AxisRotation(2, 200.0)};
  // AxisRotation(2, 190) has w = cos(95°) < 0; its negation is the nearer sign already.

  MakeSignContinuous(quats);

  EXPECT_GE(Dot(quats[0], quats[1]), 0.0);
  EXPECT_GE(Dot(quats[1], quats[2]), 0.0);
}

TEST(RotationTest, UnwrapDegreesRemovesSeamsAndKeepsTheFirstSample) {
  std::vector<double> angles = {170.0, 179.0, -179.0, -170.0, 175.0};

  UnwrapDegrees(angles);

  EXPECT_EQ(angles, (std::vector<double>{170.0, 179.0, 181.0, 190.0, 175.0}));
}

// What WrapDegrees() promises, written out with the C library's IEEE remainder.
double RemainderWrap(double v) {
  const double w = std::remainder(v, 360.0);
  return w == -180.0 ? 180.0 : w;
}

// The bits of WrapDegrees(values) against RemainderWrap() value by value (NaN as any NaN).
void ExpectWrapsLikeRemainder(std::vector<double> values) {
  const std::vector<double> input = values;
  WrapDegrees(values);
  for (std::size_t i = 0; i < input.size(); ++i) {
    const double expected = RemainderWrap(input[i]);
    if (std::isnan(expected)) {
      EXPECT_TRUE(std::isnan(values[i])) << "input " << input[i];
    } else {
      EXPECT_EQ(std::bit_cast<std::uint64_t>(values[i]), std::bit_cast<std::uint64_t>(expected))
          << std::hexfloat << "input " << input[i] << ": " << values[i] << " against "
          << expected;
    }
  }
}

TEST(RotationTest, WrapDegreesTakesMinus180As180AndKeepsAZerosSign) {
  std::vector<double> angles = {-180.0, 540.0, 180.0, -720.0, 720.0, -0.0, 190.0, -190.0};

  WrapDegrees(angles);

  EXPECT_EQ(angles, (std::vector<double>{180.0, 180.0, 180.0, 0.0, 0.0, 0.0, -170.0, 170.0}));
  EXPECT_TRUE(std::signbit(angles[3]));   // -720: a zero with v's sign, as remainder gives
  EXPECT_FALSE(std::signbit(angles[4]));
  EXPECT_TRUE(std::signbit(angles[5]));
}

TEST(RotationTest, WrapDegreesGivesTheBitsOfRemainderNearEveryHalfTurnAndAtEveryScale) {
  // Half turns and their neighbours a few ulps away, where v / 360 rounds next to a half and
  // the quotient may land one turn off; up to the largest samples a clip may hold (1e9) and on
  // to where the exact way ends (2^51).
  std::vector<double> values;
  for (double k : {1.0, 2.0, 3.0, 5.0, 7.0, 1001.0, 4097.0, 5555555.0, 5555556.0, 0x1p40,
                   0x1p40 + 1.0, 0x1p43 - 1.0, 0x1p43}) {
    for (double sign : {1.0, -1.0}) {
      double v = sign * 180.0 * k;
      for (int step = 0; step < 4; ++step) v = std::nextafter(v, 0.0);
      for (int step = 0; step < 9; ++step) {
        values.push_back(v);
        v = std::nextafter(v, sign * std::numeric_limits<double>::infinity());
      }
    }
  }
  std::mt19937_64 random(20261203);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-1074, 50);
  for (double scale : {400.0, 1e4, 1e9}) {
    for (int i = 0; i < 20000; ++i) values.push_back(scale * unit(random));
  }
  for (int i = 0; i < 20000; ++i) values.push_back(std::ldexp(unit(random), exponent(random)));
  for (double v : {0.0, -0.0, 0x1p-1074, -0x1p-1074, 1e-310, 127.99999999999999, 128.0,
                   0x1.fffffffffffffp50, -0x1.fffffffffffffp50}) {
    values.push_back(v);
  }
  // Every value within the exact way's range: the vector loop over the whole array (an odd
  // length, so its scalar end runs too).
  values.push_back(1.0);
  ExpectWrapsLikeRemainder(values);
  // The same values beside ones past it, and infinities and NaN: sample by sample, the larger
  // through std::remainder. 2^60 and 1e20 are where the four operations would go wrong (-256 for
  // 136, 0 for -80), and 2^51 + 172 where remainder gives -180, so the fallback and its
  // -180 -> 180 are pinned.
  for (double v : {0x1p51, -0x1p51, 0x1p60, 1e20, 0x1.0000000000158p+51, 1e300, -1e300,
                   std::numeric_limits<double>::infinity(),
                   -std::numeric_limits<double>::infinity(),
                   std::numeric_limits<double>::quiet_NaN()}) {
    values.push_back(v);
  }
  ExpectWrapsLikeRemainder(values);
  std::vector<double> beyond = {0x1p60, 1e20, 0x1.0000000000158p+51};
  WrapDegrees(beyond);
  EXPECT_EQ(beyond, (std::vector<double>{136.0, -80.0, 180.0}));
}

TEST(RotationTest, WrapDegreesMendsAQuotientRoundedOneTurnOff) {
  // 1980 less an ulp: v / 360 rounds to 5.5 and on to 6, one turn past the nearest (5).
  std::vector<double> angles = {0x1.eefffffffffffp+10, -0x1.eefffffffffffp+10};

  WrapDegrees(angles);

  EXPECT_EQ(angles, (std::vector<double>{180.0 - 0x1p-42, -(180.0 - 0x1p-42)}));
}

TEST(RotationTest, WrapDegreesTakesEmptyAndShortArrays) {
  ExpectWrapsLikeRemainder({});
  ExpectWrapsLikeRemainder({190.0});
  ExpectWrapsLikeRemainder({190.0, -540.0});
  ExpectWrapsLikeRemainder({190.0, -540.0, std::numeric_limits<double>::quiet_NaN()});
}

TEST(RotationTest, ParseEulerOrderAcceptsDistinctAxesOnly) {
  const absl::StatusOr<EulerOrder> zxy = ParseEulerOrder("ZXY");
  const absl::StatusOr<EulerOrder> bad = ParseEulerOrder("XXY");

  ASSERT_TRUE(zxy.ok());
  EXPECT_EQ(*zxy, (EulerOrder{2, 0, 1}));
  EXPECT_EQ(bad.status().message(), "euler order 'XXY': needs three distinct axes from X, Y, Z");
}

}  // namespace
}  // namespace tempokey::core
