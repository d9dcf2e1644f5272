// The noise-aware key reduction (SPEC 4.3); the method is described in noise_fit.h.
#include "tempokey/core/reduce/noise_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"
#include "noise_smoother.h"
#include "simd.h"


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
// Midpoints of the integral that gives the degrees of freedom per frame.
constexpr int kTraceNodes = 512;

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
class BandSolver {
 public:
  void Solve(std::span<const double> x, std::span<const double> lambda, std::span<double> y) {
    const std::size_t n = x.size();
    band_.assign(n, {1.0, 0.0, 0.0, 0.0});  // band_[i][k] = A(i, i - k)
    for (std::size_t r = 0; r + kOrder < n; ++r) {
      const double l = lambda[r];
      for (int a = 0; a <= kOrder; ++a) {
        for (int b = 0; b <= a; ++b) band_[r + a][a - b] += l * kDifference[a] * kDifference[b];
      }
    }
    // In place: band_ becomes L with A = L L^T.
    for (std::size_t i = 0; i < n; ++i) {
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
    }
    for (std::size_t i = 0; i < n; ++i) {
      double s = x[i];
      for (int k = 1; k <= kOrder && i >= static_cast<std::size_t>(k); ++k) {
        s -= band_[i][k] * y[i - static_cast<std::size_t>(k)];
      }
      y[i] = s / band_[i][0];
    }
    for (std::size_t i = n; i-- > 0;) {
      double s = y[i];
      for (int k = 1; k <= kOrder && i + static_cast<std::size_t>(k) < n; ++k) {
        s -= band_[i + static_cast<std::size_t>(k)][k] * y[i + static_cast<std::size_t>(k)];
      }
      y[i] = s / band_[i][0];
    }
  }

 private:
  std::vector<std::array<double, kOrder + 1>> band_;
};

// ---- many constant levels at once ---------------------------------------------------------------

// The searches below solve one signal at many constant levels. A single solve is a chain of
// divisions from frame to frame (each row of the factorization and of both substitutions divides
// by the previous rows' results), so it runs at the divider's latency; sixteen independent levels,
// one per lane of a vector, run at its throughput. And at a constant level the matrix depends on
// nothing but the level and the number of frames, so its factor is computed once and shared by
// every block window of that length and every channel of the clip; each solve is then the two
// substitutions. Each lane performs exactly BandSolver::Solve()'s operations in the same order
// (IEEE operations are exact per lane, and -std=c++20 contracts nothing into FMA), so every
// level's solution is bit for bit the scalar one.
using Lanes = double __attribute__((vector_size(128)));
constexpr int kLanes = 16;
// Wrapped in 64-byte aligned structs for the vectors that hold them: a template argument drops
// the vector type's alignment attribute, and code built for the baseline target aligns the type
// to 16 bytes only, where the AVX clone expects 32.
struct alignas(64) BandRow {
  Lanes entry[kOrder + 1];
};
struct alignas(64) LaneValues {
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
TEMPOKEY_AVX_CLONES void FactorConstantLevels(std::size_t n, const double* level,
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
  for (std::size_t i = kOrder; i < n; ++i) {
    const bool inside = i <= last_penalty;
    const Lanes a0 = inside ? interior[0] : entry(i, 0);
    const Lanes a1 = inside ? interior[1] : entry(i, 1);
    const Lanes a2 = inside ? interior[2] : entry(i, 2);
    const Lanes a3 = inside ? interior[3] : entry(i, 3);
    const Lanes* r1 = band[i - 1].entry;
    const Lanes* r2 = band[i - 2].entry;
    const Lanes* r3 = band[i - 3].entry;
    const Lanes e3 = a3 / r3[0];
    const Lanes e2 = (a2 - e3 * r2[1]) / r2[0];
    Lanes s1 = a1 - e2 * r1[1];
    s1 -= e3 * r1[2];
    const Lanes e1 = s1 / r1[0];
    Lanes s0 = a0 - e1 * e1;
    s0 -= e2 * e2;
    s0 -= e3 * e3;
    Lanes* row = band[i].entry;
    row[0] = Root(s0);
    row[1] = e1;
    row[2] = e2;
    row[3] = e3;
  }
}

// Solves L L^T y = x for the sixteen factors of `band` (FactorConstantLevels()): forward, then back
// substitution, as BandSolver does. y[i].value[l] is level l's solution at frame i.
TEMPOKEY_AVX_CLONES void SubstituteConstantLevels(const double* x, std::size_t n,
                                                  const BandRow* band, LaneValues* y) {
  for (std::size_t i = 0; i < n; ++i) {
    const Lanes* row = band[i].entry;
    Lanes f = Broadcast(x[i]);
    if (i >= kOrder) {
      f -= row[1] * y[i - 1].value;
      f -= row[2] * y[i - 2].value;
      f -= row[3] * y[i - 3].value;
    } else {
      for (int k = 1; k <= kOrder && i >= static_cast<std::size_t>(k); ++k) {
        f -= row[k] * y[i - static_cast<std::size_t>(k)].value;
      }
    }
    y[i].value = f / row[0];
  }
  for (std::size_t i = n; i-- > 0;) {
    Lanes s = y[i].value;
    if (i + kOrder < n) {
      s -= band[i + 1].entry[1] * y[i + 1].value;
      s -= band[i + 2].entry[2] * y[i + 2].value;
      s -= band[i + 3].entry[3] * y[i + 3].value;
    } else {
      for (int k = 1; k <= kOrder && i + static_cast<std::size_t>(k) < n; ++k) {
        const auto uk = static_cast<std::size_t>(k);
        s -= band[i + uk].entry[k] * y[i + uk].value;
      }
    }
    y[i].value = s / band[i].entry[0];
  }
}

// Residual sums of squares of the sixteen solutions `y` (of x[0 ...]) over frames [b0, b1), each
// summed frame by frame in order as a scalar loop would.
TEMPOKEY_AVX_CLONES void LaneResiduals(const LaneValues* y, const double* x, std::size_t b0,
                                       std::size_t b1, double* rss) {
  Lanes sum{};
  for (std::size_t f = b0; f < b1; ++f) {
    const Lanes r = y[f].value - x[f];
    sum += r * r;
  }
  for (int lane = 0; lane < kLanes; ++lane) rss[lane] = sum[lane];
}

}  // namespace

