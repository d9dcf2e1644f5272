// Memory under hostile and heavy requests, on the real tempokey-server binary where the figure is
// the process's own (its resident set, read from /proc/<pid>/status), and on an in-process server
// where the test needs to see the memory budget's accounts:
//   - declared sizes buy no memory: uploads, inline clips and Process calls declaring 3 channels x
//     10 000 000 frames with one sample at the last frame leave the peak resident set flat;
//   - one budget refuses uploads, inline clips, jobs and results past it (RESOURCE_EXHAUSTED
//     naming --memory_budget_bytes), evicting stored clips and finished jobs first;
//   - ListJobs pages stop at their byte cap;
//   - memory deleted jobs held goes back to the system.
#include <signal.h>

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "server/memory_budget.h"
#include "server/motion_service.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

constexpr std::int64_t kDeclaredFrames = 10'000'000;
constexpr int kDeclaredChannels = 3;
// The old assembler zero-filled every declared channel when a slice came out of order: 240 MB
// per upload of this shape. What remains is gRPC's own per-call buffers and the few hundred
// bytes of layout and samples per call.
constexpr std::int64_t kMaxPeakGrowthKiB = 8 * 1024;

std::string StatusPath(pid_t pid) { return absl::StrCat("/proc/", pid, "/status"); }

// A clip header declaring kDeclaredChannels rotation channels x kDeclaredFrames frames.
v1::ClipHeader HugeDeclaredHeader() {
  core::Clip layout = MakeClip(1, 1);
  layout.channels.resize(kDeclaredChannels);
  layout.skeleton.joints[0].channels = {0, 1, 2};
  for (int c = 0; c < kDeclaredChannels; ++c) {
    layout.channels[c].kind = c == 0   ? core::ChannelKind::kZRotation
                              : c == 1 ? core::ChannelKind::kXRotation
                                       : core::ChannelKind::kYRotation;
  }
  v1::ClipHeader header = wire::ClipHeaderToProto(layout);
  header.set_frame_count(kDeclaredFrames);
  return header;
}

// One sample of `channel` at the last declared frame.
v1::ChannelSamples LastFrameSample(int channel) {
  v1::ChannelSamples slice;
  slice.set_channel_index(channel);
  slice.set_first_frame(kDeclaredFrames - 1);
  slice.add_samples(1.0);
  return slice;
}

// Uploads, an inline SubmitJob and a Process call of the declared-size shape against `target`:
// every call must fail (frames never arrived), none may take memory for the declared frames.
void SendDeclaredSizeAttack(const std::string& target) {
  constexpr int kUploads = 4;
  auto stub = v1::MotionService::NewStub(Connect(target));
  // Four uploads open at once, each with its header and its three samples sent.
  std::vector<std::unique_ptr<grpc::ClientContext>> contexts;
  std::vector<v1::UploadClipResponse> responses(kUploads);
  std::vector<std::unique_ptr<grpc::ClientWriter<v1::UploadClipRequest>>> uploads;
  for (int i = 0; i < kUploads; ++i) {
    contexts.push_back(std::make_unique<grpc::ClientContext>());
    SetDeadline(*contexts.back());
    uploads.push_back(stub->UploadClip(contexts.back().get(), &responses[i]));
    v1::UploadClipRequest header;
    *header.mutable_header() = HugeDeclaredHeader();
    uploads.back()->Write(header);
    for (int c = 0; c < kDeclaredChannels; ++c) {
      v1::UploadClipRequest samples;
      *samples.mutable_samples() = LastFrameSample(c);
      uploads.back()->Write(samples);
    }
  }
  for (auto& upload : uploads) {
    upload->WritesDone();
    EXPECT_THAT(upload->Finish(), GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                                               HasSubstr("frames 0..9999998 never arrived")));
  }

  v1::SubmitJobRequest inline_request;
  *inline_request.mutable_inline_clip()->mutable_header() = HugeDeclaredHeader();
  for (int c = 0; c < kDeclaredChannels; ++c) {
    *inline_request.mutable_inline_clip()->add_samples() = LastFrameSample(c);
  }
  *inline_request.mutable_operations() = WrapOperations();
  EXPECT_LT(inline_request.ByteSizeLong(), 200u);  // the 117-byte request, give or take
  EXPECT_THAT(Submit(*stub, inline_request).status,
              GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                           HasSubstr("inline_clip: channel 0 (joint0.Zrotation): frames "
                                     "0..9999998 never arrived")));

  grpc::ClientContext context;
  SetDeadline(context);
  auto process = stub->Process(&context);
  v1::ProcessRequest request;
  *request.mutable_header() = HugeDeclaredHeader();
  process->Write(request);
  for (int c = 0; c < kDeclaredChannels; ++c) {
    *request.mutable_samples() = LastFrameSample(c);
    process->Write(request);
  }
  *request.mutable_start()->mutable_operations() = WrapOperations();
  process->Write(request);
  process->WritesDone();
  v1::ProcessResponse response;
  while (process->Read(&response)) {
  }
  EXPECT_THAT(process->Finish(), GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                                              HasSubstr("frames 0..9999998 never arrived")));
}

