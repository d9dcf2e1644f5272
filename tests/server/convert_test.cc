// Wire conversions (proto/convert.h): exact round trips, slicing, and the assembler's precise
// refusal of malformed clips.
#include "proto/convert.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/server/server_test_util.h"

namespace tempokey::wire {
namespace {

using ::tempokey::testing::MakeClip;
using ::tempokey::testing::StatusIs;
using ::testing::HasSubstr;

core::Clip ClipWithExtras() {
  core::Clip clip = MakeClip(3, 40);
  clip.name = "extras";
  clip.skeleton.joints[2].end_sites.push_back({0.5, -1.25, 3.0});
  clip.markers.push_back(core::Marker{.name = "contact", .time_seconds = 0.1, .duration_seconds = 0.05});
  core::Channel scalar;
  scalar.kind = core::ChannelKind::kScalar;
  scalar.name = "blend";
  scalar.samples.assign(40, 0.25);
  clip.channels.push_back(scalar);
  return clip;
}

std::vector<v1::ChannelSamples> Slices(const core::Clip& clip, std::int64_t slice_bytes) {
  std::vector<v1::ChannelSamples> slices;
  EXPECT_TRUE(ForEachSamplesSlice(clip, slice_bytes, [&](v1::ChannelSamples&& s) {
                slices.push_back(std::move(s));
                return absl::OkStatus();
              }).ok());
  return slices;
}

TEST(ClipConvertTest, ClipRoundTripsExactly) {
  const core::Clip clip = ClipWithExtras();

  absl::StatusOr<core::Clip> back = ClipFromProto(ClipToProto(clip));

  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, clip);
}

TEST(ClipConvertTest, SlicesRespectSliceBytesAndReassembleInAnyOrder) {
  const core::Clip clip = MakeClip(4, 1000);  // 15 channels x 1000 frames
  constexpr std::int64_t kSliceBytes = 8 * 300;

  std::vector<v1::ChannelSamples> slices = Slices(clip, kSliceBytes);
  std::mt19937 rng(7);
  std::shuffle(slices.begin(), slices.end(), rng);
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());
  for (const v1::ChannelSamples& s : slices) {
    EXPECT_LE(s.samples_size(), 300);
    ASSERT_TRUE(assembler.AddSamples(s).ok());
  }
  absl::StatusOr<core::Clip> back = std::move(assembler).Finish();

  EXPECT_EQ(slices.size(), 15u * 4u);  // ceil(1000 / 300) = 4 per channel
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, clip);
}

TEST(ClipConvertTest, BatchesFillTheSliceBudgetAcrossChannelsAndReassembleInAnyOrder) {
  const core::Clip clip = MakeClip(4, 128);  // 15 channels x 128 frames = 1920 samples
  constexpr std::int64_t kSliceBytes = 8 * 500;

  std::vector<v1::SampleSlices> batches;
  ASSERT_TRUE(ForEachSamplesBatch(clip, kSliceBytes, [&](v1::SampleSlices&& batch) {
                batches.push_back(std::move(batch));
                return absl::OkStatus();
              }).ok());

  ASSERT_EQ(batches.size(), 4u);  // ceil(1920 / 500): 15 channels in 4 messages
  for (std::size_t b = 0; b < batches.size(); ++b) {
    std::int64_t samples = 0;
    for (const v1::ChannelSamples& slice : batches[b].slices()) samples += slice.samples_size();
    EXPECT_EQ(samples, b + 1 < batches.size() ? 500 : 1920 - 3 * 500) << "batch " << b;
  }
  std::mt19937 rng(11);
  std::shuffle(batches.begin(), batches.end(), rng);
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());
  for (const v1::SampleSlices& batch : batches) ASSERT_TRUE(assembler.AddSampleSlices(batch).ok());
  absl::StatusOr<core::Clip> back = std::move(assembler).Finish();
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, clip);
}

TEST(ClipConvertTest, ABadSliceInABatchIsNamedLikeASingleOne) {
  const core::Clip clip = MakeClip(1, 10);
  v1::SampleSlices batch;
  *batch.add_slices() = SamplesSliceToProto(clip, 0, 0, 10);
  v1::ChannelSamples* bad = batch.add_slices();
  *bad = SamplesSliceToProto(clip, 1, 0, 10);
  bad->set_samples(4, std::nan(""));
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());

  absl::Status status = assembler.AddSampleSlices(batch);

  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(status.message()),
              ::testing::HasSubstr("samples message 2: channel 1 ("));
  EXPECT_THAT(std::string(status.message()), ::testing::EndsWith("sample at frame 4 is NaN"));
}

