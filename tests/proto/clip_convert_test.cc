// Clip conversions (proto/clip_convert.h): exact round trips, slicing, and the assembler's precise
// refusal of malformed clips.
#include "proto/clip_convert.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/scratch_arena.h"
#include "tempokey/v1/motion_service.pb.h"
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

TEST(ClipConvertTest, PiecesBuiltInAnArenaAreTheHeapOnesByteForByte) {
  const core::Clip clip = ClipWithExtras();
  core::Curve curve;
  for (int k = 0; k < 3; ++k) {
    core::Key& key = curve.keys.emplace_back();
    key.time_seconds = 0.5 * k;
    key.value = 1.0 - k;
    key.in_tangent = 0.25 * k;
    key.out_tangent = -0.25 * k;
  }
  curve.keys[1].in_weight = 0.25;  // a weighted curve: six columns
  google::protobuf::Arena arena;

  const v1::ClipHeader* header = ClipHeaderOnArena(clip, &arena);
  const v1::ChannelSamples* slice = SamplesSliceOnArena(clip, 2, 5, 30, &arena);
  const v1::KeyedCurve* piece = KeyedCurveSliceOnArena(4, curve, 1, 2, &arena);

  EXPECT_EQ(header->GetArena(), &arena);
  EXPECT_EQ(header->SerializeAsString(), ClipHeaderToProto(clip).SerializeAsString());
  EXPECT_EQ(slice->GetArena(), &arena);
  EXPECT_EQ(slice->SerializeAsString(), SamplesSliceToProto(clip, 2, 5, 30).SerializeAsString());
  EXPECT_EQ(piece->GetArena(), &arena);
  EXPECT_EQ(piece->SerializeAsString(), KeyedCurveSliceToProto(4, curve, 1, 2).SerializeAsString());
}

TEST(ClipConvertTest, BatchesBuiltInScratchArenasReassembleTheClip) {
  const core::Clip clip = MakeClip(4, 128);
  SamplesBatcher batches(clip, 8 * 500);
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());
  int count = 0;
  for (;;) {
    ScratchMessage<v1::ProcessRequest> request;
    if (!batches.Next(request->mutable_sample_slices())) break;
    ++count;
    // What a sender writes: the bytes, parsed again by protobuf.
    v1::ProcessRequest received;
    ASSERT_TRUE(received.ParseFromString(request->SerializeAsString()));
    ASSERT_TRUE(assembler.AddSampleSlices(received.sample_slices()).ok());
  }
  absl::StatusOr<core::Clip> back = std::move(assembler).Finish();

  EXPECT_EQ(count, 4);  // ceil(15 x 128 / 500), as ForEachSamplesBatch() cuts it
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

// A batch of no slices brings nothing, as an empty slice does: refused, so a stream of them
// cannot keep a Process call alive without ever completing its clip.
TEST(ClipConvertTest, ABatchOfNoSlicesIsRefused) {
  const core::Clip clip = MakeClip(1, 10);
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());

  absl::Status status = assembler.AddSampleSlices(v1::SampleSlices());

  EXPECT_EQ(status.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(), "samples message 1: carries no slices");
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

TEST_F(AssemblerErrorTest, SampleBeyondABillionIsRefused) {
  ClipAssembler assembler;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip_)).ok());
  v1::ChannelSamples near = SamplesSliceToProto(clip_, 1, 0, 20);
  near.set_samples(2, 1.07e9);  // under 2^30, so only the exact test catches it
  v1::ChannelSamples edge = SamplesSliceToProto(clip_, 2, 0, 20);
  edge.set_samples(5, -1e9);

  EXPECT_THAT(assembler.AddSamples(near),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       HasSubstr("sample at frame 2 is 1.07e+09, beyond the +-1e+09 a clip may "
                                 "hold")));
  EXPECT_TRUE(assembler.AddSamples(edge).ok());
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
              StatusIs(absl::StatusCode::kResourceExhausted,
                       "clip header: clip has 100 frames x 9 channels, over the limit of 500 "
                       "samples"));
  EXPECT_FALSE(assembler.has_header());
}

TEST_F(AssemblerErrorTest, HugeDeclaredFrameCountIsRefused) {
  ClipAssembler assembler;
  v1::ClipHeader header = ClipHeaderToProto(clip_);
  header.set_frame_count(std::numeric_limits<std::int64_t>::max());

  EXPECT_THAT(assembler.AddHeader(header),
              StatusIs(absl::StatusCode::kResourceExhausted, HasSubstr("over the limit")));
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
                       "marker 0 (\"step\"): time_seconds must be in [-1e+11, 1e+11], got NaN"));
}

TEST_F(AssemblerErrorTest, SubnormalFrameTime) {
  v1::ClipHeader header = ClipHeaderToProto(clip_);
  header.set_frame_time_seconds(1e-320);

  EXPECT_THAT(ClipLayoutFromProto(header),
              StatusIs(absl::StatusCode::kInvalidArgument,
                       "frame time must be in [1e-06, 3600] seconds, got 9.99989e-321"));
}

