#include "server/job_proto.h"

#include <algorithm>
#include <chrono>
#include <utility>
#include <variant>

#include "absl/strings/str_cat.h"
#include "proto/convert.h"

namespace tempokey::server {
namespace {

void SetTimestamp(SystemTime time, google::protobuf::Timestamp* out) {
  const auto since_epoch = time.time_since_epoch();
  const auto seconds = std::chrono::floor<std::chrono::seconds>(since_epoch);
  out->set_seconds(seconds.count());
  out->set_nanos(static_cast<std::int32_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(since_epoch - seconds).count()));
}

}  // namespace

v1::JobState JobStateToProto(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return v1::JOB_STATE_QUEUED;
    case JobState::kRunning:
      return v1::JOB_STATE_RUNNING;
    case JobState::kSucceeded:
      return v1::JOB_STATE_SUCCEEDED;
    case JobState::kFailed:
      return v1::JOB_STATE_FAILED;
    case JobState::kCancelled:
      return v1::JOB_STATE_CANCELLED;
  }
  return v1::JOB_STATE_UNSPECIFIED;
}

absl::StatusOr<JobState> JobStateFromProto(int state) {
  switch (state) {
    case v1::JOB_STATE_QUEUED:
      return JobState::kQueued;
    case v1::JOB_STATE_RUNNING:
      return JobState::kRunning;
    case v1::JOB_STATE_SUCCEEDED:
      return JobState::kSucceeded;
    case v1::JOB_STATE_FAILED:
      return JobState::kFailed;
    case v1::JOB_STATE_CANCELLED:
      return JobState::kCancelled;
    default:
      return absl::InvalidArgumentError(absl::StrCat("job state ", state, " is not a state"));
  }
}

v1::Job JobToProto(const JobSnapshot& job) {
  v1::Job out;
  out.set_job_id(job.job_id);
  out.set_state(JobStateToProto(job.state));
  out.set_clip_id(job.spec->clip_id);
  out.mutable_operations()->Reserve(static_cast<int>(job.spec->steps.size()));
  for (const core::PipelineStep& step : job.spec->steps) {
    *out.add_operations() = wire::PipelineStepToProto(step);
  }
  for (const auto& [key, value] : job.spec->labels) (*out.mutable_labels())[key] = value;
  out.set_request_id(job.spec->request_id);
  out.set_progress(job.progress);
  out.set_stage(job.stage);
  out.set_version(job.version);
  if (!job.error.ok()) {
    out.set_error_code(static_cast<std::int32_t>(job.error.code()));
    out.set_error_message(std::string(job.error.message()));
  }
  SetTimestamp(job.create_time, out.mutable_create_time());
  if (job.start_time) SetTimestamp(*job.start_time, out.mutable_start_time());
  if (job.end_time) SetTimestamp(*job.end_time, out.mutable_end_time());
  if (job.result != nullptr) {
    for (const core::StepReport& report : job.result->reports) {
      *out.add_reports() = wire::StepReportToProto(report);
    }
  }
  return out;
}

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

bool ResultSlicer::NextSamples(std::int64_t budget_bytes, v1::ChannelSamples* samples) {
  const core::Clip& clip = std::get<core::Clip>(result_->output);
  while (channel_ < static_cast<int>(clip.channels.size())) {
    const auto total = static_cast<std::int64_t>(clip.channels[channel_].samples.size());
    if (offset_ < total) {
      const std::int64_t n = std::min(wire::SamplesPerSlice(budget_bytes), total - offset_);
      *samples = wire::SamplesSliceToProto(clip, channel_, offset_, n);
      offset_ += n;
      if (offset_ == total) {
        ++channel_;
        offset_ = 0;
      }
      return true;
    }
    ++channel_;
    offset_ = 0;
  }
  return false;
}

bool ResultSlicer::NextCurve(std::int64_t budget_bytes, v1::KeyedCurve* piece) {
  const core::KeyedClip& keyed = std::get<core::KeyedClip>(result_->output);
  // Every curve sends at least one piece (a valid curve has keys; an empty one sends one empty
  // piece).
  if (channel_ >= static_cast<int>(keyed.curves.size())) return false;
  const core::Curve& curve = keyed.curves[channel_];
  const auto total = static_cast<std::int64_t>(curve.keys.size());
  const std::int64_t n = std::min(wire::KeysPerSlice(curve, budget_bytes), total - offset_);
  *piece = wire::KeyedCurveSliceToProto(channel_, curve, offset_, n);
  offset_ += n;
  if (offset_ >= total) {
    ++channel_;
    offset_ = 0;
  }
  return true;
}

bool ResultSlicer::Next(v1::ResultPart* part) {
  part->Clear();
  const auto* clip = std::get_if<core::Clip>(&result_->output);
  const auto* keyed = std::get_if<core::KeyedClip>(&result_->output);
  if (!header_sent_) {
    header_sent_ = true;
    v1::ResultHeader* header = part->mutable_header();
    if (clip != nullptr) {
      *header->mutable_clip() = wire::ClipHeaderToProto(*clip);
    } else {
      *header->mutable_keyed_clip() = wire::ClipHeaderToProto(keyed->layout);
    }
    for (const core::StepReport& report : result_->reports) {
      *header->add_reports() = wire::StepReportToProto(report);
    }
    return true;
  }
  if (Done()) return false;
  if (!batch_parts_) {
    return clip != nullptr ? NextSamples(slice_bytes_, part->mutable_samples())
                           : NextCurve(slice_bytes_, part->mutable_curve());
  }
  // Batched: pieces until the budget is spent (each piece takes what is left of it).
  std::int64_t used = 0;
  while (used < slice_bytes_ && !Done()) {
    if (clip != nullptr) {
      v1::ChannelSamples* samples = part->mutable_sample_slices()->add_slices();
      NextSamples(slice_bytes_ - used, samples);
      used += static_cast<std::int64_t>(samples->samples_size()) *
              static_cast<std::int64_t>(sizeof(double));
    } else {
      v1::KeyedCurve* piece = part->mutable_curves()->add_curves();
      NextCurve(slice_bytes_ - used, piece);
      used += static_cast<std::int64_t>(piece->ByteSizeLong());
    }
  }
  return true;
}

}  // namespace tempokey::server
