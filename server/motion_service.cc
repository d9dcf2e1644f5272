#include "server/motion_service.h"

#include <memory>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "proto/clip_convert.h"
#include "proto/editing_convert.h"
#include "proto/operations_convert.h"
#include "proto/jobs_convert.h"
#include "proto/clip_digest.h"
#include "server/job_proto.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/pipeline/cost.h"

namespace tempokey::server {
namespace {

constexpr int kMaxLabels = 64;
constexpr std::size_t kMaxLabelKeyBytes = 128;
constexpr std::size_t kMaxLabelValueBytes = 1024;
constexpr std::size_t kMaxRequestIdBytes = 256;
constexpr std::size_t kMaxIdBytes = 256;

grpc::ServerUnaryReactor* FinishUnary(grpc::CallbackServerContext* call,
                                      const absl::Status& status) {
  grpc::ServerUnaryReactor* reactor = call->DefaultReactor();
  reactor->Finish(ToGrpcStatus(status, call));
  return reactor;
}

absl::Status CheckLabels(const google::protobuf::Map<std::string, std::string>& labels) {
  if (labels.size() > kMaxLabels) {
    return absl::InvalidArgumentError(
        absl::StrCat("labels has ", labels.size(), " entries, over the limit of ", kMaxLabels));
  }
  for (const auto& [key, value] : labels) {
    if (key.empty() || key.size() > kMaxLabelKeyBytes) {
      return absl::InvalidArgumentError(absl::StrCat("label key \"", key.substr(0, 32),
                                                     "\" must be 1..", kMaxLabelKeyBytes,
                                                     " bytes, got ", key.size()));
    }
    if (value.size() > kMaxLabelValueBytes) {
      return absl::InvalidArgumentError(absl::StrCat("label \"", key, "\": value is ",
                                                     value.size(), " bytes, over the limit of ",
                                                     kMaxLabelValueBytes));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status CheckId(std::string_view field, const std::string& id) {
  if (id.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(core::AsAbsl(field), " is empty"));
  }
  if (id.size() > kMaxIdBytes) {
    return absl::InvalidArgumentError(absl::StrCat(core::AsAbsl(field), " is ", id.size(),
                                                   " bytes, over the limit of ", kMaxIdBytes));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<core::PipelineStep>> PrepareSteps(
    const google::protobuf::RepeatedPtrField<v1::Operation>& operations, const core::Clip& clip,
    const core::ClipLimits& limits, double max_cost_seconds) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<core::PipelineStep> steps,
                            wire::PipelineFromProto(operations));
  TEMPOKEY_ASSIGN_OR_RETURN(core::PipelineCost cost,
                            core::EstimatePipelineCost(clip, steps, limits));
  if (max_cost_seconds > 0.0 && cost.seconds > max_cost_seconds) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "the request is over this server's work limit: ", cost.Describe(),
        ", over the limit of ", max_cost_seconds,
        " s (--max_job_cost_seconds); ask for less work (fewer iterations, a shorter clip, "
        "a coarser accuracy) or use a server with a higher limit"));
  }
  return steps;
}

std::string DescribeSteps(const std::vector<core::PipelineStep>& steps) {
  return absl::StrJoin(steps, "+", [](std::string* out, const core::PipelineStep& step) {
    absl::StrAppend(out, core::AsAbsl(core::StepName(step)));
  });
}

grpc::ServerUnaryReactor* MotionService::GetServerInfo(grpc::CallbackServerContext* call,
                                                       const v1::GetServerInfoRequest*,
                                                       v1::ServerInfo* response) {
  if (absl::Status auth = context_->CheckAuth(*call); !auth.ok()) return FinishUnary(call, auth);
  const ServerOptions& o = context_->options;
  response->set_version(TEMPOKEY_VERSION);
  response->set_max_message_bytes(o.max_message_bytes);
  response->set_max_clip_samples(o.max_clip_samples);
  response->set_queue_capacity(context_->pool->queue_capacity());
  response->set_worker_count(context_->pool->workers());
  for (const std::string& operation : context_->operations) response->add_operations(operation);
  response->set_max_stored_clips(o.max_stored_clips);
  response->set_max_stored_results(o.max_stored_results);
  for (std::string_view feature : {wire::kFeatureSampleSlices, wire::kFeatureBatchParts}) {
    response->add_features(std::string(feature));
  }
  for (const core::ExportFormat& format : core::ExportFormats()) {
    *response->add_export_formats() = wire::ExportFormatToProto(format);
  }
  return FinishUnary(call, absl::OkStatus());
}

grpc::ServerReadReactor<v1::UploadClipRequest>* MotionService::UploadClip(
    grpc::CallbackServerContext* call, v1::UploadClipResponse* response) {
  return NewUploadReactor(context_, call, response);
}

grpc::ServerUnaryReactor* MotionService::SubmitJob(grpc::CallbackServerContext* call,
                                                   const v1::SubmitJobRequest* request,
                                                   v1::Job* response) {
  absl::Status status = [&]() -> absl::Status {
    TEMPOKEY_RETURN_IF_ERROR(context_->CheckAuth(*call));
    context_->BytesIn(static_cast<std::int64_t>(request->ByteSizeLong()));
    if (context_->draining.load()) {
      return absl::UnavailableError("the server is shutting down and accepts no new jobs");
    }
    if (request->request_id().size() > kMaxRequestIdBytes) {
      return absl::InvalidArgumentError(absl::StrCat("request_id is ", request->request_id().size(),
                                                     " bytes, over the limit of ",
                                                     kMaxRequestIdBytes));
    }
    // A retried submit answers with the first job before anything else is looked at, so it
    // succeeds even if its clip was evicted meanwhile.
    if (!request->request_id().empty()) {
      if (std::optional<JobSnapshot> existing =
              context_->jobs->FindByRequestId(request->request_id())) {
        *response = JobToProto(*existing);
        return absl::OkStatus();
      }
    }
    TEMPOKEY_RETURN_IF_ERROR(CheckLabels(request->labels()));

    std::shared_ptr<const core::Clip> clip;
    std::string clip_id;
    switch (request->source_case()) {
      case v1::SubmitJobRequest::kClipId: {
        TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request->clip_id()));
        TEMPOKEY_ASSIGN_OR_RETURN(clip, context_->clips->Get(request->clip_id()));
        clip_id = request->clip_id();
        break;
      }
      case v1::SubmitJobRequest::kInlineClip: {
        absl::StatusOr<core::Clip> inline_clip =
            wire::ClipFromProto(request->inline_clip(), context_->clip_limits);
        if (!inline_clip.ok()) return core::Annotate(inline_clip.status(), "inline_clip");
        clip_id = wire::ClipContentId(*inline_clip);
        clip = std::make_shared<const core::Clip>(*std::move(inline_clip));
        break;
      }
      case v1::SubmitJobRequest::SOURCE_NOT_SET:
        return absl::InvalidArgumentError("the job has no clip: set clip_id or inline_clip");
    }
    TEMPOKEY_ASSIGN_OR_RETURN(std::vector<core::PipelineStep> steps,
                              PrepareSteps(request->operations(), *clip, context_->clip_limits,
                                           context_->options.max_job_cost_seconds));

