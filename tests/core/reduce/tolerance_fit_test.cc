// The error-bounded spline fit (SPEC 4.2) on signals with known answers.
#include "tempokey/core/reduce/tolerance_fit.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <future>
#include <latch>
#include <limits>
#include <random>
#include <span>
#include <stop_token>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"

// g++ 12 warns (-Wmissing-field-initializers) about designated initializers that leave members
// at their defaults, which is how STYLE.md builds options structs.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

using Samples = std::vector<double>;

absl::StatusOr<SplineFit> Fit(const std::vector<Samples>& channels, std::vector<double> bounds,
                              const ToleranceFitOptions& options = {}) {
  std::vector<std::span<const double>> spans(channels.begin(), channels.end());
  return FitWithinTolerance(spans, bounds, options);
}

absl::StatusOr<SplineFit> FitOne(const Samples& samples, double bound) {
  return Fit({samples}, {bound});
}

double MaxError(const SplineFit& fit, std::size_t channel, const Samples& samples) {
  const Samples curve = EvaluateSplineFit(fit, channel);
  double worst = 0.0;
  for (std::size_t f = 0; f < samples.size(); ++f) {
    worst = std::max(worst, std::abs(curve[f] - samples[f]));
  }
  return worst;
}

double Rms(const Samples& a, const Samples& b) {
  double sum = 0.0;
  for (std::size_t f = 0; f < a.size(); ++f) sum += (a[f] - b[f]) * (a[f] - b[f]);
  return std::sqrt(sum / static_cast<double>(a.size()));
}

Samples Sine(int frames, double amplitude, double period_frames, double phase = 0.0) {
  Samples s(static_cast<std::size_t>(frames));
  for (int f = 0; f < frames; ++f) {
    s[f] = amplitude * std::sin(2.0 * M_PI * f / period_frames + phase);
  }
  return s;
}

void ExpectSameFitBits(const SplineFit& got, const SplineFit& expected, const char* what) {
  ASSERT_EQ(got.frames, expected.frames) << what;
  ASSERT_EQ(got.values.size(), expected.values.size()) << what;
  for (std::size_t c = 0; c < got.values.size(); ++c) {
    for (std::size_t k = 0; k < got.frames.size(); ++k) {
      ASSERT_EQ(std::bit_cast<std::uint64_t>(got.values[c][k]),
                std::bit_cast<std::uint64_t>(expected.values[c][k]))
          << what << ": channel " << c << " key " << k;
      ASSERT_EQ(std::bit_cast<std::uint64_t>(got.slopes[c][k]),
                std::bit_cast<std::uint64_t>(expected.slopes[c][k]))
          << what << ": channel " << c << " key " << k;
    }
  }
}

// A thread keeps a fit's solve blocks and weights for its next fit (tolerance_fit.cc): what the
// fit before left in them, large or small, trimmed or kept, changes no bit of the next fit, which
// equals the same fit run first on a thread of its own.
TEST(ToleranceFitTest, AFitIsTheSameWhateverFitTheThreadRanBefore) {
  std::mt19937 random(29);
  std::normal_distribution<double> noise(0.0, 1.0);
  Samples noisy(40000);  // keyed almost every frame: blocks past what a thread keeps (1 MiB)
  for (double& v : noisy) v = noise(random);
  Samples medium = Sine(3000, 30.0, 37.0);
  for (double& v : medium) v += 0.2 * noise(random);
  const Samples smooth = Sine(400, 20.0, 90.0, 0.3);
  const Samples wavy = Sine(700, 5.0, 23.0, 1.1);
  auto fresh = [](const Samples& samples, double bound) {
    return std::async(std::launch::async, [&] { return FitOne(samples, bound); }).get();
  };
  const absl::StatusOr<SplineFit> smooth_alone = fresh(smooth, 0.05);
  const absl::StatusOr<SplineFit> wavy_alone = fresh(wavy, 0.01);
  ASSERT_TRUE(smooth_alone.ok() && wavy_alone.ok());

  // On this thread: a large fit, then a small one; a medium one, then small ones, in turn.
  ASSERT_TRUE(FitOne(noisy, 0.05).ok());
  const absl::StatusOr<SplineFit> smooth_after_large = FitOne(smooth, 0.05);
  ASSERT_TRUE(FitOne(medium, 0.1).ok());
  const absl::StatusOr<SplineFit> wavy_after_medium = FitOne(wavy, 0.01);
  const absl::StatusOr<SplineFit> smooth_after_wavy = FitOne(smooth, 0.05);

  ASSERT_TRUE(smooth_after_large.ok() && wavy_after_medium.ok() && smooth_after_wavy.ok());
  ExpectSameFitBits(*smooth_after_large, *smooth_alone, "after a large fit");
  ExpectSameFitBits(*wavy_after_medium, *wavy_alone, "after a medium fit");
  ExpectSameFitBits(*smooth_after_wavy, *smooth_alone, "after a small fit");
}

