#include "tempokey/core/retime/retime.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"
#include "tempokey/core/retime/resample.h"
#include "tempokey/core/retime/time_map.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// Values of a few units resampled through closed-form maps: a few ulps, far below 1e-12.
constexpr double kLinearTolerance = 1e-12;
// Angles (degrees) recovered from quaternions via atan2: a few ulps of 180.
constexpr double kAngleTolerance = 1e-9;
// World positions of a 4-joint chain of ~10-unit bones through two independent rotation
// pipelines (quaternions vs. matrix logarithms): rounding of a few ulps per joint.
constexpr double kPositionTolerance = 1e-9;

SpeedKnot Knot(double seconds, double speed) { return {.time = {seconds, false}, .speed = speed}; }

TimeWarpSpec OverSource(std::vector<SpeedKnot> knots) {
  return {.domain = WarpDomain::kSpeedOverSource, .speed = std::move(knots)};
}

// A clip of plain named channels (no skeleton).
Clip PlainClip(double frame_time, const std::vector<std::vector<double>>& columns,
               ChannelKind kind = ChannelKind::kScalar) {
  Clip clip;
  clip.name = "synthetic";
  clip.frame_time_seconds = frame_time;
  clip.frame_count = static_cast<std::int64_t>(columns.front().size());
  for (std::size_t c = 0; c < columns.size(); ++c) {
    clip.channels.push_back({.joint = -1, .kind = kind, .name = absl::StrCat("c", c),
                             .samples = columns[c]});
  }
  return clip;
}

// One joint with the given channel kinds, samples from `columns` in the same order.
Clip JointClip(double frame_time, const std::vector<ChannelKind>& kinds,
               const std::vector<std::vector<double>>& columns) {
  Clip clip;
  clip.name = "joint";
  clip.frame_time_seconds = frame_time;
  clip.frame_count = static_cast<std::int64_t>(columns.front().size());
  clip.skeleton.joints.push_back({.name = "J"});
  for (std::size_t c = 0; c < kinds.size(); ++c) {
    clip.skeleton.joints[0].channels.push_back(static_cast<int>(c));
    clip.channels.push_back({.joint = 0, .kind = kinds[c], .samples = columns[c]});
  }
  return clip;
}

std::vector<double> Linear(std::int64_t frames, double frame_time, double offset, double slope) {
  std::vector<double> v(static_cast<std::size_t>(frames));
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = offset + slope * static_cast<double>(i) * frame_time;
  return v;
}

RetimeResult RetimeOrDie(const Clip& clip, const TimeWarpSpec& warp, const RetimeOptions& options) {
  absl::StatusOr<RetimeResult> result = Retime(clip, warp, options);
  EXPECT_TRUE(result.ok()) << result.status();
  return *std::move(result);
}

bool BitEqual(double a, double b) { return std::signbit(a) == std::signbit(b) && a == b; }

// ---- identity ----------------------------------------------------------------------------------

class RetimeFilterTest : public ::testing::TestWithParam<ResampleFilter> {};

TEST_P(RetimeFilterTest, IdentityIsBitExactIncludingNegativeZeroAndSeams) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> angle(-180.0, 180.0);
  std::vector<std::vector<double>> columns(3, std::vector<double>(50));
  for (auto& column : columns) {
    for (double& v : column) v = angle(rng);  // jumps of up to 360: seams everywhere
  }
  columns[1][7] = -0.0;
  const Clip clip = JointClip(1.0 / 30, {ChannelKind::kZRotation, ChannelKind::kXRotation,
                                         ChannelKind::kYRotation}, columns);
  Clip scalar = PlainClip(1.0 / 30, columns);

  const RetimeResult rotation = RetimeOrDie(clip, {}, {.filter = GetParam()});
  const RetimeResult euler =
      RetimeOrDie(clip, {}, {.filter = GetParam(), .rotation_mode = RotationMode::kEuler});
  const RetimeResult plain = RetimeOrDie(scalar, {}, {.filter = GetParam()});

  for (const RetimeResult* r : {&rotation, &euler, &plain}) {
    ASSERT_EQ(r->clip.frame_count, 50);
    EXPECT_EQ(r->clip.frame_time_seconds, clip.frame_time_seconds);
    for (std::size_t c = 0; c < 3; ++c) {
      for (std::size_t i = 0; i < 50; ++i) {
        ASSERT_TRUE(BitEqual(r->clip.channels[c].samples[i], columns[c][i])) << c << " " << i;
      }
    }
  }
  EXPECT_EQ(rotation.report.filtered_sample_count, 0);
  EXPECT_EQ(rotation.report.fit_factor, 1.0);
}

TEST_P(RetimeFilterTest, ReverseIsTheBitExactMirror) {
  const std::vector<double> samples = {1.5, -0.0, 3.25, 7.0, -2.0, 0.125};
  const Clip clip = PlainClip(1.0 / 24, {samples});

  const RetimeResult r = RetimeOrDie(clip, {.reverse = true}, {.filter = GetParam()});

  ASSERT_EQ(r.clip.frame_count, 6);
  for (std::size_t j = 0; j < 6; ++j) {
    EXPECT_TRUE(BitEqual(r.clip.channels[0].samples[j], samples[5 - j])) << j;
  }
}

TEST_P(RetimeFilterTest, AConstantChannelComesOutAsExactlyItsValueAtEveryOutput) {
  // Bone offsets and the like: every output of a channel that never changes is its value to the
  // bit, in slow motion, sped up, at another rate and through a ramp, where a weighted sum of the
  // samples gives it only to within rounding (0.1 summed with weights 1/3 is not 0.1). A single
  // angle channel too (unwrapped, then resampled as a scalar); -0 keeps its sign.
  const double dt = 1.0 / 120;
  const std::vector<double> values = {0.1, -17.3, 1.0 / 3.0, 123456.789, -0.0};
  std::vector<std::vector<double>> columns;
  for (double v : values) columns.emplace_back(301, v);
  const Clip plain = PlainClip(dt, columns);
  const Clip angles = PlainClip(dt, columns, ChannelKind::kYRotation);
  const std::vector<std::pair<TimeWarpSpec, RetimeOptions>> warps = {
      {OverSource({Knot(0, 0.4)}), {}},
      {OverSource({Knot(0, 1.7)}), {}},
      {OverSource({Knot(0, 2.5)}), {}},
      {{}, {.output_rate = FrameRate{30, 1}}},
      {OverSource({Knot(0, 0.5), Knot(1, 3.0)}), {}},
  };
  for (std::size_t w = 0; w < warps.size(); ++w) {
    RetimeOptions options = warps[w].second;
    options.filter = GetParam();
    for (const Clip* clip : {&plain, &angles}) {
      const RetimeResult r = RetimeOrDie(*clip, warps[w].first, options);
      for (std::size_t c = 0; c < values.size(); ++c) {
        for (std::size_t j = 0; j < r.clip.channels[c].samples.size(); ++j) {
          ASSERT_TRUE(BitEqual(r.clip.channels[c].samples[j], values[c]))
              << "warp " << w << " channel " << c << " output " << j << ": "
              << r.clip.channels[c].samples[j];
        }
      }
    }
  }
  // Zeros of both signs compare equal, so a channel of them is constant: the outputs that copy a
  // sample keep its sign (the identity copies every one), the others are zero.
  std::vector<double> zeros(301, 0.0);
  for (std::size_t i = 0; i < zeros.size(); i += 3) zeros[i] = -0.0;
  const Clip signed_zeros = PlainClip(dt, {zeros});
  const RetimeResult same = RetimeOrDie(signed_zeros, {}, {.filter = GetParam()});
  for (std::size_t i = 0; i < zeros.size(); ++i) {
    ASSERT_TRUE(BitEqual(same.clip.channels[0].samples[i], zeros[i])) << i;
  }
  const RetimeResult faster =
      RetimeOrDie(signed_zeros, OverSource({Knot(0, 2.5)}), {.filter = GetParam()});
  for (double v : faster.clip.channels[0].samples) ASSERT_EQ(v, 0.0);
}

