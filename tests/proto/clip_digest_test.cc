// Content ids (proto/clip_digest.h): SHA-256 against the published test vectors, and a clip's id
// independent of the order its samples arrive in.
#include "proto/clip_digest.h"

#include <string>

#include "gtest/gtest.h"

namespace tempokey::wire {
namespace {

// FIPS 180-2 appendix B.1 and B.2, and the digest of the empty message.
TEST(ClipDigestTest, Sha256IdMatchesThePublishedVectors) {
  EXPECT_EQ(Sha256Id("abc"),
            "sha256:ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Sha256Id("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "sha256:248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(Sha256Id(""),
            "sha256:e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

core::Clip TwoChannels() {
  core::Clip clip;
  clip.name = "two";
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = 3;
  clip.channels.resize(2);
  clip.channels[0].kind = core::ChannelKind::kScalar;
  clip.channels[0].name = "a";
  clip.channels[0].samples = {1.0, 2.0, 3.0};
  clip.channels[1].kind = core::ChannelKind::kScalar;
  clip.channels[1].name = "b";
  clip.channels[1].samples = {-1.0, 0.5, 7.25};
  return clip;
}

TEST(ClipDigestTest, IdDoesNotDependOnTheOrderSamplesArrive) {
  const core::Clip clip = TwoChannels();

  IncrementalClipDigest backwards(clip);
  backwards.Offer(1, 0, clip.channels[1].samples);  // out of canonical order: hashed at Finish
  backwards.Offer(0, 0, clip.channels[0].samples);
  IncrementalClipDigest in_order(clip);
  in_order.Offer(0, 0, clip.channels[0].samples);
  in_order.Offer(1, 0, clip.channels[1].samples);

  const std::string id = ClipContentId(clip);
  EXPECT_EQ(backwards.Finish(clip), id);
  EXPECT_EQ(in_order.Finish(clip), id);
}

TEST(ClipDigestTest, AnySampleOrNameChangesTheId) {
  const core::Clip clip = TwoChannels();
  core::Clip sample = clip;
  sample.channels[1].samples[2] = 7.250000000000001;
  core::Clip renamed = clip;
  renamed.channels[0].name = "c";

  EXPECT_NE(ClipContentId(sample), ClipContentId(clip));
  EXPECT_NE(ClipContentId(renamed), ClipContentId(clip));
}

}  // namespace
}  // namespace tempokey::wire
