// The reductions give exactly the keys they always did: every method on the shared clips is
// pinned by a digest of its keys (time, value, tangents, weights, bit for bit) and of its
// per-channel report, recorded from the library before its inner loops were rewritten for speed
// (commit eadaf91), and by its world-space report's errors to 1e-12 of their value.
//
// The digests left the world-space report out from 79ea94a on, when forward kinematics took the
// vector kernels' sines and cosines (within 2.5 units in the last place of libm's): every digest
// below was recorded from 79ea94a itself, with libm's, and is the same with the kernels', but for
// the joint bound's (see there).
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

// The keys and the per-channel report, bit for bit.
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
}

std::string Hex(std::uint64_t value) {
  char text[32];
  std::snprintf(text, sizeof text, "0x%016llx", static_cast<unsigned long long>(value));
  return text;
}

// What ReduceKeys(clip, options) gives over a list of clips, in order: the digest of AddResult(),
// and the sums over the clips of the world-space report's worst and RMS joint errors.
struct Outcome {
  std::string digest;
  double world_max_sum = 0.0;
  double world_rms_sum = 0.0;
};

Outcome OutcomeOf(const std::vector<std::string>& clips, const ReduceOptions& options) {
  BitDigest digest;
  Outcome outcome;
  for (const std::string& clip : clips) {
    const absl::StatusOr<ReduceResult> result = ReduceKeys(SharedClip(clip), options);
    EXPECT_TRUE(result.ok()) << clip << ": " << result.status();
    if (!result.ok()) continue;
    AddResult(*result, digest);
    if (const auto& world = result->report.world) {
      outcome.world_max_sum += world->max_error;
      outcome.world_rms_sum += world->rms_error;
    }
  }
  outcome.digest = Hex(digest.value());
  return outcome;
}

// The digest of the outcome's keys and per-channel report; its world-space report's errors, which
// move in their last bits with the sines and cosines of forward kinematics, to 1e-12 of the
// values recorded with libm's.
void ExpectPinned(const std::vector<std::string>& clips, const ReduceOptions& options,
                  const std::string& digest, double world_max_sum, double world_rms_sum) {
  const Outcome outcome = OutcomeOf(clips, options);
  EXPECT_EQ(outcome.digest, digest);
  EXPECT_NEAR(outcome.world_max_sum, world_max_sum, 1e-12 * world_max_sum);
  EXPECT_NEAR(outcome.world_rms_sum, world_rms_sum, 1e-12 * world_rms_sum);
}

std::vector<std::string> BandaiClips() {
  return {AllClips().begin() + 1, AllClips().end()};
}

TEST(ReduceIdentityTest, ToleranceKeepsItsPinnedKeysOnEverySharedClip) {
  ExpectPinned(AllClips(), ReduceOptions{}, "0x6f3b34d370d788dc",
               13.844488867691627, 3.6177284074127343);
}

TEST(ReduceIdentityTest, PoseAlignedToleranceKeepsItsPinnedKeys) {
  ReduceOptions options;
  options.tolerance.pose_alignment = PoseAlignment::kJoint;
  ExpectPinned({AllClips()[0], AllClips()[3]}, options, "0xb032d6955d4b9985",
               2.1124795626782742, 0.39742165843185878);
  options.tolerance.pose_alignment = PoseAlignment::kClip;
  ExpectPinned({AllClips()[1]}, options, "0xfbce47e78f5d0824",
               0.35445751376931056, 0.042312453082040832);
}

TEST(ReduceIdentityTest, ToleranceWithAKeyBudgetKeepsItsPinnedKeys) {
  ReduceOptions options;
  options.tolerance.key_budget = 900;
  ExpectPinned({AllClips()[1]}, options, "0xd13b8436adf863e1",
               1.0691040239247074, 0.31704642385307236);
}

// Re-recorded when forward kinematics took the vector kernels' sines and cosines: a joint bound
// refits channels by the world-space errors it measures, so its keys follow those errors' last
// bits. Against libm's (79ea94a), on these 8 clips: the same 30 191 keys on the same frames, 1 228
// values different by at most 1.8e-11 (2.9e-14 of the value), tangents by at most 1.2e-10, the
// worst joint error by at most 5.5e-14 of itself.
TEST(ReduceIdentityTest, JointBoundKeepsItsPinnedKeysOnEverySharedClip) {
  ReduceOptions options;
  options.tolerance.joint_tolerance = JointTolerance{.value = 1.0};
  ExpectPinned(BandaiClips(), options, "0x1b3f386f9fdb0d8d",
               6.3319994713510352, 1.8928578417513466);
  options.tolerance.joint_tolerance = JointTolerance{.value = 0.5, .percent_of_height = true};
  ExpectPinned({AllClips()[0]}, options, "0x704e8a3579555815",
               0.1033398887701321, 0.029561861526390454);
}

// Re-recorded for two changes of behaviour, not of speed: the whiteness-gated noise estimate,
// and the guard's last resort at real jumps (kGuardFloorLogLambda in noise_fit.cc).
TEST(ReduceIdentityTest, NoiseMethodKeepsItsPinnedKeysOnEverySharedClip) {
  ReduceOptions options;
  options.method = ReduceMethod::kNoise;
  ExpectPinned(AllClips(), options, "0x7a0c05bb5d7a5aac",
               0.94066659264132835, 0.099110182212617581);
  options.noise.rotation_sigma_degrees = 0.5;
  ExpectPinned({AllClips()[2]}, options, "0xdb4e03edb61c5aa5",
               3.8733814845109977, 0.26761076634462116);
}

TEST(ReduceIdentityTest, PaperKeepsItsPinnedKeysOnCmuAndABandaiClip) {
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  options.paper.max_iterations = 8;
  ExpectPinned({AllClips()[0], AllClips()[1]}, options, "0x9fb56619036fba38",
               4.977397875407477, 0.51546742803364398);
}

}  // namespace
}  // namespace tempokey::core
