// Jobs: a pipeline queued on the JobPool, its state, progress, result and retention. No gRPC in
// here (the service converts snapshots to messages), so it is unit-tested under ThreadSanitizer.
#ifndef TEMPOKEY_SERVER_JOB_MANAGER_H_
#define TEMPOKEY_SERVER_JOB_MANAGER_H_

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <stop_token>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "server/job_pool.h"
#include "server/memory_budget.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::server {

enum class JobState { kQueued, kRunning, kSucceeded, kFailed, kCancelled };

bool IsTerminal(JobState state);
// "QUEUED", "RUNNING", "SUCCEEDED", "FAILED", "CANCELLED".
std::string_view JobStateName(JobState state);

using SystemTime = std::chrono::system_clock::time_point;

// What a job runs. Immutable once submitted.
struct JobSpec {
  std::string clip_id{};                        // "sha256:..." of the input clip
  std::vector<core::PipelineStep> steps{};      // validated by the caller (ValidatePipeline)
  std::map<std::string, std::string> labels{};
  std::string request_id{};                     // idempotency key; empty: none
  // Who submitted it (a digest of the bearer token, "" without tokens): only calls of the same
  // owner find the job.
  std::string owner{};
  // Digest of the whole request, so a request_id reused for a different request is refused.
  std::string request_digest{};
};

// A consistent copy of one job at one version.
struct JobSnapshot {
  std::string job_id;
  std::shared_ptr<const JobSpec> spec;          // never null
  JobState state = JobState::kQueued;
  double progress = 0.0;                        // 0..1 over the whole pipeline
  std::string stage;                            // "queued", "retime", "reduce 12/96", ...
  std::int64_t version = 0;                     // grows by >= 1 with every change of the job
  absl::Status error;                           // FAILED and CANCELLED: why
  SystemTime create_time{};
  std::optional<SystemTime> start_time;
  std::optional<SystemTime> end_time;
  std::shared_ptr<const core::PipelineResult> result;  // SUCCEEDED only
};

// Receives the changes of one watched job.
class JobWatcher {
 public:
  virtual ~JobWatcher() = default;
  // A new snapshot. Called without JobManager locks held, from any thread (a worker, the caller
  // of Cancel()); two calls may overtake each other, so keep the highest version seen.
  virtual void OnJobUpdate(const JobSnapshot& snapshot) = 0;
  // The watch must end with `status` (kUnavailable: the server is draining). At most once, after
  // which no more updates arrive.
  virtual void OnWatchClosed(const absl::Status& status) = 0;
};

struct JobManagerOptions {
  // Finished jobs kept, by count and by bytes (results, operations and the job's own record);
  // the oldest finished unwatched job is removed first when either is exceeded.
  std::int64_t max_stored_results = 1000;
  std::int64_t max_stored_result_bytes = std::int64_t{2} << 30;
  // A finished job is removed this long after it ended (unless watched at that moment).
  std::chrono::seconds job_ttl{3600};
  // What a pipeline may produce (a retime's or bake's frames and samples).
  core::ClipLimits output_limits;
  // Counts every job's operations and record while it is stored, and its result; null: none.
  // When a result does not fit, the job fails with kResourceExhausted.
  MemoryBudget* budget = nullptr;
  // Wall clock for timestamps and retention; tests substitute their own.
  std::function<SystemTime()> clock;
  // Test hook: called on the worker with the job id right before the pipeline runs; may block.
  std::function<void(std::string_view job_id)> on_job_start;
  // Called once per job that reached a terminal state, with how long it queued and ran (0 for
  // a job cancelled before it started). Used for the per-job log line and metrics. Called with
  // the manager's lock held, before anyone can see the terminal state (so a client that saw
  // it also sees it counted); must not call back into the manager.
  std::function<void(const JobSnapshot& job, std::chrono::duration<double> queue_wait,
                     std::chrono::duration<double> run_time)>
      on_job_end;
};

struct ListJobsQuery {
  int page_size = 0;                            // 0: kDefaultPageSize; capped at kMaxPageSize
  std::string page_token{};
  std::vector<JobState> states{};               // empty: every state
  std::map<std::string, std::string> labels{};  // jobs carrying all of them
};

struct ListJobsPage {
  std::vector<JobSnapshot> jobs;                // in submission order
  std::vector<std::string> tokens;              // tokens[i] resumes a listing at jobs[i]
  std::string next_page_token;                  // empty on the last page
};

// Thread-safe: every method may be called from any thread. Callbacks (JobWatcher, options hooks)
// are invoked without the manager's lock held.
class JobManager {
 public:
  static constexpr int kDefaultPageSize = 50;
  static constexpr int kMaxPageSize = 1000;

  // `pool` runs the jobs and must outlive the manager's jobs (drain it before destroying).
  JobManager(JobPool* pool, JobManagerOptions options);
  JobManager(const JobManager&) = delete;
  JobManager& operator=(const JobManager&) = delete;

  // Queues a job running `spec.steps` on `clip`. A non-empty request_id the same owner already
  // used returns that job's snapshot instead (and `*deduplicated` = true when given), so a
  // retried submit runs once.
  // Errors: kUnavailable while draining; kResourceExhausted when the pool's queue is full (with
  // the pool's retry hint) or the job does not fit the memory budget; kAlreadyExists when the
  // request_id names a job submitted with a different request_digest; kInvalidArgument for a
  // null clip.
  absl::StatusOr<JobSnapshot> Submit(JobSpec spec, std::shared_ptr<const core::Clip> clip,
                                     bool* deduplicated = nullptr);

