// One memory budget for everything a server holds on behalf of its clients: clips being uploaded
// or assembled for Process, stored clips, queued and running jobs (operations and inputs), results
// stored or in flight. Memory is reserved before it is allocated, from bytes that have arrived,
// never from sizes a request merely declares; a reservation that does not fit (after the caches
// were asked to give memory back) is refused with RESOURCE_EXHAUSTED naming the budget, with a
// retry hint when the budget could take it once others give memory back, without one when it
// is more than the whole budget (retrying cannot help).
//
// No gRPC in here, so it is unit-tested under ThreadSanitizer with the job manager.
#ifndef TEMPOKEY_SERVER_MEMORY_BUDGET_H_
#define TEMPOKEY_SERVER_MEMORY_BUDGET_H_

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tempokey::server {

// What a reservation pays for (metrics report the budget's use by kind).
enum class MemoryUse { kUpload, kStoredClip, kJob, kResult, kProcess };
inline constexpr int kMemoryUseCount = 5;
// "upload", "stored_clip", "job", "result", "process".
std::string_view MemoryUseName(MemoryUse use);

// Sets glibc's allocator for serving, before the server's threads start: requests under
// kServingMmapThresholdBytes (a call's clip-sized buffers: 132 channels x 128 frames is 135 KB)
// are served from the arenas (glibc maps a smaller request only when its arena cannot grow),
// and an arena's free top is handed back by glibc once it reaches kServingTrimThresholdBytes.
// glibc's defaults (thresholds that start at 128 KiB and follow the largest mapped chunk freed,
// up to 32 MiB, the trim threshold at twice that) map and unmap such buffers, or trim the heap
// they were freed to, on many calls: each unmapping or trim flushes the TLBs of every core
// running the server's threads, and the next call faults the pages in again. The rest of the
// free memory goes back through MemoryBudget's trims. (Setting either threshold also ends
// glibc's dynamic adjustment of it: the GNU C Library manual, "Malloc Tunable Parameters",
// https://www.gnu.org/software/libc/manual/html_node/Malloc-Tunable-Parameters.html.)
// The trim threshold applies to each thread's arena (glibc's heap_trim), so it is kept small:
// at 32 MiB, arenas kept that much each after large deletes.
inline constexpr int kServingMmapThresholdBytes = 1 << 20;
inline constexpr int kServingTrimThresholdBytes = 8 << 20;
// Errors: kUnavailable naming the setting the allocator refused (AddressSanitizer's refuses
// both); its defaults then stay.
absl::Status TuneAllocatorForServing();

// The retry hint of a refusal the budget may take later: memory comes back as calls end and jobs
// finish, which the budget cannot foresee, so a fixed second (clients add their own random share).
inline constexpr std::chrono::milliseconds kMemoryRetryAfter{1000};

class MemoryBudget {
 public:
  // Asked to free memory when a reservation does not fit: release cached data (least recently
  // used first) worth at least `wanted` bytes if there is that much, and return. Called without
  // the budget's lock; must not reserve.
  using Reclaimer = std::function<void(std::int64_t wanted)>;

  // Free heap memory goes back to the system (the trimming thread's malloc_trim) when either
  //  - what the budget holds has fallen below its peak since the last trim by a quarter of what
  //    it holds, and by at least kTrimThresholdBytes (large deletes, a finished large job), or
  //  - the bytes given back since the last trim reach kTurnoverTrimBytes, and what the budget
  //    holds (stored clips replaced at a steady level: glibc reuses freed memory only in the
  //    arena that freed it, and uploads arrive on many threads, so without trims the resident
  //    set grows well past what the budget holds).
  // Memory given back and claimed again by the next calls is trimmed only at that turnover, not
  // every few calls: every trim hands the arenas' free pages back (madvise), and the next
  // allocations fault them in again.
  static constexpr std::int64_t kTrimThresholdBytes = std::int64_t{8} << 20;
  static constexpr std::int64_t kTurnoverTrimBytes = std::int64_t{128} << 20;

  // `capacity_bytes` >= 1. Starts the trimming thread.
  explicit MemoryBudget(std::int64_t capacity_bytes);
  // Stops the trimming thread. Every reservation must have been released.
  ~MemoryBudget();
  MemoryBudget(const MemoryBudget&) = delete;
  MemoryBudget& operator=(const MemoryBudget&) = delete;

  // A claim on part of the budget, released when destroyed. Move-only. Not thread-safe by
  // itself: one owner at a time.
  class Reservation {
   public:
    Reservation() = default;  // holds nothing, belongs to no budget
    Reservation(Reservation&& other) noexcept;
    Reservation& operator=(Reservation&& other) noexcept;
    ~Reservation();

    std::int64_t bytes() const { return bytes_; }
    // Claims `more` bytes (>= 0) on top of what it holds.
    // Errors: kResourceExhausted as MemoryBudget::Reserve(); the reservation is unchanged.
    absl::Status Grow(std::int64_t more);
    // Gives back what it holds beyond `bytes` (no effect when it holds less).
    void ShrinkTo(std::int64_t bytes);
    // Sets the claim to exactly `bytes` of memory that exists already (an assembled clip whose
    // exact size differs from what was claimed while it arrived), even slightly past the budget.
    void Settle(std::int64_t bytes);
    void Release() { ShrinkTo(0); }
    // Counts what it holds under `use` from now on (metrics), e.g. an upload once stored.
    void ChangeUse(MemoryUse use);
    // Names `bytes` of the budget that its holder keeps alive beside it (the stored clip or job
    // result it copies), which no reclaimer can give back while it grows: a growth that, with
    // them and what it holds, is more than the whole budget never fits (its refusal has no retry
    // hint).
    void Pin(std::int64_t bytes) { pinned_ = bytes; }

   private:
    friend class MemoryBudget;
    Reservation(MemoryBudget* budget, MemoryUse use, std::string_view what)
        : budget_(budget), use_(use), what_(what) {}

    MemoryBudget* budget_ = nullptr;
    MemoryUse use_ = MemoryUse::kUpload;
    std::string_view what_;  // a literal: "an upload", "a job's result", ...
    std::int64_t bytes_ = 0;
    std::int64_t pinned_ = 0;  // Pin()
  };

  // A reservation of `bytes` (>= 0) for `use`; `what` (a string literal) names it in the error.
  // When it does not fit, the reclaimers are asked for the difference, in order, until it does.
  // Errors: kResourceExhausted "the server's memory budget (--memory_budget_bytes=N) cannot take
  // a job's result of 5242880 more bytes: 1048576 bytes free; retry later or send less", with
  // the retry hint kMemoryRetryAfter (proto/retry_hint.h); kResourceExhausted "... N bytes in all,
  // more than the whole budget; send less" without a hint when the reservation would hold more
  // than the whole budget.
  absl::StatusOr<Reservation> Reserve(std::int64_t bytes, MemoryUse use, std::string_view what);

  // Memory freed outside any reservation (a large request parsed and dropped, a large response
  // sent): it counts as given back, and as in use on top of what the budget holds now (the
  // largest such message since the last trim, not their sum, raises the peak).
  void NoteFreed(std::int64_t bytes);

  // Adds a reclaimer; call before the budget is shared between threads.
  void AddReclaimer(Reclaimer reclaimer);

  std::int64_t capacity() const { return capacity_; }
  std::int64_t used() const;
  std::int64_t used(MemoryUse use) const;
  // Times the trimming thread returned memory to the system (tests wait for it).
  std::int64_t trims() const;
  // Blocks until the trimming thread has handled every release so far (tests).
  void WaitForTrim() const;

 private:
  // `held`: what the claiming reservation holds already and what it pins (a claim that does not
  // fit beside them is refused at once, without asking the reclaimers, and without a hint).
  absl::Status Claim(MemoryUse use, std::string_view what, std::int64_t more, std::int64_t held);
  // "the server's memory budget (...) cannot take <what> of <more> more bytes: ", a refusal's start.
  std::string RefusalHead(std::string_view what, std::int64_t more) const;
  bool TryClaimLocked(MemoryUse use, std::int64_t more) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void Return(MemoryUse use, std::int64_t bytes);
  // Counts `bytes` given back; true when a trim is due (see kTrimThresholdBytes), which starts
  // a fresh peak and count (the caller notifies the trimmer).
  bool TrimDueLocked(std::int64_t bytes) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  void TrimLoop();

  const std::int64_t capacity_;
  std::vector<Reclaimer> reclaimers_;  // set before serving, then read-only

  mutable std::mutex mu_;
  mutable std::condition_variable trim_cv_;
  std::int64_t used_ ABSL_GUARDED_BY(mu_) = 0;
  std::array<std::int64_t, kMemoryUseCount> used_by_ ABSL_GUARDED_BY(mu_){};
  // The most the budget held (and memory noted freed outside it, on top of what it held then)
  // since the last trim.
  std::int64_t peak_since_trim_ ABSL_GUARDED_BY(mu_) = 0;
  std::int64_t released_since_trim_ ABSL_GUARDED_BY(mu_) = 0;
  std::int64_t trim_requests_ ABSL_GUARDED_BY(mu_) = 0;
  std::int64_t trims_ ABSL_GUARDED_BY(mu_) = 0;
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  std::thread trimmer_;
};

// `value` shared, with `reservation` released when the last reference goes: the budget counts
// a clip or result exactly as long as the memory exists, whoever holds it.
template <typename T>
std::shared_ptr<const T> ShareWithReservation(T value, MemoryBudget::Reservation reservation) {
  struct Holder {
    T value;
    MemoryBudget::Reservation reservation;
  };
  auto holder = std::make_shared<Holder>(Holder{std::move(value), std::move(reservation)});
  return std::shared_ptr<const T>(holder, &holder->value);
}

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_MEMORY_BUDGET_H_
