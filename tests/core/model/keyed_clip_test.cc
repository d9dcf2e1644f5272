#include "tempokey/core/model/keyed_clip.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "gtest/gtest.h"

// Keys and channels below are written with designated initializers naming only what matters.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// Evaluations of the same cubic along two formulas agree to rounding of values of order 10.
constexpr double kRounding = 1e-12;

Clip TwoChannelLayout() {
  Clip layout;
  layout.name = "layout";
  layout.frame_time_seconds = 0.1;
  layout.frame_count = 11;
  layout.channels = {Channel{.joint = -1, .kind = ChannelKind::kScalar, .name = "a"},
                     Channel{.joint = -1, .kind = ChannelKind::kScalar, .name = "b"}};
  return layout;
}

TEST(EvaluateCurveTest, NonWeightedSegmentIsTheCubicHermiteInTime) {
  const Curve curve{{Key{.time_seconds = 1.0, .value = 2.0, .in_tangent = 0, .out_tangent = 3.0},
                     Key{.time_seconds = 3.0, .value = -1.0, .in_tangent = 0.5, .out_tangent = 0}}};

  // s = 0.25, dt = 2: h00 = 0.84375, h10 = 0.140625, h01 = 0.15625, h11 = -0.046875.
  const double expected = 0.84375 * 2.0 + 0.140625 * 3.0 * 2.0 + 0.15625 * -1.0 +
                          -0.046875 * 0.5 * 2.0;

  EXPECT_NEAR(EvaluateCurve(curve, 1.5), expected, kRounding);
  EXPECT_EQ(EvaluateCurve(curve, 1.0), 2.0);
  EXPECT_EQ(EvaluateCurve(curve, 3.0), -1.0);
  EXPECT_EQ(EvaluateCurve(curve, 0.0), 2.0);
  EXPECT_EQ(EvaluateCurve(curve, 9.0), -1.0);
}

TEST(EvaluateCurveTest, WeightsOfOneThirdMatchNonWeightedKeys) {
  Curve plain{{Key{.time_seconds = 0.0, .value = 1.0, .in_tangent = 0, .out_tangent = -4.0},
               Key{.time_seconds = 0.5, .value = 3.0, .in_tangent = 2.0, .out_tangent = 0}}};
  Curve weighted = plain;
  for (Key& key : weighted.keys) {
    key.in_weight = 1.0 / 3.0;
    key.out_weight = 1.0 / 3.0;
  }

  for (int i = 0; i <= 50; ++i) {
    const double t = 0.01 * i;
    EXPECT_NEAR(EvaluateCurve(weighted, t), EvaluateCurve(plain, t), kRounding) << t;
  }
}

TEST(EvaluateCurveTest, WeightedSegmentFollowsTheTwoDimensionalBezier) {
  // Handles at 0.1 and 0.6 of a 1 s segment: time x(s) and value y(s) are Beziers with controls
  // (0, 0.1, 0.4, 1) and (0, 0.1 * 2, 5 - 0.6 * 1, 5); the curve passes through (x(s), y(s)).
  const Curve curve{
      {Key{.time_seconds = 0, .value = 0, .out_tangent = 2.0, .out_weight = 0.1},
       Key{.time_seconds = 1, .value = 5, .in_tangent = 1.0, .in_weight = 0.6}}};
  for (double s : {0.1, 0.3, 0.5, 0.77, 0.95}) {
    const double u = 1 - s;
    const double x = 3 * u * u * s * 0.1 + 3 * u * s * s * 0.4 + s * s * s;
    const double y = 3 * u * u * s * 0.2 + 3 * u * s * s * 4.4 + s * s * s * 5.0;

    EXPECT_NEAR(EvaluateCurve(curve, x), y, 1e-10) << "s " << s;
  }
}

TEST(SampleCurveTest, EqualsEvaluateCurveBitForBitOnRandomCurves) {
  std::mt19937 random(7);
  std::uniform_real_distribution<double> value(-100.0, 100.0);
  std::uniform_real_distribution<double> weight(0.05, 0.45);
  std::uniform_int_distribution<int> gap(1, 9);
  for (int trial = 0; trial < 50; ++trial) {
    const double frame_time = trial % 2 == 0 ? 1.0 / 30.0 : 1.0 / 120.0;
    Curve curve;
    double frame = trial % 3;  // sometimes the first key is after time 0
    for (int k = 0; k < 1 + trial % 12; ++k) {
      Key key{.time_seconds = frame * frame_time, .value = value(random),
              .in_tangent = value(random), .out_tangent = value(random)};
      if (trial % 4 == 1) {  // weighted tangents on some curves
        key.in_weight = weight(random);
        key.out_weight = weight(random);
      }
      curve.keys.push_back(key);
      frame += gap(random);
    }
    // Past the last key too, where the curve holds its last value.
    std::vector<double> sampled(static_cast<std::size_t>(frame) + 5);
    SampleCurve(curve, frame_time, sampled);
    for (std::size_t i = 0; i < sampled.size(); ++i) {
      const double expected = EvaluateCurve(curve, static_cast<double>(i) * frame_time);
      ASSERT_EQ(sampled[i], expected) << "trial " << trial << " sample " << i;
    }
  }
}

