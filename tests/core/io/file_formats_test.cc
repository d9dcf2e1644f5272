// The list of file formats: each entry writes what the format's own function writes, keyed
// results in sampled formats are baked first, and clip files are read by their extension.
#include <stop_token>
#include <string>
#include <variant>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/csv.h"
#include "tempokey/core/io/file_formats.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/gltf.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/io/maya_anim.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

const Clip& Bandai() {
  static const Clip clip = *ReadBvhFile(testing::SharedBvh("bandai/dataset-1_bow_active_001.bvh"));
  return clip;
}

const KeyedClip& Keyed() {
  static const KeyedClip keyed = ReduceKeys(Bandai(), {})->keyed;
  return keyed;
}

TEST(FileFormatsTest, ListsTheCliOutputFormatsInOrder) {
  std::vector<std::string> names;
  for (const ExportFormat& format : ExportFormats()) {
    names.emplace_back(format.name);
    EXPECT_EQ(format.extension, "." + std::string(format.name));
    EXPECT_EQ(format.format_sampled != nullptr, format.content == FileContent::kSampled);
    EXPECT_EQ(format.format_keyed != nullptr, format.content == FileContent::kKeyed);
  }

  EXPECT_EQ(names, (std::vector<std::string>{"bvh", "csv", "json", "anim", "gltf", "glb"}));
  EXPECT_EQ(FindExportFormat("BVH"), FindExportFormat(".bvh"));
  EXPECT_EQ(FindExportFormat("gif"), nullptr);
}

TEST(FileFormatsTest, EachFormatWritesWhatItsOwnFunctionWrites) {
  const std::variant<Clip, KeyedClip> sampled = Bandai();
  const std::variant<Clip, KeyedClip> keyed = Keyed();
  const Clip baked = *Bake(Keyed());

  EXPECT_EQ(*FormatOutput(sampled, *FindExportFormat("bvh")), *FormatBvh(Bandai()));
  EXPECT_EQ(*FormatOutput(sampled, *FindExportFormat("csv")), *FormatCsv(Bandai()));
  EXPECT_EQ(*FormatOutput(keyed, *FindExportFormat("json")), *FormatKeyedClipJson(Keyed()));
  EXPECT_EQ(*FormatOutput(keyed, *FindExportFormat("anim")), *FormatMayaAnim(Keyed()));
  EXPECT_EQ(*FormatOutput(keyed, *FindExportFormat("bvh")), *FormatBvh(baked));
  EXPECT_EQ(*FormatOutput(keyed, *FindExportFormat("csv")), *FormatCsv(baked));
}

