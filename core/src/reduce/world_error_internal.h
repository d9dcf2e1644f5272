// The world-error measurement shared by ReduceKeys() (its report and the joint bound's
// verification) and MeasureWorldError(): the source's points placed once, any number of fitted
// sample sets measured against them.
#ifndef TEMPOKEY_CORE_SRC_REDUCE_WORLD_ERROR_INTERNAL_H_
#define TEMPOKEY_CORE_SRC_REDUCE_WORLD_ERROR_INTERNAL_H_

#include <cstdint>
#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/reduce/world_error.h"

namespace tempokey::core::reduce_internal {

// Per point (SkeletonPoints() order): the largest distance from the source over every frame and
// the first frame where it is; the sum of squared distances over every point and frame.
struct PointErrors {
  std::vector<double> max_error;
  std::vector<std::int64_t> worst_frame;
  double squared_sum = 0.0;
};

// Borrows `clip`, which must outlive the meter. Holds the source's world positions of every point
// at every frame (points x frames x 3 doubles). Not thread-safe (forward kinematics scratch).
class WorldErrorMeter {
 public:
  // Errors: kInvalidArgument when the clip has no skeleton or fails ValidateClip().
  static absl::StatusOr<WorldErrorMeter> ForClip(const Clip& clip);

  // ForClip() for a clip that has passed ValidateClip() already (ReduceKeys()), without checking
  // its samples again. `stop` is looked at every kMeasureFrames frames placed, here and by every
  // measure; a measure it stops returns errors of only some frames, so its caller must look at
  // `stop` before using them. Errors: kInvalidArgument when the clip has no skeleton;
  // kCancelled when `stop` was requested.
  static absl::StatusOr<WorldErrorMeter> ForValidatedClip(const Clip& clip,
                                                           std::stop_token stop = {});

  // The errors of `fitted` (one span of frame_count samples per channel of the clip).
  PointErrors Measure(std::span<const std::span<const double>> fitted);

  // Measure() of `fitted` where only the channels with changed[c] != 0 may differ from the
  // samples of the previous call (every channel is read on the first call): the cosines and
  // sines of the other rotation channels' angles are kept from call to call (two doubles per
  // rotation sample, up to 4M samples; a longer clip is measured whole). The same errors as
  // Measure(), bit for bit.
  PointErrors MeasureChanged(std::span<const std::span<const double>> fitted,
                             std::span<const char> changed);

  // The report of `errors` (as Measure() or MeasureChanged() returned them), with
  // `joint_tolerance` as the bound kept.
  WorldErrorReport Report(const PointErrors& errors, double joint_tolerance) const;

  const Clip& clip() const { return *clip_; }
  const PointTrajectories& source() const { return source_; }
  double figure_height() const { return figure_height_; }

 private:
  WorldErrorMeter(const Clip& clip, ForwardKinematics fk, std::stop_token stop)
      : clip_(&clip), fk_(std::move(fk)), stop_(std::move(stop)) {}

  // Adds the errors of frames [first, first + count), placed in scratch_, to `errors`, frame by
  // frame and point by point.
  void AddErrors(std::size_t first, std::size_t count, PointErrors& errors) const;
  // The errors of every frame, placed kMeasureFrames at a time by place(first, count, out) into
  // scratch_ (out: count frames of points) and added by AddErrors().
  template <class Place>
  PointErrors MeasureFrames(Place place);

  const Clip* clip_;
  ForwardKinematics fk_;
  std::stop_token stop_;
  PointTrajectories source_;
  double figure_height_ = 0.0;
  std::vector<Vec3> scratch_;  // placed points, frame-major, of the frames being measured
  // MeasureChanged()'s angles per channel at every frame (empty for other than rotations, and
  // before the first call).
  std::vector<std::vector<double>> cosines_;
  std::vector<std::vector<double>> sines_;
};

// Every channel's samples at every source frame of `curves` (one curve per channel, sampled at
// f * frame_time_seconds as SampleCurve() does).
std::vector<std::vector<double>> SampleCurves(std::span<const Curve> curves,
                                              std::int64_t frame_count, double frame_time_seconds);

// SampleCurves() a piece at a time, looking at `stop` between pieces; empty when it was seen.
std::vector<std::vector<double>> SampleCurves(std::span<const Curve> curves,
                                              std::int64_t frame_count, double frame_time_seconds,
                                              const std::stop_token& stop);

// MeasureFitted() (reduction_internal.h) of curves already sampled at every frame: `baked` holds
// SampleCurves() of `curves`. The same report, bit for bit, without sampling the curves again.
ReductionReport MeasureBaked(std::span<const std::span<const double>> samples,
                             std::span<const Curve> curves,
                             std::span<const std::span<const double>> baked);

// Spans over `samples`.
std::vector<std::span<const double>> Spans(const std::vector<std::vector<double>>& samples);

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_WORLD_ERROR_INTERNAL_H_