// Flat keys (a constant channel's) at any value, -0 included, with zero tangents of either sign;
// and curves that are nearly flat (a tangent of 1e-300, a weight): every sample is what
// EvaluateCurve() gives at its time, bit for bit, before, between and after the keys.
TEST(SampleCurveTest, FlatAndNearlyFlatCurvesGiveEvaluateCurvesBits) {
  const double frame_time = 1.0 / 30.0;
  for (double value : {1.5, -2.25, 0.0, -0.0, 1e12, 5e-324, -5e-324}) {
    for (int variant = 0; variant < 5; ++variant) {
      Curve curve;
      for (int k = 0; k < (variant == 1 ? 5 : 2); ++k) {
        curve.keys.push_back(Key{.time_seconds = (2.0 + 9.0 * k) * frame_time, .value = value,
                                 .in_tangent = k % 2 == 0 ? 0.0 : -0.0,
                                 .out_tangent = k % 2 == 0 ? -0.0 : 0.0});
      }
      if (variant == 2) curve.keys[0].out_tangent = 1e-300;
      if (variant == 3) curve.keys[1].in_weight = 0.25;
      if (variant == 4) curve.keys[1].value = std::nextafter(value, 1.0);
      const double last_frame = curve.keys.back().time_seconds / frame_time;
      std::vector<double> sampled(static_cast<std::size_t>(last_frame) + 4);
      std::vector<double> piece(sampled.size() - 5);

      SampleCurve(curve, frame_time, sampled);
      SampleCurve(curve, frame_time, piece, 5);

      for (std::size_t i = 0; i < sampled.size(); ++i) {
        const double expected = EvaluateCurve(curve, static_cast<double>(i) * frame_time);
        ASSERT_EQ(std::bit_cast<std::uint64_t>(sampled[i]), std::bit_cast<std::uint64_t>(expected))
            << "value " << value << " variant " << variant << " sample " << i << ": "
            << sampled[i] << " against " << expected;
        if (i >= 5) {
          ASSERT_EQ(std::bit_cast<std::uint64_t>(piece[i - 5]),
                    std::bit_cast<std::uint64_t>(expected))
              << "value " << value << " variant " << variant << " piece sample " << i;
        }
      }
    }
  }
}

// The closed form, not EvaluateCurve(): flat keys are their value at every time. For -0 the
// IEEE sums give -0 at and outside the keys (the key's value itself) and +0 between them, where
// the Hermite adds its +0 terms (-0 + +0 = +0).
TEST(SampleCurveTest, FlatKeysAreTheirValueAtEveryFrame) {
  const double frame_time = 1.0 / 120.0;
  for (double value : {3.25, -7.5, 0.0, 1e-310, -1e12}) {
    const Curve curve{{Key{.time_seconds = 4 * frame_time, .value = value},
                       Key{.time_seconds = 9 * frame_time, .value = value},
                       Key{.time_seconds = 30 * frame_time, .value = value, .in_tangent = -0.0}}};
    std::vector<double> sampled(40);

    SampleCurve(curve, frame_time, sampled);

    for (std::size_t i = 0; i < sampled.size(); ++i) {
      ASSERT_EQ(std::bit_cast<std::uint64_t>(sampled[i]), std::bit_cast<std::uint64_t>(value))
          << "value " << value << " frame " << i;
    }
  }
  const Curve negative_zero{{Key{.time_seconds = 4 * frame_time, .value = -0.0},
                             Key{.time_seconds = 9 * frame_time, .value = -0.0}}};
  std::vector<double> sampled(12);

  SampleCurve(negative_zero, frame_time, sampled);

  for (std::size_t i = 0; i < sampled.size(); ++i) {
    const bool between_keys = i > 4 && i < 9;
    EXPECT_EQ(std::signbit(sampled[i]), !between_keys) << "frame " << i;
    EXPECT_EQ(sampled[i], 0.0) << "frame " << i;
  }
}

