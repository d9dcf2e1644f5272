// The client library against a real server started in this process on 127.0.0.1:0 (real
// sockets, real gRPC): uploads, jobs, watches, results, Process, health, errors and retries.
#include "client/client.h"

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <chrono>
#include <future>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "grpcpp/support/validate_service_config.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "tempokey/core/io/bvh.h"
#include "tests/testing/start_gate.h"
#include "tests/testing/test_paths.h"

namespace tempokey::client {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::Each;
using ::testing::Ge;
using ::testing::HasSubstr;
using ::testing::Le;
using ::testing::MatchesRegex;
using ::testing::Not;
using ::tempokey::testing::SharedBvh;

// Bounded waits for things that happen on other threads.
constexpr auto kWaitLimit = std::chrono::seconds(60);

core::Clip BandaiWalk() {
  absl::StatusOr<core::Clip> clip =
      core::ReadBvhFile(SharedBvh("bandai/dataset-1_walk_active_001.bvh"));
  EXPECT_TRUE(clip.ok()) << clip.status();
  return clip.ok() ? *std::move(clip) : core::Clip();
}

class ClientTest : public ::testing::Test {
 protected:
  // Starts a server (with `tokens` accepted, if any) and a client to it.
  void StartServer(std::vector<std::string> tokens = {}, bool gated = false) {
    server::ServerOptions options;
    options.address = "127.0.0.1:0";
    options.workers = 2;
    options.drain_grace = std::chrono::seconds(5);
    options.auth_tokens = std::move(tokens);
    if (gated) options.test_hooks.on_job_start = [this](std::string_view) { gate_.Arrive(); };
    absl::StatusOr<std::unique_ptr<server::Server>> server = server::Server::Start(options);
    ASSERT_TRUE(server.ok()) << server.status();
    server_ = *std::move(server);
  }

  std::unique_ptr<Client> Connect(ClientOptions options = {}) {
    options.target = server_->target();
    absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(options);
    EXPECT_TRUE(client.ok()) << client.status();
    return client.ok() ? *std::move(client) : nullptr;
  }

  void TearDown() override {
    gate_.Open();
    if (server_) server_->Drain();
  }

