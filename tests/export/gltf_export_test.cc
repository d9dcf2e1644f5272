// glTF exports of every shared clip, checked by tools that are not ours: the Khronos validator
// (no errors, no warnings) and three.js's GLTFLoader + AnimationMixer under node, which must
// reproduce every joint's local rotation and translation within the reduction's bounds at every
// source frame (tests/export/three_check.mjs reads the source BVH with its own reader).
#include "tempokey/core/io/gltf.h"

#include <optional>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_formats.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/export/export_tools.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

using testing::NumberOf;
using testing::RunNodeScript;

// glTF stores float32: a translation of magnitude ~300 (Bandai roots, cm) is rounded by up to
// 300 * 2^-24 = 1.8e-5; rotations by ~1e-5 degrees. The bounds are checked with this slack.
constexpr double kFloat32TranslationSlack = 1e-4;
constexpr double kFloat32RotationSlackDegrees = 1e-3;
// Sampled files key every frame at float32 times, which sit up to 2^-24 relative (4e-7 s at 7 s)
// from the frame times i x 0.0083333 that three.js is asked for; the CMU thumb, turning up to
// ~15000 degrees/s, moves 0.006 degrees in that time. (Keyed fits are verified in C++ with the
// same float32 times and double queries, so their bound already includes it.)
constexpr double kFloat32TimeSlackDegrees = 0.01;
// World positions from float32 rotations and translations along a chain of up to ~10 joints of
// up to ~150 cm (Bandai) or ~30 units (CMU): each rounding moves a point by about 1e-5 of the
// chain's length.
constexpr double kFloat32WorldSlack = 1e-3;

std::string Stem(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  const std::string name = path.substr(slash + 1);
  return name.substr(0, name.rfind('.'));
}

// Reduces `path` within `tolerance` (degrees and file units) and writes it as glTF in `dir`.
std::string WriteKeyed(const std::string& path, double tolerance, GltfContainer container,
                       const std::string& dir) {
  absl::StatusOr<Clip> source = ReadBvhFile(path);
  EXPECT_TRUE(source.ok()) << source.status();
  ReduceOptions options;
  options.tolerance.max_rotation_error_degrees = tolerance;
  options.tolerance.max_position_error = tolerance;
  absl::StatusOr<ReduceResult> reduced = ReduceKeys(*source, options);
  EXPECT_TRUE(reduced.ok()) << reduced.status();
  absl::StatusOr<GltfFile> file =
      FormatGltfKeyed(*source, reduced->keyed, {.max_rotation_error_degrees = tolerance}, container);
  EXPECT_TRUE(file.ok()) << file.status();
  const std::string out = absl::StrCat(dir, "/", Stem(path), "_", tolerance,
                                       container == GltfContainer::kText ? ".gltf" : ".glb");
  EXPECT_TRUE(WriteFileAtomically(out, file->bytes).ok());
  return out;
}

std::string WriteSampled(const std::string& path, GltfContainer container, const std::string& dir) {
  absl::StatusOr<Clip> source = ReadBvhFile(path);
  EXPECT_TRUE(source.ok()) << source.status();
  absl::StatusOr<GltfFile> file = FormatGltfSampled(*source, container);
  EXPECT_TRUE(file.ok()) << file.status();
  const std::string out = absl::StrCat(dir, "/", Stem(path), "_sampled",
                                       container == GltfContainer::kText ? ".gltf" : ".glb");
  EXPECT_TRUE(WriteFileAtomically(out, file->bytes).ok());
  return out;
}