TEST(SampleCurveTest, PiecesFromALaterFirstFrameEqualTheWholeCurveBitForBit) {
  std::mt19937 random(13);
  std::uniform_real_distribution<double> value(-100.0, 100.0);
  const double frame_time = 1.0 / 120.0;
  Curve curve;
  for (int k = 0; k < 40; ++k) {
    curve.keys.push_back(Key{.time_seconds = 7.0 * k * frame_time, .value = value(random),
                             .in_tangent = value(random), .out_tangent = value(random)});
  }
  std::vector<double> whole(300);
  SampleCurve(curve, frame_time, whole);
  for (std::int64_t first : {1, 6, 7, 33, 150, 271}) {
    std::vector<double> piece(static_cast<std::size_t>(300 - first));
    SampleCurve(curve, frame_time, piece, first);
    for (std::size_t i = 0; i < piece.size(); ++i) {
      ASSERT_EQ(piece[i], whole[static_cast<std::size_t>(first) + i])
          << "first " << first << " sample " << i;
    }
  }
}

TEST(SolveBezierParameterTest, InvertsRandomMonotonicControls) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int trial = 0; trial < 1000; ++trial) {
    const double x1 = unit(rng);
    const double x2 = x1 + (1.0 - x1) * unit(rng);
    const double s = unit(rng);
    const double u = 1 - s;
    const double x = 3 * u * u * s * x1 + 3 * u * s * s * x2 + s * s * s * 1.0;

    const double solved = SolveBezierParameter(0.0, x1, x2, 1.0, x);

    const double v = 1 - solved;
    EXPECT_NEAR(3 * v * v * solved * x1 + 3 * v * solved * solved * x2 + solved * solved * solved,
                x, 1e-14);
  }
}

TEST(ValidateKeyedClipTest, MalformedCurvesAreNamed) {
  const Key a{.time_seconds = 0.0, .value = 1.0};
  const Key b{.time_seconds = 0.5, .value = 1.0};
  struct Case {
    Curve curve;
    const char* message;
  } cases[] = {
      {Curve{}, "channel 1 (b): the curve has no keys"},
      {Curve{{a, a}}, "channel 1 (b): key 1: time 0 s is not after the previous key's 0 s"},
      {Curve{{a, Key{.time_seconds = 1, .value = NAN}}}, "channel 1 (b): key 1: value is NaN"},
      {Curve{{a, Key{.time_seconds = 1, .out_tangent = INFINITY}}},
       "channel 1 (b): key 1: out tangent is +infinity"},
      {Curve{{Key{.out_weight = 0.0}, b}},
       "channel 1 (b): key 0: out weight must be in (0, 1], got 0"},
      {Curve{{Key{.out_weight = 0.8}, Key{.time_seconds = 1, .in_weight = 0.5}}},
       "channel 1 (b): key 1: in weight plus the previous key's out weight is 1.3, over 1 (time "
       "would run backwards)"},
  };
  for (const Case& c : cases) {
    KeyedClip keyed{TwoChannelLayout(), {Curve{{a, b}}, c.curve}};

    const absl::Status status = ValidateKeyedClip(keyed);

    EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << c.message;
    EXPECT_EQ(status.message(), c.message);
  }
}

// Every field of a key at, and just past, each end of its range, one field at a time: the bound
// itself is accepted, anything past it (NaN and the infinities included) refused with the key and
// the field named.
TEST(ValidateCurveTest, EachFieldIsRefusedJustPastItsLimitAndAcceptedAtIt) {
  struct Field {
    const char* name;
    double Key::*member;
    double bound;
  } fields[] = {
      {"time", &Key::time_seconds, kMaxTimeSeconds},
      {"value", &Key::value, kMaxKeyValueMagnitude},
      {"in tangent", &Key::in_tangent, kMaxKeyTangent},
      {"out tangent", &Key::out_tangent, kMaxKeyTangent},
  };
  for (const Field& field : fields) {
    // Key 1 of two is changed; key 0 sits before any time used.
    auto curve_with = [&](double value) {
      Curve curve{{Key{.time_seconds = -kMaxTimeSeconds}, Key{.time_seconds = 0.0}}};
      curve.keys[1].*field.member = value;
      return curve;
    };
    const double over = std::nextafter(field.bound, INFINITY);

    EXPECT_TRUE(ValidateCurve(curve_with(field.bound), "c").ok()) << field.name;
    if (field.member != &Key::time_seconds) {  // key 1's time must stay after key 0's
      EXPECT_TRUE(ValidateCurve(curve_with(-field.bound), "c").ok()) << field.name;
    }
    for (double bad : {over, -over, double{NAN}, double{INFINITY}, -double{INFINITY}}) {
      const std::string prefix = std::string("c: key 1: ") + field.name + " ";

      const absl::Status status = ValidateCurve(curve_with(bad), "c");

      EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument) << field.name << " " << bad;
      EXPECT_EQ(std::string(status.message()).substr(0, prefix.size()), prefix)
          << status.message();
    }
  }
}

