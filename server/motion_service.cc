#include "server/motion_service.h"

#include <algorithm>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "proto/clip_convert.h"
#include "proto/clip_digest.h"
#include "proto/editing_convert.h"
#include "proto/jobs_convert.h"
#include "proto/operations_convert.h"
#include "server/job_proto.h"
#include "server/memory_size.h"
#include "server/reactors.h"
#include "server/request_digest.h"
#include "server/status_util.h"
#include "server/wire_codec.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/pipeline/cost.h"

namespace tempokey::server {
namespace {

// A unary request or response this large leaves enough freed memory behind to matter.
constexpr std::int64_t kLargeMessageBytes = std::int64_t{1} << 20;

// One unary call answered at once: OpenUnary(), `handler(owner, request, response)`,
// AnswerUnary(). `method` names the request in a parse error.
template <typename Request, typename Response, typename Handler>
grpc::ServerUnaryReactor* ServeUnary(ServiceContext* service, grpc::CallbackServerContext* call,
                                     const grpc::ByteBuffer* raw_request,
                                     grpc::ByteBuffer* raw_response, std::string_view method,
                                     Handler&& handler) {
  Request request;
  Response response;
  absl::Status status = [&]() -> absl::Status {
    TEMPOKEY_ASSIGN_OR_RETURN(const std::string owner,
                              OpenUnary(*service, *call, *raw_request, method, &request));
    return handler(owner, request, response);
  }();
  return AnswerUnary(*service, call, *raw_request, status, response, raw_response);
}

absl::Status CheckLabels(const google::protobuf::Map<std::string, std::string>& labels) {
  if (labels.size() > kMaxLabels) {
    return core::OverLimitError(
        absl::StrCat("labels has ", labels.size(), " entries, over the limit of ", kMaxLabels));
  }
  for (const auto& [key, value] : labels) {
    if (key.empty()) return absl::InvalidArgumentError("a label key is empty");
    if (key.size() > kMaxLabelKeyBytes) {
      return core::OverLimitError(absl::StrCat("label key \"", key.substr(0, 32), "...\" is ",
                                               key.size(), " bytes, over the limit of ",
                                               kMaxLabelKeyBytes));
    }
    if (value.size() > kMaxLabelValueBytes) {
      return core::OverLimitError(absl::StrCat("label \"", key, "\": value is ", value.size(),
                                               " bytes, over the limit of ",
                                               kMaxLabelValueBytes));
    }
  }
  return absl::OkStatus();
}

}  // namespace

grpc::ServerUnaryReactor* FinishUnary(grpc::CallbackServerContext* call,
                                      const absl::Status& status) {
  return FinishUnary(call->DefaultReactor(), call, status);
}

grpc::ServerUnaryReactor* FinishUnary(grpc::ServerUnaryReactor* reactor,
                                      grpc::CallbackServerContext* call,
                                      const absl::Status& status) {
  reactor->Finish(ToGrpcStatus(status, call));
  return reactor;
}

absl::StatusOr<std::string> OpenUnary(ServiceContext& service,
                                      const grpc::CallbackServerContext& call,
                                      const grpc::ByteBuffer& raw_request, std::string_view method,
                                      google::protobuf::Message* request) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::string owner, service.Authenticate(call));
  service.BytesIn(static_cast<std::int64_t>(raw_request.Length()));
  TEMPOKEY_RETURN_IF_ERROR(
      ParseMessage(raw_request, absl::StrCat(core::AsAbsl(method), " request"), request));
  return owner;
}

grpc::ServerUnaryReactor* AnswerUnary(ServiceContext& service, grpc::CallbackServerContext* call,
                                      const grpc::ByteBuffer& raw_request,
                                      const absl::Status& status,
                                      const google::protobuf::Message& response,
                                      grpc::ByteBuffer* raw_response) {
  return AnswerUnary(service, call->DefaultReactor(), call, raw_request, status, response,
                     raw_response);
}

