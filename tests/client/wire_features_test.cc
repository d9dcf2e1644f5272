// The client speaks the wire features a server advertises (ServerInfo.features) and nothing
// newer: against a server of the first v1, which knows neither SampleSlices nor the features
// list, uploads go as single slices; against one that lists "sample_slices", as batches. The
// "first v1" server here is a small stand-in: that older build cannot run beside this one.
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "client/client.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "tests/server/test_clips.h"

namespace tempokey::client {
namespace {

// Records which kind of part every upload message was; advertises `features`.
class RecordingService final : public v1::MotionService::Service {
 public:
  explicit RecordingService(std::vector<std::string> features) : features_(std::move(features)) {}

  grpc::Status GetServerInfo(grpc::ServerContext*, const v1::GetServerInfoRequest*,
                             v1::ServerInfo* info) override {
    for (const std::string& feature : features_) info->add_features(feature);
    return grpc::Status::OK;
  }

  grpc::Status UploadClip(grpc::ServerContext*, grpc::ServerReader<v1::UploadClipRequest>* reader,
                          v1::UploadClipResponse* response) override {
    v1::UploadClipRequest request;
    while (reader->Read(&request)) {
      std::lock_guard lock(mu_);
      parts_.push_back(request.part_case());
    }
    response->set_clip_id("sha256:recorded");
    return grpc::Status::OK;
  }

  std::vector<v1::UploadClipRequest::PartCase> parts() {
    std::lock_guard lock(mu_);
    return parts_;
  }

 private:
  std::vector<std::string> features_;
  std::mutex mu_;
  std::vector<v1::UploadClipRequest::PartCase> parts_;
};

// Uploads a 15-channel clip to a RecordingService advertising `features`; the parts it saw.
std::vector<v1::UploadClipRequest::PartCase> UploadParts(std::vector<std::string> features) {
  RecordingService service(std::move(features));
  grpc::ServerBuilder builder;
  builder.RegisterService(&service);
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  Client client(server->InProcessChannel(grpc::ChannelArguments()), ClientOptions());

  absl::StatusOr<v1::UploadClipResponse> uploaded =
      client.UploadClip(testing::MakeClip(4, 100));

  EXPECT_TRUE(uploaded.ok()) << uploaded.status();
  server->Shutdown();
  return service.parts();
}

TEST(WireFeaturesTest, FirstV1ServerGetsOneSliceOfOneChannelPerMessage) {
  const std::vector<v1::UploadClipRequest::PartCase> parts = UploadParts({});

  ASSERT_EQ(parts.size(), 1u + 15u);  // the header, then each channel alone
  EXPECT_EQ(parts[0], v1::UploadClipRequest::kHeader);
  for (std::size_t i = 1; i < parts.size(); ++i) {
    EXPECT_EQ(parts[i], v1::UploadClipRequest::kSamples) << "message " << i;
  }
}

TEST(WireFeaturesTest, ServerWithSampleSlicesGetsTheChannelsInOneMessage) {
  const std::vector<v1::UploadClipRequest::PartCase> parts =
      UploadParts({"sample_slices", "batch_parts"});

  ASSERT_EQ(parts.size(), 2u);  // 1500 samples fit one 1 MiB batch
  EXPECT_EQ(parts[0], v1::UploadClipRequest::kHeader);
  EXPECT_EQ(parts[1], v1::UploadClipRequest::kSampleSlices);
}

}  // namespace
}  // namespace tempokey::client
