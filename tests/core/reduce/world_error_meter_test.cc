// WorldErrorMeter::MeasureChanged() (core/src/reduce/world_error_internal.h), which keeps the
// cosines and sines of the channels a call says did not change, against Measure() of the same
// samples by a meter that keeps nothing: the same errors bit for bit over a series of partial
// changes, as the world bound's rounds make them.
#include <bit>
#include <cstdint>
#include <random>
#include <span>
#include <stop_token>
#include <vector>

#include "core/src/reduce/world_error_internal.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core::reduce_internal {
namespace {

void ExpectSameBits(const PointErrors& got, const PointErrors& expected, int round) {
  ASSERT_EQ(got.max_error.size(), expected.max_error.size());
  for (std::size_t p = 0; p < got.max_error.size(); ++p) {
    EXPECT_EQ(std::bit_cast<std::uint64_t>(got.max_error[p]),
              std::bit_cast<std::uint64_t>(expected.max_error[p]))
        << "round " << round << " point " << p;
    EXPECT_EQ(got.worst_frame[p], expected.worst_frame[p]) << "round " << round << " point " << p;
  }
  EXPECT_EQ(std::bit_cast<std::uint64_t>(got.squared_sum),
            std::bit_cast<std::uint64_t>(expected.squared_sum))
      << "round " << round;
}

TEST(WorldErrorMeterTest, MeasuringOnlyTheChangedChannelsGivesTheWholeMeasurementsBits) {
  const absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  absl::StatusOr<WorldErrorMeter> keeping = WorldErrorMeter::ForClip(*clip);
  ASSERT_TRUE(keeping.ok()) << keeping.status();
  absl::StatusOr<WorldErrorMeter> whole = WorldErrorMeter::ForClip(*clip);
  ASSERT_TRUE(whole.ok()) << whole.status();

  const std::size_t channels = clip->channels.size();
  std::vector<std::vector<double>> fitted;
  for (const Channel& channel : clip->channels) fitted.push_back(channel.samples);
  std::vector<std::span<const double>> spans(fitted.begin(), fitted.end());
  std::mt19937_64 random(7);
  std::uniform_real_distribution<double> offset(-3.0, 3.0);
  std::bernoulli_distribution picked(0.3);
  for (int round = 0; round < 6; ++round) {
    // Round 0 measures the samples as they are; later rounds move about a third of the channels
    // (the root's among them in odd rounds, as the world bound refits it).
    std::vector<char> changed(channels, round == 0 ? 1 : 0);
    for (std::size_t c = 0; round > 0 && c < channels; ++c) {
      if (!picked(random) && !(round % 2 == 1 && c < 6)) continue;
      changed[c] = 1;
      for (double& v : fitted[c]) v += offset(random);
    }
    const PointErrors kept = keeping->MeasureChanged(spans, changed);
    const PointErrors measured = whole->Measure(spans);
    ExpectSameBits(kept, measured, round);
    if (round > 0) {
      EXPECT_GT(measured.squared_sum, 0.0);
    }
  }
}

// The source is placed a piece at a time (so that a stop is seen between pieces): the same
// positions as the whole clip's forward kinematics, bit for bit.
TEST(WorldErrorMeterTest, TheSourcePlacedPieceByPieceIsTheWholeClipsForwardKinematics) {
  const absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  const absl::StatusOr<WorldErrorMeter> meter = WorldErrorMeter::ForValidatedClip(*clip);
  ASSERT_TRUE(meter.ok()) << meter.status();
  const absl::StatusOr<PointTrajectories> whole = WorldTrajectories(*clip);
  ASSERT_TRUE(whole.ok()) << whole.status();

  const std::vector<Vec3>& pieces = meter->source().positions;
  ASSERT_EQ(pieces.size(), whole->positions.size());
  std::size_t differing = 0;
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    for (int axis = 0; axis < 3; ++axis) {
      differing += std::bit_cast<std::uint64_t>(pieces[i][axis]) !=
                   std::bit_cast<std::uint64_t>(whole->positions[i][axis]);
    }
  }
  EXPECT_EQ(differing, 0u);
}

// A reduction's world error looks at its stop: a meter whose stop is requested places nothing
// more (forward kinematics of a clip at the sample limit took seconds and could not be stopped).
TEST(WorldErrorMeterTest, AStopEndsThePlacingOfTheSourceAndOfEveryMeasure) {
  const absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  std::stop_source stopped;
  stopped.request_stop();
  const absl::StatusOr<WorldErrorMeter> refused =
      WorldErrorMeter::ForValidatedClip(*clip, stopped.get_token());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kCancelled);

  std::stop_source later;
  absl::StatusOr<WorldErrorMeter> meter = WorldErrorMeter::ForValidatedClip(*clip, later.get_token());
  ASSERT_TRUE(meter.ok()) << meter.status();
  std::vector<std::vector<double>> moved;
  for (const Channel& channel : clip->channels) {
    moved.push_back(channel.samples);
    for (double& v : moved.back()) v += 1.0;
  }
  const std::vector<std::span<const double>> spans(moved.begin(), moved.end());
  EXPECT_GT(meter->Measure(spans).squared_sum, 0.0);
  later.request_stop();
  const PointErrors stopped_errors = meter->Measure(spans);
  EXPECT_EQ(stopped_errors.squared_sum, 0.0);  // no frame placed
  const std::vector<char> every(clip->channels.size(), 1);
  EXPECT_EQ(meter->MeasureChanged(spans, every).squared_sum, 0.0);
}

}  // namespace
}  // namespace tempokey::core::reduce_internal
