// An upload's content id (wire::IncrementalClipDigest) hashed beside the upload's reads. SHA-256
// of the samples was about 38 % of the server's CPU in a 50 MB upload, all of it on the thread
// that reads the stream, between one read and the next (README, "Speed").
//
// Here the first Limits::inline_bytes of samples are hashed where they are offered (a small
// upload starts no thread); past them, a thread of the digest's own hashes the offers in the
// order made, a MiB at a time, while the caller goes on reading. Bounds:
// - At most Limits::max_pending_bytes of samples wait to be hashed: an offer that would pass them
//   waits for the thread to catch up. An offer larger than the bound waits until nothing is
//   pending and is then hashed where it is made, as before. So no wait is longer than hashing
//   max_pending_bytes (about 2 ms per 4 MiB here), and what the digest holds is the messages its
//   pending samples came in: those samples, and the slices already hashed of the message at the
//   head of the queue (a batch of slices is let go with its last slice).
// - Offers that do not continue the canonical order (wire::IncrementalClipDigest hashes those
//   from the finished clip) are dropped here, not queued: they start no thread and hold nothing.
// - How many uploads hash on threads of their own at once is bounded server-wide
//   (DigestThreads): past that, an upload hashes where its samples arrive, as it did before.
// - The destructor waits for at most the MiB being hashed.
//
// No gRPC in here, so it is unit-tested under ThreadSanitizer.
#ifndef TEMPOKEY_SERVER_BACKGROUND_DIGEST_H_
#define TEMPOKEY_SERVER_BACKGROUND_DIGEST_H_

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <utility>

#include "absl/base/thread_annotations.h"
#include "proto/clip_digest.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::server {

// The threads BackgroundClipDigest may start at once, over every upload of a server: one per
// CPU the server may use by default (DefaultWorkerCount(): its affinity, within its cgroup's CPU
// quota), so the memory offers wait in is at most that many times their bound. Thread-safe.
class DigestThreads {
 public:
  // Starts a thread running `body` and returns it, or throws (std::system_error, as std::thread's
  // constructor does when the system cannot start one). Any exception, or a thread that is not
  // joinable, counts as a failed start.
  using Starter = std::function<std::thread(std::function<void()> body)>;

  DigestThreads();
  explicit DigestThreads(int max);
  // `start` in place of std::thread's constructor (tests: a start that fails).
  DigestThreads(int max, Starter start);
  bool TryAcquire();
  void Release() { in_use_.fetch_sub(1); }
  int in_use() const { return in_use_.load(); }
  int max() const { return max_; }
  // A thread running `body`, claimed or not (throws as Starter).
  std::thread Start(std::function<void()> body) const { return start_(std::move(body)); }

 private:
  const int max_;
  const Starter start_;
  std::atomic<int> in_use_{0};
};

class BackgroundClipDigest {
 public:
  struct Limits {
    // Samples hashed where they are offered before the thread starts.
    std::size_t inline_bytes = std::size_t{1} << 20;
    // Samples offered but not yet hashed, at most.
    std::size_t max_pending_bytes = std::size_t{4} << 20;
  };

  // Hashes the canonical header of `layout` (as wire::IncrementalClipDigest). `threads` (may be
  // null: no limit) is claimed for the thread, if one starts, until the digest goes.
  BackgroundClipDigest(const core::Clip& layout, DigestThreads* threads);
  BackgroundClipDigest(const core::Clip& layout, DigestThreads* threads, Limits limits);
  // Drops the offers not hashed yet (their memory is let go) and joins the thread.
  ~BackgroundClipDigest();
  BackgroundClipDigest(const BackgroundClipDigest&) = delete;
  BackgroundClipDigest& operator=(const BackgroundClipDigest&) = delete;

  // wire::IncrementalClipDigest::Offer(): samples of `channel` from `first_frame`, already
  // accepted by the assembler. `keep` owns the memory `samples` lie in and is held until they are
  // hashed. May wait (above).
  void Offer(std::shared_ptr<const void> keep, int channel, std::int64_t first_frame,
             std::span<const double> samples);

  // Waits until every offer is hashed; then wire::IncrementalClipDigest::Finish(clip), `clip`
  // being the assembled clip. Once only.
  std::string Finish(const core::Clip& clip);

  // Whether offers went to the thread (tests).
  bool hashing_in_background() const { return thread_.joinable(); }
  // Bytes of samples offered to the thread and not hashed yet (tests).
  std::size_t pending_bytes() const;

 private:
  struct Piece {
    std::shared_ptr<const void> keep;
    int channel = 0;
    std::int64_t first_frame = 0;
    std::span<const double> samples;
  };

  // Hashes an offer where it is made: before the thread starts, when it could not start, or when
  // the offer is larger than the bound.
  void OfferHere(int channel, std::int64_t first_frame, std::span<const double> samples);
  // Claims one of threads_ and starts the thread; false when none is free or it cannot start.
  bool StartThread();
  // Waits until the thread has hashed what makes `predicate` true (under mu_).
  template <class Predicate>
  void WaitFor(Predicate predicate);
  void Run();  // the thread

  // Touched by the thread while offers are pending, by the caller otherwise (the queue's mutex
  // orders the two).
  wire::IncrementalClipDigest digest_;
  const Limits limits_;
  DigestThreads* const threads_;
  wire::CanonicalSampleOrder taken_;  // how far the offers taken so far reach
  std::size_t hashed_here_ = 0;  // bytes hashed by OfferHere()
  bool thread_failed_ = false;   // no thread could be started: every offer hashed here
  mutable std::mutex mu_;
  std::condition_variable changed_;  // a piece queued or hashed, or stopping
  std::deque<Piece> queue_ ABSL_GUARDED_BY(mu_);
  std::size_t pending_bytes_ ABSL_GUARDED_BY(mu_) = 0;  // queued or being hashed
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  std::thread thread_;  // started by the first offer past inline_bytes
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_BACKGROUND_DIGEST_H_
