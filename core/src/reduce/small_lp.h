// A dense linear program of a few columns and up to some thousand rows, for the fewest-keys fit
// (fewest_keys_fit.h): maximize c.z subject to A z <= b and z >= 0.
//
// The two-phase simplex method on a dictionary (Chvatal, "Linear Programming", ch. 2-3): the
// slack basis, made feasible by one artificial variable where some b_i < 0; the entering column
// by Bland's rule (the lowest index with a positive reduced cost), the leaving row by Harris's
// two-pass ratio test (of the rows whose ratio is within a tolerance of the least, the largest
// pivot), so that no pivot divides by a coefficient near rounding. Each row is divided by its
// largest coefficient as it is added, and the tolerances (1e-9, 1e-11) are absolute on those
// rows: a row whose coefficients span many orders of magnitude can be misjudged (a coefficient
// below 1e-9 counts as zero, and the basis's values are clamped at 0). Callers keep their
// columns of one scale, a margin of their own, and check every solution they take.
#ifndef TEMPOKEY_CORE_SRC_REDUCE_SMALL_LP_H_
#define TEMPOKEY_CORE_SRC_REDUCE_SMALL_LP_H_

#include <span>
#include <vector>

namespace tempokey::core::reduce_internal {

class SmallLp {
 public:
  // Starts a program of `columns` variables (>= 1), without rows.
  void Reset(int columns);
  // Adds the row a.z <= bound (a: `columns` coefficients, finite).
  void AddRow(std::span<const double> a, double bound);
  int columns() const { return n_; }
  int rows() const { return static_cast<int>(bounds_.size()); }

  // Phase one: true when some z >= 0 meets every row (then Maximize() may follow, any number of
  // times, each from the last one's basis), false when none does (or the pivots ran out).
  bool FindFeasible();
  // Phase two: a z maximizing c.z (`columns` values) into `z`; false when c.z is unbounded
  // (or the pivots ran out). Precondition: FindFeasible() returned true since the last rows.
  bool Maximize(std::span<const double> c, std::vector<double>& z);
  // The basis's point (`columns` values) into `z`. Precondition: FindFeasible() returned true
  // since the last rows.
  void Point(std::vector<double>& z) const;

 private:
  double& At(int i, int j) { return tableau_[static_cast<std::size_t>(i) * cols_ + j]; }
  void Pivot(int r, int s);
  bool Iterate();
  void DropArtificial();

  int n_ = 0;                   // variables
  std::vector<double> rows_;    // the rows as added (normalized), n_ each
  std::vector<double> bounds_;  // their bounds
  // The dictionary: basic variable i = beta_[i] - sum_j At(i, j) * nonbasic variable j;
  // objective = zeta_ + sum_j gamma_[j] * nonbasic j. Variable ids: 0..n_-1 the program's,
  // n_ the artificial one, n_ + 1 + i the slack of row i.
  int m_ = 0;
  int cols_ = 0;
  std::vector<double> tableau_;
  std::vector<double> beta_;
  std::vector<double> gamma_;
  double zeta_ = 0.0;
  std::vector<int> basic_;
  std::vector<int> nonbasic_;
};

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_SMALL_LP_H_
