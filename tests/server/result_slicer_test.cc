// Results in parts: one slice or curve piece per part for clients that know only those, several
// per part (up to the slice size) for clients that ask for batch_parts; both reassemble exactly.
#include <memory>
#include <vector>

#include "client/result_assembler.h"
#include "gtest/gtest.h"
#include "server/job_proto.h"
#include "tests/server/test_clips.h"

namespace tempokey::server {
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
  client::ResultAssembler assembler;
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

}  // namespace
}  // namespace tempokey::server
