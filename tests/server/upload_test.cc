// UploadClip, GetServerInfo and health over a real server on 127.0.0.1:0 with real stubs.
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_digest.h"
#include "server/server.h"
#include "server/service_context.h"
#include "tempokey/core/io/bvh.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::HasSubstr;
using ::testing::MatchesRegex;
using ::testing::SizeIs;

constexpr char kDanceClip[] = "bandai/dataset-1_dance-short_normal_001.bvh";

class UploadTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server::ServerOptions options = TestServerOptions();
    options.max_clip_samples = 4'000'000;
    server_ = StartServer(options);
    ASSERT_NE(server_, nullptr);
    channel_ = Connect(server_->target());
    stub_ = v1::MotionService::NewStub(channel_);
  }

  // The server still answers after whatever the test did to it.
  void ExpectServing() {
    UploadOutcome outcome = UploadClip(*stub_, MakeClip(1, 10, /*seed=*/42.0));
    EXPECT_TRUE(outcome.status.ok()) << outcome.status.error_message();
  }

  std::unique_ptr<server::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(UploadTest, ServerInfoReportsLimitsAndOperations) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ServerInfo info;

  TEMPOKEY_ASSERT_GRPC_OK(stub_->GetServerInfo(&context, v1::GetServerInfoRequest(), &info));

  EXPECT_EQ(info.version(), TEMPOKEY_VERSION);
  EXPECT_EQ(info.max_clip_samples(), 4'000'000);
  EXPECT_EQ(info.max_message_bytes(), 64 << 20);
  EXPECT_EQ(info.queue_capacity(), 16);
  EXPECT_EQ(info.worker_count(), 2);
  EXPECT_THAT(info.operations(), Contains("convert"));
}

TEST_F(UploadTest, OperationsOfferedAreExactlyThoseCoreImplements) {
  // Cross-check the probe: every operation offered runs, every one missing answers UNIMPLEMENTED.
  const core::Clip clip = MakeClip(1, 32);
  core::ReduceStep paper;
  paper.options.method = core::ReduceMethod::kPaper;
  core::ReduceStep noise;
  noise.options.method = core::ReduceMethod::kNoise;
  const std::vector<std::pair<std::string, std::vector<core::PipelineStep>>> probes = {
      {"convert", {core::ConvertStep{}}},
      {"retime", {core::RetimeStep{}}},
      {"reduce/tolerance", {core::ReduceStep{}}},
      {"reduce/paper", {paper}},
      {"reduce/noise", {noise}},
  };
  const std::vector<std::string>& offered = server_->operations();

  for (const auto& [name, steps] : probes) {
    absl::StatusOr<core::PipelineResult> result = core::RunPipeline(clip, steps);
    const bool implemented =
        result.ok() || result.status().code() != absl::StatusCode::kUnimplemented;

    EXPECT_EQ(std::find(offered.begin(), offered.end(), name) != offered.end(), implemented)
        << name << ": " << result.status();
  }
}

TEST_F(UploadTest, HealthIsServingForLivenessAndReadiness) {
  absl::StatusOr<int> live = CheckHealth(channel_, "");
  absl::StatusOr<int> ready = CheckHealth(channel_, "tempokey.v1.MotionService");

  ASSERT_TRUE(live.ok()) << live.status();
  ASSERT_TRUE(ready.ok()) << ready.status();
  EXPECT_EQ(*live, 1);  // SERVING
  EXPECT_EQ(*ready, 1);
}

