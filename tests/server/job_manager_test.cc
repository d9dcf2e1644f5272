// JobManager over a real JobPool and core::RunPipeline: lifecycle, cancellation, dedupe, paging,
// retention and watchers. No gRPC: runs under ThreadSanitizer.
#include "server/job_manager.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_replace.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/job_pool.h"
#include "server/memory_budget.h"
#include "tests/server/test_clips.h"

namespace tempokey::server {
namespace {

using ::tempokey::testing::MakeClip;
using ::tempokey::testing::StartGate;
using ::tempokey::testing::WrappedCopy;
using ::testing::ElementsAre;
using ::testing::HasSubstr;

constexpr auto kHangGuard = std::chrono::seconds(60);

// A retime of this many speed knots: 2.4 MB of operations in one step.
constexpr int kManyKnots = 100'000;
constexpr std::int64_t kManyKnotsBytes =
    std::int64_t{kManyKnots} * static_cast<std::int64_t>(sizeof(core::SpeedKnot));
core::RetimeStep RetimeOfManyKnots() {
  core::RetimeStep retime;
  retime.warp.domain = core::WarpDomain::kSpeedOverSource;
  for (int k = 0; k < kManyKnots; ++k) {
    retime.warp.speed.push_back(core::SpeedKnot{.time = {.value = k * 1e-4}, .speed = 1.0});
  }
  return retime;
}

// Records every update in arrival order; closes are recorded too.
class RecordingWatcher : public JobWatcher {
 public:
  void OnJobUpdate(const JobSnapshot& snapshot) override {
    std::lock_guard lock(mu_);
    versions_.push_back(snapshot.version);
    states_.push_back(snapshot.state);
    cv_.notify_all();
  }
  void OnWatchClosed(const absl::Status& status) override {
    std::lock_guard lock(mu_);
    closed_ = status;
    cv_.notify_all();
  }
  bool WaitForState(JobState state) {
    std::unique_lock lock(mu_);
    return cv_.wait_for(lock, kHangGuard, [&] {
      return std::find(states_.begin(), states_.end(), state) != states_.end();
    });
  }
  std::vector<std::int64_t> versions() {
    std::lock_guard lock(mu_);
    return versions_;
  }
  std::optional<absl::Status> closed() {
    std::lock_guard lock(mu_);
    return closed_;
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<std::int64_t> versions_;
  std::vector<JobState> states_;
  std::optional<absl::Status> closed_;
};

class JobManagerTest : public ::testing::Test {
 protected:
  void Start(JobManagerOptions options, int workers = 1, int queue = 8) {
    pool_ = std::make_unique<JobPool>(workers, queue);
    options.clock = [this] { return now_.load(); };
    manager_ = std::make_unique<JobManager>(pool_.get(), std::move(options));
  }

  void TearDown() override {
    if (gate_) gate_->Open();
    if (pool_) pool_->Shutdown();
  }

  JobManagerOptions GatedOptions() {
    gate_ = std::make_shared<StartGate>();
    JobManagerOptions options;
    options.on_job_start = [gate = gate_](std::string_view id) { gate->Arrive(id); };
    return options;
  }

  JobSnapshot SubmitWrap(std::map<std::string, std::string> labels = {},
                         std::string request_id = "", int joints = 2) {
    JobSpec spec{.clip_id = "sha256:test",
                 .steps = {core::ConvertStep{.wrap_rotations = true}},
                 .labels = std::move(labels),
                 .request_id = std::move(request_id)};
    absl::StatusOr<JobSnapshot> job =
        manager_->Submit(std::move(spec), std::make_shared<const core::Clip>(MakeClip(joints, 50)));
    EXPECT_TRUE(job.ok()) << job.status();
    return job.ok() ? *job : JobSnapshot{};
  }

