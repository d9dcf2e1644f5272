// The noise-aware reduction: known noise on known curves (the estimate, the fit against the truth,
// the guard), clean data, bad input, and the method through ReduceKeys().
#include "tempokey/core/reduce/noise_fit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>
#include <optional>
#include <random>
#include <span>
#include <stop_token>
#include <string>
#include <vector>

#include "core/src/reduce/noise_smoother.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

constexpr double kSigma = 0.5;
constexpr unsigned kSeed = 7;

// A motion of a few slow and one quicker component, 120 fps, degrees.
double Motion(int f) {
  const double t = f / 120.0;
  return 30.0 * std::sin(2.0 * std::numbers::pi * 0.4 * t) +
         8.0 * std::sin(2.0 * std::numbers::pi * 1.3 * t + 1.0) + 5.0 * t;
}

std::vector<double> Truth(int frames) {
  std::vector<double> v;
  for (int f = 0; f < frames; ++f) v.push_back(Motion(f));
  return v;
}

std::vector<double> WithNoise(std::vector<double> v, double sigma, unsigned seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  for (double& x : v) x += noise(random);
  return v;
}

double Rms(const std::vector<double>& a, const std::vector<double>& b) {
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) sum += (a[i] - b[i]) * (a[i] - b[i]);
  return std::sqrt(sum / static_cast<double>(a.size()));
}

TEST(NoiseFitTest, EstimateRecoversKnownGaussianNoiseOnAMovingCurve) {
  // The median of 20000 correlated third differences: a standard error near 1.5 %.
  const std::vector<double> noisy = WithNoise(Truth(20000), kSigma, kSeed);

  const double estimate = EstimateNoiseSigma(noisy);

  EXPECT_NEAR(estimate, kSigma, 0.04 * kSigma);
}

TEST(NoiseFitTest, EstimateOfAQuadraticIsZero) {
  std::vector<double> quadratic;
  for (int f = 0; f < 100; ++f) quadratic.push_back(0.25 * f * f - 3.0 * f + 7.0);

  EXPECT_LT(EstimateNoiseSigma(quadratic), 1e-9);
  EXPECT_EQ(EstimateNoiseSigma(std::vector<double>{1.0, 2.0, 4.0}), 0.0);
}

TEST(NoiseFitTest, EstimateOfCleanSmoothMotionIsFarBelowTheNoise) {
  // Its third differences are those of the motion itself: 30 deg at 0.4 Hz and 8 deg at 1.3 Hz
  // give |d| up to 8 (2 pi 1.3 / 120)^3 = 2.5e-3, a median near 5e-4 / (0.6745 sqrt 20).
  EXPECT_LT(EstimateNoiseSigma(Truth(2000)), 1e-3);
}

TEST(NoiseFitTest, FitFollowsTheMotionNotTheNoise) {
  const std::vector<double> truth = Truth(2400);
  const std::vector<double> noisy = WithNoise(truth, kSigma, kSeed);

  absl::StatusOr<SplineFit> fit = FitToNoise(noisy, kSigma);

  ASSERT_TRUE(fit.ok()) << fit.status();
  const std::vector<double> curve = EvaluateSplineFit(*fit, 0);
  // A smooth motion: the error against the truth is a small part of the noise (a quarter, where
  // the noise projected on the keys' 2 K parameters alone would be sqrt(2 K / N) = 0.25), with
  // few keys, and what is left against the data is the noise itself.
  EXPECT_LT(Rms(curve, truth), 0.3 * kSigma);
  EXPECT_LT(fit->frames.size(), 2400u / 25);
  const double residual = Rms(curve, noisy);
  EXPECT_GT(residual, 0.9 * kSigma);
  EXPECT_LT(residual, 1.05 * kSigma);
}