// Weights: unset or in (0, 1], and a segment's two at most 1 (+ kWeightSumSlack), an unset one
// counting as 1/3.
TEST(ValidateCurveTest, WeightsAreRefusedOutsideTheirRangeAndOverOneTogether) {
  auto curve_with = [](std::optional<double> out_weight, std::optional<double> in_weight) {
    return Curve{{Key{.time_seconds = 0.0, .out_weight = out_weight},
                  Key{.time_seconds = 1.0, .in_weight = in_weight}}};
  };

  EXPECT_TRUE(ValidateCurve(curve_with(std::nullopt, std::nullopt), "c").ok());
  EXPECT_TRUE(ValidateCurve(curve_with(0.5, 0.5), "c").ok());
  EXPECT_TRUE(ValidateCurve(curve_with(0.6, 0.4 + 1e-10), "c").ok());
  EXPECT_TRUE(ValidateCurve(curve_with(1e-300, 0.5), "c").ok());
  for (double bad : {0.0, -0.0, -0.5, std::nextafter(1.0, 2.0), double{NAN}, double{INFINITY}}) {
    EXPECT_FALSE(ValidateCurve(curve_with(bad, std::nullopt), "c").ok()) << bad;
    EXPECT_FALSE(ValidateCurve(curve_with(std::nullopt, bad), "c").ok()) << bad;
  }
  EXPECT_FALSE(ValidateCurve(curve_with(0.6, 0.4 + 2e-9), "c").ok());
  const absl::Status over = ValidateCurve(curve_with(0.7, std::nullopt), "c");
  EXPECT_NE(std::string(over.message()).find("c: key 1: in weight plus the previous key's out "
                                             "weight is"),
            std::string::npos)
      << over.message();
}

TEST(ValidateKeyedClipTest, CurveCountMustMatchChannels) {
  const KeyedClip keyed{TwoChannelLayout(), {Curve{{Key{}}}}};

  EXPECT_EQ(ValidateKeyedClip(keyed).message(), "keyed clip has 1 curves for 2 channels");
}

TEST(BakeTest, SamplesEveryFrameOfTheLayoutDuration) {
  const Curve line{{Key{.time_seconds = 0, .value = 0, .out_tangent = 2.0},
                    Key{.time_seconds = 1, .value = 2, .in_tangent = 2.0}}};
  const KeyedClip keyed{TwoChannelLayout(), {line, Curve{{Key{.value = 7.0}}}}};

  absl::StatusOr<Clip> same_rate = Bake(keyed);
  absl::StatusOr<Clip> fourth_rate = Bake(keyed, 0.25);

  ASSERT_TRUE(same_rate.ok()) << same_rate.status();
  EXPECT_EQ(same_rate->frame_count, 11);
  for (int i = 0; i <= 10; ++i) {
    EXPECT_NEAR(same_rate->channels[0].samples[i], 0.2 * i, kRounding);
    EXPECT_EQ(same_rate->channels[1].samples[i], 7.0);
  }
  ASSERT_TRUE(fourth_rate.ok());
  EXPECT_EQ(fourth_rate->frame_count, 5);
  EXPECT_EQ(fourth_rate->frame_time_seconds, 0.25);
  EXPECT_TRUE(ValidateClip(*fourth_rate).ok());
}

TEST(BakeTest, RefusesBadFrameTimesAndHugeResults) {
  const KeyedClip keyed{TwoChannelLayout(), {Curve{{Key{}}}, Curve{{Key{}}}}};

  EXPECT_EQ(Bake(keyed, 0.0).status().message(),
            "bake frame time must be in [1e-06, 3600] seconds, got 0");
  EXPECT_EQ(Bake(keyed, NAN).status().message(),
            "bake frame time must be in [1e-06, 3600] seconds, got NaN");
  EXPECT_EQ(Bake(keyed, 1e-10).status().message(),
            "bake frame time must be in [1e-06, 3600] seconds, got 1e-10");
  ClipLimits small;
  small.max_samples = 1000;
  EXPECT_EQ(Bake(keyed, 1e-3, small).status().message(),
            "bake at 0.001 s per frame gives 1001 frames x 2 channels, over the limit of "
            "1000 samples");
}

}  // namespace
}  // namespace tempokey::core
