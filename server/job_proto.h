// Job snapshots and result parts as tempokey.v1 messages.
#ifndef TEMPOKEY_SERVER_JOB_PROTO_H_
#define TEMPOKEY_SERVER_JOB_PROTO_H_

#include <cstdint>
#include <memory>

#include "server/job_manager.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/v1/motion_service.pb.h"

namespace tempokey::server {

namespace v1 = ::tempokey::v1;

v1::JobState JobStateToProto(JobState state);
// Errors: kInvalidArgument for JOB_STATE_UNSPECIFIED or an unknown value.
absl::StatusOr<JobState> JobStateFromProto(int state);

// The job as the API shows it. `operations` are the steps the server runs (wire::
// PipelineStepToProto() of the validated steps, so defaults appear filled in); `reports` appear
// once the job succeeded.
v1::Job JobToProto(const JobSnapshot& job);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_JOB_PROTO_H_
