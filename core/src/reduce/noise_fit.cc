// The noise-aware key reduction (SPEC 4.3); the method is described in noise_fit.h.
#include "tempokey/core/reduce/noise_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <stop_token>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"
#include "core/src/simd/instruction_set.h"
#include "core/src/simd/vectors.h"
#include "noise_smoother.h"
#include "lane_pack.h"


namespace tempokey::core {
namespace {

// The penalty's difference order and its coefficients (third difference of y at r:
// y_{r+3} - 3 y_{r+2} + 3 y_{r+1} - y_r).
constexpr int kOrder = 3;
constexpr std::array<double, kOrder + 1> kDifference = {-1.0, 3.0, -3.0, 1.0};
// Smoothing levels searched: 10^-3 is no smoothing to within rounding of the noise, 10^11 a
// quadratic through the block (beyond it the banded factorization loses digits).
constexpr double kMinLogLambda = -3.0;
constexpr double kMaxLogLambda = 11.0;
// Grid of the search, in decades: the channel's single best level on a half-decade grid refined
// by a quarter decade, each block's within kBlockReach decades of it.
constexpr double kCoarseStep = 0.5;
constexpr double kFineStep = 0.25;
constexpr double kBlockReach = 3.0;
// Guard rounds at most; each divides the lambda of every block over the guard by kGuardFactor.
constexpr int kMaxGuardRounds = 16;
constexpr double kGuardFactor = 10.0;
// Where the guard still fails at the lowest level searched, the block drops to this one. 10^-3
// leaves noise-sized detail alone but not a real jump: the smoother moves a step of height h by
// about lambda * 10 * h, so a 170-degree Euler flip or a joint's real snap came out 1.9 degrees
// off the data at every noise level (131_01, RThumb, frame 243). At 10^-12 a full turn moves by
// under 1e-8 degrees.
constexpr double kGuardFloorLogLambda = -12.0;
// Midpoints of the integral that gives the degrees of freedom per frame.
constexpr int kTraceNodes = 512;
// Rows of a band solve (or of a level interpolation) between two looks at the stop token: a
// millisecond or two of work, so a stop ends even a channel of millions of frames at once.
constexpr std::size_t kStopCheckRows = std::size_t{1} << 16;

// The innermost ScopedSmootherStopProbe of this thread, or null (always, outside tests).
thread_local const std::function<void(reduce_internal::SmootherStopSite)>* stop_probe = nullptr;

// Every look at the stop token inside one channel's smoothing.
bool StopRequested(const std::stop_token& stop, reduce_internal::SmootherStopSite site) {
  if (stop_probe != nullptr) [[unlikely]] (*stop_probe)(site);
  return stop.stop_requested();
}

// (2 sin(w / 2))^2 at the midpoints w of the integral below, computed once.
const std::array<double, kTraceNodes>& TraceNodeSquares() {
  static const std::array<double, kTraceNodes> squares = [] {
    std::array<double, kTraceNodes> out{};
    for (int k = 0; k < kTraceNodes; ++k) {
      const double w = std::numbers::pi * (k + 0.5) / kTraceNodes;
      const double s = 2.0 * std::sin(0.5 * w);
      out[static_cast<std::size_t>(k)] = s * s;
    }
    return out;
  }();
  return squares;
}

// Degrees of freedom per frame of the smoother with level `lambda` on an endless signal:
// (1 / pi) * integral over [0, pi] of 1 / (1 + lambda (2 sin(w / 2))^6), by the midpoint rule.
double DofPerFrame(double lambda) {
  const std::array<double, kTraceNodes>& squares = TraceNodeSquares();
  double sum = 0.0;
  for (const double s2 : squares) sum += 1.0 / (1.0 + lambda * s2 * s2 * s2);
  return sum / kTraceNodes;
}

// DofPerFrame() of the levels a search visits, remembered: the searches revisit the same grid of
// levels channel after channel. Per thread; a few dozen levels at most.
double CachedDofPerFrame(double lambda) {
  thread_local std::vector<std::pair<double, double>> cache;
  for (const auto& [level, dof] : cache) {
    if (level == lambda) return dof;
  }
  const double dof = DofPerFrame(lambda);
  if (cache.size() < 256) cache.emplace_back(lambda, dof);
  return dof;
}

// Solves (I + sum_r lambda[r] d_r d_r^T) y = x, d_r the third difference at r, for x of n >= 4
// samples and n - 3 levels: a symmetric positive definite band of half-width 3, by Cholesky.
// False, y incomplete, when a stop was requested on `stop` (looked at every kStopCheckRows rows).
class BandSolver {
 public:
  bool Solve(std::span<const double> x, std::span<const double> lambda, std::span<double> y,
             const std::stop_token& stop) {
    const std::size_t n = x.size();
    band_.assign(n, {1.0, 0.0, 0.0, 0.0});  // band_[i][k] = A(i, i - k)
    // The rows in pieces of kStopCheckRows, the token looked at between pieces (not per row:
    // the loops stay as tight as without it).
    for (std::size_t begin = 0; begin < n; begin += kStopCheckRows) {
      if (StopRequested(stop, reduce_internal::SmootherStopSite::kBandRows)) return false;
      const std::size_t end = std::min(n, begin + kStopCheckRows);
      for (std::size_t i = begin; i < end; ++i) ForwardRow(i, x, lambda, y);
    }
    for (std::size_t end = n; end > 0;) {
      if (StopRequested(stop, reduce_internal::SmootherStopSite::kBandRows)) return false;
      const std::size_t begin = end > kStopCheckRows ? end - kStopCheckRows : 0;
      for (std::size_t i = end; i-- > begin;) BackRow(i, n, y);
      end = begin;
    }
    return true;
  }

 private:
  // One sweep assembles, factors and forward-substitutes: row i of the matrix is complete once
  // the penalty rows up to r = i are added (their terms still in increasing r), row i of L
  // needs rows i - 3 .. i of it, and the forward step at i row i of L. The factor's chain of
  // divisions and square roots and the substitution's then overlap instead of running one
  // after the other. Row i of the sweep, rows 0 .. i - 1 done.
  [[gnu::always_inline]] void ForwardRow(std::size_t i, std::span<const double> x,
                                         std::span<const double> lambda, std::span<double> y) {
    const std::size_t n = x.size();
    if (i + kOrder < n) {
      const double l = lambda[i];
      for (int a = 0; a <= kOrder; ++a) {
        for (int b = 0; b <= a; ++b) band_[i + a][a - b] += l * kDifference[a] * kDifference[b];
      }
    }
    // In place: band_ row i becomes row i of L with A = L L^T.
    for (int k = kOrder; k >= 1; --k) {
      if (i < static_cast<std::size_t>(k)) continue;
      const std::size_t j = i - static_cast<std::size_t>(k);
      double s = band_[i][k];
      for (int m = k + 1; m <= kOrder && i >= static_cast<std::size_t>(m); ++m) {
        s -= band_[i][m] * band_[j][m - k];
      }
      band_[i][k] = s / band_[j][0];
    }
    double s = band_[i][0];
    for (int k = 1; k <= kOrder && i >= static_cast<std::size_t>(k); ++k) {
      s -= band_[i][k] * band_[i][k];
    }
    band_[i][0] = std::sqrt(s);
    double f = x[i];
    for (int k = 1; k <= kOrder && i >= static_cast<std::size_t>(k); ++k) {
      f -= band_[i][k] * y[i - static_cast<std::size_t>(k)];
    }
    y[i] = f / band_[i][0];
  }

