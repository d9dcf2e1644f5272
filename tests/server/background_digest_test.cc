// BackgroundClipDigest (server/background_digest.h): the id of a clip hashed partly on a thread of
// its own is the clip's content id computed in one piece (wire::ClipContentId, itself checked
// against the published SHA-256 vectors in clip_digest_test), whatever the order of the slices;
// what it holds for hashing stays within its bound and is let go once hashed or dropped. Run
// under ThreadSanitizer too (deploy/sanitizer-tests.sh).
#include "server/background_digest.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "proto/clip_digest.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::server {
namespace {

constexpr int kChannels = 6;
constexpr std::int64_t kFrames = 3000;
constexpr std::int64_t kSliceFrames = 500;  // 4000 bytes a slice
constexpr std::size_t kSliceBytes = kSliceFrames * sizeof(double);

core::Clip SixChannels() {
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
      clip.channels[c].samples[f] = std::sin(0.01 * static_cast<double>(f * (c + 1))) * 90.0;
    }
  }
  return clip;
}

// One slice as an upload message carries it: its own copy of the samples, owned by `keep`.
struct Slice {
  std::shared_ptr<std::vector<double>> keep;
  int channel = 0;
  std::int64_t first_frame = 0;
};

std::vector<Slice> Slices(const core::Clip& clip, bool reverse) {
  std::vector<Slice> slices;
  for (int c = 0; c < kChannels; ++c) {
    for (std::int64_t f = 0; f < kFrames; f += kSliceFrames) {
      const auto* first = clip.channels[c].samples.data() + f;
      slices.push_back({std::make_shared<std::vector<double>>(first, first + kSliceFrames), c, f});
    }
  }
  if (reverse) std::reverse(slices.begin(), slices.end());
  return slices;
}

void OfferAll(BackgroundClipDigest& digest, const std::vector<Slice>& slices) {
  for (const Slice& slice : slices) {
    digest.Offer(slice.keep, slice.channel, slice.first_frame, std::span<const double>(*slice.keep));
  }
}

// Small limits, so that a clip of 144 KB of samples crosses them many times.
constexpr BackgroundClipDigest::Limits kSmallLimits = {.inline_bytes = 2 * kSliceBytes,
                                                       .max_pending_bytes = 3 * kSliceBytes};

TEST(BackgroundClipDigestTest, IdHashedOnTheThreadIsTheClipsContentId) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);

  OfferAll(digest, Slices(clip, /*reverse=*/false));

  EXPECT_TRUE(digest.hashing_in_background());
  EXPECT_EQ(digest.Finish(clip), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, IdHashedWhereOfferedIsTheClipsContentId) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr,
                              {.inline_bytes = 1 << 20, .max_pending_bytes = 1 << 20});

  OfferAll(digest, Slices(clip, /*reverse=*/false));

  EXPECT_FALSE(digest.hashing_in_background());
  EXPECT_EQ(digest.Finish(clip), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SlicesInReverseOrderGiveTheSameId) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);

  OfferAll(digest, Slices(clip, /*reverse=*/true));

  EXPECT_TRUE(digest.hashing_in_background());
  EXPECT_EQ(digest.Finish(clip), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SamplesWaitingToBeHashedNeverExceedTheBound) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);
  std::size_t most = 0;

  for (const Slice& slice : Slices(clip, /*reverse=*/false)) {
    digest.Offer(slice.keep, slice.channel, slice.first_frame,
                 std::span<const double>(*slice.keep));
    most = std::max(most, digest.pending_bytes());
  }

  EXPECT_LE(most, kSmallLimits.max_pending_bytes);
  EXPECT_EQ(digest.Finish(clip), wire::ClipContentId(clip));
  EXPECT_EQ(digest.pending_bytes(), 0u);
}

TEST(BackgroundClipDigestTest, AnOfferLargerThanTheBoundIsTakenWhenNothingWaits) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr,
                              {.inline_bytes = 0, .max_pending_bytes = kSliceBytes / 2});

  OfferAll(digest, Slices(clip, /*reverse=*/false));

  EXPECT_EQ(digest.Finish(clip), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, SlicesAreLetGoOnceHashed) {
  const core::Clip clip = SixChannels();
  BackgroundClipDigest digest(clip, nullptr, kSmallLimits);
  std::vector<std::weak_ptr<std::vector<double>>> held;
  {
    const std::vector<Slice> slices = Slices(clip, /*reverse=*/false);
    for (const Slice& slice : slices) held.push_back(slice.keep);
    OfferAll(digest, slices);
  }

  digest.Finish(clip);

  for (const auto& slice : held) EXPECT_TRUE(slice.expired());
}

TEST(BackgroundClipDigestTest, DroppedWithSlicesQueuedItLetsThemGoAndReturns) {
  const core::Clip clip = SixChannels();
  std::vector<std::weak_ptr<std::vector<double>>> held;
  {
    BackgroundClipDigest digest(clip, nullptr,
                                {.inline_bytes = 0, .max_pending_bytes = 1 << 20});
    const std::vector<Slice> slices = Slices(clip, /*reverse=*/false);
    for (const Slice& slice : slices) held.push_back(slice.keep);
    OfferAll(digest, slices);
    // Destroyed here without Finish(): a refused or cancelled upload.
  }

  for (const auto& slice : held) EXPECT_TRUE(slice.expired());
}

TEST(BackgroundClipDigestTest, WithEveryThreadTakenAnUploadHashesWhereItsSamplesArrive) {
  const core::Clip clip = SixChannels();
  DigestThreads threads(1);
  BackgroundClipDigest first(clip, &threads, kSmallLimits);
  BackgroundClipDigest second(clip, &threads, kSmallLimits);

  OfferAll(first, Slices(clip, /*reverse=*/false));
  OfferAll(second, Slices(clip, /*reverse=*/true));

  EXPECT_TRUE(first.hashing_in_background());
  EXPECT_FALSE(second.hashing_in_background());
  EXPECT_EQ(threads.in_use(), 1);
  EXPECT_EQ(first.Finish(clip), wire::ClipContentId(clip));
  EXPECT_EQ(second.Finish(clip), wire::ClipContentId(clip));
}

TEST(BackgroundClipDigestTest, ItsThreadIsGivenBackWhenTheDigestGoes) {
  const core::Clip clip = SixChannels();
  DigestThreads threads(1);
  {
    BackgroundClipDigest digest(clip, &threads, kSmallLimits);
    OfferAll(digest, Slices(clip, /*reverse=*/false));
    EXPECT_EQ(threads.in_use(), 1);
  }
  EXPECT_EQ(threads.in_use(), 0);

  BackgroundClipDigest next(clip, &threads, kSmallLimits);
  OfferAll(next, Slices(clip, /*reverse=*/false));
  EXPECT_TRUE(next.hashing_in_background());
  EXPECT_EQ(next.Finish(clip), wire::ClipContentId(clip));
}

}  // namespace
}  // namespace tempokey::server
