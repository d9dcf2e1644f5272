// Job results as parts (proto/jobs_convert.h): the server's slicer cuts a result into one slice or
// curve piece per part for clients that know only those, several per part for clients that ask for
// batch_parts; the client's assembler joins them exactly and refuses parts out of order.
#include "proto/jobs_convert.h"

#include <algorithm>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/clip_convert.h"
#include "proto/operations_convert.h"
#include "proto/scratch_arena.h"
#include "tempokey/core/io/bvh.h"
#include "tests/server/test_clips.h"
#include "tests/testing/test_paths.h"

namespace tempokey::wire {
namespace {

using ::tempokey::testing::MakeClip;

std::vector<v1::ResultPart> AllParts(const core::PipelineResult& result, std::int64_t slice_bytes,
                                     bool batch_parts) {
  ResultSlicer slicer(std::make_shared<const core::PipelineResult>(result), slice_bytes,
                      batch_parts);
  std::vector<v1::ResultPart> parts;
  v1::ResultPart part;
  while (slicer.Next(&part)) parts.push_back(part);
  return parts;
}

core::PipelineResult Reassemble(const std::vector<v1::ResultPart>& parts) {
  ResultAssembler assembler;
  for (const v1::ResultPart& part : parts) {
    absl::Status added = assembler.AddPart(part);
    EXPECT_TRUE(added.ok()) << added;
  }
  absl::StatusOr<core::PipelineResult> result = std::move(assembler).Finish();
  EXPECT_TRUE(result.ok()) << result.status();
  return result.ok() ? *std::move(result) : core::PipelineResult{};
}

core::KeyedClip KeyedOf(const core::Clip& clip, int keys_per_curve) {
  core::KeyedClip keyed;
  keyed.layout = clip;
  for (core::Channel& channel : keyed.layout.channels) channel.samples.clear();
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    core::Curve curve;
    for (int k = 0; k < keys_per_curve; ++k) {
      core::Key key;
      key.time_seconds = 0.1 * k;
      key.value = static_cast<double>(c) - k;
      key.in_tangent = 0.5 * k;
      key.out_tangent = 0.5 * k;
      curve.keys.push_back(key);
    }
    keyed.curves.push_back(std::move(curve));
  }
  return keyed;
}

TEST(ResultSlicerTest, SampledResultIsOneChannelPerPartUnlessBatched) {
  const core::Clip clip = MakeClip(44, 128);  // 135 channels of 128 frames
  core::PipelineResult result;
  result.output = clip;

  const std::vector<v1::ResultPart> single = AllParts(result, 1 << 20, false);
  const std::vector<v1::ResultPart> batched = AllParts(result, 1 << 20, true);

  EXPECT_EQ(single.size(), 1 + clip.channels.size());  // header, then a part per channel
  for (std::size_t i = 1; i < single.size(); ++i) EXPECT_TRUE(single[i].has_samples());
  ASSERT_EQ(batched.size(), 2u);  // header, then every channel in one part of 138 KB
  EXPECT_EQ(batched[1].sample_slices().slices_size(), static_cast<int>(clip.channels.size()));
  EXPECT_EQ(std::get<core::Clip>(Reassemble(single).output), clip);
  EXPECT_EQ(std::get<core::Clip>(Reassemble(batched).output), clip);
}

TEST(ResultSlicerTest, BatchedPartsStayWithinTheSliceSize) {
  const core::Clip clip = MakeClip(4, 1000);  // 15 channels x 1000 frames
  core::PipelineResult result;
  result.output = clip;

  const std::vector<v1::ResultPart> batched = AllParts(result, 8 * 700, true);

  ASSERT_EQ(batched.size(), 1u + 22u);  // ceil(15000 / 700) parts after the header
  for (std::size_t i = 1; i < batched.size(); ++i) {
    std::int64_t samples = 0;
    for (const v1::ChannelSamples& slice : batched[i].sample_slices().slices()) {
      samples += slice.samples_size();
    }
    EXPECT_LE(samples, 700) << "part " << i;
  }
  EXPECT_EQ(std::get<core::Clip>(Reassemble(batched).output), clip);
}

TEST(ResultSlicerTest, KeyedResultBatchesCurvesAndReassemblesExactly) {
  const core::KeyedClip keyed = KeyedOf(MakeClip(10, 50), 12);  // 33 curves of 12 keys
  core::PipelineResult result;
  result.output = keyed;

  const std::vector<v1::ResultPart> single = AllParts(result, 1 << 20, false);
  const std::vector<v1::ResultPart> batched = AllParts(result, 1 << 20, true);
  const std::vector<v1::ResultPart> small = AllParts(result, 1024, true);

  EXPECT_EQ(single.size(), 1 + keyed.curves.size());
  ASSERT_EQ(batched.size(), 2u);
  EXPECT_EQ(batched[1].curves().curves_size(), static_cast<int>(keyed.curves.size()));
  EXPECT_GT(small.size(), 2u);  // 1 KiB holds a few curves per part
  EXPECT_LT(small.size(), 1 + keyed.curves.size());
  for (const auto* parts : {&single, &batched, &small}) {
    EXPECT_EQ(std::get<core::KeyedClip>(Reassemble(*parts).output), keyed);
  }
}

// Each part serialized, built on the heap or in a scratch arena (as the server writes them).
std::vector<std::string> SerializedParts(const core::PipelineResult& result, bool batch_parts,
                                         bool in_scratch_arena) {
  ResultSlicer slicer(std::make_shared<const core::PipelineResult>(result), 1024, batch_parts);
  std::vector<std::string> parts;
  for (;;) {
    std::string bytes;
    if (in_scratch_arena) {
      ScratchMessage<v1::ResultPart> part;
      EXPECT_TRUE(part.shared());
      if (!slicer.Next(part.get())) break;
      bytes = part->SerializeAsString();
    } else {
      v1::ResultPart part;
      if (!slicer.Next(&part)) break;
      bytes = part.SerializeAsString();
    }
    parts.push_back(std::move(bytes));
  }
  return parts;
}

TEST(ResultSlicerTest, PartsBuiltInAScratchArenaAreTheHeapOnesByteForByte) {
  const core::Clip clip = MakeClip(10, 50);
  core::PipelineResult sampled;
  sampled.output = clip;
  core::PipelineResult keyed;
  keyed.output = KeyedOf(clip, 12);

  for (const core::PipelineResult* result : {&sampled, &keyed}) {
    for (bool batch_parts : {false, true}) {
      SCOPED_TRACE(batch_parts ? "batched" : "single");
      const std::vector<std::string> heap = SerializedParts(*result, batch_parts, false);
      const std::vector<std::string> scratch = SerializedParts(*result, batch_parts, true);
      EXPECT_GT(heap.size(), 2u);
      EXPECT_EQ(scratch, heap);
    }
  }
}

}  // namespace
}  // namespace tempokey::wire

