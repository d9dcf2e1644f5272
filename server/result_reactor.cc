// Sliced result streams (GetJobResult, GetClip): a result in slices (ResultHeader with the
// reports first), one message in flight at a time, built lazily from the shared result: results
// far larger than a client's 4 MiB receive limit stream with constant server memory per call. A
// client that takes no message for the idle timeout is cancelled.
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/jobs_convert.h"
#include "proto/scratch_arena.h"
#include "server/job_proto.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "server/wire_codec.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

class SlicedResultReactor final : public grpc::ServerWriteReactor<grpc::ByteBuffer> {
 public:
  SlicedResultReactor(ServiceContext* service, grpc::CallbackServerContext* call,
                      const grpc::ByteBuffer& request, std::string_view stream,
                      const OpenResultStream& open)
      : service_(service), stream_(stream) {
    if (absl::Status status = Open(*call, request, open); !status.ok()) {
      End(ToGrpcStatus(status, call));
      return;
    }
    if (service_->idle != nullptr) {
      idle_ = service_->idle->NewTimer([call] { call->TryCancel(); });
    }
    WriteNext();
  }

  // Only gRPC calls these, one at a time, so the reactor needs no lock.
  void OnWriteDone(bool ok) override {
    if (idle_ != nullptr) idle_->Disarm();
    if (!ok) {
      End(ToGrpcStatus(absl::CancelledError(absl::StrCat("the ", stream_, " stream broke"))));
      return;
    }
    WriteNext();
  }

  void OnDone() override {
    if (idle_ != nullptr) idle_->Close();
    delete this;
  }

 private:
  absl::Status Open(const grpc::CallbackServerContext& call, const grpc::ByteBuffer& raw_request,
                    const OpenResultStream& open) {
    TEMPOKEY_ASSIGN_OR_RETURN(const std::string owner, service_->Authenticate(call));
    auto claim_slot = [this] {
      // A second claim would count two slots and give back one.
      if (slot_.held()) {
        return absl::InternalError(absl::StrCat("the ", stream_, " stream claimed its slot twice"));
      }
      return slot_.Claim(*service_, /*allow_while_draining=*/true);
    };
    TEMPOKEY_ASSIGN_OR_RETURN(ResultStream stream, open(owner, raw_request, claim_slot));
    if (!slot_.held()) {
      return absl::InternalError(absl::StrCat("the ", stream_, " stream took no stream slot"));
    }
    slicer_.emplace(std::move(stream.result), stream.slice_bytes, stream.batch_parts);
    return absl::OkStatus();
  }

  void WriteNext() {
    bool done = false;
    {
      // Built, serialized and dropped here: gRPC writes the serialized copy.
      wire::ScratchMessage<v1::ResultPart> part;
      done = !slicer_->Next(part.get());
      if (!done) SerializeMessage(*part, &buffer_);
    }
    if (done) {
      End(grpc::Status::OK);
      return;
    }
    service_->BytesOut(static_cast<std::int64_t>(buffer_.Length()));
    if (idle_ != nullptr) idle_->Arm();
    StartWrite(&buffer_);
  }

  // Gives back the stream slot and the result (and the memory it counts, such as GetClip's copy)
  // before the client sees the status: no write is in flight by now.
  void End(const grpc::Status& status) {
    slicer_.reset();
    slot_.Release();
    Finish(status);
  }

  ServiceContext* const service_;
  const std::string stream_;
  StreamSlot slot_;
  std::optional<wire::ResultSlicer> slicer_;
  std::shared_ptr<IdleReaper::Timer> idle_;
  grpc::ByteBuffer buffer_;
};

// GetJobResult: a succeeded job's result, the caller's own.
absl::StatusOr<ResultStream> OpenJobResult(ServiceContext& service, const std::string& owner,
                                           const grpc::ByteBuffer& raw_request,
                                           const std::function<absl::Status()>& claim_slot) {
  v1::GetJobResultRequest request;
  TEMPOKEY_RETURN_IF_ERROR(ParseMessage(raw_request, "GetJobResult request", &request));
  TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request.job_id()));
  TEMPOKEY_RETURN_IF_ERROR(CheckSliceBytes("slice_bytes", request.slice_bytes()));
  absl::StatusOr<std::shared_ptr<const core::PipelineResult>> result =
      service.jobs->Result(request.job_id(), owner);
  if (!result.ok()) return result.status();
  TEMPOKEY_RETURN_IF_ERROR(claim_slot());
  return ResultStream{*std::move(result), request.slice_bytes(), request.batch_parts()};
}

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* NewSlicedResultReactor(
    ServiceContext* service, grpc::CallbackServerContext* call, const grpc::ByteBuffer& request,
    std::string_view stream, const OpenResultStream& open) {
  return new SlicedResultReactor(service, call, request, stream, open);
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* NewResultReactor(ServiceContext* service,
                                                             grpc::CallbackServerContext* call,
                                                             const grpc::ByteBuffer* request) {
  return NewSlicedResultReactor(
      service, call, *request, "result",
      [service](const std::string& owner, const grpc::ByteBuffer& raw,
                const std::function<absl::Status()>& claim_slot) {
        return OpenJobResult(*service, owner, raw, claim_slot);
      });
}

}  // namespace tempokey::server