TEST(DeclaredSizeTest, HugeDeclaredClipsWithOneSampleLeaveThePeakResidentSetFlat) {
  absl::StatusOr<std::unique_ptr<ServerProcess>> server =
      ServerProcess::Start(MakeTempDir(), {"--workers=1"});
  ASSERT_TRUE(server.ok()) << server.status();
  const std::string status_path = StatusPath((*server)->pid());
  // Warm-up: the same calls with a small clip, so gRPC's threads and buffers exist already.
  auto stub = v1::MotionService::NewStub(Connect((*server)->target()));
  for (int i = 0; i < 4; ++i) TEMPOKEY_ASSERT_GRPC_OK(UploadClip(*stub, MakeClip(1, 100, i)).status);
  v1::SubmitJobRequest warm;
  *warm.mutable_inline_clip() = wire::ClipToProto(MakeClip(1, 100));
  *warm.mutable_operations() = WrapOperations();
  TEMPOKEY_ASSERT_GRPC_OK(Submit(*stub, warm).status);
  ASSERT_TRUE(ResetPeakRss((*server)->pid()));
  const std::int64_t before_kib = PeakRssKiB(status_path);

  SendDeclaredSizeAttack((*server)->target());
  const std::int64_t peak_kib = PeakRssKiB(status_path);

  RecordProperty("peak_rss_before_kib", static_cast<int>(before_kib));
  RecordProperty("peak_rss_growth_kib", static_cast<int>(peak_kib - before_kib));
  ASSERT_GT(before_kib, 0);
  EXPECT_LE(peak_kib - before_kib, kMaxPeakGrowthKiB)
      << "peak resident set grew from " << before_kib << " KiB to " << peak_kib << " KiB";
  EXPECT_EQ((*server)->Stop(), 0) << (*server)->log();
}

// ---- one memory budget --------------------------------------------------------------------------

constexpr std::int64_t kMiB = std::int64_t{1} << 20;

// A clip of about `mib` MiB of samples: 9 channels.
core::Clip ClipOfMiB(double mib, double seed = 0.0) {
  return MakeClip(2, static_cast<std::int64_t>(mib * static_cast<double>(kMiB) / (9 * 8)), seed);
}

TEST(MemoryBudgetServerTest, UploadLargerThanTheBudgetIsRefusedNamingIt) {
  absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(
      MakeTempDir(), {"--memory_budget_bytes=16000000", "--max_stored_clip_bytes=100000000"});
  ASSERT_TRUE(server.ok()) << server.status();
  auto stub = v1::MotionService::NewStub(Connect((*server)->target()));

  const UploadOutcome big = UploadClip(*stub, ClipOfMiB(24));
  const UploadOutcome fits = UploadClip(*stub, ClipOfMiB(4));

  EXPECT_THAT(big.status,
              GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                           HasSubstr("the server's memory budget (--memory_budget_bytes=16000000) "
                                     "cannot take an upload of")));
  // However late it comes back, it does not fit: no retry hint says it might.
  EXPECT_EQ(big.retry_after_ms, "");
  TEMPOKEY_ASSERT_GRPC_OK(fits.status);
}

