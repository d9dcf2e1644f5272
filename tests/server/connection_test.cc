// Connections on a real server: a call in flight when its connection reaches the maximum age
// runs to its end, and a client's keepalive pings at the allowed interval keep a quiet stream
// open. Each waits on a held job while the connection ages or pings; the pauses only give those
// time to happen (on a machine too loaded to age or ping in time, the tests pass without having
// shown anything, never fail).
#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "gmock/gmock.h"
#include "grpcpp/create_channel.h"
#include "grpcpp/support/channel_arguments.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "tests/server/server_test_util.h"
#include "tests/server/test_clips.h"

namespace tempokey::testing {
namespace {

// The age grace used to be the drain grace: at --drain_grace_seconds=0 a Process call in flight
// ended UNAVAILABLE as soon as its connection aged out (1.96 s in a probe with a 2 s age).
TEST(ConnectionTest, ACallInFlightWhenItsConnectionAgesOutRunsToItsEnd) {
  server::ServerOptions options = TestServerOptions();
  options.workers = 1;
  options.max_connection_age = std::chrono::seconds(1);
  options.drain_grace = std::chrono::seconds(0);
  GatedServer gated(std::move(options));
  ASSERT_NE(gated.server, nullptr);
  ProcessOutcome outcome;
  std::thread caller(
      [&] { outcome = RunProcess(*gated.stub, MakeClip(2, 60), WrapOperations()); });
  ASSERT_TRUE(gated.gate->WaitArrivals(1));  // the call's pipeline is held
  std::this_thread::sleep_for(std::chrono::seconds(3));  // the age (1 s, jittered) passes
  gated.gate->Open();
  caller.join();

  TEMPOKEY_ASSERT_GRPC_OK(outcome.status);
  EXPECT_FALSE(outcome.ResultParts().empty());
}

// gRPC's own policy allows a ping every 5 minutes and ends the connection after two pings sooner
// ("too_many_pings"): a client keeping its connection alive every 30 s lost its quiet WatchJob.
// The server allows min_client_ping_interval (10 s by default; 250 ms here, so that only pings
// bunched by a stall of 1.75 s could count against the client's, sent every 2 s).
TEST(ConnectionTest, KeepalivePingsAtTheAllowedIntervalKeepAQuietWatchOpen) {
  server::ServerOptions options = TestServerOptions();
  options.workers = 1;
  options.min_client_ping_interval = std::chrono::milliseconds(250);
  GatedServer gated(std::move(options));
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(2, 60)).response.clip_id();
  const JobOutcome job = Submit(*gated.stub, SubmitRequest(clip_id));
  TEMPOKEY_ASSERT_GRPC_OK(job.status);
  ASSERT_TRUE(gated.gate->WaitArrivals(1));  // running, held: the watch stays quiet

  grpc::ChannelArguments pinging;
  pinging.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 2000);
  pinging.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 20000);
  pinging.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  pinging.SetInt(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);  // keep pinging while it is quiet
  auto stub = v1::MotionService::NewStub(grpc::CreateCustomChannel(
      gated.server->target(), grpc::InsecureChannelCredentials(), pinging));
  WatchOutcome watch;
  std::thread watcher([&] { watch = WatchJob(*stub, job.job.job_id()); });
  std::this_thread::sleep_for(std::chrono::seconds(9));  // four pings: past three strikes
  gated.gate->Open();
  watcher.join();

  TEMPOKEY_ASSERT_GRPC_OK(watch.status);
  ASSERT_FALSE(watch.updates.empty());
  EXPECT_EQ(watch.updates.back().state(), v1::JOB_STATE_SUCCEEDED);
}

}  // namespace
}  // namespace tempokey::testing
