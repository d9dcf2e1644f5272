#include "tempokey/core/retime/time_map.h"

#include <cmath>
#include <random>
#include <vector>

#include "gtest/gtest.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// Closed forms evaluated in doubles over clips of a few seconds: a few ulps of the durations.
constexpr double kExactTolerance = 1e-12;

SpeedKnot Knot(double seconds, double speed) { return {.time = {seconds, false}, .speed = speed}; }
TimeMapKey Key(double output_seconds, double source_seconds) {
  return {.output = {output_seconds, false}, .source = {source_seconds, false}};
}

TimeWarpSpec OverSource(std::vector<SpeedKnot> knots) {
  return {.domain = WarpDomain::kSpeedOverSource, .speed = std::move(knots)};
}
TimeWarpSpec OverOutput(std::vector<SpeedKnot> knots) {
  return {.domain = WarpDomain::kSpeedOverOutput, .speed = std::move(knots)};
}

RetimeOptions NoGrid() { return {.fit_to_grid = false}; }

TimeMap CompileOrDie(double frame_time, std::int64_t frames, const TimeWarpSpec& warp,
                     const RetimeOptions& options) {
  absl::StatusOr<TimeMap> map = TimeMap::Compile(frame_time, frames, warp, options);
  EXPECT_TRUE(map.ok()) << map.status();
  return *std::move(map);
}

std::vector<double> SourceFrames(const TimeMap& map) {
  std::vector<double> x(static_cast<std::size_t>(map.output_frame_count()));
  std::vector<double> rho(x.size());
  map.SampleOutputGrid(x, rho);
  return x;
}

TEST(TimeMapTest, IdentityMapsEveryOutputFrameToTheSameSourceFrameExactly) {
  const TimeMap map = CompileOrDie(0.0083333, 994, {}, {});

  const std::vector<double> x = SourceFrames(map);

  ASSERT_EQ(map.output_frame_count(), 994);
  for (std::size_t j = 0; j < x.size(); ++j) ASSERT_EQ(x[j], static_cast<double>(j)) << j;
  EXPECT_EQ(map.fit_factor(), 1.0);
}

TEST(TimeMapTest, ConstantSpeedDividesTheDuration) {
  const TimeMap map = CompileOrDie(1.0 / 120, 1201, OverSource({Knot(0, 2.0)}), NoGrid());

  EXPECT_NEAR(map.output_duration_seconds(), 5.0, kExactTolerance);
  EXPECT_EQ(map.output_frame_count(), 601);
  EXPECT_NEAR(map.SourceTime(1.25), 2.5, kExactTolerance);
  EXPECT_NEAR(map.SpeedAt(3.0), 2.0, kExactTolerance);
}

TEST(TimeMapTest, LinearRampLastsTheLogarithmicMeanDuration) {
  // 0.5 -> 2 over 1 s: D = h·ln(v1/v0)/(v1 - v0) = ln 4 / 1.5 = 0.924196 s.
  const TimeMap map =
      CompileOrDie(1.0 / 120, 121, OverSource({Knot(0, 0.5), Knot(1, 2.0)}), NoGrid());

  EXPECT_NEAR(map.output_duration_seconds(), std::log(4.0) / 1.5, kExactTolerance);
  EXPECT_NEAR(map.output_duration_seconds(), 0.924196, 5e-7);
  EXPECT_EQ(map.output_frame_count(), 111);  // floor(0.924196 · 120) + 1
}

TEST(TimeMapTest, LinearRampSourceTimeFollowsTheExponential) {
  // dτ/dt = v(τ) = v0 + mτ  =>  τ(t) = (v0/m)(e^{mt} - 1).
  const double v0 = 0.5;
  const double m = 1.5;
  const TimeMap map =
      CompileOrDie(1.0 / 120, 121, OverSource({Knot(0, v0), Knot(1, 2.0)}), NoGrid());

  for (int j = 0; j < map.output_frame_count(); ++j) {
    const double t = j / 120.0;

    EXPECT_NEAR(map.SourceTime(t), v0 / m * std::expm1(m * t), kExactTolerance) << j;
    EXPECT_NEAR(map.SpeedAt(t), v0 * std::exp(m * t), kExactTolerance) << j;
  }
}

