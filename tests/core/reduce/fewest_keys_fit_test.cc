// The fewest-keys search (ToleranceFitOptions::fewest_keys, core/src/reduce/fewest_keys_fit.h),
// measured by what it does not share with the search: a Hermite evaluation written here, the
// usual fit's keys, and the floor no curve of cubic pieces between keys on frames can go below
// (bench/cubic_minimax.h, itself checked here against every five-frame proof of small inputs).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <numeric>
#include <optional>
#include <limits>
#include <utility>
#include <random>
#include <span>
#include <stop_token>
#include <string>
#include <vector>

#include "bench/cubic_minimax.h"
#include "core/src/reduce/fewest_keys_fit.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/reduce/tolerance_fit.h"
#include "tests/testing/bit_digest.h"
#include "tests/testing/test_paths.h"

#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

using Samples = std::vector<double>;

absl::StatusOr<SplineFit> Fit(const std::vector<Samples>& channels,
                              const std::vector<double>& bounds, bool fewest_keys = true) {
  std::vector<std::span<const double>> spans(channels.begin(), channels.end());
  return FitWithinTolerance(spans, bounds, {.fewest_keys = fewest_keys});
}

// The spline at every frame, from the cubic Hermite's definition (tolerance_fit.h), written
// again here: t = k / L, y = h00 v_a + h10 L m_a + h01 v_b + h11 L m_b.
Samples Evaluate(const SplineFit& fit, std::size_t c) {
  Samples out(static_cast<std::size_t>(fit.frames.back()) + 1);
  out.back() = fit.values[c].back();
  for (std::size_t j = 0; j + 1 < fit.frames.size(); ++j) {
    const double length = static_cast<double>(fit.frames[j + 1] - fit.frames[j]);
    for (std::int64_t f = fit.frames[j]; f < fit.frames[j + 1]; ++f) {
      const double t = static_cast<double>(f - fit.frames[j]) / length;
      out[f] = (2 * t * t * t - 3 * t * t + 1) * fit.values[c][j] +
               (t * t * t - 2 * t * t + t) * length * fit.slopes[c][j] +
               (-2 * t * t * t + 3 * t * t) * fit.values[c][j + 1] +
               (t * t * t - t * t) * length * fit.slopes[c][j + 1];
    }
  }
  return out;
}

double MaxError(const SplineFit& fit, std::size_t c, const Samples& samples) {
  const Samples curve = Evaluate(fit, c);
  return std::transform_reduce(
      curve.begin(), curve.end(), samples.begin(), 0.0,
      [](double a, double b) { return std::max(a, b); },
      [](double y, double s) { return std::abs(y - s); });
}

void ExpectKeysOnEveryFrameRange(const SplineFit& fit, std::size_t frames) {
  ASSERT_FALSE(fit.frames.empty());
  EXPECT_EQ(fit.frames.front(), 0);
  EXPECT_EQ(fit.frames.back(), static_cast<std::int64_t>(frames) - 1);
  for (std::size_t k = 1; k < fit.frames.size(); ++k) {
    EXPECT_GT(fit.frames[k], fit.frames[k - 1]);
    EXPECT_LE(fit.frames[k] - fit.frames[k - 1], kMaxMergedSegmentFrames);
  }
  for (const auto& v : fit.values) EXPECT_EQ(v.size(), fit.frames.size());
  for (const auto& m : fit.slopes) EXPECT_EQ(m.size(), fit.frames.size());
}

// Every rotation channel of a shared capture that is not constant, unwrapped as the reduction
// fits it.
std::vector<Samples> RotationChannels(const std::string& relative) {
  absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh(relative));
  EXPECT_TRUE(clip.ok()) << clip.status();
  std::vector<Samples> out;
  if (!clip.ok()) return out;
  for (const Channel& channel : clip->channels) {
    if (!IsRotation(channel.kind)) continue;
    if (std::all_of(channel.samples.begin(), channel.samples.end(),
                    [&](double v) { return v == channel.samples.front(); })) {
      continue;
    }
    out.push_back(channel.samples);
    UnwrapDegrees(out.back());
  }
  return out;
}