INSTANTIATE_TEST_SUITE_P(AllFilters, RetimeFilterTest,
                         ::testing::Values(ResampleFilter::kTent, ResampleFilter::kLinear,
                                           ResampleFilter::kBox, ResampleFilter::kCubic,
                                           ResampleFilter::kLanczos3));

// ---- constant speed: linear signals exact ------------------------------------------------------

struct ConstantSpeedCase {
  double speed;
  bool fit_to_grid;
  ResampleFilter filter;
};

class ConstantSpeedTest : public ::testing::TestWithParam<ConstantSpeedCase> {};

TEST_P(ConstantSpeedTest, ConstantSpeedReproducesLinearSignalExactly) {
  const ConstantSpeedCase& p = GetParam();
  const double dt = 1.0 / 120;
  const std::int64_t frames = 601;  // 5 s
  const Clip clip = PlainClip(dt, {Linear(frames, dt, 3.0, 2.0)});
  const double natural = 600.0 / p.speed;  // output frames the motion takes at speed c
  // Without the grid the output samples τ = c·t; with it the speed becomes 600 / K for the
  // whole frame count K nearest the natural length, so the last sample is the last pose.
  const double grid_frames = std::round(natural);
  const double effective = p.fit_to_grid ? 600.0 / grid_frames : p.speed;
  const std::int64_t expected_frames =
      static_cast<std::int64_t>(std::floor((p.fit_to_grid ? grid_frames : natural) + 1e-9)) + 1;

  const RetimeResult r = RetimeOrDie(clip, OverSource({Knot(0, p.speed)}),
                                     {.fit_to_grid = p.fit_to_grid, .filter = p.filter});

  ASSERT_EQ(r.clip.frame_count, expected_frames);
  for (std::int64_t j = 0; j < expected_frames; ++j) {
    const double tau = effective * static_cast<double>(j) * dt;
    ASSERT_NEAR(r.clip.channels[0].samples[static_cast<std::size_t>(j)], 3.0 + 2.0 * tau,
                kLinearTolerance)
        << j;
  }
  if (p.fit_to_grid) {
    EXPECT_EQ(r.clip.channels[0].samples.back(), clip.channels[0].samples.back());
  }
  EXPECT_NEAR(r.report.fit_factor, p.fit_to_grid ? effective / p.speed : 1.0, 1e-15);
}

