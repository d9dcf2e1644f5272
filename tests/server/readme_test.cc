// README.md's service tables against the server itself:
//   - the status-code table: a real server produces every code listed, and the table lists
//     every code these producers know;
//   - the limits table: each limit's value is accepted and one more is RESOURCE_EXHAUSTED;
//   - the server-flags table: the same flags and defaults as `tempokey-server --helpfull`.
#include <chrono>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <regex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "core/src/retime/retime_internal.h"
#include "gmock/gmock.h"
#include "grpcpp/generic/generic_stub.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "server/job_manager.h"
#include "server/motion_service.h"
#include "server/wire_codec.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/clip.h"
#include "tests/server/server_test_util.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

// ---- reading the README ---------------------------------------------------------------------------

std::string Readme() {
  absl::StatusOr<std::string> text = core::ReadFile(SourceDir() + "/README.md");
  EXPECT_TRUE(text.ok()) << text.status();
  return text.ok() ? *text : std::string();
}

// The rows of the first table after the paragraph starting with `marker`, as cells (trimmed,
// header and separator rows dropped).
std::vector<std::vector<std::string>> TableAfter(const std::string& readme, const std::string& marker) {
  std::vector<std::vector<std::string>> rows;
  const std::size_t start = readme.find(marker);
  if (start == std::string::npos) {
    ADD_FAILURE() << "README has no \"" << marker << "\"";
    return rows;
  }
  bool in_table = false;
  int line_index = 0;
  for (absl::string_view line : absl::StrSplit(readme.substr(start), '\n')) {
    if (line.empty() || line.front() != '|') {
      if (in_table) break;
      continue;
    }
    in_table = true;
    if (line_index++ < 2) continue;  // header and |---|
    std::vector<std::string> cells;
    for (absl::string_view cell : absl::StrSplit(line.substr(1), '|')) {
      cells.emplace_back(absl::StripAsciiWhitespace(cell));
    }
    if (!cells.empty() && cells.back().empty()) cells.pop_back();
    rows.push_back(std::move(cells));
  }
  return rows;
}

// The text inside the first pair of backticks of `cell`, or "" when there is none.
std::string FirstCode(const std::string& cell) {
  const std::size_t open = cell.find('`');
  if (open == std::string::npos) return "";
  const std::size_t close = cell.find('`', open + 1);
  return close == std::string::npos ? "" : cell.substr(open + 1, close - open - 1);
}

// ---- the status-code table ------------------------------------------------------------------------

std::unique_ptr<grpc::ClientContext> Context() {
  auto context = std::make_unique<grpc::ClientContext>();
  SetDeadline(*context);
  return context;
}

// A real server per producer, so each code comes from its own situation.
using Producer = std::function<grpc::StatusCode()>;

grpc::StatusCode ProduceInvalidArgument() {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  return Submit(*stub, v1::SubmitJobRequest()).status.error_code();  // no clip
}

grpc::StatusCode ProduceNotFound() {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  return GetJob(*stub, "job-0000000000000000").status.error_code();
}

grpc::StatusCode ProduceAlreadyExists() {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const std::string clip_id = UploadClip(*stub, MakeClip(1, 20)).response.clip_id();
  v1::SubmitJobRequest request = SubmitRequest(clip_id);
  request.set_request_id("readme-1");
  Submit(*stub, request);
  *request.mutable_operations() = WrapOperations(2);
  return Submit(*stub, request).status.error_code();
}

grpc::StatusCode ProduceFailedPrecondition() {
  GatedServer gated;
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 20)).response.clip_id();
  const JobOutcome job = Submit(*gated.stub, SubmitRequest(clip_id));
  gated.gate->WaitArrivals(1);
  const ResultOutcome early = GetResult(*gated.stub, job.job.job_id());  // it is RUNNING
  return early.status.error_code();
}

grpc::StatusCode ProduceResourceExhausted() {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  v1::SubmitJobRequest request = SubmitRequest("sha256:x");
  for (int i = 0; i < 65; ++i) (*request.mutable_labels())["k" + std::to_string(i)] = "v";
  return Submit(*stub, request).status.error_code();
}

