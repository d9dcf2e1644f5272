// ValidateClip / ValidateClipLayout: every invariant of SPEC 1 with its exact message.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "absl/strings/str_cat.h"
#include "gtest/gtest.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::core {
namespace {

// Hips (root) with Xrotation and Yrotation, Spine (child of Hips) with Xrotation; 3 frames.
Clip ValidClip() {
  Clip clip;
  clip.name = "walk";
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = 3;
  clip.skeleton.joints = {
      Joint{"Hips", -1, {0, 1, 0}, {0, 1}, {}},
      Joint{"Spine", 0, {0, 2, 0}, {2}, {{0, 1, 0}}},
  };
  clip.channels = {
      Channel{0, ChannelKind::kXRotation, "", {1, 2, 3}},
      Channel{0, ChannelKind::kYRotation, "", {4, 5, 6}},
      Channel{1, ChannelKind::kXRotation, "", {7, 8, 9}},
  };
  return clip;
}

std::string ValidateMessage(const Clip& clip, const ClipLimits& limits = {},
                            absl::StatusCode code = absl::StatusCode::kInvalidArgument) {
  const absl::Status status = ValidateClip(clip, limits);
  if (status.ok()) return "ok";
  EXPECT_EQ(status.code(), code) << status;
  return std::string(status.message());
}

// A size over a server limit is RESOURCE_EXHAUSTED (README "Status codes"), not a malformed clip.
std::string OverLimitMessage(const Clip& clip, const ClipLimits& limits) {
  return ValidateMessage(clip, limits, absl::StatusCode::kResourceExhausted);
}

// Every position of arrays long enough for several scan blocks and a tail, each bad kind of
// value, and the bound itself (within) against the next double (beyond).
TEST(FirstSampleOutOfRangeTest, FindsTheFirstBadSampleWhereverItIs) {
  const double beyond = std::nextafter(kMaxSampleMagnitude, 2 * kMaxSampleMagnitude);
  const double bad_values[] = {std::numeric_limits<double>::quiet_NaN(),
                               std::numeric_limits<double>::infinity(),
                               -std::numeric_limits<double>::infinity(), beyond, -beyond};
  for (std::size_t size : {0u, 1u, 3u, 37u, 131u}) {
    std::vector<double> samples(size);
    for (std::size_t i = 0; i < size; ++i) {
      samples[i] = i % 2 == 0 ? kMaxSampleMagnitude : -kMaxSampleMagnitude;
    }
    EXPECT_EQ(FirstSampleOutOfRange(samples), size) << size;
    for (std::size_t at = 0; at < size; ++at) {
      for (double bad : bad_values) {
        std::vector<double> copy = samples;
        copy[at] = bad;
        if (at + 1 < size) copy[size - 1] = bad;  // a later one does not hide the first
        EXPECT_EQ(FirstSampleOutOfRange(copy), at) << "size " << size << " value " << bad;
      }
    }
  }
}

TEST(ValidateClipTest, AcceptsValidClip) {
  const Clip clip = ValidClip();

  EXPECT_EQ(ValidateMessage(clip), "ok");
}

TEST(ValidateClipTest, NanSampleNamesChannelLabelAndSampleIndex) {
  Clip clip = ValidClip();
  clip.channels[1].samples[2] = std::numeric_limits<double>::quiet_NaN();

  EXPECT_EQ(ValidateMessage(clip), "channel 1 (Hips.Yrotation): sample 2 is NaN");
}

TEST(ValidateClipTest, InfiniteSamplesSayWhichInfinity) {
  Clip clip = ValidClip();
  clip.channels[2].samples[0] = -std::numeric_limits<double>::infinity();

  EXPECT_EQ(ValidateMessage(clip), "channel 2 (Spine.Xrotation): sample 0 is -infinity");
}

TEST(ValidateClipTest, SampleCountMustMatchFrameCount) {
  Clip clip = ValidClip();
  clip.channels[1].samples.pop_back();

  EXPECT_EQ(ValidateMessage(clip),
            "channel 1 (Hips.Yrotation): has 2 samples, the clip has 3 frames");
}

TEST(ValidateClipTest, ScalarChannelIsLabelledByItsName) {
  Clip clip = ValidClip();
  clip.channels.push_back(Channel{-1, ChannelKind::kScalar, "weight", {0, 0}});

  EXPECT_EQ(ValidateMessage(clip), "channel 3 (weight): has 2 samples, the clip has 3 frames");
}

TEST(ValidateClipTest, FrameTimeMustLieBetweenAMicrosecondAndAnHour) {
  auto with_frame_time = [](double seconds) {
    Clip clip = ValidClip();
    clip.frame_time_seconds = seconds;
    return ValidateMessage(clip);
  };

  EXPECT_EQ(with_frame_time(0.0), "frame time must be in [1e-06, 3600] seconds, got 0");
  EXPECT_EQ(with_frame_time(-0.5), "frame time must be in [1e-06, 3600] seconds, got -0.5");
  EXPECT_EQ(with_frame_time(std::nan("")), "frame time must be in [1e-06, 3600] seconds, got NaN");
  // Subnormal and huge frame times: accepted once, they made reductions return infinite
  // tangents and key times.
  EXPECT_EQ(with_frame_time(1e-320),
            "frame time must be in [1e-06, 3600] seconds, got 9.99989e-321");
  EXPECT_EQ(with_frame_time(1e308), "frame time must be in [1e-06, 3600] seconds, got 1e+308");
  EXPECT_EQ(with_frame_time(9.9e-7), "frame time must be in [1e-06, 3600] seconds, got 9.9e-07");
  EXPECT_EQ(with_frame_time(1e-6), "ok");
  EXPECT_EQ(with_frame_time(3600.0), "ok");
}

TEST(ValidateClipTest, SamplesAndOffsetsMustStayWithinABillion) {
  Clip sample = ValidClip();
  sample.channels[0].samples[1] = 1.5e9;
  Clip offset = ValidClip();
  offset.skeleton.joints[0].offset[2] = -2e9;
  Clip edge = ValidClip();
  edge.channels[0].samples[0] = -1e9;

  EXPECT_THAT(ValidateMessage(sample),
              ::testing::EndsWith(": sample 1 is 1.5e+09, beyond the +-1e+09 a clip may hold"));
  EXPECT_THAT(ValidateMessage(offset),
              ::testing::EndsWith("offset -2e+09 is beyond the +-1e+09 a clip may hold"));
  EXPECT_EQ(ValidateMessage(edge), "ok");
}

TEST(ValidateClipTest, EmptyClipIsRefused) {
  Clip no_frames = ValidClip();
  no_frames.frame_count = 0;
  Clip no_channels;
  no_channels.frame_count = 1;

  EXPECT_EQ(ValidateMessage(no_frames), "a clip needs at least 1 frame, got 0");
  EXPECT_EQ(ValidateMessage(no_channels), "clip has no channels");
}

TEST(ValidateClipTest, LimitsOnFramesChannelsSamplesAndJoints) {
  ClipLimits frames;
  frames.max_frames = 2;
  ClipLimits channels;
  channels.max_channels = 2;
  ClipLimits samples;
  samples.max_samples = 8;
  ClipLimits joints;
  joints.max_joints = 1;
  ClipLimits depth;
  depth.max_depth = 1;
  const Clip clip = ValidClip();

  EXPECT_EQ(OverLimitMessage(clip, frames), "clip has 3 frames, over the limit of 2");
  EXPECT_EQ(OverLimitMessage(clip, channels), "clip has 3 channels, over the limit of 2");
  EXPECT_EQ(OverLimitMessage(clip, samples),
            "clip has 3 frames x 3 channels, over the limit of 8 samples");
  EXPECT_EQ(OverLimitMessage(clip, joints), "skeleton has 2 joints, over the limit of 1");
  EXPECT_EQ(ValidateMessage(clip, depth), "joint 1 (Spine): nesting deeper than 1");
}

// End sites carry no samples but forward kinematics places each at every frame: a few channels
// with thousands of end sites passed the sample limit and cost gigabytes in a reduction's world
// error. Joints and end sites times frames stay within the sample limit too.
TEST(ValidateClipTest, JointsAndEndSitesTimesFramesStayWithinTheSampleLimit) {
  Clip clip = ValidClip();  // 2 joints, 1 end site, 3 frames: 9 positions, 9 samples
  ClipLimits nine;
  nine.max_samples = 9;
  EXPECT_EQ(ValidateMessage(clip, nine), "ok");

  clip.skeleton.joints[1].end_sites.push_back({0, 2, 0});  // 4 points x 3 frames = 12

  EXPECT_EQ(OverLimitMessage(clip, nine),
            "skeleton has 4 joints and end sites x 3 frames, over the limit of 9 positions (as "
            "many as the sample limit: each is placed at every frame)");
  EXPECT_EQ(ValidateMessage(clip), "ok");
}

TEST(ValidateClipTest, ParentMustBeAnEarlierJoint) {
  Clip self_parent = ValidClip();
  self_parent.skeleton.joints[1].parent = 1;
  Clip below_minus_one = ValidClip();
  below_minus_one.skeleton.joints[0].parent = -2;

  EXPECT_EQ(ValidateMessage(self_parent),
            "joint 1 (Spine): parent index 1 must be -1 or an earlier joint");
  EXPECT_EQ(ValidateMessage(below_minus_one),
            "joint 0 (Hips): parent index -2 must be -1 or an earlier joint");
}

TEST(ValidateClipTest, JointNamesMustBeUniqueAndNonEmpty) {
  Clip duplicate = ValidClip();
  duplicate.skeleton.joints[1].name = "Hips";
  Clip unnamed = ValidClip();
  unnamed.skeleton.joints[1].name = "";

  EXPECT_EQ(ValidateMessage(duplicate), "joint 1: duplicate joint name \"Hips\"");
  EXPECT_EQ(ValidateMessage(unnamed), "joint 1 has no name");
}

TEST(ValidateClipTest, OffsetsMustBeFinite) {
  Clip offset = ValidClip();
  offset.skeleton.joints[0].offset[1] = std::nan("");
  Clip end_site = ValidClip();
  end_site.skeleton.joints[1].end_sites[0][2] = std::numeric_limits<double>::infinity();

  EXPECT_EQ(ValidateMessage(offset), "joint 0 (Hips): offset is NaN");
  EXPECT_EQ(ValidateMessage(end_site), "joint 1 (Spine): end site offset is +infinity");
}

TEST(ValidateClipTest, JointChannelListsMatchTheChannels) {
  Clip out_of_range = ValidClip();
  out_of_range.skeleton.joints[0].channels.push_back(5);
  Clip foreign = ValidClip();
  foreign.skeleton.joints[0].channels.push_back(2);
  Clip missing = ValidClip();
  missing.skeleton.joints[0].channels = {0};
  Clip bad_joint = ValidClip();
  bad_joint.channels[2].joint = 7;

  EXPECT_EQ(ValidateMessage(out_of_range), "joint 0 (Hips): channel index 5 out of range");
  EXPECT_EQ(ValidateMessage(foreign),
            "joint 0 (Hips) lists channel 2 (Spine.Xrotation) which belongs to joint 1");
  EXPECT_EQ(ValidateMessage(missing),
            "channel 1 (Hips.Yrotation) is missing from the channel list of joint Hips");
  EXPECT_EQ(ValidateMessage(bad_joint),
            "joint 1 (Spine) lists channel 2 (channel 2) which belongs to joint 7");
}

TEST(ValidateClipTest, OneJointMayListEveryChannelOfTheClipAsScalars) {
  // 100 000 scalar channels (the channel limit) on one joint: valid; the one left out of its
  // list is named. (Each channel's membership is a lookup: this once searched the joint's list
  // once per channel, about a second here.)
  Clip clip;
  clip.frame_count = 1;
  Joint props;
  props.name = "Props";
  clip.skeleton.joints.push_back(props);
  for (int c = 0; c < 100'000; ++c) {
    clip.channels.push_back({.joint = 0, .kind = ChannelKind::kScalar,
                             .name = absl::StrCat("attribute", c), .samples = {0.0}});
    clip.skeleton.joints[0].channels.push_back(c);
  }
  Clip missing = clip;
  missing.skeleton.joints[0].channels.pop_back();

  EXPECT_TRUE(ValidateClip(clip).ok()) << ValidateClip(clip);
  EXPECT_EQ(ValidateMessage(missing),
            "channel 99999 (attribute99999) is missing from the channel list of joint Props");
}

TEST(ValidateClipTest, RotationAxisMayAppearOnlyOncePerJoint) {
  Clip clip = ValidClip();
  clip.channels[1].kind = ChannelKind::kXRotation;

  EXPECT_EQ(ValidateMessage(clip), "joint 0 (Hips): channel Xrotation appears twice");
}

TEST(ValidateClipTest, PositionAndRotationOnOneAxisMayCoexist) {
  Clip clip = ValidClip();
  clip.channels[1].kind = ChannelKind::kXPosition;

  EXPECT_EQ(ValidateMessage(clip), "ok");
}

TEST(ValidateClipTest, MarkerTimesMustBeFinite) {
  Clip nan = ValidClip();
  nan.markers = {Marker{"start", 0.0, 0.0}, Marker{"step", 0.5, 0.0},
                 Marker{"contact", std::nan(""), 0.0}};
  Clip infinite = ValidClip();
  infinite.markers = {Marker{"end", -std::numeric_limits<double>::infinity(), 0.0}};

  Clip huge = ValidClip();
  huge.markers = {Marker{"far", 2e11, 0.0}};

  EXPECT_EQ(ValidateMessage(nan),
            "marker 2 (\"contact\"): time_seconds must be in [-1e+11, 1e+11], got NaN");
  EXPECT_EQ(ValidateMessage(infinite),
            "marker 0 (\"end\"): time_seconds must be in [-1e+11, 1e+11], got -infinity");
  EXPECT_EQ(ValidateMessage(huge),
            "marker 0 (\"far\"): time_seconds must be in [-1e+11, 1e+11], got 2e+11");
}

TEST(ValidateClipTest, MarkerDurationsMustBeFiniteAndNotNegative) {
  Clip negative = ValidClip();
  negative.markers = {Marker{"contact", 0.5, -0.25}};
  Clip nan = ValidClip();
  nan.markers = {Marker{"contact", 0.5, std::nan("")}};
  Clip infinite = ValidClip();
  infinite.markers = {Marker{"contact", 0.5, std::numeric_limits<double>::infinity()}};
  Clip fine = ValidClip();
  fine.markers = {Marker{"contact", -1.0, 0.0}, Marker{"hold", 0.5, 2.0}};

  EXPECT_EQ(ValidateMessage(negative),
            "marker 0 (\"contact\"): duration_seconds must be in [0, 1e+11], got -0.25");
  EXPECT_EQ(ValidateMessage(nan),
            "marker 0 (\"contact\"): duration_seconds must be in [0, 1e+11], got NaN");
  EXPECT_EQ(ValidateMessage(infinite),
            "marker 0 (\"contact\"): duration_seconds must be in [0, 1e+11], got +infinity");
  EXPECT_EQ(ValidateMessage(fine), "ok");
}

TEST(ValidateClipLayoutTest, ChecksMarkers) {
  Clip header = ValidClip();
  for (Channel& channel : header.channels) channel.samples.clear();
  header.markers = {Marker{"contact", std::nan(""), 0.0}};

  const absl::Status status = ValidateClipLayout(header);

  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(status.message()),
            "marker 0 (\"contact\"): time_seconds must be in [-1e+11, 1e+11], got NaN");
}

