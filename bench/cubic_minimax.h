// How few keys any curve with keys on frames could keep within a bound: a lower bound on the
// key counts of SPEC 8, to read the `tolerance` method's counts against (written here).
//
// A C1 cubic Hermite spline with keys on frames is, between two keys, one cubic; within a bound
// at every frame means each of those cubics is within it at every frame of its segment, both
// keys' frames included. Dropping C1 and every link between the pieces leaves a problem whose
// answer is never larger: the fewest stretches [k_0, k_1], [k_1, k_2], ... covering the frames
// such that *some* cubic is within the bound at every frame of each. Being within reach of a
// cubic holds for any part of a stretch that holds it, so taking each stretch as long as it can
// be, left to right, gives that fewest number exactly.
//
// Whether a cubic comes within the bound of a stretch is the discrete minimax (Chebyshev)
// problem, answered here by the exchange algorithm (Stiefel, after Remez), with both answers
// proved rather than trusted:
//   - "yes" by a cubic whose largest error, evaluated at every frame, is within the bound;
//   - "no" by five frames whose fourth divided difference, sum_j w_j s(x_j), exceeds the bound
//     times sum_j |w_j|: it vanishes for every cubic, so every cubic misses one of the five
//     frames by more (de la Vallee Poussin).
// The polynomials on distinct frames form a Haar system, so the exchange reaches one of the two.
// Should it not within kMaxExchanges (rounding), the stretch counts as within reach: the count
// can only come out lower, and stays a lower bound.
#ifndef TEMPOKEY_BENCH_CUBIC_MINIMAX_H_
#define TEMPOKEY_BENCH_CUBIC_MINIMAX_H_

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

namespace tempokey::bench {

// A verdict with its proof: `level` is the error five frames force on every cubic (a lower
// bound of the minimax error), `reached` the largest error of the last cubic tried (an upper
// bound). `within` is the answer.
struct CubicReach {
  bool within = false;
  double level = 0.0;
  double reached = 0.0;
  int exchanges = 0;
  bool undecided = false;  // kMaxExchanges reached; counted as within
};

class CubicMinimax {
 public:
  static constexpr int kMaxExchanges = 200;
  // Ratio of the bound allowed for rounding, on the side that keeps the count a lower bound.
  static constexpr double kSlack = 1e-9;

  // Whether some cubic is within `bound` of samples[first..last] (inclusive, first <= last) at
  // every frame.
  CubicReach Within(std::span<const double> samples, std::int64_t first, std::int64_t last,
                    double bound) const {
    return Run(samples, first, last, bound, true);
  }

  // The least largest error of any cubic at the frames samples[first..last]: the exchange run
  // until its levelled error and its cubic's largest error meet (`level` <= minimax <= `reached`).
  CubicReach Minimax(std::span<const double> samples, std::int64_t first,
                     std::int64_t last) const {
    return Run(samples, first, last, 0.0, false);
  }

  // The fewest keys on frames of any curve made of cubic pieces between its keys that is within
  // `bound` at every frame of `samples` (the first and last frames keyed). `undecided` counts
  // the stretches counted as within without proof.
  std::int64_t FewestKeys(std::span<const double> samples, double bound,
                          std::int64_t* undecided = nullptr,
                          std::vector<std::int64_t>* frames = nullptr) const {
    const auto n = static_cast<std::int64_t>(samples.size());
    if (n <= 1) return n;
    std::int64_t keys = 1;
    std::int64_t a = 0;
    if (frames != nullptr) frames->assign(1, 0);
    while (a < n - 1) {
      auto within = [&](std::int64_t e) {
        const CubicReach r = Within(samples, a, e, bound);
        if (r.undecided && undecided != nullptr) ++*undecided;
        return r.within;
      };
      // Gallop to a stretch out of reach (or the end), then halve between the longest one known
      // within and the shortest known out of reach.
      std::int64_t good = std::min<std::int64_t>(a + 3, n - 1);  // four frames: always within
      std::int64_t bad = -1;
      for (std::int64_t step = 4; good < n - 1; step *= 2) {
        const std::int64_t e = std::min(a + step, n - 1);
        if (within(e)) {
          good = e;
        } else {
          bad = e;
          break;
        }
      }
      if (bad >= 0) {
        while (bad - good > 1) {
          const std::int64_t mid = good + (bad - good) / 2;
          (within(mid) ? good : bad) = mid;
        }
      }
      a = good;
      ++keys;
      if (frames != nullptr) frames->push_back(a);
    }
    return keys;
  }