TEST(NoiseFitTest, GuardKeepsAnImpactTheSmoothingWouldCut) {
  // A 3-frame spike of 8 sigma (an impact) on the noisy motion.
  constexpr double kSpike = 8.0 * kSigma;
  std::vector<double> truth = Truth(1200);
  for (int f = 600; f < 603; ++f) truth[f] += kSpike;
  const std::vector<double> noisy = WithNoise(truth, kSigma, kSeed);
  NoiseFitOptions guarded;
  NoiseFitOptions unguarded;
  unguarded.guard_sigmas = 100.0;

  absl::StatusOr<SplineFit> fit = FitToNoise(noisy, kSigma, guarded);
  absl::StatusOr<SplineFit> cut = FitToNoise(noisy, kSigma, unguarded);

  ASSERT_TRUE(fit.ok()) << fit.status();
  ASSERT_TRUE(cut.ok()) << cut.status();
  const std::vector<double> curve = EvaluateSplineFit(*fit, 0);
  double worst = 0.0;
  for (std::size_t f = 0; f < curve.size(); ++f) worst = std::max(worst, std::abs(curve[f] - noisy[f]));
  EXPECT_LE(worst, (guarded.guard_sigmas + guarded.key_sigmas) * kSigma);
  // The impact is kept within the guard of the data (give or take 2 sigma of noise), where the
  // risk-optimal smoothing alone flattens it further.
  const double kept = curve[601] - Motion(601);
  EXPECT_GT(kept, kSpike - 5.2 * kSigma - 2.0 * kSigma);
  EXPECT_LT(EvaluateSplineFit(*cut, 0)[601] - Motion(601), kept) << kept;
}

TEST(NoiseFitTest, GuardHoldsAtARealJumpWhateverTheNoiseLevel) {
  // A 171-degree flip between two frames (as an Euler channel of a real capture has it, 131_01's
  // RThumb at frame 243) on the noisy motion: even at the smallest level the searched grid
  // offers, the smoother pulled such a step ~1.9 degrees off the data, far beyond the guard.
  for (const double sigma : {1e-4, 0.01, 0.1}) {
    std::vector<double> truth = Truth(1200);
    for (int f = 700; f < 1200; ++f) truth[f] += 171.0;
    const std::vector<double> noisy = WithNoise(truth, sigma, kSeed);
    const NoiseFitOptions options;

    absl::StatusOr<SplineFit> fit = FitToNoise(noisy, sigma, options);

    ASSERT_TRUE(fit.ok()) << fit.status();
    const std::vector<double> curve = EvaluateSplineFit(*fit, 0);
    double worst = 0.0;
    for (std::size_t f = 0; f < curve.size(); ++f) {
      worst = std::max(worst, std::abs(curve[f] - noisy[f]));
    }
    EXPECT_LE(worst, (options.guard_sigmas + options.key_sigmas) * sigma) << "sigma " << sigma;
  }
}

TEST(NoiseFitTest, SmootherReturnsShortInputsAsTheyAre) {
  const std::vector<double> samples = {1.0, 5.0, -2.0, 4.0};

  EXPECT_EQ(SmoothToNoise(samples, kSigma), samples);
}

TEST(NoiseFitTest, BadInputIsRefusedWithItsReason) {
  const std::vector<double> samples = {0.0, 1.0, std::nan(""), 3.0};
  const std::vector<double> good = {0.0, 1.0, 2.0, 3.0};
  NoiseFitOptions bad_keys;
  bad_keys.key_sigmas = 0.0;

  EXPECT_EQ(FitToNoise(samples, kSigma).status().message(), "sample 2 is NaN");
  EXPECT_EQ(FitToNoise(good, 0.0).status().message(),
            "the noise level must be finite and > 0, got 0");
  EXPECT_EQ(FitToNoise(good, kSigma, bad_keys).status().message(),
            "key_sigmas must be in [0.01, 10], got 0");
  EXPECT_EQ(FitToNoise({}, kSigma).status().code(), absl::StatusCode::kInvalidArgument);
}

Clip TwoChannelClip(std::vector<double> rotation, std::vector<double> position) {
  Clip clip;
  clip.name = "noise";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = static_cast<std::int64_t>(rotation.size());
  clip.channels.push_back({.joint = -1, .kind = ChannelKind::kXRotation, .name = "rx",
                           .samples = std::move(rotation)});
  clip.channels.push_back({.joint = -1, .kind = ChannelKind::kXPosition, .name = "px",
                           .samples = std::move(position)});
  return clip;
}