  // Row i of the back substitution of n rows, rows i + 1 .. n - 1 done.
  [[gnu::always_inline]] void BackRow(std::size_t i, std::size_t n, std::span<double> y) const {
    double s = y[i];
    for (int k = 1; k <= kOrder && i + static_cast<std::size_t>(k) < n; ++k) {
      s -= band_[i + static_cast<std::size_t>(k)][k] * y[i + static_cast<std::size_t>(k)];
    }
    y[i] = s / band_[i][0];
  }

  std::vector<std::array<double, kOrder + 1>> band_;
};

// ---- the guard rounds' solves, several channels at once ----------------------------------------

// Channels whose guard rounds solve together, one per lane of a 4-lane vector.
constexpr std::size_t kGuardLanes = reduce_internal::kSmootherGroup;
static_assert(kGuardLanes == 4, "the lane kernels hold one channel per lane of a 4-lane vector");
// Doubles per row of LaneBandSolver's band: kOrder + 1 entries of kGuardLanes lanes.
constexpr std::size_t kLaneRow = (kOrder + 1) * kGuardLanes;

// Rows [begin, end) of BandSolver::ForwardRow() for kGuardLanes channels of n frames at once: lane
// c of x[i * kGuardLanes + c], lambda[r * kGuardLanes + c], y[i * kGuardLanes + c] and
// band[i * kLaneRow + k * kGuardLanes + c] (entry k of row i) is channel c's. Each lane performs
// exactly the scalar operations in the scalar order.
TEMPOKEY_CLONES_AVX void ForwardLaneRows(std::size_t n, std::size_t begin, std::size_t end,
                                         const double* x, const double* lambda, double* band,
                                         double* y) {
  using simd::V4;
  constexpr auto kBand = static_cast<std::size_t>(kOrder);
  const auto entry = [band](std::size_t i, std::size_t k) __attribute__((always_inline)) {
    return band + i * kLaneRow + k * kGuardLanes;
  };
  for (std::size_t i = begin; i < end; ++i) {
    if (i + kBand < n) {
      const V4 l = simd::Load(lambda + i * kGuardLanes);
      for (std::size_t a = 0; a <= kBand; ++a) {
        for (std::size_t b = 0; b <= a; ++b) {
          double* e = entry(i + a, a - b);
          simd::Store(e, simd::Load(e) + l * kDifference[a] * kDifference[b]);
        }
      }
    }
    for (std::size_t k = kBand; k >= 1; --k) {
      if (i < k) continue;
      const std::size_t j = i - k;
      V4 s = simd::Load(entry(i, k));
      for (std::size_t m = k + 1; m <= kBand && i >= m; ++m) {
        s -= simd::Load(entry(i, m)) * simd::Load(entry(j, m - k));
      }
      simd::Store(entry(i, k), s / simd::Load(entry(j, 0)));
    }
    V4 s = simd::Load(entry(i, 0));
    for (std::size_t k = 1; k <= kBand && i >= k; ++k) {
      const V4 e = simd::Load(entry(i, k));
      s -= e * e;
    }
    V4 root;
    for (int lane = 0; lane < 4; ++lane) root[lane] = std::sqrt(s[lane]);
    simd::Store(entry(i, 0), root);
    V4 f = simd::Load(x + i * kGuardLanes);
    for (std::size_t k = 1; k <= kBand && i >= k; ++k) {
      f -= simd::Load(entry(i, k)) * simd::Load(y + (i - k) * kGuardLanes);
    }
    simd::Store(y + i * kGuardLanes, f / root);
  }
}

// Rows [begin, end) of BandSolver::BackRow() for kGuardLanes channels at once, from row end - 1
// down (ForwardLaneRows()'s layout).
TEMPOKEY_CLONES_AVX void BackLaneRows(std::size_t n, std::size_t begin, std::size_t end,
                                      const double* band, double* y) {
  using simd::V4;
  constexpr auto kBand = static_cast<std::size_t>(kOrder);
  for (std::size_t i = end; i-- > begin;) {
    V4 s = simd::Load(y + i * kGuardLanes);
    for (std::size_t k = 1; k <= kBand && i + k < n; ++k) {
      s -= simd::Load(band + (i + k) * kLaneRow + k * kGuardLanes) *
           simd::Load(y + (i + k) * kGuardLanes);
    }
    simd::Store(y + i * kGuardLanes, s / simd::Load(band + i * kLaneRow));
  }
}

// BandSolver::Solve() for kGuardLanes channels of n >= 4 frames at once, each with its own
// levels (ForwardLaneRows()'s layout): every channel's solution is BandSolver's bit for bit. One
// solve is a chain of divisions and square roots from row to row, so it runs at their latency;
// four side by side take about the time of one. False, y incomplete, when a stop was requested.
class LaneBandSolver {
 public:
  bool Solve(std::size_t n, const double* x, const double* lambda, double* y,
             const std::stop_token& stop) {
    band_.assign(n * kLaneRow, 0.0);
    for (std::size_t i = 0; i < n; ++i) {
      std::fill_n(band_.begin() + static_cast<std::ptrdiff_t>(i * kLaneRow), kGuardLanes, 1.0);
    }
    for (std::size_t begin = 0; begin < n; begin += kStopCheckRows) {
      if (StopRequested(stop, reduce_internal::SmootherStopSite::kBandRows)) return false;
      ForwardLaneRows(n, begin, std::min(n, begin + kStopCheckRows), x, lambda, band_.data(), y);
    }
    for (std::size_t end = n; end > 0;) {
      if (StopRequested(stop, reduce_internal::SmootherStopSite::kBandRows)) return false;
      const std::size_t begin = end > kStopCheckRows ? end - kStopCheckRows : 0;
      BackLaneRows(n, begin, end, band_.data(), y);
      end = begin;
    }
    return true;
  }