// The floor's minimax error is the largest error five frames force on any cubic (the exchange's
// answer against every five-frame proof of small random stretches).
TEST(FewestKeysFitTest, TheFloorsMinimaxIsTheLargestFiveFrameProof) {
  std::mt19937 random(3);
  std::normal_distribution<double> noise(0.0, 1.0);
  const bench::CubicMinimax minimax;
  for (int trial = 0; trial < 300; ++trial) {
    const int n = 5 + trial % 9;
    Samples s(static_cast<std::size_t>(n));
    for (int f = 0; f < n; ++f) s[f] = 0.02 * f * f + noise(random);
    double proof = 0.0;  // max over five frames of |sum w_j s_j| / sum |w_j|
    for (int a = 0; a < n; ++a)
      for (int b = a + 1; b < n; ++b)
        for (int c = b + 1; c < n; ++c)
          for (int d = c + 1; d < n; ++d)
            for (int e = d + 1; e < n; ++e) {
              const int x[5] = {a, b, c, d, e};
              double sum = 0.0, total = 0.0;
              for (int j = 0; j < 5; ++j) {
                double product = 1.0;
                for (int k = 0; k < 5; ++k) {
                  if (k != j) product *= x[j] - x[k];
                }
                sum += s[x[j]] / product;
                total += std::abs(1.0 / product);
              }
              proof = std::max(proof, std::abs(sum) / total);
            }
    const bench::CubicReach r = minimax.Minimax(s, 0, n - 1);
    EXPECT_NEAR(r.level, proof, 1e-9 * (1.0 + proof)) << "trial " << trial;
    EXPECT_NEAR(r.reached, proof, 1e-9 * (1.0 + proof)) << "trial " << trial;
  }
}

TEST(FewestKeysFitTest, ACubicIsTwoKeys) {
  Samples s(300);
  for (int f = 0; f < 300; ++f) s[f] = 1e-5 * f * f * f - 3e-3 * f * f + 0.2 * f - 4.0;
  absl::StatusOr<SplineFit> fit = Fit({s}, {0.01});
  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_EQ(fit->frames, (std::vector<std::int64_t>{0, 299}));
  EXPECT_LE(MaxError(*fit, 0, s), 0.01);
}

// On real captures: every frame within the bound (measured here), never fewer keys than the
// floor, and fewer keys than the usual fit in all (the search is not optimal everywhere: a
// channel may keep more).
TEST(FewestKeysFitTest, RealCapturesKeepTheBoundWithFewerKeysThanTheUsualFit) {
  const bench::CubicMinimax minimax;
  for (const char* capture :
       {"bandai/dataset-1_kick_normal_001.bvh", "bandai/dataset-1_walk_active_001.bvh"}) {
    const std::vector<Samples> channels = RotationChannels(capture);
    ASSERT_FALSE(channels.empty());
    std::int64_t fewest = 0;
    std::int64_t usual = 0;
    std::int64_t samples = 0;
    for (std::size_t c = 0; c < channels.size(); ++c) {
      absl::StatusOr<SplineFit> fit = Fit({channels[c]}, {0.5});
      absl::StatusOr<SplineFit> plain = Fit({channels[c]}, {0.5}, false);
      ASSERT_TRUE(fit.ok() && plain.ok());
      ExpectKeysOnEveryFrameRange(*fit, channels[c].size());
      EXPECT_LE(MaxError(*fit, 0, channels[c]), 0.5) << capture << " channel " << c;
      const auto keys = static_cast<std::int64_t>(fit->frames.size());
      EXPECT_GE(keys, minimax.FewestKeys(channels[c], 0.5)) << capture << " channel " << c;
      fewest += keys;
      usual += static_cast<std::int64_t>(plain->frames.size());
      samples += static_cast<std::int64_t>(channels[c].size());
    }
    // Measured at 0.5 degrees: kick 11.77 % of samples against 13.93 %, walk 12.79 % against
    // 14.90 % (reduce_quality_bench fewest).
    EXPECT_LT(static_cast<double>(fewest), 0.92 * static_cast<double>(usual)) << capture;
  }
}

