// Joint world-position error of a reduction (SPEC 4.4): how far the reduced curves move every
// joint and end site from where the source puts it, measured through the skeleton with the one
// forward kinematics (model/kinematics.h) at every source frame.
#ifndef TEMPOKEY_CORE_REDUCE_WORLD_ERROR_H_
#define TEMPOKEY_CORE_REDUCE_WORLD_ERROR_H_

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/model/kinematics.h"

namespace tempokey::core {

// Distances are in file units; percentages are of the figure's height (FigureHeight(): the
// vertical extent of every joint and end site at the source's first frame).
struct WorldErrorReport {
  double figure_height = 0.0;
  // The largest distance between a point's reduced and source positions over every point
  // (joints and end sites) and frame, where it is (the first point, then frame, on ties) and the
  // point's name (SkeletonPointName()).
  double max_error = 0.0;
  SkeletonPoint worst_point{.joint = 0, .end_site = -1};
  std::string worst_point_name;
  std::int64_t worst_frame = 0;
  // Root mean square of that distance over every point and frame.
  double rms_error = 0.0;
  // The world bound the reduction kept to (file units); 0 when it had none.
  double joint_tolerance = 0.0;

  // max_error and rms_error as a percentage of figure_height (0 when the height is 0).
  double max_error_percent() const { return Percent(max_error); }
  double rms_error_percent() const { return Percent(rms_error); }
  double Percent(double distance) const {
    return figure_height > 0.0 ? 100.0 * distance / figure_height : 0.0;
  }

  friend bool operator==(const WorldErrorReport&, const WorldErrorReport&) = default;
};

// Measures `keyed` against `clip` through the skeleton: at every source frame f, every point's
// position with every channel at EvaluateCurve(curve, f * frame_time_seconds) against its
// position with the clip's samples.
//
// Errors: kInvalidArgument when the clip has no skeleton, either fails validation, or the channel
// count or kinds differ.
// Thread-safe: a pure function of its arguments.
absl::StatusOr<WorldErrorReport> MeasureWorldError(const Clip& clip, const KeyedClip& keyed);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_WORLD_ERROR_H_