 private:
  std::vector<double> band_;
};

// ---- many constant levels at once ---------------------------------------------------------------

// The searches below solve one signal at many constant levels. A single solve is a chain of
// divisions from frame to frame (each row of the factorization and of both substitutions divides
// by the previous rows' results), so it runs at the divider's latency; sixteen independent levels,
// one per lane of a vector, run at its throughput. And at a constant level the matrix depends on
// nothing but the level and the number of frames, so its factor is computed once and shared by
// every block window of that length and every channel of the clip; each solve is then the two
// substitutions. Each lane performs exactly BandSolver::Solve()'s operations in the same order
// (IEEE operations are exact per lane, and nothing is contracted into FMA: -ffp-contract=off in
// core/CMakeLists.txt), so every level's solution is bit for bit the scalar one.
using Lanes = double __attribute__((vector_size(128)));
constexpr int kLanes = 16;
// Wrapped in aligned structs for the vectors that hold them: a template argument drops the
// vector type's alignment attribute, and code built for the baseline target aligns the type to
// 16 bytes only, where the AVX clone expects 32. 128, the vector's own size: clang refuses an
// alignment below it, and GCC gave these structs 128 already.
struct alignas(128) BandRow {
  Lanes entry[kOrder + 1];
};
struct alignas(128) LaneValues {
  Lanes value;
};

[[gnu::always_inline]] inline Lanes Broadcast(double v) {
  Lanes out;
  for (int lane = 0; lane < kLanes; ++lane) out[lane] = v;
  return out;
}

[[gnu::always_inline]] inline Lanes Root(Lanes v) {
  Lanes out;
  for (int lane = 0; lane < kLanes; ++lane) out[lane] = std::sqrt(v[lane]);
  return out;
}

// The Cholesky factor L of I + level[l] D^T D (n x n, D the third differences, n >= 4) for the
// sixteen levels at once, as BandSolver computes it: band[i].entry[0] = L(i, i), entry[k] =
// L(i, i - k).
TEMPOKEY_CLONES_AVX void FactorConstantLevels(std::size_t n, const double* level,
                                              BandRow* band) {
  Lanes l;
  for (int lane = 0; lane < kLanes; ++lane) l[lane] = level[lane];
  Lanes product[kOrder + 1][kOrder + 1];
  for (int a = 0; a <= kOrder; ++a) {
    for (int b = 0; b <= a; ++b) product[a][b] = l * kDifference[a] * kDifference[b];
  }
  // The matrix entry A(i, i - k) as BandSolver assembles it: (level * d[a]) * d[a - k] from the
  // penalty rows r = i - a, 0 <= r <= n - 4, added in increasing r (decreasing a) onto 1 (k = 0)
  // or 0. Rows 3 .. n - 4 take all four rows and are all the same.
  const std::size_t last_penalty = n - 1 - kOrder;
  auto entry = [&](std::size_t i, int k) {
    Lanes sum = Broadcast(k == 0 ? 1.0 : 0.0);
    for (int a = kOrder; a >= k; --a) {
      const auto ua = static_cast<std::size_t>(a);
      if (i >= ua && i - ua <= last_penalty) sum += product[a][a - k];
    }
    return sum;
  };
  const Lanes interior[kOrder + 1] = {entry(kOrder, 0), entry(kOrder, 1), entry(kOrder, 2),
                                      entry(kOrder, 3)};
  // The first kOrder rows lack some terms.
  for (std::size_t i = 0; i < std::min<std::size_t>(n, kOrder); ++i) {
    Lanes* row = band[i].entry;
    for (int k = 0; k <= kOrder; ++k) row[k] = entry(i, k);
    for (int k = kOrder; k >= 1; --k) {
      if (i < static_cast<std::size_t>(k)) continue;
      const Lanes* above = band[i - static_cast<std::size_t>(k)].entry;
      Lanes s = row[k];
      for (int m = k + 1; m <= kOrder && i >= static_cast<std::size_t>(m); ++m) {
        s -= row[m] * above[m - k];
      }
      row[k] = s / above[0];
    }
    Lanes s = row[0];
    for (int k = 1; k <= kOrder && i >= static_cast<std::size_t>(k); ++k) s -= row[k] * row[k];
    row[0] = Root(s);
  }
  // The other rows on 4-lane vectors, a quarter of the batch at a time (kept in registers, where
  // 16-lane ones go through the stack), with the same operations per lane.
  using simd::V4;
  constexpr std::size_t kCount = kLanes;
  const double* interior_values = reinterpret_cast<const double*>(interior);
  for (std::size_t i = kOrder; i < n; ++i) {
    Lanes edge[kOrder + 1];
    const double* a = interior_values;
    if (i > last_penalty) {
      for (int k = 0; k <= kOrder; ++k) edge[k] = entry(i, k);
      a = reinterpret_cast<const double*>(edge);
    }
    const double* __restrict r1 = reinterpret_cast<const double*>(&band[i - 1]);
    const double* __restrict r2 = reinterpret_cast<const double*>(&band[i - 2]);
    const double* __restrict r3 = reinterpret_cast<const double*>(&band[i - 3]);
    double* __restrict row = reinterpret_cast<double*>(&band[i]);
    for (std::size_t q = 0; q < kCount; q += 4) {
      // Entry k of a row is at k * kCount + lane.
      const auto at = [q](const double* values, std::size_t k) __attribute__((always_inline)) {
        return simd::Load(values + k * kCount + q);
      };
      const V4 e3 = at(a, 3) / at(r3, 0);
      const V4 e2 = (at(a, 2) - e3 * at(r2, 1)) / at(r2, 0);
      V4 s1 = at(a, 1) - e2 * at(r1, 1);
      s1 -= e3 * at(r1, 2);
      const V4 e1 = s1 / at(r1, 0);
      V4 s0 = at(a, 0) - e1 * e1;
      s0 -= e2 * e2;
      s0 -= e3 * e3;
      V4 root;
      for (int lane = 0; lane < 4; ++lane) root[lane] = std::sqrt(s0[lane]);
      simd::Store(row + q, root);
      simd::Store(row + kCount + q, e1);
      simd::Store(row + 2 * kCount + q, e2);
      simd::Store(row + 3 * kCount + q, e3);
    }
  }
}

// One solve of a window's samples `x` at one batch of sixteen levels: `band` is the factor of the
// window's length at those levels (FactorConstantLevels()), `y` receives the solutions.
struct SubstitutionJob {
  const double* x;
  const BandRow* band;
  LaneValues* y;
  std::size_t quarters;  // lanes solved, in fours (1 to 4): a partly filled batch solves fewer
  // The first frame whose solution is wanted: the back substitution stops there (the frames
  // before it feed only each other's back steps, and the risk counts only its block's frames).
  std::size_t first_wanted;
};

// The substitutions' layout, in doubles: from one frame of a LaneValues (or one entry of a BandRow)
// to the next, and from one BandRow to the next.
constexpr std::size_t kLaneStride = kLanes;
constexpr std::size_t kBandRowStride = sizeof(BandRow) / sizeof(double);
static_assert(sizeof(LaneValues) == kLaneStride * sizeof(double));

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // always inlined: the by-value ABI never applies

// BandSolver::ForwardRow() for frame i of the lanes [lane, lane + lanes of V) of one job: `row` is
// the factor's row i, `y` the job's solutions, `f` the sample x[i] in every lane.
template <class V>
[[gnu::always_inline]] inline void ForwardLanes(const double* __restrict row,
                                                double* __restrict y, std::size_t i,
                                                std::size_t lane, V f) {
  const std::size_t at = i * kLaneStride + lane;
  for (std::size_t k = 1; k <= kOrder && i >= k; ++k) {
    f -= simd::Load<V>(row + k * kLaneStride + lane) * simd::Load<V>(y + at - k * kLaneStride);
  }
  simd::Store(y + at, f / simd::Load<V>(row + lane));
}

// BandSolver::BackRow() for frame i of n of the lanes [lane, lane + lanes of V) of one job: `band`
// is the whole factor, `y` the job's solutions.
template <class V>
[[gnu::always_inline]] inline void BackLanes(const double* __restrict band, double* __restrict y,
                                             std::size_t n, std::size_t i, std::size_t lane) {
  const std::size_t at = i * kLaneStride + lane;
  V s = simd::Load<V>(y + at);
  for (std::size_t k = 1; k <= kOrder && i + k < n; ++k) {
    s -= simd::Load<V>(band + (i + k) * kBandRowStride + k * kLaneStride + lane) *
         simd::Load<V>(y + at + k * kLaneStride);
  }
  simd::Store(y + at, s / simd::Load<V>(band + i * kBandRowStride + lane));
}

#pragma GCC diagnostic pop

// The substitutions' frame and job loops: forward(row, y, i, job) steps frame i of one job forward
// (`row` the factor's row i), then back(band, y, i, job) steps it back (`band` the whole factor),
// frame i from n - 1 down to the job's first wanted frame.
template <class Forward, class Back>
[[gnu::always_inline]] inline void SubstituteJobs(std::size_t n, const SubstitutionJob* jobs,
                                                  std::size_t count, Forward forward, Back back) {
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < count; ++j) {
      forward(reinterpret_cast<const double*>(&jobs[j].band[i]),
              reinterpret_cast<double*>(jobs[j].y), i, jobs[j]);
    }
  }
  std::size_t lowest = n;
  for (std::size_t j = 0; j < count; ++j) lowest = std::min(lowest, jobs[j].first_wanted);
  for (std::size_t i = n; i-- > lowest;) {
    for (std::size_t j = 0; j < count; ++j) {
      if (i < jobs[j].first_wanted) continue;
      back(reinterpret_cast<const double*>(jobs[j].band), reinterpret_cast<double*>(jobs[j].y), i,
           jobs[j]);
    }
  }
}