namespace tempokey::wire {
namespace {

using ::testing::HasSubstr;
using ::tempokey::testing::SharedBvh;

std::vector<v1::ResultPart> SampledParts(const core::Clip& clip, std::int64_t slice_bytes,
                                               const core::RetimeReport& report) {
  std::vector<v1::ResultPart> parts(1);
  *parts[0].mutable_header()->mutable_clip() = wire::ClipHeaderToProto(clip);
  *parts[0].mutable_header()->add_reports() = wire::StepReportToProto(report);
  absl::Status status = wire::ForEachSamplesSlice(clip, slice_bytes, [&](v1::ChannelSamples&& s) {
    parts.emplace_back();
    *parts.back().mutable_samples() = std::move(s);
    return absl::OkStatus();
  });
  EXPECT_TRUE(status.ok()) << status;
  return parts;
}

TEST(ResultAssemblerTest, RebuildsARealClipFromSlicesInAnyOrder) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  const core::RetimeReport report{.output_duration_seconds = 8.0, .output_frame_count = 961};
  std::vector<v1::ResultPart> parts = SampledParts(*clip, 4096, report);
  std::shuffle(parts.begin() + 1, parts.end(), std::mt19937(7));

  ResultAssembler assembler;
  for (const v1::ResultPart& part : parts) ASSERT_TRUE(assembler.AddPart(part).ok());
  absl::StatusOr<core::PipelineResult> result = std::move(assembler).Finish();

  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_TRUE(std::holds_alternative<core::Clip>(result->output));
  EXPECT_EQ(std::get<core::Clip>(result->output), *clip);
  ASSERT_EQ(result->reports.size(), 1u);
  EXPECT_EQ(std::get<core::RetimeReport>(result->reports[0]).output_frame_count, 961);
}

core::KeyedClip SmallKeyedClip() {
  core::KeyedClip keyed;
  keyed.layout.name = "k";
  keyed.layout.frame_time_seconds = 0.1;
  keyed.layout.frame_count = 11;
  for (const char* name : {"a", "b"}) {
    core::Channel channel;
    channel.kind = core::ChannelKind::kScalar;
    channel.name = name;
    keyed.layout.channels.push_back(channel);
  }
  for (int c = 0; c < 2; ++c) {
    core::Curve curve;
    for (int k = 0; k <= 10; ++k) {
      core::Key key;
      key.time_seconds = 0.1 * k;
      key.value = c + 0.5 * k;
      key.in_tangent = 1.0;
      key.out_tangent = 1.0;
      curve.keys.push_back(key);
    }
    keyed.curves.push_back(curve);
  }
  return keyed;
}

TEST(ResultAssemblerTest, JoinsKeyedCurvePieces) {
  const core::KeyedClip keyed = SmallKeyedClip();
  std::vector<v1::ResultPart> parts(1);
  *parts[0].mutable_header()->mutable_keyed_clip() = wire::ClipHeaderToProto(keyed.layout);
  // 3 keys of 4 columns x 8 bytes per piece.
  ASSERT_TRUE(wire::ForEachKeyedCurveSlice(keyed, 96, [&](v1::KeyedCurve&& curve) {
                parts.emplace_back();
                *parts.back().mutable_curve() = std::move(curve);
                return absl::OkStatus();
              }).ok());
  ASSERT_GT(parts.size(), 3u);

  ResultAssembler assembler;
  for (const v1::ResultPart& part : parts) ASSERT_TRUE(assembler.AddPart(part).ok());
  absl::StatusOr<core::PipelineResult> result = std::move(assembler).Finish();

  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_TRUE(std::holds_alternative<core::KeyedClip>(result->output));
  EXPECT_EQ(std::get<core::KeyedClip>(result->output).curves, keyed.curves);
}

TEST(ResultAssemblerTest, RefusesPartsOutOfOrder) {
  v1::ResultPart samples;
  samples.mutable_samples()->set_channel_index(0);
  v1::ResultPart header;
  header.mutable_header()->mutable_clip()->set_name("x");
  v1::ResultPart curve;
  curve.mutable_curve()->set_channel_index(0);

  ResultAssembler early;
  ResultAssembler twice;
  ResultAssembler mixed;
  ResultAssembler empty;

  EXPECT_EQ(early.AddPart(samples).message(), "result part 1: samples before the header");
  (void)twice.AddPart(header);
  EXPECT_EQ(twice.AddPart(header).message(), "result part 2: a second result header");
  (void)mixed.AddPart(header);
  EXPECT_EQ(mixed.AddPart(curve).message(), "result part 2: a curve in a sampled result");
  EXPECT_EQ(std::move(empty).Finish().status().message(), "the result has no header");
}

TEST(ResultAssemblerTest, RefusesAnIncompleteClip) {
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(SharedBvh("bandai/dataset-1_bow_active_001.bvh"));
  ASSERT_TRUE(clip.ok()) << clip.status();
  std::vector<v1::ResultPart> parts = SampledParts(*clip, 1 << 20, {});
  parts.pop_back();

  ResultAssembler assembler;
  for (const v1::ResultPart& part : parts) ASSERT_TRUE(assembler.AddPart(part).ok());
  absl::StatusOr<core::PipelineResult> result = std::move(assembler).Finish();

  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(result.status().message(), HasSubstr("never arrived"));
}

}  // namespace
}  // namespace tempokey::wire