TEST(FileFormatsTest, GltfWritesSampledClipsAndCurvesFittedAgainstTheirSource) {
  const std::variant<Clip, KeyedClip> sampled = Bandai();
  const std::variant<Clip, KeyedClip> keyed = Keyed();
  const ExportSource source{.clip = &Bandai(), .max_rotation_error_degrees = 0.25};

  EXPECT_EQ(*FormatOutput(sampled, *FindExportFormat("gltf")),
            FormatGltfSampled(Bandai(), GltfContainer::kText)->bytes);
  EXPECT_EQ(*FormatOutput(keyed, *FindExportFormat("glb"), {}, source),
            FormatGltfKeyed(Bandai(), Keyed(), {.max_rotation_error_degrees = 0.25},
                            GltfContainer::kBinary)
                ->bytes);
  const absl::StatusOr<std::string> unsourced = FormatOutput(keyed, *FindExportFormat("gltf"));
  EXPECT_EQ(unsourced.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(unsourced.status().message(),
            "a keyed gltf file is fitted against the clip the curves were reduced from, which is "
            "not available");
}

TEST(FileFormatsTest, AStopEndsTheFitsOfAKeyedGltfAndTheBakeOfCurvesButNotTheirWriting) {
  const std::variant<Clip, KeyedClip> sampled = Bandai();
  const std::variant<Clip, KeyedClip> keyed = Keyed();
  const ExportSource source{.clip = &Bandai(), .max_rotation_error_degrees = 0.5};
  std::stop_source stop;
  stop.request_stop();

  for (const char* name : {"gltf", "glb", "bvh", "csv"}) {
    const absl::StatusOr<std::string> file =
        FormatOutput(keyed, *FindExportFormat(name), {}, source, stop.get_token());
    EXPECT_EQ(file.status().code(), absl::StatusCode::kCancelled) << name;
  }
  // Writing what exists already is linear in the file: not stopped.
  for (const char* name : {"json", "anim"}) {
    EXPECT_TRUE(FormatOutput(keyed, *FindExportFormat(name), {}, source, stop.get_token()).ok())
        << name;
  }
  for (const char* name : {"bvh", "csv", "glb"}) {
    EXPECT_TRUE(FormatOutput(sampled, *FindExportFormat(name), {}, {}, stop.get_token()).ok())
        << name;
  }
}

TEST(FileFormatsTest, GltfRotationBoundIsTheRotationToleranceOrHalfADegree) {
  ReduceOptions set;
  set.tolerance.max_rotation_error_degrees = 0.3;

  EXPECT_EQ(GltfRotationBoundDegrees(set), 0.3);
  EXPECT_EQ(GltfRotationBoundDegrees(ReduceOptions{}), 0.5);
}

// As the reduction's rotation channels: a joint bound alone chooses their bounds, and a rotation
// tolerance given still applies beside it.
TEST(FileFormatsTest, UnderAJointBoundAloneGlTfRotationsHaveNoBoundOfTheirOwn) {
  ReduceOptions joint;
  joint.tolerance.joint_tolerance = JointTolerance{.value = 0.5, .percent_of_height = true};
  ReduceOptions joint_and_rotation = joint;
  joint_and_rotation.tolerance.max_rotation_error_degrees = 0.3;
  ReduceOptions joint_under_budget = joint;
  joint_under_budget.tolerance.key_budget = 3000;

  EXPECT_EQ(GltfRotationBoundDegrees(joint), kNoRotationBoundDegrees);
  EXPECT_EQ(GltfRotationBoundDegrees(joint_and_rotation), 0.3);
  EXPECT_EQ(GltfRotationBoundDegrees(joint_under_budget), 0.5);
}

TEST(FileFormatsTest, GltfJointToleranceIsTheToleranceMethodsUnlessAKeyBudgetScalesIt) {
  const JointTolerance half_percent{.value = 0.5, .percent_of_height = true};
  ReduceOptions joint;
  joint.tolerance.joint_tolerance = half_percent;
  ReduceOptions budget = joint;
  budget.tolerance.key_budget = 3000;
  ReduceOptions noise = joint;
  noise.method = ReduceMethod::kNoise;

  EXPECT_EQ(GltfJointTolerance(joint), half_percent);
  EXPECT_EQ(GltfJointTolerance(ReduceOptions{}), std::nullopt);
  EXPECT_EQ(GltfJointTolerance(budget), std::nullopt);
  EXPECT_EQ(GltfJointTolerance(noise), std::nullopt);
}

// The server's downloads (FormatOutput()) and the CLI (FormatGltfKeyed()) write one file for a
// joint-bound reduction too.
TEST(FileFormatsTest, AJointBoundGltfIsTheSameBytesThroughEitherEntry) {
  ReduceOptions options;
  options.tolerance.joint_tolerance = JointTolerance{.value = 1.0};
  const absl::StatusOr<ReduceResult> reduced = ReduceKeys(Bandai(), options);
  ASSERT_TRUE(reduced.ok()) << reduced.status();
  const ExportSource source{.clip = &Bandai(),
                            .max_rotation_error_degrees = GltfRotationBoundDegrees(options),
                            .joint_tolerance = GltfJointTolerance(options)};

  const absl::StatusOr<std::string> download = FormatOutput(
      std::variant<Clip, KeyedClip>(reduced->keyed), *FindExportFormat("glb"), {}, source);
  const absl::StatusOr<GltfFile> cli = FormatGltfKeyed(
      Bandai(), reduced->keyed,
      {.max_rotation_error_degrees = GltfRotationBoundDegrees(options),
       .joint_tolerance = GltfJointTolerance(options), .threads = 2},
      GltfContainer::kBinary);

  ASSERT_TRUE(download.ok()) << download.status();
  ASSERT_TRUE(cli.ok()) << cli.status();
  EXPECT_TRUE(*download == cli->bytes);
  EXPECT_EQ(cli->stats.joint_bound, 1.0);
  EXPECT_LE(cli->stats.max_joint_error, 1.0);
}

TEST(FileFormatsTest, SampledClipHasNoCurvesToWrite) {
  const absl::StatusOr<std::string> text =
      FormatOutput(std::variant<Clip, KeyedClip>(Bandai()), *FindExportFormat("anim"));

  ASSERT_FALSE(text.ok());
  EXPECT_EQ(text.status().message(), "anim holds key-frame curves; a sampled clip has none: reduce it first");
}

TEST(FileFormatsTest, ClipTextIsReadByItsExtension) {
  const std::string bvh = *FormatBvh(Bandai());
  const std::string csv = *FormatCsv(Bandai());

  const absl::StatusOr<Clip> from_bvh = ParseClipText(bvh, "dir/Walk.BVH", std::nullopt);
  const absl::StatusOr<Clip> from_csv = ParseClipText(csv, "walk.csv", 1.0 / 30.0);
  const absl::StatusOr<Clip> csv_without_rate = ParseClipText(csv, "walk.csv", std::nullopt);
  const absl::StatusOr<Clip> other = ParseClipText(bvh, "walk.txt", std::nullopt);
  const absl::StatusOr<Clip> none = ParseClipText(bvh, "walk", std::nullopt);
  const absl::StatusOr<Clip> broken = ParseClipText("HIERARCHY\nROOT Hips\n{\n\tOFFSET 0 0\n", "broken.bvh", std::nullopt);

  ASSERT_TRUE(from_bvh.ok()) << from_bvh.status();
  EXPECT_EQ(from_bvh->name, "Walk");
  EXPECT_EQ(from_bvh->channels, Bandai().channels);
  ASSERT_TRUE(from_csv.ok()) << from_csv.status();
  EXPECT_EQ(from_csv->channels.size(), Bandai().channels.size());
  EXPECT_EQ(csv_without_rate.status().message(),
            "walk.csv: a CSV file does not store its frame rate; give it");
  EXPECT_EQ(other.status().message(), "walk.txt: unknown clip format '.txt' (expected .bvh, .csv)");
  EXPECT_EQ(none.status().message(), "walk: no extension (expected .bvh, .csv)");
  ASSERT_FALSE(broken.ok());
  EXPECT_EQ(broken.status().message().substr(0, 13), "broken.bvh:4:");
}

}  // namespace
}  // namespace tempokey::core
