#include "server/job_manager.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <variant>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "server/memory_size.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {

using SteadyTime = std::chrono::steady_clock::time_point;

struct JobManager::JobRecord {
  // Immutable after creation.
  std::string id;
  std::uint64_t seq = 0;
  std::shared_ptr<const JobSpec> spec;
  std::stop_source stop;  // thread-safe by itself

  // The rest is guarded by JobManager::mu_.
  std::shared_ptr<const core::Clip> clip;  // released when the job ends
  JobState state = JobState::kQueued;
  double progress = 0.0;
  std::string stage = "queued";
  std::int64_t version = 1;
  absl::Status error;
  SystemTime create_time{};
  std::optional<SystemTime> start_time;
  std::optional<SystemTime> end_time;
  SteadyTime queued_at{};
  SteadyTime started_at{};
  std::shared_ptr<const core::PipelineResult> result;
  std::int64_t result_bytes = 0;
  // The record and its spec in the memory budget (its clip and result carry their own).
  MemoryBudget::Reservation reservation;
  std::int64_t spec_bytes = 0;
  std::vector<std::shared_ptr<JobWatcher>> watchers;
  bool removed = false;
};

namespace {

void Notify(const std::vector<std::shared_ptr<JobWatcher>>& watchers, const JobSnapshot& snapshot) {
  for (const auto& watcher : watchers) watcher->OnJobUpdate(snapshot);
}

// The key of a request id in by_request_id_: request ids are per owner.
std::string RequestKey(std::string_view owner, std::string_view request_id) {
  return absl::StrCat(core::AsAbsl(owner), "\n", core::AsAbsl(request_id));
}

// One bit per state, for a set of states.
unsigned StateBit(JobState state) { return 1u << static_cast<unsigned>(state); }

absl::Status ReusedRequestId(const std::string& request_id, const std::string& job_id) {
  return absl::AlreadyExistsError(absl::StrCat(
      "request_id \"", request_id, "\" already named job ", job_id,
      ", submitted with a different request; a retry must send the same request, a new request "
      "needs a new request_id"));
}

}  // namespace

bool IsTerminal(JobState state) {
  return state == JobState::kSucceeded || state == JobState::kFailed ||
         state == JobState::kCancelled;
}

std::string_view JobStateName(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return "QUEUED";
    case JobState::kRunning:
      return "RUNNING";
    case JobState::kSucceeded:
      return "SUCCEEDED";
    case JobState::kFailed:
      return "FAILED";
    case JobState::kCancelled:
      return "CANCELLED";
  }
  return "UNKNOWN";
}

JobManager::JobManager(JobPool* pool, JobManagerOptions options)
    : pool_(pool), options_(std::move(options)), id_rng_(std::random_device{}()) {}

SystemTime JobManager::Now() const {
  return options_.clock ? options_.clock() : std::chrono::system_clock::now();
}

std::string JobManager::NewJobIdLocked() {
  for (;;) {
    std::string id = absl::StrFormat("job-%016x", id_rng_());
    if (!by_id_.contains(id)) return id;
  }
}

JobSnapshot JobManager::SnapshotLocked(const JobRecord& record) const {
  JobSnapshot s;
  s.job_id = record.id;
  s.spec = record.spec;
  s.state = record.state;
  s.progress = record.progress;
  s.stage = record.stage;
  s.version = record.version;
  s.error = record.error;
  s.create_time = record.create_time;
  s.start_time = record.start_time;
  s.end_time = record.end_time;
  s.result = record.result;
  return s;
}

absl::StatusOr<std::shared_ptr<JobManager::JobRecord>> JobManager::FindLocked(
    std::string_view job_id, std::string_view owner) const {
  auto it = by_id_.find(std::string(job_id));
  // Another owner's job answers exactly like an unknown one: ids reveal nothing.
  if (it == by_id_.end() || it->second->spec->owner != owner) {
    return absl::NotFoundError(absl::StrCat("job \"", core::AsAbsl(job_id),
                                            "\" not found (unknown, deleted, or past its "
                                            "retention time)"));
  }
  return it->second;
}