TEST(ValidateClipLayoutTest, IgnoresSamplesButChecksEverythingElse) {
  Clip header = ValidClip();
  for (Channel& channel : header.channels) channel.samples.clear();
  Clip bad_header = header;
  bad_header.skeleton.joints[1].parent = 3;

  EXPECT_TRUE(ValidateClipLayout(header).ok());
  EXPECT_EQ(ValidateMessage(header),
            "channel 0 (Hips.Xrotation): has 0 samples, the clip has 3 frames");
  EXPECT_EQ(std::string(ValidateClipLayout(bad_header).message()),
            "joint 1 (Spine): parent index 3 must be -1 or an earlier joint");
}

TEST(ClipTest, ChannelNamesAndLabels) {
  Clip clip = ValidClip();
  clip.channels.push_back(Channel{-1, ChannelKind::kScalar, "weight", {}});
  clip.channels.push_back(Channel{-1, ChannelKind::kScalar, "", {}});

  EXPECT_EQ(ChannelName(clip, 2), "Spine.Xrotation");
  EXPECT_EQ(ChannelName(clip, 3), "weight");
  EXPECT_EQ(ChannelName(clip, 4), "channel 4");
  EXPECT_EQ(ChannelName(clip, 9), "channel 9");
  EXPECT_EQ(ChannelLabel(clip, 1), "channel 1 (Hips.Yrotation)");
}