  // Polls until the job is terminal (a deadline guards against hangs; no timing is asserted).
  JobSnapshot WaitTerminal(const std::string& id) { return WaitTerminalOf(id, ""); }
  JobSnapshot WaitTerminalOf(const std::string& id, const std::string& owner) {
    const auto deadline = std::chrono::steady_clock::now() + kHangGuard;
    for (;;) {
      absl::StatusOr<JobSnapshot> job = manager_->Get(id, owner);
      if (!job.ok()) {
        ADD_FAILURE() << job.status();
        return {};
      }
      if (IsTerminal(job->state)) return *job;
      if (std::chrono::steady_clock::now() > deadline) {
        ADD_FAILURE() << "job " << id << " did not end";
        return *job;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

  // Starts the manager (with `options`) on a memory budget of `bytes` for its jobs. The budget is
  // declared before the pool and the manager, so it outlives every reservation they hold.
  MemoryBudget& StartWithBudget(std::int64_t bytes, JobManagerOptions options = {}) {
    budget_ = std::make_unique<MemoryBudget>(bytes);
    options.budget = budget_.get();
    Start(std::move(options));
    return *budget_;
  }

  std::atomic<SystemTime> now_{SystemTime(std::chrono::hours(500'000))};
  std::unique_ptr<MemoryBudget> budget_;
  std::shared_ptr<StartGate> gate_;
  std::unique_ptr<JobPool> pool_;
  std::unique_ptr<JobManager> manager_;
};

TEST_F(JobManagerTest, JobRunsToSuccessWithTheCorrectResult) {
  Start({});

  JobSnapshot submitted = SubmitWrap();
  JobSnapshot done = WaitTerminal(submitted.job_id);

  EXPECT_EQ(submitted.state, JobState::kQueued);
  EXPECT_EQ(submitted.version, 1);
  EXPECT_THAT(submitted.job_id, ::testing::MatchesRegex("job-[0-9a-f]{16}"));
  ASSERT_EQ(done.state, JobState::kSucceeded);
  EXPECT_EQ(done.progress, 1.0);
  ASSERT_NE(done.result, nullptr);
  EXPECT_EQ(std::get<core::Clip>(done.result->output), WrappedCopy(MakeClip(2, 50)));
  EXPECT_TRUE(done.start_time.has_value());
  EXPECT_TRUE(done.end_time.has_value());
  EXPECT_GT(done.version, submitted.version);
}

TEST_F(JobManagerTest, WatcherSeesStrictlyIncreasingVersionsEndingTerminal) {
  JobManagerOptions options = GatedOptions();
  Start(std::move(options));
  JobSnapshot job = SubmitWrap({}, "", /*joints=*/40);
  auto watcher = std::make_shared<RecordingWatcher>();
  absl::StatusOr<JobSnapshot> initial = manager_->Watch(job.job_id, watcher);
  ASSERT_TRUE(initial.ok());

  gate_->Open();
  ASSERT_TRUE(watcher->WaitForState(JobState::kSucceeded));
  manager_->Unwatch(job.job_id, watcher.get());

  std::vector<std::int64_t> versions = watcher->versions();
  ASSERT_GE(versions.size(), 2u);  // RUNNING, then SUCCEEDED (plus progress)
  for (std::size_t i = 1; i < versions.size(); ++i) EXPECT_LT(versions[i - 1], versions[i]);
  EXPECT_GT(versions.front(), initial->version);
}

TEST_F(JobManagerTest, CancelledQueuedJobNeverRuns) {
  Start(GatedOptions());
  JobSnapshot blocker = SubmitWrap();
  ASSERT_TRUE(gate_->WaitArrivals(1));  // the only worker is held
  JobSnapshot queued = SubmitWrap();

  absl::StatusOr<JobSnapshot> cancelled = manager_->Cancel(queued.job_id);
  absl::StatusOr<JobSnapshot> again = manager_->Cancel(queued.job_id);
  gate_->Open();
  WaitTerminal(blocker.job_id);
  ASSERT_TRUE(pool_->WaitIdle(std::chrono::steady_clock::now() + kHangGuard));

  ASSERT_TRUE(cancelled.ok());
  EXPECT_EQ(cancelled->state, JobState::kCancelled);
  EXPECT_THAT(std::string(cancelled->error.message()), HasSubstr("cancelled before it started"));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->version, cancelled->version);  // idempotent: no change the second time
  absl::StatusOr<JobSnapshot> final_state = manager_->Get(queued.job_id);
  EXPECT_EQ(final_state->state, JobState::kCancelled);
  EXPECT_FALSE(final_state->start_time.has_value());  // it never started
}

TEST_F(JobManagerTest, CancelledRunningJobStopsAsCancelled) {
  Start(GatedOptions());
  JobSnapshot job = SubmitWrap();
  ASSERT_TRUE(gate_->WaitArrivals(1));

  absl::StatusOr<JobSnapshot> cancelling = manager_->Cancel(job.job_id);
  gate_->Open();
  JobSnapshot done = WaitTerminal(job.job_id);

  ASSERT_TRUE(cancelling.ok());
  EXPECT_EQ(cancelling->state, JobState::kRunning);
  EXPECT_EQ(cancelling->stage, "cancelling");
  EXPECT_EQ(done.state, JobState::kCancelled);
  EXPECT_EQ(done.error.code(), absl::StatusCode::kCancelled);
  EXPECT_EQ(done.result, nullptr);
}

TEST_F(JobManagerTest, DuplicateRequestIdRunsOnce) {
  std::atomic<int> ended{0};
  JobManagerOptions options;
  options.on_job_end = [&](const JobSnapshot&, auto, auto) { ended++; };
  Start(std::move(options));

  JobSnapshot first = SubmitWrap({}, "req-1");
  bool deduplicated = false;
  absl::StatusOr<JobSnapshot> second = manager_->Submit(
      JobSpec{.clip_id = "other", .steps = {core::ConvertStep{}}, .labels = {}, .request_id = "req-1"},
      std::make_shared<const core::Clip>(MakeClip(1, 5)), &deduplicated);
  WaitTerminal(first.job_id);
  ASSERT_TRUE(pool_->WaitIdle(std::chrono::steady_clock::now() + kHangGuard));

  ASSERT_TRUE(second.ok());
  EXPECT_TRUE(deduplicated);
  EXPECT_EQ(second->job_id, first.job_id);
  EXPECT_EQ(manager_->job_count(), 1);
  EXPECT_EQ(ended.load(), 1);
}

TEST_F(JobManagerTest, ListPagesInSubmissionOrderAndFilters) {
  Start({});
  std::vector<std::string> ids;
  for (int i = 0; i < 7; ++i) {
    ids.push_back(SubmitWrap({{"batch", i % 2 == 0 ? "even" : "odd"}}).job_id);
  }
  for (const std::string& id : ids) WaitTerminal(id);

  absl::StatusOr<ListJobsPage> page1 = manager_->List({.page_size = 3});
  absl::StatusOr<ListJobsPage> page2 = manager_->List({.page_size = 3, .page_token = page1->next_page_token});
  absl::StatusOr<ListJobsPage> page3 = manager_->List({.page_size = 3, .page_token = page2->next_page_token});
  absl::StatusOr<ListJobsPage> odd = manager_->List({.labels = {{"batch", "odd"}}});
  absl::StatusOr<ListJobsPage> queued = manager_->List({.states = {JobState::kQueued}});

  auto ids_of = [](const ListJobsPage& page) {
    std::vector<std::string> out;
    for (const JobSnapshot& job : page.jobs) out.push_back(job.job_id);
    return out;
  };
  ASSERT_TRUE(page1.ok() && page2.ok() && page3.ok() && odd.ok() && queued.ok());
  EXPECT_THAT(ids_of(*page1), ElementsAre(ids[0], ids[1], ids[2]));
  EXPECT_THAT(ids_of(*page2), ElementsAre(ids[3], ids[4], ids[5]));
  EXPECT_THAT(ids_of(*page3), ElementsAre(ids[6]));
  EXPECT_TRUE(page3->next_page_token.empty());
  EXPECT_THAT(ids_of(*odd), ElementsAre(ids[1], ids[3], ids[5]));
  EXPECT_TRUE(queued->jobs.empty());
}

TEST_F(JobManagerTest, BadPageTokenIsRefused) {
  Start({});

  absl::StatusOr<ListJobsPage> page = manager_->List({.page_token = "garbage"});

  EXPECT_EQ(page.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(page.status().message()), HasSubstr("page_token \"garbage\""));
}

TEST_F(JobManagerTest, DeleteRefusesRunningJobsAndRemovesFinishedOnes) {
  Start(GatedOptions());
  JobSnapshot job = SubmitWrap();
  ASSERT_TRUE(gate_->WaitArrivals(1));

  absl::Status while_running = manager_->Delete(job.job_id);
  gate_->Open();
  WaitTerminal(job.job_id);
  absl::Status after = manager_->Delete(job.job_id);

  EXPECT_EQ(while_running.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(while_running.message()), HasSubstr("is RUNNING; cancel it"));
  EXPECT_TRUE(after.ok());
  EXPECT_EQ(manager_->Get(job.job_id).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(manager_->Delete(job.job_id).code(), absl::StatusCode::kNotFound);
}

TEST_F(JobManagerTest, FinishedJobsExpireAfterTheirTtl) {
  JobManagerOptions options;
  options.job_ttl = std::chrono::seconds(60);
  Start(std::move(options));
  JobSnapshot job = SubmitWrap();
  WaitTerminal(job.job_id);

  now_.store(now_.load() + std::chrono::seconds(59));
  const bool kept = manager_->Get(job.job_id).ok();
  now_.store(now_.load() + std::chrono::seconds(2));
  const absl::Status gone = manager_->Get(job.job_id).status();

  EXPECT_TRUE(kept);
  EXPECT_EQ(gone.code(), absl::StatusCode::kNotFound);
}

TEST_F(JobManagerTest, ResultCapEvictsOldestButNeverAWatchedJob) {
  JobManagerOptions options;
  options.max_stored_results = 2;
  Start(std::move(options));
  JobSnapshot watched = SubmitWrap();
  auto watcher = std::make_shared<RecordingWatcher>();
  ASSERT_TRUE(manager_->Watch(watched.job_id, watcher).ok());
  WaitTerminal(watched.job_id);
  JobSnapshot second = SubmitWrap();
  WaitTerminal(second.job_id);
  JobSnapshot third = SubmitWrap();
  WaitTerminal(third.job_id);

  const bool watched_kept = manager_->Get(watched.job_id).ok();
  const bool second_kept = manager_->Get(second.job_id).ok();
  manager_->Unwatch(watched.job_id, watcher.get());
  JobSnapshot fourth = SubmitWrap();
  WaitTerminal(fourth.job_id);

  EXPECT_TRUE(watched_kept);
  EXPECT_FALSE(second_kept);  // the oldest unwatched one went first
  EXPECT_EQ(manager_->Get(watched.job_id).status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(manager_->Get(third.job_id).ok());
  EXPECT_TRUE(manager_->Get(fourth.job_id).ok());
}

TEST_F(JobManagerTest, ResultOfUnfinishedOrFailedJobIsAPreconditionError) {
  Start(GatedOptions());
  JobSnapshot job = SubmitWrap();
  ASSERT_TRUE(gate_->WaitArrivals(1));

  absl::Status early = manager_->Result(job.job_id).status();
  ASSERT_TRUE(manager_->Cancel(job.job_id).ok());
  gate_->Open();
  WaitTerminal(job.job_id);
  absl::Status cancelled = manager_->Result(job.job_id).status();

  EXPECT_EQ(early.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(early.message()), HasSubstr("has no result yet: it is RUNNING"));
  EXPECT_EQ(cancelled.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(cancelled.message()), HasSubstr("was cancelled"));
}

TEST_F(JobManagerTest, DrainClosesWatchesAndRefusesNewJobsWhileRunningOnesFinish) {
  Start(GatedOptions());
  JobSnapshot job = SubmitWrap();
  ASSERT_TRUE(gate_->WaitArrivals(1));
  auto watcher = std::make_shared<RecordingWatcher>();
  ASSERT_TRUE(manager_->Watch(job.job_id, watcher).ok());

  manager_->BeginDrain();
  absl::StatusOr<JobSnapshot> refused = manager_->Submit(
      JobSpec{.clip_id = "x", .steps = {core::ConvertStep{}}, .labels = {}, .request_id = ""},
      std::make_shared<const core::Clip>(MakeClip(1, 5)));
  absl::Status watch_refused = manager_->Watch(job.job_id, std::make_shared<RecordingWatcher>()).status();
  gate_->Open();
  JobSnapshot done = WaitTerminal(job.job_id);

  ASSERT_TRUE(watcher->closed().has_value());
  EXPECT_EQ(watcher->closed()->code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(watch_refused.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(done.state, JobState::kSucceeded);
}

TEST_F(JobManagerTest, CancelAllCancelsQueuedAndRunningJobs) {
  Start(GatedOptions());
  JobSnapshot running = SubmitWrap();
  ASSERT_TRUE(gate_->WaitArrivals(1));
  JobSnapshot queued = SubmitWrap();

  manager_->CancelAll();
  gate_->Open();

  EXPECT_EQ(WaitTerminal(running.job_id).state, JobState::kCancelled);
  EXPECT_EQ(WaitTerminal(queued.job_id).state, JobState::kCancelled);
}

TEST_F(JobManagerTest, ManyThreadsSubmittingWatchingAndCancellingStayConsistent) {
  Start({}, /*workers=*/3, /*queue=*/32);
  std::atomic<int> accepted{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 6; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 40; ++i) {
        absl::StatusOr<JobSnapshot> job = manager_->Submit(
            JobSpec{.clip_id = "c",
                    .steps = {core::ConvertStep{.wrap_rotations = true}},
                    .labels = {{"thread", std::to_string(t)}},
                    .request_id = ""},
            std::make_shared<const core::Clip>(MakeClip(1, 20)));
        if (!job.ok()) {
          EXPECT_EQ(job.status().code(), absl::StatusCode::kResourceExhausted);
          continue;
        }
        accepted++;
        auto watcher = std::make_shared<RecordingWatcher>();
        (void)manager_->Watch(job->job_id, watcher);
        if (i % 3 == 0) (void)manager_->Cancel(job->job_id);
        (void)manager_->List({.labels = {{"thread", std::to_string(t)}}});
        manager_->Unwatch(job->job_id, watcher.get());
      }
    });
  }
  for (std::thread& t : threads) t.join();
  ASSERT_TRUE(pool_->WaitIdle(std::chrono::steady_clock::now() + kHangGuard));

  absl::StatusOr<ListJobsPage> all = manager_->List({.page_size = 1000});
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(static_cast<int>(all->jobs.size()), accepted.load());
  for (const JobSnapshot& job : all->jobs) EXPECT_TRUE(IsTerminal(job.state)) << job.job_id;
}

TEST_F(JobManagerTest, RequestIdReusedForAnotherRequestIsRefusedNotDeduplicated) {
  Start(GatedOptions());
  auto submit = [&](std::string digest) {
    return manager_->Submit(JobSpec{.clip_id = "sha256:test",
                                    .steps = {core::ConvertStep{}},
                                    .request_id = "req-7",
                                    .request_digest = std::move(digest)},
                            std::make_shared<const core::Clip>(MakeClip(1, 10)));
  };

  absl::StatusOr<JobSnapshot> first = submit("digest-a");
  absl::StatusOr<JobSnapshot> retried = submit("digest-a");
  absl::StatusOr<JobSnapshot> different = submit("digest-b");
  absl::StatusOr<std::optional<JobSnapshot>> found = manager_->FindByRequestId("", "req-7", "digest-a");
  absl::StatusOr<std::optional<JobSnapshot>> mismatch =
      manager_->FindByRequestId("", "req-7", "digest-b");

  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(retried.ok()) << retried.status();
  EXPECT_EQ(retried->job_id, first->job_id);
  EXPECT_EQ(different.status().code(), absl::StatusCode::kAlreadyExists);
  EXPECT_THAT(std::string(different.status().message()),
              HasSubstr("request_id \"req-7\" already named job " + first->job_id));
  ASSERT_TRUE(found.ok() && found->has_value());
  EXPECT_EQ((*found)->job_id, first->job_id);
  EXPECT_EQ(mismatch.status().code(), absl::StatusCode::kAlreadyExists);
  EXPECT_EQ(manager_->job_count(), 1);
}

TEST_F(JobManagerTest, JobsOfAnotherOwnerAnswerLikeUnknownJobs) {
  Start({});
  absl::StatusOr<JobSnapshot> mine = manager_->Submit(
      JobSpec{.clip_id = "sha256:test", .steps = {core::ConvertStep{}}, .request_id = "r",
              .owner = "token-aaaa"},
      std::make_shared<const core::Clip>(MakeClip(1, 10)));
  ASSERT_TRUE(mine.ok()) << mine.status();
  WaitTerminalOf(mine->job_id, "token-aaaa");
  const std::string unknown_message =
      std::string(manager_->Get("job-ffffffffffffffff", "token-bbbb").status().message());

  const absl::Status get = manager_->Get(mine->job_id, "token-bbbb").status();
  const absl::Status cancel = manager_->Cancel(mine->job_id, "token-bbbb").status();
  const absl::Status result = manager_->Result(mine->job_id, "token-bbbb").status();
  const absl::Status watch =
      manager_->Watch(mine->job_id, std::make_shared<RecordingWatcher>(), "token-bbbb").status();
  const absl::Status del = manager_->Delete(mine->job_id, "token-bbbb");
  absl::StatusOr<ListJobsPage> theirs = manager_->List({}, "token-bbbb");
  absl::StatusOr<ListJobsPage> own = manager_->List({}, "token-aaaa");
  // The same request_id is another owner's own: no deduplication across owners.
  absl::StatusOr<JobSnapshot> same_request_id = manager_->Submit(
      JobSpec{.clip_id = "sha256:test", .steps = {core::ConvertStep{}}, .request_id = "r",
              .owner = "token-bbbb"},
      std::make_shared<const core::Clip>(MakeClip(1, 10)));

  for (const absl::Status& status : {get, cancel, result, watch, del}) {
    EXPECT_EQ(status.code(), absl::StatusCode::kNotFound) << status;
    EXPECT_EQ(status.message(),
              absl::StrReplaceAll(unknown_message, {{"job-ffffffffffffffff", mine->job_id}}));
  }
  ASSERT_TRUE(theirs.ok() && own.ok());
  EXPECT_TRUE(theirs->jobs.empty());
  ASSERT_EQ(own->jobs.size(), 1u);
  EXPECT_TRUE(manager_->Get(mine->job_id, "token-aaaa").ok());
  ASSERT_TRUE(same_request_id.ok()) << same_request_id.status();
  EXPECT_NE(same_request_id->job_id, mine->job_id);
}

TEST_F(JobManagerTest, EndIsReportedBeforeAnyoneSeesTheTerminalState) {
  std::atomic<int> reported{0};
  JobManagerOptions options;
  options.on_job_end = [&](const JobSnapshot&, auto, auto) { reported++; };
  Start(std::move(options));

  for (int i = 0; i < 20; ++i) {
    const JobSnapshot job = SubmitWrap();
    WaitTerminal(job.job_id);  // polls Get() until it sees the terminal state

    // Whoever saw the job end (a watcher, GetJob, a metrics scrape) sees it counted.
    EXPECT_EQ(reported.load(), i + 1);
  }
}

TEST_F(JobManagerTest, StoredJobsCountTheirOperationsInTheMemoryBudget) {
  MemoryBudget& budget = StartWithBudget(std::int64_t{8} << 20, GatedOptions());
  const core::RetimeStep retime = RetimeOfManyKnots();
  auto submit = [&](int knots_copies) {
    std::vector<core::PipelineStep> steps(static_cast<std::size_t>(knots_copies), retime);
    return manager_->Submit(JobSpec{.clip_id = "sha256:test", .steps = std::move(steps)},
                            std::make_shared<const core::Clip>(MakeClip(1, 10)));
  };

  absl::StatusOr<JobSnapshot> one = submit(1);
  const std::int64_t held = budget.used(MemoryUse::kJob);
  absl::StatusOr<JobSnapshot> too_big = submit(3);  // 7.2 MB more: over the 8 MiB budget
  ASSERT_TRUE(gate_->WaitArrivals(1));
  ASSERT_TRUE(manager_->Cancel(one->job_id).ok());
  gate_->Open();
  WaitTerminal(one->job_id);
  ASSERT_TRUE(manager_->Delete(one->job_id).ok());

  ASSERT_TRUE(one.ok()) << one.status();
  EXPECT_GE(held, kManyKnotsBytes);
  EXPECT_EQ(too_big.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(too_big.status().message()),
              HasSubstr("memory budget (--memory_budget_bytes=8388608) cannot take a job of"));
  EXPECT_EQ(budget.used(), 0);
}

TEST_F(JobManagerTest, DeletingAJobCancelledInTheQueueGivesItsMemoryBackAtOnce) {
  MemoryBudget& budget = StartWithBudget(std::int64_t{64} << 20, GatedOptions());
  JobSnapshot blocker = SubmitWrap();
  ASSERT_TRUE(gate_->WaitArrivals(1));  // the only worker is held; the next job waits behind it
  const std::int64_t blocker_bytes = budget.used(MemoryUse::kJob);
  absl::StatusOr<JobSnapshot> queued =
      manager_->Submit(JobSpec{.clip_id = "sha256:test", .steps = {RetimeOfManyKnots()}},
                       std::make_shared<const core::Clip>(MakeClip(1, 10)));
  ASSERT_TRUE(queued.ok()) << queued.status();
  const std::int64_t both_bytes = budget.used(MemoryUse::kJob);

  // Its task is still in the pool's queue behind the held worker, and must not keep it alive.
  ASSERT_TRUE(manager_->Cancel(queued->job_id).ok());
  ASSERT_TRUE(manager_->Delete(queued->job_id).ok());
  const std::int64_t after_delete = budget.used(MemoryUse::kJob);
  gate_->Open();
  WaitTerminal(blocker.job_id);
  // The orphaned task still runs, finds its job gone and starts nothing.
  ASSERT_TRUE(pool_->WaitIdle(std::chrono::steady_clock::now() + kHangGuard));

  EXPECT_GE(both_bytes - blocker_bytes, kManyKnotsBytes);
  EXPECT_EQ(after_delete, blocker_bytes);
  EXPECT_EQ(gate_->arrived(), 1);
}

TEST_F(JobManagerTest, DeletingASucceededJobGivesItsResultsMemoryBackAtOnce) {
  MemoryBudget& budget = StartWithBudget(std::int64_t{64} << 20);
  absl::StatusOr<JobSnapshot> job = manager_->Submit(
      JobSpec{.clip_id = "sha256:test", .steps = {core::ConvertStep{}}},
      std::make_shared<const core::Clip>(MakeClip(40, 2000)));  // a 2 MB result
  ASSERT_TRUE(job.ok()) << job.status();
  const JobState state = WaitTerminal(job->job_id).state;  // the snapshot (and its result) dropped
  const std::int64_t result_bytes = budget.used(MemoryUse::kResult);

  ASSERT_TRUE(manager_->Delete(job->job_id).ok());
  const std::int64_t after_delete = budget.used();

  EXPECT_EQ(state, JobState::kSucceeded);
  EXPECT_GT(result_bytes, std::int64_t{1} << 20);
  EXPECT_EQ(after_delete, 0);
}

TEST_F(JobManagerTest, ResultThatDoesNotFitTheBudgetFailsTheJobWithResourceExhausted) {
  MemoryBudget& budget = StartWithBudget(std::int64_t{1} << 20);

  // 40 joints x 3 + 3 channels x 2000 frames: a 2 MB result.
  absl::StatusOr<JobSnapshot> job = manager_->Submit(
      JobSpec{.clip_id = "x", .steps = {core::ConvertStep{}}},
      std::make_shared<const core::Clip>(MakeClip(40, 2000)));
  ASSERT_TRUE(job.ok());
  absl::StatusOr<JobSnapshot> small = manager_->Submit(
      JobSpec{.clip_id = "x", .steps = {core::ConvertStep{}}},
      std::make_shared<const core::Clip>(MakeClip(1, 10)));
  ASSERT_TRUE(small.ok());
  const JobSnapshot failed = WaitTerminal(job->job_id);
  const JobSnapshot fine = WaitTerminal(small->job_id);

  EXPECT_EQ(failed.state, JobState::kFailed);
  EXPECT_EQ(failed.error.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(failed.error.message()), HasSubstr("cannot take a job's result of"));
  EXPECT_EQ(fine.state, JobState::kSucceeded);
  EXPECT_GT(budget.used(MemoryUse::kResult), 0);
}

TEST_F(JobManagerTest, ReclaimRemovesTheOldestUnwatchedFinishedJobsFirst) {
  Start({});
  std::vector<std::string> ids;
  for (int i = 0; i < 4; ++i) {
    ids.push_back(SubmitWrap().job_id);
    WaitTerminal(ids.back());
  }
  auto watcher = std::make_shared<RecordingWatcher>();
  ASSERT_TRUE(manager_->Watch(ids[0], watcher).ok());

  manager_->ReclaimFinished(1);  // one job's worth: the oldest unwatched one

  EXPECT_TRUE(manager_->Get(ids[0]).ok());  // watched: kept
  EXPECT_EQ(manager_->Get(ids[1]).status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(manager_->Get(ids[2]).ok());
  EXPECT_TRUE(manager_->Get(ids[3]).ok());
  manager_->Unwatch(ids[0], watcher.get());
}

}  // namespace
}  // namespace tempokey::server
