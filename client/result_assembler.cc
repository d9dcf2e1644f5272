#include "client/result_assembler.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {

ResultAssembler::ResultAssembler(core::ClipLimits limits) : limits_(limits), clip_(limits) {}

absl::Status ResultAssembler::AddPart(const wire::v1::ResultPart& part) {
  ++parts_;
  const std::string where = absl::StrCat("result part ", parts_);
  switch (part.part_case()) {
    case wire::v1::ResultPart::kHeader:
      return core::Annotate(AddHeader(part.header()), where);
    case wire::v1::ResultPart::kSamples:
      TEMPOKEY_RETURN_IF_ERROR(core::Annotate(CheckSamplesExpected(), where));
      return clip_.AddSamples(part.samples());
    case wire::v1::ResultPart::kSampleSlices:
      TEMPOKEY_RETURN_IF_ERROR(core::Annotate(CheckSamplesExpected(), where));
      return clip_.AddSampleSlices(part.sample_slices());
    case wire::v1::ResultPart::kCurve:
      return core::Annotate(AddCurve(part.curve()), where);
    case wire::v1::ResultPart::kCurves:
      for (const wire::v1::KeyedCurve& curve : part.curves().curves()) {
        TEMPOKEY_RETURN_IF_ERROR(core::Annotate(AddCurve(curve), where));
      }
      return absl::OkStatus();
    case wire::v1::ResultPart::PART_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError(absl::StrCat(where, ": empty"));
}

absl::Status ResultAssembler::CheckSamplesExpected() const {
  if (!header_received_) return absl::InvalidArgumentError("samples before the header");
  if (keyed_) return absl::InvalidArgumentError("samples in a keyed result");
  return absl::OkStatus();
}

absl::Status ResultAssembler::AddHeader(const wire::v1::ResultHeader& header) {
  if (header_received_) return absl::InvalidArgumentError("a second result header");
  header_received_ = true;
  for (const wire::v1::OperationReport& report : header.reports()) {
    reports_.push_back(wire::StepReportFromProto(report));
  }
  switch (header.kind_case()) {
    case wire::v1::ResultHeader::kClip:
      return clip_.AddHeader(header.clip());
    case wire::v1::ResultHeader::kKeyedClip: {
      keyed_ = true;
      const wire::v1::ClipHeader& layout = header.keyed_clip();
      if (layout.channels_size() > limits_.max_channels) {
        return absl::InvalidArgumentError(absl::StrCat("the keyed clip has ", layout.channels_size(),
                                                       " channels, over the limit of ",
                                                       limits_.max_channels));
      }
      *keyed_clip_.mutable_header() = layout;
      return absl::OkStatus();
    }
    case wire::v1::ResultHeader::KIND_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError("the result header names neither a clip nor a keyed clip");
}

absl::Status ResultAssembler::AddCurve(const wire::v1::KeyedCurve& curve) {
  if (!header_received_) return absl::InvalidArgumentError("a curve before the header");
  if (!keyed_) return absl::InvalidArgumentError("a curve in a sampled result");
  keys_received_ += curve.time_seconds_size();
  if (keys_received_ > limits_.max_samples) {
    return absl::InvalidArgumentError(absl::StrCat("more than ", limits_.max_samples,
                                                   " keys received, over the limit"));
  }
  // Pieces of one channel are joined by KeyedClipFromProto() in arrival order.
  *keyed_clip_.add_curves() = curve;
  return absl::OkStatus();
}

absl::StatusOr<core::PipelineResult> ResultAssembler::Finish() && {
  if (!header_received_) return absl::InvalidArgumentError("the result has no header");
  core::PipelineResult result;
  result.reports = std::move(reports_);
  if (keyed_) {
    TEMPOKEY_ASSIGN_OR_RETURN(core::KeyedClip keyed, wire::KeyedClipFromProto(keyed_clip_, limits_));
    result.output = std::move(keyed);
  } else {
    TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, std::move(clip_).Finish());
    result.output = std::move(clip);
  }
  return result;
}

}  // namespace tempokey::client