// Solves L L^T y = x for every job (each of n frames): forward, then back substitution, as
// BandSolver does, the back substitution down to each job's first wanted frame (y holds the
// forward substitution's values before it). y[i].value[l] is level l's solution at frame i. One
// solve is a chain of dependent divisions from frame to frame; the jobs are independent, so
// stepping all of them frame by frame keeps several chains in flight and the divider busy. Each
// lane of each job performs exactly the scalar operations in the scalar order. Written on 4-lane
// vectors (a quarter of a batch at a time): the compiler keeps those in registers, where it moves
// 16-lane ones through the stack.
TEMPOKEY_CLONES_AVX void SubstituteConstantLevels4(std::size_t n, const SubstitutionJob* jobs,
                                                   std::size_t count) {
  using simd::V4;
  SubstituteJobs(
      n, jobs, count,
      [](const double* row, double* y, std::size_t i, const SubstitutionJob& job)
          __attribute__((always_inline)) {
            const V4 xi = simd::Broadcast(job.x[i]);
            for (std::size_t q = 0; q < job.quarters; ++q) ForwardLanes(row, y, i, 4 * q, xi);
          },
      [n](const double* band, double* y, std::size_t i, const SubstitutionJob& job)
          __attribute__((always_inline)) {
            for (std::size_t q = 0; q < job.quarters; ++q) BackLanes<V4>(band, y, n, i, 4 * q);
          });
}

#if TEMPOKEY_WIDE_KERNELS
// SubstituteConstantLevels4() on 8-lane AVX-512 vectors, half a batch at a time (a batch with an
// odd number of quarters solves its last one on a 4-lane vector): each lane performs the same
// operations in the same order, so the solutions are the same bits.
TEMPOKEY_TARGET_AVX512 void SubstituteConstantLevels8(std::size_t n, const SubstitutionJob* jobs,
                                                      std::size_t count) {
  using V8 = double __attribute__((vector_size(64)));
  using simd::V4;
  SubstituteJobs(
      n, jobs, count,
      [](const double* row, double* y, std::size_t i, const SubstitutionJob& job)
          __attribute__((always_inline)) {
            const double x = job.x[i];
            const std::size_t halves = job.quarters / 2;
            for (std::size_t h = 0; h < halves; ++h) {
              ForwardLanes(row, y, i, 8 * h, V8{x, x, x, x, x, x, x, x});
            }
            if (job.quarters % 2 != 0) ForwardLanes(row, y, i, 8 * halves, simd::Broadcast(x));
          },
      [n](const double* band, double* y, std::size_t i, const SubstitutionJob& job)
          __attribute__((always_inline)) {
            const std::size_t halves = job.quarters / 2;
            for (std::size_t h = 0; h < halves; ++h) BackLanes<V8>(band, y, n, i, 8 * h);
            if (job.quarters % 2 != 0) BackLanes<V4>(band, y, n, i, 8 * halves);
          });
}

#endif  // TEMPOKEY_WIDE_KERNELS

// The level searches' substitutions on the widest vectors the machine has.
void SubstituteConstantLevels(std::size_t n, const SubstitutionJob* jobs, std::size_t count) {
#if TEMPOKEY_WIDE_KERNELS
  if (simd::RunningInstructionSet() == simd::InstructionSet::kAvx512) {
    SubstituteConstantLevels8(n, jobs, count);
    return;
  }
#endif
  SubstituteConstantLevels4(n, jobs, count);
}

// Residual sums of squares of the first 4 * `quarters` of the sixteen solutions `y` (of x[0 ...])
// over frames [b0, b1), each summed frame by frame in order as a scalar loop would; the other
// lanes of `rss` are left at 0.
TEMPOKEY_CLONES_AVX void LaneResiduals(const LaneValues* y, const double* x, std::size_t b0,
                                       std::size_t b1, std::size_t quarters, double* rss) {
  using simd::V4;
  const double* __restrict values = reinterpret_cast<const double*>(y);
  V4 sum[kLanes / 4] = {};
  for (std::size_t f = b0; f < b1; ++f) {
    const V4 xf = simd::Broadcast(x[f]);
    for (std::size_t q = 0; q < quarters; ++q) {
      const V4 r = simd::Load(values + f * kLanes + 4 * q) - xf;
      sum[q] += r * r;
    }
  }
  for (std::size_t q = 0; q < kLanes / 4; ++q) simd::Store(rss + 4 * q, sum[q]);
}

}  // namespace

// Factors by (frames, the sixteen levels of a batch), oldest first.
struct reduce_internal::SmootherFactors::Store {
  struct Entry {
    std::size_t n;
    std::array<double, kLanes> level;
    std::shared_ptr<const std::vector<BandRow>> rows;
  };

