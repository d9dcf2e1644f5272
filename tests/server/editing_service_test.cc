// The editing calls of MotionService over gRPC against a real server on 127.0.0.1:0: clip files
// parsed by core's readers, stored clips read back, retime plans against the retime job's own
// report, the CLI's speed syntax, and files written with the bytes the CLI writes; exports stopped
// by their client, the drain deadline and a full queue.
#include <atomic>
#include <condition_variable>
#include <fstream>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <stop_token>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "client/clip_files.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/operations_convert.h"
#include "server/job_pool.h"
#include "server/server.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tests/server/http_util.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/start_gate.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

class EditingServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = StartServer(TestServerOptions());
    ASSERT_NE(server_, nullptr);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
  }

  v1::ParseClipFileResponse Parse(const std::string& name, const std::string& content,
                                  grpc::Status* status) {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::ParseClipFileRequest request;
    request.set_file_name(name);
    request.set_content(content);
    v1::ParseClipFileResponse response;
    *status = stub_->ParseClipFile(&context, request, &response);
    return response;
  }

  std::string ParseCmu() {
    grpc::Status status;
    v1::ParseClipFileResponse response = Parse("131_01.bvh", ReadBytes(Cmu()), &status);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return response.clip_id();
  }

  static std::string Cmu() { return SharedBvh("cmu/131_01.bvh"); }

  v1::RetimePlan Plan(const v1::PlanRetimeRequest& request, grpc::Status* status) {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::RetimePlan plan;
    *status = stub_->PlanRetime(&context, request, &plan);
    return plan;
  }

  // ExportFile's chunks joined; the first chunk's name in `file_name`.
  std::string Export(const v1::ExportFileRequest& request, grpc::Status* status,
                     std::string* file_name = nullptr) {
    grpc::ClientContext context;
    SetDeadline(context);
    auto reader = stub_->ExportFile(&context, request);
    std::string bytes;
    v1::FileChunk chunk;
    bool first = true;
    while (reader->Read(&chunk)) {
      if (first && file_name != nullptr) *file_name = chunk.file_name();
      first = false;
      bytes += chunk.data();
    }
    *status = reader->Finish();
    return bytes;
  }

  // A stored job running `operations` on `clip_id`, finished.
  std::string RunJob(const std::string& clip_id, const std::vector<core::PipelineStep>& steps) {
    v1::SubmitJobRequest request;
    request.set_clip_id(clip_id);
    for (const core::PipelineStep& step : steps) *request.add_operations() = wire::PipelineStepToProto(step);
    JobOutcome submitted = Submit(*stub_, request);
    EXPECT_TRUE(submitted.status.ok()) << submitted.status.error_message();
    EXPECT_EQ(WaitForJob(*stub_, submitted.job.job_id()).state(), v1::JOB_STATE_SUCCEEDED);
    return submitted.job.job_id();
  }

  std::unique_ptr<server::Server> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
};

core::RetimeStep RampStep() {
  core::RetimeStep step;
  step.warp.domain = core::WarpDomain::kSpeedOverSource;
  step.warp.speed = *core::ParseSpeedKnots("0s:1,2s:0.5,4s:2");
  step.warp.holds.push_back({.at = {.value = 1.0}, .duration_seconds = 0.25});
  return step;
}

TEST_F(EditingServiceTest, ParsedFileIsStoredUnderTheIdAnUploadOfTheSameClipGets) {
  const core::Clip clip = *core::ReadBvhFile(Cmu());
  const UploadOutcome uploaded = UploadClip(*stub_, clip);
  ASSERT_TRUE(uploaded.status.ok());

  grpc::Status status;
  const v1::ParseClipFileResponse parsed = Parse("131_01.bvh", ReadBytes(Cmu()), &status);

  TEMPOKEY_ASSERT_GRPC_OK(status);
  EXPECT_EQ(parsed.clip_id(), uploaded.response.clip_id());
  EXPECT_TRUE(parsed.already_stored());
  EXPECT_EQ(parsed.header().frame_count(), 994);
  EXPECT_EQ(parsed.header().channels_size(), 96);
  EXPECT_EQ(parsed.sample_count(), 994 * 96);
}

