// The noise method and the Euler filter through the real `tempokey` binary against a real
// `tempokey-server` child on 127.0.0.1, and through pipeline files.
#include <string>
#include <vector>

#include "client/pipeline_file.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::HasSubstr;

class CliNoiseTest : public ServerProcessTest {
 protected:
  ProcessResult Tempokey(std::vector<std::string> args) {
    args.insert(args.begin(), {"--server", server_->target()});
    return RunTempokey(args, dir_);
  }
};

const std::string& CmuClip() {
  static const std::string path = SharedBvh("cmu/131_01.bvh");
  return path;
}

TEST_F(CliNoiseTest, ReduceNoiseWithAGivenLevelPrintsItAndTheEulerFilter) {
  const std::string output = Path("noise.json");

  ProcessResult run = Tempokey({"reduce", CmuClip(), "-o", output, "--method", "noise",
                                "--noise", "0.3"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(run.err, "");
  EXPECT_THAT(run.out, HasSubstr("noise rotations: median 0.3000 (0.3000 to 0.3000), given\n"));
  EXPECT_THAT(run.out, HasSubstr("noise positions: "));
  EXPECT_THAT(run.out, HasSubstr("euler filter:    "));
  absl::StatusOr<core::KeyedClip> keyed = core::ReadKeyedClipJsonFile(output);
  ASSERT_TRUE(keyed.ok()) << keyed.status();
  std::int64_t keys = 0;
  for (const core::Curve& curve : keyed->curves) keys += static_cast<std::int64_t>(curve.keys.size());
  EXPECT_THAT(run.out, HasSubstr(absl::StrCat("keys:            ", keys, " of 95424 samples")));
}

TEST_F(CliNoiseTest, ReduceNoiseAutoEstimatesTheLevels) {
  ProcessResult run = Tempokey({"reduce", CmuClip(), "-o", Path("auto.anim"), "--method", "noise",
                                "--euler-filter", "off"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_THAT(run.out, HasSubstr("noise rotations: median "));
  EXPECT_THAT(run.out, HasSubstr("), estimated\n"));
  EXPECT_THAT(run.out, ::testing::Not(HasSubstr("euler filter:")));
}

TEST_F(CliNoiseTest, NoiseFlagsBelongToTheNoiseMethod) {
  ProcessResult run = Tempokey({"reduce", CmuClip(), "-o", Path("x.json"), "--noise", "0.5"});

  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(run.err, "error: --noise does not apply to --method tolerance\n");
}

TEST_F(CliNoiseTest, BadNoiseLevelIsRefusedBeforeSending) {
  ProcessResult bad = Tempokey({"reduce", CmuClip(), "-o", Path("x.json"), "--method", "noise",
                                "--noise", "-1"});
  ProcessResult usage = Tempokey({"reduce", CmuClip(), "-o", Path("x.json"), "--method", "noise",
                                  "--euler-filter", "maybe"});

  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_EQ(bad.err,
            "error: operation 1 (reduce): noise.rotation_sigma_degrees must be in [1e-09, "
            "1e+09], got -1\n");
  EXPECT_EQ(usage.exit_code, 2);
  EXPECT_THAT(usage.err, HasSubstr("--euler-filter"));
}

// `run --euler-filter` (a convert step): every rotation is the source's, the angles may differ.
TEST_F(CliNoiseTest, RunWithTheEulerFilterKeepsEveryRotation) {
  const std::string output = Path("filtered.bvh");

  ProcessResult run = Tempokey({"run", CmuClip(), "-o", output, "--euler-filter"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  absl::StatusOr<core::Clip> source = core::ReadBvhFile(CmuClip());
  absl::StatusOr<core::Clip> filtered = core::ReadBvhFile(output);
  ASSERT_TRUE(source.ok() && filtered.ok());
  int changed = 0;
  double worst = 0.0;
  for (const core::JointRotation& joint : core::JointRotations(*source)) {
    if (joint.channels.size() != 3) continue;
    for (std::int64_t f = 0; f < source->frame_count; ++f) {
      core::Vec3 a, b;
      for (int k = 0; k < 3; ++k) {
        a[k] = source->channels[joint.channels[k]].samples[f];
        b[k] = filtered->channels[joint.channels[k]].samples[f];
      }
      if (a != b) ++changed;
      const core::Mat3 ma = core::EulerToMatrix(joint.order, a);
      const core::Mat3 mb = core::EulerToMatrix(joint.order, b);
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) worst = std::max(worst, std::abs(ma[i][j] - mb[i][j]));
      }
    }
  }
  EXPECT_GT(changed, 0);
  EXPECT_LT(worst, 1e-12);
}

TEST(NoisePipelineFileTest, ReduceAndRetimeOptionsReadLikeTheirFlags) {
  absl::StatusOr<std::vector<core::PipelineStep>> steps = client::ParsePipelineJson(
      R"({"operations": [{"retime": {"speed": "0s:1", "euler-filter": true}},
                         {"reduce": {"method": "noise", "noise": "auto", "position-noise": 0.2,
                                     "euler-filter": "off"}}]})",
      "pipeline.json");

  ASSERT_TRUE(steps.ok()) << steps.status();
  EXPECT_TRUE(std::get<core::RetimeStep>((*steps)[0]).euler_filter);
  const core::ReduceOptions& reduce = std::get<core::ReduceStep>((*steps)[1]).options;
  EXPECT_EQ(reduce.method, core::ReduceMethod::kNoise);
  EXPECT_FALSE(reduce.noise.rotation_sigma_degrees.has_value());
  EXPECT_EQ(reduce.noise.position_sigma, 0.2);
  EXPECT_EQ(reduce.euler_filter, false);
}

}  // namespace
}  // namespace tempokey::testing
