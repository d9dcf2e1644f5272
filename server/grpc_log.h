// gRPC's own log lines (a failed TLS handshake, a bind error) through the server's logger.
// Untouched, gRPC wrote each as a raw "E1201 ..." line on stderr at any --log_level, one per
// failed handshake: any peer could add lines at will, in another format than the server's.
#ifndef TEMPOKEY_SERVER_GRPC_LOG_H_
#define TEMPOKEY_SERVER_GRPC_LOG_H_

#include <chrono>

namespace tempokey::server {

// gRPC lines shown per window; the rest are counted and said in one line when the next window
// starts.
inline constexpr int kGrpcLinesPerWindow = 20;
inline constexpr std::chrono::seconds kGrpcLogWindow{10};

// From now on gRPC's lines go to spdlog's default logger as warnings ("grpc: <message>", control
// characters escaped), subject to its level and to the limit above. Call once, before the
// server starts.
void RouteGrpcLogToSpdlog();

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_GRPC_LOG_H_
