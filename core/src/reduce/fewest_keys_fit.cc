// The fewest-keys search; the method is described in fewest_keys_fit.h.
#include "core/src/reduce/fewest_keys_fit.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <numbers>
#include <utility>
#include <vector>

#include "core/src/reduce/small_lp.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core::reduce_internal {
namespace {

// The programs keep the curve this far inside the bound, so that the rounding of a solution
// (about 1e-9 of a row's scale) never takes it past.
constexpr double kInside = 1.0 - 1e-4;
// Directions, besides the four axes, in which each key's set is measured.
constexpr int kDirections = 8;
// A long segment's program starts from this many of its frames, and adds at most kAddedFrames
// a round of those its solution misses.
constexpr std::int64_t kFirstFrames = 48;
constexpr std::size_t kAddedFrames = 16;
// The largest bound the search takes (others are left to the usual fit).
constexpr double kLargestBound = 1e300;
// How often the search looks at `stop`, in rows of programs and frames measured.
constexpr std::int64_t kRowsBetweenStopChecks = 65536;

struct Pair {
  double value = 0.0;
  double slope = 0.0;  // value units per frame
};
using Corners = std::vector<Pair>;  // one channel's set at one key: their convex hull

// The Hermite basis at frame k of a segment of `length` frames, times the length for the slopes
// (per frame): the curve there is a0 v_a + a1 m_a + b0 v_b + b1 m_b.
struct Basis {
  double a0, a1, b0, b1;
};
Basis BasisAt(std::int64_t k, std::int64_t length) {
  const double l = static_cast<double>(length);
  const double t = static_cast<double>(k) / l;
  const double t2 = t * t;
  const double t3 = t2 * t;
  return {2.0 * t3 - 3.0 * t2 + 1.0, (t3 - 2.0 * t2 + t) * l, -2.0 * t3 + 3.0 * t2,
          (t3 - t2) * l};
}

// The corners that span the hull of `points` (within 1e-9 of the extents `scale` apart, one
// kept): fewer columns for the next key's programs. Any subset of the points is a part of the
// set, so the search stays sound whatever this keeps.
Corners HullCorners(Corners points, Pair scale) {
  Corners distinct;
  for (const Pair& p : points) {
    const bool seen = std::any_of(distinct.begin(), distinct.end(), [&](const Pair& q) {
      return std::abs(q.value - p.value) <= 1e-9 * scale.value &&
             std::abs(q.slope - p.slope) <= 1e-9 * scale.slope;
    });
    if (!seen) distinct.push_back(p);
  }
  if (distinct.size() <= 2) return distinct;
  std::sort(distinct.begin(), distinct.end(), [](const Pair& a, const Pair& b) {
    return a.value < b.value || (a.value == b.value && a.slope < b.slope);
  });
  auto turn = [&](const Pair& o, const Pair& a, const Pair& b) {
    return ((a.value - o.value) / scale.value) * ((b.slope - o.slope) / scale.slope) -
           ((a.slope - o.slope) / scale.slope) * ((b.value - o.value) / scale.value);
  };
  Corners hull(2 * distinct.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < distinct.size(); ++i) {  // lower chain
    while (k >= 2 && turn(hull[k - 2], hull[k - 1], distinct[i]) <= 1e-12) --k;
    hull[k++] = distinct[i];
  }
  for (std::size_t i = distinct.size() - 1, lower = k + 1; i > 0; --i) {  // upper chain
    while (k >= lower && turn(hull[k - 2], hull[k - 1], distinct[i - 1]) <= 1e-12) --k;
    hull[k++] = distinct[i - 1];
  }
  hull.resize(k - 1);
  return hull;
}

Pair Combination(const Corners& corners, std::span<const double> weights) {
  double total = 0.0;
  for (std::size_t j = 0; j < corners.size(); ++j) total += std::max(weights[j], 0.0);
  Pair p;
  for (std::size_t j = 0; j < corners.size(); ++j) {
    const double w = std::max(weights[j], 0.0) / total;
    p.value += w * corners[j].value;
    p.slope += w * corners[j].slope;
  }
  return p;
}

class Search {
 public:
  Search(std::span<const std::span<const double>> channels, std::span<const double> max_errors,
         std::stop_token stop)
      : channels_(channels),
        bounds_(max_errors),
        n_(static_cast<std::int64_t>(channels.front().size())),
        stop_(std::move(stop)) {
    for (std::size_t c = 0; c < channels.size(); ++c) {
      double step = 0.0;
      for (std::int64_t f = 1; f < n_; ++f) {
        step = std::max(step, std::abs(channels[c][f] - channels[c][f - 1]));
      }
      // No key's slope needs to be steeper than four times the steepest step between samples
      // and the bound: the search's sets are cut there, which keeps its programs' scale.
      slope_limits_.push_back(4.0 * step + 4.0 * max_errors[c]);
    }
  }

