// The structure of glTF files (validity and playback are checked by the Khronos validator and
// three.js in tests/export, label export).
#include "tempokey/core/io/gltf.h"

#include <cstdint>
#include <cstring>
#include <string>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

std::uint32_t Uint32At(const std::string& bytes, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(bytes[at + i]);
  return v;
}

Clip Cmu() {
  absl::StatusOr<Clip> clip = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  EXPECT_TRUE(clip.ok()) << clip.status();
  return *clip;
}

TEST(GltfTest, GlbHoldsTheJointHierarchyWithOffsetsAndEndSites) {
  const Clip clip = Cmu();
  const absl::StatusOr<ReduceResult> reduced = ReduceKeys(clip, {});
  ASSERT_TRUE(reduced.ok()) << reduced.status();

  const absl::StatusOr<GltfFile> file = FormatGltfKeyed(clip, reduced->keyed, {}, GltfContainer::kBinary);

  ASSERT_TRUE(file.ok()) << file.status();
  const std::string& bytes = file->bytes;
  ASSERT_GT(bytes.size(), 28u);
  EXPECT_EQ(bytes.substr(0, 4), "glTF");
  EXPECT_EQ(Uint32At(bytes, 4), 2u);
  EXPECT_EQ(Uint32At(bytes, 8), bytes.size());
  const std::uint32_t json_length = Uint32At(bytes, 12);
  EXPECT_EQ(bytes.substr(16, 4), "JSON");
  absl::StatusOr<JsonValue> json = ParseJson(bytes.substr(20, json_length), "glb");
  ASSERT_TRUE(json.ok()) << json.status();
  std::size_t end_sites = 0;
  for (const Joint& joint : clip.skeleton.joints) end_sites += joint.end_sites.size();
  const JsonArray& nodes = *json->Find("nodes")->array;
  ASSERT_EQ(nodes.size(), clip.skeleton.joints.size() + end_sites);
  for (std::size_t j = 0; j < clip.skeleton.joints.size(); ++j) {
    EXPECT_EQ(nodes[j].Find("name")->text, clip.skeleton.joints[j].name);
    for (int axis = 0; axis < 3; ++axis) {
      EXPECT_EQ((*nodes[j].Find("translation")->array)[axis].number,
                clip.skeleton.joints[j].offset[axis]);
    }
  }
  EXPECT_EQ(nodes[clip.skeleton.joints.size()].Find("name")->text, "LeftToe_end");
  // Every CUBICSPLINE output holds in-tangent, value and out-tangent per key.
  const JsonArray& accessors = *json->Find("accessors")->array;
  for (const JsonValue& sampler : *(*json->Find("animations")->array)[0].Find("samplers")->array) {
    EXPECT_EQ(sampler.Find("interpolation")->text, "CUBICSPLINE");
    const auto input = static_cast<std::size_t>(sampler.Find("input")->number);
    const auto output = static_cast<std::size_t>(sampler.Find("output")->number);
    EXPECT_EQ(accessors[output].Find("count")->number, 3 * accessors[input].Find("count")->number);
  }
  EXPECT_EQ(file->stats.animated_joints, 31);
  EXPECT_EQ(file->stats.rotation_samples, 31 * clip.frame_count);
}

TEST(GltfTest, AKeyedGlbIsTheSameBytesWhateverTheThreadsFittingItsJoints) {
  const Clip clip = Cmu();  // 31 joints with rotations
  const absl::StatusOr<ReduceResult> reduced = ReduceKeys(clip, {});
  ASSERT_TRUE(reduced.ok()) << reduced.status();
  auto glb = [&](int threads) {
    GltfKeyedOptions options;
    options.threads = threads;
    const absl::StatusOr<GltfFile> file =
        FormatGltfKeyed(clip, reduced->keyed, options, GltfContainer::kBinary);
    EXPECT_TRUE(file.ok()) << file.status();
    return file.ok() ? file->bytes : std::string();
  };

  const std::string alone = glb(1);

  ASSERT_GT(alone.size(), 1000u);
  for (int threads : {0, 2, 3, 8, 64}) EXPECT_TRUE(glb(threads) == alone) << threads << " threads";
}

TEST(GltfTest, ClipsItCannotHoldAreRefused) {
  Clip plain;
  plain.frame_count = 2;
  Channel channel;
  channel.name = "blend";
  channel.samples = {0, 1};
  plain.channels = {channel};
  const Clip cmu = Cmu();
  const absl::StatusOr<ReduceResult> reduced = ReduceKeys(cmu, {});
  ASSERT_TRUE(reduced.ok()) << reduced.status();
  Clip other = cmu;
  other.frame_time_seconds = 1.0 / 30.0;

  EXPECT_EQ(FormatGltfSampled(plain, GltfContainer::kText).status().message(),
            "glTF export needs a skeleton: this clip has plain channels only (no nodes to animate)");
  EXPECT_EQ(FormatGltfKeyed(other, reduced->keyed, {}, GltfContainer::kText).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(FormatGltfKeyed(cmu, reduced->keyed, {.max_rotation_error_degrees = -1},
                            GltfContainer::kText)
                .status()
                .message(),
            "glTF rotation bound must be finite and > 0 degrees, got -1");
}

}  // namespace
}  // namespace tempokey::core
