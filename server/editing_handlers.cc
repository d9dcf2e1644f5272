// The editing calls of MotionService (editing.proto): clip files parsed by core's readers, stored
// clips read back, retime plans, the CLI's speed text and results written as files. Like every
// handler they only check, look up and queue: parsing, planning and formatting run on the job
// pool, so they share its bounded queue (RESOURCE_EXHAUSTED with a retry hint when full). Like
// the other calls they are raw (bytes that are not a request are INVALID_ARGUMENT), see only the
// caller's own clips and jobs, count what they store in the memory budget, and end a stream whose
// client takes no message for the idle timeout.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <stop_token>
#include <string>
#include <utility>
#include <variant>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "proto/clip_convert.h"
#include "proto/clip_digest.h"
#include "proto/editing_convert.h"
#include "proto/jobs_convert.h"
#include "server/motion_service.h"
#include "server/memory_size.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "server/wire_codec.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/file_formats.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::server {
namespace {

constexpr std::size_t kMaxFileNameBytes = 256;
constexpr std::size_t kMaxSpeedTextBytes = 64 * 1024;
constexpr std::int64_t kDefaultChunkBytes = 1 << 20;

// Runs `work` (returning the response or why not) on the job pool and answers the unary call
// with it there; a full queue or a draining server answers at once. `request` and `work` are
// kept alive by the task.
template <typename Response, typename Work>
grpc::ServerUnaryReactor* AnswerOnPool(ServiceContext* service, grpc::CallbackServerContext* call,
                                       const grpc::ByteBuffer* raw_request,
                                       grpc::ByteBuffer* raw_response, Work work) {
  if (service->draining.load()) {
    return AnswerUnary(*service, call, *raw_request,
                       absl::UnavailableError("the server is shutting down"), Response(),
                       raw_response);
  }
  // Taken once, here: DefaultReactor() rebuilds the reactor when called again, which would undo
  // a Finish() the pool thread has already made.
  grpc::ServerUnaryReactor* reactor = call->DefaultReactor();
  absl::Status queued = service->pool->TrySubmit(
      [service, reactor, call, raw_request, raw_response,
       work = std::move(work)](std::stop_token) mutable {
        // A call its client gave up on while it was queued (cancelled, or its deadline passed)
        // is not worth the work: a parse would store a clip nobody asked for any more.
        const bool late = call->deadline() <= std::chrono::system_clock::now();
        if (late || call->IsCancelled()) {
          AnswerUnary(*service, reactor, call, *raw_request,
                      late ? absl::DeadlineExceededError(
                                 "the call's deadline passed before a worker took it up")
                           : absl::CancelledError("the call was cancelled before a worker took "
                                                  "it up"),
                      Response(), raw_response);
          return;
        }
        absl::StatusOr<Response> response = work();
        AnswerUnary(*service, reactor, call, *raw_request, response.status(),
                    response.ok() ? *response : Response(), raw_response);
      });
  if (!queued.ok()) {
    return AnswerUnary(*service, reactor, call, *raw_request, queued, Response(), raw_response);
  }
  return reactor;
}

absl::Status CheckFileName(const std::string& name) {
  if (name.empty()) return absl::InvalidArgumentError("file_name is empty");
  if (name.size() > kMaxFileNameBytes) {
    return core::OverLimitError(absl::StrCat("file_name is ", name.size(),
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

// GetClip: a stored clip, the caller's own, sliced as a sampled result: a copy, counted in the
// memory budget while it streams.
absl::StatusOr<ResultStream> OpenStoredClip(ServiceContext& service, const std::string& owner,
                                            const grpc::ByteBuffer& raw_request,
                                            const std::function<absl::Status()>& claim_slot) {
  v1::GetClipRequest request;
  TEMPOKEY_RETURN_IF_ERROR(ParseMessage(raw_request, "GetClip request", &request));
  TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request.clip_id()));
  TEMPOKEY_RETURN_IF_ERROR(CheckSliceBytes("slice_bytes", request.slice_bytes()));
  TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<const core::Clip> clip,
                            service.clips->Get(owner, request.clip_id()));
  TEMPOKEY_RETURN_IF_ERROR(claim_slot());
  TEMPOKEY_ASSIGN_OR_RETURN(MemoryBudget::Reservation memory,
                            ReserveMemory(service, MemoryUse::kResult, "a clip read back"));
  const std::int64_t clip_bytes = ClipBytes(*clip);
  memory.Pin(clip_bytes);  // the stored clip, held while copied
  TEMPOKEY_RETURN_IF_ERROR(memory.Grow(clip_bytes));
  core::PipelineResult result;
  result.output = *clip;
  return ResultStream{ShareWithReservation(std::move(result), std::move(memory)),
                      request.slice_bytes(), request.batch_parts()};
}

// ExportFile: formats the job result or clip on the pool, then streams the bytes in chunks.
class ExportReactor final : public grpc::ServerWriteReactor<grpc::ByteBuffer> {
 public:
  ExportReactor(ServiceContext* service, grpc::CallbackServerContext* call,
                const grpc::ByteBuffer& request)
      : service_(service), call_(call) {
    if (service_->idle != nullptr) {
      idle_ = service_->idle->NewTimer([call] { call->TryCancel(); });
    }
    if (absl::Status status = Open(*call, request); !status.ok()) End(ToGrpcStatus(status, call));
  }

  void OnWriteDone(bool ok) override {
    if (idle_ != nullptr) idle_->Disarm();
    if (!ok) {
      End(ToGrpcStatus(absl::CancelledError("the file stream broke")));
      return;
    }
    WriteNext();
  }

  // The client cancelled or left: a file still being formatted is stopped (a keyed glTF's fits
  // can take a worker for many seconds on a long clip).
  void OnCancel() override {
    client_cancelled_.store(true);
    stop_.request_stop();
  }

  void OnDone() override {
    if (idle_ != nullptr) idle_->Close();
    delete this;
  }

 private:
  absl::Status Open(const grpc::CallbackServerContext& call, const grpc::ByteBuffer& raw) {
    TEMPOKEY_ASSIGN_OR_RETURN(const std::string owner, service_->Authenticate(call));
    v1::ExportFileRequest request;
    TEMPOKEY_RETURN_IF_ERROR(ParseMessage(raw, "ExportFile request", &request));
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
        source_ = absl::StrCat("job=", request.job_id());
        TEMPOKEY_ASSIGN_OR_RETURN(result, service_->jobs->Result(request.job_id(), owner));
        if (format_->content == core::FileContent::kEither &&
            std::holds_alternative<core::KeyedClip>(result->output)) {
          TEMPOKEY_RETURN_IF_ERROR(FindGltfSource(request.job_id(), owner));
        }
        break;
      }
      case v1::ExportFileRequest::kClipId: {
        TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request.clip_id()));
        source_ = absl::StrCat("clip=", request.clip_id());
        TEMPOKEY_ASSIGN_OR_RETURN(clip, service_->clips->Get(owner, request.clip_id()));
        break;
      }
      case v1::ExportFileRequest::SOURCE_NOT_SET:
        return absl::InvalidArgumentError("nothing to export: set job_id or clip_id");
    }
    TEMPOKEY_RETURN_IF_ERROR(slot_.Claim(*service_, /*allow_while_draining=*/true));
    TEMPOKEY_ASSIGN_OR_RETURN(memory_,
                              ReserveMemory(*service_, MemoryUse::kResult, "an exported file"));
    // The source, held while the file is formatted.
    memory_.Pin(clip != nullptr ? ClipBytes(*clip) : PipelineResultBytes(*result));
    const auto queued_at = std::chrono::steady_clock::now();
    absl::Status queued = service_->pool->TrySubmit(
        [this, result = std::move(result), clip = std::move(clip),
         queued_at](std::stop_token pool_stop) {
          auto started = std::chrono::steady_clock::now();
          absl::Status formatted;
          {
            // The drain deadline stops the formatting as the client's cancel does. Only while
            // formatting: once End() or a write has begun, this reactor may be deleted.
            std::stop_callback forward(pool_stop, [this] { stop_.request_stop(); });
            const TestHooks& hooks = service_->options.test_hooks;
            if (hooks.on_export_start) hooks.on_export_start(format_->name, stop_.get_token());
            started = std::chrono::steady_clock::now();
            // A call stopped before its formatting began is not formatted at all (sampled
            // formats, JSON and .anim are written without looking at the stop): cancelled by its
            // client, or refused as the server shuts down (the drain deadline reached it queued,
            // or it came after).
            if (!stop_.stop_requested()) {
              formatted = clip != nullptr ? Format(*clip) : Format(result->output);
            } else if (pool_stop.stop_requested() && !client_cancelled_.load()) {
              formatted = absl::UnavailableError(
                  "the server is shutting down: its drain deadline passed before this export "
                  "began");
            } else {
              formatted = absl::CancelledError("cancelled");
            }
          }
          Record(formatted, queued_at, started);
          if (formatted.code() == absl::StatusCode::kCancelled && pool_stop.stop_requested() &&
              !client_cancelled_.load()) {
            // Stopped by the drain deadline while formatting, not by its client: UNAVAILABLE,
            // which clients retry on another server, as for a Process call.
            formatted = absl::UnavailableError(
                "the server is shutting down: its drain deadline passed while this export was "
                "formatted; retry on another server");
          }
          if (!formatted.ok()) {
            End(ToGrpcStatus(formatted, call_));
            return;
          }
          WriteNext();
        });
    if (!queued.ok()) {
      if (queued.code() == absl::StatusCode::kResourceExhausted && service_->metrics != nullptr) {
        service_->metrics->RecordRejected("export");
      }
      return queued;
    }
    return absl::OkStatus();
  }

  // Runs on a worker. Only this task touches the members until its first StartWrite. The file's
  // bytes exist once formatted: they are kept only if the budget can count them.
  // A keyed glTF is fitted against the clip the curves were reduced from (as the CLI's is): the
  // job's stored input, when the job is one reduce of it. The same bounds as the CLI's.
  absl::Status FindGltfSource(const std::string& job_id, const std::string& owner) {
    TEMPOKEY_ASSIGN_OR_RETURN(const JobSnapshot job, service_->jobs->Get(job_id, owner));
    const std::vector<core::PipelineStep>& steps = job.spec->steps;
    const auto* reduce =
        steps.size() == 1 ? std::get_if<core::ReduceStep>(&steps.front()) : nullptr;
    if (reduce == nullptr) {
      return absl::FailedPreconditionError(absl::StrCat(
          "a keyed ", core::AsAbsl(format_->name), " file needs a job that is one reduce of a "
          "stored clip; job ", job_id, " runs ", steps.size(), " operations"));
    }
    absl::StatusOr<std::shared_ptr<const core::Clip>> clip =
        service_->clips->Get(owner, job.spec->clip_id);
    if (!clip.ok()) {
      return absl::FailedPreconditionError(absl::StrCat(
          "a keyed ", core::AsAbsl(format_->name), " file is fitted against the reduced clip ",
          job.spec->clip_id, ", which this server does not hold (it came inline with the job, "
          "or has left the clip store since): upload it (UploadClip) and export again"));
    }
    gltf_clip_ = *std::move(clip);
    gltf_source_ = {.clip = gltf_clip_.get(),
                    .max_rotation_error_degrees = core::GltfRotationBoundDegrees(reduce->options),
                    .joint_tolerance = core::GltfJointTolerance(reduce->options)};
    return absl::OkStatus();
  }

  absl::Status Format(const std::variant<core::Clip, core::KeyedClip>& output) {
    TEMPOKEY_ASSIGN_OR_RETURN(bytes_, core::FormatOutput(output, *format_, service_->clip_limits,
                                                         gltf_source_, stop_.get_token()));
    file_name_ = absl::StrCat(OutputName(output), core::AsAbsl(format_->extension));
    return Charge();
  }
  absl::Status Format(const core::Clip& clip) {
    TEMPOKEY_ASSIGN_OR_RETURN(
        bytes_, core::FormatOutput(std::variant<core::Clip, core::KeyedClip>(clip), *format_,
                                   service_->clip_limits, {}, stop_.get_token()));
    file_name_ = absl::StrCat(clip.name, core::AsAbsl(format_->extension));
    return Charge();
  }
  // One line per export, as per job and Process call, and the same metrics (kind "export").
  void Record(const absl::Status& formatted, std::chrono::steady_clock::time_point queued_at,
              std::chrono::steady_clock::time_point started) {
    const std::string_view outcome = OutcomeOf(formatted);
    const auto ended = std::chrono::steady_clock::now();
    const double queue_ms = std::chrono::duration<double, std::milli>(started - queued_at).count();
    const double run_ms = std::chrono::duration<double, std::milli>(ended - started).count();
    spdlog::info("export {} format={} bytes={} queue_wait_ms={:.1f} run_ms={:.1f} outcome={}{}",
                 source_, format_->name, bytes_.size(), queue_ms, run_ms, outcome,
                 formatted.ok()
                     ? ""
                     : absl::StrCat(" error=", core::LogValue(core::AsStd(formatted.message()))));
    if (service_->metrics != nullptr) {
      service_->metrics->RecordFinished("export", outcome, (queue_ms + run_ms) / 1000.0);
    }
  }

  absl::Status Charge() {
    absl::Status charged = memory_.Grow(static_cast<std::int64_t>(bytes_.capacity()));
    if (!charged.ok()) std::string().swap(bytes_);
    return charged;
  }

  void WriteNext() {
    const bool first = offset_ == 0 && !started_;
    if (!first && offset_ >= bytes_.size()) {
      End(grpc::Status::OK);
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
    SerializeMessage(chunk_, &buffer_);
    service_->BytesOut(static_cast<std::int64_t>(buffer_.Length()));
    if (idle_ != nullptr) idle_->Arm();
    StartWrite(&buffer_);
  }

  // Gives back the stream slot and the file's memory before the client sees the status: no write
  // is in flight by now (each chunk is a copy), and no task formats any more.
  void End(const grpc::Status& status) {
    std::string().swap(bytes_);
    memory_.Release();
    gltf_clip_.reset();
    slot_.Release();
    Finish(status);
  }

  ServiceContext* const service_;
  grpc::CallbackServerContext* const call_;
  StreamSlot slot_;
  std::stop_source stop_;  // the client's cancel and the drain deadline; thread-safe by itself
  std::atomic<bool> client_cancelled_{false};
  std::shared_ptr<IdleReaper::Timer> idle_;
  MemoryBudget::Reservation memory_;  // the formatted file
  const core::ExportFormat* format_ = nullptr;
  std::string source_;  // "job=<id>" or "clip=<id>", for the log line
  std::shared_ptr<const core::Clip> gltf_clip_;  // a keyed glTF's source, held while formatting
  core::ExportSource gltf_source_;
  std::int64_t chunk_bytes_ = kDefaultChunkBytes;
  bool started_ = false;
  std::string bytes_;
  std::string file_name_;
  std::size_t offset_ = 0;
  v1::FileChunk chunk_;
  grpc::ByteBuffer buffer_;
};

}  // namespace