  absl::StatusOr<std::optional<SplineFit>> Run() {
    std::vector<std::int64_t> frames{0};
    std::vector<std::vector<Corners>> sets{FirstSets()};
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t farthest, Reach(sets.back(), 0));
    while (frames.back() < n_ - 1) {
      const std::int64_t a = frames.back();
      const std::vector<Corners>& from = sets.back();
      std::int64_t key = -1;
      std::vector<Corners> key_sets;
      std::int64_t key_reach = -1;
      for (std::int64_t b : Candidates(a, farthest)) {
        TEMPOKEY_ASSIGN_OR_RETURN(std::optional<std::vector<Corners>> next, Project(from, a, b));
        if (!next) {
          if (b == farthest) return std::nullopt;
          continue;  // a candidate without a verdict is passed over
        }
        if (b == n_ - 1) {
          key = b;
          key_sets = *std::move(next);
          break;
        }
        // Only a reach beyond the best so far matters: Reach() may stop once it cannot beat it.
        TEMPOKEY_ASSIGN_OR_RETURN(const std::int64_t reach, Reach(*next, b, key_reach));
        if (reach > key_reach) {
          key = b;
          key_reach = reach;
          key_sets = *std::move(next);
          if (reach == n_ - 1) break;  // nothing reaches further
        }
      }
      frames.push_back(key);
      sets.push_back(std::move(key_sets));
      farthest = key_reach;  // the chosen key's reach, measured in full above
    }
    return Back(frames, sets);
  }

 private:
  // The frames tried for the key after the key at a, the farthest first: the last
  // kFewestKeysLookahead + 1 frames it reaches, and as many spread back to the middle of the
  // segment (a long segment's best key can sit far from its end).
  static std::vector<std::int64_t> Candidates(std::int64_t a, std::int64_t farthest) {
    std::vector<std::int64_t> out;
    for (std::int64_t d = 0; d <= kFewestKeysLookahead && farthest - d > a; ++d) {
      out.push_back(farthest - d);
    }
    const std::int64_t span = farthest - a;
    for (std::int64_t j = 1; j <= kFewestKeysLookahead; ++j) {
      const std::int64_t b = farthest - (j * span) / (2 * kFewestKeysLookahead);
      if (b > a && b < out.back()) out.push_back(b);
    }
    return out;
  }

