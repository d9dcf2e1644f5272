// The smoothing-spline anchor of the benchmarks (FITPACK's knot strategy, written here): a C2 cubic
// spline with knots on frames, knots added where the residual is largest until the least-squares
// spline's residual sum of squares is at most a target s (FITPACK's criterion: s = N sigma^2 for
// noise of level sigma). Used by filter_bench (quality against the clean motion) and spec8_bench
// (speed beside the noise-aware method).
#ifndef TEMPOKEY_BENCH_SMOOTHING_SPLINE_H_
#define TEMPOKEY_BENCH_SMOOTHING_SPLINE_H_

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace tempokey::bench {

// Solves the symmetric positive definite band system A y = b in place (band[i][k] = A(i, i - k),
// half-width 3) by Cholesky.
inline void SolveBand3(std::vector<std::array<double, 4>>& band, std::vector<double>& y) {
  const std::size_t n = band.size();
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t k = 3; k >= 1; --k) {
      if (i < k) continue;
      const std::size_t j = i - k;
      double sum = band[i][k];
      for (std::size_t m = k + 1; m <= 3 && i >= m; ++m) sum -= band[i][m] * band[j][m - k];
      band[i][k] = sum / band[j][0];
    }
    double sum = band[i][0];
    for (std::size_t k = 1; k <= 3 && i >= k; ++k) sum -= band[i][k] * band[i][k];
    band[i][0] = std::sqrt(sum);
  }
  for (std::size_t i = 0; i < n; ++i) {
    double sum = y[i];
    for (std::size_t k = 1; k <= 3 && i >= k; ++k) sum -= band[i][k] * y[i - k];
    y[i] = sum / band[i][0];
  }
  for (std::size_t i = n; i-- > 0;) {
    double sum = y[i];
    for (std::size_t k = 1; k <= 3 && i + k < n; ++k) sum -= band[i + k][k] * y[i + k];
    y[i] = sum / band[i][0];
  }
}

// The least-squares C2 cubic spline through samples x at frames 0..n-1 with the given interior
// knots (integer frames, strictly increasing inside (0, n-1)): B-splines on the clamped knot
// vector, the four non-zero ones at each frame by de Boor's recurrence, banded normal equations.
inline std::vector<double> LeastSquaresSpline(std::span<const double> x,
                                       const std::vector<std::int64_t>& interior) {
  const auto last = static_cast<double>(x.size() - 1);
  std::vector<double> knots(4, 0.0);
  for (std::int64_t k : interior) knots.push_back(static_cast<double>(k));
  for (int i = 0; i < 4; ++i) knots.push_back(last);
  const std::size_t count = interior.size() + 4;  // basis functions
  std::vector<std::array<double, 4>> band(count, {0.0, 0.0, 0.0, 0.0});
  std::vector<double> rhs(count, 0.0);
  std::vector<std::array<double, 4>> basis(x.size());
  std::vector<std::size_t> span_of(x.size());
  std::size_t span = 3;
  for (std::size_t f = 0; f < x.size(); ++f) {
    const auto u = static_cast<double>(f);
    while (span + 1 < count && knots[span + 1] <= u) ++span;
    std::array<double, 4> n{1.0, 0.0, 0.0, 0.0};
    std::array<double, 4> left{}, right{};
    for (int j = 1; j <= 3; ++j) {
      left[j] = u - knots[span + 1 - j];
      right[j] = knots[span + j] - u;
      double saved = 0.0;
      for (int r = 0; r < j; ++r) {
        const double temp = n[r] / (right[r + 1] + left[j - r]);
        n[r] = saved + right[r + 1] * temp;
        saved = left[j - r] * temp;
      }
      n[j] = saved;
    }
    basis[f] = n;
    span_of[f] = span;
    for (int a = 0; a < 4; ++a) {
      const std::size_t row = span - 3 + a;
      rhs[row] += n[a] * x[f];
      for (int b = 0; b <= a; ++b) band[row][a - b] += n[a] * n[b];
    }
  }
  for (auto& row : band) row[0] += 1e-12;  // keeps the factorization regular
  SolveBand3(band, rhs);
  std::vector<double> y(x.size());
  for (std::size_t f = 0; f < x.size(); ++f) {
    double v = 0.0;
    for (int a = 0; a < 4; ++a) v += basis[f][a] * rhs[span_of[f] - 3 + a];
    y[f] = v;
  }
  return y;
}

// FITPACK's knot strategy for s = `target` (a residual sum of squares): from no interior knots,
// fit, and while the residual exceeds the target add knots in the intervals (between knots)
// whose residual is largest, each where the interval's residual splits in half; the fit with
// residual <= target. Keys: the knots, the two ends included.
inline std::vector<double> SmoothingSpline(std::span<const double> x, double target,
                                    std::int64_t* keys) {
  const auto n = static_cast<std::int64_t>(x.size());
  std::vector<std::int64_t> interior;
  std::vector<double> y = LeastSquaresSpline(x, interior);
  for (;;) {
    std::vector<std::int64_t> bounds = {0};
    bounds.insert(bounds.end(), interior.begin(), interior.end());
    bounds.push_back(n - 1);
    double total = 0.0;
    std::vector<std::pair<double, std::size_t>> intervals;
    for (std::size_t j = 0; j + 1 < bounds.size(); ++j) {
      double rss = 0.0;
      const std::int64_t end = j + 2 == bounds.size() ? bounds[j + 1] + 1 : bounds[j + 1];
      for (std::int64_t f = bounds[j]; f < end; ++f) rss += (y[f] - x[f]) * (y[f] - x[f]);
      total += rss;
      if (bounds[j + 1] - bounds[j] >= 2) intervals.emplace_back(rss, j);
    }
    if (total <= target || intervals.empty()) break;
    std::sort(intervals.rbegin(), intervals.rend());
    const std::size_t add = std::max<std::size_t>(1, intervals.size() / 5);
    for (std::size_t r = 0; r < add && r < intervals.size(); ++r) {
      const std::size_t j = intervals[r].second;
      const double half = 0.5 * intervals[r].first;
      double sum = 0.0;
      std::int64_t at = bounds[j] + 1;
      for (std::int64_t f = bounds[j]; f < bounds[j + 1]; ++f) {
        sum += (y[f] - x[f]) * (y[f] - x[f]);
        if (sum >= half) {
          at = f;
          break;
        }
      }
      interior.push_back(std::clamp(at, bounds[j] + 1, bounds[j + 1] - 1));
    }
    std::sort(interior.begin(), interior.end());
    interior.erase(std::unique(interior.begin(), interior.end()), interior.end());
    y = LeastSquaresSpline(x, interior);
  }
  *keys = static_cast<std::int64_t>(interior.size()) + 2;
  return y;
}

}  // namespace tempokey::bench

#endif  // TEMPOKEY_BENCH_SMOOTHING_SPLINE_H_
