// PlanRetime(): the time map and report of a retime without resampling, and FormatSpeedKnots(),
// the inverse of the CLI's speed syntax.
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/retime/time_map.h"
#include "tests/testing/test_paths.h"

#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

// A real clip: 131_01 (994 frames at 120 fps, 96 channels).
const Clip& Cmu() {
  static const Clip clip = *ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  return clip;
}

struct Case {
  std::string name;
  TimeWarpSpec warp;
  RetimeOptions options;
};

std::vector<Case> Cases() {
  auto speed = [](const char* text) { return *ParseSpeedKnots(text); };
  std::vector<Case> cases;
  cases.push_back({"identity", {}, {}});
  cases.push_back({"ramp", {.domain = WarpDomain::kSpeedOverSource, .speed = speed("0s:1,2s:0.25,4s:2")}, {}});
  cases.push_back({"step and hold",
                   {.domain = WarpDomain::kSpeedOverSource, .speed = speed("0s:1,3s:1,3s:3,5s:0.5"),
                    .holds = {{.at = {.value = 1.0}, .duration_seconds = 0.5}}},
                   {}});
  cases.push_back({"output domain at 30 fps",
                   {.domain = WarpDomain::kSpeedOverOutput, .speed = speed("0s:1,2s:0.5,6s:1.5")},
                   {.output_rate = FrameRate{.numerator = 30, .denominator = 1}}});
  cases.push_back({"reverse without grid",
                   {.domain = WarpDomain::kSpeedOverSource, .speed = speed("0s:2,8s:0.5"), .reverse = true},
                   {.fit_to_grid = false, .filter = ResampleFilter::kLanczos3}});
  cases.push_back({"fit frames", {.domain = WarpDomain::kSpeedOverSource, .speed = speed("0s:1,4s:3")},
                   {.fit_frames = 500}});
  cases.push_back({"paper method", {.domain = WarpDomain::kSpeedOverSource, .speed = speed("0s:1,2s:1,3s:2,5s:0.5")},
                   {.method = RetimeMethod::kPaper}});
  return cases;
}

TEST(PlanRetimeTest, ReportAndSourcePositionsAreWhatRetimeUses) {
  for (const Case& c : Cases()) {
    SCOPED_TRACE(c.name);
    const absl::StatusOr<RetimeResult> retimed = Retime(Cmu(), c.warp, c.options);
    ASSERT_TRUE(retimed.ok()) << retimed.status();

    const absl::StatusOr<RetimePlan> plan = PlanRetime(Cmu(), c.warp, c.options);

    ASSERT_TRUE(plan.ok()) << plan.status();
    EXPECT_EQ(plan->report.output_duration_seconds, retimed->report.output_duration_seconds);
    EXPECT_EQ(plan->report.output_frame_count, retimed->report.output_frame_count);
    EXPECT_EQ(plan->report.fit_factor, retimed->report.fit_factor);
    EXPECT_EQ(plan->report.max_decimation_ratio, retimed->report.max_decimation_ratio);
    EXPECT_EQ(plan->report.filtered_sample_count, retimed->report.filtered_sample_count);
    EXPECT_EQ(plan->output_frame_time_seconds, retimed->clip.frame_time_seconds);
    EXPECT_EQ(static_cast<std::int64_t>(plan->source_frames.size()), retimed->clip.frame_count);
    EXPECT_EQ(plan->decimation_ratios.size(), plan->source_frames.size());
  }
}

TEST(PlanRetimeTest, MapMatchesTheTimeMapAndTheClosedFormRamp) {
  // 0.5 -> 2 over the first second, then flat at 2 (SPEC 3.4: the ramp lasts 0.924196 s).
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverSource, .speed = *ParseSpeedKnots("0s:0.5,1s:2")};
  const RetimeOptions options = {.fit_to_grid = false};
  const absl::StatusOr<TimeMap> map = TimeMap::Compile(Cmu().frame_time_seconds, Cmu().frame_count, warp, options);
  ASSERT_TRUE(map.ok());

  const absl::StatusOr<RetimePlan> plan = PlanRetime(Cmu(), warp, options);

  ASSERT_TRUE(plan.ok()) << plan.status();
  ASSERT_EQ(plan->knot_output_seconds.size(), 2u);
  EXPECT_EQ(plan->knot_output_seconds[0], 0.0);
  const double ramp = 1.0 * std::log(2.0 / 0.5) / (2.0 - 0.5);  // h / logmean(v0, v1)
  EXPECT_NEAR(plan->knot_output_seconds[1], ramp, 1e-12);
  EXPECT_NEAR(ramp, 0.924196, 1e-6);
  for (std::size_t j = 0; j < plan->source_frames.size(); j += 37) {
    EXPECT_EQ(plan->source_frames[j], map->SourceFrame(static_cast<double>(j)));
  }
  EXPECT_TRUE(plan->knot_source_seconds.empty());
}

