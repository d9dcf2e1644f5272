#include "client/result_assembler.h"

#include <algorithm>
#include <random>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/convert.h"
#include "tempokey/core/io/bvh.h"
#include "tests/testing/test_paths.h"

namespace tempokey::client {
namespace {

using ::testing::HasSubstr;
using ::tempokey::testing::SharedBvh;

std::vector<wire::v1::ResultPart> SampledParts(const core::Clip& clip, std::int64_t slice_bytes,
                                               const core::RetimeReport& report) {
  std::vector<wire::v1::ResultPart> parts(1);
  *parts[0].mutable_header()->mutable_clip() = wire::ClipHeaderToProto(clip);
  *parts[0].mutable_header()->add_reports() = wire::StepReportToProto(report);
  absl::Status status = wire::ForEachSamplesSlice(clip, slice_bytes, [&](wire::v1::ChannelSamples&& s) {
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
  std::vector<wire::v1::ResultPart> parts = SampledParts(*clip, 4096, report);
  std::shuffle(parts.begin() + 1, parts.end(), std::mt19937(7));

  ResultAssembler assembler;
  for (const wire::v1::ResultPart& part : parts) ASSERT_TRUE(assembler.AddPart(part).ok());
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
  std::vector<wire::v1::ResultPart> parts(1);
  *parts[0].mutable_header()->mutable_keyed_clip() = wire::ClipHeaderToProto(keyed.layout);
  // 3 keys of 4 columns x 8 bytes per piece.
  ASSERT_TRUE(wire::ForEachKeyedCurveSlice(keyed, 96, [&](wire::v1::KeyedCurve&& curve) {
                parts.emplace_back();
                *parts.back().mutable_curve() = std::move(curve);
                return absl::OkStatus();
              }).ok());
  ASSERT_GT(parts.size(), 3u);

  ResultAssembler assembler;
  for (const wire::v1::ResultPart& part : parts) ASSERT_TRUE(assembler.AddPart(part).ok());
  absl::StatusOr<core::PipelineResult> result = std::move(assembler).Finish();

  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_TRUE(std::holds_alternative<core::KeyedClip>(result->output));
  EXPECT_EQ(std::get<core::KeyedClip>(result->output).curves, keyed.curves);
}

TEST(ResultAssemblerTest, RefusesPartsOutOfOrder) {
  wire::v1::ResultPart samples;
  samples.mutable_samples()->set_channel_index(0);
  wire::v1::ResultPart header;
  header.mutable_header()->mutable_clip()->set_name("x");
  wire::v1::ResultPart curve;
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
  std::vector<wire::v1::ResultPart> parts = SampledParts(*clip, 1 << 20, {});
  parts.pop_back();

  ResultAssembler assembler;
  for (const wire::v1::ResultPart& part : parts) ASSERT_TRUE(assembler.AddPart(part).ok());
  absl::StatusOr<core::PipelineResult> result = std::move(assembler).Finish();

  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(result.status().message(), HasSubstr("never arrived"));
}

}  // namespace
}  // namespace tempokey::client
