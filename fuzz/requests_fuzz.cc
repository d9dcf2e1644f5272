// The server's checks of the two requests that carry work, on fuzzed clips and operations
// together: a SubmitJobRequest with an inline clip or a clip id (first byte even), or a Process
// stream of ProcessRequest records (header, samples, sample slices, then start; first byte odd),
// through the same functions the handlers call (server::CheckId, wire::ClipFromProto /
// wire::ClipAssembler, server::PrepareSteps with a work limit). Refusals are clean; what they
// accept within the fuzz limits runs when cheap and must succeed.
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "google/protobuf/stubs/logging.h"
#include "proto/clip_convert.h"
#include "server/reactors.h"

namespace {

using namespace tempokey;
using namespace tempokey::fuzz;

// A server's work limit small enough that what passes runs in milliseconds.
constexpr double kWorkLimitSeconds = kMaxRunSeconds;

void CheckPreparedAndRun(const core::Clip& clip,
                         const google::protobuf::RepeatedPtrField<v1::Operation>& operations) {
  const absl::StatusOr<std::vector<core::PipelineStep>> steps =
      server::PrepareSteps(operations, clip, FuzzLimits(), kWorkLimitSeconds);
  if (!steps.ok()) {
    CheckCleanRefusal(steps.status(), "PrepareSteps");
    return;
  }
  ValidateAndRunIfCheap(clip, *steps);
}

void SubmitJob(std::string_view bytes) {
  v1::SubmitJobRequest request;
  if (!request.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) return;
  switch (request.source_case()) {
    case v1::SubmitJobRequest::kClipId: {
      const absl::Status id = server::CheckId("clip_id", request.clip_id());
      if (!id.ok()) CheckCleanRefusal(id, "CheckId");
      return;  // the clip would come from the store
    }
    case v1::SubmitJobRequest::kInlineClip: {
      const absl::StatusOr<core::Clip> clip =
          wire::ClipFromProto(request.inline_clip(), FuzzLimits());
      if (!clip.ok()) {
        CheckCleanRefusal(clip.status(), "ClipFromProto");
        return;
      }
      CheckPreparedAndRun(*clip, request.operations());
      return;
    }
    case v1::SubmitJobRequest::SOURCE_NOT_SET:
      return;
  }
}

void Process(const std::uint8_t* data, std::size_t size) {
  wire::ClipAssembler assembler(FuzzLimits());
  for (const Record& record : Records(data, size)) {
    v1::ProcessRequest request;
    if (!request.ParseFromArray(record.payload.data(), static_cast<int>(record.payload.size()))) {
      return;
    }
    absl::Status status;
    switch (request.part_case()) {
      case v1::ProcessRequest::kHeader:
        status = assembler.AddHeader(request.header());
        break;
      case v1::ProcessRequest::kSamples:
        status = assembler.AddSamples(request.samples());
        break;
      case v1::ProcessRequest::kSampleSlices:
        status = assembler.AddSampleSlices(request.sample_slices());
        break;
      case v1::ProcessRequest::kStart: {
        if (!assembler.has_header()) return;  // refused by the handler before any conversion
        absl::StatusOr<core::Clip> clip = std::move(assembler).Finish();
        if (!clip.ok()) {
          CheckCleanRefusal(clip.status(), "ClipAssembler::Finish");
          return;
        }
        CheckPreparedAndRun(*clip, request.start().operations());
        return;  // the call reads nothing after its start
      }
      case v1::ProcessRequest::PART_NOT_SET:
        return;
    }
    if (!status.ok()) {
      CheckCleanRefusal(status, "ClipAssembler");
      return;
    }
  }
}

}  // namespace

TEMPOKEY_FUZZ_QUIET_PROTOBUF()

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  if (data[0] % 2 == 0) {
    SubmitJob(AsText(data + 1, size - 1));
  } else {
    Process(data + 1, size - 1);
  }
  return 0;
}
