// The noise-aware key reduction (SPEC 4.3); the method is described in noise_fit.h.
#include "tempokey/core/reduce/noise_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

// The 0.75 quantile of the standard normal: the median of |z| for z ~ N(0, 1).
constexpr double kNormalMedianAbs = 0.6744897501960817;
// Variance of a third difference of unit white noise: 1 + 9 + 9 + 1.
constexpr double kThirdDifferenceVariance = 20.0;
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

// Degrees of freedom per frame of the smoother with level `lambda` on an endless signal:
// (1 / pi) * integral over [0, pi] of 1 / (1 + lambda (2 sin(w / 2))^6), by the midpoint rule.
double DofPerFrame(double lambda) {
  double sum = 0.0;
  for (int k = 0; k < kTraceNodes; ++k) {
    const double w = std::numbers::pi * (k + 0.5) / kTraceNodes;
    const double s = 2.0 * std::sin(0.5 * w);
    const double s2 = s * s;
    sum += 1.0 / (1.0 + lambda * s2 * s2 * s2);
  }
  return sum / kTraceNodes;
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

class NoiseSmoother {
 public:
  NoiseSmoother(std::span<const double> samples, double sigma, const NoiseFitOptions& options)
      : x_(samples),
        n_(samples.size()),
        sigma2_(sigma * sigma),
        guard_(options.guard_sigmas * sigma),
        block_(static_cast<std::size_t>(options.block_frames)) {}

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
  // SURE of levels `lambda` on frames [b0, b1) of the fit `y` of x_[a0 ...], up to the constant
  // -n sigma^2: the residual plus 2 sigma^2 times the degrees of freedom.
  double Risk(std::span<const double> y, std::size_t a0, std::size_t b0, std::size_t b1,
              double dof_per_frame) const {
    double rss = 0.0;
    for (std::size_t f = b0; f < b1; ++f) {
      const double r = y[f - a0] - x_[f];
      rss += r * r;
    }
    return rss + 2.0 * sigma2_ * static_cast<double>(b1 - b0) * dof_per_frame;
  }

  // log10 of the single level of least SURE over the whole channel.
  double BestSingleLevel() {
    std::vector<double> y(n_);
    std::vector<double> lambda(n_ - kOrder);
    auto risk = [&](double log_lambda) {
      std::fill(lambda.begin(), lambda.end(), std::pow(10.0, log_lambda));
      solver_.Solve(x_, lambda, y);
      return Risk(y, 0, 0, n_, DofPerFrame(lambda[0]));
    };
    double best = kMinLogLambda;
    double best_risk = std::numeric_limits<double>::infinity();
    for (double l = kMinLogLambda; l <= kMaxLogLambda + 1e-9; l += kCoarseStep) {
      const double r = risk(l);
      if (r < best_risk) {
        best_risk = r;
        best = l;
      }
    }
    const double coarse = best;
    for (double l : {coarse - kFineStep, coarse + kFineStep}) {
      if (l < kMinLogLambda || l > kMaxLogLambda) continue;
      const double r = risk(l);
      if (r < best_risk) {
        best_risk = r;
        best = l;
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
    const std::span<const double> x = x_.subspan(a0, a1 - a0);
    if (x.size() <= kOrder + 1) return global;
    std::vector<double> y(x.size());
    std::vector<double> lambda(x.size() - kOrder);
    double best = global;
    double best_risk = std::numeric_limits<double>::infinity();
    const double low = std::max(kMinLogLambda, global - kBlockReach);
    const double high = std::min(kMaxLogLambda, global + kBlockReach);
    for (double l = low; l <= high + 1e-9; l += kFineStep) {
      const double level = std::pow(10.0, l);
      std::fill(lambda.begin(), lambda.end(), level);
      solver_.Solve(x, lambda, y);
      const double r = Risk(y, a0, b0, b1, DofPerFrame(level));
      if (r < best_risk) {
        best_risk = r;
        best = l;
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

double EstimateNoiseSigma(std::span<const double> samples) {
  if (samples.size() < kOrder + 1) return 0.0;
  std::vector<double> d(samples.size() - kOrder);
  for (std::size_t f = 0; f < d.size(); ++f) {
    d[f] = std::abs(samples[f + 3] - 3.0 * samples[f + 2] + 3.0 * samples[f + 1] - samples[f]);
  }
  const auto middle = static_cast<std::ptrdiff_t>(d.size() / 2);
  std::nth_element(d.begin(), d.begin() + middle, d.end());
  double median = d[static_cast<std::size_t>(middle)];
  if (d.size() % 2 == 0) {
    median = 0.5 * (median + *std::max_element(d.begin(), d.begin() + middle));
  }
  return median / (kNormalMedianAbs * std::sqrt(kThirdDifferenceVariance));
}

std::vector<double> SmoothToNoise(std::span<const double> samples, double sigma,
                                  const NoiseFitOptions& options) {
  return NoiseSmoother(samples, sigma, options).Run();
}

absl::StatusOr<SplineFit> FitToNoise(std::span<const double> samples, double sigma,
                                     const NoiseFitOptions& options, std::stop_token stop) {
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
  const std::vector<double> smooth = SmoothToNoise(samples, sigma, options);
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  const std::span<const double> channel(smooth);
  const double bound = options.key_sigmas * sigma;
  return FitWithinTolerance({&channel, 1}, {&bound, 1}, {}, stop);
}

}  // namespace tempokey::core