grpc::StatusCode ProduceUnimplemented() {
  std::unique_ptr<server::Server> server = StartServer(TestServerOptions());
  grpc::GenericStub stub(Connect(server->target()));
  grpc::ClientContext context;
  SetDeadline(context);
  grpc::Slice empty("");
  grpc::ByteBuffer request(&empty, 1);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, "/tempokey.v1.MotionService/Teleport", grpc::StubOptions(), &request,
                 &response, [&done](grpc::Status status) { done.set_value(std::move(status)); });
  return done.get_future().get().error_code();
}

grpc::StatusCode ProduceUnavailable() {
  GatedServer gated;
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 20)).response.clip_id();
  Submit(*gated.stub, SubmitRequest(clip_id));
  gated.gate->WaitArrivals(1);  // a running job holds the drain open
  std::thread drain([&] { gated.server->Drain(); });
  auto channel = Connect(gated.server->target());
  const auto deadline = std::chrono::steady_clock::now() + kCallDeadline;
  while (CheckHealth(channel, server::kMotionServiceName).value_or(0) != 2 &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const grpc::StatusCode code = Submit(*gated.stub, SubmitRequest(clip_id)).status.error_code();
  gated.gate->Open();
  drain.join();
  return code;
}

grpc::StatusCode ProduceUnauthenticated() {
  server::ServerOptions options = TestServerOptions();
  options.auth_tokens = {"readme-token"};
  std::unique_ptr<server::Server> server = StartServer(options);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  v1::ServerInfo info;
  return stub->GetServerInfo(Context().get(), v1::GetServerInfoRequest(), &info).error_code();
}

grpc::StatusCode ProduceDeadlineExceeded() {
  server::ServerOptions options = TestServerOptions();
  options.stream_idle_timeout = std::chrono::milliseconds(200);
  std::unique_ptr<server::Server> server = StartServer(options);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  auto context = Context();
  v1::UploadClipResponse response;
  auto upload = stub->UploadClip(context.get(), &response);
  upload->Write(UploadRequests(MakeClip(1, 20), wire::kDefaultSliceBytes)[0]);  // then silence
  return upload->Finish().error_code();
}

grpc::StatusCode ProduceCancelled() {
  GatedServer gated;
  const std::string clip_id = UploadClip(*gated.stub, MakeClip(1, 20)).response.clip_id();
  Submit(*gated.stub, SubmitRequest(clip_id));
  Submit(*gated.stub, SubmitRequest(clip_id));
  gated.gate->WaitArrivals(2);  // both workers held: the next job stays queued
  const JobOutcome queued = Submit(*gated.stub, SubmitRequest(clip_id));
  v1::CancelJobRequest cancel;
  cancel.set_job_id(queued.job.job_id());
  v1::Job cancelled;
  gated.stub->CancelJob(Context().get(), cancel, &cancelled);
  return static_cast<grpc::StatusCode>(cancelled.error_code());
}

TEST(ReadmeTest, EveryStatusCodeListedIsProducedByTheServer) {
  const std::map<std::string, std::pair<grpc::StatusCode, Producer>> producers = {
      {"INVALID_ARGUMENT", {grpc::StatusCode::INVALID_ARGUMENT, ProduceInvalidArgument}},
      {"NOT_FOUND", {grpc::StatusCode::NOT_FOUND, ProduceNotFound}},
      {"ALREADY_EXISTS", {grpc::StatusCode::ALREADY_EXISTS, ProduceAlreadyExists}},
      {"FAILED_PRECONDITION", {grpc::StatusCode::FAILED_PRECONDITION, ProduceFailedPrecondition}},
      {"RESOURCE_EXHAUSTED", {grpc::StatusCode::RESOURCE_EXHAUSTED, ProduceResourceExhausted}},
      {"UNIMPLEMENTED", {grpc::StatusCode::UNIMPLEMENTED, ProduceUnimplemented}},
      {"UNAVAILABLE", {grpc::StatusCode::UNAVAILABLE, ProduceUnavailable}},
      {"UNAUTHENTICATED", {grpc::StatusCode::UNAUTHENTICATED, ProduceUnauthenticated}},
      {"DEADLINE_EXCEEDED", {grpc::StatusCode::DEADLINE_EXCEEDED, ProduceDeadlineExceeded}},
      {"CANCELLED", {grpc::StatusCode::CANCELLED, ProduceCancelled}},
  };
  std::set<std::string> listed;
  for (const auto& row : TableAfter(Readme(), "**Status codes.**")) listed.insert(FirstCode(row[0]));

  std::set<std::string> known;
  for (const auto& [name, producer] : producers) known.insert(name);
  EXPECT_EQ(listed, known) << "the README's status codes and the codes this test produces differ";
  for (const std::string& name : listed) {
    const auto it = producers.find(name);
    if (it == producers.end()) continue;
    EXPECT_EQ(it->second.second(), it->second.first) << name;
  }
}

