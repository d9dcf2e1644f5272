// A brute-force reference of the paper's Hermite DP fit (SPEC 4.1), for tests and benchmarks on
// small inputs: every one of the 6561 combinations of each segment is evaluated directly, frame
// by frame, with x(s) = frame solved by bisection on the Bezier form; the Viterbi pass, tie rule,
// feasibility and iteration follow the definitions in tempokey/core/reduce/hermite_dp.h literally.
// Header-only; shares no code with the optimized pass but the key struct and option types.
#ifndef TEMPOKEY_TESTS_CORE_HERMITE_REFERENCE_H_
#define TEMPOKEY_TESTS_CORE_HERMITE_REFERENCE_H_

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "tempokey/core/reduce/hermite_dp.h"

namespace tempokey::testing {

struct ReferenceFit {
  std::vector<core::HermiteKey2D> keys;
  std::vector<double> squared_error_history;
  int iterations = 0;
};

// x(s) = x by bisection on the cubic Bezier with controls x0..x3, to the last representable bit.
inline double ReferenceSolve(double x0, double x1, double x2, double x3, double x) {
  if (!(x > x0)) return 0.0;
  if (!(x < x3)) return 1.0;
  double lo = 0.0;
  double hi = 1.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;
    const double u = 1.0 - mid;
    const double bezier =
        u * u * u * x0 + 3.0 * u * u * mid * x1 + 3.0 * u * mid * mid * x2 + mid * mid * mid * x3;
    if (bezier < x) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return 0.5 * (lo + hi);
}

inline bool ReferenceFeasible(const core::HermiteKey2D& a, const core::HermiteKey2D& b) {
  return a.tx >= core::kMinTangentXFrames && b.tx >= core::kMinTangentXFrames && a.x < b.x &&
         a.tx + b.tx <= 3.0 * (b.x - a.x);
}

inline double ReferenceSegmentError(std::span<const double> samples, const core::HermiteKey2D& a,
                                    const core::HermiteKey2D& b, bool last) {
  const auto first = static_cast<std::int64_t>(std::ceil(a.x));
  const auto end = last ? static_cast<std::int64_t>(std::floor(b.x)) + 1
                        : static_cast<std::int64_t>(std::ceil(b.x));
  double sum = 0.0;
  for (std::int64_t f = first; f < end; ++f) {
    const double s = ReferenceSolve(a.x, a.x + a.tx / 3.0, b.x - b.tx / 3.0, b.x,
                                    static_cast<double>(f));
    const double s2 = s * s;
    const double s3 = s2 * s;
    const double y = (2 * s3 - 3 * s2 + 1) * a.y + (s3 - 2 * s2 + s) * a.ty +
                     (-2 * s3 + 3 * s2) * b.y + (s3 - s2) * b.ty;
    const double r = y - samples[f];
    sum += r * r;
  }
  return sum;
}

inline double ReferenceCurveError(std::span<const double> samples,
                                  const std::vector<core::HermiteKey2D>& keys) {
  double sum = 0.0;
  for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
    sum += ReferenceSegmentError(samples, keys[i], keys[i + 1], i + 2 == keys.size());
  }
  return sum;
}

// The key of state `s` (index ((ix * 3 + itx) * 3 + iy) * 3 + ity) around `key`.
inline core::HermiteKey2D ReferenceState(const core::HermiteKey2D& key,
                                         const core::HermiteSteps& steps, int s) {
  const int ix = s / 27;
  const int itx = (s / 9) % 3;
  const int iy = (s / 3) % 3;
  const int ity = s % 3;
  return {key.x + static_cast<double>(ix - 1) * steps.x,
          key.y + static_cast<double>(iy - 1) * steps.y,
          key.tx + static_cast<double>(itx - 1) * steps.tangent_x,
          key.ty + static_cast<double>(ity - 1) * steps.tangent_y};
}

// The tie rule: minimum m, window m + tol(m), state 40 if inside, else the lowest index.
inline int ReferenceChoose(const std::array<double, 81>& candidates, double scale) {
  double m = std::numeric_limits<double>::infinity();
  for (double c : candidates) m = std::min(m, c);
  if (std::isinf(m)) return -1;
  const double window = m + (core::kDpTieRelative * m + core::kDpTieAbsolute * scale);
  if (candidates[40] <= window) return 40;
  for (int s = 0; s < 81; ++s) {
    if (candidates[s] <= window) return s;
  }
  return -1;
}

struct ReferencePass {
  std::vector<core::HermiteKey2D> keys;
  bool moved = false;
};

inline ReferencePass ReferenceDpPass(std::span<const double> samples,
                                     const std::vector<core::HermiteKey2D>& keys,
                                     const core::HermiteSteps& steps) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  const std::size_t k = keys.size();
  double scale = 0.0;
  for (double v : samples) scale += (v - samples[0]) * (v - samples[0]);
  std::vector<std::array<double, 81>> cost(k);
  std::vector<std::array<int, 81>> predecessor(k);
  for (int s = 0; s < 81; ++s) cost[0][s] = (s / 27 == 1) ? 0.0 : kInf;
  for (std::size_t i = 0; i + 1 < k; ++i) {
    const bool last = i + 2 == k;
    for (int t = 0; t < 81; ++t) {
      std::array<double, 81> candidates;
      candidates.fill(kInf);
      const core::HermiteKey2D b = ReferenceState(keys[i + 1], steps, t);
      if (!(last && t / 27 != 1)) {
        for (int s = 0; s < 81; ++s) {
          if (std::isinf(cost[i][s])) continue;
          const core::HermiteKey2D a = ReferenceState(keys[i], steps, s);
          if (!ReferenceFeasible(a, b) || a.x < 0.0 ||
              b.x > static_cast<double>(samples.size()) - 1.0) {
            continue;
          }
          candidates[s] = cost[i][s] + ReferenceSegmentError(samples, a, b, last);
        }
      }
      const int chosen = ReferenceChoose(candidates, scale);
      cost[i + 1][t] = chosen < 0 ? kInf : candidates[chosen];
      predecessor[i + 1][t] = chosen;
    }
  }
  ReferencePass pass;
  pass.keys.resize(k);
  int state = ReferenceChoose(cost[k - 1], scale);
  for (std::size_t i = k; i-- > 0;) {
    pass.keys[i] = ReferenceState(keys[i], steps, state);
    if (state != 40) pass.moved = true;
    if (i > 0) state = predecessor[i][state];
  }
  return pass;
}

inline ReferenceFit ReferenceFitHermiteDp(std::span<const double> samples,
                                          std::vector<core::HermiteKey2D> keys,
                                          const core::HermiteFitOptions& options) {
  ReferenceFit fit;
  double error = ReferenceCurveError(samples, keys);
  fit.squared_error_history.push_back(error);
  core::HermiteSteps steps = options.steps;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    if (std::max({steps.x, steps.y, steps.tangent_x, steps.tangent_y}) < options.accuracy) break;
    ReferencePass pass = ReferenceDpPass(samples, keys, steps);
    ++fit.iterations;
    bool taken = false;
    if (pass.moved) {
      const double candidate = ReferenceCurveError(samples, pass.keys);
      if (candidate <= error) {
        keys = pass.keys;
        error = candidate;
        taken = true;
      }
    }
    if (!taken) {
      steps.x *= 0.5;
      steps.y *= 0.5;
      steps.tangent_x *= 0.5;
      steps.tangent_y *= 0.5;
    }
    fit.squared_error_history.push_back(error);
  }
  fit.keys = keys;
  return fit;
}

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_CORE_HERMITE_REFERENCE_H_