TEST(FewestKeysFitTest, ChannelsOfAGroupShareKeyFramesAndEachKeepsItsBound) {
  std::vector<Samples> channels(3, Samples(400));
  std::mt19937 random(11);
  std::normal_distribution<double> jitter(0.0, 0.1);
  for (int f = 0; f < 400; ++f) {
    channels[0][f] = 40.0 * std::sin(f * 0.031) + jitter(random);
    channels[1][f] = 10.0 * std::cos(f * 0.057) + jitter(random);
    channels[2][f] = 2.0 * f;  // a line: any frames fit it
  }
  const std::vector<double> bounds = {0.5, 0.25, 1.0};
  absl::StatusOr<SplineFit> fit = Fit(channels, bounds);
  ASSERT_TRUE(fit.ok()) << fit.status();
  ExpectKeysOnEveryFrameRange(*fit, 400);
  ASSERT_EQ(fit->values.size(), 3u);
  for (std::size_t c = 0; c < 3; ++c) EXPECT_LE(MaxError(*fit, c, channels[c]), bounds[c]);
}

TEST(FewestKeysFitTest, ACalmChannelKeepsSegmentsWithinTheLimit) {
  Samples s(20000);
  for (int f = 0; f < 20000; ++f) s[f] = 30.0 * std::sin(f * 1e-4);
  absl::StatusOr<SplineFit> fit = Fit({s}, {0.5});
  ASSERT_TRUE(fit.ok()) << fit.status();
  ExpectKeysOnEveryFrameRange(*fit, s.size());
  EXPECT_LE(fit->frames.size(), 6u);  // 19 999 frames in segments of at most 4 096
  EXPECT_LE(MaxError(*fit, 0, s), 0.5);
}

TEST(FewestKeysFitTest, JitterFollowedWithinTheBoundAtEveryFrame) {
  std::mt19937 random(5);
  std::normal_distribution<double> noise(0.0, 3.0);
  Samples s(3000);
  for (int f = 0; f < 3000; ++f) s[f] = 50.0 * std::sin(f * 0.02) + noise(random);
  for (double bound : {0.05, 0.5, 5.0}) {
    absl::StatusOr<SplineFit> fit = Fit({s}, {bound});
    ASSERT_TRUE(fit.ok()) << fit.status();
    ExpectKeysOnEveryFrameRange(*fit, s.size());
    EXPECT_LE(MaxError(*fit, 0, s), bound) << bound;
  }
}

// The search itself (not the usual fit it may fall back to): a verdict on one channel at `bound`.
std::optional<SplineFit> Search(const Samples& samples, double bound) {
  const std::span<const double> channel(samples);
  absl::StatusOr<std::optional<SplineFit>> fit =
      reduce_internal::FitFewestKeys({&channel, 1}, {&bound, 1}, {});
  EXPECT_TRUE(fit.ok()) << fit.status();
  return fit.ok() ? *fit : std::nullopt;
}