  // Frame 0's sets: the value within the bound, the slope within its limit.
  std::vector<Corners> FirstSets() const {
    std::vector<Corners> sets;
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      const double v = channels_[c][0];
      const double e = kInside * bounds_[c];
      const double m = slope_limits_[c];
      sets.push_back({{v - e, -m}, {v + e, -m}, {v + e, m}, {v - e, m}});
    }
    return sets;
  }

  absl::Status CountRows(std::int64_t rows) {
    rows_since_check_ += rows;
    if (rows_since_check_ < kRowsBetweenStopChecks) return absl::OkStatus();
    rows_since_check_ = 0;
    return CheckNotCancelled(stop_);
  }

  // The programs of a segment a..b hold a row for each side of the bound at each frame between
  // the keys. A long segment's program starts from kFirstFrames of them spread evenly and adds
  // the frames its solution misses until it misses none (row generation): a program on part of
  // the rows without a solution proves the whole has none, and a solution is taken only once
  // every frame is measured within the bound. A calm stretch's keys 4096 frames apart then solve
  // programs of a few dozen frames, not 4095.
  void FirstFrames(std::int64_t length) {
    frames_.clear();
    if (length - 1 <= kFirstFrames) {
      for (std::int64_t k = 1; k < length; ++k) frames_.push_back(k);
      return;
    }
    for (std::int64_t i = 0; i < kFirstFrames; ++i) {
      frames_.push_back(1 + (i * (length - 2) + (kFirstFrames - 1) / 2) / (kFirstFrames - 1));
    }
    frames_.erase(std::unique(frames_.begin(), frames_.end()), frames_.end());
  }

  // Adds the frames of `misses` (offsets, by how much each misses) not yet in the program, the
  // worst first, at most kAddedFrames; false when every one is there already (rounding).
  bool AddMissed(std::vector<std::pair<double, std::int64_t>>& misses) {
    std::sort(misses.begin(), misses.end(), std::greater<>());
    std::size_t added = 0;
    for (const auto& [excess, k] : misses) {
      if (std::find(frames_.begin(), frames_.end(), k) != frames_.end()) continue;
      frames_.push_back(k);
      if (++added == kAddedFrames) break;
    }
    return added > 0;
  }

  // Forward: channel c's key at b after its key at a in `from`. Columns: the weights of from's
  // corners, then the key's value and slope above their least (ForwardLow()). Values are taken
  // from the sample at a, which keeps the rows' scale that of the motion between.
  struct Forward {
    std::size_t c;
    const Corners* from;
    std::int64_t a;
    std::int64_t b;
  };
  Pair ForwardLow(const Forward& f) const {
    return {channels_[f.c][f.b] - channels_[f.c][f.a] - kInside * bounds_[f.c],
            -slope_limits_[f.c]};
  }
  // A program whose first `weights` columns weigh a key's corners (>= 0, summing to 1), and
  // `others` more columns; row_ zeroed for the next row.
  void StartProgram(int weights, int others) {
    lp_.Reset(weights + others);
    row_.assign(static_cast<std::size_t>(weights + others), 0.0);
    std::fill(row_.begin(), row_.begin() + weights, 1.0);
    Put(1.0);
    std::fill(row_.begin(), row_.begin() + weights, -1.0);
    Put(-1.0);
  }
  // Adds row_ <= bound, and zeroes row_.
  void Put(double bound) {
    lp_.AddRow(row_, bound);
    std::fill(row_.begin(), row_.end(), 0.0);
  }

  // Every row is in units of the channel's bound, the key's value column too, and its slope
  // column holds the slope times the length in those units: a program is the same for the same
  // motion at any scale, and its columns' values are of the order of 1.
  void BuildForward(const Forward& f) {
    const int p = static_cast<int>(f.from->size());
    const double unit = bounds_[f.c];
    const double length = static_cast<double>(f.b - f.a);
    const double origin = channels_[f.c][f.a];
    const Pair low = ForwardLow(f);
    StartProgram(p, 2);
    row_[p] = 1.0;
    Put(2.0 * kInside);
    row_[p + 1] = 1.0;
    Put(2.0 * slope_limits_[f.c] * length / unit);
    for (std::int64_t k : frames_) {
      const Basis h = BasisAt(k, f.b - f.a);
      const double target =
          (channels_[f.c][f.a + k] - origin - h.b0 * low.value - h.b1 * low.slope) / unit;
      for (int sign : {1, -1}) {
        for (int j = 0; j < p; ++j) {
          row_[j] = sign *
                    (h.a0 * ((*f.from)[j].value - origin) + h.a1 * (*f.from)[j].slope) / unit;
        }
        row_[p] = sign * h.b0;
        row_[p + 1] = sign * h.b1 / length;
        Put(sign * target + kInside);
      }
    }
  }
  // The weights summing to 1, as the rows read them, give the key at a; the columns after them
  // the key at b.
  std::pair<Pair, Pair> ForwardKeys(const Forward& f, const std::vector<double>& z) const {
    const int p = static_cast<int>(f.from->size());
    const double unit = bounds_[f.c];
    const Pair low = ForwardLow(f);
    return {Combination(*f.from, z),
            {channels_[f.c][f.a] + low.value + z[p] * unit,
             low.slope + z[p + 1] * unit / static_cast<double>(f.b - f.a)}};
  }
  // Whether the segment between keys `ka` and `kb` keeps channel c within `bound` at every frame
  // between; the frames it misses by more go to `misses`.
  bool Within(std::size_t c, std::int64_t a, std::int64_t b, Pair ka, Pair kb, double bound,
              std::vector<std::pair<double, std::int64_t>>& misses) const {
    misses.clear();
    for (std::int64_t k = 1; k < b - a; ++k) {
      const Basis h = BasisAt(k, b - a);
      const double error = h.a0 * (ka.value - channels_[c][a]) + h.a1 * ka.slope +
                           h.b0 * (kb.value - channels_[c][a]) + h.b1 * kb.slope -
                           (channels_[c][a + k] - channels_[c][a]);
      if (!(std::abs(error) <= bound)) misses.emplace_back(std::abs(error) - bound, k);
    }
    return misses.empty();
  }
  // The forward program's bound, measured: past the programs' own by their rounding (about 1e-9
  // of a row's largest coefficient, which a long segment's slope terms make thousands of times
  // the bound), well inside the true bound.
  double ForwardCheck(std::size_t c) const { return (1.0 - 1e-5) * bounds_[c]; }

  // Whether channel c's key can be at b after its set at a: a verified solution, or a program
  // without one. No verdict (rounding) counts as no, which can only cost keys.
  absl::StatusOr<bool> ForwardFeasible(const Forward& f) {
    FirstFrames(f.b - f.a);
    for (;;) {
      BuildForward(f);
      TEMPOKEY_RETURN_IF_ERROR(CountRows(lp_.rows()));
      if (!lp_.FindFeasible()) return false;
      lp_.Point(z_);
      TEMPOKEY_RETURN_IF_ERROR(CountRows(f.b - f.a));  // the frames Within() measures
      const auto [ka, kb] = ForwardKeys(f, z_);
      if (Within(f.c, f.a, f.b, ka, kb, ForwardCheck(f.c), misses_)) return true;
      if (!AddMissed(misses_)) return false;
    }
  }

  // Whether every channel's key can be at b after its set at a.
  absl::StatusOr<bool> Reaches(const std::vector<Corners>& from, std::int64_t a, std::int64_t b) {
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      TEMPOKEY_ASSIGN_OR_RETURN(const bool feasible, ForwardFeasible({c, &from[c], a, b}));
      if (!feasible) return false;
    }
    return true;
  }

  // The farthest frame the next key can take after the key at a (a + 1 always can: no frame
  // lies between); or, once that is known to be at most `floor`, some frame at most `floor`
  // (the probes are the same as without a floor, so a reach beyond it is the same frame).
  absl::StatusOr<std::int64_t> Reach(const std::vector<Corners>& from, std::int64_t a,
                                     std::int64_t floor = -1) {
    const std::int64_t last = std::min(n_ - 1, a + kMaxMergedSegmentFrames);
    std::int64_t good = a + 1;
    std::int64_t bad = -1;
    for (std::int64_t step = 2; good < last; step *= 2) {
      const std::int64_t b = std::min(a + step, last);
      TEMPOKEY_ASSIGN_OR_RETURN(const bool reaches, Reaches(from, a, b));
      if (!reaches) {
        bad = b;
        break;
      }
      good = b;
    }
    while (bad - good > 1 && bad - 1 > floor) {
      const std::int64_t mid = good + (bad - good) / 2;
      TEMPOKEY_ASSIGN_OR_RETURN(const bool reaches, Reaches(from, a, mid));
      (reaches ? good : bad) = mid;
    }
    return good;
  }

  // The pair at b furthest along (along_value, along_slope) in channel c's program, verified at
  // every frame; std::nullopt without a verdict.
  absl::StatusOr<std::optional<Pair>> Corner(const Forward& f, double along_value,
                                             double along_slope) {
    const int p = static_cast<int>(f.from->size());
    std::vector<double> objective(static_cast<std::size_t>(p + 2), 0.0);
    objective[p] = along_value;
    objective[p + 1] = along_slope;
    for (;;) {
      // The program's rows for the pivots, and the frames Within() measures.
      TEMPOKEY_RETURN_IF_ERROR(CountRows(lp_.rows() + (f.b - f.a)));
      if (!lp_.Maximize(objective, z_)) return std::nullopt;
      const auto [ka, kb] = ForwardKeys(f, z_);
      if (Within(f.c, f.a, f.b, ka, kb, ForwardCheck(f.c), misses_)) return kb;
      if (!AddMissed(misses_)) return std::nullopt;
      BuildForward(f);
      TEMPOKEY_RETURN_IF_ERROR(CountRows(lp_.rows()));
      if (!lp_.FindFeasible()) return std::nullopt;  // it had a solution
    }
  }

  // Every channel's set at b after its set at a; std::nullopt when a program gives no verdict.
  absl::StatusOr<std::optional<std::vector<Corners>>> Project(const std::vector<Corners>& from,
                                                              std::int64_t a, std::int64_t b) {
    std::vector<Corners> sets;
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      const Forward f{c, &from[c], a, b};
      TEMPOKEY_ASSIGN_OR_RETURN(const bool feasible, ForwardFeasible(f));
      if (!feasible) return std::nullopt;  // Reach() found it feasible
      Corners points;
      for (const auto& [along_value, along_slope] :
           {std::pair{1.0, 0.0}, std::pair{-1.0, 0.0}, std::pair{0.0, 1.0}, std::pair{0.0, -1.0}}) {
        TEMPOKEY_ASSIGN_OR_RETURN(std::optional<Pair> corner, Corner(f, along_value, along_slope));
        if (!corner) return std::nullopt;
        points.push_back(*corner);
      }
      Pair least{HUGE_VAL, HUGE_VAL};
      Pair most{-HUGE_VAL, -HUGE_VAL};
      for (const Pair& q : points) {
        least = {std::min(least.value, q.value), std::min(least.slope, q.slope)};
        most = {std::max(most.value, q.value), std::max(most.slope, q.slope)};
      }
      const Pair scale{std::max(most.value - least.value, 1e-300),
                       std::max(most.slope - least.slope, 1e-300)};
      const double length = static_cast<double>(b - a);  // of the slope's column
      for (int d = 0; d < kDirections; ++d) {
        const double angle = (d + 0.5) * 2.0 * std::numbers::pi / kDirections;
        TEMPOKEY_ASSIGN_OR_RETURN(
            std::optional<Pair> corner,
            Corner(f, std::cos(angle) * bounds_[c] / scale.value,
                   std::sin(angle) * bounds_[c] / (scale.slope * length)));
        if (!corner) return std::nullopt;
        points.push_back(*corner);
      }
      sets.push_back(HullCorners(std::move(points), scale));
    }
    return sets;
  }

  // Going back: each key's value and slope, the widest margin to the bound on the segment after
  // it, inside its set; then the whole curve measured against the bound.
  absl::StatusOr<std::optional<SplineFit>> Back(const std::vector<std::int64_t>& frames,
                                                const std::vector<std::vector<Corners>>& sets) {
    const std::size_t keys = frames.size();
    SplineFit fit;
    fit.frames = frames;
    fit.values.assign(channels_.size(), std::vector<double>(keys));
    fit.slopes.assign(channels_.size(), std::vector<double>(keys));
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      Pair q;  // the centre of the last key's set
      for (const Pair& corner : sets.back()[c]) {
        q.value += corner.value / static_cast<double>(sets.back()[c].size());
        q.slope += corner.slope / static_cast<double>(sets.back()[c].size());
      }
      fit.values[c][keys - 1] = q.value;
      fit.slopes[c][keys - 1] = q.slope;
      for (std::size_t k = keys - 1; k-- > 0;) {
        TEMPOKEY_ASSIGN_OR_RETURN(std::optional<Pair> before,
                                  Before(c, sets[k][c], frames[k], frames[k + 1], q));
        if (!before) return std::nullopt;
        q = *before;
        fit.values[c][k] = q.value;
        fit.slopes[c][k] = q.slope;
      }
      const std::vector<double> curve = EvaluateSplineFit(fit, c);
      for (std::int64_t f = 0; f < n_; ++f) {
        if (!(std::abs(curve[f] - channels_[c][f]) <= bounds_[c])) return std::nullopt;
      }
    }
    return fit;
  }

  // Channel c's key at a, inside `corners`, before its key at b fixed at q: the widest margin
  // to the bound at the frames between (columns: the corners' weights, then the margin plus the
  // bound, in [0, 2 bound]), the frames added as the margin's solution misses them; std::nullopt
  // when no solution keeps every frame within the bound (rounding).
  absl::StatusOr<std::optional<Pair>> Before(std::size_t c, const Corners& corners,
                                             std::int64_t a, std::int64_t b, Pair q) {
    const int p = static_cast<int>(corners.size());
    const double e = bounds_[c];
    const double origin = channels_[c][a];
    std::vector<double> objective(static_cast<std::size_t>(p + 1), 0.0);
    objective[p] = 1.0;
    FirstFrames(b - a);
    for (;;) {  // rows in units of the bound, as the forward programs' (the margin's too)
      StartProgram(p, 1);
      row_[p] = 1.0;
      Put(2.0);
      for (std::int64_t k : frames_) {
        const Basis h = BasisAt(k, b - a);
        const double target =
            (channels_[c][a + k] - origin - h.b0 * (q.value - origin) - h.b1 * q.slope) / e;
        for (int sign : {1, -1}) {
          for (int j = 0; j < p; ++j) {
            row_[j] = sign * (h.a0 * (corners[j].value - origin) + h.a1 * corners[j].slope) / e;
          }
          row_[p] = 1.0;
          Put(sign * target + 2.0);
        }
      }
      TEMPOKEY_RETURN_IF_ERROR(CountRows(lp_.rows()));
      if (!lp_.FindFeasible() || !lp_.Maximize(objective, z_) || z_[p] < 1.0) return std::nullopt;
      const Pair at_a = Combination(corners, z_);
      // Within the bound at every frame is what is taken; the frames that take the margin below
      // what the program found are added, so that the next solution keeps it.
      TEMPOKEY_RETURN_IF_ERROR(CountRows(b - a));
      if (Within(c, a, b, at_a, q, e, misses_)) return at_a;
      Within(c, a, b, at_a, q, (2.0 - z_[p]) * e, misses_);
      if (!AddMissed(misses_)) return std::nullopt;
    }
  }

  std::span<const std::span<const double>> channels_;
  std::span<const double> bounds_;
  std::int64_t n_;
  std::stop_token stop_;
  std::vector<double> slope_limits_;
  SmallLp lp_;
  std::vector<double> row_;
  std::vector<double> z_;
  std::vector<std::int64_t> frames_;  // the frames between the keys a program holds (offsets)
  std::vector<std::pair<double, std::int64_t>> misses_;
  std::int64_t rows_since_check_ = 0;
};

bool AllConstant(std::span<const std::span<const double>> channels) {
  return std::all_of(channels.begin(), channels.end(), [](std::span<const double> samples) {
    return std::all_of(samples.begin(), samples.end(),
                       [&](double v) { return v == samples.front(); });
  });
}

}  // namespace

absl::StatusOr<std::optional<SplineFit>> FitFewestKeys(
    std::span<const std::span<const double>> channels, std::span<const double> max_errors,
    std::stop_token stop) {
  const auto n = static_cast<std::int64_t>(channels.front().size());
  if (n <= 2 || AllConstant(channels)) return std::nullopt;  // the usual fit's keys are fewest
  // Bounds near the largest doubles would overflow the programs' ranges (twice the bound, four
  // times the steepest step): there the usual fit's two keys are fewest anyway.
  for (std::size_t c = 0; c < channels.size(); ++c) {
    if (!(max_errors[c] <= kLargestBound)) return std::nullopt;
  }
  return Search(channels, max_errors, std::move(stop)).Run();
}

}  // namespace tempokey::core::reduce_internal
