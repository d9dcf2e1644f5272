#include "server/background_digest.h"

#include <algorithm>
#include <exception>
#include <system_error>
#include <utility>

#include "server/server_options.h"
#include "spdlog/spdlog.h"

namespace tempokey::server {
namespace {

// Samples the thread hashes between two looks at whether the digest is going.
constexpr std::size_t kHashPieceSamples = (std::size_t{1} << 20) / sizeof(double);

}  // namespace

DigestThreads::DigestThreads() : DigestThreads(DefaultWorkerCount()) {}

DigestThreads::DigestThreads(int max)
    : DigestThreads(max, [](std::function<void()> body) { return std::thread(std::move(body)); }) {}

DigestThreads::DigestThreads(int max, Starter start) : max_(max), start_(std::move(start)) {}

bool DigestThreads::TryAcquire() {
  int in_use = in_use_.load();
  while (in_use < max_) {
    if (in_use_.compare_exchange_weak(in_use, in_use + 1)) return true;
  }
  return false;
}

BackgroundClipDigest::BackgroundClipDigest(const core::Clip& layout, DigestThreads* threads)
    : BackgroundClipDigest(layout, threads, Limits{}) {}

BackgroundClipDigest::BackgroundClipDigest(const core::Clip& layout, DigestThreads* threads,
                                           Limits limits)
    : digest_(layout),
      limits_(limits),
      threads_(threads),
      taken_(layout.frame_count, static_cast<int>(layout.channels.size())) {}

BackgroundClipDigest::~BackgroundClipDigest() {
  if (!thread_.joinable()) return;
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  changed_.notify_all();
  thread_.join();
  if (threads_ != nullptr) threads_->Release();
}

void BackgroundClipDigest::Offer(std::shared_ptr<const void> keep, int channel,
                                 std::int64_t first_frame, std::span<const double> samples) {
  // wire::IncrementalClipDigest hashes such samples from the finished clip instead.
  if (!taken_.Advance(channel, first_frame, samples.size())) return;
  const std::size_t bytes = samples.size_bytes();
  if (!thread_.joinable()) {
    if (thread_failed_ || hashed_here_ + bytes <= limits_.inline_bytes || !StartThread()) {
      OfferHere(channel, first_frame, samples);
      return;
    }
  }
  if (bytes > limits_.max_pending_bytes) {
    WaitFor([&] { return pending_bytes_ == 0; });
    OfferHere(channel, first_frame, samples);
    return;
  }
  {
    std::unique_lock lock(mu_);
    changed_.wait(lock, [&] {
      return pending_bytes_ + bytes <= limits_.max_pending_bytes;
    });
    queue_.push_back({std::move(keep), channel, first_frame, samples});
    pending_bytes_ += bytes;
  }
  changed_.notify_all();
}

void BackgroundClipDigest::OfferHere(int channel, std::int64_t first_frame,
                                     std::span<const double> samples) {
  digest_.Offer(channel, first_frame, samples);
  hashed_here_ += samples.size_bytes();
}

bool BackgroundClipDigest::StartThread() {
  if (threads_ != nullptr && !threads_->TryAcquire()) {
    thread_failed_ = true;
    return false;
  }
  // Any failure to start (std::system_error from the system, std::bad_alloc for the thread's
  // state, a starter that returns no thread) leaves the upload hashing where its samples arrive:
  // an exception let out of here would end the reactor's read callback without a next read or a
  // finish, and the call would hang with its claim held.
  std::string failure = "the starter returned no thread";
  try {
    auto body = [this] { Run(); };
    thread_ = threads_ != nullptr ? threads_->Start(body) : std::thread(body);
    if (thread_.joinable()) return true;
  } catch (const std::exception& error) {
    failure = error.what();
  } catch (...) {
    failure = "an exception that is not a std::exception";
  }
  spdlog::warn("upload digest: no thread ({}), hashing where the samples arrive", failure);
  if (threads_ != nullptr) threads_->Release();
  thread_failed_ = true;
  return false;
}

template <class Predicate>
void BackgroundClipDigest::WaitFor(Predicate predicate) {
  std::unique_lock lock(mu_);
  changed_.wait(lock, predicate);
}

std::string BackgroundClipDigest::Finish(const core::Clip& clip) {
  if (thread_.joinable()) {
    WaitFor([&] { return pending_bytes_ == 0; });
  }
  return digest_.Finish(clip);
}

std::size_t BackgroundClipDigest::pending_bytes() const {
  std::lock_guard lock(mu_);
  return pending_bytes_;
}

void BackgroundClipDigest::Run() {
  for (;;) {
    Piece piece;
    {
      std::unique_lock lock(mu_);
      changed_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;  // the pieces still queued are dropped with the digest
      piece = std::move(queue_.front());
      queue_.pop_front();
    }
    // A MiB at a time, so that a digest being dropped waits for one MiB at most.
    for (std::size_t done = 0; done < piece.samples.size();) {
      const std::size_t count = std::min(kHashPieceSamples, piece.samples.size() - done);
      digest_.Offer(piece.channel, piece.first_frame + static_cast<std::int64_t>(done),
                    piece.samples.subspan(done, count));
      done += count;
      if (done < piece.samples.size()) {
        std::lock_guard lock(mu_);
        if (stopping_) return;
      }
    }
    piece.keep.reset();  // the message's memory goes back before the caller is told
    {
      std::lock_guard lock(mu_);
      pending_bytes_ -= piece.samples.size_bytes();
    }
    changed_.notify_all();
  }
}

}  // namespace tempokey::server
