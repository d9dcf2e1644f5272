// Retiming the real captures in ../shared/data/bvh.
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/retime/resample.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/retime/time_map.h"
#include "tests/testing/angle_jumps.h"
#include "tests/testing/bit_digest.h"
#include "tests/testing/test_paths.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

using ::tempokey::testing::AllSharedBvhFiles;
using ::tempokey::testing::Jump;
using ::tempokey::testing::JumpsTheSourceLacks;
using ::tempokey::testing::kJumpDegrees;
using ::tempokey::testing::MaxAngleStep;
using ::tempokey::testing::SharedBvh;

Clip ReadOrDie(const std::string& path) {
  absl::StatusOr<Clip> clip = ReadBvhFile(path);
  EXPECT_TRUE(clip.ok()) << clip.status();
  return clip.ok() ? *std::move(clip) : Clip{};
}

using ::tempokey::testing::SameBits;

TEST(RetimeCorpusTest, IdentityIsBitExactOnEveryFile) {
  const std::vector<std::string> files = AllSharedBvhFiles();
  ASSERT_EQ(files.size(), 8u);

  for (const std::string& path : files) {
    const Clip clip = ReadOrDie(path);
    for (RotationMode mode : {RotationMode::kQuaternion, RotationMode::kEuler}) {
      const absl::StatusOr<RetimeResult> r = Retime(clip, {}, {.rotation_mode = mode});

      ASSERT_TRUE(r.ok()) << path << ": " << r.status();
      ASSERT_EQ(r->clip.frame_count, clip.frame_count) << path;
      ASSERT_EQ(r->clip.frame_time_seconds, clip.frame_time_seconds) << path;
      for (std::size_t c = 0; c < clip.channels.size(); ++c) {
        for (std::size_t i = 0; i < clip.channels[c].samples.size(); ++i) {
          ASSERT_TRUE(SameBits(r->clip.channels[c].samples[i], clip.channels[c].samples[i]))
              << path << " channel " << c << " frame " << i;
        }
      }
      EXPECT_EQ(r->clip.skeleton, clip.skeleton);
    }
  }
}

TEST(RetimeCorpusTest, CmuHalfSpeedFromTwoToFourSecondsHasTheClosedFormLengthAndNoNewJumps) {
  const Clip clip = ReadOrDie(SharedBvh("cmu/131_01.bvh"));
  const absl::StatusOr<std::vector<SpeedKnot>> knots =
      ParseSpeedKnots("0s:1,2s:1,2s:0.5,4s:0.5,4s:1");
  ASSERT_TRUE(knots.ok());
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverSource, .speed = *knots};
  // T_o = 2 s at speed 1 + 2 s / 0.5 + (T_s - 4 s) at speed 1 = T_s + 2 s.
  const double dt = clip.frame_time_seconds;
  const double source_seconds = static_cast<double>(clip.frame_count - 1) * dt;
  const double natural_frames = (source_seconds + 2.0) / dt;
  const auto off_grid = static_cast<std::int64_t>(std::floor(natural_frames + 1e-9)) + 1;
  const auto on_grid = static_cast<std::int64_t>(std::round(natural_frames)) + 1;

  const absl::StatusOr<RetimeResult> grid = Retime(clip, warp, {});
  const absl::StatusOr<RetimeResult> exact = Retime(clip, warp, {.fit_to_grid = false});

  ASSERT_TRUE(grid.ok()) << grid.status();
  ASSERT_TRUE(exact.ok()) << exact.status();
  EXPECT_EQ(exact->clip.frame_count, off_grid);
  EXPECT_EQ(grid->clip.frame_count, on_grid);
  EXPECT_EQ(on_grid, 1234);
  EXPECT_NEAR(exact->report.output_duration_seconds, source_seconds + 2.0, 1e-12);
  for (const Jump& jump : JumpsTheSourceLacks(clip, grid->clip, warp, {})) {
    ADD_FAILURE() << "channel " << jump.channel << " output frame " << jump.output_frame
                  << ": step " << jump.output_step << " where the source moves "
                  << jump.source_variation;
  }
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    if (!IsRotation(clip.channels[c].kind)) continue;
    // Slowing down never makes the largest step larger, beyond what a source jump of the
    // largest size plus half a frame of motion either side can add.
    EXPECT_LE(MaxAngleStep(grid->clip.channels[c].samples),
              std::max(kJumpDegrees, MaxAngleStep(clip.channels[c].samples) + 1.0))
        << "channel " << c;
    EXPECT_EQ(grid->clip.channels[c].samples.back(), clip.channels[c].samples.back());
  }
}