std::vector<ConstantSpeedCase> ConstantSpeedCases() {
  std::vector<ConstantSpeedCase> cases;
  for (double speed : {0.5, 1.7, 2.0, 3.3}) {
    for (bool grid : {false, true}) {
      for (ResampleFilter f : {ResampleFilter::kTent, ResampleFilter::kLinear, ResampleFilter::kBox,
                               ResampleFilter::kCubic}) {
        cases.push_back({speed, grid, f});
      }
    }
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(SpeedsGridsFilters, ConstantSpeedTest,
                         ::testing::ValuesIn(ConstantSpeedCases()));

// The tent filter's weights: a partition of unity at every phase and width (a resampled constant
// stays that constant), symmetric within rounding, and the plain hat (linear interpolation) below
// the plan's smallest width, where 1 / (6 a^2) would be infinite.
TEST(TentWeightTest, SumsToOneIsSymmetricAndIsTheHatBelowTheSmallestWidth) {
  for (const double a : {0.25, 1.0, 2.5, 4.0, 9.75}) {
    for (const double phase : {0.0, 0.125, 0.5, 0.7}) {
      double sum = 0.0;
      for (int i = -12; i <= 12; ++i) sum += TentWeight(i - phase, a);
      EXPECT_NEAR(sum, 1.0, 1e-14) << "a " << a << ", phase " << phase;
      EXPECT_NEAR(TentWeight(phase, a), TentWeight(-phase, a), 1e-15) << a;
    }
  }
  for (const double a : {1e-101, 1e-200, 5e-324}) {
    for (const double d : {0.0, 0.5, -0.25, 1.0, 3.0}) {
      EXPECT_EQ(TentWeight(d, a), std::max(0.0, 1.0 - std::abs(d))) << "a " << a << ", d " << d;
    }
  }
}

// The plan's tent weights (evaluated four at a time on vectors) are TentWeight() of each tap's
// offset i - x, bit for bit, at every phase, width and kernel length; and each kernel spans the
// taps it should: the source samples just outside it have a negligible TentWeight() (the plan
// trims below 1e-300), so a weight made wrongly small at an end cannot be trimmed unseen.
TEST(TentWeightTest, PlanWeightsAreTentWeightOfEachTapBitForBit) {
  constexpr std::int64_t kSources = 400;
  constexpr double kTrimmed = 1e-300;
  std::mt19937_64 rng(16);
  std::uniform_real_distribution<double> position(0.0, kSources - 1.0);
  std::uniform_real_distribution<double> ratio(1.0, 9.0);
  std::vector<double> positions, ratios;
  for (int j = 0; j < 2000; ++j) {
    positions.push_back(position(rng));
    ratios.push_back(ratio(rng));
  }
  // Whole positions, steady ratios and positions near both ends as well.
  for (const double x : {1.0, 2.0, 7.0, 200.0, 397.5, 398.0, 398.999}) {
    for (const double rho : {1.5, 2.0, 2.5, 4.0, 8.25}) {
      positions.push_back(x);
      ratios.push_back(rho);
    }
  }

  const absl::StatusOr<ResamplePlan> plan =
      MakeResamplePlan(positions, ratios, kSources, ResampleFilter::kTent);

  ASSERT_TRUE(plan.ok()) << plan.status();
  for (std::size_t j = 0; j < positions.size(); ++j) {
    // No position is an end and every ratio is above 1: every output is a tent kernel.
    ASSERT_EQ(plan->kind[j], SampleKind::kWeighted) << "output " << j;
    const double x = plan->position[j];
    const double a = plan->width[j];
    const std::int64_t first = plan->first[j];
    const std::int64_t taps = plan->offset[j + 1] - plan->offset[j];
    for (std::int64_t n = 0; n < taps; ++n) {
      const std::int64_t i = first + n;
      const double expected = TentWeight(static_cast<double>(i) - x, a);
      const double got = plan->weights[static_cast<std::size_t>(plan->offset[j] + n)];
      ASSERT_TRUE(BitEqual(got, expected))
          << "output " << j << " (x " << x << ", width " << a << "), tap " << i << ": " << got
          << " where TentWeight gives " << expected;
    }
    for (const std::int64_t outside : {first - 1, first + taps}) {
      if (outside < 0 || outside >= kSources) continue;
      EXPECT_LT(std::abs(TentWeight(static_cast<double>(outside) - x, a)), kTrimmed)
          << "output " << j << " (x " << x << ", width " << a << "): source sample " << outside
          << " left out of taps [" << first << ", " << first + taps << ")";
    }
  }
}

// ---- ramp --------------------------------------------------------------------------------------

TEST(RetimeTest, RampFromHalfToDoubleSpeedLastsItsClosedFormAndSamplesTheExponential) {
  // v(τ) = 0.5 + 1.5τ over 1 s: T_o = ln 4 / 1.5 = 0.924196 s, τ(t) = (v0/m)(e^{mt} - 1).
  const double dt = 1.0 / 120;
  const Clip clip = PlainClip(dt, {Linear(121, dt, 0.0, 1.0)});  // x(τ) = τ
  const double v0 = 0.5;
  const double m = 1.5;

  const RetimeResult r =
      RetimeOrDie(clip, OverSource({Knot(0, v0), Knot(1, 2.0)}), {.fit_to_grid = false});

  EXPECT_NEAR(r.report.output_duration_seconds, 0.924196, 5e-7);
  EXPECT_NEAR(r.report.output_duration_seconds, std::log(4.0) / m, kLinearTolerance);
  ASSERT_EQ(r.clip.frame_count, 111);
  for (int j = 0; j < 111; ++j) {
    const double t = j * dt;
    EXPECT_NEAR(r.clip.channels[0].samples[static_cast<std::size_t>(j)], v0 / m * std::expm1(m * t),
                kLinearTolerance)
        << j;
  }
  EXPECT_NEAR(r.report.max_decimation_ratio, v0 * std::exp(m * 110 * dt), kLinearTolerance);
  EXPECT_GT(r.report.filtered_sample_count, 0);  // the part above speed 1 is filtered
}

TEST(RetimeTest, RampOnTheGridScalesBothSpeedsByOneFactor) {
  // On the grid: 110.90 natural frames become 111, every speed scaled by c = 110.90 / 111, so
  // τ(t) = (c·v0 / c·m)(e^{c·m·t} - 1) and the last sample is the last source pose.
  const double dt = 1.0 / 120;
  const Clip clip = PlainClip(dt, {Linear(121, dt, 0.0, 1.0)});
  const double c = (std::log(4.0) / 1.5 * 120.0) / 111.0;

  const RetimeResult r = RetimeOrDie(clip, OverSource({Knot(0, 0.5), Knot(1, 2.0)}), {});

  ASSERT_EQ(r.clip.frame_count, 112);
  EXPECT_NEAR(r.report.fit_factor, c, 1e-15);
  for (int j = 0; j < 112; ++j) {
    EXPECT_NEAR(r.clip.channels[0].samples[static_cast<std::size_t>(j)],
                0.5 / 1.5 * std::expm1(c * 1.5 * j * dt), kLinearTolerance)
        << j;
  }
  EXPECT_EQ(r.clip.channels[0].samples.back(), clip.channels[0].samples.back());
}

// ---- fit -----------------------------------------------------------------------------------------

TEST(RetimeTest, FitToFramesGivesExactlyThoseFramesAndTheSourcesFirstAndLastPoses) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> value(-170.0, 170.0);
  std::vector<std::vector<double>> columns(4, std::vector<double>(200));
  for (auto& column : columns) {
    for (double& v : column) v = value(rng);
  }
  const Clip clip = JointClip(1.0 / 30,
                              {ChannelKind::kXPosition, ChannelKind::kZRotation,
                               ChannelKind::kXRotation, ChannelKind::kYRotation},
                              columns);

  for (std::int64_t n : {5, 17, 120, 250, 5000}) {
    const RetimeResult r = RetimeOrDie(clip, OverSource({Knot(0, 0.5), Knot(3, 2.0)}),
                                       {.fit_frames = n});

    ASSERT_EQ(r.clip.frame_count, n);
    EXPECT_EQ(r.report.output_frame_count, n);
    EXPECT_NEAR(r.report.output_duration_seconds, static_cast<double>(n - 1) / 30.0, 1e-12);
    for (std::size_t c = 0; c < 4; ++c) {
      EXPECT_EQ(r.clip.channels[c].samples.front(), columns[c].front()) << n << " " << c;
      EXPECT_EQ(r.clip.channels[c].samples.back(), columns[c].back()) << n << " " << c;
    }
  }
}

TEST(RetimeTest, FitToSecondsOnTheGridRoundsToWholeFrames) {
  const Clip clip = PlainClip(1.0 / 30, {Linear(301, 1.0 / 30, 0.0, 1.0)});

  const RetimeResult r = RetimeOrDie(clip, {}, {.fit_seconds = 2.01});

  EXPECT_EQ(r.clip.frame_count, 61);  // 2.01 s rounds to 60 frame intervals
  EXPECT_NEAR(r.report.fit_factor, 5.0, 1e-12);
  EXPECT_EQ(r.clip.channels[0].samples.back(), clip.channels[0].samples.back());
}

// ---- anti-aliasing -----------------------------------------------------------------------------

// Least-squares amplitude of `out` against sin(ω·x_j) at the interior outputs (the kernel
// narrows within a few samples of the ends).
double FittedAmplitude(const std::vector<double>& out, double omega_per_output, std::size_t skip) {
  double num = 0.0;
  double den = 0.0;
  for (std::size_t j = skip; j + skip < out.size(); ++j) {
    const double s = std::sin(omega_per_output * static_cast<double>(j));
    num += out[j] * s;
    den += s * s;
  }
  return num / den;
}

double Sinc(double z) { return z == 0.0 ? 1.0 : std::sin(z) / z; }

TEST(RetimeTest, TenHertzSineFrom120To30IsAttenuatedAsTheTentKernelPredicts) {
  // The tent output is the samples filtered by C = hat ⊛ triangle_a (a = ρ = 4 source samples
  // at 120 -> 30). Its frequency response at ω (radians per source sample) is the product of
  // the two triangles' transforms: sinc²(ω/2)·sinc²(aω/2); the aliases at ω ± 2π add < 1e-4.
  const double dt = 1.0 / 120;
  const double omega = 2.0 * std::numbers::pi * 10.0 * dt;
  std::vector<double> samples(1201);
  for (std::size_t i = 0; i < samples.size(); ++i) samples[i] = std::sin(omega * static_cast<double>(i));
  const Clip clip = PlainClip(dt, {samples});
  const double a = 4.0;
  const double expected = std::pow(Sinc(omega / 2), 2) * std::pow(Sinc(a * omega / 2), 2);

  const RetimeResult tent = RetimeOrDie(clip, {}, {.output_rate = FrameRate{30, 1}});
  const RetimeResult point =
      RetimeOrDie(clip, {}, {.output_rate = FrameRate{30, 1}, .filter = ResampleFilter::kLinear});

  ASSERT_EQ(tent.clip.frame_count, 301);
  const double tent_amplitude = FittedAmplitude(tent.clip.channels[0].samples, 4 * omega, 2);
  const double point_amplitude = FittedAmplitude(point.clip.channels[0].samples, 4 * omega, 2);
  EXPECT_NEAR(tent_amplitude / expected, 1.0, 0.02) << tent_amplitude << " vs " << expected;
  EXPECT_LT(tent_amplitude, 0.7);
  EXPECT_NEAR(point_amplitude, 1.0, 1e-12);
  EXPECT_EQ(tent.report.max_decimation_ratio, 4.0);
  EXPECT_EQ(tent.report.filtered_sample_count, 299);  // all but the two end samples
}

// ---- rotations ---------------------------------------------------------------------------------

std::vector<double> SeamRamp() {
  // 150, 160, 170, 180, -170, ... -90: a Z rotation crossing ±180 at 10 degrees per frame.
  std::vector<double> z;
  for (int i = 0; i <= 12; ++i) z.push_back(std::remainder(150.0 + 10.0 * i, 360.0));
  return z;
}

void ExpectSeamAtHalfSpeed(const std::vector<double>& out) {
  ASSERT_EQ(out.size(), 25u);
  for (std::size_t j = 0; j < out.size(); ++j) {
    const double expected = 150.0 + 5.0 * static_cast<double>(j);
    EXPECT_NEAR(std::remainder(out[j] - expected, 360.0), 0.0, kAngleTolerance) << j;
    EXPECT_GT(std::abs(out[j]), 89.0) << j << ": passes near 0";  // never through 0
    EXPECT_LE(std::abs(out[j]), 180.0) << j << ": keeps the source's (-180, 180] convention";
  }
}

TEST(RetimeTest, EulerSeamAtHalfSpeedStepsFiveDegreesPerFrameAndNeverPassesZero) {
  const std::vector<double> z = SeamRamp();
  const std::vector<double> zero(z.size(), 0.0);
  const Clip clip = JointClip(1.0 / 30, {ChannelKind::kZRotation, ChannelKind::kXRotation,
                                         ChannelKind::kYRotation}, {z, zero, zero});

  const RetimeResult r = RetimeOrDie(clip, OverSource({Knot(0, 0.5)}), {});

  ExpectSeamAtHalfSpeed(r.clip.channels[0].samples);
  for (std::size_t j = 0; j < 25; ++j) {
    EXPECT_NEAR(r.clip.channels[1].samples[j], 0.0, kAngleTolerance);
    EXPECT_NEAR(r.clip.channels[2].samples[j], 0.0, kAngleTolerance);
  }
}

TEST(RetimeTest, EulerSeamInEulerModeAndOnASingleAngleChannel) {
  const std::vector<double> z = SeamRamp();
  const std::vector<double> zero(z.size(), 0.0);
  const Clip three = JointClip(1.0 / 30, {ChannelKind::kZRotation, ChannelKind::kXRotation,
                                          ChannelKind::kYRotation}, {z, zero, zero});
  const Clip single = JointClip(1.0 / 30, {ChannelKind::kZRotation}, {z});

  const RetimeResult euler = RetimeOrDie(three, OverSource({Knot(0, 0.5)}),
                                         {.rotation_mode = RotationMode::kEuler});
  const RetimeResult one = RetimeOrDie(single, OverSource({Knot(0, 0.5)}), {});

  ExpectSeamAtHalfSpeed(euler.clip.channels[0].samples);
  ExpectSeamAtHalfSpeed(one.clip.channels[0].samples);
}

TEST(RetimeTest, CompressingAcrossASeamAveragesTheRotationNotTheNumbers) {
  // At 3x the tent averages ~7 samples around ±180: the mean rotation stays near 180, where a
  // naive average of the raw numbers would land near 0.
  std::vector<double> z;
  for (int i = 0; i < 61; ++i) z.push_back(i % 2 == 0 ? 178.0 : -178.0);
  const std::vector<double> zero(z.size(), 0.0);
  const Clip clip = JointClip(1.0 / 30, {ChannelKind::kZRotation, ChannelKind::kXRotation,
                                         ChannelKind::kYRotation}, {z, zero, zero});

  for (RotationMode mode : {RotationMode::kQuaternion, RotationMode::kEuler}) {
    const RetimeResult r = RetimeOrDie(clip, OverSource({Knot(0, 3.0)}), {.rotation_mode = mode});

    for (double v : r.clip.channels[0].samples) EXPECT_GT(std::abs(v), 175.0);
  }
}

TEST(RetimeTest, RotationJumpOverOneHundredFiftyDegreesIsHeldNotInterpolated) {
  // Frame 2 -> 3 flips the X rotation by 170 degrees in one frame (a glitch, as CMU's thumb
  // does): the sample half way between copies the nearer pose instead of inventing a half turn
  // on the geodesic; elsewhere the slerp interpolates.
  const std::vector<double> x = {0.0, 10.0, 20.0, -150.0, -140.0};
  const std::vector<double> zero(x.size(), 0.0);
  const Clip clip = JointClip(1.0 / 30, {ChannelKind::kXRotation, ChannelKind::kYRotation,
                                         ChannelKind::kZRotation}, {x, zero, zero});

  const RetimeResult r = RetimeOrDie(clip, OverSource({Knot(0, 0.5)}), {});

  const std::vector<double>& out = r.clip.channels[0].samples;
  ASSERT_EQ(out.size(), 9u);
  EXPECT_NEAR(out[1], 5.0, kAngleTolerance);
  EXPECT_NEAR(out[3], 15.0, kAngleTolerance);
  EXPECT_EQ(out[5], -150.0);  // x = 2.5 rounds to the later frame
  EXPECT_NEAR(out[7], -145.0, kAngleTolerance);
}

// A joint spinning 100 or 140 degrees a frame at 30 fps (a fast spin; the file's angles wrap at
// +-180) is slowed down 4 times: every output turns a quarter of a step further, as the slerp
// does. With turns over 90 degrees held as discontinuities, the output stood still for four
// frames at a time and was up to 50 degrees off.
TEST(RetimeTest, AFastSpinOfUpToOneHundredFiftyDegreesAFrameIsInterpolated) {
  for (const double step : {100.0, 140.0}) {
    std::vector<double> z;
    for (int i = 0; i < 20; ++i) z.push_back(std::remainder(i * step, 360.0));
    const std::vector<double> zero(z.size(), 0.0);
    const Clip clip = JointClip(1.0 / 30, {ChannelKind::kZRotation, ChannelKind::kXRotation,
                                           ChannelKind::kYRotation}, {z, zero, zero});

    const RetimeResult r = RetimeOrDie(clip, OverSource({Knot(0, 0.25)}), {});

    const std::vector<double>& out = r.clip.channels[0].samples;
    ASSERT_EQ(out.size(), 77u) << step;
    for (std::size_t j = 0; j < out.size(); ++j) {
      const double expected = static_cast<double>(j) * step / 4.0;
      EXPECT_NEAR(std::remainder(out[j] - expected, 360.0), 0.0, kAngleTolerance)
          << step << " output " << j;
    }
  }
}

// Rotation matrix of one axis, written out independently of the library.
using M3 = std::array<std::array<double, 3>, 3>;
M3 TestAxis(int axis, double degrees) {
  const double r = degrees * std::numbers::pi / 180.0;
  const double c = std::cos(r), s = std::sin(r);
  if (axis == 0) return {{{1, 0, 0}, {0, c, -s}, {0, s, c}}};
  if (axis == 1) return {{{c, 0, s}, {0, 1, 0}, {-s, 0, c}}};
  return {{{c, -s, 0}, {s, c, 0}, {0, 0, 1}}};
}
M3 Mul(const M3& a, const M3& b) {
  M3 o{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) o[i][j] += a[i][k] * b[k][j];
  return o;
}
M3 Transpose(const M3& a) {
  M3 o{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) o[i][j] = a[j][i];
  return o;
}
// Geodesic interpolation R0·exp(t·log(R0ᵀR1)) via Rodrigues' formula.
M3 Geodesic(const M3& r0, const M3& r1, double t) {
  const M3 rel = Mul(Transpose(r0), r1);
  const double cos_angle = std::clamp((rel[0][0] + rel[1][1] + rel[2][2] - 1.0) / 2.0, -1.0, 1.0);
  const double angle = std::acos(cos_angle);
  if (angle < 1e-12) return r0;
  const double k = 1.0 / (2.0 * std::sin(angle));
  const double ax = (rel[2][1] - rel[1][2]) * k;
  const double ay = (rel[0][2] - rel[2][0]) * k;
  const double az = (rel[1][0] - rel[0][1]) * k;
  const double a = angle * t;
  const double s = std::sin(a), c = std::cos(a), v = 1.0 - c;
  const M3 step = {{{c + ax * ax * v, ax * ay * v - az * s, ax * az * v + ay * s},
                    {ay * ax * v + az * s, c + ay * ay * v, ay * az * v - ax * s},
                    {az * ax * v - ay * s, az * ay * v + ax * s, c + az * az * v}}};
  return Mul(r0, step);
}

struct TestJoint {
  int parent;
  Vec3 offset;
  std::vector<ChannelKind> kinds;
};

// World positions of every joint given each joint's local rotation matrix and translation.
std::vector<Vec3> TestFk(const std::vector<TestJoint>& joints, const std::vector<M3>& rotation,
                         const std::vector<Vec3>& translation) {
  std::vector<M3> world_r(joints.size());
  std::vector<Vec3> world_p(joints.size());
  for (std::size_t j = 0; j < joints.size(); ++j) {
    if (joints[j].parent < 0) {
      world_r[j] = rotation[j];
      world_p[j] = translation[j];
      continue;
    }
    const auto p = static_cast<std::size_t>(joints[j].parent);
    for (int i = 0; i < 3; ++i) {
      world_p[j][i] = world_p[p][i];
      for (int k = 0; k < 3; ++k) world_p[j][i] += world_r[p][i][k] * translation[j][k];
    }
    world_r[j] = Mul(world_r[p], rotation[j]);
  }
  return world_p;
}

// Local rotation (channels composed left to right) and translation of joint j at one frame.
void LocalTransform(const Clip& clip, std::size_t joint, std::size_t frame, M3& rotation,
                    Vec3& translation) {
  rotation = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  translation = clip.skeleton.joints[joint].offset;
  for (int c : clip.skeleton.joints[joint].channels) {
    const Channel& ch = clip.channels[static_cast<std::size_t>(c)];
    if (IsRotation(ch.kind)) rotation = Mul(rotation, TestAxis(Axis(ch.kind), ch.samples[frame]));
    if (IsPosition(ch.kind)) translation[static_cast<std::size_t>(Axis(ch.kind))] = ch.samples[frame];
  }
}

TEST(RetimeTest, MixedRotationOrdersMatchAnIndependentForwardKinematicsReference) {
  using K = ChannelKind;
  const std::vector<TestJoint> joints = {
      {-1, {0, 0, 0}, {K::kXPosition, K::kYPosition, K::kZPosition, K::kZRotation, K::kXRotation, K::kYRotation}},
      {0, {0, 10, 0}, {K::kXRotation, K::kYRotation, K::kZRotation}},
      {1, {5, 0, 0}, {K::kYRotation, K::kZRotation, K::kXRotation}},
      {2, {0, 0, 4}, {K::kZRotation, K::kYRotation, K::kXRotation}},
      {3, {3, 1, 0}, {}},
  };
  const std::size_t frames = 40;
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> start(-180.0, 180.0);
  std::uniform_real_distribution<double> step(-20.0, 20.0);  // < 90° per frame in all
  Clip clip;
  clip.frame_time_seconds = 1.0 / 30;
  clip.frame_count = static_cast<std::int64_t>(frames);
  for (std::size_t j = 0; j < joints.size(); ++j) {
    clip.skeleton.joints.push_back({.name = absl::StrCat("joint", j),
                                    .parent = joints[j].parent,
                                    .offset = joints[j].offset});
    for (K kind : joints[j].kinds) {
      std::vector<double> samples(frames);
      double value = start(rng);
      for (double& s : samples) {
        value += step(rng);
        s = IsRotation(kind) ? std::remainder(value, 360.0) : value;  // wrapped: seams included
      }
      clip.skeleton.joints[j].channels.push_back(static_cast<int>(clip.channels.size()));
      clip.channels.push_back({.joint = static_cast<int>(j), .kind = kind, .samples = samples});
    }
  }
  struct Case {
    TimeWarpSpec warp;
    RetimeOptions options;
  };
  const std::vector<Case> cases = {
      {OverSource({Knot(0, 0.5)}), {}},
      {{}, {.output_rate = FrameRate{120, 1}}},
      {OverSource({Knot(0, 0.3), Knot(1.3, 0.9)}), {.fit_to_grid = false}},
  };

  for (const Case& c : cases) {
    const RetimeResult r = RetimeOrDie(clip, c.warp, c.options);
    const TimeMap map =
        *TimeMap::Compile(clip.frame_time_seconds, clip.frame_count, c.warp, c.options);
    ASSERT_EQ(r.clip.frame_count, map.output_frame_count());

    for (std::int64_t out = 0; out < r.clip.frame_count; ++out) {
      const double x = map.SourceFrame(static_cast<double>(out));
      const auto i0 = std::min(static_cast<std::size_t>(std::floor(x)), frames - 2);
      const double t = x - static_cast<double>(i0);
      std::vector<M3> ref_r(joints.size()), got_r(joints.size());
      std::vector<Vec3> ref_p(joints.size()), got_p(joints.size());
      for (std::size_t j = 0; j < joints.size(); ++j) {
        M3 r0, r1;
        Vec3 p0, p1;
        LocalTransform(clip, j, i0, r0, p0);
        LocalTransform(clip, j, i0 + 1, r1, p1);
        ref_r[j] = Geodesic(r0, r1, t);
        for (int k = 0; k < 3; ++k) ref_p[j][k] = p0[k] + t * (p1[k] - p0[k]);
        LocalTransform(r.clip, j, static_cast<std::size_t>(out), got_r[j], got_p[j]);
      }
      const std::vector<Vec3> expected = TestFk(joints, ref_r, ref_p);
      const std::vector<Vec3> got = TestFk(joints, got_r, got_p);
      for (std::size_t j = 0; j < joints.size(); ++j) {
        for (int k = 0; k < 3; ++k) {
          ASSERT_NEAR(got[j][k], expected[j][k], kPositionTolerance)
              << "output " << out << " joint " << j << " axis " << k;
        }
      }
    }
  }
}

// ---- holds, rates ------------------------------------------------------------------------------

TEST(RetimeTest, HoldFreezesThePoseThenPlaysOn) {
  const double dt = 1.0 / 32;
  std::vector<double> samples(33);
  for (std::size_t i = 0; i < samples.size(); ++i) samples[i] = std::sin(0.3 * static_cast<double>(i));
  const Clip clip = PlainClip(dt, {samples});

  const RetimeResult r =
      RetimeOrDie(clip, {.holds = {{.at = {10.0, true}, .duration_seconds = 0.25}}}, {});

  ASSERT_EQ(r.clip.frame_count, 41);  // 8 frames of hold
  const std::vector<double>& out = r.clip.channels[0].samples;
  for (std::size_t j = 0; j <= 10; ++j) EXPECT_EQ(out[j], samples[j]) << j;
  for (std::size_t j = 10; j <= 18; ++j) EXPECT_EQ(out[j], samples[10]) << j;
  for (std::size_t j = 18; j < 41; ++j) EXPECT_EQ(out[j], samples[j - 8]) << j;
}

TEST(RetimeTest, DownsamplingFrom120To30KeepsLinearMotionAndTheEndPoses) {
  const double dt = 1.0 / 120;
  const Clip clip = PlainClip(dt, {Linear(994, dt, -4.0, 3.0), std::vector<double>(994, 2.5)});

  const RetimeResult r = RetimeOrDie(clip, {}, {.output_rate = FrameRate{30, 1}});

  // 993 / 4 = 248.25 output frames, the grid rounds to 248: speed 993/992.
  ASSERT_EQ(r.clip.frame_count, 249);
  EXPECT_EQ(r.clip.frame_time_seconds, 1.0 / 30);
  const double c = 993.0 / 992.0;
  for (std::size_t j = 0; j < 249; ++j) {
    EXPECT_NEAR(r.clip.channels[0].samples[j], -4.0 + 3.0 * c * static_cast<double>(j) / 30.0,
                kLinearTolerance);
    EXPECT_NEAR(r.clip.channels[1].samples[j], 2.5, 1e-14);
  }
  EXPECT_EQ(r.clip.channels[0].samples.back(), clip.channels[0].samples.back());
}

TEST(RetimeTest, UpsamplingFrom30To120PutsEveryFourthOutputExactlyOnASourceSample) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> value(-180.0, 180.0);
  std::vector<std::vector<double>> columns(3, std::vector<double>(31));
  for (auto& column : columns) {
    for (double& v : column) v = value(rng);
  }
  const Clip clip = JointClip(1.0 / 30, {ChannelKind::kYRotation, ChannelKind::kXRotation,
                                         ChannelKind::kZRotation}, columns);

  const RetimeResult r = RetimeOrDie(clip, {}, {.output_rate = FrameRate{120, 1}});

  ASSERT_EQ(r.clip.frame_count, 121);
  for (std::size_t c = 0; c < 3; ++c) {
    for (std::size_t i = 0; i < 31; ++i) {
      EXPECT_TRUE(BitEqual(r.clip.channels[c].samples[4 * i], columns[c][i])) << c << " " << i;
    }
  }
  EXPECT_EQ(r.report.filtered_sample_count, 0);
  EXPECT_EQ(r.report.max_decimation_ratio, 0.25);
}

