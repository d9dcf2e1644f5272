// GetJobResult: the result of a succeeded job in slices (ResultHeader with the reports first),
// one message in flight at a time, built lazily from the shared result: results far larger than
// a client's 4 MiB receive limit stream with constant server memory per call.
#include <memory>
#include <utility>

#include "absl/strings/str_cat.h"

#include "proto/jobs_convert.h"
#include "server/job_proto.h"
#include "server/reactors.h"
#include "server/status_util.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

class ResultReactor final : public grpc::ServerWriteReactor<v1::ResultPart> {
 public:
  ResultReactor(ServiceContext* service, grpc::CallbackServerContext* call,
                const v1::GetJobResultRequest* request)
      : service_(service) {
    absl::Status status = Open(*call, *request);
    if (!status.ok()) {
      Finish(ToGrpcStatus(status, call));
      return;
    }
    WriteNext();
  }

  // Only gRPC calls these, one at a time, so the reactor needs no lock.
  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(ToGrpcStatus(absl::CancelledError("the result stream broke")));
      return;
    }
    WriteNext();
  }

  void OnDone() override {
    if (holds_stream_) service_->CloseStream();
    delete this;
  }

 private:
  absl::Status Open(const grpc::CallbackServerContext& call, const v1::GetJobResultRequest& request) {
    if (absl::Status auth = service_->CheckAuth(call); !auth.ok()) return auth;
    TEMPOKEY_RETURN_IF_ERROR(CheckId("job_id", request.job_id()));
    if (request.slice_bytes() < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("slice_bytes must be >= 0 (0: 1 MiB), got ", request.slice_bytes()));
    }
    absl::StatusOr<std::shared_ptr<const core::PipelineResult>> result =
        service_->jobs->Result(request.job_id());
    if (!result.ok()) return result.status();
    if (absl::Status admitted = service_->AdmitStream(/*allow_while_draining=*/true);
        !admitted.ok()) return admitted;
    holds_stream_ = true;
    slicer_.emplace(*std::move(result), request.slice_bytes(), request.batch_parts());
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

}  // namespace

grpc::ServerWriteReactor<v1::ResultPart>* NewResultReactor(ServiceContext* service,
                                                           grpc::CallbackServerContext* call,
                                                           const v1::GetJobResultRequest* request) {
  return new ResultReactor(service, call, request);
}

}  // namespace tempokey::server
