// BackgroundClipDigest (server/background_digest.h): the id of a clip hashed partly on a thread of
// its own is the clip's content id computed in one piece (wire::ClipContentId, itself checked
// against the published SHA-256 vectors in clip_digest_test), whatever the order of the slices;
// what it holds for hashing stays within its bound and is let go once hashed or dropped. Run
// under ThreadSanitizer too (deploy/sanitizer-tests.sh).
//
// Where the slices come in order, Finish() is given a clip of the same layout whose samples all
// differ: wire::IncrementalClipDigest reads from the clip only what was not offered in order, so
// the id comes out right only if the offers themselves were hashed, each once, in order.
#include "server/background_digest.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <new>
#include <span>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "proto/clip_digest.h"
#include "server/server_options.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::server {
namespace {

constexpr int kChannels = 6;
constexpr std::int64_t kFrames = 3000;
constexpr std::int64_t kSliceFrames = 500;  // 4000 bytes a slice
constexpr std::size_t kSliceBytes = kSliceFrames * sizeof(double);

core::Clip SixChannels(double phase = 0.0) {
  core::Clip clip;
  clip.name = "six";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = kFrames;
  clip.channels.resize(kChannels);
  for (int c = 0; c < kChannels; ++c) {
    clip.channels[c].kind = core::ChannelKind::kScalar;
    clip.channels[c].name = "c" + std::to_string(c);
    clip.channels[c].samples.resize(kFrames);
    for (std::int64_t f = 0; f < kFrames; ++f) {
      const double t = 0.01 * static_cast<double>(f * (c + 1)) + phase;
      clip.channels[c].samples[f] = std::sin(t) * 90.0;
    }
  }
  return clip;
}

// The same layout, every sample different: what Finish() must not need to read.
core::Clip OtherSamples() { return SixChannels(/*phase=*/1.0); }

// One slice as an upload message carries it: samples owned by `keep`, a message of its own
// unless several slices share one (a batch).
struct Slice {
  std::shared_ptr<std::vector<double>> keep;
  int channel = 0;
  std::int64_t first_frame = 0;
  std::span<const double> samples;
};

enum class Order { kCanonical, kReverse };

// The clip's slices; `per_message` consecutive slices share one message.
std::vector<Slice> Slices(const core::Clip& clip, Order order, int per_message = 1) {
  std::vector<Slice> slices;
  std::shared_ptr<std::vector<double>> message;
  for (int c = 0; c < kChannels; ++c) {
    for (std::int64_t f = 0; f < kFrames; f += kSliceFrames) {
      const int index = static_cast<int>(slices.size());
      if (index % per_message == 0) {
        message = std::make_shared<std::vector<double>>();
        message->reserve(static_cast<std::size_t>(per_message * kSliceFrames));
      }
      const auto* first = clip.channels[c].samples.data() + f;
      const std::size_t at = message->size();
      message->insert(message->end(), first, first + kSliceFrames);
      slices.push_back(
          {message, c, f, std::span<const double>(*message).subspan(at, kSliceFrames)});
    }
  }
  if (order == Order::kReverse) std::reverse(slices.begin(), slices.end());
  return slices;
}

void OfferAll(BackgroundClipDigest& digest, const std::vector<Slice>& slices) {
  for (const Slice& slice : slices) {
    digest.Offer(slice.keep, slice.channel, slice.first_frame, slice.samples);
  }
}

// What the caller held of the slices it offered, once it let them go: what the digest still holds.
using Held = std::vector<std::weak_ptr<std::vector<double>>>;
Held OfferAllAndLetGo(BackgroundClipDigest& digest, std::vector<Slice> slices) {
  Held held;
  for (const Slice& slice : slices) held.push_back(slice.keep);
  OfferAll(digest, slices);
  return held;
}

// Small limits, so that a clip of 144 KB of samples crosses them many times.
constexpr BackgroundClipDigest::Limits kSmallLimits = {.inline_bytes = 2 * kSliceBytes,
                                                       .max_pending_bytes = 3 * kSliceBytes};

TEST(BackgroundClipDigestTest, SlicesInOrderAreHashedOnTheThreadIntoTheClipsContentId) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);

  OfferAll(digest, Slices(clip, Order::kCanonical));

  EXPECT_TRUE(digest.hashing_in_background());
  EXPECT_EQ(digest.Finish(OtherSamples()), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SmallUploadIsHashedWhereOfferedIntoTheClipsContentId) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr,
                              {.inline_bytes = 1 << 20, .max_pending_bytes = 1 << 20});

  OfferAll(digest, Slices(clip, Order::kCanonical));

  EXPECT_FALSE(digest.hashing_in_background());
  EXPECT_EQ(digest.Finish(OtherSamples()), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SlicesOutOfOrderStartNoThreadAndGiveTheSameId) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);
  const Held held = OfferAllAndLetGo(digest, Slices(clip, Order::kReverse));

  // Only the last slice offered (channel 0, frame 0) continues the canonical order: it alone is
  // hashed, where it is offered (within inline_bytes); the others are left to Finish() and not
  // held, though they are far more than inline_bytes.
  EXPECT_FALSE(digest.hashing_in_background());
  for (const auto& slice : held) EXPECT_TRUE(slice.expired());
  EXPECT_EQ(digest.Finish(clip), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SlicesSharingAMessageGiveTheSameId) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);

  OfferAll(digest, Slices(clip, Order::kCanonical, /*per_message=*/4));

  EXPECT_TRUE(digest.hashing_in_background());
  EXPECT_EQ(digest.Finish(OtherSamples()), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SamplesWaitingToBeHashedNeverExceedTheBound) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);
  std::size_t most = 0;

  for (const Slice& slice : Slices(clip, Order::kCanonical)) {
    digest.Offer(slice.keep, slice.channel, slice.first_frame, slice.samples);
    most = std::max(most, digest.pending_bytes());
  }

  EXPECT_LE(most, kSmallLimits.max_pending_bytes);
  EXPECT_EQ(digest.Finish(OtherSamples()), wire::ClipContentId(clip));
  EXPECT_EQ(digest.pending_bytes(), 0u);
}