TEST(NoiseReductionTest, ReportCarriesEachChannelsEstimatedOrGivenNoise) {
  const Clip clip = TwoChannelClip(WithNoise(Truth(1200), kSigma, 1),
                                   WithNoise(Truth(1200), 0.1, 2));
  ReduceOptions estimated;
  estimated.method = ReduceMethod::kNoise;
  ReduceOptions given = estimated;
  given.noise.rotation_sigma_degrees = 0.4;

  absl::StatusOr<ReduceResult> a = ReduceKeys(clip, estimated);
  absl::StatusOr<ReduceResult> b = ReduceKeys(clip, given);

  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  // 1200 frames: the estimate's standard error is near 6 %.
  EXPECT_NEAR(a->report.channels[0].noise_sigma, kSigma, 0.15 * kSigma);
  EXPECT_TRUE(a->report.channels[0].noise_sigma_estimated);
  EXPECT_NEAR(a->report.channels[1].noise_sigma, 0.1, 0.015);
  EXPECT_EQ(b->report.channels[0].noise_sigma, 0.4);
  EXPECT_FALSE(b->report.channels[0].noise_sigma_estimated);
  EXPECT_TRUE(b->report.channels[1].noise_sigma_estimated);
  // Keys on whole frames, C1.
  for (const Key& key : a->keyed.curves[0].keys) {
    const double frame = key.time_seconds / clip.frame_time_seconds;
    EXPECT_NEAR(frame, std::round(frame), 1e-9);
    EXPECT_EQ(key.in_tangent, key.out_tangent);
  }
}

// A reduction shares the smoother's factors between channels and solves many levels and block
// windows together; each channel must still come out exactly as it does smoothed on its own. A
// noiseless channel among them (estimate 0) is keyed from its samples and leaves the smoothing of
// the others as it was.
TEST(NoiseReductionTest, ChannelsOfOneClipComeOutAsEachDoesAlone) {
  constexpr int kFrames = 1000;  // 16 blocks of 60 and one of 40: windows of four lengths
  constexpr int kNoiseless = 2;
  Clip clip;
  clip.name = "noise";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = kFrames;
  const double sigmas[] = {0.5, 0.05, 2.0, 0.2};
  for (int c = 0; c < 4; ++c) {
    std::vector<double> samples = WithNoise(Truth(kFrames), sigmas[c], 20 + c);
    for (int f = 0; f < kFrames; ++f) samples[f] *= 1.0 + 0.5 * c;
    clip.channels.push_back({.joint = -1, .kind = ChannelKind::kXPosition,
                             .name = "p" + std::to_string(c), .samples = std::move(samples)});
  }
  clip.channels.insert(clip.channels.begin() + kNoiseless,
                       {.joint = -1, .kind = ChannelKind::kXPosition, .name = "clean",
                        .samples = Truth(kFrames)});
  ASSERT_EQ(EstimateNoiseSigma(clip.channels[kNoiseless].samples), 0.0);
  ReduceOptions options;
  options.method = ReduceMethod::kNoise;

  absl::StatusOr<ReduceResult> together = ReduceKeys(clip, options);

  ASSERT_TRUE(together.ok()) << together.status();
  // Backwards, so that no channel finds the factors the clip left behind in the same order.
  for (int c = 4; c >= 0; --c) {
    SCOPED_TRACE(c);
    const double sigma = together->report.channels[c].noise_sigma;
    const std::vector<double>& samples = clip.channels[c].samples;
    absl::StatusOr<SplineFit> alone =
        c == kNoiseless ? reduce_internal::FitKeysToNoise(samples, sigma, {}, {})
                        : FitToNoise(samples, sigma);
    ASSERT_TRUE(alone.ok()) << alone.status();
    const std::vector<Key>& keys = together->keyed.curves[c].keys;
    ASSERT_EQ(keys.size(), alone->frames.size());
    for (std::size_t k = 0; k < keys.size(); ++k) {
      EXPECT_EQ(keys[k].time_seconds,
                static_cast<double>(alone->frames[k]) * clip.frame_time_seconds);
      EXPECT_EQ(keys[k].value, alone->values[0][k]);
    }
  }
}

// A channel in which the estimate finds no noise at all is fitted from its samples: its keys stay
// within key_sigmas * min_sigma of every sample. Smoothed at min_sigma instead, the curve would
// move by up to guard_sigmas * min_sigma (2e-4 at this clip's ends).
TEST(NoiseReductionTest, ANoiselessChannelIsKeyedWithinTheKeyBoundOfItsSamples) {
  std::vector<double> cornered = Truth(600);
  for (int f = 0; f < 600; ++f) cornered[static_cast<std::size_t>(f)] += 0.5 * std::abs(f - 300);
  ASSERT_EQ(EstimateNoiseSigma(cornered), 0.0);
  ReduceOptions options;
  options.method = ReduceMethod::kNoise;

  absl::StatusOr<ReduceResult> result =
      ReduceKeys(TwoChannelClip(cornered, cornered), options);

  ASSERT_TRUE(result.ok()) << result.status();
  const NoiseParams& noise = options.noise;
  for (const ChannelReduction& channel : result->report.channels) {
    SCOPED_TRACE(channel.channel_index);
    EXPECT_EQ(channel.noise_sigma, noise.min_sigma);
    EXPECT_TRUE(channel.noise_sigma_estimated);
    EXPECT_LE(channel.max_error, noise.key_sigmas * noise.min_sigma);
  }
}

