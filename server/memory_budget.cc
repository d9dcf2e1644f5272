#include "server/memory_budget.h"

#include <malloc.h>

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/retry_hint.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {

std::string_view MemoryUseName(MemoryUse use) {
  switch (use) {
    case MemoryUse::kUpload:
      return "upload";
    case MemoryUse::kStoredClip:
      return "stored_clip";
    case MemoryUse::kJob:
      return "job";
    case MemoryUse::kResult:
      return "result";
    case MemoryUse::kProcess:
      return "process";
  }
  return "unknown";
}

absl::Status TuneAllocatorForServing() {
  // mallopt() returns 1 on success, 0 on error.
  if (mallopt(M_MMAP_THRESHOLD, kServingMmapThresholdBytes) != 1) {
    return absl::UnavailableError(absl::StrCat("the allocator refused M_MMAP_THRESHOLD=",
                                               kServingMmapThresholdBytes));
  }
  if (mallopt(M_TRIM_THRESHOLD, kServingTrimThresholdBytes) != 1) {
    return absl::UnavailableError(absl::StrCat("the allocator refused M_TRIM_THRESHOLD=",
                                               kServingTrimThresholdBytes));
  }
  return absl::OkStatus();
}

// ---- Reservation ---------------------------------------------------------------------------------

MemoryBudget::Reservation::Reservation(Reservation&& other) noexcept
    : budget_(std::exchange(other.budget_, nullptr)),
      use_(other.use_),
      what_(other.what_),
      bytes_(std::exchange(other.bytes_, 0)),
      pinned_(std::exchange(other.pinned_, 0)) {}

MemoryBudget::Reservation& MemoryBudget::Reservation::operator=(Reservation&& other) noexcept {
  if (this != &other) {
    Release();
    budget_ = std::exchange(other.budget_, nullptr);
    use_ = other.use_;
    what_ = other.what_;
    bytes_ = std::exchange(other.bytes_, 0);
    pinned_ = std::exchange(other.pinned_, 0);
  }
  return *this;
}

MemoryBudget::Reservation::~Reservation() { Release(); }

absl::Status MemoryBudget::Reservation::Grow(std::int64_t more) {
  if (more <= 0) return absl::OkStatus();
  if (budget_ == nullptr) return absl::OkStatus();  // an unbudgeted holder (tests, clients)
  TEMPOKEY_RETURN_IF_ERROR(budget_->Claim(use_, what_, more, bytes_ + pinned_));
  bytes_ += more;
  return absl::OkStatus();
}

void MemoryBudget::Reservation::ShrinkTo(std::int64_t bytes) {
  bytes = std::max<std::int64_t>(bytes, 0);
  if (bytes >= bytes_) return;
  if (budget_ != nullptr) budget_->Return(use_, bytes_ - bytes);
  bytes_ = bytes;
}

void MemoryBudget::Reservation::Settle(std::int64_t bytes) {
  if (bytes <= bytes_) {
    ShrinkTo(bytes);
    return;
  }
  if (budget_ == nullptr) return;
  const std::int64_t more = bytes - bytes_;
  {
    std::lock_guard lock(budget_->mu_);
    budget_->used_ += more;
    budget_->used_by_[static_cast<int>(use_)] += more;
    budget_->peak_since_trim_ = std::max(budget_->peak_since_trim_, budget_->used_);
  }
  bytes_ = bytes;
}

void MemoryBudget::Reservation::ChangeUse(MemoryUse use) {
  if (budget_ != nullptr && bytes_ > 0 && use != use_) {
    std::lock_guard lock(budget_->mu_);
    budget_->used_by_[static_cast<int>(use_)] -= bytes_;
    budget_->used_by_[static_cast<int>(use)] += bytes_;
  }
  use_ = use;
}

// ---- MemoryBudget --------------------------------------------------------------------------------

MemoryBudget::MemoryBudget(std::int64_t capacity_bytes)
    : capacity_(std::max<std::int64_t>(1, capacity_bytes)), trimmer_([this] { TrimLoop(); }) {}

MemoryBudget::~MemoryBudget() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  trim_cv_.notify_all();
  trimmer_.join();
}

void MemoryBudget::AddReclaimer(Reclaimer reclaimer) { reclaimers_.push_back(std::move(reclaimer)); }

absl::StatusOr<MemoryBudget::Reservation> MemoryBudget::Reserve(std::int64_t bytes, MemoryUse use,
                                                                std::string_view what) {
  Reservation reservation(this, use, what);
  TEMPOKEY_RETURN_IF_ERROR(reservation.Grow(bytes));
  return reservation;
}

