// The editing calls of MotionService (editing.proto): clip files parsed by core's readers, stored
// clips read back, retime plans, the CLI's speed text and results written as files. Like every
// handler they only check, look up and queue: parsing, planning and formatting run on the job
// pool, so they share its bounded queue (RESOURCE_EXHAUSTED with a retry hint when full).
#include <algorithm>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <variant>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "proto/clip_convert.h"
#include "proto/clip_digest.h"
#include "proto/editing_convert.h"
#include "proto/jobs_convert.h"
#include "server/motion_service.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/file_formats.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::server {
namespace {

constexpr std::size_t kMaxFileNameBytes = 256;
constexpr std::size_t kMaxSpeedTextBytes = 64 * 1024;
constexpr std::int64_t kDefaultChunkBytes = 1 << 20;

grpc::ServerUnaryReactor* FinishNow(grpc::CallbackServerContext* call, const absl::Status& status) {
  grpc::ServerUnaryReactor* reactor = call->DefaultReactor();
  reactor->Finish(ToGrpcStatus(status, call));
  return reactor;
}

// Runs `work` (returning a status, filling the call's response) on the job pool and finishes the
// unary call with its status there; a full queue or a draining server finishes it at once.
template <typename Work>
grpc::ServerUnaryReactor* FinishOnPool(ServiceContext* service, grpc::CallbackServerContext* call,
                                       Work work) {
  if (service->draining.load()) {
    return FinishNow(call, absl::UnavailableError("the server is shutting down"));
  }
  grpc::ServerUnaryReactor* reactor = call->DefaultReactor();
  absl::Status queued = service->pool->TrySubmit(
      [reactor, call, work = std::move(work)](std::stop_token) mutable {
        reactor->Finish(ToGrpcStatus(work(), call));
      });
  if (!queued.ok()) reactor->Finish(ToGrpcStatus(queued, call));
  return reactor;
}

absl::Status CheckFileName(const std::string& name) {
  if (name.empty()) return absl::InvalidArgumentError("file_name is empty");
  if (name.size() > kMaxFileNameBytes) {
    return absl::InvalidArgumentError(absl::StrCat("file_name is ", name.size(),
                                                   " bytes, over the limit of ", kMaxFileNameBytes));
  }
  return absl::OkStatus();
}

absl::StatusOr<const core::ExportFormat*> LookUpFormat(const std::string& name) {
  if (const core::ExportFormat* format = core::FindExportFormat(name)) return format;
  std::vector<std::string> names;
  for (const core::ExportFormat& format : core::ExportFormats()) names.emplace_back(format.name);
  return absl::InvalidArgumentError(absl::StrCat("format \"", name.substr(0, 32),
                                                 "\" is not one of ", absl::StrJoin(names, ", ")));
}

std::string OutputName(const std::variant<core::Clip, core::KeyedClip>& output) {
  if (const auto* clip = std::get_if<core::Clip>(&output)) return clip->name;
  return std::get<core::KeyedClip>(output).layout.name;
}

// GetClip: a stored clip sliced as a sampled result (ResultSlicer), one message in flight.
class ClipReactor final : public grpc::ServerWriteReactor<v1::ResultPart> {
 public:
  ClipReactor(ServiceContext* service, grpc::CallbackServerContext* call,
              const v1::GetClipRequest& request)
      : service_(service) {
    if (absl::Status status = Open(*call, request); !status.ok()) {
      Finish(ToGrpcStatus(status, call));
      return;
    }
    WriteNext();
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(ToGrpcStatus(absl::CancelledError("the clip stream broke")));
      return;
    }
    WriteNext();
  }

  void OnDone() override {
    if (holds_stream_) service_->CloseStream();
    delete this;
  }

 private:
  absl::Status Open(const grpc::CallbackServerContext& call, const v1::GetClipRequest& request) {
    TEMPOKEY_RETURN_IF_ERROR(service_->CheckAuth(call));
    TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request.clip_id()));
    if (request.slice_bytes() < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("slice_bytes must be >= 0 (0: 1 MiB), got ", request.slice_bytes()));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<const core::Clip> clip,
                              service_->clips->Get(request.clip_id()));
    TEMPOKEY_RETURN_IF_ERROR(service_->AdmitStream(/*allow_while_draining=*/true));
    holds_stream_ = true;
    auto result = std::make_shared<core::PipelineResult>();
    result->output = *clip;
    slicer_.emplace(std::move(result), request.slice_bytes(), request.batch_parts());
    return absl::OkStatus();
  }

  void WriteNext() {
    if (!slicer_->Next(&part_)) {
      Finish(grpc::Status::OK);
      return;
    }
    service_->BytesOut(static_cast<std::int64_t>(part_.ByteSizeLong()));
    StartWrite(&part_);
  }

  ServiceContext* const service_;
  bool holds_stream_ = false;
  std::optional<wire::ResultSlicer> slicer_;
  v1::ResultPart part_;
};

