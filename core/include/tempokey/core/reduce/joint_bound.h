// The world-space bound of key reduction (SPEC 4.4, `--joint-tolerance D` or `D%`): every joint
// and end site stays within D of its source position at every source frame.
//
// How the tolerance method gets there (joint_bound.cc):
//   1. Levers. A position channel's error moves its joint and everything below by at most that
//      error. A rotation error of θ at joint i moves a point at distance r below it by at most
//      2·r·sin(θ/2) <= r·θ (θ in radians), and the three Euler channels of a joint turn it by at
//      most the sum of their errors. So each rotation channel gets a lever: the largest distance,
//      over every frame of the source, from its joint to any point it moves (descendants and end
//      sites), and at least kMinLeverHeightFraction of the figure's height, the distance at which
//      ozz-animation's optimizer measures a joint's error by default (10 cm) to stand for the
//      skin around a bone: a hand or head whose end site sits on the joint still keeps its
//      orientation.
//   2. Budgets (ozz-style, each channel alone may use the whole bound): a rotation channel of
//      lever r gets 2·asin(D / 2r), a position channel D; per-channel bounds given as well cap them.
//   3. Fit every channel with tolerance_fit within its budget; place every point of the result at
//      every frame by forward kinematics and compare with the source.
//   4. For each point over D, tighten only the channels on its chain (its joint's and its
//      ancestors' position channels, the rotation channels above it) by the factor its error
//      asks for, never below the guaranteed budget: D / (lever · n), n the number of non-constant
//      channels on the chain, with which the triangle inequality alone keeps the point within D
//      whatever the errors. Refit what changed (reduce.cc's fitter starts each refit from the
//      keys of the group's last fit: fewer keys to insert and to try removing); repeat. From round
//      kJointBoundSnapRound every channel on a chain still over the bound takes its guaranteed
//      budget, so the next verification passes: the bound always holds (checked, not assumed).
#ifndef TEMPOKEY_CORE_REDUCE_JOINT_BOUND_H_
#define TEMPOKEY_CORE_REDUCE_JOINT_BOUND_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/kinematics.h"

namespace tempokey::core {

// A world-space bound: `value` file units, or `value` percent of the figure's height
// (FigureHeight(): the vertical extent of every joint and end site at the first frame).
struct JointTolerance {
  double value = 1.0;
  bool percent_of_height = false;

  friend bool operator==(const JointTolerance&, const JointTolerance&) = default;
};

// A rotation channel's lever is at least this fraction of the figure's height (ozz-animation's
// AnimationOptimizer measures error 10 cm from each joint by default, 6 % of a 1.7 m figure:
// include/ozz/animation/offline/animation_optimizer.h, Setting::distance).
inline constexpr double kMinLeverHeightFraction = 0.06;
// Tightening rounds before chains still over the bound take their guaranteed budgets.
inline constexpr int kJointBoundSnapRound = 6;

// "1" for 1 file unit, "0.5%" for 0.5 % of the figure's height: the CLI's spelling.
std::string FormatJointTolerance(const JointTolerance& tolerance);

// Errors: kInvalidArgument "tolerance.joint_tolerance must be > 0, got -1" (finite and > 0).
absl::Status ValidateJointTolerance(const JointTolerance& tolerance);

// The bound in file units for a figure `figure_height` tall (file units).
// Errors: kInvalidArgument as ValidateJointTolerance(); kFailedPrecondition for a percentage
// when the height is not > 0 ("tolerance.joint_tolerance 0.5% is relative to the figure's
// height, which is 0 (every joint and end site at one height at the first frame)").
absl::StatusOr<double> ResolveJointTolerance(const JointTolerance& tolerance,
                                             double figure_height);

// The smallest joint bound, as a fraction of the clip's reach (the largest |coordinate| of any
// joint or end site at any frame, file units): world positions are computed in doubles, whose
// rounding at that distance (about 1e-16 of it per operation) no fit can get under; a bound near
// it would leave chains over the bound at every budget.
inline constexpr double kMinJointBoundOfReach = 1e-12;

// OK when `bound` (file units, resolved from `tolerance`) is at least kMinJointBoundOfReach of
// the reach of `source`, the clip's joint and end-site trajectories.
// Errors: kInvalidArgument "tolerance.joint_tolerance 1e-15 is below what this clip's joint
// positions can be computed to: at least 1.7e-10 file units (1e-12 of the 170 file units its
// joints reach from the origin)".
absl::Status CheckJointBoundAboveRounding(const JointTolerance& tolerance, double bound,
                                          const PointTrajectories& source);

// Before any work (the pipeline's validation): refuses a joint bound below twice the floor of
// CheckJointBoundAboveRounding(), the reach taken as an upper bound from the skeleton alone
// (along each chain, every offset's length plus the largest values of the joint's position
// channels), so that what passes here passes there too, after a retime's overshoot as well.
// Errors: kInvalidArgument as CheckJointBoundAboveRounding(); those of ResolveJointTolerance().
absl::Status CheckJointBoundForClip(const JointTolerance& tolerance, const Clip& clip);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_JOINT_BOUND_H_
