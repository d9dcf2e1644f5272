// tempokey.v1.MotionService on the gRPC callback API. Handlers only validate, enqueue or look
// up; pipelines run on the JobPool.
#ifndef TEMPOKEY_SERVER_MOTION_SERVICE_H_
#define TEMPOKEY_SERVER_MOTION_SERVICE_H_

#include "server/service_context.h"
#include "tempokey/v1/motion_service.grpc.pb.h"

namespace tempokey::server {

// Thread-safe; `context` must outlive the service and every call it serves.
class MotionService final : public v1::MotionService::CallbackService {
 public:
  explicit MotionService(ServiceContext* context) : context_(context) {}

  grpc::ServerUnaryReactor* GetServerInfo(grpc::CallbackServerContext* call,
                                          const v1::GetServerInfoRequest* request,
                                          v1::ServerInfo* response) override;
  grpc::ServerReadReactor<v1::UploadClipRequest>* UploadClip(
      grpc::CallbackServerContext* call, v1::UploadClipResponse* response) override;
  grpc::ServerUnaryReactor* SubmitJob(grpc::CallbackServerContext* call,
                                      const v1::SubmitJobRequest* request,
                                      v1::Job* response) override;
  grpc::ServerUnaryReactor* GetJob(grpc::CallbackServerContext* call,
                                   const v1::GetJobRequest* request, v1::Job* response) override;
  grpc::ServerUnaryReactor* ListJobs(grpc::CallbackServerContext* call,
                                     const v1::ListJobsRequest* request,
                                     v1::ListJobsResponse* response) override;
  grpc::ServerUnaryReactor* CancelJob(grpc::CallbackServerContext* call,
                                      const v1::CancelJobRequest* request,
                                      v1::Job* response) override;
  grpc::ServerUnaryReactor* DeleteJob(grpc::CallbackServerContext* call,
                                      const v1::DeleteJobRequest* request,
                                      v1::DeleteJobResponse* response) override;
  grpc::ServerWriteReactor<v1::Job>* WatchJob(grpc::CallbackServerContext* call,
                                              const v1::WatchJobRequest* request) override;
  grpc::ServerWriteReactor<v1::ResultPart>* GetJobResult(
      grpc::CallbackServerContext* call, const v1::GetJobResultRequest* request) override;
  grpc::ServerBidiReactor<v1::ProcessRequest, v1::ProcessResponse>* Process(
      grpc::CallbackServerContext* call) override;

  // For editors (editing.proto); defined in editing_handlers.cc.
  grpc::ServerUnaryReactor* ParseClipFile(grpc::CallbackServerContext* call,
                                          const v1::ParseClipFileRequest* request,
                                          v1::ParseClipFileResponse* response) override;
  grpc::ServerWriteReactor<v1::ResultPart>* GetClip(grpc::CallbackServerContext* call,
                                                    const v1::GetClipRequest* request) override;
  grpc::ServerUnaryReactor* PlanRetime(grpc::CallbackServerContext* call,
                                       const v1::PlanRetimeRequest* request,
                                       v1::RetimePlan* response) override;
  grpc::ServerUnaryReactor* ParseSpeedKnots(grpc::CallbackServerContext* call,
                                            const v1::ParseSpeedKnotsRequest* request,
                                            v1::ParseSpeedKnotsResponse* response) override;
  grpc::ServerWriteReactor<v1::FileChunk>* ExportFile(grpc::CallbackServerContext* call,
                                                      const v1::ExportFileRequest* request) override;

 private:
  ServiceContext* const context_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_MOTION_SERVICE_H_
