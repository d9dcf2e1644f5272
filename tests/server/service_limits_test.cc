// Admission, size limits and metrics of a real server on 127.0.0.1:0: a full queue answers
// RESOURCE_EXHAUSTED with a retry hint and the server keeps serving; a 50 MB clip goes up and its
// result comes back with gRPC's default client limits; the Prometheus port is scraped over HTTP.
#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_digest.h"
#include "proto/retry_hint.h"
#include "server/job_manager.h"
#include "server/server.h"
#include "server/server_options.h"
#include "tests/server/http_util.h"
#include "tests/server/server_test_util.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

// ---- queue full ---------------------------------------------------------------------------------

TEST(QueueFullTest, SubmitBeyondTheQueueIsResourceExhaustedWithARetryHintAndServingGoesOn) {
  server::ServerOptions options = TestServerOptions();
  options.workers = 1;
  options.queue_capacity = 3;
  GatedServer gated(options);
  ASSERT_NE(gated.server, nullptr);
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 40)).response.clip_id();
  std::vector<std::string> accepted;
  const JobOutcome running = Submit(*gated.stub, SubmitRequest(clip_id));
  TEMPOKEY_ASSERT_GRPC_OK(running.status);
  accepted.push_back(running.job.job_id());
  ASSERT_TRUE(gated.gate->WaitArrivals(1));  // the one worker holds the first job
  for (int i = 0; i < 3; ++i) {
    const JobOutcome queued = Submit(*gated.stub, SubmitRequest(clip_id));
    TEMPOKEY_ASSERT_GRPC_OK(queued.status);
    accepted.push_back(queued.job.job_id());
  }

  grpc::ClientContext context;
  SetDeadline(context);
  v1::Job refused_job;
  const grpc::Status refused =
      gated.stub->SubmitJob(&context, SubmitRequest(clip_id), &refused_job);
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto hint = trailers.find(wire::kRetryAfterMetadataKey);
  gated.gate->Open();
  std::vector<v1::JobState> final_states;
  for (const std::string& id : accepted) final_states.push_back(WaitForJob(*gated.stub, id).state());
  const JobOutcome after = Submit(*gated.stub, SubmitRequest(clip_id));
  const v1::Job after_done = WaitForJob(*gated.stub, after.job.job_id());

  EXPECT_THAT(refused, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                    HasSubstr("queue is full")));
  ASSERT_NE(hint, trailers.end());
  int hint_ms = 0;
  ASSERT_TRUE(absl::SimpleAtoi(std::string(hint->second.data(), hint->second.size()), &hint_ms));
  EXPECT_GT(hint_ms, 0);
  EXPECT_THAT(final_states, ::testing::Each(v1::JOB_STATE_SUCCEEDED));
  TEMPOKEY_ASSERT_GRPC_OK(after.status);
  EXPECT_EQ(after_done.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(gated.server->jobs().job_count(), 5);  // the refused submit left nothing behind
}

// ---- a 50 MB clip -------------------------------------------------------------------------------

TEST(LargeClipTest, FiftyMegabyteClipUploadsAndItsResultDownloadsWithDefaultClientLimits) {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));  // default 4 MiB receive
  const core::Clip clip = MakeClip(44, 48'000);  // 135 channels x 48000 frames = 51.8 MB
  ASSERT_GT(clip.sample_count() * 8, 50'000'000);

  const UploadOutcome upload = UploadClip(*stub, clip);
  TEMPOKEY_ASSERT_GRPC_OK(upload.status);
  const JobOutcome submitted = Submit(*stub, SubmitRequest(upload.response.clip_id()));
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  const v1::Job done = WaitForJob(*stub, submitted.job.job_id());
  const ResultOutcome result = GetResult(*stub, submitted.job.job_id());
  TEMPOKEY_ASSERT_GRPC_OK(result.status);
  absl::StatusOr<core::Clip> rebuilt = AssembleClipResult(result.parts);

  EXPECT_EQ(done.state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_LT(result.largest_part_bytes, 4 << 20);
  EXPECT_GT(result.parts.size(), 50u);
  ASSERT_TRUE(rebuilt.ok()) << rebuilt.status();
  const core::Clip expected = WrappedCopy(clip);
  ASSERT_EQ(rebuilt->channels.size(), expected.channels.size());
  for (std::size_t c = 0; c < expected.channels.size(); ++c) {
    ASSERT_EQ(rebuilt->channels[c].samples, expected.channels[c].samples) << "channel " << c;
  }
}

// ---- output limits -------------------------------------------------------------------------------

TEST(OutputLimitTest, RetimeOrBakeBeyondTheServersClipLimitIsRefusedBeforeQueueing) {
  server::ServerOptions options = TestServerOptions();
  options.max_clip_samples = 100'000;
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const core::Clip clip = MakeClip(1, 1000);  // 6 channels x 1000 frames: well within the limit
  const std::string clip_id = UploadClip(*stub, clip).response.clip_id();
  google::protobuf::RepeatedPtrField<v1::Operation> stretch;
  v1::RetimeOperation* retime = stretch.Add()->mutable_retime();
  retime->set_fit_frames(20'000);  // 120 000 samples out of 6 000 in
  retime->set_min_speed(0.001);
  google::protobuf::RepeatedPtrField<v1::Operation> fine_bake;
  fine_bake.Add()->mutable_reduce()->set_method(v1::REDUCE_METHOD_TOLERANCE);
  v1::BakeOperation* bake = fine_bake.Add()->mutable_bake();
  bake->set_rate_numerator(2400);  // 20x the clip's 120 Hz
  bake->set_rate_denominator(1);

  const JobOutcome refused = Submit(*stub, SubmitRequest(clip_id, stretch));
  const JobOutcome baked = Submit(*stub, SubmitRequest(clip_id, fine_bake));

  EXPECT_THAT(refused.status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           "operation 1 (retime): the retimed clip would have 20000 frames x 6 "
                           "channels, over the limit of 100000 samples"));
  // A bake's length follows from the reduced clip's layout and the rate: refused up front too.
  EXPECT_THAT(baked.status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           HasSubstr("operation 2 (bake): bake at 0.000416667 s per frame gives "
                                     "19981 frames x 6 channels, over the limit of 100000 "
                                     "samples")));
}