TEST(RetimeTest, CubicFilterReproducesQuadraticsInSlowMotion) {
  // Catmull-Rom's central-difference tangents are exact for quadratics, so at 0.25x the interior
  // of τ² is reproduced; linear interpolation would sag between samples by up to (dt/4)²·... .
  const double dt = 1.0 / 30;
  std::vector<double> samples(61);
  for (std::size_t i = 0; i < samples.size(); ++i) samples[i] = std::pow(static_cast<double>(i) * dt, 2);
  const Clip clip = PlainClip(dt, {samples});

  const RetimeResult cubic =
      RetimeOrDie(clip, OverSource({Knot(0, 0.25)}), {.filter = ResampleFilter::kCubic});
  const RetimeResult linear =
      RetimeOrDie(clip, OverSource({Knot(0, 0.25)}), {.filter = ResampleFilter::kLinear});

  ASSERT_EQ(cubic.clip.frame_count, 241);
  double linear_worst = 0.0;
  for (std::size_t j = 4; j + 4 < 241; ++j) {  // away from the first and last source interval
    const double tau = 0.25 * static_cast<double>(j) * dt;
    EXPECT_NEAR(cubic.clip.channels[0].samples[j], tau * tau, kLinearTolerance) << j;
    linear_worst = std::max(linear_worst, std::abs(linear.clip.channels[0].samples[j] - tau * tau));
  }
  EXPECT_NEAR(linear_worst, dt * dt / 4, 1e-9);  // the chord's sag at the interval's middle
}