class MemoryBudgetInProcessTest : public ::testing::Test {
 protected:
  void Start(std::int64_t budget_bytes, bool gated = false) {
    server::ServerOptions options = TestServerOptions();
    options.memory_budget_bytes = budget_bytes;
    if (gated) {
      options.test_hooks.on_job_start = [g = gate_](std::string_view id) { g->Arrive(id); };
    }
    server_ = StartServer(std::move(options));
    ASSERT_NE(server_, nullptr);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }
  void TearDown() override {
    gate_->Open();
    server_.reset();
  }

  std::shared_ptr<StartGate> gate_ = std::make_shared<StartGate>();
  std::unique_ptr<server::Server> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

TEST_F(MemoryBudgetInProcessTest, StoredClipsAreEvictedLeastRecentlyUsedFirstToMakeRoom) {
  Start(12 * kMiB);
  const UploadOutcome a = UploadClip(*stub_, ClipOfMiB(4, 1.0));
  const UploadOutcome b = UploadClip(*stub_, ClipOfMiB(4, 2.0));
  ASSERT_TRUE(a.status.ok() && b.status.ok());
  TEMPOKEY_ASSERT_GRPC_OK(Submit(*stub_, SubmitRequest(b.response.clip_id())).status);  // b used

  const UploadOutcome c = UploadClip(*stub_, ClipOfMiB(6, 3.0));  // needs a's room

  TEMPOKEY_ASSERT_GRPC_OK(c.status);
  EXPECT_THAT(Submit(*stub_, SubmitRequest(a.response.clip_id())).status,
              GrpcStatusIs(grpc::StatusCode::NOT_FOUND, HasSubstr("evicted")));
  TEMPOKEY_ASSERT_GRPC_OK(Submit(*stub_, SubmitRequest(c.response.clip_id())).status);
  EXPECT_LE(server_->budget().used(), 12 * kMiB);
}

TEST_F(MemoryBudgetInProcessTest, UploadsInProgressShareTheBudget) {
  Start(10 * kMiB);
  const core::Clip clip = ClipOfMiB(6);
  grpc::ClientContext context;
  SetDeadline(context);
  v1::UploadClipResponse response;
  auto first = stub_->UploadClip(&context, &response);
  std::vector<v1::UploadClipRequest> requests = UploadRequests(clip, 256 * 1024);
  const std::size_t half = requests.size() / 2;
  for (std::size_t i = 0; i < half; ++i) ASSERT_TRUE(first->Write(requests[i]));
  // Written is not received: wait (bounded) until the server holds the first half.
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  while (server_->budget().used(server::MemoryUse::kUpload) < 2 * kMiB &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_GE(server_->budget().used(server::MemoryUse::kUpload), 2 * kMiB);

  const UploadOutcome second = UploadClip(*stub_, ClipOfMiB(8, 5.0));
  for (std::size_t i = half; i < requests.size(); ++i) ASSERT_TRUE(first->Write(requests[i]));
  first->WritesDone();
  const grpc::Status first_status = first->Finish();

  EXPECT_THAT(second.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                          HasSubstr("cannot take an upload of")));
  TEMPOKEY_ASSERT_GRPC_OK(first_status);
}

TEST_F(MemoryBudgetInProcessTest, AnIncompleteUploadGivesItsMemoryBackBeforeItsStatus) {
  Start(10 * kMiB);
  grpc::ClientContext context;
  SetDeadline(context);
  v1::UploadClipResponse response;
  auto upload = stub_->UploadClip(&context, &response);
  std::vector<v1::UploadClipRequest> requests = UploadRequests(ClipOfMiB(6), 256 * 1024);
  // The header and half the samples: the clip can never be complete.
  for (std::size_t i = 0; i < requests.size() / 2; ++i) ASSERT_TRUE(upload->Write(requests[i]));
  upload->WritesDone();
  const grpc::Status status = upload->Finish();
  // Read as soon as the status is in: the memory must be back already, not once gRPC gets
  // round to destroying the call (a client's next upload may need it at once).
  const std::int64_t held_after_status = server_->budget().used(server::MemoryUse::kUpload);

  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT, HasSubstr("never arrived")));
  EXPECT_EQ(held_after_status, 0);
}