TEST_F(EditingServiceTest, MalformedFileIsRefusedWithTheReadersLocatedMessage) {
  std::string text = ReadBytes(Cmu());
  text.replace(text.find("Yposition"), 9, "Ypozition");
  const absl::StatusOr<core::Clip> local = core::ParseBvh(text, "broken.bvh");
  ASSERT_FALSE(local.ok());

  grpc::Status broken, unknown, unnamed;
  Parse("broken.bvh", text, &broken);
  Parse("walk.txt", text, &unknown);
  Parse("", text, &unnamed);

  EXPECT_THAT(broken, GrpcStatusIs(grpc::INVALID_ARGUMENT, std::string(local.status().message())));
  EXPECT_THAT(broken, GrpcStatusIs(grpc::INVALID_ARGUMENT, StartsWith("broken.bvh:5:")));
  EXPECT_THAT(unknown, GrpcStatusIs(grpc::INVALID_ARGUMENT,
                                    "walk.txt: unknown clip format '.txt' (expected .bvh, .csv)"));
  EXPECT_THAT(unnamed, GrpcStatusIs(grpc::INVALID_ARGUMENT, "file_name is empty"));
}

// The CSV frame time is the request's own field: its refusal names it (it said "frame time").
TEST_F(EditingServiceTest, ABadCsvFrameTimeIsRefusedNamingItsField) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ParseClipFileRequest request;
  request.set_file_name("walk.csv");
  request.set_content("Hips.Xrotation\n1\n2\n");
  request.set_csv_frame_time_seconds(-1);
  v1::ParseClipFileResponse response;

  const grpc::Status status = stub_->ParseClipFile(&context, request, &response);

  EXPECT_THAT(status, GrpcStatusIs(grpc::INVALID_ARGUMENT,
                                   "csv_frame_time_seconds must be in [1e-06, 3600] seconds, got -1"));
}

TEST_F(EditingServiceTest, GetClipReturnsTheStoredClipSampleForSample) {
  const std::string clip_id = ParseCmu();
  grpc::ClientContext context;
  SetDeadline(context);
  v1::GetClipRequest request;
  request.set_clip_id(clip_id);
  auto reader = stub_->GetClip(&context, request);
  std::vector<v1::ResultPart> parts;
  v1::ResultPart part;
  while (reader->Read(&part)) parts.push_back(part);
  TEMPOKEY_ASSERT_GRPC_OK(reader->Finish());

  const absl::StatusOr<core::Clip> clip = AssembleClipResult(parts);

  ASSERT_TRUE(clip.ok()) << clip.status();
  const core::Clip expected = *core::ReadBvhFile(Cmu());
  EXPECT_EQ(clip->channels, expected.channels);
  EXPECT_EQ(clip->skeleton, expected.skeleton);
  EXPECT_EQ(clip->frame_time_seconds, expected.frame_time_seconds);
}

TEST_F(EditingServiceTest, GetClipRefusedOrEndedGivesItsStreamSlotBack) {
  const std::string clip_id = ParseCmu();
  auto get = [&](const std::string& id, std::int32_t slice_bytes) {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::GetClipRequest request;
    request.set_clip_id(id);
    request.set_slice_bytes(slice_bytes);
    auto reader = stub_->GetClip(&context, request);
    v1::ResultPart part;
    int parts = 0;
    while (reader->Read(&part)) ++parts;
    return std::pair(reader->Finish(), parts);
  };

  // Each stream gives its slot back before its status goes out: none is open once the client
  // has it.
  const auto [negative, negative_parts] = get(clip_id, -1);
  EXPECT_EQ(server_->open_streams(), 0);
  const auto [unknown, unknown_parts] = get("no-such-clip", 0);
  EXPECT_EQ(server_->open_streams(), 0);
  const auto [whole, whole_parts] = get(clip_id, 0);
  EXPECT_EQ(server_->open_streams(), 0);

  EXPECT_THAT(negative, GrpcStatusIs(grpc::INVALID_ARGUMENT,
                                     "slice_bytes must be >= 0 (0: 1 MiB), got -1"));
  EXPECT_EQ(negative_parts, 0);
  EXPECT_THAT(unknown, GrpcStatusIs(grpc::NOT_FOUND, HasSubstr("no-such-clip")));
  EXPECT_EQ(unknown_parts, 0);
  EXPECT_TRUE(whole.ok()) << whole.error_message();
  EXPECT_GT(whole_parts, 1);
}

