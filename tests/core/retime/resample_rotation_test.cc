// ResampleRotation() on joints whose rotation never changes: their angles come back exactly, and
// near gimbal lock (where the general path's safeguards apply) within the identity tolerance of
// the reference implementation (rotation_reference.h).
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <span>
#include <utility>
#include <stop_token>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/retime/resample.h"
#include "tests/core/retime/rotation_reference.h"
#include "tests/testing/bit_digest.h"

namespace tempokey::core {
namespace {

using ::tempokey::testing::ReferenceResampleRotation;
using ::tempokey::testing::SameBits;

constexpr std::int64_t kSourceCount = 200;

// Output positions at `speed` source frames per output frame, with that decimation ratio.
ResamplePlan PlanAtSpeed(double speed, ResampleFilter filter) {
  std::vector<double> positions, ratios;
  for (double x = 0.0; x <= static_cast<double>(kSourceCount - 1); x += speed) {
    positions.push_back(x + 0.3 * speed);
    ratios.push_back(speed);
  }
  absl::StatusOr<ResamplePlan> plan = MakeResamplePlan(positions, ratios, kSourceCount, filter);
  EXPECT_TRUE(plan.ok()) << plan.status();
  return *std::move(plan);
}

struct Resampled {
  std::array<std::vector<double>, 3> fast, reference;
};

Resampled ResampleFixed(const ResamplePlan& plan, const EulerOrder& order,
                        const std::array<double, 3>& angles) {
  std::array<std::vector<double>, 3> source;
  for (int c = 0; c < 3; ++c) source[c].assign(kSourceCount, angles[c]);
  Resampled r;
  std::array<std::span<const double>, 3> in;
  std::array<std::span<double>, 3> fast, reference;
  for (int c = 0; c < 3; ++c) {
    r.fast[c].assign(plan.position.size(), 0.0);
    r.reference[c].assign(plan.position.size(), 0.0);
    in[c] = source[c];
    fast[c] = r.fast[c];
    reference[c] = r.reference[c];
  }
  ResampleRotation(plan, order, in, fast);
  ReferenceResampleRotation(plan, order, in, reference);
  return r;
}

TEST(ResampleRotationTest, AJointThatNeverTurnsKeepsItsAnglesExactlyUnderEveryKernel) {
  const EulerOrder order = *ParseEulerOrder("ZXY");
  const std::array<double, 3> angles = {-172.25, 33.125, 405.5};
  for (const ResampleFilter filter : {ResampleFilter::kTent, ResampleFilter::kBox,
                                      ResampleFilter::kLinear, ResampleFilter::kCubic,
                                      ResampleFilter::kLanczos3}) {
    for (const double speed : {0.4, 1.0, 2.5, 4.0}) {
      const Resampled r = ResampleFixed(PlanAtSpeed(speed, filter), order, angles);
      for (int c = 0; c < 3; ++c) {
        for (std::size_t j = 0; j < r.fast[c].size(); ++j) {
          ASSERT_EQ(r.fast[c][j], angles[c]) << "filter " << static_cast<int>(filter) << " speed "
                                             << speed << " channel " << c << " sample " << j;
          // The reference's conversions round, a few units in the last place.
          ASSERT_NEAR(r.fast[c][j], r.reference[c][j], 1e-12);
        }
      }
    }
  }
}

TEST(ResampleRotationTest, AFixedJointNearGimbalLockStaysWithinTheReferencesTolerance) {
  const EulerOrder order = *ParseEulerOrder("XYZ");
  // Middle angles whose cosine is below the batched conversions' bound: the outer angles are
  // ill-conditioned there, and the general path (its scalar fallback) answers.
  for (const double middle : {89.99, -88.5, 90.0}) {
    const std::array<double, 3> angles = {12.5, middle, -40.0};
    const Resampled r = ResampleFixed(PlanAtSpeed(2.5, ResampleFilter::kTent), order, angles);
    for (int c = 0; c < 3; ++c) {
      for (std::size_t j = 0; j < r.fast[c].size(); ++j) {
        ASSERT_NEAR(r.fast[c][j], r.reference[c][j], 1e-12)
            << "middle " << middle << " channel " << c << " sample " << j;
      }
    }
  }
}

// A clip long enough that the schedule does not lay out its slots beforehand (about 100 MB of
// them, over its 64 MB): each joint lays them out one batch at a time, with the same results.
TEST(ResampleRotationTest, ALongLanczosClipMatchesTheReferenceBatchByBatch) {
  constexpr std::int64_t kFrames = 600'000;
  constexpr double kSpeed = 1.3;
  std::vector<double> positions, ratios;
  for (double x = 0.37; x <= static_cast<double>(kFrames - 1); x += kSpeed) {
    positions.push_back(x);
    ratios.push_back(kSpeed);
  }
  const absl::StatusOr<ResamplePlan> plan =
      MakeResamplePlan(positions, ratios, kFrames, ResampleFilter::kLanczos3);
  ASSERT_TRUE(plan.ok()) << plan.status();
  std::array<std::vector<double>, 3> source;
  for (auto& channel : source) channel.resize(kFrames);
  for (std::size_t i = 0; i < kFrames; ++i) {
    const auto f = static_cast<double>(i);
    source[0][i] = 30.0 * std::sin(f * 1e-3);
    source[1][i] = 20.0 * std::cos(f * 7e-4);
    // Swinging about 180 degrees, wrapped into [-180, 180]: seams to unwrap.
    source[2][i] = std::remainder(180.0 + 40.0 * std::sin(f * 2e-3), 360.0);
  }
  std::array<std::vector<double>, 3> fast, reference;
  std::array<std::span<const double>, 3> in;
  std::array<std::span<double>, 3> fast_out, reference_out;
  for (int c = 0; c < 3; ++c) {
    fast[c].assign(plan->position.size(), 0.0);
    reference[c].assign(plan->position.size(), 0.0);
    in[c] = source[c];
    fast_out[c] = fast[c];
    reference_out[c] = reference[c];
  }
  const EulerOrder order = *ParseEulerOrder("ZXY");

  ResampleRotation(*plan, order, in, fast_out);
  ReferenceResampleRotation(*plan, order, in, reference_out);

  for (int c = 0; c < 3; ++c) {
    for (std::size_t j = 0; j < fast[c].size(); ++j) {
      ASSERT_NEAR(fast[c][j], reference[c][j], 1e-12) << "channel " << c << " sample " << j;
    }
  }
}

// Output samples of several kinds in one batch (slow sections interpolate, fast ones average):
// the batch orders its slots by kind, so a vector group can hold outputs that are not one after
// the other even where its first and last are a group's width apart (outputs 2..7 and 1, 9 of
// the first plan). Every output must land in its own frame, as the reference puts it.
TEST(ResampleRotationTest, MixedSpeedSectionsPutEveryOutputInItsOwnFrame) {
  std::vector<std::pair<std::vector<double>, std::vector<double>>> profiles = {
      {{0.0, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 9.0, 10.5, 12.0},
       {1.0, 1.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.5, 1.0}}};
  // Random sections of 0.5x, 1.5x and 2x, one to six outputs each.
  std::mt19937 random(1);
  const std::array<double, 3> speeds = {0.5, 1.5, 2.0};
  for (int p = 0; p < 300; ++p) {
    std::vector<double> positions, ratios;
    double x = 0.0;
    while (positions.size() < 40) {
      const double speed = speeds[random() % 3];
      const auto length = 1 + static_cast<std::uint32_t>(random() % 6);
      for (std::uint32_t k = 0; k < length && positions.size() < 40; ++k) {
        positions.push_back(x);
        ratios.push_back(speed);
        x += speed;
      }
    }
    profiles.emplace_back(std::move(positions), std::move(ratios));
  }
  const EulerOrder order = *ParseEulerOrder("ZXY");
  for (std::size_t p = 0; p < profiles.size(); ++p) {
    const auto& [positions, ratios] = profiles[p];
    const auto frames = static_cast<std::int64_t>(std::ceil(positions.back())) + 1;
    const absl::StatusOr<ResamplePlan> plan =
        MakeResamplePlan(positions, ratios, frames, ResampleFilter::kTent);
    ASSERT_TRUE(plan.ok()) << plan.status();
    std::array<std::vector<double>, 3> source, fast, reference;
    std::array<std::span<const double>, 3> in;
    std::array<std::span<double>, 3> fast_out, reference_out;
    for (int c = 0; c < 3; ++c) {
      for (std::int64_t i = 0; i < frames; ++i) {
        const auto f = static_cast<double>(i);
        source[c].push_back(10.0 * (c + 1) + 3.0 * f + 0.1 * f * f);
      }
      fast[c].assign(positions.size(), -999.0);
      reference[c].assign(positions.size(), 0.0);
      in[c] = source[c];
      fast_out[c] = fast[c];
      reference_out[c] = reference[c];
    }

    ResampleRotation(*plan, order, in, fast_out);
    ReferenceResampleRotation(*plan, order, in, reference_out);

    for (int c = 0; c < 3; ++c) {
      for (std::size_t j = 0; j < positions.size(); ++j) {
        ASSERT_NEAR(fast[c][j], reference[c][j], 1e-12)
            << "profile " << p << " channel " << c << " output " << j;
      }
    }
  }
}

TEST(ResampleRotationTest, AScheduleMadeAfterAStopRequestIsNeverUsed) {
  const ResamplePlan plan = PlanAtSpeed(1.3, ResampleFilter::kLanczos3);
  std::array<std::vector<double>, 3> source;
  for (int c = 0; c < 3; ++c) {
    source[c].resize(kSourceCount);
    for (std::int64_t i = 0; i < kSourceCount; ++i) {
      source[c][static_cast<std::size_t>(i)] = 10.0 * (c + 1) * std::sin(0.05 * static_cast<double>(i));
    }
  }
  std::stop_source stop;
  stop.request_stop();
  const RotationSchedule incomplete(plan, stop.get_token());

  constexpr double kUntouched = 1234.5;
  std::array<std::vector<double>, 3> out;
  std::array<std::span<const double>, 3> in;
  std::array<std::span<double>, 3> target;
  for (int c = 0; c < 3; ++c) {
    out[c].assign(plan.position.size(), kUntouched);
    in[c] = source[c];
    target[c] = out[c];
  }
  // No stop requested here: the schedule alone is incomplete.
  RotationScratch scratch;
  ResampleRotation(plan, incomplete, scratch, *ParseEulerOrder("ZXY"), in, target);

  for (int c = 0; c < 3; ++c) {
    for (double v : out[c]) ASSERT_EQ(v, kUntouched);
  }
}

// A plan over `source_count` frames at `speed` source frames per output frame (tent filter).
ResamplePlan PlanOver(std::int64_t source_count, double speed) {
  std::vector<double> positions, ratios;
  for (double x = 0.0; x <= static_cast<double>(source_count - 1); x += speed) {
    positions.push_back(x);
    ratios.push_back(speed);
  }
  absl::StatusOr<ResamplePlan> plan =
      MakeResamplePlan(positions, ratios, source_count, ResampleFilter::kTent);
  EXPECT_TRUE(plan.ok()) << plan.status();
  return *std::move(plan);
}

TEST(ResampleRotationTest, OneScratchServesJointAfterJointAsAFreshOneWould) {
  // Joints of two clips of different lengths, in turn, through one scratch, against each joint
  // resampled alone: a joint that crosses the +-180 seam (unwrapped angles), two in a row near
  // gimbal lock (the scalar path, whose converted rotations must not leak into the next joint), a
  // joint that never turns and ordinary ones, at a speed that takes weighted means and one that
  // takes slerps.
  const EulerOrder order = *ParseEulerOrder("ZXY");
  struct Joint {
    std::int64_t frames;
    double speed;
    std::array<double, 3> base, swing;
  };
  const std::vector<Joint> joints = {
      {300, 2.5, {20, 89.5, -30}, {25, 1.5, 40}},   // near gimbal lock
      {300, 2.5, {-70, 90.4, 60}, {35, 1.2, 15}},   // near gimbal lock, other angles
      {90, 0.7, {175, 10, -40}, {20, 15, 30}},      // crosses the seam
      {300, 2.5, {10, 20, 30}, {40, 30, 25}},
      {90, 2.5, {-120, 89.8, 5}, {30, 0.5, 30}},    // near gimbal lock, the short clip
      {90, 2.5, {12, 34, 56}, {0, 0, 0}},           // never turns
      {300, 0.7, {-10, -40, 170}, {30, 25, 40}},    // crosses the seam, slerps
  };
  RotationScratch scratch;
  for (std::size_t n = 0; n < joints.size(); ++n) {
    const Joint& joint = joints[n];
    const ResamplePlan plan = PlanOver(joint.frames, joint.speed);
    const RotationSchedule schedule(plan);
    std::array<std::vector<double>, 3> source, shared, alone;
    std::array<std::span<const double>, 3> in;
    std::array<std::span<double>, 3> shared_out, alone_out;
    for (int c = 0; c < 3; ++c) {
      for (std::int64_t i = 0; i < joint.frames; ++i) {
        double angle = joint.base[static_cast<std::size_t>(c)] +
                       joint.swing[static_cast<std::size_t>(c)] *
                           std::sin(0.09 * static_cast<double>(i) + c);
        if (angle > 180.0) angle -= 360.0;  // wrapped, as files write them
        source[c].push_back(angle);
      }
      shared[c].assign(plan.position.size(), 0.0);
      alone[c].assign(plan.position.size(), 0.0);
      in[c] = source[c];
      shared_out[c] = shared[c];
      alone_out[c] = alone[c];
    }
    ResampleRotation(plan, schedule, scratch, order, in, shared_out);
    ResampleRotation(plan, order, in, alone_out);
    for (int c = 0; c < 3; ++c) {
      for (std::size_t j = 0; j < shared[c].size(); ++j) {
        ASSERT_TRUE(SameBits(shared[c][j], alone[c][j]))
            << "joint " << n << " channel " << c << " output " << j << ": " << shared[c][j]
            << " against " << alone[c][j];
      }
    }
  }
}

}  // namespace
}  // namespace tempokey::core
