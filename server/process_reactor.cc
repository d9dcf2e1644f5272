// Process: clip header, sample slices and ProcessStart in; Progress and ResultPart out. The
// pipeline runs on the JobPool like a job, but nothing is stored: the call owns its clip and
// result, and ending the call (or the client cancelling) stops the pipeline between channels.
// The clip and the result are charged to the server's memory budget while the call holds them.
// Messages after ProcessStart are refused (INVALID_ARGUMENT, the pipeline stopped): a Process
// call takes one clip and one start. A client silent for the idle timeout before its start, or
// not taking a result message for that long, loses the call.
#include <chrono>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "grpcpp/alarm.h"
#include "proto/clip_convert.h"
#include "proto/jobs_convert.h"
#include "proto/scratch_arena.h"
#include "server/job_proto.h"
#include "server/memory_size.h"
#include "server/progress_throttle.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "server/wire_codec.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

using ProcessReactorBase = grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>;

// State shared by the reactor (gRPC threads) and the worker running the pipeline; outlives the
// reactor while the worker holds it.
class ProcessLink final : public std::enable_shared_from_this<ProcessLink> {
 public:
  ProcessLink(ServiceContext* service, ProcessReactorBase* reactor,
              grpc::CallbackServerContext* call)
      : service_(service), reactor_(reactor), call_(call) {}

  // Sets what the worker runs; before the task is queued. `clip_memory` counts the clip.
  void Prepare(core::Clip clip, MemoryBudget::Reservation clip_memory,
               std::vector<core::PipelineStep> steps, std::int64_t slice_bytes, bool batch_parts) {
    clip_ = std::move(clip);
    clip_memory_ = std::move(clip_memory);
    steps_ = std::move(steps);
    slice_bytes_ = slice_bytes;
    batch_parts_ = batch_parts;
    description_ = absl::StrCat("frames=", clip_.frame_count, " channels=", clip_.channels.size(),
                                " operations=", DescribeSteps(steps_));
    queued_at_ = std::chrono::steady_clock::now();
  }

  // Drops the clip and gives its memory back: after the run, or (with no task queued) when the
  // call is refused.
  void DropInput() {
    clip_ = core::Clip();
    clip_memory_.Release();
  }

  // On a worker.
  void Run(std::stop_token pool_stop) {
    {
      std::lock_guard lock(mu_);
      if (finished_) {  // ended while queued (its client left, an abort): logged and counted too
        DropInput();
        Record(OutcomeOf(finished_status_), std::chrono::steady_clock::now(), 0.0,
               finished_status_);
        return;
      }
    }
    const auto started = std::chrono::steady_clock::now();
    if (service_->options.test_hooks.on_job_start) service_->options.test_hooks.on_job_start("");
    std::stop_callback forward(pool_stop, [this] { stop_.request_stop(); });
    absl::StatusOr<core::PipelineResult> result = core::RunPipeline(
        clip_, steps_,
        [this](double fraction, std::string_view stage) {
          OnProgress(fraction, stage);
          const TestHooks& hooks = service_->options.test_hooks;
          if (hooks.on_process_progress) hooks.on_process_progress(fraction, stage);
        },
        stop_.get_token(), service_->clip_limits);
    DropInput();  // the input is no longer needed while the result streams out
    const auto ended = std::chrono::steady_clock::now();
    // A pipeline stopped by the call's own end (a message after the start, the client's cancel)
    // is logged and counted with that end's reason, not as a cancellation of its own.
    absl::Status recorded = result.status();
    if (!result.ok() && result.status().code() == absl::StatusCode::kCancelled &&
        !pool_stop.stop_requested()) {
      std::lock_guard lock(mu_);
      if (finished_) {
        recorded = finished_status_;
      } else if (end_status_) {
        recorded = *end_status_;
      }
    }
    Record(OutcomeOf(recorded), started,
           std::chrono::duration<double, std::milli>(ended - started).count(), recorded);
    if (!result.ok() && result.status().code() == absl::StatusCode::kCancelled &&
        pool_stop.stop_requested()) {
      // Stopped by the server's drain deadline, not by its client: UNAVAILABLE, which clients
      // retry on another server (a batch took CANCELLED for a client's own and failed the file).
      result = absl::UnavailableError(
          "the server is shutting down: its drain deadline passed while this call ran; retry on "
          "another server");
    }
    OnResult(std::move(result));
  }

