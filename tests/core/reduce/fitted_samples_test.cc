// FittedSamples (core/src/reduce/reduction_internal.h): the samples a reduction fits are the
// clip's with each rotation channel unwrapped (UnwrapDegrees()), bit for bit; a channel that
// unwrapping leaves as it is is read where the clip holds it, without a copy.
#include <bit>
#include <cmath>
#include <cstdint>
#include <random>
#include <span>
#include <vector>

#include "core/src/reduce/reduction_internal.h"
#include "gtest/gtest.h"
#include "tempokey/core/model/rotation.h"

// Channels below are written with designated initializers naming only what matters.
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core::reduce_internal {
namespace {

Clip OneRotationAndOnePosition(const std::vector<double>& rotation) {
  Clip clip;
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = static_cast<std::int64_t>(rotation.size());
  clip.channels = {Channel{.joint = -1, .kind = ChannelKind::kXRotation, .name = "r",
                           .samples = rotation},
                   Channel{.joint = -1, .kind = ChannelKind::kXPosition, .name = "p",
                           .samples = rotation}};
  return clip;
}

// UnwrapDegrees() on a copy: what the fit must see.
std::vector<double> Unwrapped(std::vector<double> degrees) {
  UnwrapDegrees(degrees);
  return degrees;
}

void ExpectSameBits(std::span<const double> got, const std::vector<double>& expected,
                    const char* what) {
  ASSERT_EQ(got.size(), expected.size()) << what;
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(std::bit_cast<std::uint64_t>(got[i]), std::bit_cast<std::uint64_t>(expected[i]))
        << what << ": sample " << i << " is " << got[i] << ", expected " << expected[i];
  }
}

// A smooth rotation, steps of a few degrees, no zeros.
std::vector<double> Smooth(std::size_t n) {
  std::vector<double> out(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = 40.0 * std::sin(0.05 * static_cast<double>(i)) + 0.5;
  return out;
}

TEST(FittedSamplesTest, ARotationThatNeedsNoUnwrappingIsReadInPlace) {
  for (std::size_t n : {0, 1, 2, 33, 100}) {
    const Clip clip = OneRotationAndOnePosition(Smooth(n));

    const FittedSamples fitted(clip);

    ASSERT_EQ(fitted.channels().size(), 2u);
    EXPECT_EQ(fitted.channels()[0].data(), clip.channels[0].samples.data()) << n;
    EXPECT_EQ(fitted.channels()[1].data(), clip.channels[1].samples.data()) << n;
    ExpectSameBits(fitted.channels()[0], clip.channels[0].samples, "rotation");
  }
}

// A turn through +-180 or a -0 anywhere after the first sample (in a vector block or in the tail
// after the last whole block) makes a copy, unwrapped as UnwrapDegrees() does it; the position
// channel with the same samples is never unwrapped.
TEST(FittedSamplesTest, WrapsAndNegativeZerosAnywhereAreUnwrappedIntoACopy) {
  for (std::size_t n : {2, 5, 33, 67, 100}) {
    for (std::size_t at = 0; at < n; ++at) {
      for (int kind = 0; kind < 3; ++kind) {
        std::vector<double> rotation = Smooth(n);
        if (kind == 0) {
          rotation[at] = -0.0;
        } else {
          // A jump of more than half a turn from the sample before.
          rotation[at] += kind == 1 ? 185.0 : -359.0;
        }
        const Clip clip = OneRotationAndOnePosition(rotation);

        const FittedSamples fitted(clip);

        // Only -0 at the first sample, which unwrapping never touches, keeps the clip's samples.
        const bool changed = !(kind == 0 && at == 0);
        EXPECT_EQ(fitted.channels()[0].data() != clip.channels[0].samples.data(), changed)
            << n << " " << at << " " << kind;
        ExpectSameBits(fitted.channels()[0], Unwrapped(rotation), "rotation");
        EXPECT_EQ(fitted.channels()[1].data(), clip.channels[1].samples.data());
        if (::testing::Test::HasFailure()) return;
      }
    }
  }
}

TEST(FittedSamplesTest, RandomRotationsAreUnwrappedBitForBit) {
  std::mt19937_64 random(20261130);
  std::uniform_real_distribution<double> step(-12.0, 12.0);
  std::uniform_int_distribution<int> event(0, 60);
  for (int trial = 0; trial < 200; ++trial) {
    const std::size_t n = 1 + static_cast<std::size_t>(trial % 97);
    std::vector<double> rotation(n);
    double angle = 170.0;
    for (std::size_t i = 0; i < n; ++i) {
      angle += step(random);
      const int e = event(random);
      // Now and then a wrap of the angle into (-180, 180], an exact 0 or a -0.
      const double wrapped = angle > 180.0 ? angle - 360.0 : angle < -180.0 ? angle + 360.0 : angle;
      rotation[i] = e == 0 ? 0.0 : e == 1 ? -0.0 : e < 20 ? wrapped : angle;
    }
    const Clip clip = OneRotationAndOnePosition(rotation);

    const FittedSamples fitted(clip);

    ExpectSameBits(fitted.channels()[0], Unwrapped(rotation), "rotation");
    ExpectSameBits(fitted.channels()[1], rotation, "position");
    // The closed form of unwrapping, not UnwrapDegrees(): every sample moved by whole turns
    // only, and no step between samples over half a turn.
    const std::span<const double> unwrapped = fitted.channels()[0];
    for (std::size_t i = 0; i < n; ++i) {
      const double turns = (unwrapped[i] - rotation[i]) / 360.0;
      EXPECT_NEAR(turns, std::round(turns), 1e-9) << "trial " << trial << " sample " << i;
      if (i > 0) {
        EXPECT_LE(std::abs(unwrapped[i] - unwrapped[i - 1]), 180.0) << i;
      }
    }
    if (::testing::Test::HasFailure()) return;
  }
}

}  // namespace
}  // namespace tempokey::core::reduce_internal