TEST(ClipConvertTest, NonPositiveSliceBytesUsesTheDefault) {
  const core::Clip clip = MakeClip(1, 10);

  std::vector<v1::ChannelSamples> slices = Slices(clip, 0);

  ASSERT_EQ(slices.size(), clip.channels.size());
  EXPECT_EQ(slices[0].samples_size(), 10);
}

class AssemblerErrorTest : public ::testing::Test {
 protected:
  AssemblerErrorTest() : clip_(MakeClip(2, 100)) {}  // joint0: 6 channels, joint1: 3

  absl::Status AddAll(ClipAssembler& assembler, const std::vector<v1::ChannelSamples>& slices) {
    for (const v1::ChannelSamples& s : slices) {
      absl::Status status = assembler.AddSamples(s);
      if (!status.ok()) return status;
    }
    return absl::OkStatus();
  }

  core::Clip clip_;
};

TEST_F(AssemblerErrorTest, NanSampleNamesChannelAndFrame) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  v1::ChannelSamples s = SamplesSliceToProto(clip_, 4, 0, 100);
  s.set_samples(17, std::numeric_limits<double>::quiet_NaN());

  EXPECT_THAT(assembler.AddSamples(s),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "samples message 1: channel 4 (joint0.Xrotation): sample at frame 17 is NaN"));
}

TEST_F(AssemblerErrorTest, InfiniteSampleIsRefused) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  v1::ChannelSamples s = SamplesSliceToProto(clip_, 0, 10, 20);
  s.set_samples(3, -std::numeric_limits<double>::infinity());

  EXPECT_THAT(assembler.AddSamples(s),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("channel 0 (joint0.Xposition): sample at frame 13 is -infinity")));
}

TEST_F(AssemblerErrorTest, OverlapNamesBothRanges) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  ASSERT_TRUE(assembler.AddSamples(SamplesSliceToProto(clip_, 7, 0, 60)).ok());

  EXPECT_THAT(assembler.AddSamples(SamplesSliceToProto(clip_, 7, 50, 50)),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "samples message 2: channel 7 (joint1.Xrotation): frames 50..99 overlap "
                       "frames 50..59 already received"));
}

TEST_F(AssemblerErrorTest, OverlapWithALaterRangeIsFound) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  ASSERT_TRUE(assembler.AddSamples(SamplesSliceToProto(clip_, 1, 80, 20)).ok());
  ASSERT_TRUE(assembler.AddSamples(SamplesSliceToProto(clip_, 1, 0, 10)).ok());

  EXPECT_THAT(assembler.AddSamples(SamplesSliceToProto(clip_, 1, 10, 75)),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("frames 10..84 overlap frames 80..84 already received")));
}

TEST_F(AssemblerErrorTest, MissingFramesAreNamedAtFinish) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  std::vector<v1::ChannelSamples> slices = Slices(clip_, 8 * 50);
  slices.erase(slices.begin() + 7);  // channel 3, frames 50..99

  ASSERT_TRUE(AddAll(assembler, slices).ok());

  EXPECT_THAT(std::move(assembler).Finish(),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "channel 3 (joint0.Zrotation): frames 50..99 never arrived"));
}

TEST_F(AssemblerErrorTest, ChannelIndexOutOfRange) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  v1::ChannelSamples s = SamplesSliceToProto(clip_, 0, 0, 10);
  s.set_channel_index(99);

  EXPECT_THAT(assembler.AddSamples(s),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "samples message 1: channel index 99 out of range, the clip has 9 channels"));
}

TEST_F(AssemblerErrorTest, FramesPastTheEnd) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  v1::ChannelSamples s = SamplesSliceToProto(clip_, 2, 0, 20);
  s.set_first_frame(90);

  EXPECT_THAT(assembler.AddSamples(s),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("channel 2 (joint0.Zposition): frames 90..109 run past the last "
                                 "frame 99")));
}

TEST_F(AssemblerErrorTest, NegativeFirstFrame) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  v1::ChannelSamples s = SamplesSliceToProto(clip_, 2, 0, 20);
  s.set_first_frame(-5);

  EXPECT_THAT(assembler.AddSamples(s),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("first_frame -5 out of range, the clip has 100 frames (0..99)")));
}