TEST(BackgroundClipDigestTest, AnOfferLargerThanTheBoundIsHashedWhereMadeAfterThoseWaiting) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr,
                              {.inline_bytes = 0, .max_pending_bytes = 2 * kSliceBytes});
  std::size_t most = 0;
  // Channel 0 in slices, then every other channel whole (six slices' worth, over the bound).
  for (const Slice& slice : Slices(clip, Order::kCanonical)) {
    if (slice.channel != 0) continue;
    digest.Offer(slice.keep, slice.channel, slice.first_frame, slice.samples);
    most = std::max(most, digest.pending_bytes());
  }
  for (int c = 1; c < kChannels; ++c) {
    auto whole = std::make_shared<std::vector<double>>(clip.channels[c].samples);
    digest.Offer(whole, c, 0, *whole);
    most = std::max(most, digest.pending_bytes());
  }

  EXPECT_TRUE(digest.hashing_in_background());
  EXPECT_LE(most, 2 * kSliceBytes);
  EXPECT_EQ(digest.Finish(OtherSamples()), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SlicesAreLetGoOnceHashed) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);
  const Held held = OfferAllAndLetGo(digest, Slices(clip, Order::kCanonical));

  digest.Finish(clip);

  for (const auto& slice : held) EXPECT_TRUE(slice.expired());
}

TEST(BackgroundClipDigestTest, DroppedWithSlicesQueuedItLetsThemGoAndReturns) {
  const core::Clip clip = SixChannels();
  Held held;
  {
    BackgroundClipDigest digest(clip, nullptr,
                                {.inline_bytes = 0, .max_pending_bytes = 1 << 20});
    held = OfferAllAndLetGo(digest, Slices(clip, Order::kCanonical));
    // Destroyed here without Finish(): a refused or cancelled upload.
  }

  for (const auto& slice : held) EXPECT_TRUE(slice.expired());
}

