// The joint-bound fit of ReduceKeys() (the method is described in joint_bound.h): per-channel
// budgets from levers, fit, verification by forward kinematics, tightening along the chains
// still over the bound.
#ifndef TEMPOKEY_CORE_SRC_REDUCE_JOINT_BOUND_FIT_H_
#define TEMPOKEY_CORE_SRC_REDUCE_JOINT_BOUND_FIT_H_

#include <cstddef>
#include <functional>
#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/keyed_clip.h"
#include "world_error_internal.h"

namespace tempokey::core::reduce_internal {

// Fits every channel of the alignment groups `groups` (indices into the caller's groups) within
// bounds[c] (value units), writing curves[c] of each. Called again for the groups whose budgets
// were tightened; it may keep what it learnt of a group between calls (reduce.cc's fitter
// starts a refit from the keys of the group's last fit).
using GroupFitter = std::function<absl::Status(std::span<const std::size_t> groups,
                                               std::span<const double> bounds,
                                               std::vector<Curve>& curves)>;

// A joint-bound fit: the curves, and what their verification measured.
struct JointBoundCurves {
  std::vector<Curve> curves;
  std::vector<std::vector<double>> samples;  // per channel, its curve at every frame
  PointErrors errors;                        // of `samples`: every point within the bound
};

class JointBoundPlan {
 public:
  // `meter` measures against the clip being reduced and must outlive the plan; `inputs` are the
  // samples being fitted (one span per channel, rotations unwrapped).
  JointBoundPlan(WorldErrorMeter& meter, std::span<const std::span<const double>> inputs);

  // Per channel, the budget with which every point stays within `bound` (file units) by the
  // triangle inequality alone, whatever each channel's error within its budget: degrees for
  // rotations, file units for positions; +infinity for channels no point depends on (scalars,
  // constant channels, rotations that move nothing on a figure without height).
  std::vector<double> GuaranteedBudgets(double bound) const;

  // Curves within `bound` at every point and frame (verified). Each channel's budget is also
  // capped by caps[c] (+infinity for none); a channel left without a finite budget takes
  // fallback[c]. `groups` are the alignment groups, fitted through `fit`.
  // Errors: kCancelled from `stop`; what `fit` returns; kInternal if the guaranteed budgets ever
  // failed verification (a broken invariant).
  absl::StatusOr<JointBoundCurves> Fit(double bound, std::span<const double> caps,
                                         std::span<const double> fallback,
                                         const std::vector<std::vector<int>>& groups,
                                         const GroupFitter& fit, std::stop_token stop);

 private:
  // Budgets each channel would take alone, capped.
  std::vector<double> InitialBudgets(double bound) const;

  WorldErrorMeter& meter_;
  // Per channel: file units of point movement per degree (rotations) or per file unit
  // (positions); 0 for channels that move nothing.
  std::vector<double> lever_;
  // Per point: the channels that move it (constant channels left out).
  std::vector<std::vector<int>> chain_;
};

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_JOINT_BOUND_FIT_H_