  // The factor of n frames at the sixteen levels `level`, computed on first use. Shared: it stays
  // valid for its holder when the store lets it go.
  std::shared_ptr<const std::vector<BandRow>> Get(std::size_t n, const double* level) {
    for (const Entry& entry : entries) {
      if (entry.n == n && std::equal(entry.level.begin(), entry.level.end(), level)) {
        return entry.rows;
      }
    }
    const std::size_t size = n * sizeof(BandRow);
    while (!entries.empty() && bytes + size > kMaxSmootherFactorBytes) {
      bytes -= entries.front().rows->size() * sizeof(BandRow);
      entries.erase(entries.begin());
    }
    auto rows = std::make_shared<std::vector<BandRow>>(n);
    FactorConstantLevels(n, level, rows->data());
    Entry& entry = entries.emplace_back();
    entry.n = n;
    std::copy(level, level + kLanes, entry.level.begin());
    entry.rows = std::move(rows);
    bytes += size;
    return entry.rows;
  }

  std::vector<Entry> entries;
  std::size_t bytes = 0;
  // The level searches' solutions: one buffer for every search of the reduction, so a channel
  // does not fault in fresh pages for it.
  std::vector<LaneValues> solutions;
};

reduce_internal::SmootherFactors::SmootherFactors() : store_(std::make_unique<Store>()) {}
reduce_internal::SmootherFactors::~SmootherFactors() = default;

reduce_internal::ScopedSmootherStopProbe::ScopedSmootherStopProbe(
    std::function<void(SmootherStopSite)> probe)
    : probe_(std::move(probe)), outer_(stop_probe) {
  stop_probe = &probe_;
}

reduce_internal::ScopedSmootherStopProbe::~ScopedSmootherStopProbe() { stop_probe = outer_; }

namespace {

// Frames above which a search solves level by level with BandSolver instead of sixteen levels at
// once: sixteen factors of that many frames would take more than kMaxSmootherFactorBytes.
constexpr std::size_t kMaxLaneFrames = reduce_internal::kMaxSmootherFactorBytes / sizeof(BandRow);
// Frames above which a channel's guard rounds solve alone (BandSolver) instead of beside others:
// the lanes' samples, levels, solutions and factor (28 doubles a frame for four channels, where
// one channel alone takes 7) would exceed kMaxSmootherFactorBytes.
constexpr std::size_t kMaxGuardLaneFrames =
    reduce_internal::kMaxSmootherFactorBytes / (kLaneRow + 3 * kGuardLanes) / sizeof(double);
// Solutions computed at once (bytes): windows step together until theirs fill about half of a
// second-level cache.
constexpr std::size_t kMaxSolutionBytes = std::size_t{256} << 10;
// But at least this many batch solves step together (a long channel's whole-window searches: a
// solve's divisions wait on each other, several solves' overlap), and never more than
// kMaxStepSolutionBytes of solutions.
constexpr std::size_t kMinStepUnits = 16;
constexpr std::size_t kMaxStepSolutionBytes = std::size_t{16} << 20;

// The smoother of one channel. It looks at the stop token between batches of window solves, per
// guard round and every kStopCheckRows rows of a band solve; once a stop is seen every phase
// returns at once and RunGroup()'s result is incomplete (the caller reports the cancellation).
class NoiseSmoother {
 public:
  NoiseSmoother(std::span<const double> samples, double sigma, const NoiseFitOptions& options,
                reduce_internal::SmootherFactors& factors, std::stop_token stop)
      : x_(samples),
        n_(samples.size()),
        sigma2_(sigma * sigma),
        guard_(options.guard_sigmas * sigma),
        block_(static_cast<std::size_t>(options.block_frames)),
        factors_(factors.store()),
        stop_(std::move(stop)) {}