TEST(ToleranceFitTest, CubicIsTwoKeysThatReproduceIt) {
  Samples cubic(200);
  for (int f = 0; f < 200; ++f) {
    const double x = f / 199.0;
    cubic[f] = 3.0 - 40.0 * x + 90.0 * x * x - 55.0 * x * x * x;
  }
  // A cubic on the whole clip is one Hermite segment; only rounding separates them.
  constexpr double kRounding = 1e-9;

  const absl::StatusOr<SplineFit> fit = FitOne(cubic, 0.01);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_EQ(fit->frames, (std::vector<std::int64_t>{0, 199}));
  EXPECT_LT(MaxError(*fit, 0, cubic), kRounding);
}

TEST(ToleranceFitTest, SineStaysWithinEveryBoundAndNeedsFewerKeysForLooserOnes) {
  const Samples sine = Sine(2000, 45.0, 240.0);
  std::vector<std::size_t> keys;

  for (double bound : {0.01, 0.1, 0.5, 2.0}) {
    const absl::StatusOr<SplineFit> fit = FitOne(sine, bound);

    ASSERT_TRUE(fit.ok()) << fit.status();
    EXPECT_LE(MaxError(*fit, 0, sine), bound) << "bound " << bound;
    EXPECT_EQ(fit->frames.front(), 0);
    EXPECT_EQ(fit->frames.back(), 1999);
    EXPECT_TRUE(std::is_sorted(fit->frames.begin(), fit->frames.end()));
    keys.push_back(fit->frames.size());
  }

  // A cubic piece covers a quarter period within 0.5 of a 45-amplitude sine, and its error
  // shrinks with the 4th power of its length: the counts fall steeply and stay modest.
  EXPECT_GT(keys[0], keys[1]);
  EXPECT_GT(keys[1], keys[2]);
  EXPECT_GT(keys[2], keys[3]);
  EXPECT_LT(keys[2], 2000u / 20);  // fewer than one key per 20 frames at 0.5
}

TEST(ToleranceFitTest, NoiseUnderTheBoundAddsNoKeysAndTheCurveFollowsTheMotion) {
  const Samples truth = Sine(1200, 30.0, 300.0, 0.4);
  Samples noisy = truth;
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.3);
  for (double& v : noisy) v += noise(rng);
  // Three sigmas: the bound sits at the jitter's reach, so the curve need not chase it.
  constexpr double kBound = 0.9;

  const absl::StatusOr<SplineFit> clean_fit = FitOne(truth, kBound);
  const absl::StatusOr<SplineFit> noisy_fit = FitOne(noisy, kBound);

  ASSERT_TRUE(clean_fit.ok()) << clean_fit.status();
  ASSERT_TRUE(noisy_fit.ok()) << noisy_fit.status();
  EXPECT_LE(MaxError(*noisy_fit, 0, noisy), kBound);
  EXPECT_LE(noisy_fit->frames.size(), clean_fit->frames.size() + 4);
  EXPECT_LT(Rms(EvaluateSplineFit(*noisy_fit, 0), truth), 0.85 * Rms(noisy, truth));
}