absl::StatusOr<JobSnapshot> JobManager::Submit(JobSpec spec, std::shared_ptr<const core::Clip> clip,
                                               bool* deduplicated) {
  if (deduplicated != nullptr) *deduplicated = false;
  if (clip == nullptr) return absl::InvalidArgumentError("a job needs a clip");
  auto record = std::make_shared<JobRecord>();
  // The job's own memory is claimed before the lock: the budget may ask this manager to evict.
  record->spec_bytes = static_cast<std::int64_t>(sizeof(JobRecord) + sizeof(JobSpec)) +
                       StepsBytes(spec.steps) +
                       static_cast<std::int64_t>(spec.request_id.size() + spec.owner.size() +
                                                 spec.request_digest.size());
  for (const auto& [key, value] : spec.labels) {
    record->spec_bytes += static_cast<std::int64_t>(key.size() + value.size()) + 64;
  }
  if (options_.budget != nullptr) {
    TEMPOKEY_ASSIGN_OR_RETURN(record->reservation,
                              options_.budget->Reserve(record->spec_bytes, MemoryUse::kJob, "a job"));
  }
  std::lock_guard lock(mu_);
  if (draining_) {
    return absl::UnavailableError("the server is shutting down and accepts no new jobs");
  }
  if (!spec.request_id.empty()) {
    if (auto it = by_request_id_.find(RequestKey(spec.owner, spec.request_id));
        it != by_request_id_.end()) {
      if (auto job = by_id_.find(it->second); job != by_id_.end()) {
        if (job->second->spec->request_digest != spec.request_digest) {
          return ReusedRequestId(spec.request_id, job->second->id);
        }
        if (deduplicated != nullptr) *deduplicated = true;
        return SnapshotLocked(*job->second);
      }
    }
  }
  EvictLocked();

  record->id = NewJobIdLocked();
  record->seq = next_seq_;
  record->spec = std::make_shared<const JobSpec>(std::move(spec));
  record->clip = std::move(clip);
  record->create_time = Now();
  record->queued_at = std::chrono::steady_clock::now();
  TEMPOKEY_RETURN_IF_ERROR(pool_->TrySubmit(
      [this, job = std::weak_ptr<JobRecord>(record)](std::stop_token pool_stop) {
        Run(job, std::move(pool_stop));
      }));
  ++next_seq_;
  by_seq_.emplace(record->seq, record);
  by_id_.emplace(record->id, record);
  if (!record->spec->request_id.empty()) {
    by_request_id_[RequestKey(record->spec->owner, record->spec->request_id)] = record->id;
  }
  return SnapshotLocked(*record);
}

void JobManager::Run(const std::weak_ptr<JobRecord>& job, std::stop_token pool_stop) {
  JobSnapshot snapshot;
  std::vector<std::shared_ptr<JobWatcher>> watchers;
  std::shared_ptr<const core::Clip> clip;
  std::shared_ptr<JobRecord> record;
  {
    std::lock_guard lock(mu_);
    record = job.lock();  // under mu_: gone if it was cancelled while queued and then deleted
    if (record == nullptr || record->state != JobState::kQueued) {  // cancelled: never runs
      record.reset();  // under mu_ too: a DeleteJob after the unlock frees it
      return;
    }
    record->state = JobState::kRunning;
    record->start_time = Now();
    record->started_at = std::chrono::steady_clock::now();
    record->stage = "starting";
    ++record->version;
    snapshot = SnapshotLocked(*record);
    watchers = record->watchers;
    clip = record->clip;
  }
  Notify(watchers, snapshot);

  if (options_.on_job_start) options_.on_job_start(record->id);
  // The drain deadline (pool_stop) cancels the job like a CancelJob would.
  std::stop_callback forward(pool_stop, [stop = record->stop]() mutable { stop.request_stop(); });
  absl::StatusOr<core::PipelineResult> result = core::RunPipeline(
      *clip, record->spec->steps,
      [this, &record](double fraction, std::string_view stage) {
        PublishProgress(record, fraction, stage);
      },
      record->stop.get_token(), options_.output_limits);
  clip.reset();
  {
    // The input is not needed any more: drop it first, so the store may evict it for the result.
    std::lock_guard lock(mu_);
    record->clip.reset();
  }

  // The result exists already; it is kept only if the budget can count it (the budget may first
  // evict older finished jobs and stored clips to make room).
  std::shared_ptr<const core::PipelineResult> shared_result;
  std::int64_t result_bytes = 0;
  if (result.ok()) {
    result_bytes = PipelineResultBytes(*result);
    MemoryBudget::Reservation reservation;
    if (options_.budget != nullptr) {
      absl::StatusOr<MemoryBudget::Reservation> reserved =
          options_.budget->Reserve(result_bytes, MemoryUse::kResult, "a job's result");
      if (!reserved.ok()) {
        result = reserved.status();
      } else {
        reservation = *std::move(reserved);
      }
    }
    if (result.ok()) {
      shared_result = ShareWithReservation(*std::move(result), std::move(reservation));
    }
  }
  {
    std::lock_guard lock(mu_);
    record->end_time = Now();
    if (shared_result != nullptr) {
      record->state = JobState::kSucceeded;
      record->progress = 1.0;
      record->stage = "done";
      record->result = std::move(shared_result);  // the record's alone: a DeleteJob frees it
      record->result_bytes = result_bytes;
    } else if (result.status().code() == absl::StatusCode::kCancelled &&
               record->stop.stop_requested()) {
      record->state = JobState::kCancelled;
      record->stage = "cancelled";
      record->error = result.status();
    } else {
      record->state = JobState::kFailed;
      record->stage = "failed";
      record->error = result.status();
    }
    ++record->version;
    record->clip.reset();
    snapshot = SnapshotLocked(*record);
    watchers = record->watchers;
    finished_.push_back(record);
    ++finished_count_;
    finished_bytes_ += record->result_bytes + record->spec_bytes;
    ReportEndLocked(snapshot, *record);
    // Let go before the unlock: a DeleteJob right after it gives the job's memory back at once,
    // not whenever this worker returns (finished_ holds the record until then). Only watchers
    // need the snapshot's result, which they are sent.
    record.reset();
    if (watchers.empty()) snapshot.result.reset();
    EvictLocked();
  }
  Notify(watchers, snapshot);
}

