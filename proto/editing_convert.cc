#include "proto/editing_convert.h"

#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/operations_convert.h"
#include "tempokey/core/model/status.h"

namespace tempokey::wire {

absl::StatusOr<core::RetimeStep> RetimeStepFromProto(const v1::RetimeOperation& retime) {
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  *operations.Add()->mutable_retime() = retime;
  absl::StatusOr<std::vector<core::PipelineStep>> steps = PipelineFromProto(operations);
  if (!steps.ok()) {
    // One operation: "operation 1: retime.x ..." says no more than "retime.x ...".
    std::string message(steps.status().message());
    constexpr std::string_view kPrefix = "operation 1: ";
    if (message.rfind(kPrefix, 0) == 0) message.erase(0, kPrefix.size());
    return absl::Status(steps.status().code(), message);
  }
  return std::get<core::RetimeStep>(std::move(steps->front()));
}

std::vector<std::int64_t> PlanPointIndices(std::int64_t count, std::int64_t max_points) {
  std::vector<std::int64_t> indices;
  if (count <= 0) return indices;
  if (count <= max_points) {
    indices.resize(static_cast<std::size_t>(count));
    for (std::int64_t j = 0; j < count; ++j) indices[static_cast<std::size_t>(j)] = j;
    return indices;
  }
  indices.reserve(static_cast<std::size_t>(max_points));
  const std::int64_t last = count - 1;
  for (std::int64_t i = 0; i < max_points; ++i) {
    // Exact integer spacing: i * last / (max_points - 1), the last one is `last` (no overflow:
    // both factors are bounded by the clip and point limits, far below 2^31).
    const std::int64_t index = i * last / (max_points - 1);
    if (indices.empty() || index > indices.back()) indices.push_back(index);
  }
  return indices;
}

v1::RetimePlan RetimePlanToProto(const core::RetimePlan& plan, const core::RetimeStep& step,
                                 double source_frame_time_seconds,
                                 std::int64_t source_frame_count, std::int64_t max_points) {
  v1::RetimePlan out;
  const core::StepReport report = plan.report;
  *out.mutable_report() = StepReportToProto(report).retime();
  out.set_source_frame_time_seconds(source_frame_time_seconds);
  out.set_output_frame_time_seconds(plan.output_frame_time_seconds);
  out.set_source_duration_seconds(static_cast<double>(source_frame_count - 1) *
                                  source_frame_time_seconds);
  const auto count = static_cast<std::int64_t>(plan.source_frames.size());
  const std::vector<std::int64_t> indices = PlanPointIndices(count, max_points);
  const auto n = static_cast<int>(indices.size());
  out.mutable_output_frames()->Reserve(n);
  out.mutable_source_time_seconds()->Reserve(n);
  out.mutable_speed()->Reserve(n);
  out.mutable_decimation_ratio()->Reserve(n);
  // ρ = |dτ/dt|·f_s/f_o, so |dτ/dt| = ρ·(source frame time)/(output frame time).
  const double ratio_to_speed = source_frame_time_seconds / plan.output_frame_time_seconds;
  for (std::int64_t j : indices) {
    const auto at = static_cast<std::size_t>(j);
    out.add_output_frames(j);
    out.add_source_time_seconds(plan.source_frames[at] * source_frame_time_seconds);
    out.add_speed(plan.decimation_ratios[at] * ratio_to_speed);
    out.add_decimation_ratio(plan.decimation_ratios[at]);
  }
  for (double t : plan.knot_output_seconds) out.add_knot_output_time_seconds(t);
  for (double t : plan.knot_source_seconds) out.add_knot_source_time_seconds(t);
  out.set_speed_text(core::FormatSpeedKnots(step.warp.speed));
  return out;
}

v1::SpeedKnot SpeedKnotToProto(const core::SpeedKnot& knot) {
  v1::SpeedKnot out;
  if (knot.time.in_frames) {
    out.mutable_time()->set_frames(knot.time.value);
  } else {
    out.mutable_time()->set_seconds(knot.time.value);
  }
  out.set_speed(knot.speed);
  return out;
}

v1::ExportFormat ExportFormatToProto(const core::ExportFormat& format) {
  v1::ExportFormat out;
  out.set_name(std::string(format.name));
  out.set_extension(std::string(format.extension));
  out.set_media_type(std::string(format.media_type));
  out.set_keyed(format.content == core::FileContent::kKeyed);
  return out;
}

}  // namespace tempokey::wire
