#include "proto/jobs_convert.h"

#include <algorithm>
#include <utility>
#include <variant>

#include "absl/strings/str_cat.h"
#include "proto/operations_convert.h"
#include "tempokey/core/model/status.h"

namespace tempokey::wire {

ResultSlicer::ResultSlicer(std::shared_ptr<const core::PipelineResult> result,
                           std::int64_t slice_bytes, bool batch_parts)
    : result_(std::move(result)),
      slice_bytes_(slice_bytes > 0 ? slice_bytes : wire::kDefaultSliceBytes),
      batch_parts_(batch_parts) {}

bool ResultSlicer::Done() const {
  if (const auto* clip = std::get_if<core::Clip>(&result_->output)) {
    return channel_ >= static_cast<int>(clip->channels.size());
  }
  return channel_ >= static_cast<int>(std::get<core::KeyedClip>(result_->output).curves.size());
}

v1::ChannelSamples* ResultSlicer::NextSamples(std::int64_t budget_bytes,
                                              google::protobuf::Arena* arena) {
  const core::Clip& clip = std::get<core::Clip>(result_->output);
  while (channel_ < static_cast<int>(clip.channels.size())) {
    const auto total = static_cast<std::int64_t>(clip.channels[channel_].samples.size());
    if (offset_ < total) {
      const std::int64_t n = std::min(wire::SamplesPerSlice(budget_bytes), total - offset_);
      v1::ChannelSamples* samples = wire::SamplesSliceOnArena(clip, channel_, offset_, n, arena);
      offset_ += n;
      if (offset_ == total) {
        ++channel_;
        offset_ = 0;
      }
      return samples;
    }
    ++channel_;
    offset_ = 0;
  }
  return nullptr;
}

v1::KeyedCurve* ResultSlicer::NextCurve(std::int64_t budget_bytes, google::protobuf::Arena* arena) {
  const core::KeyedClip& keyed = std::get<core::KeyedClip>(result_->output);
  // Every curve sends at least one piece (a valid curve has keys; an empty one sends one empty
  // piece).
  if (channel_ >= static_cast<int>(keyed.curves.size())) return nullptr;
  const core::Curve& curve = keyed.curves[channel_];
  const auto total = static_cast<std::int64_t>(curve.keys.size());
  const std::int64_t n = std::min(wire::KeysPerSlice(curve, budget_bytes), total - offset_);
  v1::KeyedCurve* piece = wire::KeyedCurveSliceOnArena(channel_, curve, offset_, n, arena);
  offset_ += n;
  if (offset_ >= total) {
    ++channel_;
    offset_ = 0;
  }
  return piece;
}

bool ResultSlicer::Next(v1::ResultPart* part) {
  part->Clear();
  // The header's and the samples' and curves' pieces are built in the part's arena and handed to
  // it without a copy: in a scratch arena (scratch_arena.h), a few blocks instead of a message, an
  // array and names per channel from the heap. (The step reports, a few small messages, are
  // copied in.)
  google::protobuf::Arena* const arena = part->GetArena();
  const auto* clip = std::get_if<core::Clip>(&result_->output);
  const auto* keyed = std::get_if<core::KeyedClip>(&result_->output);
  if (!header_sent_) {
    header_sent_ = true;
    v1::ResultHeader* header = part->mutable_header();
    if (clip != nullptr) {
      header->set_allocated_clip(wire::ClipHeaderOnArena(*clip, arena));
    } else {
      header->set_allocated_keyed_clip(wire::ClipHeaderOnArena(keyed->layout, arena));
    }
    for (const core::StepReport& report : result_->reports) {
      *header->add_reports() = wire::StepReportToProto(report);
    }
    return true;
  }
  if (Done()) return false;
  if (!batch_parts_) {
    if (clip != nullptr) {
      v1::ChannelSamples* samples = NextSamples(slice_bytes_, arena);
      if (samples == nullptr) return false;
      part->set_allocated_samples(samples);
    } else {
      v1::KeyedCurve* piece = NextCurve(slice_bytes_, arena);
      if (piece == nullptr) return false;
      part->set_allocated_curve(piece);
    }
    return true;
  }
  // Batched: pieces until the budget is spent (each piece takes what is left of it).
  std::int64_t used = 0;
  bool added = false;
  while (used < slice_bytes_ && !Done()) {
    if (clip != nullptr) {
      v1::ChannelSamples* samples = NextSamples(slice_bytes_ - used, arena);
      if (samples == nullptr) break;
      part->mutable_sample_slices()->mutable_slices()->AddAllocated(samples);
      added = true;
      used += static_cast<std::int64_t>(samples->samples_size()) *
              static_cast<std::int64_t>(sizeof(double));
    } else {
      v1::KeyedCurve* piece = NextCurve(slice_bytes_ - used, arena);
      if (piece == nullptr) break;
      part->mutable_curves()->mutable_curves()->AddAllocated(piece);
      added = true;
      used += static_cast<std::int64_t>(piece->ByteSizeLong());
    }
  }
  return added;  // nothing left but empty channels: done
}

ResultAssembler::ResultAssembler(core::ClipLimits limits) : limits_(limits), clip_(limits) {}

absl::Status ResultAssembler::AddPart(const v1::ResultPart& part) {
  ++parts_;
  const std::string where = absl::StrCat("result part ", parts_);
  switch (part.part_case()) {
    case v1::ResultPart::kHeader:
      return core::Annotate(AddHeader(part.header()), where);
    case v1::ResultPart::kSamples:
      TEMPOKEY_RETURN_IF_ERROR(core::Annotate(CheckSamplesExpected(), where));
      return clip_.AddSamples(part.samples());
    case v1::ResultPart::kSampleSlices:
      TEMPOKEY_RETURN_IF_ERROR(core::Annotate(CheckSamplesExpected(), where));
      return clip_.AddSampleSlices(part.sample_slices());
    case v1::ResultPart::kCurve:
      return core::Annotate(AddCurve(part.curve()), where);
    case v1::ResultPart::kCurves:
      for (const v1::KeyedCurve& curve : part.curves().curves()) {
        TEMPOKEY_RETURN_IF_ERROR(core::Annotate(AddCurve(curve), where));
      }
      return absl::OkStatus();
    case v1::ResultPart::PART_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError(absl::StrCat(where, ": empty"));
}

absl::Status ResultAssembler::CheckSamplesExpected() const {
  if (!header_received_) return absl::InvalidArgumentError("samples before the header");
  if (keyed_) return absl::InvalidArgumentError("samples in a keyed result");
  return absl::OkStatus();
}

absl::Status ResultAssembler::AddHeader(const v1::ResultHeader& header) {
  if (header_received_) return absl::InvalidArgumentError("a second result header");
  header_received_ = true;
  for (const v1::OperationReport& report : header.reports()) {
    reports_.push_back(StepReportFromProto(report));
  }
  switch (header.kind_case()) {
    case v1::ResultHeader::kClip:
      return clip_.AddHeader(header.clip());
    case v1::ResultHeader::kKeyedClip: {
      keyed_ = true;
      const v1::ClipHeader& layout = header.keyed_clip();
      if (layout.channels_size() > limits_.max_channels) {
        return absl::InvalidArgumentError(absl::StrCat("the keyed clip has ", layout.channels_size(),
                                                       " channels, over the limit of ",
                                                       limits_.max_channels));
      }
      *keyed_clip_.mutable_header() = layout;
      return absl::OkStatus();
    }
    case v1::ResultHeader::KIND_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError("the result header names neither a clip nor a keyed clip");
}

absl::Status ResultAssembler::AddCurve(const v1::KeyedCurve& curve) {
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
    TEMPOKEY_ASSIGN_OR_RETURN(core::KeyedClip keyed, KeyedClipFromProto(keyed_clip_, limits_));
    result.output = std::move(keyed);
  } else {
    TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, std::move(clip_).Finish());
    result.output = std::move(clip);
  }
  return result;
}

}  // namespace tempokey::wire
