// Bad warps and options through the core API: each is refused with its exact message, by both
// Retime() and ValidateRetime(), and nothing crashes or hangs.
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/retime/retime.h"
#include "tests/core/retime/retime_invalid_cases.h"

namespace tempokey::core {
namespace {

using retime_cases::BadRetime;
using retime_cases::BadRetimes;
using retime_cases::EightSecondClip;
using retime_cases::Knot;
using retime_cases::kNaN;
using retime_cases::OverSource;

class RetimeInvalidTest : public ::testing::TestWithParam<BadRetime> {};

TEST_P(RetimeInvalidTest, RefusedWithItsExactMessage) {
  const BadRetime& bad = GetParam();
  const Clip clip = EightSecondClip();

  const absl::StatusOr<RetimeResult> result = Retime(clip, bad.warp, bad.options);
  const absl::Status validation = ValidateRetime(clip, bad.warp, bad.options);

  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(result.status().message(), bad.message);
  EXPECT_EQ(validation.message(), bad.message);
}

INSTANTIATE_TEST_SUITE_P(Table, RetimeInvalidTest, ::testing::ValuesIn(BadRetimes()),
                         [](const ::testing::TestParamInfo<BadRetime>& row) { return row.param.name; });

TEST(RetimeInvalidTest, OutputOverTheSampleCapIsRefusedBeforeAllocating) {
  Clip clip;
  clip.frame_time_seconds = 1.0 / 30;
  clip.frame_count = 241;
  for (int c = 0; c < 10000; ++c) clip.channels.push_back({.samples = {}});

  const absl::Status status =
      ValidateRetime(clip, OverSource({Knot(0, 0.01)}), {.fit_to_grid = false});

  EXPECT_EQ(status.message(),
            "the retimed clip would have 24001 frames x 10000 channels, over the limit of "
            "200000000 samples");
}

TEST(RetimeInvalidTest, OutputOverTheFrameCapIsRefused) {
  Clip clip;
  clip.frame_time_seconds = 1.0 / 30;
  clip.frame_count = 200000;

  const absl::Status status = ValidateRetime(clip, OverSource({Knot(0, 0.01)}), {});

  EXPECT_EQ(status.message(),
            "the retimed clip would last 666663 s (19999901 frames), over the limit of 10000000 "
            "frames");
}

// Counts over a size limit are RESOURCE_EXHAUSTED, as every other limit of the API (frames,
// channels, labels, joints); they were INVALID_ARGUMENT.
TEST(RetimeInvalidTest, TooManySpeedKnotsAreOverALimit) {
  std::vector<SpeedKnot> knots;
  for (int k = 0; k <= 100000; ++k) knots.push_back(Knot(k * 1e-5, 1.0));

  const absl::Status status = ValidateRetime(EightSecondClip(), OverSource(knots), {});
  const absl::Status paper =
      ValidateRetime(EightSecondClip(), OverSource(knots), {.method = RetimeMethod::kPaper});

  EXPECT_EQ(status.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(status.message(), "too many speed knots: 100001, over the limit of 100000");
  EXPECT_EQ(paper.code(), absl::StatusCode::kResourceExhausted);
}

TEST(RetimeInvalidTest, InvalidClipIsRefusedNamingTheSample) {
  Clip clip = EightSecondClip();
  clip.channels[1].samples[3] = kNaN;

  const absl::StatusOr<RetimeResult> result = Retime(clip, {}, {});

  EXPECT_EQ(result.status().message(), "channel 1 (b): sample 3 is NaN");
}

TEST(RetimeInvalidTest, UnknownEnumValuesAreRefused) {
  RetimeOptions options;
  options.filter = static_cast<ResampleFilter>(42);

  const absl::Status status = ValidateRetime(EightSecondClip(), {}, options);

  EXPECT_EQ(status.message(), "unknown resample filter 42");
}

}  // namespace
}  // namespace tempokey::core