// Factors by (frames, the sixteen levels of a batch), oldest first.
struct reduce_internal::SmootherFactors::Store {
  struct Entry {
    std::size_t n;
    std::array<double, kLanes> level;
    std::vector<BandRow> rows;
  };

  // The factor of n frames at the sixteen levels `level`, computed on first use. Valid until the
  // next call.
  const BandRow* Get(std::size_t n, const double* level) {
    for (const Entry& entry : entries) {
      if (entry.n == n && std::equal(entry.level.begin(), entry.level.end(), level)) {
        return entry.rows.data();
      }
    }
    const std::size_t size = n * sizeof(BandRow);
    while (!entries.empty() && bytes + size > kMaxSmootherFactorBytes) {
      bytes -= entries.front().rows.size() * sizeof(BandRow);
      entries.erase(entries.begin());
    }
    Entry& entry = entries.emplace_back();
    entry.n = n;
    std::copy(level, level + kLanes, entry.level.begin());
    entry.rows.resize(n);
    FactorConstantLevels(n, level, entry.rows.data());
    bytes += size;
    return entry.rows.data();
  }

  std::vector<Entry> entries;
  std::size_t bytes = 0;
};

reduce_internal::SmootherFactors::SmootherFactors() : store_(std::make_unique<Store>()) {}
reduce_internal::SmootherFactors::~SmootherFactors() = default;

namespace {

// Frames above which a search solves level by level with BandSolver instead of sixteen levels at
// once: sixteen factors of that many frames would take more than kMaxSmootherFactorBytes.
constexpr std::size_t kMaxLaneFrames = reduce_internal::kMaxSmootherFactorBytes / sizeof(BandRow);

class NoiseSmoother {
 public:
  NoiseSmoother(std::span<const double> samples, double sigma, const NoiseFitOptions& options,
                reduce_internal::SmootherFactors& factors)
      : x_(samples),
        n_(samples.size()),
        sigma2_(sigma * sigma),
        guard_(options.guard_sigmas * sigma),
        block_(static_cast<std::size_t>(options.block_frames)),
        factors_(factors.store()) {}

