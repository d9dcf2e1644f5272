// Operations off the wire (a ProcessStart message): wire::PipelineFromProto() refuses cleanly or
// gives steps that convert back to messages the same conversion accepts again, and that are
// validated on a small clip and, when cheap, run: what validation accepts must run.
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "google/protobuf/stubs/logging.h"
#include "proto/operations_convert.h"
#include "tempokey/v1/motion_service.pb.h"

TEMPOKEY_FUZZ_QUIET_PROTOBUF()

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  v1::ProcessStart start;
  if (!start.ParseFromArray(data, static_cast<int>(size))) return 0;
  const absl::StatusOr<std::vector<core::PipelineStep>> steps =
      wire::PipelineFromProto(start.operations());
  if (!steps.ok()) {
    CheckCleanRefusal(steps.status(), "PipelineFromProto");
    return 0;
  }
  google::protobuf::RepeatedPtrField<v1::Operation> back;
  for (const core::PipelineStep& step : *steps) *back.Add() = wire::PipelineStepToProto(step);
  const absl::StatusOr<std::vector<core::PipelineStep>> again = wire::PipelineFromProto(back);
  Check(again.ok(), "PipelineFromProto refused PipelineStepToProto's messages",
        Describe(again.status()));
  Check(again->size() == steps->size(), "operations lost converting back and forth");
  static const core::Clip clip = SmallClip();
  ValidateAndRunIfCheap(clip, *steps);
  return 0;
}