    JobSpec spec{.clip_id = clip_id,
                 .steps = std::move(steps),
                 .labels = {request->labels().begin(), request->labels().end()},
                 .request_id = request->request_id()};
    absl::StatusOr<JobSnapshot> job = context_->jobs->Submit(std::move(spec), std::move(clip));
    if (!job.ok()) {
      if (job.status().code() == absl::StatusCode::kResourceExhausted && context_->metrics) {
        context_->metrics->RecordRejected("job");
      }
      return job.status();
    }
    *response = JobToProto(*job);
    return absl::OkStatus();
  }();
  if (status.ok()) context_->BytesOut(static_cast<std::int64_t>(response->ByteSizeLong()));
  return FinishUnary(call, status);
}

grpc::ServerUnaryReactor* MotionService::GetJob(grpc::CallbackServerContext* call,
                                                const v1::GetJobRequest* request,
                                                v1::Job* response) {
  absl::Status status = [&]() -> absl::Status {
    TEMPOKEY_RETURN_IF_ERROR(context_->CheckAuth(*call));
    TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request->job_id()));
    TEMPOKEY_ASSIGN_OR_RETURN(JobSnapshot job, context_->jobs->Get(request->job_id()));
    *response = JobToProto(job);
    return absl::OkStatus();
  }();
  return FinishUnary(call, status);
}