TEST(RetimeTest, LanczosKeepsConstantsAndAttenuatesWhenCompressing) {
  const double dt = 1.0 / 120;
  std::vector<double> sine(601);
  const double omega = 2.0 * std::numbers::pi * 20.0 * dt;  // 20 Hz: above 30 fps' Nyquist
  for (std::size_t i = 0; i < sine.size(); ++i) sine[i] = std::sin(omega * static_cast<double>(i));
  const Clip clip = PlainClip(dt, {std::vector<double>(601, 1.25), sine});

  const RetimeResult r = RetimeOrDie(clip, {}, {.output_rate = FrameRate{30, 1},
                                                .filter = ResampleFilter::kLanczos3});

  double worst = 0.0;
  for (std::size_t j = 4; j + 4 < r.clip.channels[1].samples.size(); ++j) {
    EXPECT_NEAR(r.clip.channels[0].samples[j], 1.25, 1e-14);
    worst = std::max(worst, std::abs(r.clip.channels[1].samples[j]));
  }
  EXPECT_LT(worst, 0.05);  // a 20 Hz tone at 30 fps is removed, not aliased to 10 Hz
}

TEST(RetimeTest, BoxFilterAttenuatesAsItsAnalyticResponse) {
  // Box of half-width b = ρ/2 = 2 source samples at 120 -> 30: the response of hat ⊛ box is
  // sinc²(ω/2)·sinc(bω).
  const double dt = 1.0 / 120;
  const double omega = 2.0 * std::numbers::pi * 10.0 * dt;
  std::vector<double> samples(1201);
  for (std::size_t i = 0; i < samples.size(); ++i) samples[i] = std::sin(omega * static_cast<double>(i));
  const Clip clip = PlainClip(dt, {samples});
  const double expected = std::pow(Sinc(omega / 2), 2) * Sinc(2.0 * omega);

  const RetimeResult r = RetimeOrDie(clip, {}, {.output_rate = FrameRate{30, 1},
                                                .filter = ResampleFilter::kBox});

  const double amplitude = FittedAmplitude(r.clip.channels[0].samples, 4 * omega, 2);
  EXPECT_NEAR(amplitude / expected, 1.0, 0.02) << amplitude << " vs " << expected;
}