grpc::ServerUnaryReactor* AnswerUnary(ServiceContext& service, grpc::ServerUnaryReactor* reactor,
                                      grpc::CallbackServerContext* call,
                                      const grpc::ByteBuffer& raw_request,
                                      const absl::Status& status,
                                      const google::protobuf::Message& response,
                                      grpc::ByteBuffer* raw_response) {
  if (status.ok()) {
    SerializeMessage(response, raw_response);
    service.BytesOut(static_cast<std::int64_t>(raw_response->Length()));
  }
  // The parsed request and the response built for it are freed once the call ends; large ones
  // count towards returning free memory to the system.
  const auto transient = static_cast<std::int64_t>(raw_request.Length() + raw_response->Length());
  if (service.budget != nullptr && transient >= kLargeMessageBytes) {
    service.budget->NoteFreed(transient);
  }
  return FinishUnary(reactor, call, status);
}

absl::Status CheckId(std::string_view field, const std::string& id) {
  if (id.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(core::AsAbsl(field), " is empty"));
  }
  if (id.size() > kMaxIdBytes) {
    return core::OverLimitError(absl::StrCat(core::AsAbsl(field), " is ", id.size(),
                                             " bytes, over the limit of ", kMaxIdBytes));
  }
  return absl::OkStatus();
}

absl::Status CheckSliceBytes(std::string_view field, std::int64_t slice_bytes) {
  if (slice_bytes < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        core::AsAbsl(field), " must be >= 0 (0: 1 MiB), got ", slice_bytes));
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

wire::AllocationHook ChargeTo(MemoryBudget::Reservation* reservation) {
  return [reservation](std::int64_t bytes) -> absl::Status {
    if (bytes < 0) {
      reservation->ShrinkTo(reservation->bytes() + bytes);
      return absl::OkStatus();
    }
    return reservation->Grow(bytes);
  };
}

absl::Status IdleError(std::string_view call, std::chrono::milliseconds timeout) {
  return absl::DeadlineExceededError(absl::StrCat(
      core::AsAbsl(call), ": the client sent nothing for ",
      static_cast<double>(timeout.count()) / 1000.0,
      " s (--stream_idle_timeout_seconds); the call was ended"));
}

absl::StatusOr<MemoryBudget::Reservation> ReserveMemory(ServiceContext& service, MemoryUse use,
                                                        std::string_view what) {
  if (service.budget == nullptr) return MemoryBudget::Reservation();
  return service.budget->Reserve(0, use, what);
}

grpc::ServerUnaryReactor* MotionService::GetServerInfo(grpc::CallbackServerContext* call,
                                                       const grpc::ByteBuffer* raw_request,
                                                       grpc::ByteBuffer* raw_response) {
  return ServeUnary<v1::GetServerInfoRequest, v1::ServerInfo>(
      context_, call, raw_request, raw_response, "GetServerInfo",
      [this](const std::string&, const v1::GetServerInfoRequest&, v1::ServerInfo& response) {
        const ServerOptions& o = context_->options;
        response.set_version(TEMPOKEY_VERSION);
        response.set_max_message_bytes(o.max_message_bytes);
        response.set_max_clip_samples(o.max_clip_samples);
        response.set_queue_capacity(context_->pool->queue_capacity());
        response.set_worker_count(context_->pool->workers());
        for (const std::string& operation : context_->operations) response.add_operations(operation);
        response.set_max_stored_clips(o.max_stored_clips);
        response.set_max_stored_results(o.max_stored_results);
        for (std::string_view feature : {wire::kFeatureSampleSlices, wire::kFeatureBatchParts}) {
          response.add_features(std::string(feature));
        }
        for (const core::ExportFormat& format : core::ExportFormats()) {
          *response.add_export_formats() = wire::ExportFormatToProto(format);
        }
        return absl::OkStatus();
      });
}

grpc::ServerReadReactor<grpc::ByteBuffer>* MotionService::UploadClip(
    grpc::CallbackServerContext* call, grpc::ByteBuffer* response) {
  return NewUploadReactor(context_, call, response);
}