TEST(PlanRetimeTest, OutputDomainKnotsGetTheirSourceTimes) {
  // Speed over output time 1 for 2 s, then 0.5: at output 2 s the source is at 2 s.
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverOutput, .speed = *ParseSpeedKnots("0s:1,2s:1,2s:0.5")};

  const absl::StatusOr<RetimePlan> plan = PlanRetime(Cmu(), warp, {.fit_to_grid = false});

  ASSERT_TRUE(plan.ok()) << plan.status();
  ASSERT_EQ(plan->knot_source_seconds.size(), 3u);
  EXPECT_NEAR(plan->knot_source_seconds[1], 2.0, 1e-12);
  EXPECT_TRUE(plan->knot_output_seconds.empty());
}

TEST(PlanRetimeTest, RefusesWhatRetimeRefusesWithTheSameMessage) {
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverSource, .speed = *ParseSpeedKnots("0s:1,2s:-1")};

  const absl::StatusOr<RetimePlan> plan = PlanRetime(Cmu(), warp, {});
  const absl::StatusOr<RetimeResult> retimed = Retime(Cmu(), warp, {});

  ASSERT_FALSE(plan.ok());
  EXPECT_EQ(plan.status(), retimed.status());
  EXPECT_EQ(plan.status().message(), "speed knot 2 (2s:-1): speed must be > 0");
}

TEST(PlanRetimeTest, HoldsItsOutputToTheLimits) {
  const TimeWarpSpec warp = {.domain = WarpDomain::kSpeedOverSource, .speed = *ParseSpeedKnots("0s:0.01")};

  const absl::StatusOr<RetimePlan> plan = PlanRetime(Cmu(), warp, {}, {.max_frames = 50000});

  ASSERT_FALSE(plan.ok());
  EXPECT_EQ(plan.status().message(),
            "the retimed clip would have 99301 frames, over the limit of 50000 frames");
}

TEST(FormatSpeedKnotsTest, WritesTheCliSyntaxWithShortestNumbers) {
  const std::vector<SpeedKnot> knots = {{.time = {.value = 0.0}, .speed = 1.0},
                                        {.time = {.value = 2.5}, .speed = 0.5},
                                        {.time = {.value = 75.0, .in_frames = true}, .speed = 0.1},
                                        {.time = {.value = 1e-7}, .speed = 100.0}};

  EXPECT_EQ(FormatSpeedKnots(knots), "0s:1,2.5s:0.5,75f:0.1,1e-07s:100");
  EXPECT_EQ(FormatSpeedKnots({}), "");
}

TEST(FormatSpeedKnotsTest, ParseReadsBackEveryKnotBitForBit) {
  std::mt19937_64 random(20261124);
  std::uniform_real_distribution<double> time(-10.0, 1e4);
  std::uniform_real_distribution<double> exponent(-6.0, 2.0);
  for (int round = 0; round < 200; ++round) {
    std::vector<SpeedKnot> knots;
    for (int k = 0; k < 1 + round % 9; ++k) {
      knots.push_back({.time = {.value = time(random), .in_frames = (random() & 1) != 0},
                       .speed = std::pow(10.0, exponent(random))});
    }

    const absl::StatusOr<std::vector<SpeedKnot>> back = ParseSpeedKnots(FormatSpeedKnots(knots));

    ASSERT_TRUE(back.ok()) << back.status();
    ASSERT_EQ(back->size(), knots.size());
    for (std::size_t k = 0; k < knots.size(); ++k) {
      EXPECT_EQ((*back)[k].time.value, knots[k].time.value);
      EXPECT_EQ((*back)[k].time.in_frames, knots[k].time.in_frames);
      EXPECT_EQ((*back)[k].speed, knots[k].speed);
    }
  }
}

}  // namespace
}  // namespace tempokey::core
