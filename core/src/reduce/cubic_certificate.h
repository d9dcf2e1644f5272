// A proof, from five samples, that no cubic comes within a bound of a stretch of samples: the
// tolerance fit's removal skips the trials of a key whose removal no curve can make.
//
// For any cubic p, the fourth divided difference at five distinct frames x_0 < ... < x_4 is zero:
// sum_j w_j p(x_j) = 0 with w_j = 1 / prod_{k != j} (x_j - x_k). So for samples s,
//   |sum_j w_j s(x_j)| = |sum_j w_j (s - p)(x_j)| <= max_j |s - p|(x_j) * sum_j |w_j|,
// and where the left side exceeds bound * sum_j |w_j|, every cubic is further than the bound from
// s at one of the five frames (de la Vallee Poussin's lower bound of the minimax error). The
// frames are spread evenly over the stretch, where a key that the stretch cannot lose shows.
#ifndef TEMPOKEY_CORE_SRC_REDUCE_CUBIC_CERTIFICATE_H_
#define TEMPOKEY_CORE_SRC_REDUCE_CUBIC_CERTIFICATE_H_

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace tempokey::core::reduce_internal {

// A proof is trusted only where it clears the bound by this factor, where the samples it reads
// are within kCertificateReach bounds of zero, and where the bound is far above the smallest
// doubles (below, the margin and the products round away). A fit evaluates its curve through
// rounded basis columns; a curve it accepts is then within the bound of an exact cubic, plus
// roundings of its terms. Those terms can be much larger than the samples (a stretch of 4
// frames inside a segment of 2 000, samples far beyond it): about 1e-4 bounds in the most
// extreme case estimated, a tenth of the margin, and far less on any real clip.
inline constexpr double kCertificateMargin = 1.01;
inline constexpr double kCertificateReach = 1e6;
inline constexpr double kCertificateSmallestBound = 1e-250;

// The i-th of the five frames spread over a stretch of `length` frames (offsets from its first):
// 0 and `length` included, distinct for length >= 4.
constexpr std::int64_t SpreadFrame(int i, std::int64_t length) {
  return static_cast<std::int64_t>((static_cast<std::uint64_t>(i * length) + 2) / 4);
}

// The divided difference's weights at the spread frames, divided by the sum of their magnitudes.
using FivePointWeights = std::array<double, 5>;
constexpr FivePointWeights DividedDifferenceWeights(std::int64_t length) {
  FivePointWeights w{};
  double total = 0.0;
  for (int j = 0; j < 5; ++j) {
    double product = 1.0;  // of whole numbers below 2^13: exact
    for (int k = 0; k < 5; ++k) {
      if (k != j) product *= static_cast<double>(SpreadFrame(j, length) - SpreadFrame(k, length));
    }
    w[j] = 1.0 / product;
    total += product < 0.0 ? -w[j] : w[j];
  }
  for (double& x : w) x /= total;
  return w;
}

// The weights of the stretches most removals have, computed at compile time.
inline constexpr std::int64_t kTabledStretch = 256;
inline constexpr auto kStretchWeights = [] {
  std::array<FivePointWeights, kTabledStretch> table{};
  for (std::int64_t length = 4; length < kTabledStretch; ++length) {
    table[static_cast<std::size_t>(length)] = DividedDifferenceWeights(length);
  }
  return table;
}();

// The weights of a longer stretch, out of line: inlined, GCC computed its products ahead of the
// table's branch on every call.
[[gnu::noinline]] inline FivePointWeights LongStretchWeights(std::int64_t length) {
  return DividedDifferenceWeights(length);
}

// True when no cubic is within `bound` (> 0) of `s` at every frame of [a, e] (e - a >= 4; the
// caller's samples cover it); false says nothing.
inline bool NoCubicWithin(const double* s, std::int64_t a, std::int64_t e, double bound) {
  const std::int64_t length = e - a;
  const FivePointWeights w = length < kTabledStretch
                                 ? kStretchWeights[static_cast<std::size_t>(length)]
                                 : LongStretchWeights(length);
  const double* at = s + a;
  double difference = 0.0;
  double largest = 0.0;
  for (int j = 0; j < 5; ++j) {
    const double sample = at[SpreadFrame(j, length)];
    difference += w[j] * sample;
    largest = std::max(largest, std::abs(sample));
  }
  return bound >= kCertificateSmallestBound && largest <= kCertificateReach * bound &&
         std::abs(difference) > kCertificateMargin * bound;
}

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_CUBIC_CERTIFICATE_H_