TEST_F(AssemblerErrorTest, EmptySliceIsRefused) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  v1::ChannelSamples s;
  s.set_channel_index(1);

  EXPECT_THAT(assembler.AddSamples(s),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("carries no samples")));
}

TEST_F(AssemblerErrorTest, SamplesBeforeHeader) {
  ClipAssembler assembler;

  EXPECT_THAT(assembler.AddSamples(SamplesSliceToProto(clip_, 0, 0, 10)),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "samples message 1 arrived before the clip header"));
}

TEST_F(AssemblerErrorTest, SecondHeader) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());

  EXPECT_THAT(assembler.AddHeader(ClipHeaderToProto(clip_)),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("a second clip header")));
}

TEST_F(AssemblerErrorTest, HeaderOverTheSampleLimitIsRefusedBeforeAnyAllocation) {
  ClipAssembler assembler(core::ClipLimits{.max_samples = 500});
  v1::ClipHeader header = ClipHeaderToProto(clip_);  // 100 frames x 9 channels = 900

  EXPECT_THAT(assembler.AddHeader(header),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "clip header: clip has 100 frames x 9 channels, over the limit of 500 "
                       "samples"));
  EXPECT_FALSE(assembler.has_header());
}

TEST_F(AssemblerErrorTest, HugeDeclaredFrameCountIsRefused) {
  ClipAssembler assembler;
  v1::ClipHeader header = ClipHeaderToProto(clip_);
  header.set_frame_count(std::numeric_limits<std::int64_t>::max());

  EXPECT_THAT(assembler.AddHeader(header),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("over the limit")));
}

TEST_F(AssemblerErrorTest, UnspecifiedChannelKind) {
  ClipAssembler assembler;
  v1::ClipHeader header = ClipHeaderToProto(clip_);
  header.mutable_channels(3)->set_kind(v1::CHANNEL_KIND_UNSPECIFIED);

  EXPECT_THAT(assembler.AddHeader(header),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "clip header: header.channels[3]: kind is CHANNEL_KIND_UNSPECIFIED"));
}

TEST_F(AssemblerErrorTest, JointIndexOutOfRange) {
  v1::ClipHeader header = ClipHeaderToProto(clip_);
  header.mutable_channels(5)->set_joint_index(12);

  EXPECT_THAT(ClipLayoutFromProto(header),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "header.channels[5]: joint_index 12 out of range, the header has 2 joints"));
}

TEST_F(AssemblerErrorTest, NonPositiveFrameTime) {
  v1::ClipHeader header = ClipHeaderToProto(clip_);
  header.set_frame_time_seconds(0.0);

  EXPECT_THAT(ClipLayoutFromProto(header),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("frame time")));
}

TEST_F(AssemblerErrorTest, NanMarkerTime) {
  v1::ClipHeader header = ClipHeaderToProto(clip_);
  v1::Marker* marker = header.add_markers();
  marker->set_name("step");
  marker->set_time_seconds(std::nan(""));

  EXPECT_THAT(ClipLayoutFromProto(header),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "marker 0 (\"step\"): time_seconds is NaN"));
}

TEST(ClipConvertTest, ClipWithoutHeaderIsRefused) {
  EXPECT_THAT(ClipFromProto(v1::Clip()),
              StatusIs(absl::StatusCode::kInvalidArgument, "clip has no header"));
}

// ---- keyed clips --------------------------------------------------------------------------------

core::KeyedClip MakeKeyed(int keys_per_curve) {
  core::KeyedClip keyed;
  keyed.layout = MakeClip(1, 200);
  for (core::Channel& channel : keyed.layout.channels) channel.samples.clear();
  for (std::size_t c = 0; c < keyed.layout.channels.size(); ++c) {
    core::Curve curve;
    for (int k = 0; k < keys_per_curve; ++k) {
      core::Key key;
      key.time_seconds = 0.01 * k;
      key.value = static_cast<double>(c) + 0.5 * k;
      key.in_tangent = -1.0 * k;
      key.out_tangent = 2.0 * k;
      if (c == 1 && k % 2 == 0) {
        key.in_weight = 0.25;
        key.out_weight = 0.5;
      }
      curve.keys.push_back(key);
    }
    keyed.curves.push_back(std::move(curve));
  }
  return keyed;
}

TEST(KeyedConvertTest, UnweightedCurvesRoundTripExactly) {
  core::KeyedClip keyed = MakeKeyed(5);
  for (core::Key& key : keyed.curves[1].keys) key.in_weight = key.out_weight = std::nullopt;

  absl::StatusOr<core::KeyedClip> back = KeyedClipFromProto(KeyedClipToProto(keyed));

  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, keyed);
}

