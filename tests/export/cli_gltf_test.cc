// The CLI's glTF outputs through a real server: checked by the Khronos validator, played by
// three.js under node, and opened in headless Chromium (the screenshot is kept under the build
// tree: tests/export_artifacts/131_01_posed.png).
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tests/export/export_tools.h"
#include "tests/testing/process_util.h"
#include "tests/testing/test_paths.h"

namespace tempokey::testing {
namespace {

using ::testing::StartsWith;

class CliGltfTest : public ServerProcessTest {
 protected:
  ProcessResult Tempokey(std::vector<std::string> args) {
    args.insert(args.begin(), {"--server", server_->target()});
    return RunTempokey(args, dir_);
  }

  void ExpectValid(const std::vector<std::string>& files) {
    const std::vector<core::JsonValue> reports = RunNodeScript("validate.mjs", files, dir_);
    ASSERT_EQ(reports.size(), files.size());
    for (const core::JsonValue& report : reports) {
      EXPECT_EQ(NumberOf(report, "errors"), 0) << report.Find("file")->text;
      EXPECT_EQ(NumberOf(report, "warnings"), 0) << report.Find("file")->text;
    }
  }

  // A batch's inputs in the test's folder: in/walk.bvh, a copy of `bvh`, and ops.json holding
  // `operations` (its JSON text). Call under ASSERT_NO_FATAL_FAILURE.
  void WriteBatchInputs(const std::string& bvh, std::string_view operations) {
    std::filesystem::create_directories(Path("in"));
    std::filesystem::copy_file(bvh, Path("in/walk.bvh"));
    ASSERT_TRUE(core::WriteFileAtomically(Path("ops.json"), operations).ok());
  }
};

// The build tree's folder for artefacts a person looks at (the browser screenshot).
std::string ArtifactDir() {
  const std::string dir = BinaryDir() + "/tests/export_artifacts";
  std::filesystem::create_directories(dir);
  return dir;
}

// Segments the page draws: each joint to its parent, each End Site to its joint.
int BoneCount(const core::Clip& clip) {
  int bones = 0;
  for (const core::Joint& joint : clip.skeleton.joints) {
    bones += (joint.parent >= 0 ? 1 : 0) + static_cast<int>(joint.end_sites.size());
  }
  return bones;
}

TEST_F(CliGltfTest, ReducedCmuClipPlaysWithinTheBoundAndOpensInChromium) {
  const std::string cmu = SharedBvh("cmu/131_01.bvh");
  const std::string gltf = ArtifactDir() + "/131_01.gltf";

  const ProcessResult run = Tempokey({"reduce", cmu, "-o", gltf, "--tolerance", "0.5"});

  ASSERT_EQ(run.exit_code, 0) << run.err;
  ExpectValid({gltf});
  const std::vector<core::JsonValue> played = RunNodeScript("three_check.mjs", {cmu, gltf}, dir_);
  ASSERT_EQ(played.size(), 1u);
  EXPECT_LE(NumberOf(played[0], "max_rotation_error_degrees"), 0.5);
  EXPECT_LE(NumberOf(played[0], "max_translation_error"), 0.5 + 1e-4);  // float32 storage
  // A posed frame (4.2 s: mid-stride) in a real browser, three.js from the pinned package.
  const std::string png = ArtifactDir() + "/131_01_posed.png";
  std::filesystem::remove(png);
  const std::vector<core::JsonValue> shot =
      RunNodeScript("browser_shot.mjs", {TEMPOKEY_CHROMIUM, gltf, png, "4.2"}, dir_);
  ASSERT_EQ(shot.size(), 1u);
  absl::StatusOr<core::Clip> clip = core::ReadBvhFile(cmu);
  ASSERT_TRUE(clip.ok()) << clip.status();
  EXPECT_THAT(shot[0].Find("status")->text,
              StartsWith(absl::StrCat("ready bones=", BoneCount(*clip), " renderer=")));
  EXPECT_GT(NumberOf(shot[0], "png_bytes"), 2000);  // an empty 800x600 page is ~1.5 kB
}

TEST_F(CliGltfTest, RetimeAndBatchWriteValidGltf) {
  const std::string walk = SharedBvh("bandai/dataset-1_walk_active_001.bvh");
  ASSERT_NO_FATAL_FAILURE(
      WriteBatchInputs(walk, R"({"operations": [{"retime": {"speed": "0s:1,2s:0.5", "fps": 30}},)"
                             R"( {"reduce": {"tolerance": 0.5}}]})"));

  const ProcessResult retime = Tempokey({"retime", walk, "-o", Path("slow.glb"), "--speed",
                                         "0s:1,2s:0.5"});
  const ProcessResult batch = Tempokey(
      {"batch", Path("in"), "-o", Path("out"), "--ops", Path("ops.json"), "--format", "gltf"});

  ASSERT_EQ(retime.exit_code, 0) << retime.err;
  ASSERT_EQ(batch.exit_code, 0) << batch.err;
  ExpectValid({Path("slow.glb"), Path("out/walk.gltf")});
}

// `reduce --joint-tolerance` and a batch's reduce with one write glTFs within the joint bound as
// three.js places them (both pass it to the glTF's fit, as the server's downloads do): the bound
// the reduction reports, plus three.js's float32 interpolation.
TEST_F(CliGltfTest, JointToleranceReductionsWriteGlbWithinTheBound) {
  const std::string cmu = SharedBvh("cmu/131_01.bvh");
  const std::string walk = SharedBvh("bandai/dataset-1_walk_active_001.bvh");
  ASSERT_NO_FATAL_FAILURE(
      WriteBatchInputs(walk, R"({"operations": [{"reduce": {"joint-tolerance": "0.5%"}}]})"));

  const ProcessResult reduce =
      Tempokey({"reduce", cmu, "-o", Path("cmu.glb"), "--joint-tolerance", "0.5%"});
  const ProcessResult batch = Tempokey(
      {"batch", Path("in"), "-o", Path("out"), "--ops", Path("ops.json"), "--format", "glb"});

  ASSERT_EQ(reduce.exit_code, 0) << reduce.err;
  ASSERT_EQ(batch.exit_code, 0) << batch.err;
  EXPECT_THAT(reduce.out, ::testing::HasSubstr("joint bound:     0.1264 (0.500% of height)"));
  ExpectValid({Path("cmu.glb"), Path("out/walk.glb")});
  // 0.5 % of the figures' heights: 25.27 (CMU 131_01) and 139.24 (the Bandai walk) file units.
  const std::pair<std::string, double> checks[] = {{cmu, 0.12637}, {walk, 0.69622}};
  const std::string files[] = {Path("cmu.glb"), Path("out/walk.glb")};
  for (std::size_t i = 0; i < 2; ++i) {
    const std::vector<core::JsonValue> placed =
        RunNodeScript("world_check.mjs", {checks[i].first, files[i]}, dir_);
    ASSERT_EQ(placed.size(), 1u);
    EXPECT_LE(NumberOf(placed[0], "max_world_error"), checks[i].second + 1e-3) << files[i];
    if (i == 0) {
      // What the CLI says of the file is what three.js finds in it (printed to 4 decimals).
      const std::size_t at = reduce.out.find("gltf joint max:  ");
      ASSERT_NE(at, std::string::npos) << reduce.out;
      const double said = std::stod(reduce.out.substr(at + 17));
      EXPECT_NEAR(said, NumberOf(placed[0], "max_world_error"), 1e-4) << reduce.out;
    }
  }
  EXPECT_THAT(reduce.out, ::testing::HasSubstr(" joint frames), "));
}

}  // namespace
}  // namespace tempokey::testing