  std::vector<double> Run() {
    std::vector<double> y(x_.begin(), x_.end());
    if (n_ <= kOrder + 1) return y;
    const double global = BestSingleLevel();
    // Per block: the level of least SURE on the block, solved with context on both sides.
    std::vector<double> block_log;
    for (std::size_t b0 = 0; b0 < n_; b0 += block_) block_log.push_back(BestBlockLevel(b0, global));
    std::vector<double> lambda(n_ - kOrder);
    for (int round = 0;; ++round) {
      Interpolate(block_log, lambda);
      solver_.Solve(x_, lambda, y);
      if (round == kMaxGuardRounds) break;
      bool lowered = false;
      for (std::size_t b = 0; b < block_log.size(); ++b) {
        const std::size_t b0 = b * block_;
        const std::size_t b1 = std::min(n_, b0 + block_);
        double worst = 0.0;
        for (std::size_t f = b0; f < b1; ++f) worst = std::max(worst, std::abs(y[f] - x_[f]));
        if (worst > guard_ && block_log[b] > kMinLogLambda) {
          block_log[b] = std::max(kMinLogLambda, block_log[b] - std::log10(kGuardFactor));
          lowered = true;
        }
      }
      if (!lowered) break;
    }
    return y;
  }

 private:
  // SURE on frames [b0, b1) of the solutions of x_[a0, a1) at the constant levels 10^logs[i], up
  // to the constant -n sigma^2: each one's residual there plus 2 sigma^2 times its degrees of
  // freedom. Sixteen levels per solve.
  std::vector<double> Risks(std::span<const double> logs, std::size_t a0, std::size_t a1,
                            std::size_t b0, std::size_t b1) {
    const std::size_t n = a1 - a0;
    std::vector<double> risks(logs.size());
    if (n > kMaxLaneFrames) {
      std::vector<double> y(n);
      std::vector<double> lambda(n - kOrder);
      for (std::size_t i = 0; i < logs.size(); ++i) {
        const double level = std::pow(10.0, logs[i]);
        std::fill(lambda.begin(), lambda.end(), level);
        solver_.Solve(x_.subspan(a0, n), lambda, y);
        double rss = 0.0;
        for (std::size_t f = b0; f < b1; ++f) {
          const double r = y[f - a0] - x_[f];
          rss += r * r;
        }
        risks[i] = rss + 2.0 * sigma2_ * static_cast<double>(b1 - b0) * CachedDofPerFrame(level);
      }
      return risks;
    }
    lanes_y_.resize(n);
    for (std::size_t first = 0; first < logs.size(); first += kLanes) {
      double level[kLanes];
      for (std::size_t lane = 0; lane < kLanes; ++lane) {
        level[lane] = std::pow(10.0, logs[std::min(first + lane, logs.size() - 1)]);
      }
      SubstituteConstantLevels(x_.data() + a0, n, factors_.Get(n, level), lanes_y_.data());
      double rss[kLanes];
      LaneResiduals(lanes_y_.data(), x_.data() + a0, b0 - a0, b1 - a0, rss);
      for (std::size_t lane = 0; lane < kLanes && first + lane < logs.size(); ++lane) {
        risks[first + lane] = rss[lane] + 2.0 * sigma2_ * static_cast<double>(b1 - b0) *
                                              CachedDofPerFrame(level[lane]);
      }
    }
    return risks;
  }