  // The call's log line and its jobs metrics: `outcome`, queued until `started`, `run_ms` of
  // work, `error` (when not OK) in the line.
  void Record(std::string_view outcome, std::chrono::steady_clock::time_point started,
              double run_ms, const absl::Status& error) {
    const double queue_ms =
        std::chrono::duration<double, std::milli>(started - queued_at_).count();
    const std::string error_field =
        error.ok() ? "" : absl::StrCat(" error=", core::LogValue(core::AsStd(error.message())));
    spdlog::info("process {} queue_wait_ms={:.1f} run_ms={:.1f} outcome={}{}", description_,
                 queue_ms, run_ms, outcome, error_field);
    if (service_->metrics != nullptr) {
      service_->metrics->RecordFinished("process", outcome, (queue_ms + run_ms) / 1000.0);
    }
  }

  void OnWriteDone(bool ok) {
    if (idle_ != nullptr) idle_->Disarm();
    std::lock_guard lock(mu_);
    writing_ = false;
    if (finished_) return;
    if (!ok) {
      stop_.request_stop();
      FinishLocked(absl::CancelledError("the Process stream broke"));
    } else if (end_status_) {
      FinishLocked(*end_status_);  // an abort's failure stays a failure, cancel or not
    } else if (cancelled_) {
      // The write got through before the cancel (gRPC may report it so after OnCancel()):
      // otherwise the call would wait for the pipeline to notice its stop.
      FinishLocked(absl::CancelledError("the Process call was cancelled"));
    } else {
      WriteNextLocked();
    }
  }

  void OnCancel() {
    stop_.request_stop();
    std::lock_guard lock(mu_);
    // With a write in flight, its OnWriteDone() finishes the call.
    cancelled_ = true;
    if (!finished_ && !writing_) FinishLocked(absl::CancelledError("the Process call was cancelled"));
  }

  void FinishNow(const absl::Status& status) {
    std::lock_guard lock(mu_);
    if (finished_) return;
    if (writing_) {
      end_status_ = status;
    } else {
      FinishLocked(status);
    }
  }

  // Runs `start_read` (which starts the call's next read) unless the call has finished, under
  // the lock finishing takes: no read starts after the read-idle timer's FinishNow() (gRPC runs
  // the reactions a start causes after the current one returns, never inside it).
  template <typename StartRead>
  void ReadUnlessFinished(StartRead start_read) {
    std::lock_guard lock(mu_);
    if (finished_) return;
    start_read();
  }

  // As FinishNow(), also stopping a queued or running pipeline.
  void Abort(const absl::Status& status) {
    stop_.request_stop();
    FinishNow(status);
  }

  bool finished() {
    std::lock_guard lock(mu_);
    return finished_ || end_status_.has_value();
  }

  // Armed while a result message is being written; set before the task is queued.
  void SetIdleTimer(std::shared_ptr<IdleReaper::Timer> idle) { idle_ = std::move(idle); }
  // The reactor's stream slot, released when the call answers; valid until then.
  void SetSlot(StreamSlot* slot) {
    std::lock_guard lock(mu_);
    slot_ = slot;
  }

 private:
  void OnProgress(double fraction, std::string_view stage) {
    const ProgressThrottle::Clock::time_point now = ProgressThrottle::Clock::now();
    std::lock_guard lock(mu_);
    if (finished_ || result_ready_) return;
    switch (throttle_.Offer(fraction, stage, now)) {
      case ProgressThrottle::Verdict::kSend:
        SendProgressLocked(ProgressReport{fraction, std::string(stage)});
        return;
      case ProgressThrottle::Verdict::kDefer:
        ArmFlushLocked(now);
        return;
      case ProgressThrottle::Verdict::kDrop:
        return;
    }
  }

