// WatchJob: the snapshot at once, then latest-wins updates (a slow reader skips versions, never
// queues them), ending after the terminal state. The JobManager talks to a WatchLink that
// outlives the reactor, so an update racing with the end of the call finds the link closed
// instead of a deleted reactor. A client that takes no message for the idle timeout while one
// is being written is cancelled, so it holds its stream slot no longer.
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>

#include "server/job_proto.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "server/wire_codec.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

class WatchReactor;

class WatchLink final : public JobWatcher {
 public:
  explicit WatchLink(WatchReactor* reactor) : reactor_(reactor) {}

  void OnJobUpdate(const JobSnapshot& snapshot) override;
  void OnWatchClosed(const absl::Status& status) override;
  void OnWriteDone(bool ok);
  void OnCancel();
  // Ends the call at once (before any write), e.g. for an unknown job.
  void FinishNow(const absl::Status& status);
  // Armed while a write is outstanding (set before the first write).
  void SetIdleTimer(std::shared_ptr<IdleReaper::Timer> idle) { idle_ = std::move(idle); }

 private:
  void WriteNextLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void FinishLocked(const absl::Status& status) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  std::mutex mu_;
  WatchReactor* reactor_ ABSL_GUARDED_BY(mu_);  // valid until finished_
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  bool writing_ ABSL_GUARDED_BY(mu_) = false;
  // OnCancel() has run; a write in flight then ends the call in OnWriteDone().
  bool cancelled_ ABSL_GUARDED_BY(mu_) = false;
  bool terminal_queued_ ABSL_GUARDED_BY(mu_) = false;  // the last snapshot is sent or pending
  std::int64_t newest_version_ ABSL_GUARDED_BY(mu_) = 0;
  std::optional<JobSnapshot> pending_ ABSL_GUARDED_BY(mu_);
  std::optional<absl::Status> close_ ABSL_GUARDED_BY(mu_);
  grpc::ByteBuffer message_ ABSL_GUARDED_BY(mu_);  // the write in flight
  std::shared_ptr<IdleReaper::Timer> idle_;
};

class WatchReactor final : public grpc::ServerWriteReactor<grpc::ByteBuffer> {
 public:
  WatchReactor(ServiceContext* service, grpc::CallbackServerContext* call,
               const grpc::ByteBuffer* raw_request)
      : service_(service), call_(call), link_(std::make_shared<WatchLink>(this)) {
    std::string owner;
    absl::Status admitted = [&]() -> absl::Status {
      TEMPOKEY_ASSIGN_OR_RETURN(owner, service_->Authenticate(*call));
      v1::WatchJobRequest request;
      TEMPOKEY_RETURN_IF_ERROR(ParseMessage(*raw_request, "WatchJob request", &request));
      job_id_ = request.job_id();
      TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", job_id_));
      return slot_.Claim(*service_);
    }();
    if (!admitted.ok()) {
      link_->FinishNow(admitted);
      return;
    }
    if (service_->idle != nullptr) {
      // A write outstanding for the whole timeout: the client stopped reading.
      idle_ = service_->idle->NewTimer([call] { call->TryCancel(); });
      link_->SetIdleTimer(idle_);
    }
    absl::StatusOr<JobSnapshot> snapshot = service_->jobs->Watch(job_id_, link_, owner);
    if (!snapshot.ok()) {
      link_->FinishNow(snapshot.status());
      return;
    }
    watching_ = true;
    link_->OnJobUpdate(*snapshot);
  }

  void OnWriteDone(bool ok) override { link_->OnWriteDone(ok); }
  void OnCancel() override { link_->OnCancel(); }
  void OnDone() override {
    if (idle_ != nullptr) idle_->Close();
    if (watching_) service_->jobs->Unwatch(job_id_, link_.get());
    delete this;
  }

  ServiceContext* service() const { return service_; }
  grpc::CallbackServerContext* call() const { return call_; }
  StreamSlot& slot() { return slot_; }

 private:
  ServiceContext* const service_;
  grpc::CallbackServerContext* const call_;
  std::string job_id_;
  const std::shared_ptr<WatchLink> link_;
  std::shared_ptr<IdleReaper::Timer> idle_;
  StreamSlot slot_;
  bool watching_ = false;
};

void WatchLink::OnJobUpdate(const JobSnapshot& snapshot) {
  std::lock_guard lock(mu_);
  if (finished_ || terminal_queued_ || snapshot.version <= newest_version_) return;
  newest_version_ = snapshot.version;
  terminal_queued_ = IsTerminal(snapshot.state);
  pending_ = snapshot;
  if (!writing_) WriteNextLocked();
}

void WatchLink::OnWatchClosed(const absl::Status& status) {
  std::lock_guard lock(mu_);
  // A watch whose terminal snapshot is on its way ends normally after it.
  if (finished_ || terminal_queued_) return;
  close_ = status;
  pending_.reset();
  if (!writing_) FinishLocked(status);
}

void WatchLink::OnWriteDone(bool ok) {
  if (idle_ != nullptr) idle_->Disarm();
  std::lock_guard lock(mu_);
  writing_ = false;
  if (finished_) return;
  if (!ok) {
    FinishLocked(absl::CancelledError("the watch stream broke"));
  } else if (cancelled_) {
    // The write got through before the cancel: nothing else may be pending to end the call, which
    // would then hold its stream slot until the job's next update.
    FinishLocked(absl::CancelledError("the watch was cancelled"));
  } else if (pending_) {
    WriteNextLocked();
  } else if (close_) {
    FinishLocked(*close_);
  } else if (terminal_queued_) {
    FinishLocked(absl::OkStatus());
  }
}

void WatchLink::OnCancel() {
  std::lock_guard lock(mu_);
  // With a write in flight, its OnWriteDone() finishes the call. gRPC orders no reactions but
  // OnDone (grpcpp/support/server_callback.h: "Reactions may be invoked concurrently"), so that
  // write may be reported done (ok) after the cancel: the cancel is remembered.
  cancelled_ = true;
  if (!finished_ && !writing_) FinishLocked(absl::CancelledError("the watch was cancelled"));
}

void WatchLink::FinishNow(const absl::Status& status) {
  std::lock_guard lock(mu_);
  if (!finished_) FinishLocked(status);
}

void WatchLink::WriteNextLocked() {
  SerializeMessage(JobToProto(*pending_), &message_);
  pending_.reset();
  writing_ = true;
  reactor_->service()->BytesOut(static_cast<std::int64_t>(message_.Length()));
  if (idle_ != nullptr) idle_->Arm();
  reactor_->StartWrite(&message_);
}

void WatchLink::FinishLocked(const absl::Status& status) {
  finished_ = true;
  WatchReactor* reactor = reactor_;
  reactor_ = nullptr;
  reactor->slot().Release();
  // With the call's context, so that a refusal's retry hint (no stream slot) reaches the client.
  reactor->Finish(ToGrpcStatus(status, reactor->call()));
}

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* NewWatchReactor(ServiceContext* service,
                                                            grpc::CallbackServerContext* call,
                                                            const grpc::ByteBuffer* request) {
  return new WatchReactor(service, call, request);
}

}  // namespace tempokey::server