  // log10 of the single level of least SURE over the whole channel.
  double BestSingleLevel() {
    std::vector<double> coarse_logs;
    for (double l = kMinLogLambda; l <= kMaxLogLambda + 1e-9; l += kCoarseStep) {
      coarse_logs.push_back(l);
    }
    double best = kMinLogLambda;
    double best_risk = std::numeric_limits<double>::infinity();
    const std::vector<double> coarse_risks = Risks(coarse_logs, 0, n_, 0, n_);
    for (std::size_t i = 0; i < coarse_logs.size(); ++i) {
      if (coarse_risks[i] < best_risk) {
        best_risk = coarse_risks[i];
        best = coarse_logs[i];
      }
    }
    const double coarse = best;
    std::vector<double> fine_logs;
    for (double l : {coarse - kFineStep, coarse + kFineStep}) {
      if (l < kMinLogLambda || l > kMaxLogLambda) continue;
      fine_logs.push_back(l);
    }
    const std::vector<double> fine_risks = Risks(fine_logs, 0, n_, 0, n_);
    for (std::size_t i = 0; i < fine_logs.size(); ++i) {
      if (fine_risks[i] < best_risk) {
        best_risk = fine_risks[i];
        best = fine_logs[i];
      }
    }
    return best;
  }

  // log10 of the level of least SURE on the block starting at b0, within kBlockReach decades of
  // `global`.
  double BestBlockLevel(std::size_t b0, double global) {
    const std::size_t b1 = std::min(n_, b0 + block_);
    const std::size_t a0 = b0 >= block_ ? b0 - block_ : 0;
    const std::size_t a1 = std::min(n_, b1 + block_);
    if (a1 - a0 <= kOrder + 1) return global;
    double best = global;
    double best_risk = std::numeric_limits<double>::infinity();
    const double low = std::max(kMinLogLambda, global - kBlockReach);
    const double high = std::min(kMaxLogLambda, global + kBlockReach);
    std::vector<double> logs;
    for (double l = low; l <= high + 1e-9; l += kFineStep) logs.push_back(l);
    const std::vector<double> risks = Risks(logs, a0, a1, b0, b1);
    for (std::size_t i = 0; i < logs.size(); ++i) {
      if (risks[i] < best_risk) {
        best_risk = risks[i];
        best = logs[i];
      }
    }
    return best;
  }

  // The level of each penalty row (its centre at r + 1.5) from the block levels, geometrically
  // interpolated between block centres and held beyond the first and last.
  void Interpolate(const std::vector<double>& block_log, std::vector<double>& lambda) const {
    const auto block = static_cast<double>(block_);
    const auto last = static_cast<std::ptrdiff_t>(block_log.size()) - 1;
    for (std::size_t r = 0; r < lambda.size(); ++r) {
      const double position = (static_cast<double>(r) + 1.5 - 0.5 * block) / block;
      const double below = std::floor(position);
      const double t = position - below;
      const auto k = static_cast<std::ptrdiff_t>(below);
      const double l0 = block_log[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(k, 0, last))];
      const double l1 =
          block_log[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(k + 1, 0, last))];
      lambda[r] = std::pow(10.0, l0 + t * (l1 - l0));
    }
  }

  std::span<const double> x_;
  std::size_t n_;
  double sigma2_;
  double guard_;
  std::size_t block_;
  BandSolver solver_;
  reduce_internal::SmootherFactors::Store& factors_;
  std::vector<LaneValues> lanes_y_;
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
  return reduce_internal::SmoothToNoise(samples, sigma, options, factors);
}

absl::StatusOr<SplineFit> FitToNoise(std::span<const double> samples, double sigma,
                                     const NoiseFitOptions& options, std::stop_token stop) {
  reduce_internal::SmootherFactors factors;
  return reduce_internal::FitToNoise(samples, sigma, options, stop, factors);
}

std::vector<double> reduce_internal::SmoothToNoise(std::span<const double> samples, double sigma,
                                                   const NoiseFitOptions& options,
                                                   SmootherFactors& factors) {
  return NoiseSmoother(samples, sigma, options, factors).Run();
}

absl::StatusOr<SplineFit> reduce_internal::FitToNoise(std::span<const double> samples,
                                                      double sigma,
                                                      const NoiseFitOptions& options,
                                                      std::stop_token stop,
                                                      SmootherFactors& factors) {
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
  TEMPOKEY_RETURN_IF_ERROR(ValidateOptions(options));
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  const std::vector<double> smooth = SmoothToNoise(samples, sigma, options, factors);
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  const std::span<const double> channel(smooth);
  const double bound = options.key_sigmas * sigma;
  return FitWithinTolerance({&channel, 1}, {&bound, 1}, {}, stop);
}

}  // namespace tempokey::core
