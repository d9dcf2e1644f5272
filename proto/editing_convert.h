// The editing messages of tempokey.v1 (editing.proto) to and from core types: retime plans,
// speed knots and export formats.
#ifndef TEMPOKEY_PROTO_EDITING_CONVERT_H_
#define TEMPOKEY_PROTO_EDITING_CONVERT_H_

#include <cstdint>
#include <span>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/io/file_formats.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/v1/editing.pb.h"

namespace tempokey::wire {

namespace v1 = ::tempokey::v1;

// PlanRetimeRequest.max_points: 0 means this many; more than kMaxPlanPoints is refused.
inline constexpr std::int32_t kDefaultPlanPoints = 20000;
inline constexpr std::int32_t kMaxPlanPoints = 100000;

// A RetimeOperation as a core step, with the encoding checks of PipelineFromProto() (messages
// start "retime."). Values are core::ValidateRetime()'s to check.
// Errors: kInvalidArgument "retime.speed_over_source[2].time has no unit: set seconds or frames".
absl::StatusOr<core::RetimeStep> RetimeStepFromProto(const v1::RetimeOperation& retime);

// The indices of at most `max_points` (>= 2) output samples out of `count` (>= 1), evenly spread,
// first and last included, increasing; every index when count <= max_points.
std::vector<std::int64_t> PlanPointIndices(std::int64_t count, std::int64_t max_points);

// `plan` of `step` on a clip of `source_frame_time_seconds` and `source_frame_count` frames, with
// the map at the output samples PlanPointIndices() picks (max_points >= 2).
v1::RetimePlan RetimePlanToProto(const core::RetimePlan& plan, const core::RetimeStep& step,
                                 double source_frame_time_seconds,
                                 std::int64_t source_frame_count, std::int64_t max_points);

v1::SpeedKnot SpeedKnotToProto(const core::SpeedKnot& knot);

v1::ExportFormat ExportFormatToProto(const core::ExportFormat& format);

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_EDITING_CONVERT_H_