grpc::ServerUnaryReactor* MotionService::ParseClipFile(grpc::CallbackServerContext* call,
                                                       const grpc::ByteBuffer* raw_request,
                                                       grpc::ByteBuffer* raw_response) {
  auto request = std::make_shared<v1::ParseClipFileRequest>();
  absl::StatusOr<std::string> owner =
      OpenUnary(*context_, *call, *raw_request, "ParseClipFile", request.get());
  absl::Status checked = owner.ok() ? CheckFileName(request->file_name()) : owner.status();
  // The CSV frame time is checked here, not by the CSV reader, so that the refusal names the
  // field (ignored for a .bvh, as the field says).
  if (checked.ok() && request->csv_frame_time_seconds() != 0.0 &&
      absl::EndsWithIgnoreCase(request->file_name(), ".csv")) {
    checked = core::CheckFrameTime(request->csv_frame_time_seconds(), "csv_frame_time_seconds");
  }
  if (!checked.ok()) {
    return AnswerUnary(*context_, call, *raw_request, checked, v1::ParseClipFileResponse(),
                       raw_response);
  }
  ServiceContext* service = context_;
  return AnswerOnPool<v1::ParseClipFileResponse>(
      service, call, raw_request, raw_response,
      [service, request, owner = *std::move(owner)]() -> absl::StatusOr<v1::ParseClipFileResponse> {
        std::optional<double> csv_frame_time;
        if (request->csv_frame_time_seconds() != 0.0) {
          csv_frame_time = request->csv_frame_time_seconds();
        }
        TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip,
                                  core::ParseClipText(request->content(), request->file_name(),
                                                      csv_frame_time, service->clip_limits));
        TEMPOKEY_RETURN_IF_ERROR(core::ValidateClip(clip, service->clip_limits));
        // The clip exists once parsed (bounded by the message size): stored only if it fits.
        TEMPOKEY_ASSIGN_OR_RETURN(MemoryBudget::Reservation memory,
                                  ReserveMemory(*service, MemoryUse::kStoredClip, "a parsed clip"));
        TEMPOKEY_RETURN_IF_ERROR(memory.Grow(ClipBytes(clip)));
        const std::string id = wire::ClipContentId(clip);
        v1::ParseClipFileResponse response;
        *response.mutable_header() = wire::ClipHeaderToProto(clip);
        response.set_sample_count(clip.sample_count());
        TEMPOKEY_ASSIGN_OR_RETURN(
            ClipStore::PutResult stored,
            service->clips->Put(owner, id, ShareWithReservation(std::move(clip), std::move(memory))));
        response.set_clip_id(id);
        response.set_already_stored(stored.already_stored);
        spdlog::info("parse clip file={} clip={} already_stored={}",
                     core::LogValue(request->file_name()), id, stored.already_stored);
        return response;
      });
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* MotionService::GetClip(
    grpc::CallbackServerContext* call, const grpc::ByteBuffer* request) {
  ServiceContext* service = context_;
  return NewSlicedResultReactor(
      service, call, *request, "clip",
      [service](const std::string& owner, const grpc::ByteBuffer& raw,
                const std::function<absl::Status()>& claim_slot) {
        return OpenStoredClip(*service, owner, raw, claim_slot);
      });
}