TEST(KeyedConvertTest, PartlyWeightedCurveFillsOneThird) {
  const core::KeyedClip keyed = MakeKeyed(4);

  v1::KeyedCurve curve = KeyedCurveToProto(1, keyed.curves[1]);

  ASSERT_EQ(curve.in_weight_size(), 4);
  EXPECT_EQ(curve.in_weight(0), 0.25);
  EXPECT_EQ(curve.in_weight(1), 1.0 / 3.0);
  EXPECT_EQ(curve.out_weight(2), 0.5);
  EXPECT_EQ(KeyedCurveToProto(0, keyed.curves[0]).in_weight_size(), 0);
}

TEST(KeyedConvertTest, PiecesOfACurveJoinInOrder) {
  core::KeyedClip keyed = MakeKeyed(100);
  for (core::Key& key : keyed.curves[1].keys) key.in_weight = key.out_weight = std::nullopt;
  v1::KeyedClip message;
  *message.mutable_header() = ClipHeaderToProto(keyed.layout);

  ASSERT_TRUE(ForEachKeyedCurveSlice(keyed, 32 * 7, [&](v1::KeyedCurve&& piece) {
                EXPECT_LE(piece.time_seconds_size(), 7);
                *message.add_curves() = std::move(piece);
                return absl::OkStatus();
              }).ok());
  absl::StatusOr<core::KeyedClip> back = KeyedClipFromProto(message);

  EXPECT_EQ(message.curves_size(), 6 * 15);  // ceil(100 / 7) pieces per channel
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, keyed);
}

TEST(KeyedConvertTest, ColumnLengthMismatchIsRefused) {
  v1::KeyedClip message = KeyedClipToProto(MakeKeyed(3));
  message.mutable_curves(2)->mutable_value()->RemoveLast();

  EXPECT_THAT(KeyedClipFromProto(message),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("curve message 3: channel 2 (joint0.Zposition): columns differ in "
                                 "length: time_seconds 3, value 2")));
}

TEST(KeyedConvertTest, ChannelWithoutCurveIsRefused) {
  v1::KeyedClip message = KeyedClipToProto(MakeKeyed(3));
  message.mutable_curves()->RemoveLast();

  EXPECT_THAT(KeyedClipFromProto(message),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "channel 5 (joint0.Yrotation): no curve arrived"));
}

// ---- operations ---------------------------------------------------------------------------------

TEST(OperationConvertTest, UnsetOptionalFieldsTakeCoreDefaults) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  ops.Add()->mutable_reduce()->set_method(v1::REDUCE_METHOD_PAPER);

  absl::StatusOr<std::vector<core::PipelineStep>> steps = PipelineFromProto(ops);

  ASSERT_TRUE(steps.ok()) << steps.status();
  const auto& reduce = std::get<core::ReduceStep>((*steps)[0]);
  const core::PaperParams defaults;
  EXPECT_EQ(reduce.options.method, core::ReduceMethod::kPaper);
  EXPECT_EQ(reduce.options.paper.step_y, defaults.step_y);
  EXPECT_EQ(reduce.options.paper.max_iterations, defaults.max_iterations);
  EXPECT_EQ(reduce.options.tolerance.max_rotation_error_degrees,
            core::ToleranceParams().max_rotation_error_degrees);
}

TEST(OperationConvertTest, SetOptionalFieldsAreUsed) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  v1::ReduceOperation* reduce = ops.Add()->mutable_reduce();
  reduce->mutable_paper()->set_step_y(0.125);
  reduce->mutable_paper()->set_max_iterations(3);
  reduce->mutable_tolerance()->set_max_rotation_error_degrees(0.2);
  reduce->mutable_tolerance()->set_key_budget(40);
  reduce->mutable_tolerance()->set_pose_alignment(v1::POSE_ALIGNMENT_JOINT);

  absl::StatusOr<std::vector<core::PipelineStep>> steps = PipelineFromProto(ops);

  ASSERT_TRUE(steps.ok()) << steps.status();
  const auto& step = std::get<core::ReduceStep>((*steps)[0]);
  EXPECT_EQ(step.options.method, core::ReduceMethod::kTolerance);
  EXPECT_EQ(step.options.paper.step_y, 0.125);
  EXPECT_EQ(step.options.paper.max_iterations, 3);
  EXPECT_EQ(step.options.tolerance.max_rotation_error_degrees, 0.2);
  EXPECT_EQ(step.options.tolerance.key_budget, 40);
  EXPECT_EQ(step.options.tolerance.pose_alignment, core::PoseAlignment::kJoint);
}