// Its programs are in units of the bound: the same motion at any scale, or far from zero, gets
// the same keys (to a key: rounding), each within its bound.
TEST(FewestKeysFitTest, ScaledOrOffsetMotionGetsTheSameKeys) {
  std::mt19937 random(5);
  std::normal_distribution<double> noise(0.0, 3.0);
  Samples s(1500);
  for (int f = 0; f < 1500; ++f) s[f] = 50.0 * std::sin(f * 0.02) + noise(random);
  const std::optional<SplineFit> unit = Search(s, 0.5);
  ASSERT_TRUE(unit.has_value());
  for (const auto& [scale, offset] : std::vector<std::pair<double, double>>{
           {1e-6, 0.0}, {1e-3, 0.0}, {1e3, 0.0}, {1e6, 0.0}, {1e290, 0.0}, {1.0, 1e9}}) {
    Samples moved = s;
    for (double& v : moved) v = v * scale + offset;
    const std::optional<SplineFit> fit = Search(moved, 0.5 * scale);
    ASSERT_TRUE(fit.has_value()) << scale << " " << offset;
    EXPECT_NEAR(static_cast<double>(fit->frames.size()), static_cast<double>(unit->frames.size()),
                2.0)
        << scale << " " << offset;
    EXPECT_LE(MaxError(*fit, 0, moved), 0.5 * scale) << scale << " " << offset;
  }
}

// The search's shortcuts (a candidate's reach measured only until it cannot beat the best so
// far; the chosen key's reach reused as the next key's farthest frame) change the work, never
// the keys: the search's own key frames on a real capture (no fallback to the usual fit), single
// channels and a joint's three channels together, as the search without the shortcuts placed
// them (a6d9f96): their count and a digest of every frame in order.
TEST(FewestKeysFitTest, TheSearchShortcutsKeepTheKeysOfTheFullSearch) {
  const std::vector<Samples> channels = RotationChannels("bandai/dataset-1_walk_active_001.bvh");
  ASSERT_GE(channels.size(), 3u);
  std::int64_t keys = 0;
  testing::BitDigest frames;
  auto add = [&](const std::optional<SplineFit>& fit) {
    ASSERT_TRUE(fit.has_value());
    keys += static_cast<std::int64_t>(fit->frames.size());
    for (const std::int64_t f : fit->frames) frames.AddCount(f);
  };
  for (const Samples& channel : channels) add(Search(channel, 0.5));
  const std::vector<std::span<const double>> joint(channels.begin(), channels.begin() + 3);
  const std::vector<double> bounds(3, 0.5);
  absl::StatusOr<std::optional<SplineFit>> together =
      reduce_internal::FitFewestKeys(joint, bounds, {});
  ASSERT_TRUE(together.ok()) << together.status();
  add(*together);
  EXPECT_EQ(keys, 1204);
  EXPECT_EQ(frames.value(), 16702370078165810707u);
}

// Every channel of a real capture gets the search's own keys (not the usual fit's by a fallback).
TEST(FewestKeysFitTest, TheSearchConcludesOnEveryChannelOfARealCapture) {
  for (const Samples& channel : RotationChannels("cmu/131_01.bvh")) {
    const std::optional<SplineFit> fit = Search(channel, 0.5);
    ASSERT_TRUE(fit.has_value());
    EXPECT_LE(MaxError(*fit, 0, channel), 0.5);
  }
}

// A slow motion's keys sit far apart, and the best next key far from the end of what the last
// one reaches: the look-ahead spreads back to the middle of the segment (with only the last 8
// frames the search kept 18, 24 and 34 keys here against the usual fit's 13, 15 and 21).
TEST(FewestKeysFitTest, SlowMotionGetsFewerKeysThanTheUsualFit) {
  std::mt19937 random(1);
  std::normal_distribution<double> noise(0.0, 1.0);
  Samples smooth(2000), jittered(2000), slower(2000);
  for (int f = 0; f < 2000; ++f) {
    smooth[f] = 30.0 * std::sin(f * 0.01);
    jittered[f] = smooth[f] + 0.1 * noise(random);
    slower[f] = 30.0 * std::sin(f * 0.003) + 0.2 * noise(random);
  }
  for (const Samples* s : {&smooth, &jittered, &slower}) {
    const std::optional<SplineFit> fit = Search(*s, 0.5);
    absl::StatusOr<SplineFit> plain = Fit({*s}, {0.5}, false);
    ASSERT_TRUE(fit.has_value() && plain.ok());
    EXPECT_LT(fit->frames.size(), plain->frames.size());
    EXPECT_LE(MaxError(*fit, 0, *s), 0.5);
  }
}

