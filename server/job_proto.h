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
  // one value, or an empty curve's one empty piece) into `samples` / `curve`; false when done.
  bool NextSamples(std::int64_t budget_bytes, v1::ChannelSamples* samples);
  bool NextCurve(std::int64_t budget_bytes, v1::KeyedCurve* curve);
  bool Done() const;

  std::shared_ptr<const core::PipelineResult> result_;
  std::int64_t slice_bytes_;
  bool batch_parts_;
  bool header_sent_ = false;
  int channel_ = 0;
  std::int64_t offset_ = 0;  // frame (sampled) or key (keyed) within channel_
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_JOB_PROTO_H_