struct BadOperationCase {
  const char* name;
  std::function<void(google::protobuf::RepeatedPtrField<v1::Operation>&)> build;
  const char* message;
};

class BadOperationTest : public ::testing::TestWithParam<BadOperationCase> {};

TEST_P(BadOperationTest, IsRefusedWithAMessageNamingTheField) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  ops.Add()->mutable_convert();
  GetParam().build(ops);

  EXPECT_THAT(PipelineFromProto(ops),
              StatusIs(absl::StatusCode::kInvalidArgument, GetParam().message));
}

INSTANTIATE_TEST_SUITE_P(
    Table, BadOperationTest,
    ::testing::Values(
        BadOperationCase{"UnknownReduceMethod",
                         [](auto& ops) {
                           ops.Add()->mutable_reduce()->set_method(static_cast<v1::ReduceMethod>(9));
                         },
                         "operation 2: reduce.method has unknown value 9"},
        BadOperationCase{"EmptyOperation", [](auto& ops) { ops.Add(); },
                         "operation 2: no operation set (one of retime, reduce, bake, convert)"},
        BadOperationCase{"TwoWarpDomains",
                         [](auto& ops) {
                           v1::RetimeOperation* r = ops.Add()->mutable_retime();
                           r->add_speed_over_source()->mutable_time()->set_seconds(0);
                           r->add_time_map()->mutable_output()->set_seconds(0);
                         },
                         "operation 2: retime takes at most one of speed_over_source, "
                         "speed_over_output and time_map, got speed_over_source and time_map"},
        BadOperationCase{"KnotWithoutUnit",
                         [](auto& ops) {
                           ops.Add()->mutable_retime()->add_speed_over_output()->set_speed(1.0);
                         },
                         "operation 2: retime.speed_over_output[0].time has no unit: set seconds "
                         "or frames"},
        BadOperationCase{"UnknownFilter",
                         [](auto& ops) {
                           ops.Add()->mutable_retime()->set_filter(static_cast<v1::ResampleFilter>(42));
                         },
                         "operation 2: retime.filter has unknown value 42"}),
    [](const ::testing::TestParamInfo<BadOperationCase>& p) { return p.param.name; });

// Values are core's to check (one set of limits and messages): the conversion hands them over
// untouched, and core::ValidatePipeline() refuses them naming the field.
TEST(OperationConvertTest, ValuesPassThroughForCoreToCheck) {
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  v1::ReduceOperation* reduce = ops.Add()->mutable_reduce();
  reduce->set_method(v1::REDUCE_METHOD_PAPER);
  reduce->mutable_paper()->set_step_y(-1);
  reduce->mutable_paper()->set_max_iterations(0);
  v1::RetimeOperation* retime = ops.Add()->mutable_retime();
  retime->set_output_rate_numerator(30);
  retime->set_fit_frames(0);
  v1::SpeedKnot* knot = retime->add_speed_over_source();
  knot->mutable_time()->set_frames(std::numeric_limits<double>::infinity());
  knot->set_speed(std::nan(""));
  core::Clip clip = MakeClip(1, 40);

  absl::StatusOr<std::vector<core::PipelineStep>> steps = PipelineFromProto(ops);

  ASSERT_TRUE(steps.ok()) << steps.status();
  const auto& paper = std::get<core::ReduceStep>((*steps)[0]).options.paper;
  EXPECT_EQ(paper.step_y, -1);
  EXPECT_EQ(paper.max_iterations, 0);
  const auto& r = std::get<core::RetimeStep>((*steps)[1]);
  ASSERT_TRUE(r.options.output_rate.has_value());
  EXPECT_EQ(r.options.output_rate->numerator, 30);
  EXPECT_EQ(r.options.output_rate->denominator, 0);
  EXPECT_EQ(r.options.fit_frames, 0);
  EXPECT_TRUE(std::isinf(r.warp.speed[0].time.value));
  EXPECT_TRUE(std::isnan(r.warp.speed[0].speed));
  EXPECT_THAT(core::ValidatePipeline(clip, *steps),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "operation 1 (reduce): paper.step_y must be > 0, got -1"));
}