// Reduces `path` under a joint bound (`joint`), writes the reduction baked at the source's
// frames as a sampled glTF in `dir` and returns the file and the world error tempokey reports.
struct WorldBounded {
  std::string file;
  WorldErrorReport report;
};
WorldBounded WriteWorldBounded(const std::string& path, std::optional<JointTolerance> joint,
                               const std::string& dir) {
  absl::StatusOr<Clip> source = ReadBvhFile(path);
  EXPECT_TRUE(source.ok()) << source.status();
  ReduceOptions options;
  options.tolerance.joint_tolerance = joint;
  absl::StatusOr<ReduceResult> reduced = ReduceKeys(*source, options);
  EXPECT_TRUE(reduced.ok()) << reduced.status();
  absl::StatusOr<Clip> baked = Bake(reduced->keyed);
  EXPECT_TRUE(baked.ok()) << baked.status();
  absl::StatusOr<GltfFile> file = FormatGltfSampled(*baked, GltfContainer::kBinary);
  EXPECT_TRUE(file.ok()) << file.status();
  const std::string out =
      absl::StrCat(dir, "/", Stem(path), joint ? "_joint_bound" : "_per_channel", ".glb");
  EXPECT_TRUE(WriteFileAtomically(out, file->bytes).ok());
  return {out, *reduced->report.world};
}

void ExpectThreeWithin(const std::string& bvh, const std::string& gltf, double rotation_bound,
                       double translation_bound, const std::string& dir) {
  const std::vector<JsonValue> lines = RunNodeScript("three_check.mjs", {bvh, gltf}, dir);
  ASSERT_EQ(lines.size(), 1u) << gltf;
  const JsonValue& result = lines[0];
  EXPECT_LE(NumberOf(result, "max_rotation_error_degrees"),
            rotation_bound + kFloat32RotationSlackDegrees)
      << gltf;
  EXPECT_LE(NumberOf(result, "max_translation_error"),
            translation_bound + kFloat32TranslationSlack)
      << gltf;
  EXPECT_GT(NumberOf(result, "animated_joints"), 0) << gltf;
}

TEST(GltfExportTest, EveryKeyedAndSampledFilePassesTheKhronosValidatorCleanly) {
  const std::string dir = testing::MakeTempDir();
  std::vector<std::string> files;
  for (const std::string& path : testing::AllSharedBvhFiles()) {
    files.push_back(WriteKeyed(path, 0.5, GltfContainer::kText, dir));
  }
  const std::string cmu = testing::SharedBvh("cmu/131_01.bvh");
  const std::string walk = testing::SharedBvh("bandai/dataset-1_walk_active_001.bvh");
  files.push_back(WriteKeyed(cmu, 0.5, GltfContainer::kBinary, dir));
  files.push_back(WriteSampled(cmu, GltfContainer::kText, dir));
  files.push_back(WriteSampled(walk, GltfContainer::kBinary, dir));

  const std::vector<JsonValue> reports = RunNodeScript("validate.mjs", files, dir);

  ASSERT_EQ(reports.size(), files.size());
  for (const JsonValue& report : reports) {
    const std::string file = report.Find("file")->text;
    EXPECT_EQ(NumberOf(report, "errors"), 0) << file;
    EXPECT_EQ(NumberOf(report, "warnings"), 0) << file;
    for (const JsonValue& message : *report.Find("messages")->array) {
      ADD_FAILURE() << file << ": " << message.text;
    }
  }
}

