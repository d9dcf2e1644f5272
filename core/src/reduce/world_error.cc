// Joint world-position error (SPEC 4.4), through the one forward kinematics.
#include "tempokey/core/reduce/world_error.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"
#include "reduction_internal.h"
#include "world_error_internal.h"

namespace tempokey::core {
namespace reduce_internal {
namespace {

// Samples evaluated between two looks at the stop token.
constexpr std::size_t kSamplePiece = 65536;
// Angles whose cosines and sines MeasureChanged() keeps at most (64 MB); longer clips are measured
// whole every time rather than double the memory their rotations take.
constexpr std::size_t kMaxKeptAngles = std::size_t{1} << 22;
// Frames placed together before their errors are summed.
constexpr std::size_t kMeasureFrames = 4 * ForwardKinematics::kBlockFrames;

}  // namespace

absl::StatusOr<WorldErrorMeter> WorldErrorMeter::ForClip(const Clip& clip) {
  if (clip.skeleton.empty()) {
    return absl::InvalidArgumentError("forward kinematics needs a skeleton, the clip has none");
  }
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  return ForValidatedClip(clip);
}

absl::StatusOr<WorldErrorMeter> WorldErrorMeter::ForValidatedClip(const Clip& clip,
                                                                  std::stop_token stop) {
  TEMPOKEY_ASSIGN_OR_RETURN(ForwardKinematics fk, ForwardKinematics::ForLayout(clip));
  WorldErrorMeter meter(clip, std::move(fk), std::move(stop));
  // WorldTrajectories(clip), with the meter's own forward kinematics.
  std::vector<std::span<const double>> samples;
  samples.reserve(clip.channels.size());
  for (const Channel& channel : clip.channels) samples.emplace_back(channel.samples);
  PointTrajectories& source = meter.source_;
  source.points = meter.fk_.points();
  source.frame_count = clip.frame_count;
  const std::size_t n = source.points.size();
  const auto frame_count = static_cast<std::size_t>(clip.frame_count);
  // Grown a piece at a time within its reserved size, so that zeroing its pages (hundreds of MB
  // for the longest clips) is stopped with the placing.
  source.positions.reserve(frame_count * n);
  for (std::size_t first = 0; first < frame_count; first += kMeasureFrames) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(meter.stop_));
    const std::size_t count = std::min(kMeasureFrames, frame_count - first);
    source.positions.resize((first + count) * n);
    meter.fk_.PoseFrames(samples, first, count,
                         std::span<Vec3>(source.positions).subspan(first * n, count * n));
  }
  meter.figure_height_ =
      VerticalExtent(std::span<const Vec3>(source.positions).first(source.points.size()));
  meter.scratch_.resize(kMeasureFrames * source.points.size());
  return meter;
}

template <class Place>
PointErrors WorldErrorMeter::MeasureFrames(Place place) {
  const std::size_t n = source_.points.size();
  PointErrors errors;
  errors.max_error.assign(n, 0.0);
  errors.worst_frame.assign(n, 0);
  const auto frame_count = static_cast<std::size_t>(source_.frame_count);
  for (std::size_t first = 0; first < frame_count; first += kMeasureFrames) {
    if (stop_.stop_requested()) break;  // the caller looks at the stop before the errors
    const std::size_t count = std::min(kMeasureFrames, frame_count - first);
    place(first, count, std::span<Vec3>(scratch_).first(count * n));
    AddErrors(first, count, errors);
  }
  return errors;
}

PointErrors WorldErrorMeter::Measure(std::span<const std::span<const double>> fitted) {
  return MeasureFrames([&](std::size_t first, std::size_t count, std::span<Vec3> out) {
    fk_.PoseFrames(fitted, first, count, out);
  });
}

PointErrors WorldErrorMeter::MeasureChanged(std::span<const std::span<const double>> fitted,
                                            std::span<const char> changed) {
  const auto frame_count = static_cast<std::size_t>(source_.frame_count);
  std::size_t rotation_channels = 0;
  for (const Channel& channel : clip_->channels) rotation_channels += IsRotation(channel.kind);
  if (rotation_channels * frame_count > kMaxKeptAngles) return Measure(fitted);
  const bool first_call = cosines_.empty();
  if (first_call) {
    cosines_.resize(fitted.size());
    sines_.resize(fitted.size());
  }
  for (std::size_t c = 0; c < fitted.size(); ++c) {
    if (!IsRotation(clip_->channels[c].kind) || (!first_call && !changed[c])) continue;
    cosines_[c].resize(frame_count);
    sines_[c].resize(frame_count);
    ForwardKinematics::RotationTrig(fitted[c].first(frame_count), cosines_[c], sines_[c]);
  }
  const std::vector<std::span<const double>> cosines = Spans(cosines_);
  const std::vector<std::span<const double>> sines = Spans(sines_);
  return MeasureFrames([&](std::size_t first, std::size_t count, std::span<Vec3> out) {
    fk_.PoseFramesFromTrig(fitted, cosines, sines, first, count, out);
  });
}

