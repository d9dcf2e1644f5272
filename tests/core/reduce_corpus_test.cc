// The paper method on every rotation channel of every shared BVH file.
#include <cctype>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/bvh.h"
#include "tempokey/core/reduce.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

// The rotation channels of `clip` alone, as a plain clip (keeps the skeleton for BVH output).
Clip RotationsOnly(const Clip& clip) {
  Clip out = clip;
  for (Channel& channel : out.channels) {
    if (!IsRotation(channel.kind)) channel.samples.assign(channel.samples.size(), 0.0);
  }
  return out;
}

class ReduceCorpusTest : public ::testing::TestWithParam<std::string> {};

TEST_P(ReduceCorpusTest, PaperFitNeverIncreasesErrorAndBakesToValidBvh) {
  absl::StatusOr<Clip> clip = ReadBvhFile(GetParam());
  ASSERT_TRUE(clip.ok()) << clip.status();
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  options.paper.max_iterations = 4;

  absl::StatusOr<ReduceResult> result = ReduceKeys(RotationsOnly(*clip), options);

  ASSERT_TRUE(result.ok()) << result.status();
  for (std::size_t c = 0; c < clip->channels.size(); ++c) {
    const std::vector<double>& history = result->squared_error_history[c];
    if (!IsRotation(clip->channels[c].kind)) continue;
    for (std::size_t i = 1; i < history.size(); ++i) {
      EXPECT_LE(history[i], history[i - 1]) << ChannelLabel(*clip, static_cast<int>(c))
                                            << " iteration " << i;
    }
    EXPECT_LE(result->report.channels[c].key_count, clip->frame_count);
  }
  EXPECT_LT(result->report.key_percent(), 50.0);
  absl::StatusOr<Clip> baked = Bake(result->keyed);
  ASSERT_TRUE(baked.ok()) << baked.status();
  EXPECT_EQ(baked->frame_count, clip->frame_count);
  absl::StatusOr<std::string> text = FormatBvh(*baked);
  ASSERT_TRUE(text.ok()) << text.status();
  absl::StatusOr<Clip> reread = ParseBvh(*text, "baked.bvh");
  ASSERT_TRUE(reread.ok()) << reread.status();
  EXPECT_TRUE(ValidateClip(*reread).ok());
  EXPECT_EQ(reread->channels.size(), clip->channels.size());
}

INSTANTIATE_TEST_SUITE_P(SharedData, ReduceCorpusTest,
                         ::testing::ValuesIn(testing::AllSharedBvhFiles()),
                         [](const ::testing::TestParamInfo<std::string>& param) {
                           std::string name = param.param.substr(param.param.rfind('/') + 1);
                           for (char& ch : name) {
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           }
                           return name;
                         });

}  // namespace
}  // namespace tempokey::core