  // The smoothed samples of each smoother of `group` (1 to kGuardLanes of them, over channels of
  // the same length); incomplete when stopped() is true afterwards for any of them. Each
  // channel's levels are searched alone; the guard rounds then solve the channels side by side
  // (LaneBandSolver), each channel's rounds ending when its own guard holds: a channel's later
  // solves repeat its levels, so they give its last solution again, bit for bit. A group of one
  // channel solves alone (BandSolver, the same bits): the lanes would take four times its memory
  // for no gain.
  static std::vector<std::vector<double>> RunGroup(std::span<NoiseSmoother* const> group) {
    std::vector<std::vector<double>> y;
    for (const NoiseSmoother* smoother : group) {
      y.emplace_back(smoother->x_.begin(), smoother->x_.end());
    }
    const std::size_t n = group.front()->n_;
    if (n <= kOrder + 1) return y;
    const std::vector<double> global = BestSingleLevels(group);
    if (group.front()->Stopping(reduce_internal::SmootherStopSite::kPhase)) {
      return StopAll(group, std::move(y));
    }
    // Per block: the level of least SURE on the block, solved with context on both sides.
    std::vector<std::vector<double>> block_log = BestBlockLevels(group, global);
    if (group.front()->Stopping(reduce_internal::SmootherStopSite::kPhase)) {
      return StopAll(group, std::move(y));
    }
    // Lanes beyond the group repeat its last channel.
    const std::size_t lanes = group.size() == 1 ? 1 : kGuardLanes;
    const auto channel_of = [&](std::size_t lane) { return std::min(lane, group.size() - 1); };
    std::vector<double> x;
    if (lanes > 1) {
      x.resize(n * lanes);
      for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t lane = 0; lane < lanes; ++lane) {
          x[i * lanes + lane] = group[channel_of(lane)]->x_[i];
        }
      }
    }
    std::vector<double> levels(n - kOrder);
    std::vector<double> lambda((n - kOrder) * lanes);
    std::vector<double> solution(n * lanes);
    std::vector<bool> lowered(group.size(), true);  // levels changed since the last solve
    LaneBandSolver solver;
    for (int round = 0;; ++round) {
      for (std::size_t lane = 0; lane < lanes; ++lane) {
        const std::size_t c = channel_of(lane);
        if (!lowered[c]) continue;
        if (lane == c && !group[c]->Interpolate(block_log[c], levels)) {
          return StopAll(group, std::move(y));
        }
        for (std::size_t r = 0; r < levels.size(); ++r) lambda[r * lanes + lane] = levels[r];
      }
      const bool solved =
          lanes == 1 ? group.front()->SolveBand(group.front()->x_, lambda, solution)
                     : solver.Solve(n, x.data(), lambda.data(), solution.data(),
                                    group.front()->stop_);
      if (!solved) return StopAll(group, std::move(y));
      if (round == kMaxGuardRounds) break;
      bool any = false;
      for (std::size_t c = 0; c < group.size(); ++c) {
        if (!lowered[c]) continue;  // its guard held: its solution is final
        lowered[c] = group[c]->LowerGuardedBlocks(solution, lanes, c, block_log[c]);
        any = any || lowered[c];
      }
      if (!any) break;
    }
    for (std::size_t c = 0; c < group.size(); ++c) {
      for (std::size_t i = 0; i < n; ++i) y[c][i] = solution[i * lanes + c];
    }
    return y;
  }

  // Whether a stop was seen: RunGroup()'s result is then not to be used.
  bool stopped() const { return stopped_; }

 private:
  // Marks every smoother of `group` stopped (they share the token) and returns `y`.
  static std::vector<std::vector<double>> StopAll(std::span<NoiseSmoother* const> group,
                                                  std::vector<std::vector<double>> y) {
    for (NoiseSmoother* smoother : group) smoother->stopped_ = true;
    return y;
  }

  // One guard round's check of this channel's solution (lane `lane` of `lanes` in `solution`,
  // frame f at solution[f * lanes + lane]): each block whose solution strays more than the guard
  // from the samples has its level lowered by kGuardFactor (from the lowest searched, to the
  // floor). Whether any was.
  bool LowerGuardedBlocks(std::span<const double> solution, std::size_t lanes, std::size_t lane,
                          std::vector<double>& block_log) const {
    bool lowered = false;
    for (std::size_t b = 0; b < block_log.size(); ++b) {
      const std::size_t b0 = b * block_;
      const std::size_t b1 = std::min(n_, b0 + block_);
      double worst = 0.0;
      for (std::size_t f = b0; f < b1; ++f) {
        worst = std::max(worst, std::abs(solution[f * lanes + lane] - x_[f]));
      }
      if (worst <= guard_ || block_log[b] <= kGuardFloorLogLambda) continue;
      block_log[b] = block_log[b] > kMinLogLambda
                         ? std::max(kMinLogLambda, block_log[b] - std::log10(kGuardFactor))
                         : kGuardFloorLogLambda;
      lowered = true;
    }
    return lowered;
  }
  // Looks at the stop token; true (and from then on) once a stop was requested.
  // Looks every time (a stop once requested stays requested), so that a test's probe sees work
  // that goes on past a stop.
  bool Stopping(reduce_internal::SmootherStopSite site) {
    if (StopRequested(stop_, site)) stopped_ = true;
    return stopped_;
  }

  // solver_.Solve() noting a stop: false when one was seen.
  bool SolveBand(std::span<const double> x, std::span<const double> lambda, std::span<double> y) {
    if (stopped_ || !solver_.Solve(x, lambda, y, stop_)) {
      stopped_ = true;
      return false;
    }
    return true;
  }

  // A block and the frames it is solved on: SURE counts frames [b0, b1) of the solution of
  // x_[a0, a1).
  struct Window {
    std::size_t a0, a1, b0, b1;
  };

  // One window of one channel to be searched: `logs.size()` risks go to `risks`.
  struct Search {
    const NoiseSmoother* channel;
    Window window;
    std::span<const double> logs;
    double* risks;
  };

  // SURE on each search's block of the solutions of its window at the constant levels
  // 10^logs[i], up to the constant -n sigma^2: each one's residual there plus 2 sigma^2 (its
  // channel's) times its degrees of freedom, to search.risks[i]. Every window has n frames, so
  // they share the factors (this smoother's store); sixteen levels per factor, and the solves of
  // several searches and batches of levels step together (SubstituteConstantLevels()): the more
  // of them, the more chains of divisions in flight. False, risks incomplete, once a stop is seen
  // (between window solves or steps).
  bool Risks(std::size_t n, std::span<const Search> searches) {
    if (n > kMaxLaneFrames) {
      std::vector<double> y(n);
      std::vector<double> lambda(n - kOrder);
      for (const Search& search : searches) {
        const Window& window = search.window;
        const std::span<const double> x = search.channel->x_;
        for (std::size_t i = 0; i < search.logs.size(); ++i) {
          const double level = std::pow(10.0, search.logs[i]);
          std::fill(lambda.begin(), lambda.end(), level);
          if (!SolveBand(x.subspan(window.a0, n), lambda, y)) return false;
          double rss = 0.0;
          for (std::size_t f = window.b0; f < window.b1; ++f) {
            const double r = y[f - window.a0] - x[f];
            rss += r * r;
          }
          search.risks[i] = rss + 2.0 * search.channel->sigma2_ *
                                      static_cast<double>(window.b1 - window.b0) *
                                      CachedDofPerFrame(level);
        }
      }
      return true;
    }
    // One unit: a search at one batch of sixteen of its levels.
    struct Unit {
      std::size_t search, batch;
    };
    std::vector<Unit> units;
    for (std::size_t i = 0; i < searches.size(); ++i) {
      for (std::size_t b = 0; b * kLanes < searches[i].logs.size(); ++b) units.push_back({i, b});
    }
    // Units solved at once: enough for several chains in flight, few enough that their solutions
    // stay near the cache (kMaxSolutionBytes) and within kMaxStepSolutionBytes, and their factors
    // within kMaxSmootherFactorBytes.
    const std::size_t solution_bytes = n * sizeof(LaneValues);
    const std::size_t factor_bytes = n * sizeof(BandRow);
    const std::size_t per_step = std::max<std::size_t>(
        1, std::min({std::max(kMinStepUnits, kMaxSolutionBytes / solution_bytes),
                     kMaxStepSolutionBytes / solution_bytes,
                     reduce_internal::kMaxSmootherFactorBytes / factor_bytes}));
    struct Batch {
      const double* logs;
      std::size_t batch;
      std::array<double, kLanes> level;
      std::array<double, kLanes> dof;  // degrees of freedom per frame
      std::shared_ptr<const std::vector<BandRow>> factor;
    };
    std::vector<Batch> batches;  // of the step, each distinct one once
    std::vector<std::size_t> batch_of;  // per unit of the step
    for (std::size_t first = 0; first < units.size(); first += per_step) {
      if (Stopping(reduce_internal::SmootherStopSite::kSearchStep)) return false;
      const std::size_t step = std::min(per_step, units.size() - first);
      batches.clear();
      batch_of.clear();
      for (std::size_t u = first; u < first + step; ++u) {
        const Search& search = searches[units[u].search];
        const std::size_t b = units[u].batch;
        std::size_t k = 0;
        while (k < batches.size() &&
               !(batches[k].logs == search.logs.data() && batches[k].batch == b)) {
          ++k;
        }
        if (k == batches.size()) {
          Batch& batch = batches.emplace_back();
          batch.logs = search.logs.data();
          batch.batch = b;
          const std::size_t count = search.logs.size();
          for (std::size_t lane = 0; lane < kLanes; ++lane) {
            batch.level[lane] = std::pow(10.0, search.logs[std::min(b * kLanes + lane, count - 1)]);
            batch.dof[lane] = CachedDofPerFrame(batch.level[lane]);
          }
          batch.factor = factors_.Get(n, batch.level.data());
        }
        batch_of.push_back(k);
      }
      std::vector<LaneValues>& solutions = factors_.solutions;
      if (solutions.size() < step * n) solutions.resize(step * n);
      jobs_.clear();
      for (std::size_t u = 0; u < step; ++u) {
        const Search& search = searches[units[first + u].search];
        const std::size_t used =
            std::min<std::size_t>(kLanes, search.logs.size() - units[first + u].batch * kLanes);
        jobs_.push_back({search.channel->x_.data() + search.window.a0,
                         batches[batch_of[u]].factor->data(), solutions.data() + u * n,
                         (used + 3) / 4, search.window.b0 - search.window.a0});
      }
      SubstituteConstantLevels(n, jobs_.data(), jobs_.size());
      for (std::size_t u = 0; u < step; ++u) {
        const Search& search = searches[units[first + u].search];
        const Window& window = search.window;
        const SubstitutionJob& job = jobs_[u];
        double rss[kLanes];
        LaneResiduals(job.y, job.x, window.b0 - window.a0, window.b1 - window.a0, job.quarters,
                      rss);
        const std::size_t first_level = units[first + u].batch * kLanes;
        const Batch& batch = batches[batch_of[u]];
        for (std::size_t lane = 0; lane < kLanes && first_level + lane < search.logs.size();
             ++lane) {
          search.risks[first_level + lane] =
              rss[lane] + 2.0 * search.channel->sigma2_ *
                              static_cast<double>(window.b1 - window.b0) * batch.dof[lane];
        }
      }
    }
    return true;
  }

  // The index of the least of `risks`, the first of equals; `none` when none is below infinity.
  static constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
  static std::size_t Least(std::span<const double> risks) {
    std::size_t best = kNone;
    double best_risk = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < risks.size(); ++i) {
      if (risks[i] < best_risk) {
        best_risk = risks[i];
        best = i;
      }
    }
    return best;
  }

  // log10 of the single level of least SURE over the whole channel, for each channel of `group`
  // (of one length), searched together. Empty once a stop is seen.
  static std::vector<double> BestSingleLevels(std::span<NoiseSmoother* const> group) {
    NoiseSmoother& owner = *group.front();
    const std::size_t n = owner.n_;
    std::vector<double> coarse_logs;
    for (double l = kMinLogLambda; l <= kMaxLogLambda + 1e-9; l += kCoarseStep) {
      coarse_logs.push_back(l);
    }
    const std::size_t count = coarse_logs.size();
    const Window whole{0, n, 0, n};
    std::vector<double> coarse_risks(group.size() * count);
    std::vector<Search> searches;
    for (std::size_t c = 0; c < group.size(); ++c) {
      searches.push_back({group[c], whole, coarse_logs, coarse_risks.data() + c * count});
    }
    if (!owner.Risks(n, searches)) return {};
    std::vector<double> best(group.size());
    std::vector<double> best_risk(group.size());
    std::vector<std::vector<double>> fine_logs(group.size());
    std::vector<std::array<double, 2>> fine_risks(group.size());
    searches.clear();
    for (std::size_t c = 0; c < group.size(); ++c) {
      const std::span<const double> own(coarse_risks.data() + c * count, count);
      const std::size_t coarse = Least(own);
      best[c] = coarse == kNone ? kMinLogLambda : coarse_logs[coarse];
      best_risk[c] = coarse == kNone ? std::numeric_limits<double>::infinity() : own[coarse];
      for (double l : {best[c] - kFineStep, best[c] + kFineStep}) {
        if (l < kMinLogLambda || l > kMaxLogLambda) continue;
        fine_logs[c].push_back(l);
      }
      if (!fine_logs[c].empty()) {
        searches.push_back({group[c], whole, fine_logs[c], fine_risks[c].data()});
      }
    }
    if (!owner.Risks(n, searches)) return {};
    for (std::size_t c = 0; c < group.size(); ++c) {
      for (std::size_t i = 0; i < fine_logs[c].size(); ++i) {
        if (fine_risks[c][i] < best_risk[c]) {
          best_risk[c] = fine_risks[c][i];
          best[c] = fine_logs[c][i];
        }
      }
    }
    return best;
  }

  // log10 of the level of least SURE on each block of each channel of `group` (of one length),
  // within kBlockReach decades of the channel's `global` level. The windows of equal length are
  // searched together, those of all the channels at once. Empty once a stop is seen.
  static std::vector<std::vector<double>> BestBlockLevels(std::span<NoiseSmoother* const> group,
                                                          std::span<const double> global) {
    NoiseSmoother& owner = *group.front();
    const std::size_t n_all = owner.n_;
    const std::size_t block = owner.block_;
    std::vector<std::vector<double>> logs(group.size());
    for (std::size_t c = 0; c < group.size(); ++c) {
      const double low = std::max(kMinLogLambda, global[c] - kBlockReach);
      const double high = std::min(kMaxLogLambda, global[c] + kBlockReach);
      for (double l = low; l <= high + 1e-9; l += kFineStep) logs[c].push_back(l);
    }
    std::vector<Window> windows;
    for (std::size_t b0 = 0; b0 < n_all; b0 += block) {
      const std::size_t b1 = std::min(n_all, b0 + block);
      const std::size_t a0 = b0 >= block ? b0 - block : 0;
      const std::size_t a1 = std::min(n_all, b1 + block);
      windows.push_back({a0, a1, b0, b1});
    }
    std::vector<std::vector<double>> block_log;
    for (std::size_t c = 0; c < group.size(); ++c) {
      // Kept where the window is too short to solve.
      block_log.emplace_back(windows.size(), global[c]);
    }
    std::vector<bool> done(windows.size(), false);
    std::vector<std::size_t> members;
    std::vector<Search> searches;
    std::vector<double> risks;
    for (std::size_t w = 0; w < windows.size(); ++w) {
      const std::size_t n = windows[w].a1 - windows[w].a0;
      if (done[w] || n <= kOrder + 1) continue;
      members.clear();
      for (std::size_t v = w; v < windows.size(); ++v) {
        if (!done[v] && windows[v].a1 - windows[v].a0 == n) {
          members.push_back(v);
          done[v] = true;
        }
      }
      std::size_t total = 0;
      for (std::size_t c = 0; c < group.size(); ++c) total += logs[c].size() * members.size();
      risks.resize(total);
      searches.clear();
      double* next = risks.data();
      for (std::size_t c = 0; c < group.size(); ++c) {
        for (const std::size_t v : members) {
          searches.push_back({group[c], windows[v], logs[c], next});
          next += logs[c].size();
        }
      }
      if (!owner.Risks(n, searches)) return {};
      std::size_t s = 0;
      for (std::size_t c = 0; c < group.size(); ++c) {
        for (const std::size_t v : members) {
          const std::size_t least = Least({searches[s].risks, logs[c].size()});
          if (least != kNone) block_log[c][v] = logs[c][least];
          ++s;
        }
      }
    }
    return block_log;
  }

  // The level of each penalty row (its centre at r + 1.5) from the block levels, geometrically
  // interpolated between block centres and held beyond the first and last. False, `lambda`
  // incomplete, once a stop is seen.
  bool Interpolate(const std::vector<double>& block_log, std::vector<double>& lambda) {
    const auto block = static_cast<double>(block_);
    const auto last = static_cast<std::ptrdiff_t>(block_log.size()) - 1;
    // Between two blocks of the same level, and beyond the first and last, the exponent repeats:
    // its power is reused.
    double exponent = std::numeric_limits<double>::quiet_NaN();
    double power = 0.0;
    for (std::size_t begin = 0; begin < lambda.size(); begin += kStopCheckRows) {
      if (Stopping(reduce_internal::SmootherStopSite::kLevelRows)) return false;
      const std::size_t end = std::min(lambda.size(), begin + kStopCheckRows);
      for (std::size_t r = begin; r < end; ++r) {
        const double position = (static_cast<double>(r) + 1.5 - 0.5 * block) / block;
        const double below = std::floor(position);
        const double t = position - below;
        const auto k = static_cast<std::ptrdiff_t>(below);
        const double l0 =
            block_log[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(k, 0, last))];
        const double l1 =
            block_log[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(k + 1, 0, last))];
        const double e = l0 + t * (l1 - l0);
        if (!(e == exponent)) {
          exponent = e;
          power = std::pow(10.0, e);
        }
        lambda[r] = power;
      }
    }
    return true;
  }

  std::span<const double> x_;
  std::size_t n_;
  double sigma2_;
  double guard_;
  std::size_t block_;
  BandSolver solver_;
  reduce_internal::SmootherFactors::Store& factors_;
  std::vector<SubstitutionJob> jobs_;
  std::stop_token stop_;
  bool stopped_ = false;
};

