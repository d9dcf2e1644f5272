// An upload's content id (wire::IncrementalClipDigest) hashed beside the upload's reads. SHA-256
// of the samples was about 38 % of the server's CPU in a 50 MB upload, all of it on the thread
// that reads the stream, between one read and the next (README, "Speed"). Here the first
// Limits::inline_bytes of samples are hashed where they are offered (a small upload starts no
// thread); past them, a thread of the digest's own hashes them in the order offered while the
// caller goes on reading. At most Limits::max_pending_bytes wait to be hashed: an offer beyond
// them waits for the thread to catch up, so the memory an upload holds for its hashing is
// bounded, and no wait is longer than hashing that much (about two milliseconds per 4 MiB
// here). How many uploads hash on threads of their own at once is bounded server-wide
// (DigestThreads): past that, an upload hashes where its samples arrive, as it did before.
//
// No gRPC in here, so it is unit-tested under ThreadSanitizer.
#ifndef TEMPOKEY_SERVER_BACKGROUND_DIGEST_H_
#define TEMPOKEY_SERVER_BACKGROUND_DIGEST_H_

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>

#include "absl/base/thread_annotations.h"
#include "proto/clip_digest.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::server {

// The threads BackgroundClipDigest may start at once, over every upload of a server: one per
// core by default, so the memory offers wait in is at most that many times their bound.
// Thread-safe.
class DigestThreads {
 public:
  DigestThreads();  // std::thread::hardware_concurrency(), at least 1
  explicit DigestThreads(int max) : max_(max) {}
  bool TryAcquire();
  void Release() { in_use_.fetch_sub(1); }
  int in_use() const { return in_use_.load(); }

 private:
  const int max_;
  std::atomic<int> in_use_{0};
};

class BackgroundClipDigest {
 public:
  struct Limits {
    // Samples hashed where they are offered before the thread starts.
    std::size_t inline_bytes = std::size_t{1} << 20;
    // Samples offered but not yet hashed, at most (a larger single offer waits for none).
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
  // hashed. Waits while taking them would leave more than max_pending_bytes unhashed.
  void Offer(std::shared_ptr<const void> keep, int channel, std::int64_t first_frame,
             std::span<const double> samples);

  // Waits until every offer is hashed; then wire::IncrementalClipDigest::Finish(clip), `clip`
  // being the assembled clip. Once only.
  std::string Finish(const core::Clip& clip);

  // Whether offers went to the thread (tests).
  bool hashing_in_background() const { return thread_.joinable(); }
  // Bytes offered and not hashed yet (tests).
  std::size_t pending_bytes() const;

 private:
  struct Piece {
    std::shared_ptr<const void> keep;
    int channel = 0;
    std::int64_t first_frame = 0;
    std::span<const double> samples;
  };

  // Hashes offers where they are made: before the thread starts, or when it could not start.
  void OfferHere(int channel, std::int64_t first_frame, std::span<const double> samples);
  // Claims one of threads_ and starts the thread; false when none is free or it cannot start.
  bool StartThread();
  void Run();  // the thread

  // Touched by the thread while offers are pending, by the caller otherwise (the queue's mutex
  // orders the two).
  wire::IncrementalClipDigest digest_;
  const Limits limits_;
  DigestThreads* const threads_;
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