void JobManager::ReportEndLocked(const JobSnapshot& snapshot, const JobRecord& record) {
  if (!options_.on_job_end) return;
  std::chrono::duration<double> queue_wait{0};
  std::chrono::duration<double> run_time{0};
  const SteadyTime now = std::chrono::steady_clock::now();
  if (snapshot.start_time.has_value()) {
    queue_wait = record.started_at - record.queued_at;
    run_time = now - record.started_at;
  } else {
    queue_wait = now - record.queued_at;
  }
  options_.on_job_end(snapshot, queue_wait, run_time);
}

void JobManager::PublishProgress(const std::shared_ptr<JobRecord>& record, double fraction,
                                 std::string_view stage) {
  JobSnapshot snapshot;
  std::vector<std::shared_ptr<JobWatcher>> watchers;
  {
    std::lock_guard lock(mu_);
    if (record->state != JobState::kRunning) return;
    // Latest wins: a new version per stage change or per percent of progress, not per call.
    if (stage == record->stage && std::abs(fraction - record->progress) < 0.01) return;
    record->progress = std::clamp(fraction, 0.0, 1.0);
    record->stage = std::string(stage);
    ++record->version;
    if (record->watchers.empty()) return;
    snapshot = SnapshotLocked(*record);
    watchers = record->watchers;
  }
  Notify(watchers, snapshot);
}

absl::StatusOr<std::optional<JobSnapshot>> JobManager::FindByRequestId(
    std::string_view owner, const std::string& request_id, std::string_view request_digest) {
  std::lock_guard lock(mu_);
  auto it = by_request_id_.find(RequestKey(owner, request_id));
  if (it == by_request_id_.end()) return std::nullopt;
  auto job = by_id_.find(it->second);
  if (job == by_id_.end()) return std::nullopt;
  if (job->second->spec->request_digest != request_digest) {
    return ReusedRequestId(request_id, job->second->id);
  }
  return SnapshotLocked(*job->second);
}

absl::StatusOr<JobSnapshot> JobManager::Get(std::string_view job_id, std::string_view owner) {
  std::lock_guard lock(mu_);
  EvictLocked();
  TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<JobRecord> record, FindLocked(job_id, owner));
  return SnapshotLocked(*record);
}