absl::Status ValidateOptions(const NoiseFitOptions& options) {
  if (!(options.guard_sigmas >= 2.0 && options.guard_sigmas <= 100.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("guard_sigmas must be in [2, 100], got ", options.guard_sigmas));
  }
  if (!(options.key_sigmas >= 0.01 && options.key_sigmas <= 10.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("key_sigmas must be in [0.01, 10], got ", options.key_sigmas));
  }
  if (options.block_frames < 8 || options.block_frames > 1'000'000) {
    return absl::InvalidArgumentError(
        absl::StrCat("block_frames must be in [8, 1000000], got ", options.block_frames));
  }
  return absl::OkStatus();
}

}  // namespace

std::vector<double> SmoothToNoise(std::span<const double> samples, double sigma,
                                  const NoiseFitOptions& options) {
  reduce_internal::SmootherFactors factors;
  // Without a stop token the smoother runs to the end.
  return *reduce_internal::SmoothToNoise(samples, sigma, options, factors, {});
}

absl::StatusOr<SplineFit> FitToNoise(std::span<const double> samples, double sigma,
                                     const NoiseFitOptions& options, std::stop_token stop) {
  reduce_internal::SmootherFactors factors;
  return reduce_internal::FitToNoise(samples, sigma, options, stop, factors);
}

