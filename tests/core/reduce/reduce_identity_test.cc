// The reductions give exactly the keys they always did: every method on the shared clips is
// pinned by a digest of its keys (time, value, tangents, weights, bit for bit) and of its
// report's errors, recorded from the library before its inner loops were rewritten for speed
// (commit eadaf91).
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/bit_digest.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

using ::tempokey::testing::BitDigest;
using ::tempokey::testing::SharedBvh;

const Clip& SharedClip(const std::string& relative) {
  static auto* cache = new std::vector<std::pair<std::string, Clip>>();
  for (const auto& [name, clip] : *cache) {
    if (name == relative) return clip;
  }
  absl::StatusOr<Clip> clip = ReadBvhFile(SharedBvh(relative));
  EXPECT_TRUE(clip.ok()) << clip.status();
  cache->emplace_back(relative, clip.ok() ? *std::move(clip) : Clip{});
  return cache->back().second;
}

const std::vector<std::string>& AllClips() {
  static const std::vector<std::string> clips = {
      "cmu/131_01.bvh",
      "bandai/dataset-1_bow_active_001.bvh",
      "bandai/dataset-1_dance-short_normal_001.bvh",
      "bandai/dataset-1_kick_normal_001.bvh",
      "bandai/dataset-1_punch_normal_001.bvh",
      "bandai/dataset-1_walk_active_001.bvh",
      "bandai/dataset-2_walk-turn-left_masculine_026.bvh",
      "bandai/dataset-2_wave-left-hand_normal_013.bvh",
  };
  return clips;
}

void AddResult(const ReduceResult& result, BitDigest& digest) {
  for (const Curve& curve : result.keyed.curves) {
    digest.AddCount(static_cast<std::int64_t>(curve.keys.size()));
    for (const Key& key : curve.keys) {
      digest.Add(key.time_seconds);
      digest.Add(key.value);
      digest.Add(key.in_tangent);
      digest.Add(key.out_tangent);
      digest.Add(key.in_weight.value_or(-1.0));
      digest.Add(key.out_weight.value_or(-1.0));
    }
  }
  const ReductionReport& report = result.report;
  digest.Add(report.max_error);
  digest.Add(report.rms_error);
  digest.AddCount(report.worst_frame);
  for (const ChannelReduction& channel : report.channels) {
    digest.Add(channel.max_error);
    digest.Add(channel.rms_error);
    digest.Add(channel.noise_sigma);
  }
  if (report.world) {
    digest.Add(report.world->max_error);
    digest.Add(report.world->rms_error);
    digest.AddCount(report.world->worst_frame);
    digest.Add(report.world->joint_tolerance);
  }
}

std::string Hex(std::uint64_t value) {
  char text[32];
  std::snprintf(text, sizeof text, "0x%016llx", static_cast<unsigned long long>(value));
  return text;
}

// The digest of ReduceKeys(clip, options) over `clips`, in order.
std::string DigestOf(const std::vector<std::string>& clips, const ReduceOptions& options) {
  BitDigest digest;
  for (const std::string& clip : clips) {
    const absl::StatusOr<ReduceResult> result = ReduceKeys(SharedClip(clip), options);
    EXPECT_TRUE(result.ok()) << clip << ": " << result.status();
    if (result.ok()) AddResult(*result, digest);
  }
  return Hex(digest.value());
}

std::vector<std::string> BandaiClips() {
  return {AllClips().begin() + 1, AllClips().end()};
}

TEST(ReduceIdentityTest, ToleranceKeepsItsPinnedKeysOnEverySharedClip) {
  EXPECT_EQ(DigestOf(AllClips(), ReduceOptions{}), "0xc397481887532af1");
}

TEST(ReduceIdentityTest, PoseAlignedToleranceKeepsItsPinnedKeys) {
  ReduceOptions options;
  options.tolerance.pose_alignment = PoseAlignment::kJoint;
  EXPECT_EQ(DigestOf({AllClips()[0], AllClips()[3]}, options), "0x90b1e808f214e2b3");
  options.tolerance.pose_alignment = PoseAlignment::kClip;
  EXPECT_EQ(DigestOf({AllClips()[1]}, options), "0x27d899e01dbdc5f2");
}

TEST(ReduceIdentityTest, ToleranceWithAKeyBudgetKeepsItsPinnedKeys) {
  ReduceOptions options;
  options.tolerance.key_budget = 900;
  EXPECT_EQ(DigestOf({AllClips()[1]}, options), "0x724e289bd805d609");
}

TEST(ReduceIdentityTest, JointBoundKeepsItsPinnedKeysOnEverySharedClip) {
  ReduceOptions options;
  options.tolerance.joint_tolerance = JointTolerance{.value = 1.0};
  EXPECT_EQ(DigestOf(BandaiClips(), options), "0xd267543a6b193937");
  options.tolerance.joint_tolerance = JointTolerance{.value = 0.5, .percent_of_height = true};
  EXPECT_EQ(DigestOf({AllClips()[0]}, options), "0x24c3a9b9e5d13885");
}

// Re-recorded for two changes of behaviour, not of speed: the whiteness-gated noise estimate,
// and the guard's last resort at real jumps (kGuardFloorLogLambda in noise_fit.cc).
TEST(ReduceIdentityTest, NoiseMethodKeepsItsPinnedKeysOnEverySharedClip) {
  ReduceOptions options;
  options.method = ReduceMethod::kNoise;
  EXPECT_EQ(DigestOf(AllClips(), options), "0xa7878d44f735e8cd");
  options.noise.rotation_sigma_degrees = 0.5;
  EXPECT_EQ(DigestOf({AllClips()[2]}, options), "0x04ed4fd5d07accd1");
}

TEST(ReduceIdentityTest, PaperKeepsItsPinnedKeysOnCmuAndABandaiClip) {
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  options.paper.max_iterations = 8;
  EXPECT_EQ(DigestOf({AllClips()[0], AllClips()[1]}, options), "0xb7d678d665f3d3f4");
}

}  // namespace
}  // namespace tempokey::core
