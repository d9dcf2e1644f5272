// The streaming calls of MotionService, one reactor class per method (each in its own file).
// Internal to the server library.
#ifndef TEMPOKEY_SERVER_REACTORS_H_
#define TEMPOKEY_SERVER_REACTORS_H_

#include <vector>

#include "absl/status/statusor.h"
#include "grpcpp/support/server_callback.h"
#include "server/service_context.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/v1/motion_service.pb.h"

namespace tempokey::server {

namespace v1 = ::tempokey::v1;

grpc::ServerReadReactor<v1::UploadClipRequest>* NewUploadReactor(
    ServiceContext* service, grpc::CallbackServerContext* call, v1::UploadClipResponse* response);
grpc::ServerWriteReactor<v1::Job>* NewWatchReactor(ServiceContext* service,
                                                   grpc::CallbackServerContext* call,
                                                   const v1::WatchJobRequest* request);
grpc::ServerWriteReactor<v1::ResultPart>* NewResultReactor(ServiceContext* service,
                                                           grpc::CallbackServerContext* call,
                                                           const v1::GetJobResultRequest* request);
grpc::ServerBidiReactor<v1::ProcessRequest, v1::ProcessResponse>* NewProcessReactor(
    ServiceContext* service, grpc::CallbackServerContext* call);

// Operations off the wire, checked against `clip` and what the server lets a pipeline produce
// (wire::PipelineFromProto() then core::EstimatePipelineCost(), which validates every step
// against the exact shape of its input), and refused when their predicted work is over
// `max_cost_seconds` (0: no limit), before anything is queued.
// Errors: kInvalidArgument naming the operation, field and value; kResourceExhausted "the
// request is over this server's work limit: predicted 143 s of work (operation 1, ...), over
// the limit of 60 s (--max_job_cost_seconds) ..." (no retry hint: retrying cannot help).
absl::StatusOr<std::vector<core::PipelineStep>> PrepareSteps(
    const google::protobuf::RepeatedPtrField<v1::Operation>& operations, const core::Clip& clip,
    const core::ClipLimits& limits, double max_cost_seconds);

// Checks an id field of a request (job_id, clip_id): not empty, at most 256 bytes.
// Errors: kInvalidArgument "job_id is empty", "job_id is 300 bytes, over the limit of 256".
absl::Status CheckId(std::string_view field, const std::string& id);

// "retime+reduce" for log lines.
std::string DescribeSteps(const std::vector<core::PipelineStep>& steps);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_REACTORS_H_