// Reads a server stream to its end: how many messages came, and its status.
template <typename Message, typename Reader>
std::pair<std::int64_t, grpc::Status> ReadToEnd(Reader& reader) {
  Message message;
  std::int64_t messages = 0;
  while (reader.Read(&message)) ++messages;
  return {messages, reader.Finish()};
}

// A whole GetClip stream of `clip_id`: its parts, status and retry hint.
struct ClipReadBack {
  std::int64_t parts = 0;
  grpc::Status status;
  std::string retry_after_ms;
};
ClipReadBack ReadClipBack(v1::MotionService::Stub& stub, const std::string& clip_id) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::GetClipRequest request;
  request.set_clip_id(clip_id);
  auto reader = stub.GetClip(&context, request);
  auto [parts, status] = ReadToEnd<v1::ResultPart>(*reader);
  return {parts, std::move(status), RetryAfterOf(context)};
}

TEST_F(MemoryBudgetInProcessTest, AReadClipsCopyIsGivenBackBeforeItsStatus) {
  Start(32 * kMiB);
  const UploadOutcome stored = UploadClip(*stub_, ClipOfMiB(4));
  ASSERT_TRUE(stored.status.ok());
  const auto [parts, status, hint] = ReadClipBack(*stub_, stored.response.clip_id());
  // GetClip streams a copy counted as a result; it goes back before the status, not once gRPC
  // gets round to destroying the call.
  const std::int64_t copy_after_status = server_->budget().used(server::MemoryUse::kResult);

  TEMPOKEY_ASSERT_GRPC_OK(status);
  EXPECT_GT(parts, 1);
  EXPECT_EQ(copy_after_status, 0);
}

// Reading a stored clip back copies it while it stays stored: with the copy, more than the whole
// budget never fits, so the refusal has no retry hint (the page's "Download" over HTTP gets 413,
// not a 429 that would say "retry later" forever).
TEST_F(MemoryBudgetInProcessTest, AClipTooLargeToCopyBesideItselfIsRefusedWithoutARetryHint) {
  Start(8 * kMiB);
  const UploadOutcome stored = UploadClip(*stub_, ClipOfMiB(5));
  ASSERT_TRUE(stored.status.ok()) << stored.status.error_message();

  const ClipReadBack read = ReadClipBack(*stub_, stored.response.clip_id());

  EXPECT_THAT(read.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                        HasSubstr("more than the whole budget; send less")));
  EXPECT_EQ(read.retry_after_ms, "");
  EXPECT_EQ(read.parts, 0);
}

TEST_F(MemoryBudgetInProcessTest, AProcessCallRefusedBeforeItsStartGivesItsClipBackFirst) {
  Start(32 * kMiB);
  grpc::ClientContext context;
  SetDeadline(context);
  auto process = stub_->Process(&context);
  // The whole clip, then the client's side closes without a ProcessStart.
  for (const v1::ProcessRequest& request : ProcessClipRequests(ClipOfMiB(4))) {
    ASSERT_TRUE(process->Write(request));
  }
  process->WritesDone();
  const auto [answers, status] = ReadToEnd<v1::ProcessResponse>(*process);
  const std::int64_t clip_after_status = server_->budget().used(server::MemoryUse::kProcess);

  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::INVALID_ARGUMENT,
                                   HasSubstr("ended before ProcessStart")));
  EXPECT_EQ(answers, 0);
  EXPECT_EQ(clip_after_status, 0);
}

