// SIGTERM racing a stream of submits on the real tempokey-server binary: every submit is either
// accepted (and then completes) or refused with UNAVAILABLE, the one code clients retry; none
// ends CANCELLED, whatever the interleaving of the signal and the calls.
#include <signal.h>

#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

constexpr int kClients = 4;

class DrainRaceTest : public ::testing::TestWithParam<int> {};

TEST_P(DrainRaceTest, SubmitsRacingSigtermAreAcceptedOrUnavailableNeverCancelled) {
  absl::StatusOr<std::unique_ptr<ServerProcess>> server =
      ServerProcess::Start(MakeTempDir(), {"--workers=1", "--drain_grace_seconds=30"});
  ASSERT_TRUE(server.ok()) << server.status();
  v1::SubmitJobRequest request;
  *request.mutable_inline_clip() = wire::ClipToProto(MakeClip(1, 20));
  *request.mutable_operations() = WrapOperations();

  std::mutex mu;
  std::map<grpc::StatusCode, int> codes;
  std::map<grpc::StatusCode, std::string> messages;
  std::atomic<int> accepted{0};
  std::atomic<bool> signalled{false};
  std::vector<std::thread> clients;
  for (int i = 0; i < kClients; ++i) {
    clients.emplace_back([&, i] {
      // Each client has its own connection (a distinct channel argument stops gRPC sharing one).
      grpc::ChannelArguments args;
      args.SetInt("tempokey.test.client", i);
      auto stub = v1::MotionService::NewStub(grpc::CreateCustomChannel(
          (*server)->target(), grpc::InsecureChannelCredentials(), args));
      for (int n = 0;; ++n) {
        grpc::ClientContext context;
        SetDeadline(context);
        v1::Job job;
        const grpc::Status status = stub->SubmitJob(&context, request, &job);
        {
          std::lock_guard lock(mu);
          ++codes[status.error_code()];
          messages[status.error_code()] = status.error_message();
        }
        if (status.ok() && accepted.fetch_add(1) == 20 && !signalled.exchange(true)) {
          (*server)->Signal(SIGTERM);
        }
        // Refusals while draining keep the client going; once the server is gone (or any other
        // code), the race is over for this client.
        if (!status.ok() && (signalled.load() || status.error_code() != grpc::StatusCode::UNAVAILABLE) &&
            status.error_message().find("shutting down") == std::string::npos) {
          break;
        }
      }
    });
  }
  for (std::thread& client : clients) client.join();
  const std::optional<int> exit_code = (*server)->WaitExit(std::chrono::seconds(120));

  RecordProperty("accepted", codes[grpc::StatusCode::OK]);
  RecordProperty("unavailable", codes[grpc::StatusCode::UNAVAILABLE]);

  EXPECT_TRUE(signalled.load());
  EXPECT_EQ(exit_code, 0) << (*server)->log();
  // Every client ended on a refusal, and every refusal was UNAVAILABLE.
  EXPECT_GE(codes[grpc::StatusCode::UNAVAILABLE], kClients);
  for (const auto& [code, count] : codes) {
    EXPECT_TRUE(code == grpc::StatusCode::OK || code == grpc::StatusCode::UNAVAILABLE)
        << count << " submits ended with code " << code << ": " << messages[code];
  }
}

// A few rounds: each is one race of the signal against four streams of submits.
INSTANTIATE_TEST_SUITE_P(Rounds, DrainRaceTest, ::testing::Range(0, 3));

}  // namespace
}  // namespace tempokey::testing