void WorldErrorMeter::AddErrors(std::size_t first, std::size_t count, PointErrors& errors) const {
  const std::size_t n = source_.points.size();
  // The sum is held here and stored once: added through `errors`, every addition would wait on
  // the store of the one before (the stores to max_error may alias it). The same additions in
  // the same order, so the same bits.
  double squared_sum = errors.squared_sum;
  double* const max_error = errors.max_error.data();
  std::int64_t* const worst_frame = errors.worst_frame.data();
  for (std::size_t i = 0; i < count; ++i) {
    const auto f = static_cast<std::int64_t>(first + i);
    for (std::size_t p = 0; p < n; ++p) {
      const Vec3& a = scratch_[i * n + p];
      const Vec3& b = source_.at(f, p);
      const double dx = a[0] - b[0];
      const double dy = a[1] - b[1];
      const double dz = a[2] - b[2];
      const double squared = dx * dx + dy * dy + dz * dz;
      squared_sum += squared;
      const double distance = std::sqrt(squared);
      if (distance > max_error[p]) {
        max_error[p] = distance;
        worst_frame[p] = f;
      }
    }
  }
  errors.squared_sum = squared_sum;
}

WorldErrorReport WorldErrorMeter::Report(const PointErrors& errors, double joint_tolerance) const {
  WorldErrorReport report;
  report.figure_height = figure_height_;
  report.joint_tolerance = joint_tolerance;
  std::size_t worst = 0;
  for (std::size_t p = 0; p < errors.max_error.size(); ++p) {
    if (errors.max_error[p] > errors.max_error[worst]) worst = p;
  }
  // Ties between points go to the earliest frame, then the first point.
  for (std::size_t p = 0; p < errors.max_error.size(); ++p) {
    if (errors.max_error[p] == errors.max_error[worst] &&
        errors.worst_frame[p] < errors.worst_frame[worst]) {
      worst = p;
    }
  }
  if (!errors.max_error.empty()) {
    report.max_error = errors.max_error[worst];
    report.worst_point = source_.points[worst];
    report.worst_point_name = SkeletonPointName(clip_->skeleton, report.worst_point);
    report.worst_frame = errors.worst_frame[worst];
  }
  const double count =
      static_cast<double>(errors.max_error.size()) * static_cast<double>(source_.frame_count);
  report.rms_error = count > 0.0 ? std::sqrt(errors.squared_sum / count) : 0.0;
  return report;
}

std::vector<std::vector<double>> SampleCurves(std::span<const Curve> curves,
                                              std::int64_t frame_count, double frame_time_seconds) {
  std::vector<std::vector<double>> samples(curves.size());
  for (std::size_t c = 0; c < curves.size(); ++c) {
    samples[c].resize(static_cast<std::size_t>(frame_count));
    SampleCurve(curves[c], frame_time_seconds, samples[c]);
  }
  return samples;
}

std::vector<std::vector<double>> SampleCurves(std::span<const Curve> curves,
                                              std::int64_t frame_count, double frame_time_seconds,
                                              const std::stop_token& stop) {
  std::vector<std::vector<double>> samples(curves.size());
  for (std::size_t c = 0; c < curves.size(); ++c) {
    samples[c].resize(static_cast<std::size_t>(frame_count));
    for (std::size_t first = 0; first < samples[c].size(); first += kSamplePiece) {
      if (stop.stop_requested()) return {};
      const std::size_t count = std::min(kSamplePiece, samples[c].size() - first);
      SampleCurve(curves[c], frame_time_seconds,
                  std::span<double>(samples[c]).subspan(first, count),
                  static_cast<std::int64_t>(first));
    }
  }
  return samples;
}

std::vector<std::span<const double>> Spans(const std::vector<std::vector<double>>& samples) {
  return {samples.begin(), samples.end()};
}

}  // namespace reduce_internal

absl::StatusOr<WorldErrorReport> MeasureWorldError(const Clip& clip, const KeyedClip& keyed) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateKeyedClip(keyed));
  TEMPOKEY_ASSIGN_OR_RETURN(reduce_internal::WorldErrorMeter meter,
                            reduce_internal::WorldErrorMeter::ForClip(clip));
  TEMPOKEY_RETURN_IF_ERROR(reduce_internal::CheckCurvesFitClip(clip, keyed));
  const std::vector<std::vector<double>> fitted =
      reduce_internal::SampleCurves(keyed.curves, clip.frame_count, clip.frame_time_seconds);
  return meter.Report(meter.Measure(reduce_internal::Spans(fitted)), 0.0);
}

}  // namespace tempokey::core