TEST_F(MemoryBudgetInProcessTest, AnExportedFilesMemoryIsGivenBackBeforeItsStatus) {
  Start(32 * kMiB);
  const UploadOutcome stored = UploadClip(*stub_, ClipOfMiB(2));
  ASSERT_TRUE(stored.status.ok());
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ExportFileRequest request;
  request.set_clip_id(stored.response.clip_id());
  request.set_format("bvh");
  auto reader = stub_->ExportFile(&context, request);
  const auto [chunks, status] = ReadToEnd<v1::FileChunk>(*reader);
  const std::int64_t file_after_status = server_->budget().used(server::MemoryUse::kResult);

  TEMPOKEY_ASSERT_GRPC_OK(status);
  EXPECT_GT(chunks, 1);
  EXPECT_EQ(file_after_status, 0);
}

TEST_F(MemoryBudgetInProcessTest, InlineClipsProcessCallsAndResultsCountToo) {
  Start(4 * kMiB);
  v1::SubmitJobRequest inline_request;
  *inline_request.mutable_inline_clip() = wire::ClipToProto(ClipOfMiB(5));
  *inline_request.mutable_operations() = WrapOperations();
  const UploadOutcome stored = UploadClip(*stub_, ClipOfMiB(1.5));
  ASSERT_TRUE(stored.status.ok());
  // A retime to five times the length: a 7.5 MB result.
  google::protobuf::RepeatedPtrField<v1::Operation> stretch;
  v1::RetimeOperation* retime = stretch.Add()->mutable_retime();
  v1::SpeedKnot* slow = retime->add_speed_over_source();
  slow->mutable_time()->set_seconds(0);
  slow->set_speed(0.2);

  const JobOutcome stretched = Submit(*stub_, SubmitRequest(stored.response.clip_id(), stretch));
  const v1::Job stretched_done = WaitForJob(*stub_, stretched.job.job_id());
  const JobOutcome inline_job = Submit(*stub_, inline_request);
  grpc::ClientContext context;
  SetDeadline(context);
  auto process = stub_->Process(&context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(ClipOfMiB(5))) process->Write(request);
  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = WrapOperations();
  process->Write(start);
  process->WritesDone();
  v1::ProcessResponse response;
  while (process->Read(&response)) {
  }
  const grpc::Status process_status = process->Finish();

  EXPECT_THAT(inline_job.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                              HasSubstr("cannot take an inline clip of")));
  TEMPOKEY_ASSERT_GRPC_OK(stretched.status);
  EXPECT_EQ(stretched_done.state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(stretched_done.error_code(), static_cast<int>(grpc::StatusCode::RESOURCE_EXHAUSTED));
  EXPECT_THAT(stretched_done.error_message(), HasSubstr("cannot take a job's result of"));
  EXPECT_THAT(process_status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                           HasSubstr("cannot take a Process clip of")));
}