TEST(ToleranceFitTest, ChannelsOfAGroupShareKeyFramesAndEachKeepsItsBound) {
  const Samples slow = Sine(600, 20.0, 400.0);
  const Samples fast = Sine(600, 5.0, 60.0, 1.0);
  const Samples flat(600, 7.25);

  const absl::StatusOr<SplineFit> together = Fit({slow, fast, flat}, {0.1, 0.05, 0.5});
  const absl::StatusOr<SplineFit> slow_alone = FitOne(slow, 0.1);

  ASSERT_TRUE(together.ok()) << together.status();
  ASSERT_TRUE(slow_alone.ok()) << slow_alone.status();
  ASSERT_EQ(together->values.size(), 3u);
  for (std::size_t c = 0; c < 3; ++c) {
    EXPECT_EQ(together->values[c].size(), together->frames.size());
    EXPECT_EQ(together->slopes[c].size(), together->frames.size());
  }
  EXPECT_LE(MaxError(*together, 0, slow), 0.1);
  EXPECT_LE(MaxError(*together, 1, fast), 0.05);
  EXPECT_LE(MaxError(*together, 2, flat), 0.5);
  // The fast channel sets the pace: the slow one alone needs far fewer keys.
  EXPECT_LT(slow_alone->frames.size() * 2, together->frames.size());
}

TEST(ToleranceFitTest, ConstantChannelIsTwoFlatKeys) {
  const Samples flat(500, -3.5);

  const absl::StatusOr<SplineFit> fit = FitOne(flat, 0.1);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_EQ(fit->frames, (std::vector<std::int64_t>{0, 499}));
  EXPECT_LT(MaxError(*fit, 0, flat), 1e-12);
}

TEST(ToleranceFitTest, OneFrameIsOneKeyAndTwoFramesAreTwoExactKeys) {
  const absl::StatusOr<SplineFit> one = FitOne({4.0}, 0.1);
  const absl::StatusOr<SplineFit> two = FitOne({1.0, 9.0}, 0.1);

  ASSERT_TRUE(one.ok()) << one.status();
  ASSERT_TRUE(two.ok()) << two.status();
  EXPECT_EQ(one->frames, (std::vector<std::int64_t>{0}));
  EXPECT_EQ(one->values[0], (std::vector<double>{4.0}));
  EXPECT_EQ(two->frames, (std::vector<std::int64_t>{0, 1}));
  EXPECT_LE(MaxError(*two, 0, {1.0, 9.0}), 0.1);
}

TEST(ToleranceFitTest, AlternatingSamplesAreFollowedWithinTheBound) {
  // +-10 on alternate frames with a bound of 0.1: a segment over two frames can swing through the
  // middle sample with opposite slopes at its ends, so about every other frame needs a key.
  Samples zigzag(64);
  for (int f = 0; f < 64; ++f) zigzag[f] = f % 2 == 0 ? 10.0 : -10.0;

  const absl::StatusOr<SplineFit> fit = FitOne(zigzag, 0.1);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_LE(MaxError(*fit, 0, zigzag), 0.1);
  EXPECT_GE(fit->frames.size(), 32u);
  EXPECT_LE(fit->frames.size(), 64u);
}

// The largest |curve - sample| of `channel` of `fit`, every segment evaluated here from the cubic
// Hermite basis in its factored form (h00 = (1 + 2t)(1 - t)^2, h10 = t (1 - t)^2,
// h01 = t^2 (3 - 2t), h11 = t^2 (t - 1), with y = h00 v_a + h10 L m_a + h01 v_b + h11 L m_b at
// t = k / L: tolerance_fit.h's definition), not by the library's EvaluateSplineFit().
double ClosedFormMaxError(const SplineFit& fit, std::size_t channel, const Samples& samples) {
  const std::vector<double>& v = fit.values[channel];
  const std::vector<double>& m = fit.slopes[channel];
  double worst = 0.0;
  for (std::size_t j = 0; j + 1 < fit.frames.size(); ++j) {
    const std::int64_t a = fit.frames[j];
    const auto length = static_cast<double>(fit.frames[j + 1] - a);
    for (std::int64_t f = a; f <= fit.frames[j + 1]; ++f) {
      const double t = static_cast<double>(f - a) / length;
      const double u = 1.0 - t;
      const double y = (1.0 + 2.0 * t) * u * u * v[j] + t * u * u * length * m[j] +
                       t * t * (3.0 - 2.0 * t) * v[j + 1] + t * t * (t - 1.0) * length * m[j + 1];
      worst = std::max(worst, std::abs(y - samples[static_cast<std::size_t>(f)]));
    }
  }
  return worst;
}