absl::StatusOr<ListJobsPage> JobManager::List(const ListJobsQuery& query, std::string_view owner) {
  if (query.page_size < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("page_size must be >= 0, got ", query.page_size));
  }
  const int page_size =
      query.page_size == 0 ? kDefaultPageSize : std::min(query.page_size, kMaxPageSize);
  std::uint64_t start = 0;
  if (!query.page_token.empty() && !absl::SimpleAtoi(query.page_token, &start)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "page_token \"", query.page_token, "\" is not a token this server issued"));
  }
  // The states asked for as bits, taken before the lock: a request may repeat them as many
  // times as a message holds, and searching that list for every job held the lock for seconds.
  unsigned wanted_states = 0;
  for (JobState state : query.states) wanted_states |= StateBit(state);
  auto matches = [&](const JobRecord& record) {
    if (record.spec->owner != owner) return false;
    if (!query.states.empty() && (wanted_states & StateBit(record.state)) == 0) return false;
    for (const auto& [key, value] : query.labels) {
      auto it = record.spec->labels.find(key);
      if (it == record.spec->labels.end() || it->second != value) return false;
    }
    return true;
  };

  ListJobsPage page;
  std::lock_guard lock(mu_);
  EvictLocked();
  for (auto it = by_seq_.lower_bound(start); it != by_seq_.end(); ++it) {
    if (!matches(*it->second)) continue;
    if (static_cast<int>(page.jobs.size()) == page_size) {
      page.next_page_token = absl::StrCat(it->first);
      break;
    }
    page.jobs.push_back(SnapshotLocked(*it->second));
    page.tokens.push_back(absl::StrCat(it->first));
  }
  return page;
}

std::vector<std::shared_ptr<JobWatcher>> JobManager::CancelLocked(JobRecord& record) {
  record.state = JobState::kCancelled;
  record.stage = "cancelled";
  record.error = absl::CancelledError("cancelled before it started");
  record.end_time = Now();
  ++record.version;
  record.clip.reset();
  record.stop.request_stop();
  return record.watchers;
}

absl::StatusOr<JobSnapshot> JobManager::Cancel(std::string_view job_id, std::string_view owner) {
  JobSnapshot snapshot;
  std::vector<std::shared_ptr<JobWatcher>> watchers;
  bool ended = false;  // not the record: a DeleteJob after the unlock must free it at once
  {
    std::lock_guard lock(mu_);
    TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<JobRecord> record, FindLocked(job_id, owner));
    if (record->state == JobState::kQueued) {
      watchers = CancelLocked(*record);
      finished_.push_back(record);
      ++finished_count_;
      finished_bytes_ += record->spec_bytes;
      ended = true;
    } else if (record->state == JobState::kRunning && !record->stop.stop_requested()) {
      record->stop.request_stop();
      record->stage = "cancelling";
      ++record->version;
      watchers = record->watchers;
    }
    snapshot = SnapshotLocked(*record);
    if (ended) {
      ReportEndLocked(snapshot, *record);
      EvictLocked();
    }
  }
  Notify(watchers, snapshot);
  return snapshot;
}

absl::Status JobManager::Delete(std::string_view job_id, std::string_view owner) {
  std::lock_guard lock(mu_);
  TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<JobRecord> record, FindLocked(job_id, owner));
  if (!IsTerminal(record->state)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "job ", record->id, " is ", core::AsAbsl(JobStateName(record->state)),
        "; cancel it and delete it once it has ended"));
  }
  RemoveLocked(record);
  DropRemovedLocked();  // its operations are freed now, not at the next eviction
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<const core::PipelineResult>> JobManager::Result(
    std::string_view job_id, std::string_view owner) {
  std::lock_guard lock(mu_);
  TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<JobRecord> record, FindLocked(job_id, owner));
  switch (record->state) {
    case JobState::kSucceeded:
      return record->result;
    case JobState::kFailed:
    case JobState::kCancelled:
      return absl::FailedPreconditionError(absl::StrCat(
          "job ", record->id, " has no result: it ", record->state == JobState::kFailed ? "failed" : "was cancelled",
          " (", absl::StatusCodeToString(record->error.code()), ": ", record->error.message(), ")"));
    case JobState::kQueued:
    case JobState::kRunning:
      break;
  }
  return absl::FailedPreconditionError(absl::StrCat("job ", record->id, " has no result yet: it is ",
                                                    core::AsAbsl(JobStateName(record->state))));
}

absl::StatusOr<JobSnapshot> JobManager::Watch(std::string_view job_id,
                                              std::shared_ptr<JobWatcher> watcher,
                                              std::string_view owner) {
  std::lock_guard lock(mu_);
  if (draining_) return absl::UnavailableError("the server is shutting down");
  TEMPOKEY_ASSIGN_OR_RETURN(std::shared_ptr<JobRecord> record, FindLocked(job_id, owner));
  record->watchers.push_back(std::move(watcher));
  return SnapshotLocked(*record);
}