TEST(RetimeCorpusTest, SlowAndFastRetimesAddNoAngleJumpsOnEveryFile) {
  // Half speed, 2.5x and 120 -> 30 style compression on every file, both rotation modes.
  for (const std::string& path : AllSharedBvhFiles()) {
    const Clip clip = ReadOrDie(path);
    for (double speed : {0.5, 2.5, 4.0}) {
      for (RotationMode mode : {RotationMode::kQuaternion, RotationMode::kEuler}) {
        const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverSource,
                                   .speed = {{.time = {0.0, false}, .speed = speed}}};
        const RetimeOptions options = {.rotation_mode = mode};

        const absl::StatusOr<RetimeResult> r = Retime(clip, warp, options);

        ASSERT_TRUE(r.ok()) << path << ": " << r.status();
        for (const Jump& jump : JumpsTheSourceLacks(clip, r->clip, warp, options)) {
          ADD_FAILURE() << path << " speed " << speed << " mode " << static_cast<int>(mode)
                        << " channel " << jump.channel << " output frame " << jump.output_frame
                        << ": step " << jump.output_step << " where the source moves "
                        << jump.source_variation;
        }
      }
    }
  }
}

TEST(RetimeCorpusTest, FitToFramesHitsTheCountAndBothEndPosesOnEveryFile) {
  for (const std::string& path : AllSharedBvhFiles()) {
    const Clip clip = ReadOrDie(path);
    for (std::int64_t frames : {clip.frame_count / 3, clip.frame_count * 2}) {
      const absl::StatusOr<RetimeResult> r = Retime(clip, {}, {.fit_frames = frames});

      ASSERT_TRUE(r.ok()) << path << ": " << r.status();
      ASSERT_EQ(r->clip.frame_count, frames) << path;
      for (std::size_t c = 0; c < clip.channels.size(); ++c) {
        EXPECT_TRUE(SameBits(r->clip.channels[c].samples.front(), clip.channels[c].samples.front()))
            << path << " channel " << c;
        EXPECT_TRUE(SameBits(r->clip.channels[c].samples.back(), clip.channels[c].samples.back()))
            << path << " channel " << c;
      }
    }
  }
}

TEST(RetimeCorpusTest, FrameRateChangesOnRealClips) {
  // 120 -> 30 on CMU (frame time 0.0083333 s is 120.0005 Hz: 993 frames are 248.249 output
  // frames, 248 on the grid) and 30 -> 24, 29.97 and 120 on a Bandai clip (0.0333333 s).
  const Clip cmu = ReadOrDie(SharedBvh("cmu/131_01.bvh"));
  const Clip bandai = ReadOrDie(SharedBvh("bandai/dataset-1_walk_active_001.bvh"));
  struct Case {
    const Clip* clip;
    FrameRate rate;
  };
  const Case cases[] = {{&cmu, {30, 1}}, {&cmu, {100, 1}}, {&bandai, {24, 1}},
                        {&bandai, {30000, 1001}}, {&bandai, {120, 1}}};

  for (const Case& c : cases) {
    const double natural = static_cast<double>(c.clip->frame_count - 1) *
                           c.clip->frame_time_seconds * static_cast<double>(c.rate.numerator) /
                           static_cast<double>(c.rate.denominator);

    const absl::StatusOr<RetimeResult> r = Retime(*c.clip, {}, {.output_rate = c.rate});

    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->clip.frame_count, static_cast<std::int64_t>(std::round(natural)) + 1)
        << c.rate.numerator << "/" << c.rate.denominator;
    EXPECT_EQ(r->clip.frame_time_seconds,
              static_cast<double>(c.rate.denominator) / static_cast<double>(c.rate.numerator));
    for (std::size_t ch = 0; ch < c.clip->channels.size(); ++ch) {
      EXPECT_EQ(r->clip.channels[ch].samples.back(), c.clip->channels[ch].samples.back());
    }
  }
}

}  // namespace
}  // namespace tempokey::core