// ---- metrics ------------------------------------------------------------------------------------

TEST(MetricsTest, ScrapeShowsJobsBytesAndLatencyMoving) {
  server::ServerOptions options = TestServerOptions();
  options.metrics_address = "127.0.0.1:0";
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  ASSERT_GT(server->metrics_port(), 0);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const std::optional<std::string> before = HttpGet(server->metrics_port(), "/metrics");
  ASSERT_TRUE(before.has_value());

  const std::string clip_id = UploadClip(*stub, MakeClip(2, 100)).response.clip_id();
  for (int i = 0; i < 3; ++i) {
    const JobOutcome job = Submit(*stub, SubmitRequest(clip_id));
    TEMPOKEY_ASSERT_GRPC_OK(job.status);
    // The server counts a job's end before anyone can see it (JobManager reports the end under
    // its lock), so once the watch has seen the terminal state the scrape below includes it.
    WaitForJob(*stub, job.job.job_id());
    TEMPOKEY_ASSERT_GRPC_OK(GetResult(*stub, job.job.job_id()).status);
  }
  const std::optional<std::string> after = HttpGet(server->metrics_port(), "/metrics");
  ASSERT_TRUE(after.has_value());
  const auto was = ParseSamples(*before);
  const auto now = ParseSamples(*after);

  EXPECT_THAT(*after, HasSubstr("HTTP/1.1 200"));
  EXPECT_THAT(*after, HasSubstr("# TYPE tempokey_jobs_total counter"));
  EXPECT_THAT(*after, HasSubstr("# TYPE tempokey_job_latency_seconds histogram"));
  const std::string succeeded = R"(tempokey_jobs_total{kind="job",outcome="succeeded"})";
  EXPECT_EQ(Sample(now, succeeded) - Sample(was, succeeded), 3.0);
  const std::string latency_count = R"(tempokey_job_latency_seconds_count{kind="job"})";
  EXPECT_EQ(Sample(now, latency_count) - Sample(was, latency_count), 3.0);
  const std::string bytes_in = R"(tempokey_bytes_total{direction="in"})";
  const std::string bytes_out = R"(tempokey_bytes_total{direction="out"})";
  constexpr double kClipSampleBytes = 100 * 9 * 8;  // 100 frames x 9 channels of doubles
  EXPECT_GE(Sample(now, bytes_in) - Sample(was, bytes_in), kClipSampleBytes);
  EXPECT_GE(Sample(now, bytes_out) - Sample(was, bytes_out), 3 * kClipSampleBytes);
  // The gauges, not their momentary values: a worker counts itself idle only after its job's end
  // is visible, so right after the last watch one may still read as running.
  EXPECT_THAT(*after, HasSubstr("\ntempokey_queue_depth "));
  EXPECT_THAT(*after, HasSubstr("\ntempokey_running_jobs "));
  EXPECT_LE(Sample(now, "tempokey_running_jobs"), static_cast<double>(TestServerOptions().workers));
  EXPECT_EQ(Sample(now, "tempokey_stored_jobs"), 3.0);
  EXPECT_EQ(Sample(now, "tempokey_stored_clips"), 1.0);
}

