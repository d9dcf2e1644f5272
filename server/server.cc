#include "server/server.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "grpcpp/health_check_service_interface.h"
#include "grpcpp/impl/server_builder_option.h"
#include "grpcpp/impl/server_builder_plugin.h"
#include "grpcpp/security/server_credentials.h"
#include "grpcpp/server.h"
#include "grpcpp/server_builder.h"
#include "server/clip_store.h"
#include "server/idle_reaper.h"
#include "server/job_manager.h"
#include "server/job_pool.h"
#include "server/memory_budget.h"
#include "server/metrics.h"
#include "server/motion_service.h"
#include "server/reactors.h"
#include "server/reflection_service.h"
#include "server/service_context.h"
#include "server/tls_credentials.h"
#include "spdlog/spdlog.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

// Streaming calls still open once the jobs are done get this long to end, and calls still open
// when the gRPC server shuts down get this long again before they are cancelled.
constexpr std::chrono::seconds kShutdownCallDeadline{2};
// After the grace period, cancelled jobs get this long to notice (they check between channels).
constexpr std::chrono::seconds kCancelSettleTime{10};

// libgrpc++_reflection installs gRPC's own reflection service in every server it is linked into
// (a static initializer registers its plugin), and that service cannot check a token. This
// option takes the plugin out of our builder; ReflectionService serves the protocol instead.
class WithoutStockReflection final : public grpc::ServerBuilderOption {
 public:
  void UpdateArguments(grpc::ChannelArguments*) override {}
  void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
    std::erase_if(*plugins, [](const std::unique_ptr<grpc::ServerBuilderPlugin>& plugin) {
      return plugin->name() == "proto_server_reflection";
    });
  }
};

std::string_view Outcome(JobState state) {
  switch (state) {
    case JobState::kSucceeded:
      return "succeeded";
    case JobState::kCancelled:
      return "cancelled";
    default:
      return "failed";
  }
}

// A 32-frame clip with a position and two rotation channels, for ProbeOperations().
core::Clip ProbeClip() {
  core::Clip clip;
  clip.name = "probe";
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = 32;
  core::Joint root;
  root.name = "root";
  root.channels = {0, 1, 2};
  clip.skeleton.joints.push_back(root);
  const core::ChannelKind kinds[] = {core::ChannelKind::kXPosition, core::ChannelKind::kZRotation,
                                     core::ChannelKind::kXRotation};
  for (core::ChannelKind kind : kinds) {
    core::Channel channel;
    channel.joint = 0;
    channel.kind = kind;
    for (std::int64_t f = 0; f < clip.frame_count; ++f) {
      channel.samples.push_back(10.0 * std::sin(0.2 * static_cast<double>(f)) +
                                static_cast<double>(f));
    }
    clip.channels.push_back(std::move(channel));
  }
  return clip;
}

}  // namespace

std::vector<std::string> ProbeOperations() {
  const core::Clip clip = ProbeClip();
  auto offered = [&](std::vector<core::PipelineStep> steps) {
    absl::StatusOr<core::PipelineResult> result = core::RunPipeline(clip, steps);
    return result.ok() || result.status().code() != absl::StatusCode::kUnimplemented;
  };
  std::vector<std::string> operations;
  if (offered({core::ConvertStep{.wrap_rotations = true}})) operations.push_back("convert");
  core::RetimeStep retime;
  if (offered({retime})) operations.push_back("retime");
  retime.options.method = core::RetimeMethod::kPaper;
  if (offered({retime})) operations.push_back("retime/paper");
  core::ReduceStep tolerance;
  const bool has_tolerance = offered({tolerance});
  if (has_tolerance) {
    operations.push_back("reduce");
    operations.push_back("reduce/tolerance");
  }
  core::ReduceStep paper;
  paper.options.method = core::ReduceMethod::kPaper;
  const bool has_paper = offered({paper});
  if (has_paper) operations.push_back("reduce/paper");
  core::ReduceStep noise;
  noise.options.method = core::ReduceMethod::kNoise;
  if (offered({noise})) operations.push_back("reduce/noise");
  // Bake needs a keyed clip, which only a reduce step makes.
  if ((has_tolerance || has_paper) &&
      offered({has_tolerance ? tolerance : paper, core::BakeStep{}})) {
    operations.push_back("bake");
  }
  return operations;
}

