// The streaming calls of MotionService, one reactor class per method (each in its own file).
// Internal to the server library.
#ifndef TEMPOKEY_SERVER_REACTORS_H_
#define TEMPOKEY_SERVER_REACTORS_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "grpcpp/support/byte_buffer.h"
#include "grpcpp/support/server_callback.h"
#include "proto/clip_convert.h"
#include "server/service_context.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/v1/motion_service.pb.h"

namespace tempokey::server {

namespace v1 = ::tempokey::v1;

// Each reactor parses its messages from ByteBuffers (wire_codec.h), authenticates, and arms an
// idle timer (ServiceContext::idle) while it waits on the client.
grpc::ServerReadReactor<grpc::ByteBuffer>* NewUploadReactor(ServiceContext* service,
                                                            grpc::CallbackServerContext* call,
                                                            grpc::ByteBuffer* response);
grpc::ServerWriteReactor<grpc::ByteBuffer>* NewWatchReactor(ServiceContext* service,
                                                            grpc::CallbackServerContext* call,
                                                            const grpc::ByteBuffer* request);
// What a sliced result stream (GetJobResult, GetClip) sends: the result, shared with the stream,
// and the client's slicing (wire::ResultSlicer).
struct ResultStream {
  std::shared_ptr<const core::PipelineResult> result;
  std::int64_t slice_bytes = 0;
  bool batch_parts = false;
};
// Opens a sliced result stream for `owner` from its raw request: parses, checks, looks up, and
// calls `claim_slot` (the stream's slot in ServiceContext's limit) once the request is known to
// be good and before any costly copy.
using OpenResultStream = std::function<absl::StatusOr<ResultStream>(
    const std::string& owner, const grpc::ByteBuffer& raw_request,
    const std::function<absl::Status()>& claim_slot)>;
// A reactor streaming what `open` opens, one ResultPart in flight at a time; `stream` names it in
// errors ("the clip stream broke").
grpc::ServerWriteReactor<grpc::ByteBuffer>* NewSlicedResultReactor(
    ServiceContext* service, grpc::CallbackServerContext* call, const grpc::ByteBuffer& request,
    std::string_view stream, const OpenResultStream& open);
grpc::ServerWriteReactor<grpc::ByteBuffer>* NewResultReactor(ServiceContext* service,
                                                             grpc::CallbackServerContext* call,
                                                             const grpc::ByteBuffer* request);
grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* NewProcessReactor(
    ServiceContext* service, grpc::CallbackServerContext* call);

// Finishes a unary `call` with `status` (its retry hint as trailing metadata).
grpc::ServerUnaryReactor* FinishUnary(grpc::CallbackServerContext* call, const absl::Status& status);
// The same with the call's reactor already taken: CallbackServerContext::DefaultReactor() builds
// the reactor afresh each time it is called, so a call answered on another thread must take it
// once, before it hands the work on, and finish that one.
grpc::ServerUnaryReactor* FinishUnary(grpc::ServerUnaryReactor* reactor,
                                      grpc::CallbackServerContext* call, const absl::Status& status);

// The start of every unary call: the token check (the caller's owner id), then `raw_request`
// parsed into `request` (`method` names it in the error). Counts the bytes in.
// Errors: kUnauthenticated; kInvalidArgument "SubmitJob request: 18 bytes are not a valid ...".
absl::StatusOr<std::string> OpenUnary(ServiceContext& service,
                                      const grpc::CallbackServerContext& call,
                                      const grpc::ByteBuffer& raw_request, std::string_view method,
                                      google::protobuf::Message* request);

// The end of every unary call, on any thread: `response` into `raw_response` when `status` is
// OK, the bytes counted, a large exchange noted for returning memory, the call finished.
grpc::ServerUnaryReactor* AnswerUnary(ServiceContext& service, grpc::CallbackServerContext* call,
                                      const grpc::ByteBuffer& raw_request,
                                      const absl::Status& status,
                                      const google::protobuf::Message& response,
                                      grpc::ByteBuffer* raw_response);
// The same finishing `reactor`, the call's DefaultReactor() taken before (see FinishUnary()).
grpc::ServerUnaryReactor* AnswerUnary(ServiceContext& service, grpc::ServerUnaryReactor* reactor,
                                      grpc::CallbackServerContext* call,
                                      const grpc::ByteBuffer& raw_request,
                                      const absl::Status& status,
                                      const google::protobuf::Message& response,
                                      grpc::ByteBuffer* raw_response);

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

// Checks a request's slice size `field` (0: 1 MiB).
// Errors: kInvalidArgument "slice_bytes must be >= 0 (0: 1 MiB), got -1".
absl::Status CheckSliceBytes(std::string_view field, std::int64_t slice_bytes);

// Checks an id field of a request (job_id, clip_id): not empty, at most kMaxIdBytes.
// Errors: kInvalidArgument "job_id is empty"; kResourceExhausted "job_id is 300 bytes, over the
// limit of 256".
absl::Status CheckId(std::string_view field, const std::string& id);

// An allocation hook (wire::ClipAssembler) charging `reservation`, which must outlive the
// assembler.
wire::AllocationHook ChargeTo(MemoryBudget::Reservation* reservation);

// An empty reservation for `use` in the server's budget (an unbudgeted one when the context
// has no budget), grown as data arrives.
absl::StatusOr<MemoryBudget::Reservation> ReserveMemory(ServiceContext& service, MemoryUse use,
                                                        std::string_view what);

// What an idle timer says when it ends a call whose client sent nothing for `timeout`.
absl::Status IdleError(std::string_view call, std::chrono::milliseconds timeout);

// "retime+reduce" for log lines.
std::string DescribeSteps(const std::vector<core::PipelineStep>& steps);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_REACTORS_H_