  // Latest wins: replaces a progress message not yet written.
  void SendProgressLocked(const ProgressReport& report) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    v1::Progress progress;
    progress.set_progress(report.fraction);
    progress.set_stage(report.stage);
    pending_progress_ = std::move(progress);
    if (!writing_) WriteNextLocked();
  }

  // Sends the deferred report when it is due, on gRPC's timer. One alarm at a time: a report
  // deferred while one is set replaces the one it will send. The alarm holds the link weakly: a
  // link gone by then (the call ended) has nothing to send. gRPC never runs the callback inside
  // Set() (it goes through its executor), so setting it under mu_ cannot deadlock. Costs a short
  // call one alarm set and cancelled (perf stat: 23.6 -> 24.0 context switches per sequential
  // call).
  void ArmFlushLocked(ProgressThrottle::Clock::time_point now) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    if (flush_armed_) return;
    const std::optional<ProgressThrottle::Clock::time_point> due = throttle_.deferred_due();
    if (!due) return;
    flush_armed_ = true;
    flush_alarm_ = std::make_unique<grpc::Alarm>();
    flush_alarm_->Set(std::chrono::system_clock::now() + (*due - now),
                      [weak = weak_from_this()](bool fired) {
                        if (const std::shared_ptr<ProcessLink> link = weak.lock()) {
                          link->OnFlushDue(fired);
                        }
                      });
  }

  void OnFlushDue(bool fired) {
    const ProgressThrottle::Clock::time_point now = ProgressThrottle::Clock::now();
    std::lock_guard lock(mu_);
    flush_armed_ = false;
    if (!fired || finished_ || result_ready_) return;
    if (std::optional<ProgressReport> report = throttle_.TakeDeferred(now)) {
      SendProgressLocked(*report);
    } else {
      // The worker sent a report when this one was due and deferred a newer one: set the timer
      // again for that one's due time. (Replacing the alarm from its own callback is safe: gRPC
      // keeps the alarm's state until its callback returns.)
      ArmFlushLocked(now);
    }
  }

  void OnResult(absl::StatusOr<core::PipelineResult> result) {
    // The result exists already: it is streamed only if the budget can count it.
    std::shared_ptr<const core::PipelineResult> shared;
    if (result.ok()) {
      absl::StatusOr<MemoryBudget::Reservation> memory =
          ReserveMemory(*service_, MemoryUse::kProcess, "a Process result");
      absl::Status charged =
          memory.ok() ? memory->Grow(PipelineResultBytes(*result)) : memory.status();
      if (charged.ok()) {
        shared = ShareWithReservation(*std::move(result), *std::move(memory));
      } else {
        result = charged;
      }
    }
    std::lock_guard lock(mu_);
    if (finished_) return;
    result_ready_ = true;
    pending_progress_.reset();
    if (!result.ok()) {
      // An end already pending (an abort while a progress message was being written) is what
      // the call ends with: the pipeline's "cancelled" is only its echo, and reached the client
      // as CANCELLED, which says the client cancelled.
      if (!end_status_) end_status_ = result.status();
    } else {
      slicer_.emplace(std::move(shared), slice_bytes_, batch_parts_);
    }
    if (writing_) return;
    if (end_status_) {
      FinishLocked(*end_status_);
    } else {
      WriteNextLocked();
    }
  }

  void WriteNextLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    if (!pending_progress_ && !slicer_) return;  // nothing to say yet
    bool done = false;
    {
      // Built, serialized and dropped here: gRPC writes the serialized copy.
      wire::ScratchMessage<v1::ProcessResponse> message;
      if (pending_progress_) {
        *message->mutable_progress() = *std::move(pending_progress_);
        pending_progress_.reset();
      } else {
        done = !slicer_->Next(message->mutable_result());
      }
      if (!done) SerializeMessage(*message, &buffer_);
    }
    if (done) {
      FinishLocked(absl::OkStatus());
      return;
    }
    writing_ = true;
    service_->BytesOut(static_cast<std::int64_t>(buffer_.Length()));
    if (idle_ != nullptr) idle_->Arm();
    reactor_->StartWrite(&buffer_);
  }

  void FinishLocked(const absl::Status& status) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    finished_ = true;
    finished_status_ = status;
    slicer_.reset();
    if (slot_ != nullptr) slot_->Release();
    reactor_->Finish(ToGrpcStatus(status, call_));
    reactor_ = nullptr;
  }

  ServiceContext* const service_;
  // Worker-side inputs: written by Prepare() before the task is queued, read by Run().
  core::Clip clip_;
  MemoryBudget::Reservation clip_memory_;
  std::vector<core::PipelineStep> steps_;
  std::int64_t slice_bytes_ = 0;
  bool batch_parts_ = false;
  std::string description_;
  std::chrono::steady_clock::time_point queued_at_;
  std::stop_source stop_;  // thread-safe by itself

  std::mutex mu_;
  ProcessReactorBase* reactor_ ABSL_GUARDED_BY(mu_);  // valid until finished_
  grpc::CallbackServerContext* const call_;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  absl::Status finished_status_ ABSL_GUARDED_BY(mu_);  // what the call ended with
  bool writing_ ABSL_GUARDED_BY(mu_) = false;
  // OnCancel() has run; a write in flight then ends the call in OnWriteDone().
  bool cancelled_ ABSL_GUARDED_BY(mu_) = false;
  bool result_ready_ ABSL_GUARDED_BY(mu_) = false;
  ProgressThrottle throttle_ ABSL_GUARDED_BY(mu_){service_->options.process_progress_interval};
  bool flush_armed_ ABSL_GUARDED_BY(mu_) = false;
  std::unique_ptr<grpc::Alarm> flush_alarm_ ABSL_GUARDED_BY(mu_);
  std::optional<v1::Progress> pending_progress_ ABSL_GUARDED_BY(mu_);
  std::optional<wire::ResultSlicer> slicer_ ABSL_GUARDED_BY(mu_);
  std::optional<absl::Status> end_status_ ABSL_GUARDED_BY(mu_);
  grpc::ByteBuffer buffer_ ABSL_GUARDED_BY(mu_);  // the write in flight
  std::shared_ptr<IdleReaper::Timer> idle_;
  StreamSlot* slot_ ABSL_GUARDED_BY(mu_) = nullptr;
};