// ExportFile: formats the job result or clip on the pool, then streams the bytes in chunks.
class ExportReactor final : public grpc::ServerWriteReactor<v1::FileChunk> {
 public:
  ExportReactor(ServiceContext* service, grpc::CallbackServerContext* call,
                const v1::ExportFileRequest& request)
      : service_(service), call_(call) {
    if (absl::Status status = Open(*call, request); !status.ok()) {
      Finish(ToGrpcStatus(status, call));
    }
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(ToGrpcStatus(absl::CancelledError("the file stream broke")));
      return;
    }
    WriteNext();
  }

  void OnDone() override {
    if (holds_stream_) service_->CloseStream();
    delete this;
  }

 private:
  absl::Status Open(const grpc::CallbackServerContext& call, const v1::ExportFileRequest& request) {
    TEMPOKEY_RETURN_IF_ERROR(service_->CheckAuth(call));
    TEMPOKEY_ASSIGN_OR_RETURN(format_, LookUpFormat(request.format()));
    if (request.chunk_bytes() < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("chunk_bytes must be >= 0 (0: 1 MiB), got ", request.chunk_bytes()));
    }
    chunk_bytes_ = request.chunk_bytes() > 0 ? request.chunk_bytes() : kDefaultChunkBytes;
    std::shared_ptr<const core::PipelineResult> result;
    std::shared_ptr<const core::Clip> clip;
    switch (request.source_case()) {
      case v1::ExportFileRequest::kJobId: {
        TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request.job_id()));
        TEMPOKEY_ASSIGN_OR_RETURN(result, service_->jobs->Result(request.job_id()));
        break;
      }
      case v1::ExportFileRequest::kClipId: {
        TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request.clip_id()));
        TEMPOKEY_ASSIGN_OR_RETURN(clip, service_->clips->Get(request.clip_id()));
        break;
      }
      case v1::ExportFileRequest::SOURCE_NOT_SET:
        return absl::InvalidArgumentError("nothing to export: set job_id or clip_id");
    }
    TEMPOKEY_RETURN_IF_ERROR(service_->AdmitStream(/*allow_while_draining=*/true));
    holds_stream_ = true;
    absl::Status queued = service_->pool->TrySubmit(
        [this, result = std::move(result), clip = std::move(clip)](std::stop_token) {
          absl::Status formatted = clip != nullptr ? Format(*clip) : Format(result->output);
          if (!formatted.ok()) {
            Finish(ToGrpcStatus(formatted, call_));
            return;
          }
          WriteNext();
        });
    if (!queued.ok()) return queued;
    return absl::OkStatus();
  }

  // Runs on a worker. Only this task touches the members until its first StartWrite.
  absl::Status Format(const std::variant<core::Clip, core::KeyedClip>& output) {
    TEMPOKEY_ASSIGN_OR_RETURN(bytes_,
                              core::FormatOutput(output, *format_, service_->clip_limits));
    file_name_ = absl::StrCat(OutputName(output), core::AsAbsl(format_->extension));
    return absl::OkStatus();
  }
  absl::Status Format(const core::Clip& clip) {
    TEMPOKEY_ASSIGN_OR_RETURN(bytes_, core::FormatOutput(std::variant<core::Clip, core::KeyedClip>(clip),
                                                         *format_, service_->clip_limits));
    file_name_ = absl::StrCat(clip.name, core::AsAbsl(format_->extension));
    return absl::OkStatus();
  }

  void WriteNext() {
    const bool first = offset_ == 0 && !started_;
    if (!first && offset_ >= bytes_.size()) {
      Finish(grpc::Status::OK);
      return;
    }
    started_ = true;
    chunk_.Clear();
    if (first) {
      chunk_.set_file_name(file_name_);
      chunk_.set_media_type(std::string(format_->media_type));
      chunk_.set_total_bytes(static_cast<std::int64_t>(bytes_.size()));
    }
    const std::size_t take =
        std::min(bytes_.size() - offset_, static_cast<std::size_t>(chunk_bytes_));
    chunk_.set_data(bytes_.substr(offset_, take));
    offset_ += take;
    service_->BytesOut(static_cast<std::int64_t>(chunk_.ByteSizeLong()));
    StartWrite(&chunk_);
  }

  ServiceContext* const service_;
  grpc::CallbackServerContext* const call_;
  const core::ExportFormat* format_ = nullptr;
  std::int64_t chunk_bytes_ = kDefaultChunkBytes;
  bool holds_stream_ = false;
  bool started_ = false;
  std::string bytes_;
  std::string file_name_;
  std::size_t offset_ = 0;
  v1::FileChunk chunk_;
};

}  // namespace