bool MemoryBudget::TryClaimLocked(MemoryUse use, std::int64_t more) {
  if (more > capacity_ - used_) return false;
  used_ += more;
  used_by_[static_cast<int>(use)] += more;
  peak_since_trim_ = std::max(peak_since_trim_, used_);
  return true;
}

absl::Status MemoryBudget::Claim(MemoryUse use, std::string_view what, std::int64_t more,
                                 std::int64_t held) {
  // Beside what the claimant holds and pins, more than the whole budget: nothing the caches give
  // back makes room, so they are not asked (a stored clip being read back, or a job's result being
  // exported, is not evicted for a claim that fails anyway), and the refusal has no retry hint (an
  // HTTP client gets 413, not the 429 that says "retry later").
  if (more > capacity_ - held) {
    return absl::ResourceExhaustedError(absl::StrCat(
        RefusalHead(what, more), held + more, " bytes in all, more than the whole budget; send less"));
  }
  {
    std::lock_guard lock(mu_);
    if (TryClaimLocked(use, more)) return absl::OkStatus();
  }
  // Caches give memory back (outside the lock: releasing takes it), then one more try.
  for (const Reclaimer& reclaim : reclaimers_) {
    std::int64_t missing = 0;
    {
      std::lock_guard lock(mu_);
      if (TryClaimLocked(use, more)) return absl::OkStatus();
      missing = more - (capacity_ - used_);
    }
    reclaim(missing);
  }
  std::lock_guard lock(mu_);
  if (TryClaimLocked(use, more)) return absl::OkStatus();
  // It fits once others give memory back.
  absl::Status refused = absl::ResourceExhaustedError(
      absl::StrCat(RefusalHead(what, more), std::max<std::int64_t>(0, capacity_ - used_),
                   " bytes free; retry later or send less"));
  wire::SetRetryAfter(refused, kMemoryRetryAfter);
  return refused;
}

std::string MemoryBudget::RefusalHead(std::string_view what, std::int64_t more) const {
  return absl::StrCat("the server's memory budget (--memory_budget_bytes=", capacity_,
                      ") cannot take ", core::AsAbsl(what), " of ", more, " more bytes: ");
}

bool MemoryBudget::TrimDueLocked(std::int64_t bytes) {
  released_since_trim_ += bytes;
  const bool fell = peak_since_trim_ - used_ >= std::max(kTrimThresholdBytes, used_ / 4);
  const bool turned_over = released_since_trim_ >= std::max(kTurnoverTrimBytes, used_);
  if (!fell && !turned_over) return false;
  peak_since_trim_ = used_;
  released_since_trim_ = 0;
  ++trim_requests_;
  return true;
}

void MemoryBudget::Return(MemoryUse use, std::int64_t bytes) {
  bool trim = false;
  {
    std::lock_guard lock(mu_);
    used_ -= bytes;
    used_by_[static_cast<int>(use)] -= bytes;
    trim = TrimDueLocked(bytes);
  }
  if (trim) trim_cv_.notify_all();
}

void MemoryBudget::NoteFreed(std::int64_t bytes) {
  if (bytes <= 0) return;
  bool trim = false;
  {
    std::lock_guard lock(mu_);
    // The memory existed on top of what is reserved now.
    peak_since_trim_ = std::max(peak_since_trim_, used_ + bytes);
    trim = TrimDueLocked(bytes);
  }
  if (trim) trim_cv_.notify_all();
}

std::int64_t MemoryBudget::used() const {
  std::lock_guard lock(mu_);
  return used_;
}

std::int64_t MemoryBudget::used(MemoryUse use) const {
  std::lock_guard lock(mu_);
  return used_by_[static_cast<int>(use)];
}

std::int64_t MemoryBudget::trims() const {
  std::lock_guard lock(mu_);
  return trims_;
}

void MemoryBudget::WaitForTrim() const {
  std::unique_lock lock(mu_);
  trim_cv_.wait(lock, [&] { return trims_ >= trim_requests_ || stopping_; });
}

void MemoryBudget::TrimLoop() {
  std::unique_lock lock(mu_);
  for (;;) {
    trim_cv_.wait(lock, [&] { return stopping_ || trims_ < trim_requests_; });
    if (stopping_) return;
    const std::int64_t requests = trim_requests_;
    lock.unlock();
    // glibc returns freed chunks below its (dynamic) mmap threshold to its arenas, not to the
    // system; after large frees the resident set would stay at its peak. malloc_trim(0) gives
    // every arena's free pages back (madvise), so memory deleted jobs and evicted clips held is
    // returned. It walks the arenas, so it runs here, off the request threads, and requests
    // that pile up meanwhile are served by one trim.
    malloc_trim(0);
    lock.lock();
    trims_ = requests;
    trim_cv_.notify_all();
  }
}

}  // namespace tempokey::server