  // The job `owner` submitted with `request_id`, if it is still stored.
  // Errors: kAlreadyExists when that job's request_digest is not `request_digest`.
  absl::StatusOr<std::optional<JobSnapshot>> FindByRequestId(std::string_view owner,
                                                             const std::string& request_id,
                                                             std::string_view request_digest);

  // Every lookup takes the caller's owner: a job of another owner is not found.
  // Errors: kNotFound for an unknown, deleted or expired job.
  absl::StatusOr<JobSnapshot> Get(std::string_view job_id, std::string_view owner = {});
  // The owner's jobs. Errors: kInvalidArgument for a bad page token or a negative page size.
  absl::StatusOr<ListJobsPage> List(const ListJobsQuery& query, std::string_view owner = {});

  // Idempotent: a queued job becomes CANCELLED at once and never runs; a running job is asked to
  // stop (it ends CANCELLED when the pipeline notices, between channels); a finished job is
  // returned unchanged. Errors: kNotFound.
  absl::StatusOr<JobSnapshot> Cancel(std::string_view job_id, std::string_view owner = {});
  // Removes a finished job and its result. Errors: kNotFound; kFailedPrecondition while it is
  // queued or running (cancel it first).
  absl::Status Delete(std::string_view job_id, std::string_view owner = {});

  // The result of a succeeded job (shared: streaming it survives a concurrent Delete()).
  // Errors: kNotFound; kFailedPrecondition when the job has not succeeded (the message says its
  // state, and the error of a failed job).
  absl::StatusOr<std::shared_ptr<const core::PipelineResult>> Result(std::string_view job_id,
                                                                     std::string_view owner = {});

  // Attaches `watcher` to a job and returns its current snapshot; every later change is
  // delivered to the watcher until Unwatch(). While attached, the job is never evicted.
  // Errors: kNotFound; kUnavailable while draining.
  absl::StatusOr<JobSnapshot> Watch(std::string_view job_id, std::shared_ptr<JobWatcher> watcher,
                                    std::string_view owner = {});
  void Unwatch(std::string_view job_id, const JobWatcher* watcher);

  // Drain, step 1: refuse new jobs and watches (kUnavailable) and close every open watch with
  // kUnavailable. Queued and running jobs continue.
  void BeginDrain();
  bool draining() const;
  // Cancels every queued and running job (the drain deadline passed).
  void CancelAll();

  // Jobs stored (any state).
  std::int64_t job_count() const;

  // Removes the oldest finished unwatched jobs until their bytes reach `wanted` or none is left
  // (the memory budget's reclaimer).
  void ReclaimFinished(std::int64_t wanted);

 private:
  struct JobRecord;

  // Runs the job on a pool worker. The queued task does not own the record, and the worker lets go
  // of it (and of the result, unless watchers are sent it) under the lock that ends the job: once
  // anyone can see a job ended and delete it, a DeleteJob gives its memory back at once.
  void Run(const std::weak_ptr<JobRecord>& job, std::stop_token pool_stop);
  void PublishProgress(const std::shared_ptr<JobRecord>& record, double fraction,
                       std::string_view stage);
  JobSnapshot SnapshotLocked(const JobRecord& record) const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  absl::StatusOr<std::shared_ptr<JobRecord>> FindLocked(std::string_view job_id,
                                                        std::string_view owner) const
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // Marks `record` cancelled (from QUEUED) and returns who to tell.
  std::vector<std::shared_ptr<JobWatcher>> CancelLocked(JobRecord& record)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // Removes expired and over-cap finished jobs, oldest first, skipping watched ones.
  void EvictLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void RemoveLocked(const std::shared_ptr<JobRecord>& record) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // Drops removed records from finished_, so their memory goes now.
  void DropRemovedLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  std::string NewJobIdLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  SystemTime Now() const;
  void ReportEndLocked(const JobSnapshot& snapshot, const JobRecord& record)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  JobPool* const pool_;
  const JobManagerOptions options_;

  mutable std::mutex mu_;
  bool draining_ ABSL_GUARDED_BY(mu_) = false;
  std::uint64_t next_seq_ ABSL_GUARDED_BY(mu_) = 1;
  std::mt19937_64 id_rng_ ABSL_GUARDED_BY(mu_);
  std::map<std::uint64_t, std::shared_ptr<JobRecord>> by_seq_ ABSL_GUARDED_BY(mu_);
  std::unordered_map<std::string, std::shared_ptr<JobRecord>> by_id_ ABSL_GUARDED_BY(mu_);
  // owner + '\n' + request_id -> job id.
  std::unordered_map<std::string, std::string> by_request_id_ ABSL_GUARDED_BY(mu_);
  // Finished jobs in the order they finished (eviction order).
  std::deque<std::shared_ptr<JobRecord>> finished_ ABSL_GUARDED_BY(mu_);
  std::int64_t finished_count_ ABSL_GUARDED_BY(mu_) = 0;  // in finished_, not removed
  std::int64_t finished_bytes_ ABSL_GUARDED_BY(mu_) = 0;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_JOB_MANAGER_H_