grpc::ServerUnaryReactor* MotionService::ParseClipFile(grpc::CallbackServerContext* call,
                                                       const v1::ParseClipFileRequest* request,
                                                       v1::ParseClipFileResponse* response) {
  if (absl::Status auth = context_->CheckAuth(*call); !auth.ok()) return FinishNow(call, auth);
  if (absl::Status name = CheckFileName(request->file_name()); !name.ok()) {
    return FinishNow(call, name);
  }
  context_->BytesIn(static_cast<std::int64_t>(request->ByteSizeLong()));
  ServiceContext* service = context_;
  return FinishOnPool(service, call, [service, request, response]() -> absl::Status {
    std::optional<double> csv_frame_time;
    if (request->csv_frame_time_seconds() != 0.0) csv_frame_time = request->csv_frame_time_seconds();
    TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip,
                              core::ParseClipText(request->content(), request->file_name(),
                                                  csv_frame_time, service->clip_limits));
    TEMPOKEY_RETURN_IF_ERROR(core::ValidateClip(clip, service->clip_limits));
    const std::string id = wire::ClipContentId(clip);
    *response->mutable_header() = wire::ClipHeaderToProto(clip);
    response->set_sample_count(clip.sample_count());
    TEMPOKEY_ASSIGN_OR_RETURN(ClipStore::PutResult stored, service->clips->Put(id, std::move(clip)));
    response->set_clip_id(id);
    response->set_already_stored(stored.already_stored);
    spdlog::info("parse clip file={} clip={} already_stored={}", request->file_name(), id,
                 stored.already_stored);
    service->BytesOut(static_cast<std::int64_t>(response->ByteSizeLong()));
    return absl::OkStatus();
  });
}

grpc::ServerWriteReactor<v1::ResultPart>* MotionService::GetClip(
    grpc::CallbackServerContext* call, const v1::GetClipRequest* request) {
  return new ClipReactor(context_, call, *request);
}

grpc::ServerUnaryReactor* MotionService::PlanRetime(grpc::CallbackServerContext* call,
                                                    const v1::PlanRetimeRequest* request,
                                                    v1::RetimePlan* response) {
  std::shared_ptr<const core::Clip> clip;
  std::optional<core::RetimeStep> step;
  std::int64_t max_points = wire::kDefaultPlanPoints;
  absl::Status checked = [&]() -> absl::Status {
    TEMPOKEY_RETURN_IF_ERROR(context_->CheckAuth(*call));
    TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request->clip_id()));
    if (request->max_points() < 0 || request->max_points() == 1 ||
        request->max_points() > wire::kMaxPlanPoints) {
      return absl::InvalidArgumentError(absl::StrCat("max_points must be 0 (", wire::kDefaultPlanPoints,
                                                     ") or in [2, ", wire::kMaxPlanPoints, "], got ",
                                                     request->max_points()));
    }
    if (request->max_points() > 0) max_points = request->max_points();
    TEMPOKEY_ASSIGN_OR_RETURN(clip, context_->clips->Get(request->clip_id()));
    TEMPOKEY_ASSIGN_OR_RETURN(step, wire::RetimeStepFromProto(request->retime()));
    return absl::OkStatus();
  }();
  if (!checked.ok()) return FinishNow(call, checked);
  context_->BytesIn(static_cast<std::int64_t>(request->ByteSizeLong()));
  ServiceContext* service = context_;
  return FinishOnPool(
      service, call,
      [service, response, clip = std::move(clip), step = *std::move(step), max_points]() -> absl::Status {
        TEMPOKEY_ASSIGN_OR_RETURN(
            core::RetimePlan plan,
            core::PlanRetime(*clip, step.warp, step.options, service->clip_limits));
        *response = wire::RetimePlanToProto(plan, step, clip->frame_time_seconds, clip->frame_count,
                                            max_points);
        service->BytesOut(static_cast<std::int64_t>(response->ByteSizeLong()));
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* MotionService::ParseSpeedKnots(grpc::CallbackServerContext* call,
                                                         const v1::ParseSpeedKnotsRequest* request,
                                                         v1::ParseSpeedKnotsResponse* response) {
  absl::Status status = [&]() -> absl::Status {
    TEMPOKEY_RETURN_IF_ERROR(context_->CheckAuth(*call));
    if (request->text().size() > kMaxSpeedTextBytes) {
      return absl::InvalidArgumentError(absl::StrCat("text is ", request->text().size(),
                                                     " bytes, over the limit of ",
                                                     kMaxSpeedTextBytes));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(std::vector<core::SpeedKnot> knots,
                              core::ParseSpeedKnots(request->text()));
    for (const core::SpeedKnot& knot : knots) *response->add_knots() = wire::SpeedKnotToProto(knot);
    response->set_text(core::FormatSpeedKnots(knots));
    return absl::OkStatus();
  }();
  return FinishNow(call, status);
}

grpc::ServerWriteReactor<v1::FileChunk>* MotionService::ExportFile(
    grpc::CallbackServerContext* call, const v1::ExportFileRequest* request) {
  return new ExportReactor(context_, call, *request);
}

}  // namespace tempokey::server