TEST_F(UploadTest, RealClipGetsAContentIdAndRepeatedUploadIsFree) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(SharedBvh(kDanceClip));
  ASSERT_TRUE(clip.ok()) << clip.status();

  UploadOutcome first = UploadClip(*stub_, *clip, 64 << 10);
  UploadOutcome again = UploadMessages(*stub_, UploadRequests(*clip, 8 << 10, /*reverse=*/true));

  TEMPOKEY_ASSERT_GRPC_OK(first.status);
  TEMPOKEY_ASSERT_GRPC_OK(again.status);
  EXPECT_THAT(first.response.clip_id(), MatchesRegex("sha256:[0-9a-f]{64}"));
  EXPECT_EQ(first.response.frame_count(), clip->frame_count);
  EXPECT_EQ(first.response.channel_count(), static_cast<int>(clip->channels.size()));
  EXPECT_EQ(first.response.sample_count(), clip->sample_count());
  EXPECT_FALSE(first.response.already_stored());
  EXPECT_EQ(again.response.clip_id(), first.response.clip_id());
  EXPECT_TRUE(again.response.already_stored());
}

TEST_F(UploadTest, ClipLargerThanFourMiBUploadsInChunks) {
  const core::Clip clip = MakeClip(44, 4000);  // 135 channels x 4000 frames = 4.3 MB of samples
  ASSERT_GT(clip.sample_count() * 8, 4 << 20);

  UploadOutcome outcome = UploadClip(*stub_, clip, 256 << 10);
  UploadOutcome again = UploadClip(*stub_, clip, 1 << 20);

  TEMPOKEY_ASSERT_GRPC_OK(outcome.status);
  EXPECT_EQ(outcome.response.sample_count(), 135 * 4000);
  EXPECT_EQ(again.response.clip_id(), outcome.response.clip_id());
  EXPECT_TRUE(again.response.already_stored());
}

// Past its first MiB an upload's samples are hashed on a thread of their own while the next
// messages are read (server/background_digest.h): the id is still the clip's content id
// computed here in one piece, whether the slices come in order or backwards.
TEST_F(UploadTest, LargeUploadsIdIsTheContentIdOfTheClipInEitherOrder) {
  const core::Clip clip = MakeClip(44, 4000);
  const std::string expected = wire::ClipContentId(clip);

  UploadOutcome forwards = UploadClip(*stub_, clip, 256 << 10);
  // Hashed again (a clip is looked up by the id its samples give), then found stored.
  UploadOutcome backwards =
      UploadMessages(*stub_, UploadRequests(clip, 256 << 10, /*reverse=*/true));

  TEMPOKEY_ASSERT_GRPC_OK(forwards.status);
  TEMPOKEY_ASSERT_GRPC_OK(backwards.status);
  EXPECT_EQ(forwards.response.clip_id(), expected);
  EXPECT_EQ(backwards.response.clip_id(), expected);
  EXPECT_TRUE(backwards.response.already_stored());
}