absl::StatusOr<std::unique_ptr<Server>> Server::Start(ServerOptions options) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateServerOptions(options));
  TEMPOKEY_RETURN_IF_ERROR(CheckUnixSocketFree(options.address));
  // TLS files are checked before anything starts, so a bad pair is reported as such.
  TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<grpc::ServerCredentials> credentials,
                            BuildCredentials(options));
  std::unique_ptr<Server> server(new Server());
  const int workers = options.workers > 0 ? options.workers : DefaultWorkerCount();
  const std::int64_t budget =
      options.memory_budget_bytes > 0 ? options.memory_budget_bytes : DefaultMemoryBudget();
  options.memory_budget_bytes = budget;
  server->budget_ = std::make_unique<MemoryBudget>(budget);
  server->idle_ = std::make_unique<IdleReaper>(options.stream_idle_timeout);
  server->pool_ = std::make_unique<JobPool>(workers, options.queue_capacity);
  server->clips_ = std::make_unique<ClipStore>(options.max_stored_clips,
                                               options.max_stored_clip_bytes);
  server->context_ = std::make_unique<ServiceContext>();
  ServiceContext* context = server->context_.get();
  context->options = options;
  context->budget = server->budget_.get();
  context->idle = server->idle_.get();
  for (const std::string& token : options.auth_tokens) {
    context->owner_ids.push_back(OwnerIdOfToken(token));
  }
  context->clip_limits.max_samples = options.max_clip_samples;
  context->clip_limits.max_frames = std::min(context->clip_limits.max_frames, options.max_clip_samples);
  context->clip_limits.max_channels =
      std::min(context->clip_limits.max_channels, options.max_clip_samples);

  JobManagerOptions job_options;
  job_options.max_stored_results = options.max_stored_results;
  job_options.max_stored_result_bytes = options.max_stored_result_bytes;
  job_options.job_ttl = options.job_ttl;
  job_options.output_limits = context->clip_limits;
  job_options.budget = server->budget_.get();
  job_options.on_job_start = options.test_hooks.on_job_start;
  job_options.on_job_end = [context](const JobSnapshot& job, std::chrono::duration<double> wait,
                                     std::chrono::duration<double> run) {
    const std::string error =
        job.error.ok() ? ""
                       : absl::StrCat(" error=", core::LogValue(core::AsStd(job.error.message())));
    spdlog::info("job id={} clip={} operations={} queue_wait_ms={:.1f} run_ms={:.1f} outcome={}{}",
                 job.job_id, job.spec->clip_id, DescribeSteps(job.spec->steps),
                 wait.count() * 1000.0, run.count() * 1000.0, Outcome(job.state), error);
    if (context->metrics != nullptr) {
      context->metrics->RecordFinished("job", Outcome(job.state), (wait + run).count());
    }
  };
  server->jobs_ = std::make_unique<JobManager>(server->pool_.get(), std::move(job_options));
  context->pool = server->pool_.get();
  context->jobs = server->jobs_.get();
  context->clips = server->clips_.get();
  context->operations = ProbeOperations();
  // Caches give memory back when the budget is short: stored clips first (a client can upload
  // again), then finished jobs, oldest first.
  ClipStore* clip_store = server->clips_.get();
  JobManager* job_manager = server->jobs_.get();
  server->budget_->AddReclaimer([clip_store](std::int64_t wanted) { clip_store->Reclaim(wanted); });
  server->budget_->AddReclaimer(
      [job_manager](std::int64_t wanted) { job_manager->ReclaimFinished(wanted); });

  if (!options.metrics_address.empty()) {
    JobPool* pool = server->pool_.get();
    JobManager* jobs = server->jobs_.get();
    ClipStore* clips = server->clips_.get();
    MemoryBudget* memory = server->budget_.get();
    MetricsAuthCheck check_auth;
    if (!options.auth_tokens.empty()) {
      check_auth = [context](const char* header) { return context->CheckBearer(header); };
    }
    TEMPOKEY_ASSIGN_OR_RETURN(
        server->metrics_,
        Metrics::Start(
            options.metrics_address,
            MetricsGaugeSources{
                .queue_depth = [pool] { return pool->queue_depth(); },
                .running = [pool] { return pool->running(); },
                .stored_jobs = [jobs] { return jobs->job_count(); },
                .stored_clips = [clips] { return clips->size(); },
                .memory_budget = [memory] { return memory->capacity(); },
                .memory_used =
                    [memory] {
                      std::vector<std::pair<std::string, std::int64_t>> used;
                      for (int i = 0; i < kMemoryUseCount; ++i) {
                        const auto use = static_cast<MemoryUse>(i);
                        used.emplace_back(std::string(MemoryUseName(use)), memory->used(use));
                      }
                      return used;
                    },
                .digest_threads = [context] { return context->digest_threads.in_use(); },
                .digest_threads_max = [context] { return context->digest_threads.max(); }},
            std::move(check_auth)));
    context->metrics = server->metrics_.get();
  }

  server->service_ = std::make_unique<MotionService>(context);
  server->reflection_ = std::make_unique<ReflectionService>(
      context, std::vector<std::string>{kMotionServiceName, "grpc.health.v1.Health",
                                        "grpc.reflection.v1alpha.ServerReflection"});
  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  builder.AddListeningPort(options.address, credentials, &server->port_);
  // gRPC sets SO_REUSEPORT on Linux by default: a second server on a port in use would start
  // and silently take a share of its connections. Off, the second one fails to listen.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.SetMaxReceiveMessageSize(static_cast<int>(options.max_message_bytes));
  builder.RegisterService(server->service_.get());
  builder.RegisterCallbackGenericService(server->reflection_.get());
  builder.SetOption(std::make_unique<WithoutStockReflection>());
  if (options.max_connection_age.count() > 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_MS,
                               static_cast<int>(options.max_connection_age.count() * 1000));
    // No grace limit (INT_MAX is gRPC's "unlimited", grpc_types.h, and its own default): the
    // GOAWAY already sends new calls to a new connection (the rebalancing), and a call in flight
    // (a long Process, a quiet WatchJob) runs to its end. The drain grace served here before: at
    // --drain_grace_seconds=0 every aged connection cut its calls.
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_AGE_GRACE_MS,
                               std::numeric_limits<int>::max());
  }
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS,
                             static_cast<int>(options.min_client_ping_interval.count()));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  // Covers the TLS handshake and the wait for the client's HTTP/2 SETTINGS (chttp2's server
  // closes a connection without them at the handshake deadline), plain connections included.
  builder.AddChannelArgument(GRPC_ARG_SERVER_HANDSHAKE_TIMEOUT_MS,
                             static_cast<int>(options.handshake_timeout.count()));
  server->grpc_server_ = builder.BuildAndStart();
  if (server->grpc_server_ == nullptr || server->port_ == 0) {
    return absl::UnavailableError(
        absl::StrCat("cannot listen on ", options.address, " (address in use or invalid?)"));
  }
  grpc::HealthCheckServiceInterface* health = server->grpc_server_->GetHealthCheckService();
  health->SetServingStatus("", true);
  health->SetServingStatus(kMotionServiceName, true);
  spdlog::info("serving on port {} workers={} queue_capacity={} memory_budget_bytes={} tls={} "
               "mtls={} auth_tokens={} open_reflection={} operations={}",
               server->port_, workers, options.queue_capacity, budget,
               !options.tls_cert_file.empty(), !options.tls_client_ca_file.empty(),
               options.auth_tokens.size(), options.open_reflection,
               absl::StrJoin(context->operations, ","));
  return server;
}