TEST(TimeMapTest, NearlyFlatRampKeepsFullPrecision) {
  // d = 1e-10: D = ln(1 + d)/d = 1 - d/2 + d²/3 - ...; (ln v1 - ln v0)/(v1 - v0) in doubles
  // would be wrong in the 7th digit.
  const double d = 1e-10;
  const TimeMap map =
      CompileOrDie(1.0 / 120, 121, OverSource({Knot(0, 1.0), Knot(1, 1.0 + d)}), NoGrid());
  const double v1 = 1.0 + d;  // the double actually stored
  const double dd = v1 - 1.0;

  EXPECT_NEAR(map.output_duration_seconds(), 1.0 - dd / 2 + dd * dd / 3, 1e-15);
  EXPECT_NEAR(Log1pRatio(1e-7), 1.0 - 0.5e-7 + 1e-14 / 3, 1e-16);
  EXPECT_NEAR(Expm1Ratio(-1e-7), 1.0 - 0.5e-7 + 1e-14 / 6, 1e-16);
  EXPECT_EQ(Log1pRatio(0.0), 1.0);
  EXPECT_EQ(Expm1Ratio(0.0), 1.0);
}

TEST(TimeMapTest, SpeedOverOutputTimeIsQuadraticInSourceTime) {
  // s(t) = 1 + t for t <= 1, then 2: τ(t) = t + t²/2, then 1.5 + 2(t - 1); τ = 3 at t = 1.75.
  const TimeMap map =
      CompileOrDie(1.0 / 120, 361, OverOutput({Knot(0, 1.0), Knot(1, 2.0)}), NoGrid());

  EXPECT_NEAR(map.output_duration_seconds(), 1.75, kExactTolerance);
  EXPECT_NEAR(map.SourceTime(0.5), 0.625, kExactTolerance);
  EXPECT_NEAR(map.SourceTime(1.25), 2.0, kExactTolerance);
  EXPECT_NEAR(map.OutputTime(0.625), 0.5, kExactTolerance);
  EXPECT_NEAR(map.SpeedAt(0.5), 1.5, kExactTolerance);
}

TEST(TimeMapTest, TimeMapKeysInterpolateLinearlyAndFlatKeysHold) {
  const TimeWarpSpec warp = {
      .domain = WarpDomain::kTimeMapKeys,
      .keys = {Key(0, 0), Key(1, 0.5), Key(2, 0.5), Key(3, 2.0)},
  };

  const TimeMap map = CompileOrDie(1.0 / 32, 65, warp, NoGrid());

  EXPECT_NEAR(map.output_duration_seconds(), 3.0, kExactTolerance);
  EXPECT_NEAR(map.SourceTime(0.5), 0.25, kExactTolerance);
  EXPECT_EQ(map.SourceTime(1.5), 0.5);
  EXPECT_EQ(map.SpeedAt(1.5), 0.0);
  EXPECT_NEAR(map.SourceTime(2.5), 1.25, kExactTolerance);
  EXPECT_NEAR(map.OutputTime(0.5), 1.0, kExactTolerance);  // a hold's first output time
}

TEST(TimeMapTest, TimeMapKeysBeyondTheClipAreClippedAndShiftedToStartAtZero) {
  const TimeWarpSpec warp = {.domain = WarpDomain::kTimeMapKeys, .keys = {Key(0, -1), Key(3, 2)}};

  const TimeMap map = CompileOrDie(1.0 / 32, 33, warp, NoGrid());

  EXPECT_NEAR(map.output_duration_seconds(), 1.0, kExactTolerance);
  EXPECT_NEAR(map.SourceTime(0.25), 0.25, kExactTolerance);
}

TEST(TimeMapTest, HoldFreezesSourceTimeForItsDuration) {
  const TimeWarpSpec warp = {.holds = {{.at = {0.5, false}, .duration_seconds = 0.25}}};

  const TimeMap map = CompileOrDie(1.0 / 32, 65, warp, NoGrid());

  EXPECT_EQ(map.output_duration_seconds(), 2.25);
  EXPECT_EQ(map.SourceTime(0.6), 0.5);
  EXPECT_EQ(map.SpeedAt(0.6), 0.0);
  EXPECT_NEAR(map.SourceTime(0.8), 0.55, kExactTolerance);
  EXPECT_EQ(map.OutputTime(0.5), 0.5);
  EXPECT_NEAR(map.OutputTime(0.6), 0.85, kExactTolerance);
}

TEST(TimeMapTest, ReverseReadsTheForwardMapBackwards) {
  const TimeWarpSpec forward = OverSource({Knot(0, 0.5), Knot(1, 2.0)});
  TimeWarpSpec backward = forward;
  backward.reverse = true;

  const TimeMap f = CompileOrDie(1.0 / 120, 121, forward, NoGrid());
  const TimeMap b = CompileOrDie(1.0 / 120, 121, backward, NoGrid());

  const double total = f.output_duration_seconds();
  EXPECT_EQ(b.output_duration_seconds(), total);
  for (double t : {0.0, 0.1, 0.5, 0.9, total}) {
    EXPECT_NEAR(b.SourceTime(t), f.SourceTime(total - t), kExactTolerance) << t;
  }
  EXPECT_EQ(SourceFrames(b).front(), 120.0);
}