// ---- the limits table -----------------------------------------------------------------------------

// A check of one limit: `at` is the README's value; true when `at` passes and `at + 1` is
// refused with RESOURCE_EXHAUSTED "over the limit of <at>".
using LimitCheck = std::function<void(v1::MotionService::Stub&, const std::string& clip_id, int at)>;

void ExpectLimit(const std::function<grpc::Status(int)>& call, int at) {
  const grpc::Status within = call(at);
  const grpc::Status beyond = call(at + 1);
  EXPECT_NE(within.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << within.error_message();
  EXPECT_THAT(beyond, GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                   HasSubstr("over the limit of " + std::to_string(at))));
}

TEST(ReadmeTest, LimitsTableMatchesWhatTheServerRefuses) {
  server::ServerOptions options = TestServerOptions();
  options.max_clip_samples = 5000;
  std::unique_ptr<server::Server> server = StartServer(options);
  ASSERT_NE(server, nullptr);
  auto stub = v1::MotionService::NewStub(Connect(server->target()));
  const std::string clip_id = UploadClip(*stub, MakeClip(1, 20)).response.clip_id();
  auto submit = [&](v1::SubmitJobRequest request) { return Submit(*stub, request).status; };
  const std::map<std::string, LimitCheck> checks = {
      {"labels per job",
       [&](auto&, const std::string& id, int at) {
         ExpectLimit([&](int n) {
           v1::SubmitJobRequest r = SubmitRequest(id);
           for (int i = 0; i < n; ++i) (*r.mutable_labels())["k" + std::to_string(i)] = "v";
           return submit(r);
         }, at);
       }},
      {"label key",
       [&](auto&, const std::string& id, int at) {
         ExpectLimit([&](int n) {
           v1::SubmitJobRequest r = SubmitRequest(id);
           (*r.mutable_labels())[std::string(static_cast<std::size_t>(n), 'k')] = "v";
           return submit(r);
         }, at);
       }},
      {"label value",
       [&](auto&, const std::string& id, int at) {
         ExpectLimit([&](int n) {
           v1::SubmitJobRequest r = SubmitRequest(id);
           (*r.mutable_labels())["k"] = std::string(static_cast<std::size_t>(n), 'v');
           return submit(r);
         }, at);
       }},
      {"`request_id`",
       [&](auto&, const std::string& id, int at) {
         ExpectLimit([&](int n) {
           v1::SubmitJobRequest r = SubmitRequest(id);
           r.set_request_id(std::string(static_cast<std::size_t>(n), 'r'));
           return submit(r);
         }, at);
       }},
      {"`job_id`, `clip_id`",
       [&](auto& s, const std::string&, int at) {
         // Within the limit an unknown id is NOT_FOUND; beyond it, refused before any lookup.
         ExpectLimit([&](int n) { return GetJob(s, std::string(static_cast<std::size_t>(n), 'j')).status; }, at);
         ExpectLimit([&](int n) {
           return submit(SubmitRequest(std::string(static_cast<std::size_t>(n), 'c')));
         }, at);
       }},
      {"operations per pipeline",
       [&](auto&, const std::string& id, int at) {
         ExpectLimit([&](int n) { return submit(SubmitRequest(id, WrapOperations(n))); }, at);
       }},
      {"clip samples (frames × channels)",
       [&](auto& s, const std::string&, int) {
         // The value is the flag, 5000 here: 833 frames x 6 channels fit, 834 do not.
         EXPECT_TRUE(UploadClip(s, MakeClip(1, 833)).status.ok());
         EXPECT_THAT(UploadClip(s, MakeClip(1, 834)).status,
                     GrpcStatusIs(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                  HasSubstr("834 frames x 6 channels, over the limit of 5000")));
       }},
      // Refused at these values by the core tests (clip, BVH and retime limits) and
      // wire_codec_test / protocol_test; here the values are the server's.
      {"frames per clip",
       [&](auto&, const std::string&, int at) { EXPECT_EQ(at, core::ClipLimits{}.max_frames); }},
      {"channels per clip",
       [&](auto&, const std::string&, int at) { EXPECT_EQ(at, core::ClipLimits{}.max_channels); }},
      {"joints per clip",
       [&](auto&, const std::string&, int at) { EXPECT_EQ(at, core::ClipLimits{}.max_joints); }},
      {"speed knots, time-map keys, holds, pins per retime (each)",
       [&](auto&, const std::string&, int at) {
         EXPECT_EQ(at, static_cast<int>(core::retime_internal::kMaxWarpItems));
       }},
      {"items inside one request message (joints, channels, markers, knots, names, unknown "
       "fields, ...), counted before it is read",
       [&](auto&, const std::string&, int at) { EXPECT_EQ(at, server::kMaxMessageItems); }},
      {"jobs per `ListJobs` page",
       [&](auto&, const std::string&, int at) { EXPECT_EQ(at, server::JobManager::kMaxPageSize); }},
      {"bytes per `ListJobs` page",
       [&](auto&, const std::string&, int at) {
         // Exercised in memory_test.cc (ListJobsPageTest): here the value is the server's.
         EXPECT_EQ(at, server::kMaxListPageBytes);
       }},
  };

  std::set<std::string> listed;
  for (const auto& row : TableAfter(Readme(), "**Limits.**")) {
    ASSERT_GE(row.size(), 2u);
    listed.insert(row[0]);
    const auto check = checks.find(row[0]);
    if (check == checks.end()) continue;
    int value = 0;
    const std::string code = FirstCode(row[1]);
    if (!absl::SimpleAtoi(code, &value)) value = 0;  // a flag name: the check knows the value
    SCOPED_TRACE(row[0]);
    check->second(*stub, clip_id, value);
  }
  std::set<std::string> known;
  for (const auto& [name, check] : checks) known.insert(name);
  EXPECT_EQ(listed, known);
}