TEST(BackgroundClipDigestTest, PastTheThreadLimitAnUploadHashesWhereItsSamplesArrive) {
  const core::Clip clip = SixChannels();
  DigestThreads one(1);
  DigestThreads none(0);
  BackgroundClipDigest first(clip, &one, kSmallLimits);
  BackgroundClipDigest second(clip, &one, kSmallLimits);
  BackgroundClipDigest third(clip, &none, kSmallLimits);

  for (BackgroundClipDigest* digest : {&first, &second, &third}) {
    OfferAll(*digest, Slices(clip, Order::kCanonical));
  }

  EXPECT_TRUE(first.hashing_in_background());
  EXPECT_FALSE(second.hashing_in_background());
  EXPECT_FALSE(third.hashing_in_background());
  EXPECT_EQ(one.in_use(), 1);
  EXPECT_EQ(none.in_use(), 0);
  for (BackgroundClipDigest* digest : {&first, &second, &third}) {
    EXPECT_EQ(digest->Finish(OtherSamples()), wire::ClipContentId(clip));
  }
}

// Ways a thread's start can fail: the system refuses one (what std::thread throws then), another
// exception (std::thread's own allocation), one that says nothing, one that is not a
// std::exception, a starter that returns no thread.
enum class StartFailure {
  kSystemError,
  kOtherException,
  kSilentException,
  kNotAnException,
  kNoThread,
};

// An exception whose what() is empty.
struct Silent : std::exception {
  const char* what() const noexcept override { return ""; }
};

DigestThreads::Starter FailingStarter(StartFailure failure, int& starts) {
  return [failure, &starts](std::function<void()>) -> std::thread {
    ++starts;
    switch (failure) {
      case StartFailure::kSystemError:
        throw std::system_error(std::make_error_code(std::errc::resource_unavailable_try_again),
                                "no thread in this test");
      case StartFailure::kOtherException:
        throw std::bad_alloc();
      case StartFailure::kSilentException:
        throw Silent();
      case StartFailure::kNotAnException:
        throw 42;
      case StartFailure::kNoThread:
        break;
    }
    return std::thread();
  };
}

TEST(BackgroundClipDigestTest, WhenNoThreadCanStartItHashesWhereOfferedAndGivesTheClaimBack) {
  const core::Clip clip = SixChannels();
  for (const StartFailure failure :
       {StartFailure::kSystemError, StartFailure::kOtherException, StartFailure::kSilentException,
        StartFailure::kNotAnException, StartFailure::kNoThread}) {
    int starts = 0;
    DigestThreads threads(2, FailingStarter(failure, starts));
    BackgroundClipDigest digest(clip, &threads, kSmallLimits);

    OfferAll(digest, Slices(clip, Order::kCanonical));

    const int kind = static_cast<int>(failure);
    EXPECT_EQ(starts, 1) << kind;  // tried once, then every offer hashed where made
    EXPECT_FALSE(digest.hashing_in_background()) << kind;
    EXPECT_EQ(threads.in_use(), 0) << kind;
    EXPECT_EQ(digest.pending_bytes(), 0u) << kind;
    EXPECT_EQ(digest.Finish(OtherSamples()), wire::ClipContentId(clip)) << kind;
  }
}

TEST(DigestThreadsTest, AllowsByDefaultOneThreadPerCpuTheServerMayUse) {
  DigestThreads threads;
  const int cpus = DefaultWorkerCount();  // the affinity mask within the cgroup's CPU quota

  for (int i = 0; i < cpus; ++i) EXPECT_TRUE(threads.TryAcquire()) << i;
  EXPECT_FALSE(threads.TryAcquire());
  EXPECT_EQ(threads.in_use(), cpus);
  for (int i = 0; i < cpus; ++i) threads.Release();
  EXPECT_EQ(threads.in_use(), 0);
}

TEST(BackgroundClipDigestTest, ItsThreadIsGivenBackWhenTheDigestGoes) {
  const core::Clip clip = SixChannels();
  DigestThreads threads(1);
  {
    BackgroundClipDigest digest(clip, &threads, kSmallLimits);
    OfferAll(digest, Slices(clip, Order::kCanonical));
    EXPECT_EQ(threads.in_use(), 1);
  }
  EXPECT_EQ(threads.in_use(), 0);

  BackgroundClipDigest next(clip, &threads, kSmallLimits);
  OfferAll(next, Slices(clip, Order::kCanonical));
  EXPECT_TRUE(next.hashing_in_background());
  EXPECT_EQ(next.Finish(OtherSamples()), wire::ClipContentId(clip));
}

}  // namespace
}  // namespace tempokey::server