class ProcessReactor final : public ProcessReactorBase {
 public:
  ProcessReactor(ServiceContext* service, grpc::CallbackServerContext* call)
      : service_(service), call_(call), link_(std::make_shared<ProcessLink>(service, this, call)) {
    absl::Status admitted = Admit();
    if (!admitted.ok()) {
      link_->FinishNow(admitted);
      return;
    }
    if (service_->idle != nullptr) {
      // Before the start: the client's next message is due. After it: the client must take the
      // result messages (a write outstanding for the whole timeout cancels the call).
      read_idle_ = service_->idle->NewTimer([this] {
        link_->FinishNow(IdleError("Process", service_->idle->timeout()));
      });
      write_idle_ = service_->idle->NewTimer([call] { call->TryCancel(); });
      link_->SetIdleTimer(write_idle_);
    }
    Read();
  }

  void OnReadDone(bool ok) override {
    if (read_idle_ != nullptr) read_idle_->Disarm();
    if (!ok) {
      // After the start a half-close is the normal end of the client's side.
      if (!started_) {
        ReleaseInput();
        link_->FinishNow(absl::InvalidArgumentError(
            "the Process stream ended before ProcessStart (send header, samples, then start)"));
      }
      return;
    }
    ++messages_;
    service_->BytesIn(static_cast<std::int64_t>(buffer_.Length()));
    if (started_) {
      link_->Abort(absl::InvalidArgumentError(absl::StrCat(
          "Process message ", messages_,
          " arrived after ProcessStart; a Process call takes one clip and one start, then the "
          "client only reads")));
      return;
    }
    absl::Status status;
    {
      // Parsed, taken into the clip (or the start) and dropped here.
      wire::ScratchMessage<v1::ProcessRequest> request;
      status = ParseMessage(buffer_, absl::StrCat("Process message ", messages_), request.get());
      if (status.ok()) status = Accept(*request);
    }
    if (!status.ok()) {
      ReleaseInput();
      link_->FinishNow(status);
      return;
    }
    if (!link_->finished()) Read();
  }

  void OnWriteDone(bool ok) override { link_->OnWriteDone(ok); }
  void OnCancel() override { link_->OnCancel(); }
  void OnDone() override {
    if (read_idle_ != nullptr) read_idle_->Close();
    if (write_idle_ != nullptr) write_idle_->Close();
    delete this;
  }