grpc::ServerUnaryReactor* MotionService::PlanRetime(grpc::CallbackServerContext* call,
                                                    const grpc::ByteBuffer* raw_request,
                                                    grpc::ByteBuffer* raw_response) {
  std::shared_ptr<const core::Clip> clip;
  std::optional<core::RetimeStep> step;
  std::int64_t max_points = wire::kDefaultPlanPoints;
  absl::Status checked = [&]() -> absl::Status {
    v1::PlanRetimeRequest request;
    TEMPOKEY_ASSIGN_OR_RETURN(const std::string owner,
                              OpenUnary(*context_, *call, *raw_request, "PlanRetime", &request));
    TEMPOKEY_RETURN_IF_ERROR(CheckId("clip_id", request.clip_id()));
    if (request.max_points() < 0 || request.max_points() == 1 ||
        request.max_points() > wire::kMaxPlanPoints) {
      return absl::InvalidArgumentError(absl::StrCat("max_points must be 0 (", wire::kDefaultPlanPoints,
                                                     ") or in [2, ", wire::kMaxPlanPoints, "], got ",
                                                     request.max_points()));
    }
    if (request.max_points() > 0) max_points = request.max_points();
    TEMPOKEY_ASSIGN_OR_RETURN(clip, context_->clips->Get(owner, request.clip_id()));
    TEMPOKEY_ASSIGN_OR_RETURN(step, wire::RetimeStepFromProto(request.retime()));
    return absl::OkStatus();
  }();
  if (!checked.ok()) {
    return AnswerUnary(*context_, call, *raw_request, checked, v1::RetimePlan(), raw_response);
  }
  ServiceContext* service = context_;
  return AnswerOnPool<v1::RetimePlan>(
      service, call, raw_request, raw_response,
      [service, clip = std::move(clip), step = *std::move(step),
       max_points]() -> absl::StatusOr<v1::RetimePlan> {
        TEMPOKEY_ASSIGN_OR_RETURN(
            core::RetimePlan plan,
            core::PlanRetime(*clip, step.warp, step.options, service->clip_limits));
        return wire::RetimePlanToProto(plan, step, clip->frame_time_seconds, clip->frame_count,
                                       max_points);
      });
}