  ::tempokey::testing::StartGate gate_;
  std::unique_ptr<server::Server> server_;
};

TEST_F(ClientTest, UploadReturnsTheContentIdAndSeesARepeat) {
  StartServer();
  ClientOptions options;
  options.slice_bytes = 4096;
  std::unique_ptr<Client> client = Connect(options);
  const core::Clip clip = BandaiWalk();

  absl::StatusOr<v1::UploadClipResponse> first = client->UploadClip(clip);
  absl::StatusOr<v1::UploadClipResponse> second = client->UploadClip(clip);

  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_THAT(first->clip_id(), MatchesRegex("sha256:[0-9a-f]{64}"));
  EXPECT_EQ(first->frame_count(), 146);
  EXPECT_EQ(first->channel_count(), 132);
  EXPECT_FALSE(first->already_stored());
  EXPECT_EQ(second->clip_id(), first->clip_id());
  EXPECT_TRUE(second->already_stored());
}

TEST_F(ClientTest, SubmittedJobIsWatchedToSuccessAndItsResultIsTheClip) {
  StartServer();
  std::unique_ptr<Client> client = Connect();
  const core::Clip clip = BandaiWalk();
  absl::StatusOr<v1::UploadClipResponse> uploaded = client->UploadClip(clip);
  ASSERT_TRUE(uploaded.ok()) << uploaded.status();
  const core::PipelineStep steps[] = {core::ConvertStep{}};

  absl::StatusOr<v1::Job> job = client->SubmitJob(uploaded->clip_id(), steps);
  ASSERT_TRUE(job.ok()) << job.status();
  std::vector<std::int64_t> versions;
  absl::StatusOr<v1::Job> final_job =
      client->WatchJob(job->job_id(), [&](const v1::Job& update) { versions.push_back(update.version()); });
  absl::StatusOr<core::PipelineResult> result = client->GetJobResult(job->job_id());

  ASSERT_TRUE(final_job.ok()) << final_job.status();
  EXPECT_EQ(final_job->state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(final_job->clip_id(), uploaded->clip_id());
  ASSERT_FALSE(versions.empty());
  EXPECT_TRUE(std::is_sorted(versions.begin(), versions.end()));
  EXPECT_EQ(std::adjacent_find(versions.begin(), versions.end()), versions.end());
  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_TRUE(std::holds_alternative<core::Clip>(result->output));
  EXPECT_EQ(std::get<core::Clip>(result->output), clip);
}

TEST_F(ClientTest, InlineJobRunsWithoutAnUpload) {
  StartServer();
  std::unique_ptr<Client> client = Connect();
  const core::Clip clip = BandaiWalk();
  const core::PipelineStep steps[] = {core::ConvertStep{.wrap_rotations = true}};

  SubmitOptions submit;
  submit.labels = {{"take", "3"}};
  absl::StatusOr<v1::Job> job = client->SubmitInlineJob(clip, steps, submit);
  ASSERT_TRUE(job.ok()) << job.status();
  absl::StatusOr<v1::Job> final_job = client->WatchJob(job->job_id(), {});
  absl::StatusOr<core::PipelineResult> result = client->GetJobResult(job->job_id());

  ASSERT_TRUE(final_job.ok()) << final_job.status();
  EXPECT_EQ(final_job->state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(final_job->labels().at("take"), "3");
  ASSERT_TRUE(result.ok()) << result.status();
  const core::Clip& wrapped = std::get<core::Clip>(result->output);
  for (const core::Channel& channel : wrapped.channels) {
    if (!core::IsRotation(channel.kind)) continue;
    EXPECT_THAT(channel.samples, Each(AllOf(Ge(-180.0), Le(180.0))));
  }
}

TEST_F(ClientTest, RepeatedRequestIdReturnsTheFirstJob) {
  StartServer();
  std::unique_ptr<Client> client = Connect();
  const core::Clip clip = BandaiWalk();
  const core::PipelineStep steps[] = {core::ConvertStep{}};
  SubmitOptions submit;
  submit.request_id = "0b7a4c1e-retry-test";

  absl::StatusOr<v1::Job> first = client->SubmitInlineJob(clip, steps, submit);
  absl::StatusOr<v1::Job> second = client->SubmitInlineJob(clip, steps, submit);

  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_EQ(second->job_id(), first->job_id());
}

TEST_F(ClientTest, ProcessReportsProgressAndReturnsTheRetimedClip) {
  StartServer();
  ClientOptions options;
  options.slice_bytes = 8192;
  std::unique_ptr<Client> client = Connect(options);
  const core::Clip clip = BandaiWalk();
  core::RetimeStep retime;
  retime.options.output_rate = core::FrameRate{.numerator = 60, .denominator = 1};
  const core::PipelineStep steps[] = {retime};
  std::vector<double> fractions;

  absl::StatusOr<core::PipelineResult> result =
      client->Process(clip, steps, [&](double fraction, std::string_view) { fractions.push_back(fraction); });

  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_FALSE(fractions.empty());
  EXPECT_THAT(fractions, Each(AllOf(Ge(0.0), Le(1.0))));
  const core::Clip& retimed = std::get<core::Clip>(result->output);
  EXPECT_EQ(retimed.channels.size(), clip.channels.size());
  EXPECT_DOUBLE_EQ(retimed.frame_time_seconds, 1.0 / 60.0);
  ASSERT_EQ(result->reports.size(), 1u);
  EXPECT_EQ(std::get<core::RetimeReport>(result->reports[0]).output_frame_count,
            retimed.frame_count);
}

TEST_F(ClientTest, ProcessKeepsThePipelinesErrorCodeAndMessage) {
  StartServer();
  std::unique_ptr<Client> client = Connect();
  const core::PipelineStep steps[] = {core::BakeStep{}};

  absl::StatusOr<core::PipelineResult> result = client->Process(BandaiWalk(), steps);

  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(result.status().message(), HasSubstr("operation 1 (bake): needs a keyed clip"));
}

TEST_F(ClientTest, UnknownJobKeepsTheServersCodeAndMessage) {
  StartServer();
  std::unique_ptr<Client> client = Connect();

  absl::Status status = client->GetJob("no-such-job").status();
  absl::Status result = client->GetJobResult("no-such-job").status();

  EXPECT_EQ(status.code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(status.message(),
            "job \"no-such-job\" not found (unknown, deleted, or past its retention time)");
  EXPECT_EQ(result.code(), absl::StatusCode::kNotFound);
}

TEST_F(ClientTest, CancelStopsARunningJobAndItsResultIsRefused) {
  StartServer({}, /*gated=*/true);
  std::unique_ptr<Client> client = Connect();
  const core::PipelineStep steps[] = {core::ConvertStep{}};
  absl::StatusOr<v1::Job> job = client->SubmitInlineJob(BandaiWalk(), steps);
  ASSERT_TRUE(job.ok()) << job.status();
  ASSERT_TRUE(gate_.WaitArrivals(1));

  absl::StatusOr<v1::Job> cancelled = client->CancelJob(job->job_id());
  gate_.Open();
  absl::StatusOr<v1::Job> final_job = client->WatchJob(job->job_id(), {});
  absl::Status result = client->GetJobResult(job->job_id()).status();

  ASSERT_TRUE(cancelled.ok()) << cancelled.status();
  ASSERT_TRUE(final_job.ok()) << final_job.status();
  EXPECT_EQ(final_job->state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(final_job->error_code(), static_cast<int>(absl::StatusCode::kCancelled));
  EXPECT_EQ(result.code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(ClientTest, ListJobsFiltersByLabelAndDeleteRemovesAJob) {
  StartServer();
  std::unique_ptr<Client> client = Connect();
  const core::PipelineStep steps[] = {core::ConvertStep{}};
  const core::Clip clip = BandaiWalk();
  SubmitOptions shot_a;
  shot_a.labels = {{"shot", "a"}};
  SubmitOptions shot_b;
  shot_b.labels = {{"shot", "b"}};
  absl::StatusOr<v1::Job> a = client->SubmitInlineJob(clip, steps, shot_a);
  absl::StatusOr<v1::Job> b = client->SubmitInlineJob(clip, steps, shot_b);
  ASSERT_TRUE(a.ok() && b.ok());
  v1::ListJobsRequest only_a;
  (*only_a.mutable_labels())["shot"] = "a";

  // A job is deleted once it has ended: wait for it rather than for the clock.
  absl::StatusOr<v1::Job> a_ended = client->WatchJob(a->job_id(), {});
  ASSERT_TRUE(a_ended.ok()) << a_ended.status();

  absl::StatusOr<v1::ListJobsResponse> listed = client->ListJobs(only_a);
  absl::Status deleted = client->DeleteJob(a->job_id());
  absl::Status after = client->GetJob(a->job_id()).status();

  ASSERT_TRUE(listed.ok()) << listed.status();
  ASSERT_EQ(listed->jobs_size(), 1);
  EXPECT_EQ(listed->jobs(0).job_id(), a->job_id());
  EXPECT_TRUE(deleted.ok()) << deleted;
  EXPECT_EQ(after.code(), absl::StatusCode::kNotFound);
}

TEST_F(ClientTest, HealthIsServingForTheServerAndTheService) {
  StartServer();
  std::unique_ptr<Client> client = Connect();

  absl::StatusOr<HealthState> overall = client->CheckHealth("");
  absl::StatusOr<HealthState> service = client->CheckHealth(kMotionServiceName);
  absl::StatusOr<HealthState> unknown = client->CheckHealth("no.such.Service");

  ASSERT_TRUE(overall.ok()) << overall.status();
  ASSERT_TRUE(service.ok()) << service.status();
  EXPECT_EQ(*overall, HealthState::kServing);
  EXPECT_EQ(*service, HealthState::kServing);
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kNotFound);
}

TEST_F(ClientTest, ProcessRefusedByAFullQueueCarriesTheServersRetryHint) {
  server::ServerOptions options;
  options.address = "127.0.0.1:0";
  options.workers = 1;
  options.queue_capacity = 1;
  options.test_hooks.on_job_start = [this](std::string_view) { gate_.Arrive(); };
  absl::StatusOr<std::unique_ptr<server::Server>> started = server::Server::Start(options);
  ASSERT_TRUE(started.ok()) << started.status();
  server_ = *std::move(started);
  std::unique_ptr<Client> client = Connect();
  const core::Clip clip = BandaiWalk();
  const std::vector<core::PipelineStep> steps = {core::ConvertStep{}};
  ASSERT_TRUE(client->SubmitInlineJob(clip, steps).ok());  // runs, held by the gate
  ASSERT_TRUE(gate_.WaitArrivals(1));
  ASSERT_TRUE(client->SubmitInlineJob(clip, steps).ok());  // fills the queue

  const absl::StatusOr<core::PipelineResult> refused = client->Process(clip, steps);

  EXPECT_EQ(refused.status().code(), absl::StatusCode::kResourceExhausted);
  ASSERT_TRUE(wire::GetRetryAfter(refused.status()).has_value()) << refused.status();
  EXPECT_GT(wire::GetRetryAfter(refused.status())->count(), 0);
}

TEST_F(ClientTest, DrainingServerIsNotReadyAndRefusesJobsWithUnavailable) {
  StartServer({}, /*gated=*/true);
  ClientOptions options;
  options.max_attempts = 2;
  std::unique_ptr<Client> client = Connect(options);
  const core::PipelineStep steps[] = {core::ConvertStep{}};
  const core::Clip clip = BandaiWalk();
  ASSERT_TRUE(client->SubmitInlineJob(clip, steps).ok());
  ASSERT_TRUE(gate_.WaitArrivals(1));

  std::thread drain([&] { server_->Drain(); });
  absl::StatusOr<HealthState> readiness = HealthState::kServing;
  const auto deadline = std::chrono::steady_clock::now() + kWaitLimit;
  while (readiness.ok() && *readiness == HealthState::kServing &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    readiness = client->CheckHealth(kMotionServiceName);
  }
  absl::Status refused = client->SubmitInlineJob(clip, steps).status();
  gate_.Open();
  drain.join();

  ASSERT_TRUE(readiness.ok()) << readiness.status();
  EXPECT_EQ(*readiness, HealthState::kNotServing);
  EXPECT_EQ(refused.code(), absl::StatusCode::kUnavailable);
}

TEST_F(ClientTest, DeadlineEndsACallTheServerHoldsWithDeadlineExceeded) {
  StartServer({}, /*gated=*/true);
  ClientOptions options;
  options.timeout_seconds = 1.0;
  std::unique_ptr<Client> client = Connect(options);
  const core::PipelineStep steps[] = {core::ConvertStep{}};

  absl::Status status = client->Process(BandaiWalk(), steps).status();

  EXPECT_EQ(status.code(), absl::StatusCode::kDeadlineExceeded);
}

TEST_F(ClientTest, BearerTokenIsRequiredAndAccepted) {
  StartServer({"s3cret"});
  std::unique_ptr<Client> anonymous = Connect();
  ClientOptions guess;
  guess.bearer_token = "guess";
  ClientOptions secret;
  secret.bearer_token = "s3cret";
  std::unique_ptr<Client> wrong = Connect(guess);
  std::unique_ptr<Client> allowed = Connect(secret);

  absl::Status refused = anonymous->GetServerInfo().status();
  absl::Status rejected = wrong->UploadClip(BandaiWalk()).status();
  absl::StatusOr<v1::ServerInfo> info = allowed->GetServerInfo();

  EXPECT_EQ(refused.code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(refused.message(), "missing \"authorization: Bearer <token>\" metadata");
  EXPECT_EQ(rejected.code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(rejected.message(), "the bearer token is not accepted");
  ASSERT_TRUE(info.ok()) << info.status();
  EXPECT_EQ(info->version(), TEMPOKEY_VERSION);
}

TEST_F(ClientTest, UnreachableServerIsUnavailableAfterRetries) {
  ClientOptions options;
  options.target = "127.0.0.1:1";
  options.timeout_seconds = 20;
  absl::StatusOr<std::unique_ptr<Client>> client = Client::Connect(options);
  ASSERT_TRUE(client.ok());

  absl::Status info = (*client)->GetServerInfo().status();
  absl::Status upload = (*client)->UploadClip(BandaiWalk()).status();

  EXPECT_EQ(info.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(upload.code(), absl::StatusCode::kUnavailable);
}

TEST(ClientOptionsTest, ServiceConfigIsValidAndRetriesOnlyUnavailable) {
  ClientOptions options;

  const std::string json = ServiceConfigJson(options);

  EXPECT_EQ(grpc::experimental::ValidateServiceConfigJSON(json), "") << json;
  EXPECT_THAT(json, HasSubstr(R"("loadBalancingConfig":[{"round_robin":{}}])"));
  EXPECT_THAT(json, HasSubstr(R"("retryableStatusCodes":["UNAVAILABLE"])"));
  EXPECT_THAT(json, HasSubstr(R"("maxAttempts":4)"));
}

TEST(ClientOptionsTest, ServiceConfigWithoutRetriesIsValid) {
  ClientOptions options;
  options.max_attempts = 1;
  options.load_balancing_policy = "pick_first";

  const std::string json = ServiceConfigJson(options);

  EXPECT_EQ(grpc::experimental::ValidateServiceConfigJSON(json), "") << json;
  EXPECT_THAT(json, Not(HasSubstr("retryPolicy")));
}

// `options` with one change applied.
template <class Change>
ClientOptions With(Change change) {
  ClientOptions options;
  change(options);
  return options;
}

TEST(ClientOptionsTest, RefusesOptionsNoChannelCanUse) {
  EXPECT_EQ(ValidateClientOptions(With([](auto& o) { o.target = ""; })).message(),
            "the server target is empty");
  EXPECT_EQ(ValidateClientOptions(With([](auto& o) { o.target = "127.0.0.1:99999"; })).message(),
            "server 127.0.0.1:99999: port 99999 is not a TCP port (0 to 65535)");
  EXPECT_EQ(ValidateClientOptions(With([](auto& o) { o.bearer_token = "two\nlines"; })).message(),
            "the token holds a line break at byte 4; a bearer token is one line of printable "
            "ASCII (it travels in an HTTP header)");
  EXPECT_EQ(ValidateClientOptions(With([](auto& o) { o.max_attempts = 0; })).message(),
            "attempts must be in 1..10, got 0");
  EXPECT_EQ(ValidateClientOptions(With([](auto& o) { o.load_balancing_policy = "random"; })).message(),
            "load balancing policy 'random' is not round_robin or pick_first");
  EXPECT_EQ(ValidateClientOptions(With([](auto& o) {
              o.tls.enabled = true;
              o.tls.cert_chain_pem = "x";
            })).message(),
            "a client certificate needs its private key and a key its certificate");
  EXPECT_EQ(ValidateClientOptions(With([](auto& o) { o.tls.root_ca_pem = "x"; })).message(),
            "TLS settings were given but TLS is not enabled");
  EXPECT_TRUE(ValidateClientOptions(ClientOptions()).ok());
}

// The token probe of this sitting's TLS review: a fake plaintext server on another machine's
// address recorded "authorization: Bearer ..." from the CLI and the package alike. RFC 6750 5.3:
// a client MUST use TLS with bearer tokens; only this machine, TLS, or an explicit allowance
// (a network that encrypts it itself) may carry one now.
TEST(ClientOptionsTest, ABearerTokenTravelsInCleartextOnlyOnThisMachineOrWhenAllowed) {
  auto with_token = [](const std::string& target, bool tls, bool allow) {
    return With([&](ClientOptions& o) {
      o.target = target;
      o.bearer_token = "s3cret";
      o.tls.enabled = tls;
      o.allow_plaintext_token = allow;
    });
  };

  EXPECT_EQ(ValidateClientOptions(with_token("192.0.2.2:50051", false, false)).message(),
            "refusing to send the bearer token in cleartext to 192.0.2.2:50051, which is not on "
            "this machine: connect with TLS (the CLI's --tls or --ca), or allow it "
            "(--allow-plaintext-token) only where the network itself is trusted, as in a service "
            "mesh that encrypts it");
  EXPECT_EQ(ValidateClientOptions(with_token("dns:///tempokey.svc:50051", false, false)).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(ValidateClientOptions(with_token("192.0.2.2:50051", true, false)).ok());
  EXPECT_TRUE(ValidateClientOptions(with_token("192.0.2.2:50051", false, true)).ok());
  EXPECT_TRUE(ValidateClientOptions(with_token("127.0.0.1:50051", false, false)).ok());
  EXPECT_TRUE(ValidateClientOptions(with_token("unix:/run/tempokey.sock", false, false)).ok());
  EXPECT_TRUE(ValidateClientOptions(With([](ClientOptions& o) { o.target = "192.0.2.2:1"; })).ok());
}

}  // namespace
}  // namespace tempokey::client