 private:
  absl::Status Admit() {
    TEMPOKEY_RETURN_IF_ERROR(service_->CheckAuth(*call_));
    TEMPOKEY_ASSIGN_OR_RETURN(clip_memory_,
                              ReserveMemory(*service_, MemoryUse::kProcess, "a Process clip"));
    assembler_.emplace(service_->clip_limits, ChargeTo(&clip_memory_));
    TEMPOKEY_RETURN_IF_ERROR(slot_.Claim(*service_));
    link_->SetSlot(&slot_);
    return absl::OkStatus();
  }

  // What a refused call holds goes back to the budget before the client sees the refusal, not
  // when gRPC destroys the call. Only from OnReadDone() before a task was queued: no read is
  // pending and nothing else touches the input.
  void ReleaseInput() {
    assembler_.reset();
    clip_memory_.Release();
    link_->DropInput();
  }

  void Read() {
    link_->ReadUnlessFinished([this] {
      // Only the input phase waits on the client: after the start it may keep its side open.
      if (read_idle_ != nullptr && !started_) read_idle_->Arm();
      StartRead(&buffer_);
    });
  }

  absl::Status Accept(const v1::ProcessRequest& request) {
    switch (request.part_case()) {
      case v1::ProcessRequest::kHeader:
        return assembler_->AddHeader(request.header());
      case v1::ProcessRequest::kSamples:
        return assembler_->AddSamples(request.samples());
      case v1::ProcessRequest::kSampleSlices:
        return assembler_->AddSampleSlices(request.sample_slices());
      case v1::ProcessRequest::kStart:
        return Start(request.start());
      case v1::ProcessRequest::PART_NOT_SET:
        break;
    }
    return absl::InvalidArgumentError(
        absl::StrCat("Process message ", messages_, " has no header, samples or start"));
  }

  absl::Status Start(const v1::ProcessStart& start) {
    TEMPOKEY_RETURN_IF_ERROR(CheckSliceBytes("start.slice_bytes", start.slice_bytes()));
    if (!assembler_->has_header()) {
      return absl::InvalidArgumentError("ProcessStart arrived before the clip header");
    }
    // A call opened before the drain began starts no new work during it: clients retry
    // UNAVAILABLE elsewhere, where they would not retry a CANCELLED at the grace period's end.
    if (service_->draining.load()) {
      return absl::UnavailableError("the server is shutting down and accepts no new jobs");
    }
    TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, std::move(*assembler_).Finish());
    assembler_.reset();
    TEMPOKEY_ASSIGN_OR_RETURN(std::vector<core::PipelineStep> steps,
                              PrepareSteps(start.operations(), clip, service_->clip_limits,
                                           service_->options.max_job_cost_seconds));
    clip_memory_.Settle(ClipBytes(clip));
    link_->Prepare(std::move(clip), std::move(clip_memory_), std::move(steps), start.slice_bytes(),
                   start.batch_parts());
    started_ = true;
    absl::Status queued = service_->pool->TrySubmit(
        [link = link_](std::stop_token pool_stop) { link->Run(std::move(pool_stop)); });
    if (!queued.ok()) {
      if (queued.code() == absl::StatusCode::kResourceExhausted && service_->metrics != nullptr) {
        service_->metrics->RecordRejected("process");
      }
      return queued;
    }
    return absl::OkStatus();
  }

  ServiceContext* const service_;
  grpc::CallbackServerContext* const call_;
  const std::shared_ptr<ProcessLink> link_;
  std::shared_ptr<IdleReaper::Timer> read_idle_;
  std::shared_ptr<IdleReaper::Timer> write_idle_;
  StreamSlot slot_;
  bool started_ = false;
  std::int64_t messages_ = 0;
  grpc::ByteBuffer buffer_;
  // Declared before the assembler, which charges it.
  MemoryBudget::Reservation clip_memory_;
  std::optional<wire::ClipAssembler> assembler_;
};

}  // namespace

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* NewProcessReactor(
    ServiceContext* service, grpc::CallbackServerContext* call) {
  return new ProcessReactor(service, call);
}

}  // namespace tempokey::server
