// Pipeline operations and their reports as tempokey.v1 messages (operations.proto), shared by the
// server and the client. The encoding's own mistakes are refused here; every value is core's to
// check (core::ValidatePipeline()).
#ifndef TEMPOKEY_PROTO_OPERATIONS_CONVERT_H_
#define TEMPOKEY_PROTO_OPERATIONS_CONVERT_H_

#include <vector>

#include "absl/status/statusor.h"
#include "google/protobuf/repeated_field.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/v1/operations.pb.h"

namespace tempokey::wire {

namespace v1 = ::tempokey::v1;

// Each Operation as a core pipeline step. Checks only what the encoding itself can get wrong (an
// empty oneof, two warp domains at once, a time point without a unit, an enum value out of
// range); every value is core::ValidatePipeline()'s to check, with the one set of limits and
// messages core has ("operation 2 (reduce): paper.step_y must be > 0, got -1"). Unset proto3
// `optional` fields and 0 speeds or 0/0 rates take core's defaults.
// Errors: kInvalidArgument "operation 2: retime takes at most one of speed_over_source,
//         speed_over_output and time_map, got speed_over_source and time_map".
absl::StatusOr<std::vector<core::PipelineStep>> PipelineFromProto(
    const google::protobuf::RepeatedPtrField<v1::Operation>& operations);

// The inverse, for clients that build steps in core terms (the CLI).
v1::Operation PipelineStepToProto(const core::PipelineStep& step);

v1::OperationReport StepReportToProto(const core::StepReport& report);
core::StepReport StepReportFromProto(const v1::OperationReport& report);

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_OPERATIONS_CONVERT_H_
