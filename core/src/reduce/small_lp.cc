#include "core/src/reduce/small_lp.h"

#include <algorithm>
#include <cmath>
#include <cstddef>

namespace tempokey::core::reduce_internal {
namespace {

// Reduced costs and pivot coefficients below these count as zero (rows are scaled to a largest
// coefficient of 1).
constexpr double kCostTolerance = 1e-11;
constexpr double kPivotTolerance = 1e-9;
// Harris's ratio test: rows within this much of the least ratio's bound compete on pivot size.
constexpr double kRatioSlack = 1e-9;
// A basis is found in a few pivots per column; a program that needs far more is cycling on
// rounding and is given up.
constexpr int kMaxPivots = 10'000;

}  // namespace

void SmallLp::Reset(int columns) {
  n_ = columns;
  rows_.clear();
  bounds_.clear();
}

void SmallLp::AddRow(std::span<const double> a, double bound) {
  double scale = 0.0;
  for (double x : a) scale = std::max(scale, std::abs(x));
  if (scale == 0.0) scale = 1.0;
  for (double x : a) rows_.push_back(x / scale);
  bounds_.push_back(bound / scale);
}

bool SmallLp::FindFeasible() {
  m_ = rows();
  cols_ = n_ + 1;  // the last column is the artificial variable's
  tableau_.assign(static_cast<std::size_t>(m_) * static_cast<std::size_t>(cols_), 0.0);
  beta_ = bounds_;
  basic_.resize(static_cast<std::size_t>(m_));
  nonbasic_.resize(static_cast<std::size_t>(cols_));
  for (int i = 0; i < m_; ++i) {
    for (int j = 0; j < n_; ++j) At(i, j) = rows_[static_cast<std::size_t>(i) * n_ + j];
    At(i, n_) = -1.0;
    basic_[i] = n_ + 1 + i;
  }
  for (int j = 0; j <= n_; ++j) nonbasic_[j] = j;
  int most_negative = -1;
  for (int i = 0; i < m_; ++i) {
    if (beta_[i] < 0.0 && (most_negative < 0 || beta_[i] < beta_[most_negative])) {
      most_negative = i;
    }
  }
  if (most_negative >= 0) {
    // Maximize -artificial from the basis where it covers the most negative bound.
    gamma_.assign(static_cast<std::size_t>(cols_), 0.0);
    gamma_[n_] = -1.0;
    zeta_ = 0.0;
    Pivot(most_negative, n_);
    if (!Iterate() || zeta_ < -kRatioSlack) return false;
    for (int i = 0; i < m_; ++i) {
      if (basic_[i] != n_) continue;
      int s = -1;  // a degenerate pivot takes it out of the basis
      for (int j = 0; j < cols_; ++j) {
        if (std::abs(At(i, j)) > kPivotTolerance &&
            (s < 0 || std::abs(At(i, j)) > std::abs(At(i, s)))) {
          s = j;
        }
      }
      if (s < 0) return false;
      Pivot(i, s);
    }
  }
  DropArtificial();
  return true;
}

bool SmallLp::Maximize(std::span<const double> c, std::vector<double>& z) {
  // The objective in the current nonbasic variables.
  gamma_.assign(static_cast<std::size_t>(cols_), 0.0);
  zeta_ = 0.0;
  for (int j = 0; j < cols_; ++j) {
    if (nonbasic_[j] < n_) gamma_[j] = c[static_cast<std::size_t>(nonbasic_[j])];
  }
  for (int i = 0; i < m_; ++i) {
    if (basic_[i] >= n_) continue;
    const double cb = c[static_cast<std::size_t>(basic_[i])];
    zeta_ += cb * beta_[i];
    for (int j = 0; j < cols_; ++j) gamma_[j] -= cb * At(i, j);
  }
  if (!Iterate()) return false;
  Point(z);
  return true;
}

void SmallLp::Point(std::vector<double>& z) const {
  z.assign(static_cast<std::size_t>(n_), 0.0);
  for (int i = 0; i < m_; ++i) {
    if (basic_[i] < n_) z[static_cast<std::size_t>(basic_[i])] = beta_[i];
  }
}

void SmallLp::Pivot(int r, int s) {
  const double inverse = 1.0 / At(r, s);
  beta_[r] *= inverse;
  for (int j = 0; j < cols_; ++j) {
    if (j != s) At(r, j) *= inverse;
  }
  At(r, s) = inverse;
  for (int i = 0; i < m_; ++i) {
    const double a = At(i, s);
    if (i == r || a == 0.0) continue;
    beta_[i] = std::max(beta_[i] - a * beta_[r], 0.0);  // the ratio test keeps it >= -slack
    for (int j = 0; j < cols_; ++j) {
      if (j != s) At(i, j) -= a * At(r, j);
    }
    At(i, s) = -a * inverse;
  }
  const double g = gamma_[s];
  if (g != 0.0) {
    zeta_ += g * beta_[r];
    for (int j = 0; j < cols_; ++j) {
      if (j != s) gamma_[j] -= g * At(r, j);
    }
    gamma_[s] = -g * inverse;
  }
  std::swap(basic_[r], nonbasic_[s]);
}

bool SmallLp::Iterate() {
  for (int pivots = 0; pivots < kMaxPivots; ++pivots) {
    int s = -1;
    for (int j = 0; j < cols_; ++j) {
      if (gamma_[j] > kCostTolerance && (s < 0 || nonbasic_[j] < nonbasic_[s])) s = j;
    }
    if (s < 0) return true;  // optimal
    double theta = HUGE_VAL;
    for (int i = 0; i < m_; ++i) {
      const double a = At(i, s);
      if (a > kPivotTolerance) theta = std::min(theta, (std::max(beta_[i], 0.0) + kRatioSlack) / a);
    }
    int r = -1;
    for (int i = 0; i < m_; ++i) {
      const double a = At(i, s);
      if (a > kPivotTolerance && std::max(beta_[i], 0.0) / a <= theta && (r < 0 || a > At(r, s))) {
        r = i;
      }
    }
    if (r < 0) return false;  // unbounded
    Pivot(r, s);
  }
  return false;
}

void SmallLp::DropArtificial() {
  const auto at = std::find(nonbasic_.begin(), nonbasic_.end(), n_);
  if (at == nonbasic_.end()) return;
  const int s = static_cast<int>(at - nonbasic_.begin());
  const int last = cols_ - 1;
  std::vector<double> kept(static_cast<std::size_t>(m_) * static_cast<std::size_t>(last));
  for (int i = 0; i < m_; ++i) {
    for (int j = 0; j < last; ++j) {
      kept[static_cast<std::size_t>(i) * last + j] = At(i, j == s ? last : j);
    }
  }
  nonbasic_[s] = nonbasic_[last];
  nonbasic_.resize(static_cast<std::size_t>(last));
  tableau_.swap(kept);
  cols_ = last;
}

}  // namespace tempokey::core::reduce_internal