grpc::ServerUnaryReactor* MotionService::ListJobs(grpc::CallbackServerContext* call,
                                                  const v1::ListJobsRequest* request,
                                                  v1::ListJobsResponse* response) {
  absl::Status status = [&]() -> absl::Status {
    TEMPOKEY_RETURN_IF_ERROR(context_->CheckAuth(*call));
    ListJobsQuery query;
    query.page_size = request->page_size();
    query.page_token = request->page_token();
    for (int i = 0; i < request->states_size(); ++i) {
      absl::StatusOr<JobState> state = JobStateFromProto(request->states(i));
      if (!state.ok()) return core::Annotate(state.status(), absl::StrCat("states[", i, "]"));
      query.states.push_back(*state);
    }
    query.labels = {request->labels().begin(), request->labels().end()};
    TEMPOKEY_ASSIGN_OR_RETURN(ListJobsPage page, context_->jobs->List(query));
    response->mutable_jobs()->Reserve(static_cast<int>(page.jobs.size()));
    for (const JobSnapshot& job : page.jobs) *response->add_jobs() = JobToProto(job);
    response->set_next_page_token(page.next_page_token);
    return absl::OkStatus();
  }();
  return FinishUnary(call, status);
}

grpc::ServerUnaryReactor* MotionService::CancelJob(grpc::CallbackServerContext* call,
                                                   const v1::CancelJobRequest* request,
                                                   v1::Job* response) {
  absl::Status status = [&]() -> absl::Status {
    TEMPOKEY_RETURN_IF_ERROR(context_->CheckAuth(*call));
    TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request->job_id()));
    TEMPOKEY_ASSIGN_OR_RETURN(JobSnapshot job, context_->jobs->Cancel(request->job_id()));
    *response = JobToProto(job);
    return absl::OkStatus();
  }();
  return FinishUnary(call, status);
}

grpc::ServerUnaryReactor* MotionService::DeleteJob(grpc::CallbackServerContext* call,
                                                   const v1::DeleteJobRequest* request,
                                                   v1::DeleteJobResponse*) {
  absl::Status status = [&]() -> absl::Status {
    TEMPOKEY_RETURN_IF_ERROR(context_->CheckAuth(*call));
    TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request->job_id()));
    return context_->jobs->Delete(request->job_id());
  }();
  return FinishUnary(call, status);
}

grpc::ServerWriteReactor<v1::Job>* MotionService::WatchJob(grpc::CallbackServerContext* call,
                                                           const v1::WatchJobRequest* request) {
  return NewWatchReactor(context_, call, request);
}

grpc::ServerWriteReactor<v1::ResultPart>* MotionService::GetJobResult(
    grpc::CallbackServerContext* call, const v1::GetJobResultRequest* request) {
  return NewResultReactor(context_, call, request);
}

grpc::ServerBidiReactor<v1::ProcessRequest, v1::ProcessResponse>* MotionService::Process(
    grpc::CallbackServerContext* call) {
  return NewProcessReactor(context_, call);
}

}  // namespace tempokey::server
