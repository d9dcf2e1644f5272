// gRPC server reflection (grpc.reflection.v1alpha.ServerReflection, what grpcurl and grpc_cli
// use) behind the same bearer-token check as MotionService, unless the server opens it
// (ServerOptions::open_reflection). gRPC's own reflection plugin cannot check a token, so this is
// served on the generic callback API, which also answers every unknown method: UNIMPLEMENTED with
// a message naming it.
//
// The protocol messages are built by reflection from the descriptors libgrpc++_reflection
// registers (reflection.proto is not compiled again here: two copies abort at start-up). Files
// are described from the generated descriptor pool, each file with the files it imports, once per
// stream; grpc.health.v1's file is compiled into tempokey_proto for this (gRPC's health service
// registers no descriptors of its own).
#ifndef TEMPOKEY_SERVER_REFLECTION_SERVICE_H_
#define TEMPOKEY_SERVER_REFLECTION_SERVICE_H_

#include <string>
#include <vector>

#include "grpcpp/generic/async_generic_service.h"
#include "server/service_context.h"

namespace tempokey::server {

inline constexpr char kReflectionMethod[] =
    "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo";

class ReflectionService final : public grpc::CallbackGenericService {
 public:
  // `services`: the names list_services answers. `context` must outlive the service.
  ReflectionService(ServiceContext* context, std::vector<std::string> services)
      : context_(context), services_(std::move(services)) {}

  grpc::ServerGenericBidiReactor* CreateReactor(grpc::GenericCallbackServerContext* call) override;

 private:
  ServiceContext* const context_;
  const std::vector<std::string> services_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_REFLECTION_SERVICE_H_