TEST(ClipTest, ChannelKindNamesRoundTrip) {
  for (ChannelKind kind : {ChannelKind::kXPosition, ChannelKind::kYPosition,
                           ChannelKind::kZPosition, ChannelKind::kXRotation,
                           ChannelKind::kYRotation, ChannelKind::kZRotation}) {
    EXPECT_EQ(ParseChannelKind(ChannelKindName(kind)), kind);
  }
  EXPECT_EQ(ParseChannelKind("xrotation"), std::nullopt);  // BVH spelling is case-sensitive
  EXPECT_EQ(ParseChannelKind("scalar"), std::nullopt);
  EXPECT_EQ(Axis(ChannelKind::kYRotation), 1);
  EXPECT_EQ(Axis(ChannelKind::kScalar), -1);
  EXPECT_TRUE(IsRotation(ChannelKind::kZRotation));
  EXPECT_FALSE(IsRotation(ChannelKind::kZPosition));
  EXPECT_TRUE(IsPosition(ChannelKind::kXPosition));
}

TEST(ClipTest, DurationCountsIntervalsNotFrames) {
  Clip clip = ValidClip();
  clip.frame_time_seconds = 0.25;

  EXPECT_EQ(clip.duration_seconds(), 0.5);  // 3 frames span 2 intervals
  EXPECT_EQ(clip.sample_count(), 9);
  EXPECT_EQ(clip.frame_rate(), 4.0);
}

}  // namespace
}  // namespace tempokey::core