// The fit starts from keys about as far apart as the bound allows on a curve of that fourth
// difference: c f^4 has fourth differences 24 c at every frame, and L^4 24 c / 384 = bound at
// L = 5.5 / kInitialSpacingOverSegment for the bound below.
TEST(NoiseFitTest, InitialSpacingFollowsTheMedianFourthDifference) {
  constexpr double kC = 1e-3;
  std::vector<double> quartic;
  for (int f = 0; f < 40; ++f) quartic.push_back(kC * std::pow(f, 4));
  const double segment = 5.5 / reduce_internal::kInitialSpacingOverSegment;
  const double bound = std::pow(segment, 4) * 24.0 * kC / 384.0;
  std::vector<double> line;
  for (int f = 0; f < 40; ++f) line.push_back(3.0 * f - 7.0);

  EXPECT_EQ(reduce_internal::InitialKeySpacing(quartic, bound), 5);
  EXPECT_EQ(reduce_internal::InitialKeySpacing(quartic, bound * 1e-6),
            reduce_internal::kMinInitialKeySpacing);
  EXPECT_EQ(reduce_internal::InitialKeySpacing(quartic, bound * 1e6),
            reduce_internal::kMaxInitialKeySpacing);
  EXPECT_EQ(reduce_internal::InitialKeySpacing(line, 1e-9),
            reduce_internal::kMaxInitialKeySpacing);
  EXPECT_EQ(reduce_internal::InitialKeySpacing(std::span(quartic).first(4), bound),
            reduce_internal::kMaxInitialKeySpacing);
  // Samples near the largest doubles, whose fourth differences would overflow (inf - inf): as
  // rough a curve as any, it starts at the densest spacing.
  std::vector<double> huge;
  for (int f = 0; f < 40; ++f) huge.push_back(f % 2 == 0 ? 1e308 : 0.9e308);
  EXPECT_EQ(reduce_internal::InitialKeySpacing(huge, bound),
            reduce_internal::kMinInitialKeySpacing);
  EXPECT_TRUE(FitToNoise(huge, 1.0).ok());
}

TEST(NoiseReductionTest, InvalidNoiseParamsAreNamed) {
  ReduceOptions options;
  options.method = ReduceMethod::kNoise;
  options.noise.rotation_sigma_degrees = -1.0;

  EXPECT_EQ(ValidateReduceOptions(options).message(),
            "noise.rotation_sigma_degrees must be in [1e-09, 1e+09], got -1");
  // The error bounds' range: 1e-300 kept a key at nearly every frame, 1e308 smoothed flat.
  options.noise.rotation_sigma_degrees = 1e-300;
  EXPECT_EQ(ValidateReduceOptions(options).message(),
            "noise.rotation_sigma_degrees must be in [1e-09, 1e+09], got 1e-300");
  options.noise.rotation_sigma_degrees.reset();
  options.noise.position_sigma = 1e308;
  EXPECT_EQ(ValidateReduceOptions(options).message(),
            "noise.position_sigma must be in [1e-09, 1e+09], got 1e+308");
  options.noise.position_sigma = 1e9;
  EXPECT_TRUE(ValidateReduceOptions(options).ok());
  options.noise.position_sigma.reset();
  options.noise.guard_sigmas = 1.0;
  EXPECT_EQ(ValidateReduceOptions(options).message(),
            "noise.guard_sigmas must be in [2, 100], got 1");
}

