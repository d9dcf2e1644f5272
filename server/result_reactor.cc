// GetJobResult: the result of a succeeded job in slices (ResultHeader with the reports first),
// one message in flight at a time, built lazily from the shared result: results far larger than
// a client's 4 MiB receive limit stream with constant server memory per call. A client that
// takes no message for the idle timeout is cancelled.
#include <memory>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/jobs_convert.h"
#include "server/job_proto.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "server/wire_codec.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

class ResultReactor final : public grpc::ServerWriteReactor<grpc::ByteBuffer> {
 public:
  ResultReactor(ServiceContext* service, grpc::CallbackServerContext* call,
                const grpc::ByteBuffer* request)
      : service_(service) {
    absl::Status status = Open(*call, *request);
    if (!status.ok()) {
      slot_.Release();
      Finish(ToGrpcStatus(status, call));
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
      slot_.Release();
      Finish(ToGrpcStatus(absl::CancelledError("the result stream broke")));
      return;
    }
    WriteNext();
  }

  void OnDone() override {
    if (idle_ != nullptr) idle_->Close();
    delete this;
  }

 private:
  absl::Status Open(const grpc::CallbackServerContext& call, const grpc::ByteBuffer& raw_request) {
    TEMPOKEY_ASSIGN_OR_RETURN(const std::string owner, service_->Authenticate(call));
    v1::GetJobResultRequest request;
    TEMPOKEY_RETURN_IF_ERROR(ParseMessage(raw_request, "GetJobResult request", &request));
    TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request.job_id()));
    if (request.slice_bytes() < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("slice_bytes must be >= 0 (0: 1 MiB), got ", request.slice_bytes()));
    }
    absl::StatusOr<std::shared_ptr<const core::PipelineResult>> result =
        service_->jobs->Result(request.job_id(), owner);
    if (!result.ok()) return result.status();
    TEMPOKEY_RETURN_IF_ERROR(slot_.Claim(*service_, /*allow_while_draining=*/true));
    slicer_.emplace(*std::move(result), request.slice_bytes(), request.batch_parts());
    return absl::OkStatus();
  }

  void WriteNext() {
    if (!slicer_->Next(&part_)) {
      slot_.Release();
      Finish(grpc::Status::OK);
      return;
    }
    SerializeMessage(part_, &buffer_);
    service_->BytesOut(static_cast<std::int64_t>(buffer_.Length()));
    if (idle_ != nullptr) idle_->Arm();
    StartWrite(&buffer_);
  }

  ServiceContext* const service_;
  StreamSlot slot_;
  std::optional<wire::ResultSlicer> slicer_;
  std::shared_ptr<IdleReaper::Timer> idle_;
  v1::ResultPart part_;
  grpc::ByteBuffer buffer_;
};

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* NewResultReactor(ServiceContext* service,
                                                             grpc::CallbackServerContext* call,
                                                             const grpc::ByteBuffer* request) {
  return new ResultReactor(service, call, request);
}

}  // namespace tempokey::server
