// Job results as tempokey.v1 ResultPart streams (motion_service.proto), both ends: the server cuts
// a pipeline result into parts (ResultSlicer), the client joins them again (ResultAssembler).
#ifndef TEMPOKEY_PROTO_JOBS_CONVERT_H_
#define TEMPOKEY_PROTO_JOBS_CONVERT_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "google/protobuf/arena.h"
#include "proto/clip_convert.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/v1/motion_service.pb.h"

namespace tempokey::wire {

namespace v1 = ::tempokey::v1;

// ServerInfo.features of what this build speaks beyond the first v1.
inline constexpr std::string_view kFeatureSampleSlices = "sample_slices";
inline constexpr std::string_view kFeatureBatchParts = "batch_parts";

// Produces the parts of a result stream one at a time (GetJobResult, Process): a ResultHeader
// with the reports, then ChannelSamples slices (sampled clip) or KeyedCurve pieces (keyed clip)
// in channel order, each carrying at most `slice_bytes` of values (<= 0: 1 MiB).
// Not thread-safe: one per stream.
class ResultSlicer {
 public:
  // `batch_parts` packs consecutive slices (SampleSlices) or curve pieces (KeyedCurves) into one
  // part up to `slice_bytes`, for clients that asked for it; otherwise one slice or piece per part.
  ResultSlicer(std::shared_ptr<const core::PipelineResult> result, std::int64_t slice_bytes,
               bool batch_parts = false);

  // Fills `part` with the next part; false once every part was produced.
  bool Next(v1::ResultPart* part);

 private:
  // The next slice of samples or piece of a curve, at most `budget_bytes` of values (at least
  // one value, or an empty curve's one empty piece), built in `arena` (nullptr: on the heap, the
  // caller's); nullptr when done.
  v1::ChannelSamples* NextSamples(std::int64_t budget_bytes, google::protobuf::Arena* arena);
  v1::KeyedCurve* NextCurve(std::int64_t budget_bytes, google::protobuf::Arena* arena);
  bool Done() const;

  std::shared_ptr<const core::PipelineResult> result_;
  std::int64_t slice_bytes_;
  bool batch_parts_;
  bool header_sent_ = false;
  int channel_ = 0;
  std::int64_t offset_ = 0;  // frame (sampled) or key (keyed) within channel_
};

// Collects a ResultHeader, then either ChannelSamples (a sampled clip, checked slice by slice by
// ClipAssembler) or KeyedCurve parts (a keyed clip; several parts of one channel are
// consecutive runs of its keys, joined in arrival order by KeyedClipFromProto()).
//
// Errors (from AddPart / Finish): kInvalidArgument for parts before the header, a second header,
// samples in a keyed result or curves in a sampled one, more keys than limits.max_samples, and
// whatever the clip and keyed-clip validation refuses (a curve channel out of range, ...).
//
// Not thread-safe: one assembler per result stream.
class ResultAssembler {
 public:
  explicit ResultAssembler(core::ClipLimits limits = {});

  absl::Status AddPart(const v1::ResultPart& part);
  bool has_header() const { return header_received_; }
  // The result once every part has arrived.
  absl::StatusOr<core::PipelineResult> Finish() &&;

 private:
  absl::Status AddHeader(const v1::ResultHeader& header);
  absl::Status CheckSamplesExpected() const;
  absl::Status AddCurve(const v1::KeyedCurve& curve);

  core::ClipLimits limits_;
  bool header_received_ = false;
  bool keyed_ = false;
  std::int64_t parts_ = 0;
  std::vector<core::StepReport> reports_;
  ClipAssembler clip_;
  v1::KeyedClip keyed_clip_;
  std::int64_t keys_received_ = 0;
};

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_JOBS_CONVERT_H_