 private:
  CubicReach Run(std::span<const double> samples, std::int64_t first, std::int64_t last,
                 double bound, bool decide) const {
    CubicReach out;
    const std::int64_t length = last - first;
    if (length < 4) {  // a cubic passes through four frames
      out.within = true;
      return out;
    }
    const double* s = samples.data() + first;
    std::array<std::int64_t, 5> ref{};
    for (int j = 0; j < 5; ++j) ref[j] = (j * length + 2) / 4;
    const double loose = bound * (1.0 + kSlack);
    for (;;) {
      Level level = Solve(s, ref);
      out.level = std::abs(level.h);
      if (decide && out.level > loose) return out;  // proved out of reach
      // The largest error of the levelled cubic over the whole stretch.
      std::int64_t worst = ref[0];
      double worst_error = 0.0;
      for (std::int64_t x = 0; x <= length; ++x) {
        const double e = s[x] - level.Evaluate(static_cast<double>(x));
        if (std::abs(e) > std::abs(worst_error)) {
          worst_error = e;
          worst = x;
        }
      }
      out.reached = std::abs(worst_error);
      if (decide && out.reached <= loose) {
        out.within = true;  // proved by the cubic
        return out;
      }
      const bool converged = out.reached <= out.level * (1.0 + kSlack) ||
                             std::find(ref.begin(), ref.end(), worst) != ref.end();
      if (converged || out.exchanges == kMaxExchanges) {
        // Deciding, the level would have returned above the bound and the cubic within it:
        // only rounding stops here. Counted as within, which can only lower the count.
        out.within = decide || out.reached <= bound;
        out.undecided = decide || !converged;
        return out;
      }
      Exchange(ref, level.h, worst, worst_error);
      ++out.exchanges;
    }
  }


  // The cubic with errors +h, -h, +h, -h, +h at the five reference frames (offsets from the
  // stretch's first frame), in Newton's form through the first four.
  struct Level {
    double h = 0.0;
    std::array<double, 4> x{};
    std::array<double, 4> c{};  // divided differences
    double Evaluate(double t) const {
      return c[0] + (t - x[0]) * (c[1] + (t - x[1]) * (c[2] + (t - x[2]) * c[3]));
    }
  };

  static Level Solve(const double* s, const std::array<std::int64_t, 5>& ref) {
    Level level;
    double levelled = 0.0;
    double total = 0.0;
    for (int j = 0; j < 5; ++j) {
      double product = 1.0;
      for (int k = 0; k < 5; ++k) {
        if (k != j) product *= static_cast<double>(ref[j] - ref[k]);
      }
      const double w = 1.0 / product;  // its sign is (-1)^j
      levelled += w * s[ref[j]];
      total += std::abs(w);
    }
    level.h = levelled / total;
    std::array<double, 4> y{};
    for (int j = 0; j < 4; ++j) {
      level.x[j] = static_cast<double>(ref[j]);
      y[j] = s[ref[j]] - ((j % 2 == 0) ? level.h : -level.h);
    }
    for (int order = 1; order < 4; ++order) {
      for (int j = 3; j >= order; --j) {
        y[j] = (y[j] - y[j - 1]) / (level.x[j] - level.x[j - order]);
      }
    }
    level.c = y;
    return level;
  }

  // Stiefel's single exchange: `worst` (error `e`, larger than |h|) replaces the reference frame
  // beside it whose error has its sign, so that the signs still alternate; beyond either end
  // with the other sign, the reference shifts and drops the far end.
  static void Exchange(std::array<std::int64_t, 5>& ref, double h, std::int64_t worst, double e) {
    const double first_sign = h >= 0.0 ? 1.0 : -1.0;  // the error's sign at ref[0]
    auto sign_at = [&](int j) { return (j % 2 == 0) ? first_sign : -first_sign; };
    const double sign = e >= 0.0 ? 1.0 : -1.0;
    if (worst < ref[0]) {
      if (sign == sign_at(0)) {
        ref[0] = worst;
      } else {
        for (int j = 4; j > 0; --j) ref[j] = ref[j - 1];
        ref[0] = worst;
      }
      return;
    }
    if (worst > ref[4]) {
      if (sign == sign_at(4)) {
        ref[4] = worst;
      } else {
        for (int j = 0; j < 4; ++j) ref[j] = ref[j + 1];
        ref[4] = worst;
      }
      return;
    }
    for (int j = 0; j < 4; ++j) {
      if (worst > ref[j] && worst < ref[j + 1]) {
        if (sign == sign_at(j)) {
          ref[j] = worst;
        } else {
          ref[j + 1] = worst;
        }
        return;
      }
    }
  }
};

}  // namespace tempokey::bench

#endif  // TEMPOKEY_BENCH_CUBIC_MINIMAX_H_