// An upload past its first MiB hashes its content id on a thread of its own
// (server/background_digest.h): the gauge shows it while the stream is open and not once it has
// ended; an upload open under its first MiB shows none. Scrapes are polled (bounded, within the
// calls' deadline) because the server reads the streams on its own threads.
TEST(MetricsTest, ScrapeShowsAnUploadHashingOnAThreadOfItsOwnUntilItEnds) {
  server::ServerOptions options = TestServerOptions();
  options.metrics_address = "127.0.0.1:0";
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  auto scrape = [&](const std::string& name) -> std::optional<double> {
    const std::optional<std::string> text = HttpGet(server->metrics_port(), "/metrics");
    if (!text.has_value()) return std::nullopt;
    return Sample(ParseSamples(*text), name);
  };
  const std::string threads = "tempokey_upload_digest_threads";
  const std::string bytes_in = R"(tempokey_bytes_total{direction="in"})";
  constexpr auto kPollLimit = std::chrono::seconds(30);
  auto poll_until = [&](const std::string& name, auto holds) {
    const auto deadline = std::chrono::steady_clock::now() + kPollLimit;
    std::optional<double> seen = scrape(name);
    while (!(seen.has_value() && holds(*seen)) && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      seen = scrape(name);
    }
    return seen;
  };
  auto equals = [](double wanted) { return [wanted](double seen) { return seen == wanted; }; };
  auto bytes_of = [](const std::vector<v1::UploadClipRequest>& requests, std::size_t count) {
    double bytes = 0.0;
    for (std::size_t i = 0; i < count; ++i) {
      bytes += static_cast<double>(requests[i].ByteSizeLong());
    }
    return bytes;
  };
  const std::optional<double> before = scrape(threads);

  // A small upload held open, every message but its last read by the server: no thread.
  const core::Clip small_clip = MakeClip(1, 1000);  // 6 channels x 1000 frames: 48 KB
  const std::vector<v1::UploadClipRequest> small = UploadRequests(small_clip, 256 << 10);
  ASSERT_GT(small.size(), 2u);
  const double bytes_before = scrape(bytes_in).value_or(-1.0);
  grpc::ClientContext small_context;
  SetDeadline(small_context);
  v1::UploadClipResponse small_response;
  auto small_upload = stub->UploadClip(&small_context, &small_response);
  for (std::size_t i = 0; i + 1 < small.size(); ++i) ASSERT_TRUE(small_upload->Write(small[i]));
  const double small_bytes = bytes_of(small, small.size() - 1);
  const std::optional<double> read =
      poll_until(bytes_in, [&](double seen) { return seen >= bytes_before + small_bytes; });
  const std::optional<double> while_small_open = scrape(threads);
  ASSERT_TRUE(small_upload->Write(small.back()));
  small_upload->WritesDone();
  const grpc::Status small_status = small_upload->Finish();

  // A large one, held open past its first MiB.
  const core::Clip clip = MakeClip(44, 4000);  // 135 channels x 4000 frames: 4.3 MB of samples
  const std::vector<v1::UploadClipRequest> requests = UploadRequests(clip, 256 << 10);
  constexpr std::size_t kMessagesPastTheFirstMiB = 64;  // the header, then a channel each
  ASSERT_GT(requests.size(), kMessagesPastTheFirstMiB);
  grpc::ClientContext context;
  SetDeadline(context);
  v1::UploadClipResponse response;
  auto upload = stub->UploadClip(&context, &response);
  for (std::size_t i = 0; i < kMessagesPastTheFirstMiB; ++i) {
    ASSERT_TRUE(upload->Write(requests[i]));
  }
  const std::optional<double> while_open = poll_until(threads, equals(1.0));
  for (std::size_t i = kMessagesPastTheFirstMiB; i < requests.size(); ++i) {
    ASSERT_TRUE(upload->Write(requests[i]));
  }
  // The thread is claimed until the upload's digest goes, after its last message.
  const std::optional<double> before_the_end = scrape(threads);
  upload->WritesDone();
  const grpc::Status status = upload->Finish();
  const std::optional<double> after = poll_until(threads, equals(0.0));
  const std::optional<double> most = scrape("tempokey_upload_digest_threads_max");

  EXPECT_EQ(before, 0.0);
  ASSERT_TRUE(read.has_value());
  EXPECT_GE(*read, bytes_before + small_bytes);
  EXPECT_EQ(while_small_open, 0.0);
  TEMPOKEY_ASSERT_GRPC_OK(small_status);
  EXPECT_EQ(while_open, 1.0);
  EXPECT_EQ(before_the_end, 1.0);
  TEMPOKEY_ASSERT_GRPC_OK(status);
  EXPECT_EQ(response.clip_id(), wire::ClipContentId(clip));
  EXPECT_EQ(after, 0.0);
  EXPECT_EQ(most, static_cast<double>(server::DefaultWorkerCount()));
}

}  // namespace
}  // namespace tempokey::testing