grpc::ServerUnaryReactor* MotionService::SubmitJob(grpc::CallbackServerContext* call,
                                                   const grpc::ByteBuffer* raw_request,
                                                   grpc::ByteBuffer* raw_response) {
  return ServeUnary<v1::SubmitJobRequest, v1::Job>(
      context_, call, raw_request, raw_response, "SubmitJob",
      [this](const std::string& owner, const v1::SubmitJobRequest& request,
             v1::Job& response) -> absl::Status {
        if (context_->draining.load()) {
          return absl::UnavailableError("the server is shutting down and accepts no new jobs");
        }
        if (request.request_id().size() > kMaxRequestIdBytes) {
          return core::OverLimitError(absl::StrCat("request_id is ", request.request_id().size(),
                                                   " bytes, over the limit of ",
                                                   kMaxRequestIdBytes));
        }
        // The labels first: the digest below sorts them, and a request may carry as many as a
        // message holds (a retry of an accepted request has labels within the limits).
        TEMPOKEY_RETURN_IF_ERROR(CheckLabels(request.labels()));
        // A retried submit answers with the first job before its clip and operations are looked
        // at, so it succeeds even if its clip was evicted meanwhile; the same request_id with
        // another request is refused (ALREADY_EXISTS), never mistaken for a retry.
        std::string digest;
        if (!request.request_id().empty()) {
          digest = RequestDigest(request);
          TEMPOKEY_ASSIGN_OR_RETURN(
              std::optional<JobSnapshot> existing,
              context_->jobs->FindByRequestId(owner, request.request_id(), digest));
          if (existing) {
            response = JobToProto(*existing);
            return absl::OkStatus();
          }
        }

        std::shared_ptr<const core::Clip> clip;
        std::string clip_id;
        switch (request.source_case()) {
          case v1::SubmitJobRequest::kClipId: {
            TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request.clip_id()));
            TEMPOKEY_ASSIGN_OR_RETURN(clip, context_->clips->Get(owner, request.clip_id()));
            clip_id = request.clip_id();
            break;
          }
          case v1::SubmitJobRequest::kInlineClip: {
            // Charged as it is assembled, from the samples that came, like an upload.
            TEMPOKEY_ASSIGN_OR_RETURN(
                MemoryBudget::Reservation reservation,
                ReserveMemory(*context_, MemoryUse::kJob, "an inline clip"));
            absl::StatusOr<core::Clip> inline_clip = wire::ClipFromProto(
                request.inline_clip(), context_->clip_limits, ChargeTo(&reservation));
            if (!inline_clip.ok()) return core::Annotate(inline_clip.status(), "inline_clip");
            clip_id = wire::ClipContentId(*inline_clip);
            reservation.Settle(ClipBytes(*inline_clip));
            clip = ShareWithReservation(*std::move(inline_clip), std::move(reservation));
            break;
          }
          case v1::SubmitJobRequest::SOURCE_NOT_SET:
            return absl::InvalidArgumentError("the job has no clip: set clip_id or inline_clip");
        }
        TEMPOKEY_ASSIGN_OR_RETURN(std::vector<core::PipelineStep> steps,
                                  PrepareSteps(request.operations(), *clip, context_->clip_limits,
                                               context_->options.max_job_cost_seconds));

        JobSpec spec{.clip_id = clip_id,
                     .steps = std::move(steps),
                     .labels = {request.labels().begin(), request.labels().end()},
                     .request_id = request.request_id(),
                     .owner = owner,
                     .request_digest = std::move(digest)};
        absl::StatusOr<JobSnapshot> job = context_->jobs->Submit(std::move(spec), std::move(clip));
        if (!job.ok()) {
          if (job.status().code() == absl::StatusCode::kResourceExhausted && context_->metrics) {
            context_->metrics->RecordRejected("job");
          }
          return job.status();
        }
        response = JobToProto(*job);
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* MotionService::GetJob(grpc::CallbackServerContext* call,
                                                const grpc::ByteBuffer* raw_request,
                                                grpc::ByteBuffer* raw_response) {
  return ServeUnary<v1::GetJobRequest, v1::Job>(
      context_, call, raw_request, raw_response, "GetJob",
      [this](const std::string& owner, const v1::GetJobRequest& request,
             v1::Job& response) -> absl::Status {
        TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request.job_id()));
        TEMPOKEY_ASSIGN_OR_RETURN(JobSnapshot job, context_->jobs->Get(request.job_id(), owner));
        response = JobToProto(job);
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* MotionService::ListJobs(grpc::CallbackServerContext* call,
                                                  const grpc::ByteBuffer* raw_request,
                                                  grpc::ByteBuffer* raw_response) {
  return ServeUnary<v1::ListJobsRequest, v1::ListJobsResponse>(
      context_, call, raw_request, raw_response, "ListJobs",
      [this](const std::string& owner, const v1::ListJobsRequest& request,
             v1::ListJobsResponse& response) -> absl::Status {
        ListJobsQuery query;
        query.page_size = request.page_size();
        query.page_token = request.page_token();
        for (int i = 0; i < request.states_size(); ++i) {
          absl::StatusOr<JobState> state = JobStateFromProto(request.states(i));
          if (!state.ok()) return core::Annotate(state.status(), absl::StrCat("states[", i, "]"));
          // Each state once: a request may repeat them as many times as a message holds.
          if (std::find(query.states.begin(), query.states.end(), *state) == query.states.end()) {
            query.states.push_back(*state);
          }
        }
        query.labels = {request.labels().begin(), request.labels().end()};
        TEMPOKEY_ASSIGN_OR_RETURN(ListJobsPage page, context_->jobs->List(query, owner));
        // A page also stops at kMaxListPageBytes, so a listing of jobs with large pipelines
        // stays a few messages of bounded size instead of one of hundreds of megabytes.
        std::int64_t bytes = 0;
        std::string next_token = page.next_page_token;
        for (std::size_t i = 0; i < page.jobs.size(); ++i) {
          v1::Job job = JobToProto(page.jobs[i]);
          auto job_bytes = static_cast<std::int64_t>(job.ByteSizeLong()) + 8;
          if (job_bytes > kMaxListPageBytes) {
            // A job whose pipeline alone is larger than a page is listed without its operations
            // (GetJob has them), so every page fits a client's default receive limit.
            job.clear_operations();
            job_bytes = static_cast<std::int64_t>(job.ByteSizeLong()) + 8;
          }
          if (i > 0 && bytes + job_bytes > kMaxListPageBytes) {
            next_token = page.tokens[i];
            break;
          }
          bytes += job_bytes;
          *response.add_jobs() = std::move(job);
        }
        response.set_next_page_token(next_token);
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* MotionService::CancelJob(grpc::CallbackServerContext* call,
                                                   const grpc::ByteBuffer* raw_request,
                                                   grpc::ByteBuffer* raw_response) {
  return ServeUnary<v1::CancelJobRequest, v1::Job>(
      context_, call, raw_request, raw_response, "CancelJob",
      [this](const std::string& owner, const v1::CancelJobRequest& request,
             v1::Job& response) -> absl::Status {
        TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request.job_id()));
        TEMPOKEY_ASSIGN_OR_RETURN(JobSnapshot job, context_->jobs->Cancel(request.job_id(), owner));
        response = JobToProto(job);
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* MotionService::DeleteJob(grpc::CallbackServerContext* call,
                                                   const grpc::ByteBuffer* raw_request,
                                                   grpc::ByteBuffer* raw_response) {
  return ServeUnary<v1::DeleteJobRequest, v1::DeleteJobResponse>(
      context_, call, raw_request, raw_response, "DeleteJob",
      [this](const std::string& owner, const v1::DeleteJobRequest& request,
             v1::DeleteJobResponse&) -> absl::Status {
        TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request.job_id()));
        return context_->jobs->Delete(request.job_id(), owner);
      });
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* MotionService::WatchJob(
    grpc::CallbackServerContext* call, const grpc::ByteBuffer* request) {
  return NewWatchReactor(context_, call, request);
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* MotionService::GetJobResult(
    grpc::CallbackServerContext* call, const grpc::ByteBuffer* request) {
  return NewResultReactor(context_, call, request);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* MotionService::Process(
    grpc::CallbackServerContext* call) {
  return NewProcessReactor(context_, call);
}

}  // namespace tempokey::server