TEST(RetimeTest, CubicRotationsFollowAQuadraticAngleProfileExactly) {
  // About one axis squad's inner control points shift each angle by a quarter of its second
  // difference, which makes it exact for angles quadratic in time (θ_i = 0.5·i²).
  std::vector<double> z(13);
  for (std::size_t i = 0; i < z.size(); ++i) z[i] = 0.5 * static_cast<double>(i * i);
  const std::vector<double> zero(z.size(), 0.0);
  const Clip clip = JointClip(1.0 / 30, {ChannelKind::kZRotation, ChannelKind::kXRotation,
                                         ChannelKind::kYRotation}, {z, zero, zero});

  const RetimeResult cubic =
      RetimeOrDie(clip, OverSource({Knot(0, 0.25)}), {.filter = ResampleFilter::kCubic});

  ASSERT_EQ(cubic.clip.frame_count, 49);
  for (std::size_t j = 4; j + 4 < 49; ++j) {
    const double x = static_cast<double>(j) / 4.0;
    EXPECT_NEAR(cubic.clip.channels[0].samples[j], 0.5 * x * x, kAngleTolerance) << j;
  }
}

TEST(RetimeTest, SpeedOverOutputTimeSamplesTheQuadraticMap) {
  // s(t) = 1 + t for t <= 1 s, then 2: τ(t) = t + t²/2 up to 1 s.
  const double dt = 1.0 / 120;
  const Clip clip = PlainClip(dt, {Linear(361, dt, 0.0, 1.0)});
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverOutput,
                             .speed = {Knot(0, 1.0), Knot(1, 2.0)}};

  const RetimeResult r = RetimeOrDie(clip, warp, {.fit_to_grid = false});

  ASSERT_EQ(r.clip.frame_count, 211);  // T_o = 1.75 s
  for (std::size_t j = 0; j <= 120; ++j) {
    const double t = static_cast<double>(j) * dt;
    EXPECT_NEAR(r.clip.channels[0].samples[j], t + t * t / 2, kLinearTolerance) << j;
  }
  for (std::size_t j = 121; j < 211; ++j) {
    const double t = static_cast<double>(j) * dt;
    EXPECT_NEAR(r.clip.channels[0].samples[j], 1.5 + 2.0 * (t - 1.0), kLinearTolerance) << j;
  }
}