TEST_F(EditingServiceTest, PlanReportIsTheReportOfTheRetimeJob) {
  const std::string clip_id = ParseCmu();
  const std::string job_id = RunJob(clip_id, {RampStep()});
  const v1::Job job = GetJob(*stub_, job_id).job;
  v1::PlanRetimeRequest request;
  request.set_clip_id(clip_id);
  *request.mutable_retime() = wire::PipelineStepToProto(RampStep()).retime();
  request.set_max_points(5);

  grpc::Status status;
  const v1::RetimePlan plan = Plan(request, &status);

  TEMPOKEY_ASSERT_GRPC_OK(status);
  ASSERT_EQ(job.reports_size(), 1);
  EXPECT_EQ(plan.report().SerializeAsString(), job.reports(0).retime().SerializeAsString());
  const std::int64_t frames = plan.report().output_frame_count();
  EXPECT_THAT(plan.output_frames(), ::testing::ElementsAre(0, (frames - 1) / 4, (frames - 1) / 2,
                                                           3 * (frames - 1) / 4, frames - 1));
  EXPECT_EQ(plan.source_time_seconds(0), 0.0);
  EXPECT_EQ(plan.source_time_seconds(4), 993 * 0.0083333);
  EXPECT_EQ(plan.speed_text(), "0s:1,2s:0.5,4s:2");
  EXPECT_EQ(plan.knot_output_time_seconds_size(), 3);
  EXPECT_EQ(plan.source_duration_seconds(), 993 * 0.0083333);
}

TEST_F(EditingServiceTest, PlanRefusesBadKnotsUnknownClipsAndPointCounts) {
  const std::string clip_id = ParseCmu();
  v1::PlanRetimeRequest bad_knot;
  bad_knot.set_clip_id(clip_id);
  v1::SpeedKnot* knot = bad_knot.mutable_retime()->add_speed_over_source();
  knot->mutable_time()->set_seconds(0);
  knot->set_speed(1000);
  v1::PlanRetimeRequest no_unit = bad_knot;
  no_unit.mutable_retime()->mutable_speed_over_source(0)->clear_time();
  v1::PlanRetimeRequest unknown;
  unknown.set_clip_id("sha256:0");
  v1::PlanRetimeRequest one_point;
  one_point.set_clip_id(clip_id);
  one_point.set_max_points(1);

  grpc::Status s1, s2, s3, s4;
  Plan(bad_knot, &s1);
  Plan(no_unit, &s2);
  Plan(unknown, &s3);
  Plan(one_point, &s4);

  EXPECT_THAT(s1, GrpcStatusIs(grpc::INVALID_ARGUMENT,
                               "speed knot 1 (0s:1000): speed 1000 is outside the allowed range [0.01, 100]"));
  EXPECT_THAT(s2, GrpcStatusIs(grpc::INVALID_ARGUMENT,
                               "retime.speed_over_source[0].time has no unit: set seconds or frames"));
  EXPECT_EQ(s3.error_code(), grpc::NOT_FOUND);
  EXPECT_THAT(s4, GrpcStatusIs(grpc::INVALID_ARGUMENT, HasSubstr("max_points must be 0")));
}

TEST_F(EditingServiceTest, SpeedTextIsReadAndWrittenInTheCliSyntax) {
  auto parse = [&](const std::string& text, grpc::Status* status) {
    grpc::ClientContext context;
    SetDeadline(context);
    v1::ParseSpeedKnotsRequest request;
    request.set_text(text);
    v1::ParseSpeedKnotsResponse response;
    *status = stub_->ParseSpeedKnots(&context, request, &response);
    return response;
  };
  grpc::Status ok, bad;

  const v1::ParseSpeedKnotsResponse knots = parse(" 0s:1, 2.50s:0.5,75f:+2", &ok);
  parse("0s:1,2x:0.5", &bad);

  TEMPOKEY_ASSERT_GRPC_OK(ok);
  ASSERT_EQ(knots.knots_size(), 3);
  EXPECT_EQ(knots.knots(1).time().seconds(), 2.5);
  EXPECT_EQ(knots.knots(2).time().frames(), 75.0);
  EXPECT_EQ(knots.knots(2).speed(), 2.0);
  EXPECT_EQ(knots.text(), "0s:1,2.5s:0.5,75f:2");
  EXPECT_THAT(bad, GrpcStatusIs(grpc::INVALID_ARGUMENT, "speed knot 2 '2x:0.5': time needs a unit, s or f"));
}