std::int64_t LongestSegment(const SplineFit& fit) {
  std::int64_t longest = 0;
  for (std::size_t k = 1; k < fit.frames.size(); ++k) {
    longest = std::max(longest, fit.frames[k] - fit.frames[k - 1]);
  }
  return longest;
}

TEST(ToleranceFitTest, LongSegmentsBeyondTheTabledLengthsFitToo) {
  // A slow sine over 200 000 frames: segments run far past the 256-frame basis tables.
  const Samples slow = Sine(200'000, 10.0, 150'000.0);

  const absl::StatusOr<SplineFit> fit = FitOne(slow, 0.05);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_LE(MaxError(*fit, 0, slow), 0.05);
  EXPECT_LT(fit->frames.size(), 200u);
  EXPECT_GT(LongestSegment(*fit), 256);
}

TEST(ToleranceFitTest, ARemovalMakesNoSegmentLongerThanTheLimit) {
  // Slow motion well within the bound over 100 000 frames: two keys would do, but merging keys
  // one at a time into one segment costs the square of its length; the removal stops at the
  // limit and keeps a key there.
  const Samples calm = Sine(100'000, 0.2, 150'000.0);

  const absl::StatusOr<SplineFit> fit = FitOne(calm, 0.5);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_LE(ClosedFormMaxError(*fit, 0, calm), 0.5);
  EXPECT_EQ(LongestSegment(*fit), kMaxMergedSegmentFrames);
  // Merging stops only at the limit: about one key per limit's length.
  const auto limit_lengths = static_cast<std::size_t>(100'000 / kMaxMergedSegmentFrames);
  EXPECT_LE(fit->frames.size(), 2 * limit_lengths + 2);
}

TEST(ToleranceFitTest, AChannelAsLongAsTheLimitIsStillOneSegment) {
  const auto frames = static_cast<int>(kMaxMergedSegmentFrames);
  const Samples at_limit = Sine(frames + 1, 0.2, 150'000.0);
  const Samples past_limit = Sine(frames + 2, 0.2, 150'000.0);

  const absl::StatusOr<SplineFit> one_segment = FitOne(at_limit, 0.5);
  const absl::StatusOr<SplineFit> two_segments = FitOne(past_limit, 0.5);

  ASSERT_TRUE(one_segment.ok()) << one_segment.status();
  ASSERT_TRUE(two_segments.ok()) << two_segments.status();
  EXPECT_EQ(one_segment->frames, (std::vector<std::int64_t>{0, frames}));
  EXPECT_EQ(two_segments->frames.size(), 3u);
  EXPECT_LE(LongestSegment(*two_segments), kMaxMergedSegmentFrames);
  EXPECT_LE(ClosedFormMaxError(*two_segments, 0, past_limit), 0.5);
}

// Still until `first`, then `height` from `first + 1` on, reached in a smooth step of `width`
// frames: a small quick step the fit meets only near where its merges reach the limit.
Samples StillThenStep(int frames, int first, int width, double height) {
  Samples s(static_cast<std::size_t>(frames), 0.0);
  for (int f = first + 1; f < frames; ++f) {
    const double x = std::min(1.0, static_cast<double>(f - first) / width);
    s[f] = height * x * x * (3.0 - 2.0 * x);
  }
  return s;
}

TEST(ToleranceFitTest, ASlideStopsAtTheLimitToo) {
  // The merge from frame 0 misses at the step, after the key that may slide, so the slides would
  // carry that key (and the merged segment) away past the limit: by 3 frames for the first step,
  // by 1 for the second (steps found by a search, with the slides' limit lifted or one frame
  // longer).
  for (const Samples& step :
       {StillThenStep(4300, 4085, 2, 0.8), StillThenStep(4300, 4085, 1, 0.8)}) {
    const absl::StatusOr<SplineFit> fit = FitOne(step, 0.5);

    ASSERT_TRUE(fit.ok()) << fit.status();
    EXPECT_LE(LongestSegment(*fit), kMaxMergedSegmentFrames);
    EXPECT_LE(ClosedFormMaxError(*fit, 0, step), 0.5);
  }
}

TEST(ToleranceFitTest, ASlideMayEndExactlyAtTheLimit) {
  // Keys every 16 frames to 4080, then from 4093: the merge of frame 0 to 4093 misses at the
  // step just after it, and the slide that fits carries that key to 4096, the limit itself.
  const Samples step = StillThenStep(4400, 4090, 3, 0.6);
  ToleranceFitOptions options;
  for (std::int64_t f = 0; f <= 4080; f += 16) options.initial_frames.push_back(f);
  for (std::int64_t f = 4093; f < 4399; f += 16) options.initial_frames.push_back(f);
  options.initial_frames.push_back(4399);

  const absl::StatusOr<SplineFit> fit = Fit({step}, {0.5}, options);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_EQ(fit->frames, (std::vector<std::int64_t>{0, kMaxMergedSegmentFrames, 4399}));
  EXPECT_LE(ClosedFormMaxError(*fit, 0, step), 0.5);
}

// A step of 1 at `step_at` on a still channel, fitted from keys every 8 frames to 96, then at 100,
// at 100 + `after` and 99 frames later: the removal of the key at 96 slides the key at 100 back
// towards it, which lengthens the segment after it.
struct SlideBackCase {
  Samples samples;
  ToleranceFitOptions options;
};

SlideBackCase StepBeforeALongStartSegment(int step_at, std::int64_t after) {
  SlideBackCase c;
  const std::int64_t last = 100 + after + 99;
  c.samples.assign(static_cast<std::size_t>(last + 1), 0.0);
  for (std::int64_t f = step_at; f <= last; ++f) c.samples[static_cast<std::size_t>(f)] = 1.0;
  for (std::int64_t f = 0; f < 100; f += 8) c.options.initial_frames.push_back(f);
  for (std::int64_t f : {std::int64_t{100}, 100 + after, last}) {
    c.options.initial_frames.push_back(f);
  }
  return c;
}

TEST(ToleranceFitTest, ASlideBackStretchesNoSegmentPastTheLimit) {
  // A start segment of exactly the limit: any slide back would stretch it past the limit.
  const SlideBackCase c = StepBeforeALongStartSegment(40, kMaxMergedSegmentFrames);

  const absl::StatusOr<SplineFit> fit = Fit({c.samples}, {0.5}, c.options);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_LE(LongestSegment(*fit), kMaxMergedSegmentFrames);
  EXPECT_LE(ClosedFormMaxError(*fit, 0, c.samples), 0.5);
}

TEST(ToleranceFitTest, ASlideBackMayLeaveTheNextSegmentExactlyAtTheLimit) {
  // A start segment of 4093 frames: the slide back to frame 97 makes it exactly the limit.
  const SlideBackCase c = StepBeforeALongStartSegment(30, kMaxMergedSegmentFrames - 3);

  const absl::StatusOr<SplineFit> fit = Fit({c.samples}, {0.5}, c.options);

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_EQ(fit->frames, (std::vector<std::int64_t>{0, 97, 4193, 4292}));
  EXPECT_LE(ClosedFormMaxError(*fit, 0, c.samples), 0.5);
}

TEST(ToleranceFitTest, EveryOptionSettingKeepsTheBound) {
  const Samples sine = Sine(900, 60.0, 170.0);
  for (const ToleranceFitOptions& options :
       {ToleranceFitOptions{.initial_spacing_frames = 1, .lawson_iterations = 0, .slide_frames = 0},
        ToleranceFitOptions{.initial_spacing_frames = 900, .lawson_iterations = 5,
                            .slide_frames = 6}}) {
    const absl::StatusOr<SplineFit> fit = Fit({sine}, {0.2}, options);

    ASSERT_TRUE(fit.ok()) << fit.status();
    EXPECT_LE(MaxError(*fit, 0, sine), 0.2);
  }
}

TEST(ToleranceFitTest, TheFitStartsFromTheGivenKeyFrames) {
  const Samples sine = Sine(400, 1.0, 90.0);
  std::vector<std::int64_t> every_third;
  for (std::int64_t f = 0; f < 399; f += 3) every_third.push_back(f);
  every_third.push_back(399);
  // Keys every third frame already fit a slow sine far within the bound: nothing is inserted,
  // and without slides the removal only takes keys away.
  const absl::StatusOr<SplineFit> fit =
      Fit({sine}, {0.01}, {.slide_frames = 0, .initial_frames = every_third});

  ASSERT_TRUE(fit.ok()) << fit.status();
  EXPECT_LE(MaxError(*fit, 0, sine), 0.01);
  EXPECT_LT(fit->frames.size(), every_third.size());
  for (std::int64_t frame : fit->frames) {
    EXPECT_TRUE(frame % 3 == 0 || frame == 399) << "key at frame " << frame;
  }
}

TEST(ToleranceFitTest, EveryStartKeepsTheBound) {
  const Samples fast = Sine(600, 40.0, 23.0);
  const absl::StatusOr<SplineFit> loose = Fit({fast}, {0.5});
  ASSERT_TRUE(loose.ok()) << loose.status();
  std::vector<std::int64_t> every_frame(600);
  for (std::int64_t f = 0; f < 600; ++f) every_frame[f] = f;
  std::vector<std::int64_t> clustered = {0};
  for (std::int64_t f = 290; f < 310; ++f) clustered.push_back(f);
  clustered.push_back(599);

  for (const std::vector<std::int64_t>& start :
       {loose->frames, every_frame, std::vector<std::int64_t>{0, 599}, clustered}) {
    const absl::StatusOr<SplineFit> fit = Fit({fast}, {0.05}, {.initial_frames = start});

    ASSERT_TRUE(fit.ok()) << fit.status();
    EXPECT_LE(MaxError(*fit, 0, fast), 0.05) << "from " << start.size() << " keys";
  }
}

TEST(ToleranceFitTest, OneAndTwoFrameChannelsTakeTheirOnlyStart) {
  const absl::StatusOr<SplineFit> one = Fit({Samples{3.0}}, {0.1}, {.initial_frames = {0}});
  ASSERT_TRUE(one.ok()) << one.status();
  EXPECT_EQ(one->frames, (std::vector<std::int64_t>{0}));

  const absl::StatusOr<SplineFit> two =
      Fit({Samples{3.0, 5.0}}, {0.1}, {.initial_frames = {0, 1}});
  ASSERT_TRUE(two.ok()) << two.status();
  EXPECT_EQ(two->frames, (std::vector<std::int64_t>{0, 1}));
  EXPECT_LE(MaxError(*two, 0, Samples{3.0, 5.0}), 0.1);
}

// The first non-finite sample is named wherever it lies: in a vector block, in the tail after the
// last whole block, or alone; the largest finite doubles pass the check.
TEST(ToleranceFitTest, TheFirstNonFiniteSampleIsNamedWhereverItIs) {
  for (std::size_t n : {1, 3, 37, 131}) {
    for (std::size_t at = 0; at < n; ++at) {
      for (double bad : {std::numeric_limits<double>::quiet_NaN(),
                         std::numeric_limits<double>::infinity(),
                         -std::numeric_limits<double>::infinity()}) {
        Samples samples(n, std::numeric_limits<double>::max());
        samples[at] = bad;
        if (at + 1 < n) samples[n - 1] = bad;  // a later one is not the one named

        const absl::StatusOr<SplineFit> fit = Fit({Samples(n, 0.0), samples}, {0.1, 0.1});

        EXPECT_EQ(fit.status().message(),
                  absl::StrCat("channel 1: sample ", at, " is ",
                               std::isnan(bad) ? "NaN" : "infinite"))
            << n << " " << at;
      }
    }
  }
}

TEST(ToleranceFitTest, InvalidInputsAreRefusedWithReasons) {
  const Samples good = Sine(50, 1.0, 20.0);
  Samples with_nan = good;
  with_nan[17] = std::numeric_limits<double>::quiet_NaN();

  EXPECT_EQ(Fit({}, {}).status().message(), "a fit needs at least one channel");
  EXPECT_EQ(Fit({good}, {0.1, 0.1}).status().message(), "got 2 bounds for 1 channels");
  EXPECT_EQ(Fit({good, Samples(49, 0.0)}, {0.1, 0.1}).status().message(),
            "channel 1 has 49 samples, channel 0 has 50");
  EXPECT_EQ(Fit({Samples{}}, {0.1}).status().message(), "channel 0 has no samples");
  EXPECT_EQ(Fit({with_nan}, {0.1}).status().message(), "channel 0: sample 17 is NaN");
  EXPECT_EQ(Fit({good}, {0.0}).status().message(),
            "channel 0: the bound must be finite and > 0, got 0");
  EXPECT_EQ(Fit({good}, {std::numeric_limits<double>::infinity()}).status().message(),
            "channel 0: the bound must be finite and > 0, got inf");
  EXPECT_EQ(Fit({good}, {0.1}, {.initial_spacing_frames = 0}).status().message(),
            "initial_spacing_frames must be in [1, 1000000], got 0");
  EXPECT_EQ(Fit({good}, {0.1}, {.initial_frames = {1, 49}}).status().message(),
            "initial_frames must start at frame 0 and end at the last frame (49), got 1 to 49");
  EXPECT_EQ(Fit({good}, {0.1}, {.initial_frames = {0, 48}}).status().message(),
            "initial_frames must start at frame 0 and end at the last frame (49), got 0 to 48");
  EXPECT_EQ(Fit({good}, {0.1}, {.initial_frames = {0, 20, 20, 49}}).status().message(),
            "initial_frames must be strictly increasing: key 2 at frame 20 follows frame 20");
  EXPECT_EQ(Fit({good}, {0.1}, {.initial_frames = {0}}).status().message(),
            "initial_frames must start at frame 0 and end at the last frame (49), got 0 to 0");
  EXPECT_EQ(Fit({good}, {0.1}, {.lawson_iterations = -1}).status().message(),
            "lawson_iterations must be in [0, 100], got -1");
  EXPECT_EQ(Fit({good}, {0.1}, {.slide_frames = 5000}).status().message(),
            "slide_frames must be in [0, 1000], got 5000");
}

TEST(ToleranceFitTest, StopRequestCancels) {
  std::stop_source stop;
  stop.request_stop();
  const Samples sine = Sine(100, 1.0, 30.0);
  const std::vector<std::span<const double>> channels = {sine};
  const std::vector<double> bounds = {0.1};

  const absl::StatusOr<SplineFit> fit = FitWithinTolerance(channels, bounds, {}, stop.get_token());

  EXPECT_EQ(fit.status().code(), absl::StatusCode::kCancelled);
}

TEST(ToleranceFitTest, LongFitStoppedFromAnotherThreadIsCancelled) {
  // A triangle wave of 3 million frames with keys a million frames apart to start, the widest
  // slides and the most Lawson rounds: about a minute of work uncancelled (the removal's trials
  // and Lawson rounds count for the stop token, not only its candidates).
  Samples triangle(3'000'000);
  for (std::size_t f = 0; f < triangle.size(); ++f) {
    triangle[f] = 1e-3 * std::abs(static_cast<double>(f % 400'000) - 200'000.0);
  }
  const std::vector<std::span<const double>> channels = {triangle};
  const std::vector<double> bounds = {0.01};
  const ToleranceFitOptions options = {
      .initial_spacing_frames = 1'000'000, .lawson_iterations = 100, .slide_frames = 1000};
  std::stop_source stop;
  std::latch started(1);

  // The stop is requested from this thread once the fit's thread is about to begin.
  std::future<absl::StatusOr<SplineFit>> run = std::async(std::launch::async, [&] {
    started.count_down();
    return FitWithinTolerance(channels, bounds, options, stop.get_token());
  });
  started.wait();
  stop.request_stop();
  const absl::StatusOr<SplineFit> fit = run.get();

  EXPECT_EQ(fit.status().code(), absl::StatusCode::kCancelled) << fit.status();
}

}  // namespace
}  // namespace tempokey::core