// ---- the server-flags table -----------------------------------------------------------------------

// --name -> default, from `tempokey-server --help`: one line per flag of server/main.cc,
// "  --name   help text (default: value)", "none" for an empty default.
std::map<std::string, std::string> ServerFlags() {
  const ProcessResult help = RunProcess({ServerBinary(), "--help"}, MakeTempDir());
  EXPECT_EQ(help.exit_code, 0) << help.err;
  std::map<std::string, std::string> flags;
  const std::regex flag(R"(^  (--[a-z_0-9]+) .*\(default: (.*)\)$)");
  for (absl::string_view view : absl::StrSplit(help.out, '\n')) {
    const std::string line(view);
    std::smatch match;
    if (!std::regex_match(line, match, flag)) continue;
    flags[match[1].str()] = match[2].str() == "none" ? "" : match[2].str();
  }
  return flags;
}

TEST(ReadmeTest, ServerFlagsTableIsTheBinarysFlagsWithTheirDefaults) {
  const std::map<std::string, std::string> binary = ServerFlags();
  std::map<std::string, std::string> readme;
  for (const auto& row : TableAfter(Readme(), "**Server flags**")) {
    ASSERT_GE(row.size(), 2u);
    readme[FirstCode(row[0])] = row[1] == "none" ? "" : FirstCode(row[1]);
  }

  EXPECT_GT(binary.size(), 20u);
  EXPECT_EQ(readme, binary);
}

}  // namespace
}  // namespace tempokey::testing