// Clean captures as they are (30 fps): the estimate reads only their own frame-level detail, a
// fraction of the benchmark's 0.5 degrees (median 0.02 to 0.15 per clip), and the curve stays
// within a tenth of a degree RMS of the data: clean data is not smoothed.
TEST(NoiseReductionCorpusTest, CleanBandaiClipsReadAsNearlyNoiseless) {
  for (const std::string& path : testing::AllSharedBvhFiles()) {
    if (path.find("bandai") == std::string::npos) continue;
    SCOPED_TRACE(path);
    absl::StatusOr<Clip> clip = ReadBvhFile(path);
    ASSERT_TRUE(clip.ok()) << clip.status();
    ReduceOptions options;
    options.method = ReduceMethod::kNoise;

    absl::StatusOr<ReduceResult> result = ReduceKeys(*clip, options);

    ASSERT_TRUE(result.ok()) << result.status();
    std::vector<double> levels;
    for (const ChannelReduction& channel : result->report.channels) {
      if (IsRotation(clip->channels[channel.channel_index].kind)) {
        levels.push_back(channel.noise_sigma);
      }
    }
    std::sort(levels.begin(), levels.end());
    EXPECT_LT(levels[levels.size() / 2], 0.2);
    EXPECT_LT(result->report.rms_error, 0.12);
  }
}

// SmoothGroupToNoise() of `channels`, each with its sigma; expects one curve per channel.
std::vector<std::vector<double>> SmoothedTogether(
    const std::vector<std::vector<double>>& channels, const std::vector<double>& sigmas) {
  const std::vector<std::span<const double>> spans(channels.begin(), channels.end());
  reduce_internal::SmootherFactors factors;
  absl::StatusOr<std::vector<std::vector<double>>> together =
      reduce_internal::SmoothGroupToNoise(spans, sigmas, {}, factors, {});
  EXPECT_TRUE(together.ok()) << together.status();
  if (!together.ok()) return {};
  EXPECT_EQ(together->size(), channels.size());
  return *std::move(together);
}

TEST(NoiseFitTest, ChannelsSmoothedTogetherComeOutAsEachAlone) {
  // Six channels: four of one length (one with an impact, so its guard rounds outlast the
  // others'; one at a much higher noise level), then two shorter ones. Smoothed together, each
  // must be bit for bit what it is alone.
  std::vector<double> impact = Truth(900);
  for (int f = 400; f < 403; ++f) impact[static_cast<std::size_t>(f)] += 8.0 * kSigma;
  const std::vector<std::vector<double>> channels = {
      WithNoise(Truth(900), kSigma, 1),      WithNoise(impact, kSigma, 2),
      WithNoise(Truth(900), 4.0 * kSigma, 3), WithNoise(Truth(900), kSigma, 4),
      WithNoise(Truth(500), kSigma, 5),      WithNoise(Truth(500), kSigma, 6)};
  const std::vector<double> sigmas = {kSigma, kSigma, 4.0 * kSigma, kSigma, kSigma, kSigma};

  const std::vector<std::vector<double>> together = SmoothedTogether(channels, sigmas);

  ASSERT_EQ(together.size(), channels.size());
  for (std::size_t c = 0; c < channels.size(); ++c) {
    EXPECT_EQ(together[c], SmoothToNoise(channels[c], sigmas[c])) << "channel " << c;
  }
}

TEST(NoiseFitTest, LongChannelsSmoothedTogetherComeOutAsEachAlone) {
  // Beyond the frames whose guard rounds solve side by side (their memory would be four
  // channels' at once): each such channel is solved alone, with the same result.
  constexpr int kFrames = 160'000;
  const std::vector<std::vector<double>> channels = {WithNoise(Truth(kFrames), kSigma, 1),
                                                     WithNoise(Truth(kFrames), kSigma, 2)};
  const std::vector<double> sigmas = {kSigma, kSigma};

  const std::vector<std::vector<double>> together = SmoothedTogether(channels, sigmas);

  ASSERT_EQ(together.size(), channels.size());
  for (std::size_t c = 0; c < channels.size(); ++c) {
    EXPECT_EQ(together[c], SmoothToNoise(channels[c], sigmas[c])) << "channel " << c;
    EXPECT_LT(Rms(together[c], Truth(kFrames)), 0.5 * kSigma) << "channel " << c;
  }
}

// ---- cancellation -------------------------------------------------------------------------------

// The smoother looks at the stop token inside its searches and band solves: a stop requested
// while a long channel is being smoothed ends the reduction with kCancelled, never a finished
// result. What these tests pin is the outcome, not a duration (bench/cancel_bench measures how
// soon the stop is seen).

// A slow sine under noise of kSigma: the searches pick levels well inside their range.
std::vector<double> LongNoisySine(int frames) {
  std::vector<double> v;
  v.reserve(static_cast<std::size_t>(frames));
  for (int f = 0; f < frames; ++f) v.push_back(10.0 * std::sin(0.01 * f));
  return WithNoise(std::move(v), kSigma, kSeed);
}