TEST_F(EditingServiceTest, ExportedFilesAreTheBytesTheCliWritesForTheSameResult) {
  const std::string clip_id = ParseCmu();
  const core::Clip clip = *core::ReadBvhFile(Cmu());
  const core::RetimeStep retime = RampStep();
  const core::ReduceStep reduce;
  const std::string dir = MakeTempDir();
  struct Case {
    std::vector<core::PipelineStep> job;      // what the page runs
    std::vector<core::PipelineStep> cli;      // what the CLI runs for that output
    client::FileFormat format;
    std::string name;
  };
  const std::vector<Case> cases = {
      {{retime}, {retime}, client::FileFormat::kBvh, "bvh"},
      {{retime}, {retime}, client::FileFormat::kCsv, "csv"},
      {{reduce}, {reduce}, client::FileFormat::kKeyedJson, "json"},
      {{reduce}, {reduce}, client::FileFormat::kMayaAnim, "anim"},
      {{reduce}, {reduce, core::BakeStep{}}, client::FileFormat::kBvh, "bvh"},
      {{reduce}, {reduce, core::BakeStep{}}, client::FileFormat::kCsv, "csv"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name + " after " + std::string(core::StepName(c.job.front())));
    const std::string job_id = RunJob(clip_id, c.job);
    const absl::StatusOr<core::PipelineResult> local = core::RunPipeline(clip, c.cli);
    ASSERT_TRUE(local.ok());
    const std::string path = dir + "/cli" + std::string(client::ExtensionOf(c.format));
    TEMPOKEY_ASSERT_OK(client::WriteOutput(path, c.format, local->output));
    v1::ExportFileRequest request;
    request.set_job_id(job_id);
    request.set_format(c.name);
    request.set_chunk_bytes(100000);

    grpc::Status status;
    std::string file_name;
    const std::string bytes = Export(request, &status, &file_name);

    TEMPOKEY_ASSERT_GRPC_OK(status);
    EXPECT_EQ(file_name, "131_01" + std::string(client::ExtensionOf(c.format)));
    EXPECT_GT(bytes.size(), 1000u);
    EXPECT_TRUE(bytes == ReadBytes(path)) << bytes.size() << " bytes vs " << ReadBytes(path).size();
  }
}

// A keyed glTF is fitted against the job's input clip. A job whose clip came inline was never
// stored: the refusal says so, where it said the server "no longer holds" a clip it never had,
// and the upload it asks for is what makes the export work.
TEST_F(EditingServiceTest, AKeyedGltfOfAJobWhoseClipCameInlineAsksForTheUploadThatMakesItWork) {
  const core::Clip clip = *core::ReadBvhFile(SharedBvh("bandai/dataset-1_bow_active_001.bvh"));
  v1::SubmitJobRequest submit;
  *submit.mutable_inline_clip() = wire::ClipToProto(clip);
  *submit.add_operations() = wire::PipelineStepToProto(core::ReduceStep{});
  const JobOutcome submitted = Submit(*stub_, submit);
  TEMPOKEY_ASSERT_GRPC_OK(submitted.status);
  ASSERT_EQ(WaitForJob(*stub_, submitted.job.job_id()).state(), v1::JOB_STATE_SUCCEEDED);
  v1::ExportFileRequest request;
  request.set_job_id(submitted.job.job_id());
  request.set_format("glb");

  grpc::Status refused;
  Export(request, &refused);
  grpc::Status uploaded;
  const std::string clip_id =
      Parse(clip.name + ".bvh", ReadBytes(SharedBvh("bandai/dataset-1_bow_active_001.bvh")),
            &uploaded)
          .clip_id();
  grpc::Status exported;
  const std::string glb = Export(request, &exported);

  EXPECT_THAT(refused, GrpcStatusIs(grpc::FAILED_PRECONDITION,
                                    HasSubstr("which this server does not hold (it came inline "
                                              "with the job, or has left the clip store since): "
                                              "upload it (UploadClip) and export again")));
  TEMPOKEY_ASSERT_GRPC_OK(uploaded);
  EXPECT_EQ(clip_id, submitted.job.clip_id());  // the same content, the same id
  TEMPOKEY_ASSERT_GRPC_OK(exported);
  EXPECT_EQ(glb.substr(0, 4), "glTF");
}

