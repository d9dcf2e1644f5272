// Rebuilds a pipeline result from the ResultPart messages of GetJobResult or Process.
#ifndef TEMPOKEY_CLIENT_RESULT_ASSEMBLER_H_
#define TEMPOKEY_CLIENT_RESULT_ASSEMBLER_H_

#include <cstdint>
#include <optional>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "proto/convert.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/v1/motion_service.pb.h"

namespace tempokey::client {

// Collects a ResultHeader, then either ChannelSamples (a sampled clip, checked slice by slice by
// wire::ClipAssembler) or KeyedCurve parts (a keyed clip; several parts of one channel are
// consecutive runs of its keys, joined in arrival order by wire::KeyedClipFromProto()).
//
// Errors (from AddPart / Finish): kInvalidArgument for parts before the header, a second header,
// samples in a keyed result or curves in a sampled one, more keys than limits.max_samples, and
// whatever the clip and keyed-clip validation refuses (a curve channel out of range, ...).
//
// Not thread-safe: one assembler per result stream.
class ResultAssembler {
 public:
  explicit ResultAssembler(core::ClipLimits limits = {});

  absl::Status AddPart(const wire::v1::ResultPart& part);
  bool has_header() const { return header_received_; }
  // The result once every part has arrived.
  absl::StatusOr<core::PipelineResult> Finish() &&;

 private:
  absl::Status AddHeader(const wire::v1::ResultHeader& header);
  absl::Status CheckSamplesExpected() const;
  absl::Status AddCurve(const wire::v1::KeyedCurve& curve);

  core::ClipLimits limits_;
  bool header_received_ = false;
  bool keyed_ = false;
  std::int64_t parts_ = 0;
  std::vector<core::StepReport> reports_;
  wire::ClipAssembler clip_;
  wire::v1::KeyedClip keyed_clip_;
  std::int64_t keys_received_ = 0;
};

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_RESULT_ASSEMBLER_H_
