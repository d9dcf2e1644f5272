// An UploadClip (or Process) stream as the server receives it: records of a ClipHeader (tag 0),
// ChannelSamples (tag 1) or SampleSlices (tag 2), in any order, fed to wire::ClipAssembler with
// the server's checks. Every refusal is clean; a finished clip is valid and within the limits.
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "google/protobuf/stubs/logging.h"
#include "proto/clip_convert.h"

TEMPOKEY_FUZZ_QUIET_PROTOBUF()

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  const core::ClipLimits limits = FuzzLimits();
  wire::ClipAssembler assembler(limits);
  for (const Record& record : Records(data, size)) {
    absl::Status status;
    switch (record.tag % 3) {
      case 0: {
        v1::ClipHeader header;
        if (!header.ParseFromArray(record.payload.data(), static_cast<int>(record.payload.size()))) {
          return 0;
        }
        status = assembler.AddHeader(header);
        break;
      }
      case 1: {
        v1::ChannelSamples samples;
        if (!samples.ParseFromArray(record.payload.data(), static_cast<int>(record.payload.size()))) {
          return 0;
        }
        status = assembler.AddSamples(samples);
        break;
      }
      default: {
        v1::SampleSlices slices;
        if (!slices.ParseFromArray(record.payload.data(), static_cast<int>(record.payload.size()))) {
          return 0;
        }
        status = assembler.AddSampleSlices(slices);
        break;
      }
    }
    if (!status.ok()) {
      CheckCleanRefusal(status, "ClipAssembler");
      return 0;
    }
  }
  absl::StatusOr<core::Clip> clip = std::move(assembler).Finish();
  if (!clip.ok()) {
    CheckCleanRefusal(clip.status(), "ClipAssembler::Finish");
    return 0;
  }
  const absl::Status valid = core::ValidateClip(*clip, limits);
  Check(valid.ok(), "ClipAssembler finished an invalid clip", Describe(valid));
  return 0;
}