absl::StatusOr<std::vector<double>> reduce_internal::SmoothToNoise(
    std::span<const double> samples, double sigma, const NoiseFitOptions& options,
    SmootherFactors& factors, std::stop_token stop) {
  absl::StatusOr<std::vector<std::vector<double>>> smooth =
      SmoothGroupToNoise({&samples, 1}, {&sigma, 1}, options, factors, std::move(stop));
  if (!smooth.ok()) return smooth.status();
  return std::move(smooth->front());
}

absl::StatusOr<std::vector<std::vector<double>>> reduce_internal::SmoothGroupToNoise(
    std::span<const std::span<const double>> channels, std::span<const double> sigmas,
    const NoiseFitOptions& options, SmootherFactors& factors, std::stop_token stop) {
  std::vector<std::unique_ptr<NoiseSmoother>> smoothers;
  std::vector<NoiseSmoother*> group;
  std::vector<std::vector<double>> smooth;
  for (std::size_t first = 0; first < channels.size(); first += group.size()) {
    smoothers.clear();
    group.clear();
    // Consecutive channels of one length, at most kGuardLanes; a long channel alone.
    const std::size_t most =
        channels[first].size() <= kMaxGuardLaneFrames ? kGuardLanes : std::size_t{1};
    for (std::size_t c = first; c < channels.size() && group.size() < most &&
                                channels[c].size() == channels[first].size();
         ++c) {
      smoothers.push_back(
          std::make_unique<NoiseSmoother>(channels[c], sigmas[c], options, factors, stop));
      group.push_back(smoothers.back().get());
    }
    for (std::vector<double>& y : NoiseSmoother::RunGroup(group)) smooth.push_back(std::move(y));
    if (group.front()->stopped()) return absl::CancelledError("cancelled");
  }
  return smooth;
}

absl::Status reduce_internal::CheckNoiseFit(std::span<const double> samples, double sigma,
                                            const NoiseFitOptions& options) {
  if (samples.empty()) return absl::InvalidArgumentError("a fit needs at least one sample");
  for (std::size_t f = 0; f < samples.size(); ++f) {
    if (!std::isfinite(samples[f])) {
      return absl::InvalidArgumentError(
          absl::StrCat("sample ", f, " is ", std::isnan(samples[f]) ? "NaN" : "infinite"));
    }
  }
  if (!(sigma > 0.0) || !std::isfinite(sigma)) {
    return absl::InvalidArgumentError(
        absl::StrCat("the noise level must be finite and > 0, got ", sigma));
  }
  return ValidateOptions(options);
}

int reduce_internal::InitialKeySpacing(std::span<const double> curve, double bound) {
  if (curve.size() < 5) return kMaxInitialKeySpacing;
  // Sixteenths of the fourth differences: weights of total 1, so no finite samples overflow them
  // (and each is the fourth difference / 16 exactly, short of underflow: powers of two).
  std::vector<double> sixteenths(curve.size() - 4);
  for (std::size_t f = 0; f < sixteenths.size(); ++f) {
    sixteenths[f] = std::abs(curve[f] / 16.0 - curve[f + 1] / 4.0 + 3.0 * curve[f + 2] / 8.0 -
                             curve[f + 3] / 4.0 + curve[f + 4] / 16.0);
  }
  const auto middle = sixteenths.begin() + static_cast<std::ptrdiff_t>(sixteenths.size() / 2);
  std::nth_element(sixteenths.begin(), middle, sixteenths.end());
  // L^4 |fourth| / 384 = bound, i.e. L^4 = 24 bound / sixteenth; a zero median (a line, a
  // parabola) or a huge bound leaves the widest spacing.
  const double spacing =
      kInitialSpacingOverSegment * std::sqrt(std::sqrt(24.0 * bound / *middle));
  return static_cast<int>(std::clamp(std::floor(spacing),
                                     static_cast<double>(kMinInitialKeySpacing),
                                     static_cast<double>(kMaxInitialKeySpacing)));
}

absl::StatusOr<SplineFit> reduce_internal::FitKeysToNoise(std::span<const double> curve,
                                                          double sigma,
                                                          const NoiseFitOptions& options,
                                                          std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  const double bound = options.key_sigmas * sigma;
  const ToleranceFitOptions fit{.initial_spacing_frames = InitialKeySpacing(curve, bound)};
  return FitWithinTolerance({&curve, 1}, {&bound, 1}, fit, stop);
}

absl::StatusOr<SplineFit> reduce_internal::FitToNoise(std::span<const double> samples,
                                                      double sigma,
                                                      const NoiseFitOptions& options,
                                                      std::stop_token stop,
                                                      SmootherFactors& factors) {
  TEMPOKEY_RETURN_IF_ERROR(CheckNoiseFit(samples, sigma, options));
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  absl::StatusOr<std::vector<double>> smooth =
      SmoothToNoise(samples, sigma, options, factors, stop);
  if (!smooth.ok()) return smooth.status();
  return FitKeysToNoise(*smooth, sigma, options, stop);
}

}  // namespace tempokey::core