// A refusal that fits once others give memory back carries the retry hint, also through the
// layers that name the field it came from (the inline clip's annotation once dropped it: HTTP
// then answered 413 "too large" for a request that passes a moment later).
TEST_F(MemoryBudgetInProcessTest, AnInlineClipRefusedWhileTheBudgetIsInUseCarriesARetryHint) {
  Start(8 * kMiB);
  // An upload that has sent its samples but not ended holds their memory (not a cache: it is
  // not given back on demand).
  grpc::ClientContext open_context;
  SetDeadline(open_context);
  v1::UploadClipResponse open_response;
  auto open = stub_->UploadClip(&open_context, &open_response);
  for (const v1::UploadClipRequest& request : UploadRequests(ClipOfMiB(3), wire::kDefaultSliceBytes)) {
    ASSERT_TRUE(open->Write(request));
  }
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  while (server_->budget().used(server::MemoryUse::kUpload) < 3 * kMiB &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  const std::int64_t held = server_->budget().used(server::MemoryUse::kUpload);
  v1::SubmitJobRequest inline_request;
  *inline_request.mutable_inline_clip() = wire::ClipToProto(ClipOfMiB(5));
  *inline_request.mutable_operations() = WrapOperations();

  const JobOutcome busy = Submit(*stub_, inline_request);
  open->WritesDone();
  TEMPOKEY_ASSERT_GRPC_OK(open->Finish());

  ASSERT_GE(held, 3 * kMiB);
  EXPECT_THAT(busy.status, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                        HasSubstr("inline_clip: the server's memory budget")));
  EXPECT_EQ(busy.retry_after_ms, std::to_string(server::kMemoryRetryAfter.count()));
}

// ---- stored jobs, ListJobs pages, memory after deletes --------------------------------------------

// A retime whose speed curve has `knots` knots (equal speeds: valid on any clip).
google::protobuf::RepeatedPtrField<v1::Operation> ManyKnots(int knots, int retimes = 1) {
  google::protobuf::RepeatedPtrField<v1::Operation> operations;
  for (int r = 0; r < retimes; ++r) {
    v1::RetimeOperation* retime = operations.Add()->mutable_retime();
    for (int k = 0; k < knots; ++k) {
      v1::SpeedKnot* knot = retime->add_speed_over_source();
      knot->mutable_time()->set_seconds(k * 1e-5);
      knot->set_speed(1.0);
    }
  }
  return operations;
}

struct Listing {
  std::vector<v1::Job> jobs;
  std::vector<std::int64_t> page_bytes;
};

Listing ListAll(v1::MotionService::Stub& stub) {
  Listing listing;
  std::string token;
  do {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::ListJobsRequest request;
    request.set_page_size(100);
    request.set_page_token(token);
    v1::ListJobsResponse page;
    const grpc::Status status = stub.ListJobs(&context, request, &page);
    EXPECT_TRUE(status.ok()) << status.error_message();
    if (!status.ok()) break;
    listing.page_bytes.push_back(static_cast<std::int64_t>(page.ByteSizeLong()));
    for (const v1::Job& job : page.jobs()) listing.jobs.push_back(job);
    token = page.next_page_token();
  } while (!token.empty());
  return listing;
}

