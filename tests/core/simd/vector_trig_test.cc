// The vectorised sine, cosine and arctangent of the batched rotation conversions, against x87
// long-double libm (sinl, cosl, atan2l: 64-bit significands, far more exact than a double) as
// the oracle: within kMaxUlps units in the last place of the double nearest the true value, over
// the ranges the conversions use and at the special values.
#include "core/src/simd/vector_trig.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "gtest/gtest.h"

#pragma GCC diagnostic ignored "-Wpsabi"

namespace tempokey::core::vector_trig {
namespace {

// As documented in vector_trig.h: the reduction of large arguments and the polynomial each round.
constexpr double kMaxUlps = 2.5;

// |got - exact| in units in the last place of the double nearest `exact`.
double UlpError(double got, long double exact) {
  const double nearest = static_cast<double>(exact);
  if (nearest == 0.0) return got == 0.0 ? 0.0 : std::numeric_limits<double>::infinity();
  const double ulp = std::nextafter(std::abs(nearest), std::numeric_limits<double>::infinity()) -
                     std::abs(nearest);
  return static_cast<double>(std::abs(static_cast<long double>(got) - exact) / ulp);
}

struct Worst {
  double ulps = 0.0;
  double at_x = 0.0;
  double at_y = 0.0;
  void Add(double ulps_here, double x, double y = 0.0) {
    if (ulps_here > ulps) {
      ulps = ulps_here;
      at_x = x;
      at_y = y;
    }
  }
};

void SinCosOf(const std::vector<double>& xs, Worst& sine, Worst& cosine) {
  for (std::size_t i = 0; i + 4 <= xs.size(); i += 4) {
    const V4 x = {xs[i], xs[i + 1], xs[i + 2], xs[i + 3]};
    V4 s, c;
    SinCos(x, s, c);
    for (int lane = 0; lane < 4; ++lane) {
      const long double exact_x = x[lane];
      sine.Add(UlpError(s[lane], sinl(exact_x)), x[lane]);
      cosine.Add(UlpError(c[lane], cosl(exact_x)), x[lane]);
    }
  }
}

TEST(VectorTrigTest, SmallArgumentsSkipTheReductionWithTheSameBits) {
  std::mt19937_64 random(20261124);
  std::uniform_real_distribution<double> small(-kMaxUnreducedRadians, kMaxUnreducedRadians);
  std::vector<double> xs = {0.0, -0.0, 1e-300, -1e-300, 0.5, -0.5,
                            std::nextafter(kMaxUnreducedRadians, 0.0),
                            -std::nextafter(kMaxUnreducedRadians, 0.0)};
  while (xs.size() < 4000) xs.push_back(small(random));
  auto bits = [](double v) { return std::bit_cast<std::uint64_t>(v); };
  for (std::size_t i = 0; i + 4 <= xs.size(); i += 4) {
    const V4 x[1] = {{xs[i], xs[i + 1], xs[i + 2], xs[i + 3]}};
    V4 s[1], c[1], small_s[1], small_c[1];
    SinCos<1>(x, s, c);
    SinCosSmall<1>(x, small_s, small_c);
    for (int lane = 0; lane < 4; ++lane) {
      EXPECT_EQ(bits(small_s[0][lane]), bits(s[0][lane])) << "sine at " << x[0][lane];
      EXPECT_EQ(bits(small_c[0][lane]), bits(c[0][lane])) << "cosine at " << x[0][lane];
    }
  }
}

TEST(VectorTrigTest, SineAndCosineWithinTwoAndAHalfUlpsOverHalfAnglesOfRotations) {
  std::mt19937_64 random(20240611);
  // Half angles of Euler angles in radians: +-pi covers +-360 degrees; unwrapped channels reach
  // thousands of degrees.
  std::uniform_real_distribution<double> small(-3.5, 3.5);
  std::uniform_real_distribution<double> large(-200.0, 200.0);
  std::vector<double> xs;
  for (int i = 0; i < 400000; ++i) xs.push_back(i % 4 == 3 ? large(random) : small(random));
  for (double special : {0.0, -0.0, 1e-300, -1e-20, 0.7853981633974483, -0.7853981633974483,
                         1.5707963267948966, 3.141592653589793, -3.141592653589793,
                         2.356194490192345, 1e-8, 100.0, 1e6, -9.9e6}) {
    xs.push_back(special);
  }
  while (xs.size() % 4 != 0) xs.push_back(0.5);

  Worst sine, cosine;
  SinCosOf(xs, sine, cosine);

  EXPECT_LE(sine.ulps, kMaxUlps) << "sin(" << sine.at_x << ")";
  EXPECT_LE(cosine.ulps, kMaxUlps) << "cos(" << cosine.at_x << ")";
}

TEST(VectorTrigTest, ArctangentWithinTwoAndAHalfUlpsOverEveryQuadrantAndScale) {
  std::mt19937_64 random(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_real_distribution<double> exponent(-30.0, 30.0);
  std::vector<std::pair<double, double>> points;
  for (int i = 0; i < 400000; ++i) {
    const double y = unit(random);
    const double x = unit(random) * (i % 3 == 0 ? std::pow(2.0, exponent(random)) : 1.0);
    points.emplace_back(y, x);
  }
  // Axes, diagonals, the reduction's boundaries (tan(pi/8)), signed zeros, subnormals (where
  // the reduction, chosen on the operands, needs them scaled).
  for (double y : {0.0, -0.0, 1.0, -1.0, 0.41421356237309503, 0.4142135623730951, 1e-310, 5e-324,
                   1e-323, -2e-323, 4e-309}) {
    for (double x : {0.0, -0.0, 1.0, -1.0, 2.414213562373095, 1e-310, 5e-324, 1e-323, -3e-323,
                     1e-308}) {
      points.emplace_back(y, x);
    }
  }
  while (points.size() % 4 != 0) points.emplace_back(0.25, 0.5);

  Worst worst;
  for (std::size_t i = 0; i < points.size(); i += 4) {
    V4 y, x;
    for (int lane = 0; lane < 4; ++lane) {
      y[lane] = points[i + lane].first;
      x[lane] = points[i + lane].second;
    }
    const V4 got = Atan2(y, x);
    for (int lane = 0; lane < 4; ++lane) {
      const long double exact = atan2l(y[lane], x[lane]);
      if (exact == 0.0L) {
        EXPECT_EQ(got[lane], 0.0) << "atan2(" << y[lane] << ", " << x[lane] << ")";
        EXPECT_EQ(std::signbit(got[lane]), std::signbit(exact)) << y[lane] << ", " << x[lane];
        continue;
      }
      worst.Add(UlpError(got[lane], exact), y[lane], x[lane]);
    }
  }

  EXPECT_LE(worst.ulps, kMaxUlps) << "atan2(" << worst.at_x << ", " << worst.at_y << ")";
}

TEST(VectorTrigTest, ArctangentKeepsStdAtan2SignedZerosAndPi) {
  const V4 y = {0.0, -0.0, 0.0, -0.0};
  const V4 x = {0.0, 0.0, -0.0, -0.0};

  const V4 got = Atan2(y, x);

  for (int lane = 0; lane < 4; ++lane) {
    const double expected = std::atan2(y[lane], x[lane]);
    EXPECT_EQ(got[lane], expected) << lane;
    EXPECT_EQ(std::signbit(got[lane]), std::signbit(expected)) << lane;
  }
}

}  // namespace
}  // namespace tempokey::core::vector_trig
