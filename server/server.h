// A running tempokey server: gRPC MotionService (callback API), health, reflection, the worker
// pool, jobs, clip store and metrics. main.cc and the tests start it the same way.
#ifndef TEMPOKEY_SERVER_SERVER_H_
#define TEMPOKEY_SERVER_SERVER_H_

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "grpcpp/channel.h"
#include "grpcpp/support/channel_arguments.h"
#include "server/server_options.h"

namespace grpc {
class Server;
}  // namespace grpc

namespace tempokey::server {

class ClipStore;
class IdleReaper;
class JobManager;
class JobPool;
class MemoryBudget;
class Metrics;
class MotionService;
class ReflectionService;
struct ServiceContext;

// The name health checks use for readiness.
inline constexpr char kMotionServiceName[] = "tempokey.v1.MotionService";

// Operation kinds core implements in this build ("convert", "retime", "retime/paper", "reduce",
// "reduce/tolerance", "reduce/paper", "bake"), found by running each on a tiny clip: what
// answers UNIMPLEMENTED is not offered.
std::vector<std::string> ProbeOperations();

class Server {
 public:
  // Validates `options`, starts the workers, binds the address and starts serving; health says
  // SERVING for "" (live) and kMotionServiceName (ready).
  // Errors: kInvalidArgument bad options, a TLS file that cannot be read or holds no PEM
  // certificate or key, a key that does not match its certificate; kUnavailable when the address
  // or the metrics address cannot be bound.
  static absl::StatusOr<std::unique_ptr<Server>> Start(ServerOptions options);
  // Drain() with what is left of the grace period, if it has not run.
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // The bound port (the real one when the address asked for port 0).
  int port() const { return port_; }
  // The bound metrics port, 0 without metrics.
  int metrics_port() const;
  // "127.0.0.1:<port>" style target for clients on this machine.
  std::string target() const;
  const ServerOptions& options() const;
  // The bearer-token check of every call, for an HTTP "Authorization" header value (null when
  // the request has none): OK when it names one of options().auth_tokens, or none are set.
  // Errors: kUnauthenticated.
  absl::Status CheckBearer(const char* header) const;
  const std::vector<std::string>& operations() const;
  JobManager& jobs() { return *jobs_; }
  // Streaming calls open now (uploads, watches, results, Process); tests check nothing leaks.
  int open_streams() const;
  JobPool& pool() { return *pool_; }
  MemoryBudget& budget() { return *budget_; }

  // Graceful stop, first part (SPEC 5): readiness goes NOT_SERVING; new jobs, uploads, watches
  // and Process calls get UNAVAILABLE; open watches end with UNAVAILABLE; queued and running jobs
  // get options.drain_grace to finish, then are cancelled; streaming calls still open (result
  // downloads, Process results) get a short while to end. gRPC keeps serving throughout, so
  // every call that arrives is answered (UNAVAILABLE for new work). Blocks until done.
  // Idempotent and thread-safe. Never call it from a signal handler: main.cc waits for signals
  // on a normal thread.
  void Quiesce();
  // Quiesce(), then the gRPC server shuts down (calls still open get a short deadline) and the
  // workers stop. gRPC cancels with CANCELLED any call it accepts after its shutdown began, so
  // tempokey-server ends its process after Quiesce() instead (connections then close, which
  // clients see as UNAVAILABLE); in-process servers (tests, benchmarks) use this.
  void Drain();

  // A channel to this server that skips the network (benchmarks, tests).
  std::shared_ptr<grpc::Channel> InProcessChannel(const grpc::ChannelArguments& args = {});

 private:
  Server() = default;

  int port_ = 0;
  // First, so it outlives everything that holds a reservation.
  std::unique_ptr<MemoryBudget> budget_;
  std::unique_ptr<IdleReaper> idle_;
  std::unique_ptr<JobPool> pool_;
  std::unique_ptr<JobManager> jobs_;
  std::unique_ptr<ClipStore> clips_;
  std::unique_ptr<Metrics> metrics_;
  std::unique_ptr<ServiceContext> context_;
  std::unique_ptr<MotionService> service_;
  std::unique_ptr<ReflectionService> reflection_;
  std::unique_ptr<grpc::Server> grpc_server_;
  std::once_flag quiesce_once_;
  std::once_flag drain_once_;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_SERVER_H_