TEST_F(EditingServiceTest, ExportRefusesUnknownFormatsAndCurvesOfASampledClip) {
  const std::string clip_id = ParseCmu();
  v1::ExportFileRequest gif;
  gif.set_clip_id(clip_id);
  gif.set_format("gif");
  v1::ExportFileRequest anim;
  anim.set_clip_id(clip_id);
  anim.set_format("anim");
  v1::ExportFileRequest bvh;
  bvh.set_clip_id(clip_id);
  bvh.set_format("bvh");

  grpc::Status s1, s2, s3;
  Export(gif, &s1);
  Export(anim, &s2);
  const std::string text = Export(bvh, &s3);

  EXPECT_THAT(s1, GrpcStatusIs(grpc::INVALID_ARGUMENT, "format \"gif\" is not one of bvh, csv, json, anim, gltf, glb"));
  EXPECT_THAT(s2, GrpcStatusIs(grpc::INVALID_ARGUMENT, HasSubstr("a sampled clip has none")));
  TEMPOKEY_ASSERT_GRPC_OK(s3);
  EXPECT_EQ(text, *core::FormatBvh(*core::ReadBvhFile(Cmu())));
}

TEST(EditingServiceAuthTest, EditingCallsNeedTheBearerToken) {
  server::ServerOptions options = TestServerOptions();
  options.auth_tokens = {"s3cret"};
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  std::vector<grpc::Status> statuses;
  {
    grpc::ClientContext context;
    v1::ParseClipFileResponse response;
    v1::ParseClipFileRequest request;
    request.set_file_name("a.bvh");
    statuses.push_back(stub->ParseClipFile(&context, request, &response));
  }
  {
    grpc::ClientContext context;
    v1::RetimePlan response;
    statuses.push_back(stub->PlanRetime(&context, v1::PlanRetimeRequest(), &response));
  }
  {
    grpc::ClientContext context;
    v1::ParseSpeedKnotsResponse response;
    statuses.push_back(stub->ParseSpeedKnots(&context, v1::ParseSpeedKnotsRequest(), &response));
  }
  {
    grpc::ClientContext context;
    v1::ResultPart part;
    auto reader = stub->GetClip(&context, v1::GetClipRequest());
    while (reader->Read(&part)) {
    }
    statuses.push_back(reader->Finish());
  }
  {
    grpc::ClientContext context;
    v1::FileChunk chunk;
    auto reader = stub->ExportFile(&context, v1::ExportFileRequest());
    while (reader->Read(&chunk)) {
    }
    statuses.push_back(reader->Finish());
  }

  for (const grpc::Status& status : statuses) {
    EXPECT_THAT(status, GrpcStatusIs(grpc::UNAUTHENTICATED, HasSubstr("authorization")));
  }
}

TEST_F(EditingServiceTest, ServerInfoListsTheExportFormats) {
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ServerInfo info;

  TEMPOKEY_ASSERT_GRPC_OK(stub_->GetServerInfo(&context, v1::GetServerInfoRequest(), &info));

  std::vector<std::string> names;
  for (const v1::ExportFormat& format : info.export_formats()) names.push_back(format.name());
  EXPECT_EQ(names, (std::vector<std::string>{"bvh", "csv", "json", "anim", "gltf", "glb"}));
  EXPECT_TRUE(info.export_formats(2).keyed());
  EXPECT_FALSE(info.export_formats(0).keyed());
}

// The on_export_start hook of the tests below: every export arrives at `gate`; the arrivals
// marked by HoldUntilStopped() (1: the first export) then wait, bounded, until the server has
// requested their stop, so what an export's formatting sees does not depend on when a client's
// cancel reaches the server.
class ExportHook {
 public:
  void Arrive(std::stop_token stop) {
    int index = 0;
    {
      std::lock_guard lock(mutex_);
      index = ++arrivals_;
    }
    gate.Arrive();
    bool hold = false;
    {
      std::lock_guard lock(mutex_);
      hold = held_.count(index) > 0;
    }
    if (!hold) return;
    std::mutex waiting;
    std::condition_variable_any stopped;
    std::unique_lock lock(waiting);
    stopped.wait_until(lock, stop, std::chrono::steady_clock::now() + StartGate::kWaitLimit,
                       [] { return false; });
  }
  void HoldUntilStopped(int arrival) {
    std::lock_guard lock(mutex_);
    held_.insert(arrival);
  }

