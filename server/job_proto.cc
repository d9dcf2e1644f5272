#include "server/job_proto.h"

#include <algorithm>
#include <chrono>
#include <utility>
#include <variant>

#include "absl/strings/str_cat.h"
#include "proto/operations_convert.h"

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

}  // namespace tempokey::server