grpc::ServerUnaryReactor* MotionService::ParseSpeedKnots(grpc::CallbackServerContext* call,
                                                         const grpc::ByteBuffer* raw_request,
                                                         grpc::ByteBuffer* raw_response) {
  v1::ParseSpeedKnotsResponse response;
  absl::Status status = [&]() -> absl::Status {
    v1::ParseSpeedKnotsRequest request;
    TEMPOKEY_RETURN_IF_ERROR(
        OpenUnary(*context_, *call, *raw_request, "ParseSpeedKnots", &request).status());
    if (request.text().size() > kMaxSpeedTextBytes) {
      return core::OverLimitError(absl::StrCat("text is ", request.text().size(),
                                               " bytes, over the limit of ", kMaxSpeedTextBytes));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(std::vector<core::SpeedKnot> knots,
                              core::ParseSpeedKnots(request.text()));
    for (const core::SpeedKnot& knot : knots) *response.add_knots() = wire::SpeedKnotToProto(knot);
    response.set_text(core::FormatSpeedKnots(knots));
    return absl::OkStatus();
  }();
  return AnswerUnary(*context_, call, *raw_request, status, response, raw_response);
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* MotionService::ExportFile(
    grpc::CallbackServerContext* call, const grpc::ByteBuffer* request) {
  return new ExportReactor(context_, call, *request);
}

}  // namespace tempokey::server