// Refused or cancelled past its first MiB, while its samples are being hashed on the digest's
// thread, an upload ends as before, and the next one is hashed and stored right.
TEST_F(UploadTest, LargeUploadEndedMidwayWhileHashingLeavesTheServerServing) {
  const core::Clip clip = MakeClip(44, 4000);
  std::vector<v1::UploadClipRequest> refused = UploadRequests(clip, 256 << 10);
  ASSERT_GT(refused.size(), 12u);
  refused.insert(refused.begin() + 12, refused[11]);  // the same slice twice: an overlap
  grpc::ClientContext context;
  SetDeadline(context);
  v1::UploadClipResponse response;
  auto cancelled = stub_->UploadClip(&context, &response);
  const std::vector<v1::UploadClipRequest> requests = UploadRequests(clip, 256 << 10);
  for (std::size_t i = 0; i < 12; ++i) ASSERT_TRUE(cancelled->Write(requests[i]));

  const UploadOutcome refusal = UploadMessages(*stub_, refused);
  context.TryCancel();
  const grpc::Status cancel = cancelled->Finish();
  const UploadOutcome next = UploadClip(*stub_, clip, 1 << 20);

  EXPECT_EQ(refusal.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(cancel.error_code(), grpc::StatusCode::CANCELLED);
  TEMPOKEY_ASSERT_GRPC_OK(next.status);
  EXPECT_EQ(next.response.clip_id(), wire::ClipContentId(clip));
  EXPECT_FALSE(next.response.already_stored());
}

TEST_F(UploadTest, RealClipTiledPastFourMiBUploads) {
  absl::StatusOr<core::Clip> dance = core::ReadBvhFile(SharedBvh(kDanceClip));
  ASSERT_TRUE(dance.ok()) << dance.status();
  core::Clip tiled = *dance;  // the real motion three times over: 1901 x 3 frames x 132 channels
  for (core::Channel& channel : tiled.channels) {
    const std::vector<double> once = channel.samples;
    for (int copy = 1; copy < 3; ++copy) channel.samples.insert(channel.samples.end(), once.begin(), once.end());
  }
  tiled.frame_count *= 3;
  ASSERT_GT(tiled.sample_count() * 8, 4 << 20);

  UploadOutcome outcome = UploadClip(*stub_, tiled, 1 << 20);

  TEMPOKEY_ASSERT_GRPC_OK(outcome.status);
  EXPECT_EQ(outcome.response.frame_count(), dance->frame_count * 3);
  EXPECT_FALSE(outcome.response.already_stored());
}

TEST_F(UploadTest, OneChangedSampleChangesTheId) {
  core::Clip clip = MakeClip(2, 50);
  UploadOutcome a = UploadClip(*stub_, clip);
  clip.channels[5].samples[33] += 1e-9;

  UploadOutcome b = UploadClip(*stub_, clip);

  TEMPOKEY_ASSERT_GRPC_OK(a.status);
  TEMPOKEY_ASSERT_GRPC_OK(b.status);
  EXPECT_NE(a.response.clip_id(), b.response.clip_id());
  EXPECT_FALSE(b.response.already_stored());
}

// ---- malformed uploads --------------------------------------------------------------------------

struct MalformedCase {
  const char* name;
  // Edits the messages of a valid upload of MakeClip(2, 100) sent in 50-sample slices.
  std::function<void(std::vector<v1::UploadClipRequest>&)> edit;
  grpc::StatusCode code;
  const char* message;
};

class MalformedUploadTest : public UploadTest,
                            public ::testing::WithParamInterface<MalformedCase> {};

TEST_P(MalformedUploadTest, IsRefusedPreciselyAndTheServerKeepsServing) {
  std::vector<v1::UploadClipRequest> requests = UploadRequests(MakeClip(2, 100), 8 * 50);
  GetParam().edit(requests);

  UploadOutcome outcome = UploadMessages(*stub_, requests);

  EXPECT_THAT(outcome.status, GrpcStatusIs(GetParam().code, HasSubstr(GetParam().message)));
  ExpectServing();
}

INSTANTIATE_TEST_SUITE_P(
    Table, MalformedUploadTest,
    ::testing::Values(
        MalformedCase{"NanSample",
                      [](auto& r) { r[9].mutable_samples()->mutable_samples()->Set(17, std::nan("")); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "samples message 9: channel 4 (joint0.Xrotation): sample at frame 17 is NaN"},
        MalformedCase{"Overlap",
                      [](auto& r) { r[4].mutable_samples()->set_first_frame(30); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "samples message 4: channel 1 (joint0.Yposition): frames 30..79 overlap "
                      "frames 30..49 already received"},
        MalformedCase{"MissingFrames", [](auto& r) { r.erase(r.begin() + 6); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "channel 2 (joint0.Zposition): frames 50..99 never arrived"},
        MalformedCase{"BadChannelIndex",
                      [](auto& r) { r[2].mutable_samples()->set_channel_index(9); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "samples message 2: channel index 9 out of range, the clip has 9 channels"},
        MalformedCase{"SamplesBeforeHeader", [](auto& r) { std::swap(r[0], r[1]); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "samples message 1 arrived before the clip header"},
        MalformedCase{"SecondHeader", [](auto& r) { r.push_back(r[0]); },
                      grpc::StatusCode::INVALID_ARGUMENT, "a second clip header arrived"},
        MalformedCase{"HeaderOverLimits",
                      [](auto& r) { r[0].mutable_header()->set_frame_count(1'000'000); },
                      grpc::StatusCode::RESOURCE_EXHAUSTED,
                      "clip header: clip has 1000000 frames x 9 channels, over the limit of "
                      "4000000 samples"},
        MalformedCase{"NoHeaderAtAll", [](auto& r) { r.clear(); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "the upload ended before a clip header arrived"},
        MalformedCase{"EmptyMessage", [](auto& r) { r[3].Clear(); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "upload message 4 has neither header nor samples"},
        // A batch of no slices resets the idle timeout like any message: a stream of them
        // would hold the call (and a stream slot) for ever without completing the clip.
        MalformedCase{"SampleSlicesWithNoSlice",
                      [](auto& r) { r[3].Clear(); r[3].mutable_sample_slices(); },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "upload message 4: sample_slices carries no slices"},
        MalformedCase{"UnspecifiedKind",
                      [](auto& r) {
                        r[0].mutable_header()->mutable_channels(1)->set_kind(
                            v1::CHANNEL_KIND_UNSPECIFIED);
                      },
                      grpc::StatusCode::INVALID_ARGUMENT,
                      "header.channels[1]: kind is CHANNEL_KIND_UNSPECIFIED"}),
    [](const ::testing::TestParamInfo<MalformedCase>& p) { return p.param.name; });

TEST(UploadLimitTest, OversizedMessageIsRefusedAndTheServerKeepsServing) {
  server::ServerOptions options = TestServerOptions();
  options.max_message_bytes = 1 << 20;
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const core::Clip clip = MakeClip(1, 300'000);  // one channel slice of 2.4 MB

  UploadOutcome big = UploadClip(*stub, clip, 4 << 20);
  UploadOutcome sliced = UploadClip(*stub, clip, 512 << 10);

  EXPECT_THAT(big.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                       HasSubstr("larger than max")));
  // Sent again, the same message is refused again: no retry hint says otherwise.
  EXPECT_EQ(big.retry_after_ms, "");
  TEMPOKEY_ASSERT_GRPC_OK(sliced.status);
}

TEST(UploadLimitTest, StreamsBeyondTheLimitAreRefusedWithARetryHint) {
  server::ServerOptions options = TestServerOptions();
  options.max_concurrent_streams = 1;
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  grpc::ClientContext open_context;
  SetDeadline(open_context);
  v1::UploadClipResponse open_response;
  auto open = stub->UploadClip(&open_context, &open_response);
  v1::UploadClipRequest header;
  *header.mutable_header() = wire::ClipHeaderToProto(MakeClip(1, 10));
  ASSERT_TRUE(open->Write(header));
  // Write() returning means sent, not registered: wait until the server counts the stream.
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  while (server->open_streams() < 1 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_EQ(server->open_streams(), 1);

  UploadOutcome refused;
  for (int attempt = 0; attempt < 100; ++attempt) {
    refused = UploadClip(*stub, MakeClip(1, 10));
    if (!refused.status.ok()) break;
  }
  const WatchOutcome watch = WatchJob(*stub, "job-any");
  open->WritesDone();
  const grpc::Status first = open->Finish();

  EXPECT_THAT(refused.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                           HasSubstr("too many streaming calls open (limit 1)")));
  // A slot frees when another call ends: the refusal says to retry, and when.
  EXPECT_EQ(refused.retry_after_ms, std::to_string(server::kStreamRetryAfter.count()));
  // A server-streaming call too (its refusal is finished by another path).
  EXPECT_THAT(watch.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                         HasSubstr("too many streaming calls open (limit 1)")));
  EXPECT_EQ(watch.retry_after_ms, std::to_string(server::kStreamRetryAfter.count()));
  EXPECT_THAT(first, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("never arrived")));
}

}  // namespace
}  // namespace tempokey::testing