// Asked for fewest keys, a fit never keeps more than without asking: both run, the fewer kept.
TEST(FewestKeysFitTest, NeverMoreKeysThanTheUsualFit) {
  for (const Samples& channel : RotationChannels("bandai/dataset-2_wave-left-hand_normal_013.bvh")) {
    absl::StatusOr<SplineFit> fit = Fit({channel}, {0.5});
    absl::StatusOr<SplineFit> plain = Fit({channel}, {0.5}, false);
    ASSERT_TRUE(fit.ok() && plain.ok());
    EXPECT_LE(fit->frames.size(), plain->frames.size());
  }
}

// A bound near the largest double would overflow the programs' ranges: the search declines and
// the usual fit (two keys) is what the caller gets, bit for bit.
TEST(FewestKeysFitTest, ABoundNearTheLargestDoubleGetsTheUsualFit) {
  Samples s(500);
  for (int f = 0; f < 500; ++f) s[f] = 30.0 * std::sin(f * 0.05);
  const double bound = std::numeric_limits<double>::max();
  EXPECT_FALSE(Search(s, bound).has_value());
  absl::StatusOr<SplineFit> fit = Fit({s}, {bound});
  absl::StatusOr<SplineFit> plain = Fit({s}, {bound}, false);
  ASSERT_TRUE(fit.ok() && plain.ok());
  EXPECT_EQ(fit->frames, plain->frames);
  EXPECT_EQ(fit->values, plain->values);
  EXPECT_EQ(fit->slopes, plain->slopes);
}

TEST(FewestKeysFitTest, ShortAndConstantChannelsTakeTheUsualKeys) {
  for (const Samples& s : {Samples{1.0}, Samples{1.0, 3.0}, Samples(50, 7.0)}) {
    absl::StatusOr<SplineFit> fit = Fit({s}, {0.5});
    absl::StatusOr<SplineFit> plain = Fit({s}, {0.5}, false);
    ASSERT_TRUE(fit.ok() && plain.ok());
    EXPECT_EQ(fit->frames, plain->frames);
    EXPECT_EQ(fit->values, plain->values);
  }
}

TEST(FewestKeysFitTest, ARequestedStopEndsTheSearch) {
  Samples s(20000);
  for (int f = 0; f < 20000; ++f) s[f] = 50.0 * std::sin(f * 0.3) + 5.0 * std::sin(f * 1.7);
  std::stop_source stop;
  stop.request_stop();
  const std::span<const double> channel(s);
  const double bound = 0.5;
  absl::StatusOr<std::optional<SplineFit>> fit =
      reduce_internal::FitFewestKeys({&channel, 1}, {&bound, 1}, stop.get_token());
  EXPECT_EQ(fit.status().code(), absl::StatusCode::kCancelled);
}

TEST(FewestKeysFitTest, ReduceKeysKeepsEveryChannelsBoundWithFewerKeys) {
  absl::StatusOr<Clip> clip =
      ReadBvhFile(testing::SharedBvh("bandai/dataset-1_punch_normal_001.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  ReduceOptions options;
  absl::StatusOr<ReduceResult> plain = ReduceKeys(*clip, options);
  options.tolerance.fewest_keys = true;
  absl::StatusOr<ReduceResult> fewest = ReduceKeys(*clip, options);
  ASSERT_TRUE(plain.ok() && fewest.ok());
  EXPECT_LT(fewest->report.key_count, plain->report.key_count);
  for (const ChannelReduction& channel : fewest->report.channels) {
    const Channel& source = clip->channels[channel.channel_index];
    const double bound = IsRotation(source.kind) ? kDefaultMaxRotationErrorDegrees
                                                 : std::numeric_limits<double>::infinity();
    EXPECT_LE(channel.max_error, bound) << channel.channel_index;
  }
}

}  // namespace
}  // namespace tempokey::core