Server::~Server() {
  Drain();
  grpc_server_.reset();  // before the service and context its calls use
  // Its endpoint serves until it goes, and its gauges and bearer check read context_, which is
  // declared after it and so would go first. Nothing records into it any more (the calls and
  // the workers are done).
  context_->metrics = nullptr;
  metrics_.reset();
}

int Server::open_streams() const { return context_->open_streams.load(); }

int Server::metrics_port() const { return metrics_ == nullptr ? 0 : metrics_->port(); }

std::string Server::target() const { return absl::StrCat("127.0.0.1:", port_); }

const ServerOptions& Server::options() const { return context_->options; }

absl::Status Server::CheckBearer(const char* header) const { return context_->CheckBearer(header); }

const std::vector<std::string>& Server::operations() const { return context_->operations; }

std::shared_ptr<grpc::Channel> Server::InProcessChannel(const grpc::ChannelArguments& args) {
  return grpc_server_->InProcessChannel(args);
}

void Server::Quiesce() {
  std::call_once(quiesce_once_, [this] {
    if (grpc_server_ == nullptr) return;  // Start() failed half way
    const auto grace = context_->options.drain_grace;
    spdlog::info("draining: not ready, refusing new work, closing watches; {} queued and {} "
                 "running get {} s to finish",
                 pool_->queue_depth(), pool_->running(), grace.count());
    // Refuse first, then say so: a client that sees NOT_SERVING and calls at once must get
    // UNAVAILABLE, never a job accepted in between.
    context_->draining.store(true);
    jobs_->BeginDrain();
    grpc_server_->GetHealthCheckService()->SetServingStatus(kMotionServiceName, false);
    if (!pool_->WaitIdle(std::chrono::steady_clock::now() + grace)) {
      spdlog::warn("drain grace period over: cancelling {} queued and {} running",
                   pool_->queue_depth(), pool_->running());
      jobs_->CancelAll();
      pool_->RequestStopAll();
      pool_->WaitIdle(std::chrono::steady_clock::now() + kCancelSettleTime);
    }
    // Results still streaming (downloads, Process answers) finish while gRPC still serves.
    const auto streams_deadline = std::chrono::steady_clock::now() + kShutdownCallDeadline;
    while (context_->open_streams.load() > 0 &&
           std::chrono::steady_clock::now() < streams_deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    spdlog::info("drained: {} streaming calls still open", context_->open_streams.load());
  });
}

void Server::Drain() {
  std::call_once(drain_once_, [this] {
    Quiesce();
    if (grpc_server_ != nullptr) {
      grpc_server_->Shutdown(std::chrono::system_clock::now() + kShutdownCallDeadline);
      grpc_server_->Wait();
    }
    if (pool_ != nullptr) pool_->Shutdown();
  });
}

}  // namespace tempokey::server