TEST(ListJobsPageTest, PagesStopAtTheirByteCapAndTogetherHoldEveryJob) {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const std::string clip_id = UploadClip(*stub, MakeClip(1, 200)).response.clip_id();
  std::vector<std::string> submitted;
  for (int i = 0; i < 30; ++i) {  // 5 000 knots: about 100 kB per job
    const JobOutcome job = Submit(*stub, SubmitRequest(clip_id, ManyKnots(5'000)));
    ASSERT_TRUE(job.status.ok()) << job.status.error_message();
    submitted.push_back(job.job.job_id());
  }
  // One job alone larger than a page: listed without its operations.
  const JobOutcome huge = Submit(*stub, SubmitRequest(clip_id, ManyKnots(80'000)));
  ASSERT_TRUE(huge.status.ok()) << huge.status.error_message();
  submitted.push_back(huge.job.job_id());

  const Listing listing = ListAll(*stub);
  const JobOutcome huge_whole = GetJob(*stub, huge.job.job_id());

  ASSERT_EQ(listing.jobs.size(), submitted.size());
  for (std::size_t i = 0; i < submitted.size(); ++i) EXPECT_EQ(listing.jobs[i].job_id(), submitted[i]);
  EXPECT_GT(listing.page_bytes.size(), 2u);
  for (const std::int64_t bytes : listing.page_bytes) {
    EXPECT_LE(bytes, server::kMaxListPageBytes);
  }
  for (std::size_t i = 0; i + 1 < listing.jobs.size(); ++i) {
    EXPECT_EQ(listing.jobs[i].operations_size(), 1) << i;
  }
  EXPECT_EQ(listing.jobs.back().operations_size(), 0);
  EXPECT_EQ(huge_whole.job.operations_size(), 1);
  EXPECT_EQ(huge_whole.job.operations(0).retime().speed_over_source_size(), 80'000);
  RecordProperty("list_pages", static_cast<int>(listing.page_bytes.size()));
}

TEST(DeletedJobsTest, MemoryOfDeletedJobsGoesBackToTheSystem) {
#if defined(TEMPOKEY_SANITIZED)
  // ASan keeps freed blocks resident in its quarantine (test_clips.h) by design; the Release
  // stage of the suite pins this.
  GTEST_SKIP() << "freed memory stays in ASan's quarantine";
#endif
  absl::StatusOr<std::unique_ptr<ServerProcess>> server =
      ServerProcess::Start(MakeTempDir(), {"--workers=2"});
  ASSERT_TRUE(server.ok()) << server.status();
  const std::string status_path = StatusPath((*server)->pid());
  auto stub = v1::MotionService::NewStub(Connect((*server)->target()));
  const std::string clip_id = UploadClip(*stub, MakeClip(1, 200)).response.clip_id();
  TEMPOKEY_ASSERT_GRPC_OK(Submit(*stub, SubmitRequest(clip_id)).status);  // warm-up
  const std::int64_t baseline_kib = RssKiB(status_path);

  // kJobs jobs of 3 retimes x 60 000 knots: 4.3 MB of stored operations each.
  constexpr int kJobs = 16;
  std::vector<std::string> ids;
  for (int i = 0; i < kJobs; ++i) {
    const JobOutcome job = Submit(*stub, SubmitRequest(clip_id, ManyKnots(60'000, 3)));
    ASSERT_TRUE(job.status.ok()) << job.status.error_message();
    ids.push_back(job.job.job_id());
  }
  // Wait (bounded) until none is queued or running; these listings are small, since jobs larger
  // than a page are listed without their operations.
  const auto run_deadline = std::chrono::steady_clock::now() + kCallDeadline;
  for (;;) {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::ListJobsRequest pending;
    pending.add_states(v1::JOB_STATE_QUEUED);
    pending.add_states(v1::JOB_STATE_RUNNING);
    v1::ListJobsResponse page;
    TEMPOKEY_ASSERT_GRPC_OK(stub->ListJobs(&context, pending, &page));
    if (page.jobs().empty()) break;
    ASSERT_LT(std::chrono::steady_clock::now(), run_deadline) << "jobs did not finish";
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const std::int64_t stored_kib = RssKiB(status_path);
  for (const std::string& id : ids) {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::DeleteJobRequest request;
    request.set_job_id(id);
    v1::DeleteJobResponse response;
    TEMPOKEY_ASSERT_GRPC_OK(stub->DeleteJob(&context, request, &response));
  }
  // The trim runs on the server's own thread: poll (bounded) for the resident set to come down.
  constexpr std::int64_t kSlackKiB = 32 * 1024;
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  std::int64_t after_kib = RssKiB(status_path);
  while (after_kib > baseline_kib + kSlackKiB && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    after_kib = RssKiB(status_path);
  }

  RecordProperty("rss_baseline_kib", static_cast<int>(baseline_kib));
  RecordProperty("rss_stored_kib", static_cast<int>(stored_kib));
  RecordProperty("rss_after_delete_kib", static_cast<int>(after_kib));
  EXPECT_GT(stored_kib, baseline_kib + 100 * 1024);  // the jobs did take memory
  EXPECT_LE(after_kib, baseline_kib + kSlackKiB)
      << "baseline " << baseline_kib << " KiB, with jobs " << stored_kib << " KiB, after deleting "
      << after_kib << " KiB";
}

}  // namespace
}  // namespace tempokey::testing