TEST(RetimeTest, TimeMapKeysPlayHoldAndPlayOn) {
  const double dt = 1.0 / 32;
  const Clip clip = PlainClip(dt, {Linear(65, dt, 0.0, 1.0)});
  const TimeWarpSpec warp = {
      .domain = WarpDomain::kTimeMapKeys,
      .keys = {{{0, false}, {0, false}}, {{1, false}, {0.5, false}}, {{2, false}, {0.5, false}},
               {{3, false}, {2.0, false}}}};

  const RetimeResult r = RetimeOrDie(clip, warp, {});

  ASSERT_EQ(r.clip.frame_count, 97);
  const std::vector<double>& out = r.clip.channels[0].samples;
  for (std::size_t j = 0; j < 97; ++j) {
    const double t = static_cast<double>(j) * dt;
    const double tau = t <= 1.0 ? 0.5 * t : t <= 2.0 ? 0.5 : 0.5 + 1.5 * (t - 2.0);
    EXPECT_NEAR(out[j], tau, kLinearTolerance) << j;
  }
}

TEST(RetimeTest, PinnedSourceTimesLandOnTheirOutputFrames) {
  const double dt = 1.0 / 32;
  const Clip clip = PlainClip(dt, {Linear(129, dt, 0.0, 1.0)});
  RetimeOptions options;
  options.pins = {{.source = {1.0, false}, .output_frame = 64},
                  {.source = {3.0, false}, .output_frame = 80}};

  const RetimeResult r = RetimeOrDie(clip, {}, options);

  ASSERT_EQ(r.clip.frame_count, 113);
  EXPECT_NEAR(r.clip.channels[0].samples[64], 1.0, kLinearTolerance);
  EXPECT_NEAR(r.clip.channels[0].samples[80], 3.0, kLinearTolerance);  // filtered (c = 4) side
  EXPECT_NEAR(r.clip.channels[0].samples[32], 0.5, kLinearTolerance);
  EXPECT_NEAR(r.clip.channels[0].samples[72], 2.0, kLinearTolerance);
  EXPECT_EQ(r.clip.channels[0].samples.back(), 4.0);
}

TEST(RetimeTest, ValidateRetimeNeedsOnlyTheClipsTiming) {
  // Cheap enough to check before queueing: no samples are read.
  Clip probe;
  probe.frame_time_seconds = 1.0 / 30;
  probe.frame_count = 2;

  EXPECT_TRUE(ValidateRetime(probe, OverSource({Knot(0, 0.5)}), {}).ok());
  EXPECT_TRUE(ValidateRetime(probe, OverSource({Knot(0, 0.5)}), {.method = RetimeMethod::kPaper}).ok());
}

TEST(RetimeTest, ExtremeFrameTimesRetimeToAnyRateWithoutInternalErrors) {
  // Every frame time a clip may have, to every output rate a retime may ask for: either a result
  // with finite samples or a refusal naming the limit, never an internal error (a subnormal
  // frame time once made the resample plan's ratio infinite).
  for (double frame_time : {1e-6, 1.0 / 120.0, 3600.0}) {
    const Clip clip = PlainClip(frame_time, {{0.0, 1.0, -2.0, 3.0, 5.0, 8.0}});
    for (FrameRate rate : {FrameRate{30, 1}, FrameRate{100000, 1}, FrameRate{1, 3600}}) {
      const absl::StatusOr<RetimeResult> result =
          Retime(clip, OverSource({Knot(0, 0.5)}), {.output_rate = rate});

      if (!result.ok()) {
        EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument)
            << frame_time << " s to " << rate.hz() << " Hz: " << result.status();
        continue;
      }
      EXPECT_TRUE(ValidateClip(result->clip).ok()) << frame_time << " s to " << rate.hz();
    }
  }
}

TEST(RetimeTest, KnotsASubnormalTimeApartAreAStepNotAnInfinitelySteepRamp) {
  // Found by fuzzing (speed_knots_fuzz): "0s:50,1e-313s:0.01" over output time, reversed, passed
  // validation, then every resampled position was NaN ("resample plan: output sample 3900 has
  // position nan") because the ramp between the knots divided by a subnormal span.
  std::vector<double> ramp;
  for (int f = 0; f < 40; ++f) ramp.push_back(static_cast<double>(f));
  const Clip clip = PlainClip(1.0 / 30, {ramp});
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverOutput,
                             .speed = {Knot(0, 50), Knot(1e-313, 0.01)},
                             .reverse = true};

  ASSERT_TRUE(ValidateRetime(clip, warp, {}).ok());
  const RetimeResult result = RetimeOrDie(clip, warp, {});

  EXPECT_TRUE(ValidateClip(result.clip).ok()) << ValidateClip(result.clip);
  EXPECT_EQ(result.clip.channels[0].samples.front(), 39.0);  // reversed: ends first
  EXPECT_EQ(result.clip.channels[0].samples.back(), 0.0);
}

TEST(RetimeTest, APositionASubnormalDistanceFromTheStartIsInterpolatedNotFiltered) {
  // Found by fuzzing (pipeline_proto_fuzz): time-map keys starting at source time 2.49e-317 s put
  // the first output sample that far from frame 0, whose tent half-width (clamped to the distance
  // from the end) squared to zero: the first sample came out NaN.
  std::vector<double> ramp;
  for (int f = 0; f < 40; ++f) ramp.push_back(static_cast<double>(f));
  const Clip clip = PlainClip(1.0 / 30, {ramp});
  const TimeWarpSpec warp = {.domain = WarpDomain::kTimeMapKeys,
                             .keys = {{.output = {0.0, false}, .source = {2.4931896347706e-317, false}},
                                      {.output = {2.0, false}, .source = {4.0000000054133125, false}}}};

  const RetimeResult result = RetimeOrDie(clip, warp, {});

  EXPECT_TRUE(ValidateClip(result.clip).ok()) << ValidateClip(result.clip);
  // The ramp's value there: the position itself, 7.5e-316.
  EXPECT_LT(std::abs(result.clip.channels[0].samples.front()), 1e-300);
}

TEST(RetimeTest, SingleFrameClipRetimesToItsPoseAndHolds) {
  const Clip clip = PlainClip(1.0 / 30, {{4.5}});

  const RetimeResult plain = RetimeOrDie(clip, OverSource({Knot(0, 0.5)}), {});
  const RetimeResult held =
      RetimeOrDie(clip, {.holds = {{.at = {0.0, false}, .duration_seconds = 0.5}}}, {});

  ASSERT_EQ(plain.clip.frame_count, 1);
  EXPECT_EQ(plain.clip.channels[0].samples[0], 4.5);
  ASSERT_EQ(held.clip.frame_count, 16);
  for (double v : held.clip.channels[0].samples) EXPECT_EQ(v, 4.5);
}

// ---- markers, progress, report, paper ---------------------------------------------------------