TEST(TimeMapTest, FitSecondsScalesSpeedsButKeepsHoldLengths) {
  // 10 s of motion + a 2 s hold fit into 7 s: the motion gets 5 s, so every speed doubles.
  const TimeWarpSpec warp = {.holds = {{.at = {4.0, false}, .duration_seconds = 2.0}}};
  RetimeOptions options = NoGrid();
  options.fit_seconds = 7.0;

  const TimeMap map = CompileOrDie(1.0 / 32, 321, warp, options);

  EXPECT_EQ(map.fit_factor(), 2.0);
  EXPECT_EQ(map.output_duration_seconds(), 7.0);
  EXPECT_NEAR(map.SourceTime(1.0), 2.0, kExactTolerance);
  EXPECT_EQ(map.SourceTime(3.0), 4.0);  // inside the hold, which starts at 2 s and lasts 2 s
  EXPECT_NEAR(map.SourceTime(4.5), 5.0, kExactTolerance);
}

TEST(TimeMapTest, FitFramesGivesExactlyThatManyFramesEndingOnTheLastSourceFrame) {
  RetimeOptions options;
  options.fit_frames = 500;

  const TimeMap map =
      CompileOrDie(0.0083333, 994, OverSource({Knot(0, 0.5), Knot(4, 3.0)}), options);
  const std::vector<double> x = SourceFrames(map);

  ASSERT_EQ(map.output_frame_count(), 500);
  EXPECT_EQ(x.front(), 0.0);
  EXPECT_EQ(x.back(), 993.0);
}

TEST(TimeMapTest, FitToGridEndsOnAWholeFrameAndReportsTheFactor) {
  // 993 source frames at speed 0.7 take 1418.571 output frames: the grid rounds to 1419.
  const TimeMap map = CompileOrDie(0.0083333, 994, OverSource({Knot(0, 0.7)}), {});
  const std::vector<double> x = SourceFrames(map);

  EXPECT_EQ(map.output_frame_count(), 1420);
  EXPECT_NEAR(map.fit_factor(), (993.0 / 0.7) / 1419.0, 1e-15);
  EXPECT_EQ(x.back(), 993.0);
  EXPECT_NEAR(map.output_duration_seconds(), 1419 * 0.0083333, kExactTolerance);
}

TEST(TimeMapTest, FrameRateChangeIsTheIdentityAtAnotherRate) {
  RetimeOptions options;
  options.output_rate = FrameRate{30, 1};

  const TimeMap map = CompileOrDie(1.0 / 120, 121, {}, options);
  std::vector<double> x(static_cast<std::size_t>(map.output_frame_count()));
  std::vector<double> rho(x.size());
  map.SampleOutputGrid(x, rho);

  ASSERT_EQ(map.output_frame_count(), 31);
  for (std::size_t j = 0; j < x.size(); ++j) {
    EXPECT_EQ(x[j], 4.0 * static_cast<double>(j));
    EXPECT_EQ(rho[j], 4.0);
  }
}

TEST(TimeMapTest, NtscOutputTimesAreExactFractionsOfTheRate) {
  RetimeOptions options = NoGrid();
  options.output_rate = FrameRate{30000, 1001};

  const TimeMap map = CompileOrDie(1.0 / 30, 301, {}, options);
  const std::vector<double> x = SourceFrames(map);

  EXPECT_EQ(map.output_frame_count(), 300);  // floor(10 s · 29.97) + 1
  for (std::size_t j = 0; j < x.size(); ++j) {
    EXPECT_NEAR(x[j] / 30.0, static_cast<double>(j) * 1001.0 / 30000.0, kExactTolerance);
  }
}

TEST(TimeMapTest, PinsLandExactlyOnTheirFramesWithOneFactorPerInterval) {
  // 4 s at 32 fps. Source 1 s -> frame 64 (32 source frames over 64: c = 0.5); source 3 s ->
  // frame 80 (64 over 16: c = 4); the rest (32 frames) at speed 1 to frame 112.
  RetimeOptions options;
  options.pins = {{.source = {1.0, false}, .output_frame = 64},
                  {.source = {96.0, true}, .output_frame = 80}};

  const TimeMap map = CompileOrDie(1.0 / 32, 129, {}, options);
  const std::vector<double> x = SourceFrames(map);

  ASSERT_EQ(map.output_frame_count(), 113);
  EXPECT_EQ(x[64], 32.0);
  EXPECT_EQ(x[80], 96.0);
  EXPECT_EQ(x[32], 16.0);
  EXPECT_EQ(x[72], 64.0);
  EXPECT_EQ(map.pin_factors(), (std::vector<double>{0.5, 4.0}));
  EXPECT_EQ(map.fit_factor(), 1.0);
}

