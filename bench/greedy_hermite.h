// The greedy Hermite anchor of the benchmarks (written here): keys on frames, each key's value its
// sample and its slope the Catmull-Rom slope through its neighbouring keys
// ((v_next - v_prev) / (f_next - f_prev), one-sided at the ends); starting from the first and last
// frames, the frame with the largest error over the whole curve becomes a key, until every frame
// is within the bound. What a plain "insert keys until within tolerance" reducer does, to measure
// the `tolerance` method's keys and speed against.
#ifndef TEMPOKEY_BENCH_GREEDY_HERMITE_H_
#define TEMPOKEY_BENCH_GREEDY_HERMITE_H_

#include <cmath>
#include <cstdint>
#include <queue>
#include <span>
#include <tuple>
#include <vector>

namespace tempokey::bench {

class GreedyHermite {
 public:
  // Keys of `samples` (at least 2) within `bound` at every frame.
  std::int64_t Reduce(std::span<const double> samples, double bound) {
    s_ = samples;
    const auto n = static_cast<std::int64_t>(samples.size());
    next_.assign(samples.size(), -1);
    prev_.assign(samples.size(), -1);
    stamp_.assign(samples.size(), 0);
    heap_ = {};
    next_[0] = n - 1;
    prev_[n - 1] = 0;
    std::int64_t keys = 2;
    Push(0);
    while (!heap_.empty()) {
      const auto [error, at, a, stamp] = heap_.top();
      heap_.pop();
      if (stamp != stamp_[a] || next_[a] < 0) continue;  // segment changed since
      if (error <= bound) break;
      const std::int64_t b = next_[a];
      next_[a] = at;
      prev_[at] = a;
      next_[at] = b;
      prev_[b] = at;
      ++keys;
      // The new key's tangent and its neighbours' changed: four segments to re-measure.
      if (prev_[a] >= 0) Push(prev_[a]);
      Push(a);
      Push(at);
      if (next_[b] >= 0) Push(b);
    }
    return keys;
  }

 private:
  double Slope(std::int64_t k) const {
    const std::int64_t p = prev_[k] >= 0 ? prev_[k] : k;
    const std::int64_t q = next_[k] >= 0 ? next_[k] : k;
    return (s_[q] - s_[p]) / static_cast<double>(q - p);
  }

  // Measures the segment starting at key `a` and queues its worst frame.
  void Push(std::int64_t a) {
    ++stamp_[a];
    const std::int64_t b = next_[a];
    const std::int64_t length = b - a;
    if (length < 2) return;
    const double l = static_cast<double>(length);
    const double va = s_[a], vb = s_[b];
    const double ma = Slope(a) * l, mb = Slope(b) * l;
    double worst = -1.0;
    std::int64_t at = a + 1;
    for (std::int64_t k = 1; k < length; ++k) {
      const double t = static_cast<double>(k) / l;
      const double t2 = t * t;
      const double t3 = t2 * t;
      const double y = (2 * t3 - 3 * t2 + 1) * va + (t3 - 2 * t2 + t) * ma +
                       (-2 * t3 + 3 * t2) * vb + (t3 - t2) * mb;
      const double e = std::abs(y - s_[a + k]);
      if (e > worst) {
        worst = e;
        at = a + k;
      }
    }
    heap_.emplace(worst, at, a, stamp_[a]);
  }

  std::span<const double> s_;
  std::vector<std::int64_t> next_, prev_, stamp_;
  std::priority_queue<std::tuple<double, std::int64_t, std::int64_t, std::int64_t>> heap_;
};

}  // namespace tempokey::bench

#endif  // TEMPOKEY_BENCH_GREEDY_HERMITE_H_
