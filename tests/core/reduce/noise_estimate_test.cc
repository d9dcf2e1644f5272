// The noise estimate (EstimateNoiseSigma(), noise_fit.h step 1) against closed forms: white
// Gaussian noise of known sigma reads sigma at any difference order, smooth motion at a capture
// rate reads 0, and their sum reads the noise.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "tempokey/core/reduce/noise_fit.h"

namespace tempokey::core {
namespace {

constexpr double kRate = 30.0;  // frames per second of the motions below

std::vector<double> WhiteNoise(int frames, double sigma, unsigned seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  std::vector<double> v(static_cast<std::size_t>(frames));
  for (double& x : v) x = noise(random);
  return v;
}

// amplitude * sin(2 pi hz t + phase) sampled at kRate, degrees.
std::vector<double> Sinusoid(int frames, double amplitude, double hz, double phase) {
  std::vector<double> v;
  for (int f = 0; f < frames; ++f) {
    v.push_back(amplitude * std::sin(2.0 * std::numbers::pi * hz * f / kRate + phase));
  }
  return v;
}

std::vector<double> Sum(std::vector<double> a, const std::vector<double>& b) {
  for (std::size_t i = 0; i < a.size(); ++i) a[i] += b[i];
  return a;
}

// The estimator this one replaced: median |third difference| / (0.6745 sqrt(20)), written here
// from its definition to show what the motion alone did to it.
double ThirdDifferenceEstimate(const std::vector<double>& x) {
  std::vector<double> d;
  for (std::size_t f = 0; f + 3 < x.size(); ++f) {
    d.push_back(std::abs(x[f + 3] - 3.0 * x[f + 2] + 3.0 * x[f + 1] - x[f]));
  }
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
  return d[d.size() / 2] / (0.6744897501960817 * std::sqrt(20.0));
}

TEST(NoiseEstimateTest, GaussianNoiseOfKnownSigmaReadsThatSigma) {
  // 5000 samples: the median of the correlated third differences has a standard error near 2 %.
  for (double sigma : {0.01, 0.5, 3.0}) {
    EXPECT_NEAR(EstimateNoiseSigma(WhiteNoise(5000, sigma, 11)), sigma, 0.05 * sigma) << sigma;
  }
}

TEST(NoiseEstimateTest, ShortWhiteNoiseIsNotMistakenForMotion) {
  // The whiteness gate allows for the white fraction's spread at each length: over 200 series
  // the median estimate stays sigma and at most a few per cent of series lose part of it.
  for (int frames : {60, 120, 250, 1000}) {
    std::vector<double> estimates;
    int reduced = 0;
    for (unsigned seed = 0; seed < 200; ++seed) {
      const std::vector<double> noise = WhiteNoise(frames, 1.0, 1000 + seed);
      const double estimate = EstimateNoiseSigma(noise);
      estimates.push_back(estimate);
      // The gate took part of the level: the estimate is below the plain third-difference one.
      if (estimate < ThirdDifferenceEstimate(noise) * (1.0 - 1e-12)) ++reduced;
    }
    std::sort(estimates.begin(), estimates.end());
    EXPECT_NEAR(estimates[100], 1.0, 0.05) << frames << " frames";
    EXPECT_LE(reduced, 10) << frames << " frames";  // 5 % of 200
  }
}

TEST(NoiseEstimateTest, SmoothMotionAtCaptureRateReadsZero) {
  // Sinusoids of 0.5 to 4 Hz at 30 fps, 30 degrees: their third differences (amplitude
  // 30 (2 sin(pi hz / 30))^3, 0.27 degrees at 1 Hz, 16 at 4 Hz) are motion, and the old
  // third-difference estimate read them as noise.
  for (double hz : {0.5, 1.0, 2.0, 4.0}) {
    const std::vector<double> motion = Sinusoid(600, 30.0, hz, 0.3);

    EXPECT_LT(EstimateNoiseSigma(motion), 1e-9) << hz << " Hz";
    EXPECT_GT(ThirdDifferenceEstimate(motion), 0.005) << hz << " Hz";
  }
}

TEST(NoiseEstimateTest, PolynomialMotionReadsZero) {
  // A cubic has constant third differences (6 * 0.002 here), which the third-difference estimate
  // takes for noise of 0.012 / (0.6745 sqrt 20) = 0.004; its sixth differences are 0.
  std::vector<double> cubic, quintic;
  for (int f = 0; f < 300; ++f) {
    const double t = f / kRate;
    cubic.push_back(0.002 * f * f * f - 0.3 * f * f + 2.0 * f);
    quintic.push_back(40.0 * std::pow(t - 5.0, 5) / 3125.0 - 12.0 * (t - 5.0) * (t - 5.0));
  }

  EXPECT_NEAR(ThirdDifferenceEstimate(cubic), 0.012 / (0.6744897501960817 * std::sqrt(20.0)),
              1e-6);
  EXPECT_LT(EstimateNoiseSigma(cubic), 1e-9);
  EXPECT_LT(EstimateNoiseSigma(quintic), 1e-9);
}

TEST(NoiseEstimateTest, NoiseOnSmoothMotionReadsTheNoise) {
  // 1 Hz at 30 degrees and 2 Hz at 10 degrees add about 0.015 deg^2 to the normalised third
  // differences' variance (s_3 alone reads 0.33 for noise of 0.3) and almost nothing to the sixth
  // differences': the estimate keeps of the motion's part only the white fraction's sampling
  // allowance (4.3 / sqrt(12000) of s_3^2), within 5 %.
  constexpr int kFrames = 12000;
  const std::vector<double> motion = Sum(Sinusoid(kFrames, 30.0, 1.0, 0.0),
                                         Sinusoid(kFrames, 10.0, 2.0, 1.0));
  for (double sigma : {0.3, 0.5, 1.0}) {
    const double estimate = EstimateNoiseSigma(Sum(motion, WhiteNoise(kFrames, sigma, 21)));

    EXPECT_NEAR(estimate, sigma, 0.05 * sigma) << sigma;
  }
}

TEST(NoiseEstimateTest, NoiseFarBelowTheMotionsThirdDifferencesIsTakenAsMotion) {
  // 3 Hz at 30 degrees has third differences of amplitude 7.1 degrees: noise of 0.05 makes up
  // almost none of them, so the estimate is 0 (the relative floor that leaves clean captures
  // unsmoothed).
  const std::vector<double> motion = Sinusoid(3000, 30.0, 3.0, 0.0);

  EXPECT_EQ(EstimateNoiseSigma(Sum(motion, WhiteNoise(3000, 0.05, 31))), 0.0);
}

TEST(NoiseEstimateTest, AFewJumpsDoNotMoveTheEstimate) {
  // Two 170-degree steps (a real rotation jump, an Euler flip): the medians ignore the few
  // differences they touch.
  std::vector<double> noisy = WhiteNoise(4000, 0.5, 41);
  for (std::size_t f = 1000; f < noisy.size(); ++f) noisy[f] += 170.0;
  for (std::size_t f = 3000; f < noisy.size(); ++f) noisy[f] -= 170.0;

  EXPECT_NEAR(EstimateNoiseSigma(noisy), 0.5, 0.025);
}

TEST(NoiseEstimateTest, FewerThanSevenSamplesReadZero) {
  EXPECT_EQ(EstimateNoiseSigma(std::vector<double>{}), 0.0);
  EXPECT_EQ(EstimateNoiseSigma(std::vector<double>{1.0, -1.0, 1.0, -1.0, 1.0, -1.0}), 0.0);
  EXPECT_EQ(EstimateNoiseSigma(std::vector<double>(100, 7.0)), 0.0);  // constant
}

}  // namespace
}  // namespace tempokey::core
