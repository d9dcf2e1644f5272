// NoCubicWithin() (core/src/reduce/cubic_certificate.h), the proof the tolerance fit's removal
// uses to skip trials: it never claims a stretch that some cubic does come within the bound of
// (samples built as a cubic plus less than the bound, also in the worst signs at its five frames),
// and it claims a lone spike exactly when the spike's closed-form minimax error over the five
// frames exceeds the bound by the margin.
#include "core/src/reduce/cubic_certificate.h"

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "gtest/gtest.h"

namespace tempokey::core::reduce_internal {
namespace {

// Samples of c0 + c1 x + c2 x^2 + c3 x^3 (x in frames) plus noise within +-noise, frames [0, n).
std::vector<double> CubicWithNoise(std::mt19937_64& rng, std::int64_t n, double scale,
                                   double noise) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const double span = static_cast<double>(n);
  const double c0 = scale * unit(rng);
  const double c1 = scale * unit(rng) / span;
  const double c2 = scale * unit(rng) / (span * span);
  const double c3 = scale * unit(rng) / (span * span * span);
  std::vector<double> s(static_cast<std::size_t>(n));
  for (std::int64_t k = 0; k < n; ++k) {
    const auto x = static_cast<double>(k);
    s[static_cast<std::size_t>(k)] = c0 + x * (c1 + x * (c2 + x * c3)) + noise * unit(rng);
  }
  return s;
}

TEST(CubicCertificateTest, NeverClaimsAStretchThatACubicComesWithinTheBoundOf) {
  std::mt19937_64 rng(20261202);
  const double bound = 0.5;
  int checked = 0;
  // Values from a degree to the certificate's reach, noise up to just under the bound, and
  // stretches from the shortest to beyond the table of weights.
  for (double scale : {1.0, 180.0, 1e4, 0.2 * kCertificateReach * bound}) {
    for (std::int64_t length : {4, 5, 7, 12, 31, 255, 256, 300, 4096}) {
      for (int round = 0; round < 200; ++round) {
        const std::vector<double> s = CubicWithNoise(rng, length + 3, scale, 0.999 * bound);
        const std::int64_t a = round % 3;
        ASSERT_FALSE(NoCubicWithin(s.data(), a, a + length, bound))
            << "scale " << scale << ", length " << length << ", round " << round;
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 4 * 9 * 200);
}

TEST(CubicCertificateTest, NeverClaimsACubicWithNoiseJustUnderTheBoundInTheWorstSigns) {
  // Noise of 0.999 bounds alternating in sign at the five frames: the divided difference's
  // largest possible value for a stretch some cubic is within the bound of.
  std::mt19937_64 rng(7);
  const double bound = 0.5;
  for (double scale : {1.0, 180.0, 1e4}) {
    for (std::int64_t length : {4, 6, 13, 64, 255, 256, 1000, 4096}) {
      for (int round = 0; round < 50; ++round) {
        std::vector<double> s = CubicWithNoise(rng, length + 1, scale, 0.0);
        for (int j = 0; j < 5; ++j) {
          const double sign = j % 2 == 0 ? 1.0 : -1.0;
          s[static_cast<std::size_t>(SpreadFrame(j, length))] += sign * 0.999 * bound;
        }
        ASSERT_FALSE(NoCubicWithin(s.data(), 0, length, bound))
            << "scale " << scale << ", length " << length << ", round " << round;
      }
    }
  }
}

TEST(CubicCertificateTest, ClaimsALoneSpikeExactlyWhenItsMinimaxErrorExceedsTheMarginedBound) {
  // Eight frames: the five frames are 0, 2, 4, 6, 8, the divided difference's weights
  // (1, -4, 6, -4, 1) / 16. A spike h at frame 4 on zeros is 6h/16 from the best cubic on those
  // frames (the error alternates +-6h/16 there), so a proof exists iff 6h/16 > the bound; the
  // certificate claims it once 6h/16 exceeds the bound times its margin of 1.01 (h > 1.3467).
  const double bound = 0.5;
  for (double h : {0.5, 1.3, 1.334, 1.346, 1.348, 1.4, 2.0, 20.0}) {
    std::vector<double> s(9, 0.0);
    s[4] = h;
    const bool expected = h > 1.3467;
    EXPECT_EQ(NoCubicWithin(s.data(), 0, 8, bound), expected) << "spike " << h;
  }
}

TEST(CubicCertificateTest, ClaimsNothingForABoundAmongTheSmallestDoubles) {
  // A spike a hundred times the bound, for a bound where the margin itself would round away.
  const double bound = 1e-300;
  std::vector<double> s(9, 0.0);
  s[4] = 100.0 * bound;
  EXPECT_FALSE(NoCubicWithin(s.data(), 0, 8, bound));
  // The same shape at an ordinary bound is claimed.
  s[4] = 100.0;
  EXPECT_TRUE(NoCubicWithin(s.data(), 0, 8, 1.0));
}

TEST(CubicCertificateTest, ClaimsNothingForSamplesBeyondItsReach) {
  // A spike far over the bound, on samples beyond the certificate's reach: no claim.
  std::vector<double> s(9, 2.0 * kCertificateReach);
  s[4] += 1e3;
  EXPECT_FALSE(NoCubicWithin(s.data(), 0, 8, 1.0));
  // The same spike on small samples is claimed.
  std::vector<double> small(9, 0.0);
  small[4] = 1e3;
  EXPECT_TRUE(NoCubicWithin(small.data(), 0, 8, 1.0));
}

TEST(CubicCertificateTest, SpreadFramesAreDistinctAndCoverTheStretch) {
  for (std::int64_t length = 4; length <= 4096; ++length) {
    EXPECT_EQ(SpreadFrame(0, length), 0);
    EXPECT_EQ(SpreadFrame(4, length), length);
    for (int j = 1; j < 5; ++j) ASSERT_LT(SpreadFrame(j - 1, length), SpreadFrame(j, length));
  }
}

TEST(CubicCertificateTest, WeightsAnnihilateCubicsAndSumToOneInMagnitude) {
  for (std::int64_t length : {4, 9, 100, 255, 256, 4096}) {
    const FivePointWeights w = DividedDifferenceWeights(length);
    double magnitude = 0.0;
    for (double x : w) magnitude += std::abs(x);
    EXPECT_NEAR(magnitude, 1.0, 1e-15);
    for (int power = 0; power <= 3; ++power) {
      double sum = 0.0;
      double scale = 0.0;
      for (int j = 0; j < 5; ++j) {
        const double term = w[j] * std::pow(static_cast<double>(SpreadFrame(j, length)), power);
        sum += term;
        scale += std::abs(term);
      }
      EXPECT_LE(std::abs(sum), 1e-13 * scale) << "length " << length << ", power " << power;
    }
    // A fourth power is not annihilated: the weights measure what a cubic cannot follow.
    double quartic = 0.0;
    for (int j = 0; j < 5; ++j) {
      quartic += w[j] * std::pow(static_cast<double>(SpreadFrame(j, length)), 4);
    }
    EXPECT_GT(std::abs(quartic), 0.0);
  }
}

}  // namespace
}  // namespace tempokey::core::reduce_internal