// A one-frame clip's reduction keys each joint once: glTF allows no CUBICSPLINE sampler with
// fewer than two keyframes (the validator's ANIMATION_SAMPLER_INPUT_ACCESSOR_TOO_FEW_ELEMENTS),
// so such samplers are LINEAR; three.js still poses the joints as the BVH does. Two frames keep
// their cubic samplers.
TEST(GltfExportTest, OneAndTwoFrameReductionsAreValidAndPlayAsTheSource) {
  const std::string dir = testing::MakeTempDir();
  std::vector<std::string> files;
  std::vector<std::string> sources;
  for (const int frames : {1, 2}) {
    std::string bvh =
        "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n"
        "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "  JOINT Arm\n  {\n    OFFSET 0 10 0\n    CHANNELS 2 Xrotation Zrotation\n"
        "    End Site\n    {\n      OFFSET 0 10 0\n    }\n  }\n}\nMOTION\n";
    absl::StrAppend(&bvh, "Frames: ", frames, "\nFrame Time: 0.0333333\n");
    for (int f = 0; f < frames; ++f) absl::StrAppend(&bvh, 1 + f, " 2 3 10 20 ", 30 + f, " 40 50\n");
    const std::string path = absl::StrCat(dir, "/frames_", frames, ".bvh");
    ASSERT_TRUE(WriteFileAtomically(path, bvh).ok());
    sources.push_back(path);
    files.push_back(WriteKeyed(path, 0.5, GltfContainer::kText, dir));
    files.push_back(WriteKeyed(path, 0.5, GltfContainer::kBinary, dir));
  }

  const std::vector<JsonValue> reports = RunNodeScript("validate.mjs", files, dir);

  ASSERT_EQ(reports.size(), files.size());
  for (const JsonValue& report : reports) {
    const std::string file = report.Find("file")->text;
    EXPECT_EQ(NumberOf(report, "errors"), 0) << file;
    for (const JsonValue& message : *report.Find("messages")->array) {
      ADD_FAILURE() << file << ": " << message.text;
    }
  }
  for (std::size_t i = 0; i < sources.size(); ++i) {
    ExpectThreeWithin(sources[i], files[2 * i], 0.5, 0.5, dir);
    ExpectThreeWithin(sources[i], files[2 * i + 1], 0.5, 0.5, dir);
  }
}

TEST(GltfExportTest, ThreeJsPlaysEveryKeyedClipWithinTheBoundAtEverySourceFrame) {
  const std::string dir = testing::MakeTempDir();
  for (const std::string& path : testing::AllSharedBvhFiles()) {
    ExpectThreeWithin(path, WriteKeyed(path, 0.5, GltfContainer::kText, dir), 0.5, 0.5, dir);
  }
}

TEST(GltfExportTest, ThreeJsStaysWithinTighterAndLooserBoundsToo) {
  // The sweep on two clips (one per source rate) keeps the stage short.
  const std::string dir = testing::MakeTempDir();
  for (const char* clip : {"cmu/131_01.bvh", "bandai/dataset-1_kick_normal_001.bvh"}) {
    const std::string path = testing::SharedBvh(clip);
    for (double tolerance : {0.1, 1.0}) {
      ExpectThreeWithin(path, WriteKeyed(path, tolerance, GltfContainer::kBinary, dir), tolerance,
                        tolerance, dir);
    }
  }
}

// Forward kinematics that is not tempokey's: three.js's scene graph places every joint and end
// site of the reduction (played from a glTF) and of the source (this folder's own BVH reader), and
// the world-space bound must hold there, with the same worst distance tempokey reports. A
// per-channel reduction, which lets a hand move 2.2 cm, shows the check can fail.
TEST(GltfExportTest, ThreeJsPlacesEveryPointOfAJointBoundReductionWithinTheBound) {
  const std::string dir = testing::MakeTempDir();
  for (const std::string& path : testing::AllSharedBvhFiles()) {
    const bool cmu = path.find("/cmu/") != std::string::npos;
    const WorldBounded reduced = WriteWorldBounded(
        path, cmu ? JointTolerance{.value = 0.5, .percent_of_height = true}
                  : JointTolerance{.value = 1.0},
        dir);
    const std::vector<JsonValue> lines =
        RunNodeScript("world_check.mjs", {path, reduced.file}, dir);
    ASSERT_EQ(lines.size(), 1u) << path;

    const double placed = NumberOf(lines[0], "max_world_error");
    EXPECT_LE(placed, reduced.report.joint_tolerance + kFloat32WorldSlack) << path;
    EXPECT_NEAR(placed, reduced.report.max_error, kFloat32WorldSlack) << path;
  }
  const std::string dance = testing::SharedBvh("bandai/dataset-1_dance-short_normal_001.bvh");
  const WorldBounded per_channel = WriteWorldBounded(dance, std::nullopt, dir);
  const std::vector<JsonValue> lines =
      RunNodeScript("world_check.mjs", {dance, per_channel.file}, dir);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_GT(NumberOf(lines[0], "max_world_error"), 2.0);
  EXPECT_NEAR(NumberOf(lines[0], "max_world_error"), per_channel.report.max_error,
              kFloat32WorldSlack);
}

// The keyed glTF of a joint-bound reduction, as three.js plays it (CUBICSPLINE quaternions
// interpolated by component, then normalised) and places it: every joint and end site within
// the bound at every source frame. Its rotations are other curves than the reduction's Euler
// keys, fitted again for glTF: before the glTF kept the joint bound itself, three.js placed CMU
// 131_01's right fingers' end site 0.166 from the source for a bound of 0.126, and a Bandai walk's
// toes 0.965 for 0.696.
TEST(GltfExportTest, ThreeJsPlacesEveryPointOfAJointBoundKeyedGltfWithinTheBound) {
  const std::string dir = testing::MakeTempDir();
  std::vector<std::string> files;
  for (const std::string& path : testing::AllSharedBvhFiles()) {
    absl::StatusOr<Clip> source = ReadBvhFile(path);
    ASSERT_TRUE(source.ok()) << source.status();
    ReduceOptions options;
    options.tolerance.joint_tolerance = JointTolerance{.value = 0.5, .percent_of_height = true};
    absl::StatusOr<ReduceResult> reduced = ReduceKeys(*source, options);
    ASSERT_TRUE(reduced.ok()) << reduced.status();
    // The bounds the CLI and the server's downloads take: the joint bound alone, no rotation
    // bound of its own (GltfRotationBoundDegrees()).
    absl::StatusOr<GltfFile> file = FormatGltfKeyed(
        *source, reduced->keyed,
        {.max_rotation_error_degrees = GltfRotationBoundDegrees(options),
         .joint_tolerance = GltfJointTolerance(options)},
        GltfContainer::kBinary);
    ASSERT_TRUE(file.ok()) << file.status();
    const std::string out = absl::StrCat(dir, "/", Stem(path), "_joint_bound_keyed.glb");
    ASSERT_TRUE(WriteFileAtomically(out, file->bytes).ok());
    files.push_back(out);

    const std::vector<JsonValue> lines = RunNodeScript("world_check.mjs", {path, out}, dir);

    ASSERT_EQ(lines.size(), 1u) << path;
    const double bound = reduced->report.world->joint_tolerance;
    // tempokey measures the file's float32 data in doubles; three.js interpolates into float32
    // buffers: kFloat32WorldSlack.
    EXPECT_LE(NumberOf(lines[0], "max_world_error"), bound + kFloat32WorldSlack) << path;
    EXPECT_NEAR(NumberOf(lines[0], "max_world_error"), file->stats.max_joint_error,
                kFloat32WorldSlack)
        << path;
  }
  const std::vector<JsonValue> reports = RunNodeScript("validate.mjs", files, dir);
  ASSERT_EQ(reports.size(), files.size());
  for (const JsonValue& report : reports) {
    EXPECT_EQ(NumberOf(report, "errors"), 0) << report.Find("file")->text;
    EXPECT_EQ(NumberOf(report, "warnings"), 0) << report.Find("file")->text;
  }
}

TEST(GltfExportTest, ThreeJsPlaysSampledClipsAsTheSourceItself) {
  const std::string dir = testing::MakeTempDir();
  for (const char* clip : {"cmu/131_01.bvh", "bandai/dataset-1_walk_active_001.bvh"}) {
    const std::string path = testing::SharedBvh(clip);
    ExpectThreeWithin(path, WriteSampled(path, GltfContainer::kBinary, dir),
                      kFloat32TimeSlackDegrees, 0.0, dir);
  }
}

}  // namespace
}  // namespace tempokey::core
