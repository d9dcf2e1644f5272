#include "client/clip_summary.h"

#include <string>
#include <utility>
#include <vector>

#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

TEST(FormatFrameRateTest, SnapsToCommonRatesForDisplayOnly) {
  EXPECT_EQ(FormatFrameRate(0.0083333), "120 fps (0.0083333 s)");
  EXPECT_EQ(FormatFrameRate(0.0333333), "30 fps (0.0333333 s)");
  EXPECT_EQ(FormatFrameRate(1001.0 / 30000.0), "29.97 fps (0.03336666666666667 s)");
  EXPECT_EQ(FormatFrameRate(0.041708), "23.976 fps (0.041708 s)");
  EXPECT_EQ(FormatFrameRate(0.04), "25 fps (0.04 s)");
}

TEST(FormatFrameRateTest, ShowsUncommonRatesWithSixDigits) {
  EXPECT_EQ(FormatFrameRate(0.0123), "81.3008 fps (0.0123 s)");
  // 1e-3 off 30 fps is not 30 fps.
  EXPECT_EQ(FormatFrameRate(1.0 / 30.03), "30.03 fps (0.0333000333000333 s)");
}

core::Channel MakeChannel(int joint, core::ChannelKind kind, std::vector<double> samples = {}) {
  core::Channel channel;
  channel.joint = joint;
  channel.kind = kind;
  channel.samples = std::move(samples);
  return channel;
}

core::Clip TwoJointClip() {
  core::Clip clip;
  clip.name = "two";
  clip.frame_time_seconds = 0.5;
  clip.frame_count = 3;
  clip.skeleton.joints = {
      core::Joint{.name = "Hips", .parent = -1, .offset = {}, .channels = {0, 1, 2, 3}, .end_sites = {}},
      core::Joint{.name = "Knee", .parent = 0, .offset = {}, .channels = {4, 5}, .end_sites = {}},
  };
  using core::ChannelKind;
  for (auto [joint, kind] : {std::pair{0, ChannelKind::kXPosition}, {0, ChannelKind::kZRotation},
                             {0, ChannelKind::kXRotation}, {0, ChannelKind::kYRotation},
                             {1, ChannelKind::kXRotation}, {1, ChannelKind::kYRotation}}) {
    clip.channels.push_back(MakeChannel(joint, kind, {0, 0, 0}));
  }
  return clip;
}

TEST(FormatClipSummaryTest, CountsChannelsAndRotationOrders) {
  const core::Clip clip = TwoJointClip();

  EXPECT_EQ(FormatClipSummary(clip),
            "name:            two\n"
            "frames:          3\n"
            "rate:            2 fps (0.5 s)\n"
            "duration:        1.000 s\n"
            "joints:          2\n"
            "channels:        6 (1 position, 5 rotation)\n"
            "rotation orders: ZXY (1 joint), XY (1 joint)\n");
}

TEST(FormatRotationOrdersTest, ListsTheMostCommonOrderFirst) {
  core::Clip clip = TwoJointClip();
  clip.skeleton.joints.push_back(
      core::Joint{.name = "Foot", .parent = 1, .offset = {}, .channels = {6, 7}, .end_sites = {}});
  clip.channels.push_back(MakeChannel(2, core::ChannelKind::kXRotation));
  clip.channels.push_back(MakeChannel(2, core::ChannelKind::kYRotation));

  EXPECT_EQ(FormatRotationOrders(clip), "XY (2 joints), ZXY (1 joint)");
}

TEST(FormatRotationOrdersTest, SaysNoneWithoutRotations) {
  core::Clip clip;
  clip.channels.push_back(MakeChannel(-1, core::ChannelKind::kScalar));

  EXPECT_EQ(FormatRotationOrders(clip), "none");
}

TEST(FormatReductionReportTest, NamesTheWorstChannelAndFrame) {
  const core::Clip clip = TwoJointClip();
  core::ReductionReport report;
  report.key_count = 30;
  report.sample_count = 1200;
  report.rms_error = 0.12345;
  report.max_error = 0.5;
  report.worst_channel_index = 4;
  report.worst_frame = 17;

  EXPECT_EQ(FormatReductionReport(report, clip),
            "keys:            30 of 1200 samples (2.50%)\n"
            "rms error:       0.1235\n"
            "max error:       0.5000\n"
            "worst:           channel 4 (Knee.Xrotation) at frame 17\n");
}

// A figure of height 0 (every point at one height at the first frame) has no share of a height to
// give: the distances stand alone, where they read "0.000% of height".
TEST(FormatWorldErrorReportTest, GivesShareOfTheHeightOnlyForAFigureThatHasOne) {
  core::WorldErrorReport world;
  world.figure_height = 200.0;
  world.max_error = 1.0;
  world.rms_error = 0.5;
  world.joint_tolerance = 2.0;
  world.worst_point_name = "Hand_L";
  world.worst_frame = 7;
  core::WorldErrorReport flat = world;
  flat.figure_height = 0.0;

  const std::string tall = FormatWorldErrorReport(world);
  const std::string none = FormatWorldErrorReport(flat);

  EXPECT_NE(tall.find("1.0000 (0.500% of height) at Hand_L, frame 7\n"), std::string::npos) << tall;
  EXPECT_NE(tall.find("2 (1.000% of height)\n"), std::string::npos) << tall;
  EXPECT_EQ(none.find("% of height"), std::string::npos) << none;
  EXPECT_NE(none.find("1.0000 at Hand_L, frame 7\n"), std::string::npos) << none;
  EXPECT_NE(none.find("0.5000\n"), std::string::npos) << none;
}

TEST(FormatRetimeReportTest, ListsTheReport) {
  core::RetimeReport report{.output_duration_seconds = 10.5,
                            .output_frame_count = 1261,
                            .fit_factor = 1.00002,
                            .max_decimation_ratio = 2,
                            .filtered_sample_count = 240};

  EXPECT_EQ(FormatRetimeReport(report),
            "output frames:   1261\n"
            "output duration: 10.500 s\n"
            "fit factor:      1.000020\n"
            "max decimation:  2.000\n"
            "filtered samples: 240\n");
}

}  // namespace
}  // namespace tempokey::client
