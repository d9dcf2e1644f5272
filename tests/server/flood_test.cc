// A bounded flood against the real tempokey-server process (SPEC 5 and 8): 2 000 submits from 32
// concurrent clients, each with its own channel, against a queue of 64. Every accepted job must
// end with its own correct result (each submit carries a different clip, so a mix-up shows), every
// refused submit must be RESOURCE_EXHAUSTED with a retry hint, and the server's peak resident set
// must stay bounded. The figures are printed for the record; nothing here measures time.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <deque>
#include <memory>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "gtest/gtest.h"
#include "proto/retry_hint.h"
#include "tempokey/core/model/euler_filter.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tests/server/test_clips.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

constexpr int kClients = 32;
constexpr int kSubmits = 2000;
constexpr int kQueueCapacity = 64;
// Accepted jobs a client keeps in flight before it collects its oldest: 32 x 4 = 128 outstanding
// jobs, twice what the queue and two workers hold, so the queue does fill.
constexpr std::size_t kWindow = 4;
// A job is milliseconds of real work (about 11 ms here), so that the clients' 128 outstanding
// jobs outrun the two workers and the queue fills: 63 Euler filter passes and a wrap over 33
// channels x 800 frames (211 kB inline). Wrap passes alone (std::remainder, 12 ns a sample) were
// that slow until the wrap ran in vectors (WrapDegrees(), 1 ns): then the queue never filled.
constexpr int kFilterPasses = 63;
constexpr std::int64_t kFrames = 800;
// The server holds at most 64 queued + 2 running jobs and the clients' 128 unfetched results,
// each well under 1 MB, besides its own ~30 MB; 512 MiB bounds it with a wide margin while still
// catching anything that keeps every clip or result of the flood (2 000 x 0.2 MB and more).
// Sanitizer builds add ASan's quarantine (test_clips.h).
constexpr std::int64_t kPeakRssBoundKiB = 512 * 1024 + kSanitizerRssAllowanceKiB;
// The longest a refused client waits before its next submit, whatever the hint says.
constexpr std::chrono::milliseconds kMaxBackoff{20};

core::Clip ClipOfSubmit(int index) { return MakeClip(10, kFrames, 0.001 * index); }

std::vector<core::PipelineStep> FloodSteps() {
  std::vector<core::PipelineStep> steps(kFilterPasses, core::ConvertStep{.euler_filter = true});
  steps.push_back(core::ConvertStep{.wrap_rotations = true});
  return steps;
}

// What FloodSteps() make of submit `index`'s clip: the Euler filter leaves a filtered clip as it
// is (every submit's clip, checked when this test was written), so one pass stands for 63; the
// wrap is the independent one of test_clips.h. A submit whose clip the filter changed again would
// fail its check, not pass unchecked.
core::Clip ExpectedResult(int index) {
  core::Clip clip = ClipOfSubmit(index);
  if (!core::ApplyEulerFilter(clip).ok()) return {};
  return WrappedCopy(std::move(clip));
}

struct Tally {
  int accepted = 0;
  int rejected = 0;
  int rejected_without_hint = 0;
  int verified = 0;
  std::vector<std::string> problems;
};

// Waits for one accepted job, checks its result against the clip that was sent, deletes it.
void Collect(const client::Client& client, int index, const std::string& job_id, Tally& tally) {
  absl::StatusOr<v1::Job> done = client.WatchJob(job_id, {});
  if (!done.ok() || done->state() != v1::JOB_STATE_SUCCEEDED) {
    tally.problems.push_back(absl::StrCat("submit ", index, " (", job_id, ") did not succeed: ",
                                          done.ok() ? done->error_message() : done.status().ToString()));
    return;
  }
  const auto label = done->labels().find("submit");
  if (label == done->labels().end() || label->second != std::to_string(index)) {
    tally.problems.push_back(absl::StrCat("submit ", index, ": job ", job_id, " has other labels"));
    return;
  }
  absl::StatusOr<core::PipelineResult> result = client.GetJobResult(job_id);
  if (!result.ok() || !std::holds_alternative<core::Clip>(result->output)) {
    tally.problems.push_back(absl::StrCat("submit ", index, ": no clip result: ",
                                          result.ok() ? "keyed" : result.status().ToString()));
    return;
  }
  const core::Clip expected = ExpectedResult(index);
  const core::Clip& got = std::get<core::Clip>(result->output);
  bool same = got.frame_count == expected.frame_count &&
              got.channels.size() == expected.channels.size();
  for (std::size_t c = 0; same && c < expected.channels.size(); ++c) {
    same = got.channels[c].samples == expected.channels[c].samples;
  }
  if (!same) {
    tally.problems.push_back(absl::StrCat("submit ", index, ": result is not its own clip"));
    return;
  }
  if (absl::Status deleted = client.DeleteJob(job_id); !deleted.ok()) {
    tally.problems.push_back(absl::StrCat("submit ", index, ": delete: ", deleted.ToString()));
    return;
  }
  ++tally.verified;
}