TEST(TimeMapTest, AHoldAtAPinBelongsToTheIntervalAfterThePin) {
  // 4 s at 32 fps. Source 1 s -> frame 64 (32 source frames over 64: c = 0.5); then the hold at
  // source 1 s, 0.5 s long (frames 64..80); then source 1..3 s (64 frames) over the 32 frames
  // left before frame 112: c = 2. Were the hold counted before the pin, the factors would be
  // 32 / 48 and 64 / 48.
  RetimeOptions options;
  options.pins = {{.source = {1.0, false}, .output_frame = 64},
                  {.source = {3.0, false}, .output_frame = 112}};
  TimeWarpSpec warp;
  warp.holds = {{.at = {1.0, false}, .duration_seconds = 0.5}};

  const TimeMap map = CompileOrDie(1.0 / 32, 129, warp, options);
  const std::vector<double> x = SourceFrames(map);

  EXPECT_EQ(map.pin_factors(), (std::vector<double>{0.5, 2.0}));
  ASSERT_EQ(map.output_frame_count(), 145);  // the last second at speed 1 after frame 112
  EXPECT_EQ(x[64], 32.0);
  EXPECT_EQ(x[72], 32.0);  // in the hold
  EXPECT_EQ(x[96], 64.0);
  EXPECT_EQ(x[112], 96.0);
}

TEST(TimeMapTest, EverySegmentOfAPinsIntervalIsHeldToTheSpeedRange) {
  // Speeds 1, 1, then down to 0.6 at 2 s; the pin at 2 s -> frame 91 scales the interval by
  // 64 / 79.93: its second segment's end would play at 0.48, under the minimum of 0.5.
  RetimeOptions options;
  options.min_speed = 0.5;
  options.max_speed = 2.0;
  options.pins = {{.source = {2.0, false}, .output_frame = 91}};

  const absl::StatusOr<TimeMap> map = TimeMap::Compile(
      1.0 / 32, 129, OverSource({Knot(0, 1.0), Knot(1, 1.0), Knot(2, 0.6)}), options);

  ASSERT_FALSE(map.ok());
  EXPECT_EQ(map.status().message(),
            "pin 1 (2s -> frame 91): needs speeds scaled by 0.800726, so speed knot 3 (2s:0.6) "
            "would play at speed 0.480435, under the minimum 0.5");
}

TEST(TimeMapTest, APinsIntervalIsHeldToTheSpeedRangeAloneNotWithTheOthers) {
  // Speed 1 up to 1 s, 0.6 after. The first interval (to frame 40) is scaled by 0.8 and the
  // second hardly at all; 0.6 x 0.8 would be under the minimum, but no segment has both.
  RetimeOptions options;
  options.min_speed = 0.5;
  options.max_speed = 2.0;
  options.pins = {{.source = {1.0, false}, .output_frame = 40},
                  {.source = {3.0, false}, .output_frame = 147}};

  const TimeMap map = CompileOrDie(
      1.0 / 32, 129, OverSource({Knot(0, 1.0), Knot(1, 1.0), Knot(1, 0.6)}), options);

  ASSERT_EQ(map.pin_factors().size(), 2u);
  EXPECT_EQ(map.pin_factors()[0], 0.8);
  // The second: what is left of the 64 source frames at 0.6 over its 107 output frames, to the
  // six digits printed.
  constexpr double kSixDigits = 1e-6;
  EXPECT_NEAR(map.pin_factors()[1], 0.996885, kSixDigits);
}