  StartGate gate;

 private:
  std::mutex mutex_;
  int arrivals_ = 0;
  std::set<int> held_;
};

// Exports on a server with one worker, a queue of two and metrics: what stops an export is seen
// in its outcome.
class ExportStopTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server::ServerOptions options = TestServerOptions();
    options.workers = 1;
    options.queue_capacity = 2;
    options.metrics_address = "127.0.0.1:0";
    options.test_hooks.on_export_start = [h = hook_](std::string_view, std::stop_token stop) {
      h->Arrive(std::move(stop));
    };
    server_ = StartServer(std::move(options));
    ASSERT_NE(server_, nullptr);
    stub_ = v1::MotionService::NewStub(Connect(server_->target()));
    // A keyed glTF of CMU 131_01's reduction (its rotations fitted again, joint by joint), and
    // the clip as BVH text (written without looking at the stop).
    grpc::ClientContext context;
    SetDeadline(context);
    v1::ParseClipFileRequest parse;
    parse.set_file_name("131_01.bvh");
    parse.set_content(ReadBytes(SharedBvh("cmu/131_01.bvh")));
    v1::ParseClipFileResponse parsed;
    TEMPOKEY_ASSERT_GRPC_OK(stub_->ParseClipFile(&context, parse, &parsed));
    v1::SubmitJobRequest submit;
    submit.set_clip_id(parsed.clip_id());
    *submit.add_operations() = wire::PipelineStepToProto(core::ReduceStep{});
    const JobOutcome job = Submit(*stub_, submit);
    TEMPOKEY_ASSERT_GRPC_OK(job.status);
    ASSERT_EQ(WaitForJob(*stub_, job.job.job_id()).state(), v1::JOB_STATE_SUCCEEDED);
    glb_.set_job_id(job.job.job_id());
    glb_.set_format("glb");
    bvh_.set_clip_id(parsed.clip_id());
    bvh_.set_format("bvh");
  }
  void TearDown() override {
    hook_->gate.Open();
    server_.reset();
  }

  // An ExportFile call in flight.
  struct Call {
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReader<v1::FileChunk>> reader;
  };
  std::unique_ptr<Call> Start(const v1::ExportFileRequest& request) {
    auto call = std::make_unique<Call>();
    SetDeadline(call->context);
    call->reader = stub_->ExportFile(&call->context, request);
    return call;
  }
  // The call read to its end: the file's bytes and the call's status.
  static std::pair<std::string, grpc::Status> Finish(Call& call) {
    std::string bytes;
    v1::FileChunk chunk;
    while (call.reader->Read(&chunk)) bytes += chunk.data();
    return {bytes, call.reader->Finish()};
  }

  double Exports(const std::string& outcome) {
    const std::optional<std::string> scrape = HttpGet(server_->metrics_port(), "/metrics");
    EXPECT_TRUE(scrape.has_value());
    return Sample(ParseSamples(scrape.value_or("")),
                  R"(tempokey_jobs_total{kind="export",outcome=")" + outcome + R"("})");
  }

  std::shared_ptr<ExportHook> hook_ = std::make_shared<ExportHook>();
  std::unique_ptr<server::Server> server_;
  std::unique_ptr<v1::MotionService::Stub> stub_;
  v1::ExportFileRequest glb_;
  v1::ExportFileRequest bvh_;
};

TEST_F(ExportStopTest, AnExportItsClientCancelsEndsCancelledAndItsWorkerTakesTheNextCall) {
  hook_->HoldUntilStopped(1);
  std::unique_ptr<Call> cancelled = Start(glb_);
  ASSERT_TRUE(hook_->gate.WaitArrivals(1));  // the worker holds the export, about to format it
  cancelled->context.TryCancel();
  Finish(*cancelled);  // CANCELLED on the client's side whatever the server does
  hook_->gate.Open();
  // One worker: this export runs once the cancelled one has ended, which it counts first.
  std::unique_ptr<Call> next = Start(glb_);
  const auto [bytes, status] = Finish(*next);

  TEMPOKEY_ASSERT_GRPC_OK(status);
  EXPECT_EQ(bytes.substr(0, 4), "glTF");
  EXPECT_EQ(Exports("cancelled"), 1.0);
  EXPECT_EQ(Exports("succeeded"), 1.0);
}