TEST(OperationConvertTest, EveryStepRoundTripsThroughProto) {
  core::RetimeStep retime;
  retime.warp.domain = core::WarpDomain::kSpeedOverSource;
  retime.warp.speed = {core::SpeedKnot{.time = {.value = 0, .in_frames = false}, .speed = 1},
                       core::SpeedKnot{.time = {.value = 48, .in_frames = true}, .speed = 0.5}};
  retime.warp.holds = {core::Hold{.at = {.value = 0.5, .in_frames = false}, .duration_seconds = 0.25}};
  retime.warp.reverse = true;
  retime.options.fit_frames = 120;
  retime.options.fit_to_grid = false;
  retime.options.output_rate = core::FrameRate{.numerator = 30000, .denominator = 1001};
  retime.options.filter = core::ResampleFilter::kLanczos3;
  retime.options.method = core::RetimeMethod::kPaper;
  retime.options.rotation_mode = core::RotationMode::kEuler;
  retime.options.pins = {core::Pin{.source = {.value = 10, .in_frames = true}, .output_frame = 20}};
  retime.options.min_speed = 0.1;
  retime.options.max_speed = 10;
  core::ReduceStep reduce;
  reduce.options.tolerance.key_budget = 12;
  reduce.options.tolerance.max_scalar_error = 0.01;
  core::ReduceStep paper;
  paper.options.method = core::ReduceMethod::kPaper;
  paper.options.paper.accuracy = 0.001;
  const std::vector<core::PipelineStep> steps = {
      retime, reduce, paper, core::BakeStep{.rate = core::FrameRate{.numerator = 24, .denominator = 1}},
      core::BakeStep{}, core::ConvertStep{.wrap_rotations = true}};
  google::protobuf::RepeatedPtrField<v1::Operation> ops;
  for (const core::PipelineStep& step : steps) *ops.Add() = PipelineStepToProto(step);

  absl::StatusOr<std::vector<core::PipelineStep>> back = PipelineFromProto(ops);

  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->size(), steps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    EXPECT_EQ(PipelineStepToProto((*back)[i]).SerializeAsString(), ops[static_cast<int>(i)].SerializeAsString())
        << "step " << i;
  }
  const auto& r = std::get<core::RetimeStep>((*back)[0]);
  EXPECT_EQ(r.warp.domain, core::WarpDomain::kSpeedOverSource);
  EXPECT_TRUE(r.warp.speed[1].time.in_frames);
  EXPECT_EQ(r.options.output_rate->numerator, 30000);
  EXPECT_EQ(r.options.pins[0].output_frame, 20);
  EXPECT_EQ(std::get<core::ReduceStep>((*back)[1]).options.tolerance.key_budget, 12);
  EXPECT_EQ(std::get<core::ReduceStep>((*back)[2]).options.paper.accuracy, 0.001);
  EXPECT_FALSE(std::get<core::BakeStep>((*back)[4]).rate.has_value());
  EXPECT_TRUE(std::get<core::ConvertStep>((*back)[5]).wrap_rotations);
}

TEST(ReportConvertTest, ReportsRoundTrip) {
  core::ReductionReport reduction;
  reduction.channels.push_back(core::ChannelReduction{.channel_index = 3,
                                                      .key_count = 7,
                                                      .sample_count = 100,
                                                      .rms_error = 0.1,
                                                      .max_error = 0.4,
                                                      .max_error_frame = 55});
  reduction.key_count = 7;
  reduction.sample_count = 100;
  reduction.worst_channel_index = 3;
  reduction.worst_frame = 55;
  reduction.iterations = 4;
  const core::RetimeReport retime{.output_duration_seconds = 2.5,
                                  .output_frame_count = 76,
                                  .fit_factor = 1.001,
                                  .max_decimation_ratio = 2.0,
                                  .filtered_sample_count = 30};

  const core::StepReport a = StepReportFromProto(StepReportToProto(reduction));
  const core::StepReport b = StepReportFromProto(StepReportToProto(retime));

  const auto& ra = std::get<core::ReductionReport>(a);
  EXPECT_EQ(ra.channels[0].max_error_frame, 55);
  EXPECT_EQ(ra.iterations, 4);
  EXPECT_EQ(ra.worst_channel_index, 3);
  const auto& rb = std::get<core::RetimeReport>(b);
  EXPECT_EQ(rb.output_frame_count, 76);
  EXPECT_EQ(rb.fit_factor, 1.001);
}

}  // namespace
}  // namespace tempokey::wire