void JobManager::Unwatch(std::string_view job_id, const JobWatcher* watcher) {
  std::lock_guard lock(mu_);
  auto it = by_id_.find(std::string(job_id));
  if (it == by_id_.end()) return;
  auto& watchers = it->second->watchers;
  watchers.erase(std::remove_if(watchers.begin(), watchers.end(),
                                [&](const auto& w) { return w.get() == watcher; }),
                 watchers.end());
}

void JobManager::BeginDrain() {
  std::vector<std::shared_ptr<JobWatcher>> closing;
  {
    std::lock_guard lock(mu_);
    draining_ = true;
    for (auto& [seq, record] : by_seq_) {
      closing.insert(closing.end(), record->watchers.begin(), record->watchers.end());
      record->watchers.clear();
    }
  }
  const absl::Status status = absl::UnavailableError(
      "the server is shutting down; the watch was closed (the job itself keeps running)");
  for (const auto& watcher : closing) watcher->OnWatchClosed(status);
}

bool JobManager::draining() const {
  std::lock_guard lock(mu_);
  return draining_;
}

void JobManager::CancelAll() {
  std::vector<std::pair<JobSnapshot, std::vector<std::shared_ptr<JobWatcher>>>> updates;
  {
    std::lock_guard lock(mu_);
    for (auto& [seq, record] : by_seq_) {
      if (record->state == JobState::kQueued) {
        auto watchers = CancelLocked(*record);
        finished_.push_back(record);
        ++finished_count_;
        finished_bytes_ += record->spec_bytes;
        JobSnapshot snapshot = SnapshotLocked(*record);
        ReportEndLocked(snapshot, *record);
        updates.emplace_back(std::move(snapshot), std::move(watchers));
      } else if (record->state == JobState::kRunning) {
        record->stop.request_stop();
      }
    }
  }
  for (const auto& [snapshot, watchers] : updates) Notify(watchers, snapshot);
}

void JobManager::ReclaimFinished(std::int64_t wanted) {
  std::lock_guard lock(mu_);
  std::int64_t freed = 0;
  for (const auto& record : finished_) {
    if (freed >= wanted) break;
    if (record->removed || !record->watchers.empty()) continue;
    freed += record->result_bytes + record->spec_bytes;
    RemoveLocked(record);
  }
  DropRemovedLocked();
}

std::int64_t JobManager::job_count() const {
  std::lock_guard lock(mu_);
  return static_cast<std::int64_t>(by_id_.size());
}

void JobManager::RemoveLocked(const std::shared_ptr<JobRecord>& record) {
  if (record->removed) return;
  record->removed = true;
  by_seq_.erase(record->seq);
  by_id_.erase(record->id);
  if (!record->spec->request_id.empty()) {
    auto it = by_request_id_.find(record->spec->request_id);
    if (it != by_request_id_.end() && it->second == record->id) by_request_id_.erase(it);
  }
  --finished_count_;  // only finished jobs are ever removed
  finished_bytes_ -= record->result_bytes + record->spec_bytes;
  record->result.reset();
  // The record (its spec and reservation) goes once finished_ drops it too: EvictLocked() or
  // DropRemovedLocked(). No worker holds it by then: Run() lets go before the job is seen to end.
}

void JobManager::DropRemovedLocked() {
  std::erase_if(finished_, [](const std::shared_ptr<JobRecord>& r) { return r->removed; });
}

void JobManager::EvictLocked() {
  const SystemTime now = Now();
  auto expired = [&](const JobRecord& record) {
    return record.end_time.has_value() && *record.end_time + options_.job_ttl <= now;
  };
  auto over_cap = [&] {
    return finished_count_ > options_.max_stored_results ||
           finished_bytes_ > options_.max_stored_result_bytes;
  };
  // finished_ is in end order: when the oldest entry is live and unexpired and no cap is
  // exceeded, there is nothing to do (the common case, O(1)).
  if (finished_.empty()) return;
  if (!over_cap() && !finished_.front()->removed && !expired(*finished_.front())) return;
  std::deque<std::shared_ptr<JobRecord>> kept;
  for (auto& record : finished_) {
    if (record->removed) continue;
    if ((expired(*record) || over_cap()) && record->watchers.empty()) {
      RemoveLocked(record);
      continue;
    }
    kept.push_back(std::move(record));
  }
  finished_.swap(kept);
}

}  // namespace tempokey::server