TEST(NoiseCancellationTest, SmootherGivenAStoppedTokenReturnsCancelled) {
  // Beyond the frames the lane searches take: the search solves the whole channel level by level.
  const std::vector<double> samples = LongNoisySine(200'000);
  reduce_internal::SmootherFactors factors;
  std::stop_source stop;
  stop.request_stop();

  const absl::StatusOr<std::vector<double>> smooth =
      reduce_internal::SmoothToNoise(samples, kSigma, {}, factors, stop.get_token());

  EXPECT_EQ(smooth.status().code(), absl::StatusCode::kCancelled) << smooth.status();
}

TEST(NoiseCancellationTest, SmootherWithATokenNeverStoppedGivesTheSameCurveBitForBit) {
  const std::vector<double> samples = LongNoisySine(5000);
  reduce_internal::SmootherFactors factors;
  const std::stop_source stop;

  const absl::StatusOr<std::vector<double>> smooth =
      reduce_internal::SmoothToNoise(samples, kSigma, {}, factors, stop.get_token());

  ASSERT_TRUE(smooth.ok()) << smooth.status();
  EXPECT_EQ(*smooth, SmoothToNoise(samples, kSigma));
}

// Where a test requests the stop inside a channel's smoothing: at the nth look at the token at
// `site`, counted from the latest look at `after` when given (so "the nth band-rows look after a
// levels look" is a look of a guard round's band solve).
struct StopPlan {
  reduce_internal::SmootherStopSite site;
  int nth = 1;
  std::optional<reduce_internal::SmootherStopSite> after;
  std::string name;
};

// The stop requested as `plan` says (reduce_internal::ScopedSmootherStopProbe: from inside the
// work, so no race between threads): whether that look came, the result, and the looks that came
// after the stop (each look reads the token, so work going on past the stop shows as looks).
struct StopSeen {
  bool reached = false;
  std::vector<reduce_internal::SmootherStopSite> looks_after;
  absl::StatusCode code = absl::StatusCode::kOk;
};

// SmoothGroupToNoise() of `channel_count` channels of `frames` noisy samples each, with `probe`
// looking on; its status.
absl::StatusCode SmoothProbed(int channel_count, int frames, std::stop_source& stop,
                              std::function<void(reduce_internal::SmootherStopSite)> probe) {
  std::vector<std::vector<double>> channels;
  for (int c = 0; c < channel_count; ++c) channels.push_back(LongNoisySine(frames));
  const std::vector<std::span<const double>> spans(channels.begin(), channels.end());
  const std::vector<double> sigmas(channels.size(), kSigma);
  reduce_internal::SmootherFactors factors;
  const reduce_internal::ScopedSmootherStopProbe scoped(std::move(probe));
  return reduce_internal::SmoothGroupToNoise(spans, sigmas, {}, factors, stop.get_token())
      .status()
      .code();
}

// The looks at the token of a guard round's band solve (the last round's, counted from the
// latest look at its levels), in a smoothing that is not stopped.
int GuardBandSolveLooks(int channel_count, int frames) {
  using Site = reduce_internal::SmootherStopSite;
  std::stop_source never;
  int looks = 0;
  SmoothProbed(channel_count, frames, never, [&](Site at) {
    if (at == Site::kLevelRows) looks = 0;
    if (at == Site::kBandRows) ++looks;
  });
  return looks;
}

StopSeen SmoothStoppedAt(const StopPlan& plan, int channel_count, int frames) {
  std::stop_source stop;
  StopSeen seen;
  bool counting = !plan.after.has_value();
  int looks_at_site = 0;
  seen.code = SmoothProbed(channel_count, frames, stop, [&](reduce_internal::SmootherStopSite at) {
    if (stop.stop_requested()) {
      seen.looks_after.push_back(at);
      return;
    }
    if (at == plan.after) {
      counting = true;
      looks_at_site = 0;
    }
    if (counting && at == plan.site && ++looks_at_site == plan.nth) {
      seen.reached = true;
      stop.request_stop();
    }
  });
  return seen;
}

TEST(NoiseCancellationTest, AStopSeenAtAnyLookInsideAChannelsSmoothingEndsItAtOnce) {
  using Site = reduce_internal::SmootherStopSite;
  // A band solve looks every 65536 rows, forward then back. One channel of 200 000 frames
  // solves its guard rounds alone (BandSolver); two of 140 000 frames, under the lanes' memory
  // bound (about 150 000), side by side (LaneBandSolver).
  struct Case {
    int channels;
    int frames;
  };
  for (const Case& c : {Case{1, 200'000}, Case{2, 140'000}}) {
    const int solve_looks = GuardBandSolveLooks(c.channels, c.frames);
    ASSERT_GE(solve_looks, 4) << c.channels;  // at least two each way, so that the plans differ
    ASSERT_EQ(solve_looks % 2, 0) << c.channels;
    const int way = solve_looks / 2;
    const std::vector<StopPlan> plans = {
        {Site::kSearchStep, 1, {}, "a search's window solves"},
        {Site::kSearchStep, 2, {}, "the next step of window solves"},
        {Site::kPhase, 1, {}, "after the channel's levels"},
        {Site::kPhase, 2, {}, "after the blocks' levels"},
        {Site::kLevelRows, 1, {}, "a guard round's levels"},
        {Site::kLevelRows, 2, {}, "the next rows of a guard round's levels"},
        {Site::kBandRows, 1, {}, "a search's band solve"},
        {Site::kBandRows, 1, Site::kLevelRows, "a guard round's band solve, forward"},
        {Site::kBandRows, way, Site::kLevelRows, "a guard round's band solve, last rows forward"},
        {Site::kBandRows, way + 1, Site::kLevelRows, "a guard round's band solve, first back"},
        {Site::kBandRows, 2 * way, Site::kLevelRows, "a guard round's band solve, last back"},
    };
    for (const StopPlan& plan : plans) {
      const StopSeen seen = SmoothStoppedAt(plan, c.channels, c.frames);

      const std::string where = plan.name + ", channels: " + std::to_string(c.channels);
      EXPECT_TRUE(seen.reached) << where;
      EXPECT_EQ(seen.code, absl::StatusCode::kCancelled) << where;
      // At most the one look on the way out: the phase's, after a search that saw the stop. A
      // stop ignored at a look would show as the next look of the same kind.
      EXPECT_LE(seen.looks_after.size(), 1u) << where;
      for (const Site after : seen.looks_after) {
        EXPECT_EQ(after, Site::kPhase) << where;
      }
      if (!seen.looks_after.empty()) {
        EXPECT_TRUE(plan.site == Site::kSearchStep || plan.site == Site::kBandRows) << where;
      }
    }
  }
}

TEST(NoiseCancellationTest, AProbeThatNeverStopsLeavesTheCurveBitForBit) {
  const std::vector<double> samples = LongNoisySine(5000);
  reduce_internal::SmootherFactors factors;
  const std::stop_source stop;
  int looks = 0;
  const reduce_internal::ScopedSmootherStopProbe probe(
      [&](reduce_internal::SmootherStopSite) { ++looks; });

  const absl::StatusOr<std::vector<double>> smooth =
      reduce_internal::SmoothToNoise(samples, kSigma, {}, factors, stop.get_token());

  ASSERT_TRUE(smooth.ok()) << smooth.status();
  EXPECT_GT(looks, 0);
  EXPECT_EQ(*smooth, SmoothToNoise(samples, kSigma));
}

TEST(NoiseCancellationTest, NoiseReductionStoppedWhileItRunsIsCancelled) {
  // Two long channels; the stop is requested when the first one's fit is reported done, from
  // inside the reduction, so it lands before the second one's fit whatever the machine's load
  // (no race between threads), and the look between channels sees it.
  constexpr int kFrames = 200'000;
  Clip clip;
  clip.name = "long";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = kFrames;
  for (const char* name : {"a", "b"}) {
    clip.channels.push_back({.joint = -1, .kind = ChannelKind::kScalar, .name = name,
                             .samples = LongNoisySine(kFrames)});
  }
  ReduceOptions options;
  options.method = ReduceMethod::kNoise;
  options.noise.position_sigma = kSigma;
  std::stop_source stop;
  const ProgressFn stop_after_first = [&](double fraction, std::string_view) {
    if (fraction > 0.0) stop.request_stop();
  };

  const absl::StatusOr<ReduceResult> result =
      ReduceKeys(clip, options, stop_after_first, stop.get_token());

  EXPECT_TRUE(stop.stop_requested());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kCancelled) << result.status();
}

}  // namespace
}  // namespace tempokey::core