TEST(RetimeTest, MarkersAreMappedThroughTheTimeMap) {
  Clip clip = PlainClip(1.0 / 32, {std::vector<double>(65, 0.0)});
  clip.markers = {{"contact", 1.0, 0.5}, {"event", 0.25, 0.0}};

  const RetimeResult fast = RetimeOrDie(clip, OverSource({Knot(0, 2.0)}), {});
  TimeWarpSpec reversed = OverSource({Knot(0, 2.0)});
  reversed.reverse = true;
  const RetimeResult rev = RetimeOrDie(clip, reversed, {});

  EXPECT_EQ(fast.clip.markers[0], (Marker{"contact", 0.5, 0.25}));
  EXPECT_EQ(fast.clip.markers[1], (Marker{"event", 0.125, 0.0}));
  EXPECT_EQ(rev.clip.markers[0], (Marker{"contact", 0.25, 0.25}));  // [1 - 0.75, 1 - 0.5]
  EXPECT_EQ(rev.clip.markers[1], (Marker{"event", 0.875, 0.0}));
}

TEST(RetimeTest, ProgressReachesOneAndAStopRequestCancels) {
  const Clip clip = PlainClip(1.0 / 30, {std::vector<double>(10, 1.0), std::vector<double>(10, 2.0)});
  std::vector<double> fractions;
  std::stop_source stop;
  stop.request_stop();

  absl::StatusOr<RetimeResult> ok =
      Retime(clip, {}, {}, [&](double f, std::string_view) { fractions.push_back(f); });
  absl::StatusOr<RetimeResult> cancelled = Retime(clip, {}, {}, {}, stop.get_token());

  ASSERT_TRUE(ok.ok());
  ASSERT_FALSE(fractions.empty());
  EXPECT_EQ(fractions.back(), 1.0);
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
}

// A joint's rotation (quaternion mode, Lanczos-3, compressed by 1.3) after a position channel,
// over `frames` frames of a slow swing.
Clip SwingingJointClip(std::int64_t frames) {
  std::vector<double> x(static_cast<std::size_t>(frames)), z(x.size()), y(x.size()), p(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) {
    const auto t = static_cast<double>(i);
    x[i] = 30.0 * std::sin(t * 1e-3);
    z[i] = 20.0 * std::cos(t * 7e-4);
    y[i] = 170.0 * std::sin(t * 3e-4);
    p[i] = 0.01 * t;
  }
  return JointClip(1.0 / 120, {ChannelKind::kXPosition, ChannelKind::kZRotation,
                               ChannelKind::kXRotation, ChannelKind::kYRotation},
                   {p, z, x, y});
}

const RetimeOptions kLanczosQuaternion = {.filter = ResampleFilter::kLanczos3,
                                          .rotation_mode = RotationMode::kQuaternion};

TEST(RetimeTest, ARotationAwareLanczosRetimeWithTheStopAlreadyRequestedIsCancelled) {
  const Clip clip = SwingingJointClip(20'000);
  std::stop_source stop;
  stop.request_stop();

  const absl::StatusOr<RetimeResult> r =
      Retime(clip, OverSource({Knot(0, 1.3)}), kLanczosQuaternion, {}, stop.get_token());

  EXPECT_EQ(r.status().code(), absl::StatusCode::kCancelled);
}

TEST(RetimeTest, AStopRequestedFromAnotherThreadCancelsALargeRotationAwareLanczosRetime) {
  const Clip clip = SwingingJointClip(400'000);
  std::stop_source stop;
  int reports = 0;
  // The position channel is resampled first; its progress report asks another thread to stop
  // and waits until it has, so the stop is there before the joint's rotation is resampled (the
  // look between channels sees it).
  const ProgressFn progress = [&](double, std::string_view) {
    if (reports++ > 0) return;
    std::thread requester([&] { stop.request_stop(); });
    requester.join();
  };

  const absl::StatusOr<RetimeResult> r =
      Retime(clip, OverSource({Knot(0, 1.3)}), kLanczosQuaternion, progress, stop.get_token());

  EXPECT_EQ(reports, 1);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kCancelled);
}

TEST(RetimeTest, PaperMethodAgreesWithTheExactMapAtConstantSpeed) {
  const double dt = 1.0 / 120;
  const Clip clip = PlainClip(dt, {Linear(121, dt, 0.0, 1.0)});

  const RetimeResult paper =
      RetimeOrDie(clip, OverSource({Knot(0, 0.5)}), {.method = RetimeMethod::kPaper});
  const RetimeResult exact = RetimeOrDie(clip, OverSource({Knot(0, 0.5)}), {});

  ASSERT_EQ(paper.clip.frame_count, 241);
  ASSERT_EQ(exact.clip.frame_count, 241);
  for (std::size_t j = 0; j < 241; ++j) {
    EXPECT_NEAR(paper.clip.channels[0].samples[j], exact.clip.channels[0].samples[j], 1e-12);
  }
}

TEST(RetimeTest, PaperMethodReverseMirrorsItsForwardOutputAndMapsMarkers) {
  const double dt = 1.0 / 120;
  Clip clip = PlainClip(dt, {Linear(121, dt, 0.0, 1.0)});
  clip.markers = {{"hit", 0.5, 0.0}};
  TimeWarpSpec forward = OverSource({Knot(0, 0.5), Knot(1, 2.0)});
  TimeWarpSpec backward = forward;
  backward.reverse = true;

  const RetimeResult f = RetimeOrDie(clip, forward, {.method = RetimeMethod::kPaper});
  const RetimeResult b = RetimeOrDie(clip, backward, {.method = RetimeMethod::kPaper});
  const RetimeResult half = RetimeOrDie(clip, OverSource({Knot(0, 0.5)}), {.method = RetimeMethod::kPaper});

  ASSERT_EQ(f.clip.frame_count, b.clip.frame_count);
  const auto m = static_cast<std::size_t>(f.clip.frame_count);
  for (std::size_t j = 0; j < m; ++j) {
    EXPECT_EQ(b.clip.channels[0].samples[j], f.clip.channels[0].samples[m - 1 - j]);
  }
  EXPECT_NEAR(half.clip.markers[0].time_seconds, 1.0, kLinearTolerance);
}

TEST(RetimeTest, PaperMethodCountsARampByItsArithmeticMeanSpeed) {
  // 0.25 -> 4 over 120 source frames: the ratio of areas gives 120 / mean(v) = 120 / 2.125 =
  // 56.47 -> 56 new intervals (0.471 per source frame); the exact map: 120·ln 16 / 3.75 = 88.7
  // (0.739 per source frame).
  const double dt = 1.0 / 120;
  const Clip clip = PlainClip(dt, {Linear(121, dt, 0.0, 1.0)});
  const TimeWarpSpec ramp = OverSource({Knot(0, 0.25), Knot(1, 4.0)});

  const RetimeResult paper = RetimeOrDie(clip, ramp, {.method = RetimeMethod::kPaper});
  const RetimeResult exact = RetimeOrDie(clip, ramp, {.fit_to_grid = false});

  EXPECT_EQ(paper.clip.frame_count, 57);
  EXPECT_EQ(exact.clip.frame_count, 89);
  const std::vector<double>& p = paper.clip.channels[0].samples;
  EXPECT_EQ(p.front(), 0.0);
  EXPECT_EQ(p.back(), clip.channels[0].samples.back());
  EXPECT_TRUE(std::is_sorted(p.begin(), p.end()));
}

}  // namespace
}  // namespace tempokey::core