TEST(TimeMapTest, EachOfManyPinsLandsOnItsFrameWithItsIntervalsOwnFactor) {
  // A pin on every source frame 1..20000 of a 20002-frame clip; the interval before pin k + 1
  // (one source frame) stretched over 1 + k % 3 output frames: factor 1 / (1 + k % 3). Each
  // interval's factor reads its own segments only (as many pins as this once took a second
  // per thousand, every pin's scale summing every segment).
  constexpr int kPins = 20'000;
  // Each pin's source frame, read back at its output frame after 20 000 frames of scaled
  // segments laid end to end: a few ulps of 20 000.
  constexpr double kFrameTolerance = 1e-9;
  RetimeOptions options;
  std::int64_t frame = 0;
  for (int k = 0; k < kPins; ++k) {
    frame += 1 + k % 3;
    options.pins.push_back({.source = {static_cast<double>(k + 1), true}, .output_frame = frame});
  }

  const TimeMap map = CompileOrDie(1.0 / 120, kPins + 2, {}, options);
  const std::vector<double> x = SourceFrames(map);

  ASSERT_EQ(map.pin_factors().size(), static_cast<std::size_t>(kPins));
  ASSERT_EQ(map.output_frame_count(), frame + 2);  // the last source frame at speed 1
  for (int k = 0; k < kPins; ++k) {
    EXPECT_EQ(map.pin_factors()[k], 1.0 / (1 + k % 3)) << "interval " << k;
    EXPECT_NEAR(x[static_cast<std::size_t>(options.pins[k].output_frame)], k + 1.0,
                kFrameTolerance)
        << "pin " << k + 1;
  }
}

TEST(TimeMapTest, KnotsOutsideTheClipAreHeldFlat) {
  const TimeMap before =
      CompileOrDie(1.0 / 32, 33, OverSource({Knot(-1, 2.0), Knot(-0.5, 2.0)}), NoGrid());
  const TimeMap after =
      CompileOrDie(1.0 / 32, 33, OverSource({Knot(5, 1.0), Knot(6, 3.0)}), NoGrid());

  EXPECT_EQ(before.output_duration_seconds(), 0.5);
  EXPECT_EQ(after.output_duration_seconds(), 1.0);
}

TEST(TimeMapTest, TwoKnotsAtOneTimeMakeAStep) {
  const TimeMap map = CompileOrDie(
      1.0 / 32, 65, OverSource({Knot(0, 1.0), Knot(1, 1.0), Knot(1, 0.5)}), NoGrid());

  EXPECT_EQ(map.output_duration_seconds(), 3.0);
  EXPECT_EQ(map.SourceTime(2.0), 1.5);
}

TEST(TimeMapTest, DecimationRatioIsSpeedTimesRateRatio) {
  RetimeOptions options;
  options.output_rate = FrameRate{30, 1};

  const TimeMap map = CompileOrDie(1.0 / 120, 241, OverSource({Knot(0, 2.0)}), options);

  EXPECT_EQ(map.DecimationRatio(3.0), 8.0);
  EXPECT_EQ(map.output_frame_count(), 31);  // 2 s of source at speed 2 is 1 s at 30 fps
}

// Random piecewise-linear speed curves (fixed seed), over source and over output time, and
// random time-map keys: t(τ(t)) = t and τ(t(τ)) = τ to 1e-12 s.
TEST(TimeMapTest, ForwardAndInverseMapsAreConsistentForRandomWarps) {
  std::mt19937 rng(2024);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  auto speed = [&] { return std::exp(std::log(0.1) + unit(rng) * std::log(100.0)); };
  const double dt = 1.0 / 120;
  const std::int64_t frames = 601;  // 5 s
  const double source_seconds = 5.0;

  for (int trial = 0; trial < 60; ++trial) {
    TimeWarpSpec warp;
    const int kind = trial % 3;
    const int count = 2 + static_cast<int>(unit(rng) * 7);
    if (kind < 2) {
      warp.domain = kind == 0 ? WarpDomain::kSpeedOverSource : WarpDomain::kSpeedOverOutput;
      double time = -0.5;
      for (int k = 0; k < count; ++k) {
        warp.speed.push_back(Knot(time, speed()));
        if (unit(rng) > 0.2) time += unit(rng) * 1.5;  // sometimes a step
      }
    } else {
      warp.domain = WarpDomain::kTimeMapKeys;
      double t = 0.0;
      double tau = 0.0;
      warp.keys.push_back(Key(t, tau));
      while (tau < source_seconds) {
        const double dt_out = 0.05 + unit(rng);
        t += dt_out;
        tau += dt_out * std::min(speed(), 5.0);
        warp.keys.push_back(Key(t, tau));
      }
    }
    warp.reverse = unit(rng) < 0.3;
    RetimeOptions options;
    options.fit_to_grid = unit(rng) < 0.5;
    const TimeMap map = CompileOrDie(dt, frames, warp, options);

    for (int i = 0; i <= 1000; ++i) {
      const double t = map.output_duration_seconds() * i / 1000.0;
      const double tau = source_seconds * i / 1000.0;

      ASSERT_NEAR(map.OutputTime(map.SourceTime(t)), t, kExactTolerance) << trial << " " << i;
      ASSERT_NEAR(map.SourceTime(map.OutputTime(tau)), tau, kExactTolerance) << trial << " " << i;
    }
  }
}

}  // namespace
}  // namespace tempokey::core
