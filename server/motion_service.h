// tempokey.v1.MotionService on the gRPC callback API. Handlers only validate, enqueue or look
// up; pipelines run on the JobPool.
//
// Every method is registered raw (ByteBuffer in and out) and parses its messages itself
// (wire_codec.h): bytes that are not a valid request get INVALID_ARGUMENT naming the message,
// where gRPC's typed handlers would answer UNIMPLEMENTED with no message.
#ifndef TEMPOKEY_SERVER_MOTION_SERVICE_H_
#define TEMPOKEY_SERVER_MOTION_SERVICE_H_

#include <cstddef>
#include <cstdint>

#include "grpcpp/support/byte_buffer.h"
#include "server/service_context.h"
#include "tempokey/v1/motion_service.grpc.pb.h"

namespace tempokey::server {

// Size limits of requests (README "Limits"); beyond them a request gets RESOURCE_EXHAUSTED.
inline constexpr int kMaxLabels = 64;
inline constexpr std::size_t kMaxLabelKeyBytes = 128;
inline constexpr std::size_t kMaxLabelValueBytes = 1024;
inline constexpr std::size_t kMaxRequestIdBytes = 256;
inline constexpr std::size_t kMaxIdBytes = 256;
// A ListJobs page stops before this many bytes of jobs (at least one job per page), well under
// the 4 MiB gRPC clients receive by default, and says where to go on.
inline constexpr std::int64_t kMaxListPageBytes = std::int64_t{1} << 20;

namespace internal {
using Generated = v1::MotionService;
// Every method raw: the editing calls, then the jobs and clips calls on top of them.
using RawEditingMethods = Generated::WithRawCallbackMethod_ParseClipFile<
    Generated::WithRawCallbackMethod_GetClip<Generated::WithRawCallbackMethod_PlanRetime<
        Generated::WithRawCallbackMethod_ParseSpeedKnots<
            Generated::WithRawCallbackMethod_ExportFile<Generated::Service>>>>>;
using RawMotionServiceBase = Generated::WithRawCallbackMethod_GetServerInfo<
    Generated::WithRawCallbackMethod_UploadClip<Generated::WithRawCallbackMethod_SubmitJob<
        Generated::WithRawCallbackMethod_GetJob<Generated::WithRawCallbackMethod_ListJobs<
            Generated::WithRawCallbackMethod_CancelJob<Generated::WithRawCallbackMethod_DeleteJob<
                Generated::WithRawCallbackMethod_WatchJob<
                    Generated::WithRawCallbackMethod_GetJobResult<
                        Generated::WithRawCallbackMethod_Process<RawEditingMethods>>>>>>>>>>;
}  // namespace internal

// Thread-safe; `context` must outlive the service and every call it serves.
class MotionService final : public internal::RawMotionServiceBase {
 public:
  explicit MotionService(ServiceContext* context) : context_(context) {}

  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* call,
                                          const grpc::ByteBuffer* request,
                                          grpc::ByteBuffer* response) override;
  grpc::ServerReadReactor<grpc::ByteBuffer>* UploadClip(grpc::CallbackServerContext* call,
                                                        grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* SubmitJob(grpc::CallbackServerContext* call,
                                      const grpc::ByteBuffer* request,
                                      grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* GetJob(grpc::CallbackServerContext* call,
                                   const grpc::ByteBuffer* request,
                                   grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* ListJobs(grpc::CallbackServerContext* call,
                                     const grpc::ByteBuffer* request,
                                     grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* CancelJob(grpc::CallbackServerContext* call,
                                      const grpc::ByteBuffer* request,
                                      grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* DeleteJob(grpc::CallbackServerContext* call,
                                      const grpc::ByteBuffer* request,
                                      grpc::ByteBuffer* response) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* WatchJob(grpc::CallbackServerContext* call,
                                                       const grpc::ByteBuffer* request) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* GetJobResult(
      grpc::CallbackServerContext* call, const grpc::ByteBuffer* request) override;
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Process(
      grpc::CallbackServerContext* call) override;

  // For editors (editing.proto); defined in editing_handlers.cc.
  grpc::ServerUnaryReactor* ParseClipFile(grpc::CallbackServerContext* call,
                                          const grpc::ByteBuffer* request,
                                          grpc::ByteBuffer* response) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* GetClip(grpc::CallbackServerContext* call,
                                                      const grpc::ByteBuffer* request) override;
  grpc::ServerUnaryReactor* PlanRetime(grpc::CallbackServerContext* call,
                                       const grpc::ByteBuffer* request,
                                       grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* ParseSpeedKnots(grpc::CallbackServerContext* call,
                                            const grpc::ByteBuffer* request,
                                            grpc::ByteBuffer* response) override;
  grpc::ServerWriteReactor<grpc::ByteBuffer>* ExportFile(grpc::CallbackServerContext* call,
                                                         const grpc::ByteBuffer* request) override;

 private:
  ServiceContext* const context_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_MOTION_SERVICE_H_