TEST_F(ExportStopTest, AnExportCancelledWhileQueuedIsNotFormatted) {
  hook_->HoldUntilStopped(2);
  std::unique_ptr<Call> running = Start(glb_);
  ASSERT_TRUE(hook_->gate.WaitArrivals(1));
  // Queued behind it: BVH text, which is written without looking at the stop. Cancelled once
  // the server has queued it (a call cancelled before its request arrives never reaches it).
  std::unique_ptr<Call> queued = Start(bvh_);
  const auto deadline = std::chrono::steady_clock::now() + StartGate::kWaitLimit;
  while (server_->pool().queue_depth() < 1 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_EQ(server_->pool().queue_depth(), 1);
  queued->context.TryCancel();
  Finish(*queued);
  hook_->gate.Open();
  const auto [running_bytes, running_status] = Finish(*running);
  // One worker: this export runs after the cancelled one has ended.
  std::unique_ptr<Call> after = Start(bvh_);
  const auto [after_bytes, after_status] = Finish(*after);

  TEMPOKEY_ASSERT_GRPC_OK(running_status);
  TEMPOKEY_ASSERT_GRPC_OK(after_status);
  EXPECT_EQ(after_bytes.substr(0, 9), "HIERARCHY");
  EXPECT_EQ(Exports("cancelled"), 1.0);
  EXPECT_EQ(Exports("succeeded"), 2.0);
}

// A parse whose deadline passes while it waits for the worker is not run when the worker comes
// free: it used to parse and store the file for nobody (three 42 MB files in a probe, pushing
// other clips out of the store).
TEST_F(ExportStopTest, AParseWhoseDeadlinePassesWhileQueuedIsNotRunOrStored) {
  std::unique_ptr<Call> running = Start(glb_);
  ASSERT_TRUE(hook_->gate.WaitArrivals(1));  // the one worker is held
  v1::ParseClipFileRequest parse;
  parse.set_file_name("bow.bvh");
  parse.set_content(ReadBytes(SharedBvh("bandai/dataset-1_bow_active_001.bvh")));
  // The call must reach the queue before its deadline passes: a loaded machine gets a longer
  // deadline on the next try (a try whose call never got queued proves nothing and is left).
  grpc::Status late;
  bool queued = false;
  for (const auto timeout : {std::chrono::seconds(3), std::chrono::seconds(10),
                             std::chrono::seconds(30)}) {
    const int before = server_->pool().queue_depth();
    std::atomic<bool> answered{false};
    std::thread caller([&] {
      grpc::ClientContext context;
      context.set_deadline(std::chrono::system_clock::now() + timeout);
      v1::ParseClipFileResponse ignored;
      late = stub_->ParseClipFile(&context, parse, &ignored);
      answered = true;
    });
    while (server_->pool().queue_depth() <= before && !answered) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    queued = server_->pool().queue_depth() > before;
    // The server received the call before it queued it, so its deadline is at most `timeout`
    // after this moment; the worker is let go only once that has passed.
    const auto queued_by = std::chrono::system_clock::now();
    caller.join();
    if (!queued) continue;
    std::this_thread::sleep_until(queued_by + timeout + std::chrono::milliseconds(50));
    break;
  }
  ASSERT_TRUE(queued) << "no try reached the queue before its deadline";
  hook_->gate.Open();
  const auto [running_bytes, running_status] = Finish(*running);
  // One worker: this parse runs after the late one was taken off the queue.
  grpc::ClientContext context;
  SetDeadline(context);
  v1::ParseClipFileResponse again;
  const grpc::Status again_status = stub_->ParseClipFile(&context, parse, &again);

  EXPECT_EQ(late.error_code(), grpc::DEADLINE_EXCEEDED);
  TEMPOKEY_ASSERT_GRPC_OK(running_status);
  TEMPOKEY_ASSERT_GRPC_OK(again_status);
  EXPECT_FALSE(again.already_stored());  // the late call stored nothing
}

// A Process call whose client leaves while it is queued is logged and counted as cancelled when
// its turn comes (it used to vanish from the log and the jobs metrics).
TEST_F(ExportStopTest, AProcessCallAbandonedWhileQueuedIsCountedCancelled) {
  std::unique_ptr<Call> running = Start(glb_);
  ASSERT_TRUE(hook_->gate.WaitArrivals(1));
  const int streams_before = server_->open_streams();
  grpc::ClientContext context;
  SetDeadline(context);
  auto process = stub_->Process(&context);
  for (const v1::ProcessRequest& request : ProcessClipRequests(MakeClip(1, 10))) {
    ASSERT_TRUE(process->Write(request));
  }
  v1::ProcessRequest start;
  *start.mutable_start()->mutable_operations() = WrapOperations();
  ASSERT_TRUE(process->Write(start));
  const auto deadline = std::chrono::steady_clock::now() + StartGate::kWaitLimit;
  while (server_->pool().queue_depth() < 1 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_EQ(server_->pool().queue_depth(), 1);
  ASSERT_EQ(server_->open_streams(), streams_before + 1);  // the queued call holds a slot
  context.TryCancel();
  const grpc::Status cancelled = process->Finish();
  // The worker is released only once the server has seen the cancel (its stream slot freed), so
  // that the call's turn comes after it however loaded the machine.
  const auto seen = std::chrono::steady_clock::now() + StartGate::kWaitLimit;
  while (server_->open_streams() > streams_before && std::chrono::steady_clock::now() < seen) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_EQ(server_->open_streams(), streams_before);
  hook_->gate.Open();
  Finish(*running);
  // One worker: this export runs after the abandoned call's turn.
  std::unique_ptr<Call> after = Start(bvh_);
  Finish(*after);

  EXPECT_EQ(cancelled.error_code(), grpc::StatusCode::CANCELLED);
  const std::optional<std::string> scrape = HttpGet(server_->metrics_port(), "/metrics");
  ASSERT_TRUE(scrape.has_value());
  EXPECT_EQ(Sample(ParseSamples(*scrape), R"(tempokey_jobs_total{kind="process",outcome="cancelled"})"),
            1.0);
}

TEST_F(ExportStopTest, AnExportTheDrainDeadlineReachesBeforeItBeginsIsRefusedUnavailable) {
  std::unique_ptr<Call> call = Start(bvh_);
  ASSERT_TRUE(hook_->gate.WaitArrivals(1));
  server_->pool().RequestStopAll();  // what Quiesce() does once the drain grace is over
  hook_->gate.Open();
  const auto [bytes, status] = Finish(*call);

  EXPECT_THAT(status, GrpcStatusIs(grpc::StatusCode::UNAVAILABLE,
                                   HasSubstr("the server is shutting down")));
  EXPECT_EQ(bytes, "");
  EXPECT_EQ(Exports("failed"), 1.0);
  EXPECT_EQ(Exports("succeeded"), 0.0);
}

TEST_F(ExportStopTest, AnExportBeyondAFullQueueIsRefusedAndCountedRejected) {
  std::unique_ptr<Call> running = Start(glb_);
  ASSERT_TRUE(hook_->gate.WaitArrivals(1));
  // Three more behind it, in whatever order they reach the server: two fill the queue of two,
  // and the last to arrive is refused while the gate holds the worker.
  std::vector<std::unique_ptr<Call>> behind;
  for (int i = 0; i < 3; ++i) behind.push_back(Start(bvh_));
  const auto deadline = std::chrono::steady_clock::now() + StartGate::kWaitLimit;
  while (Exports("rejected") < 1.0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  hook_->gate.Open();
  TEMPOKEY_ASSERT_GRPC_OK(Finish(*running).second);
  std::vector<grpc::StatusCode> codes;
  for (const std::unique_ptr<Call>& call : behind) {
    codes.push_back(Finish(*call).second.error_code());
  }

  EXPECT_THAT(codes, ::testing::UnorderedElementsAre(grpc::StatusCode::OK, grpc::StatusCode::OK,
                                                     grpc::StatusCode::RESOURCE_EXHAUSTED));
  EXPECT_EQ(Exports("rejected"), 1.0);
  EXPECT_EQ(Exports("succeeded"), 3.0);
}

}  // namespace
}  // namespace tempokey::testing
