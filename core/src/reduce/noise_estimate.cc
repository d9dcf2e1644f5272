// The noise level of one channel (EstimateNoiseSigma(); the formula and its reasons in
// noise_fit.h).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

#include "tempokey/core/reduce/noise_fit.h"

namespace tempokey::core {
namespace {

// The 0.75 quantile of the standard normal: the median of |z| for z ~ N(0, 1).
constexpr double kNormalMedianAbs = 0.6744897501960817;
// The level's difference order and the whiteness test's higher order.
constexpr int kLevelOrder = 3;
constexpr int kTestOrder = 6;
// The gate on the white fraction r = (s_6 / s_3)^2 (noise_fit.h): all of the level from
// `full` = min(kWhiteFull, 1 - kWhiteMargin / sqrt(n)), none of it below full - kGateWidth, linear
// in between. For white noise r has mean 1 and standard deviation about 1.85 / sqrt(n)
// (measured on 4000 Gaussian series of each length n from 120 to 5000: 1.81 to 1.99 over
// sqrt(n)), so kWhiteMargin = 2.33 * 1.85 lets through whole all but about 1 % of white-noise
// channels of any length from about 120 samples (shorter ones spread more and lose some).
constexpr double kWhiteFull = 0.8;
constexpr double kWhiteMargin = 4.3;
constexpr double kGateWidth = 0.2;

// C(2k, k): the variance of a k-th difference of unit white noise (sum of squared binomial
// coefficients).
double WhiteDifferenceVariance(int order) {
  double c = 1.0;
  for (int i = 1; i <= order; ++i) {
    c = c * static_cast<double>(order + i) / static_cast<double>(i);
  }
  return c;
}

double MedianInPlace(std::vector<double>& values) {
  const auto middle = static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), values.begin() + middle, values.end());
  double median = values[static_cast<std::size_t>(middle)];
  if (values.size() % 2 == 0) {
    median = 0.5 * (median + *std::max_element(values.begin(), values.begin() + middle));
  }
  return median;
}

// One more difference order of `differences`, in place (one value shorter).
void Difference(std::vector<double>& differences) {
  for (std::size_t f = 0; f + 1 < differences.size(); ++f) {
    differences[f] = differences[f + 1] - differences[f];
  }
  differences.pop_back();
}

// s_k = median |d| / (0.6745 sqrt(C(2k, k))) of the k-th differences d; `scratch` is reused.
double OrderLevel(const std::vector<double>& differences, int order, std::vector<double>& scratch) {
  scratch.resize(differences.size());
  std::transform(differences.begin(), differences.end(), scratch.begin(),
                 [](double d) { return std::abs(d); });
  return MedianInPlace(scratch) /
         (kNormalMedianAbs * std::sqrt(WhiteDifferenceVariance(order)));
}

}  // namespace

double EstimateNoiseSigma(std::span<const double> samples) {
  if (samples.size() < static_cast<std::size_t>(kTestOrder) + 1) return 0.0;
  std::vector<double> differences(samples.begin(), samples.end());
  std::vector<double> scratch;
  double level = 0.0;
  double test = 0.0;
  for (int order = 1; order <= kTestOrder; ++order) {
    Difference(differences);
    if (order == kLevelOrder) level = OrderLevel(differences, order, scratch);
    if (order == kTestOrder) test = OrderLevel(differences, order, scratch);
  }
  if (!(level > 0.0)) return 0.0;
  const double white_fraction = (test / level) * (test / level);
  // The white fraction's sampling allowance at this length.
  const double margin = kWhiteMargin / std::sqrt(static_cast<double>(samples.size()));
  const double full = std::min(kWhiteFull, 1.0 - margin);
  const double gate = std::clamp((white_fraction - (full - kGateWidth)) / kGateWidth, 0.0, 1.0);
  // The part of s_3^2 that the test puts down to motion (beyond the allowance) is taken out.
  return gate * level * std::sqrt(std::min(1.0, white_fraction + margin));
}

}  // namespace tempokey::core