// ---- memory follows the data --------------------------------------------------------------------

// A header of `channels` rotation channels x `frames` frames (nothing else sent).
v1::ClipHeader DeclaredHeader(int channels, std::int64_t frames) {
  core::Clip layout = MakeClip(1, 1);
  layout.channels.resize(static_cast<std::size_t>(channels));
  layout.skeleton.joints[0].channels.resize(static_cast<std::size_t>(std::min(channels, 6)));
  v1::ClipHeader header = ClipHeaderToProto(layout);
  header.set_frame_count(frames);
  return header;
}

v1::ChannelSamples OneSample(int channel, std::int64_t frame, double value = 1.0) {
  v1::ChannelSamples slice;
  slice.set_channel_index(channel);
  slice.set_first_frame(frame);
  slice.add_samples(value);
  return slice;
}

TEST(ClipAssemblerMemoryTest, DeclaredFramesBuyNoMemoryBeforeTheDataArrives) {
  std::int64_t charged = 0;
  ClipAssembler assembler({}, [&](std::int64_t bytes) {
    charged += bytes;
    return absl::OkStatus();
  });

  // 3 channels x 10 000 000 frames declared (240 MB of samples), one sample at the last frame.
  ASSERT_TRUE(assembler.AddHeader(DeclaredHeader(3, 10'000'000)).ok());
  const std::int64_t layout = charged;
  for (int c = 0; c < 3; ++c) ASSERT_TRUE(assembler.AddSamples(OneSample(c, 9'999'999)).ok());
  const absl::StatusOr<core::Clip> finished = std::move(assembler).Finish();

  EXPECT_LT(layout, 4096);
  EXPECT_LT(charged, layout + 3 * 256);  // three one-sample runs
  EXPECT_THAT(finished, StatusIs(absl::StatusCode::kInvalidArgument,
                                 HasSubstr("frames 0..9999998 never arrived")));
}

TEST(ClipAssemblerMemoryTest, InOrderSlicesTakeAtMostTwiceWhatArrived) {
  const core::Clip clip = MakeClip(2, 20'000);  // 9 channels
  std::int64_t charged = 0;
  std::int64_t peak = 0;
  std::int64_t received_bytes = 0;
  bool within = true;
  ClipAssembler assembler({}, [&](std::int64_t bytes) {
    charged += bytes;
    peak = std::max(peak, charged);
    return absl::OkStatus();
  });
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());
  const std::int64_t layout = charged;

  for (const v1::ChannelSamples& slice : Slices(clip, 8 * 1000)) {
    ASSERT_TRUE(assembler.AddSamples(slice).ok());
    received_bytes += 8 * slice.samples_size();
    within = within && charged - layout <= 2 * received_bytes;
  }
  absl::StatusOr<core::Clip> back = std::move(assembler).Finish();

  EXPECT_TRUE(within);
  EXPECT_LE(peak - layout, 2 * received_bytes);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, clip);
}

TEST(ClipAssemblerMemoryTest, ReversedAndShuffledSlicesAssembleTheSameClip) {
  const core::Clip clip = MakeClip(3, 777);
  for (const bool shuffle : {false, true}) {
    std::vector<v1::ChannelSamples> slices = Slices(clip, 8 * 50);
    std::reverse(slices.begin(), slices.end());
    if (shuffle) std::shuffle(slices.begin(), slices.end(), std::mt19937(11));
    std::int64_t charged = 0;
    ClipAssembler assembler({}, [&](std::int64_t bytes) {
      charged += bytes;
      return absl::OkStatus();
    });
    ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());

    for (const v1::ChannelSamples& slice : slices) ASSERT_TRUE(assembler.AddSamples(slice).ok());
    const std::int64_t held = assembler.allocated_bytes();
    absl::StatusOr<core::Clip> back = std::move(assembler).Finish();

    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_EQ(*back, clip) << (shuffle ? "shuffled" : "reversed");
    EXPECT_EQ(held, charged);  // what the hook was told is what it holds
  }
}

TEST(ClipAssemblerMemoryTest, RefusedAllocationStopsTheMessageBeforeAnythingIsAllocated) {
  const core::Clip clip = MakeClip(1, 1000);
  std::int64_t allowed = 0;
  ClipAssembler assembler({}, [&](std::int64_t bytes) {
    if (bytes > 0 && bytes > allowed) return absl::ResourceExhaustedError("over the test budget");
    allowed -= bytes;
    return absl::OkStatus();
  });
  allowed = 1 << 20;
  ASSERT_TRUE(assembler.AddHeader(ClipHeaderToProto(clip)).ok());
  allowed = 0;
  const std::int64_t before = assembler.allocated_bytes();

  const absl::Status refused = assembler.AddSamples(Slices(clip, 8 * 100)[3]);

  EXPECT_THAT(refused, StatusIs(absl::StatusCode::kResourceExhausted, "over the test budget"));
  EXPECT_EQ(assembler.allocated_bytes(), before);
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

}  // namespace
}  // namespace tempokey::wire