// One client's share of the flood: submits kSubmits / kClients clips, keeps kWindow accepted jobs
// in flight, and after a refusal waits as the server's hint says (capped) before the next submit.
void RunClient(const std::string& target, int first_index, Tally& tally) {
  client::ClientOptions options;
  options.target = target;
  absl::StatusOr<std::unique_ptr<client::Client>> client = client::Client::Connect(options);
  if (!client.ok()) {
    tally.problems.push_back(client.status().ToString());
    return;
  }
  const std::vector<core::PipelineStep> steps = FloodSteps();
  std::deque<std::pair<int, std::string>> in_flight;
  for (int index = first_index; index < kSubmits; index += kClients) {
    client::SubmitOptions submit;
    submit.labels["submit"] = std::to_string(index);
    absl::StatusOr<v1::Job> job = (*client)->SubmitInlineJob(ClipOfSubmit(index), steps, submit);
    if (job.ok()) {
      ++tally.accepted;
      in_flight.emplace_back(index, job->job_id());
      if (in_flight.size() >= kWindow) {
        Collect(**client, in_flight.front().first, in_flight.front().second, tally);
        in_flight.pop_front();
      }
    } else if (job.status().code() == absl::StatusCode::kResourceExhausted) {
      ++tally.rejected;
      const std::optional<std::chrono::milliseconds> hint = wire::GetRetryAfter(job.status());
      if (!hint) ++tally.rejected_without_hint;
      std::this_thread::sleep_for(std::min(hint.value_or(kMaxBackoff), kMaxBackoff));
    } else {
      tally.problems.push_back(absl::StrCat("submit ", index, ": ", job.status().ToString()));
    }
  }
  for (const auto& [index, job_id] : in_flight) Collect(**client, index, job_id, tally);
}

TEST(FloodTest, EveryAcceptedJobCompletesCorrectlyEveryRefusalIsResourceExhaustedMemoryBounded) {
  absl::StatusOr<std::unique_ptr<ServerProcess>> server = ServerProcess::Start(
      MakeTempDir(), {"--workers", "2", "--queue_capacity", std::to_string(kQueueCapacity)});
  ASSERT_TRUE(server.ok()) << server.status();
  const std::string status_path = absl::StrCat("/proc/", (*server)->pid(), "/status");

  std::vector<Tally> tallies(kClients);
  std::vector<std::thread> clients;
  for (int c = 0; c < kClients; ++c) {
    clients.emplace_back(RunClient, (*server)->target(), c, std::ref(tallies[c]));
  }
  for (std::thread& t : clients) t.join();
  const std::int64_t peak_rss_kib = PeakRssKiB(status_path);
  const int exit_code = (*server)->Stop();

  Tally total;
  for (const Tally& t : tallies) {
    total.accepted += t.accepted;
    total.rejected += t.rejected;
    total.rejected_without_hint += t.rejected_without_hint;
    total.verified += t.verified;
    total.problems.insert(total.problems.end(), t.problems.begin(), t.problems.end());
  }
  std::printf("flood: %d submits from %d clients, queue %d: %d accepted and verified %d, "
              "%d refused (RESOURCE_EXHAUSTED); server peak RSS %.1f MiB\n",
              kSubmits, kClients, kQueueCapacity, total.accepted, total.verified, total.rejected,
              static_cast<double>(peak_rss_kib) / 1024.0);
  RecordProperty("accepted", total.accepted);
  RecordProperty("rejected", total.rejected);
  RecordProperty("server_peak_rss_kib", static_cast<int>(peak_rss_kib));

  EXPECT_TRUE(total.problems.empty()) << total.problems.size() << " problems, first: "
                                      << (total.problems.empty() ? "" : total.problems.front());
  EXPECT_EQ(total.accepted + total.rejected, kSubmits);
  EXPECT_EQ(total.verified, total.accepted);
  EXPECT_GT(total.rejected, 0) << "the queue never filled, so admission was not exercised";
  EXPECT_EQ(total.rejected_without_hint, 0);
  EXPECT_GT(peak_rss_kib, 0);
  EXPECT_LT(peak_rss_kib, kPeakRssBoundKiB);
  EXPECT_EQ(exit_code, 0) << (*server)->log();
}

}  // namespace
}  // namespace tempokey::testing
