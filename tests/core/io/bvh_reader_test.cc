// ParseBvh accepts the spellings real files use; FormatBvh writes text that reads back exactly.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/bit_digest.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

using ::tempokey::testing::SameBits;

// Parses or fails the test.
Clip Parse(const std::string& text, const std::string& name = "walk.bvh") {
  absl::StatusOr<Clip> clip = ParseBvh(text, name);
  EXPECT_TRUE(clip.ok()) << clip.status();
  return clip.ok() ? *std::move(clip) : Clip{};
}

std::vector<std::string> ChannelNames(const Clip& clip, int joint) {
  std::vector<std::string> names;
  for (int c : clip.skeleton.joints[joint].channels) {
    names.emplace_back(ChannelKindName(clip.channels[c].kind));
  }
  return names;
}

const char kUnixText[] =
    "HIERARCHY\n"
    "ROOT Hips\n"
    "{\n"
    "  OFFSET 1 2 3\n"
    "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    "  JOINT Spine\n"
    "  {\n"
    "    OFFSET 0 4.5 0\n"
    "    CHANNELS 3 Zrotation Xrotation Yrotation\n"
    "    End Site\n"
    "    {\n"
    "      OFFSET 0 1.25 -0.5\n"
    "    }\n"
    "  }\n"
    "}\n"
    "MOTION\n"
    "Frames: 3\n"
    "Frame Time: 0.0333333\n"
    "0 1 2 3 4 5 6 7 8\n"
    "10 11 12 13 14 15 16 17 18\n"
    "20 21 22 23 24 25 26 27 28\n";

std::string ReplaceAll(std::string text, const std::string& from, const std::string& to) {
  for (std::size_t at = text.find(from); at != std::string::npos;
       at = text.find(from, at + to.size())) {
    text.replace(at, from.size(), to);
  }
  return text;
}

// The clip's name comes from the file name, which may be any bytes (Latin-1 "caf\xe9.bvh"): it
// goes into protobuf strings and JSON, which hold UTF-8 (the CLI failed with a serialization error
// and a misleading message), so a byte that is not UTF-8 becomes U+FFFD.
TEST(BvhReaderTest, ANameFromAFileNameThatIsNotUtf8IsMadeValid) {
  EXPECT_EQ(Parse(kUnixText, "in/caf\xe9.bvh").name, "caf\xEF\xBF\xBD");
  EXPECT_EQ(Parse(kUnixText, "in/caf\xc3\xa9.bvh").name, "caf\xc3\xa9");
}

TEST(BvhReaderTest, StoresSamplesChannelMajorInColumnOrder) {
  const Clip clip = Parse(kUnixText);

  ASSERT_EQ(clip.channels.size(), 9u);
  EXPECT_EQ(clip.frame_count, 3);
  for (std::size_t c = 0; c < 9; ++c) {
    const double first = static_cast<double>(c);
    EXPECT_EQ(clip.channels[c].samples, (std::vector<double>{first, first + 10, first + 20}));
  }
  EXPECT_EQ(clip.channels[0].joint, 0);
  EXPECT_EQ(clip.channels[6].joint, 1);
  EXPECT_EQ(clip.channels[6].kind, ChannelKind::kZRotation);
  EXPECT_TRUE(ValidateClip(clip).ok());
}

TEST(BvhReaderTest, KeepsOffsetsParentsAndEndSites) {
  const Clip clip = Parse(kUnixText);

  ASSERT_EQ(clip.skeleton.joints.size(), 2u);
  const Joint& hips = clip.skeleton.joints[0];
  const Joint& spine = clip.skeleton.joints[1];
  EXPECT_EQ(hips.parent, -1);
  EXPECT_EQ(hips.offset, (Vec3{1, 2, 3}));
  EXPECT_TRUE(hips.end_sites.empty());
  EXPECT_EQ(spine.parent, 0);
  EXPECT_EQ(spine.offset, (Vec3{0, 4.5, 0}));
  ASSERT_EQ(spine.end_sites.size(), 1u);
  EXPECT_EQ(spine.end_sites[0], (Vec3{0, 1.25, -0.5}));
}

TEST(BvhReaderTest, MixedLineEndingsParseLikeUnixOnes) {
  // CRLF on odd lines, LF on even ones, as in the CMU capture.
  std::string mixed;
  int line = 0;
  for (const char* p = kUnixText; *p != '\0'; ++p) {
    if (*p == '\n' && ++line % 2 == 1) mixed += '\r';
    mixed += *p;
  }

  const Clip clip = Parse(mixed);

  EXPECT_EQ(clip, Parse(kUnixText));
}

TEST(BvhReaderTest, OldMacCarriageReturnsParseLikeUnixOnes) {
  const std::string cr_only = ReplaceAll(kUnixText, "\n", "\r");

  const Clip clip = Parse(cr_only);

  EXPECT_EQ(clip, Parse(kUnixText));
}

TEST(BvhReaderTest, TabsAndExtraWhitespaceAnywhereParseTheSame) {
  std::string spaced = ReplaceAll(kUnixText, "  ", "\t");
  spaced = ReplaceAll(spaced, " ", " \t  ");
  spaced = ReplaceAll(spaced, "\n", " \t\n");
  // Blank lines between motion rows and after the last one.
  spaced = ReplaceAll(spaced, "8 \t\n", "8 \t\n\n \t \n");

  const Clip clip = Parse("\n\n" + spaced + "\n\n");

  EXPECT_EQ(clip, Parse(kUnixText));
}

TEST(BvhReaderTest, ReadsExponentLeadingDotAndPlusSignNumbers) {
  const std::string text = ReplaceAll(
      kUnixText, "0 1 2 3 4 5 6 7 8\n", "1.2e-05 -3.5E+02 1e2 .5 -.25 5. +7 -0 2.5e-310\n");

  const Clip clip = Parse(text);

  ASSERT_EQ(clip.channels.size(), 9u);
  const double expected[] = {1.2e-05, -3.5e+02, 100.0, 0.5, -0.25, 5.0, 7.0, -0.0, 2.5e-310};
  for (std::size_t c = 0; c < 9; ++c) {
    EXPECT_TRUE(SameBits(clip.channels[c].samples[0], expected[c])) << "channel " << c;
  }
}

TEST(BvhReaderTest, AcceptsFrameHeaderSpellings) {
  const std::vector<std::pair<std::string, std::string>> spellings = {
      {"Frames: 3", "Frame Time: 0.0083"},   {"Frames:3", "Frame Time:0.0083"},
      {"Frames:\t3", "Frame Time:\t0.0083"}, {"Frames :  3", "Frame\tTime :0.0083"},
      {"  Frames: 3  ", "Frame  Time: 0.0083 \t"},
  };
  for (const auto& [frames, frame_time] : spellings) {
    std::string text = ReplaceAll(kUnixText, "Frames: 3", frames);
    text = ReplaceAll(text, "Frame Time: 0.0333333", frame_time);

    const Clip clip = Parse(text);

    EXPECT_EQ(clip.frame_count, 3) << frames;
    EXPECT_TRUE(SameBits(clip.frame_time_seconds, 0.0083)) << frame_time;
  }
}

TEST(BvhReaderTest, KeepsFrameTimeExactlyAsRead) {
  const std::string text = ReplaceAll(kUnixText, "0.0333333", ".0083333");

  const Clip clip = Parse(text);

  // The double nearest 0.0083333, not 1/120.
  EXPECT_TRUE(SameBits(clip.frame_time_seconds, 0.0083333));
  EXPECT_FALSE(SameBits(clip.frame_time_seconds, 1.0 / 120.0));
}

TEST(BvhReaderTest, NamesTheClipAfterTheFileStem) {
  const Clip clip = Parse(kUnixText, "/captures/day 2/walk.fast.bvh");

  EXPECT_EQ(clip.name, "walk.fast");
}

TEST(BvhReaderTest, PreservesEachJointsChannelOrder) {
  std::string text = ReplaceAll(kUnixText,
                                "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
                                "Yrotation",
                                "CHANNELS 6 Yrotation Zposition Xrotation Xposition Zrotation "
                                "Yposition");
  text = ReplaceAll(text, "CHANNELS 3 Zrotation Xrotation Yrotation",
                    "CHANNELS 3 Xrotation Zrotation Yrotation");

  const Clip clip = Parse(text);

  EXPECT_EQ(ChannelNames(clip, 0),
            (std::vector<std::string>{"Yrotation", "Zposition", "Xrotation", "Xposition",
                                      "Zrotation", "Yposition"}));
  EXPECT_EQ(ChannelNames(clip, 1),
            (std::vector<std::string>{"Xrotation", "Zrotation", "Yrotation"}));
}

TEST(BvhReaderTest, AcceptsOneToSixChannelsAndJointsWithoutChannels) {
  const std::string text =
      "HIERARCHY\n"
      "ROOT Root\n"
      "{\n"
      "\tOFFSET 0 0 0\n"
      "\tCHANNELS 1 Yposition\n"
      "\tJOINT Fixed\n"
      "\t{\n"
      "\t\tOFFSET 0 1 0\n"
      "\t\tJOINT Wrist\n"
      "\t\t{\n"
      "\t\t\tOFFSET 0 1 0\n"
      "\t\t\tCHANNELS 2 Xrotation Zrotation\n"
      "\t\t}\n"
      "\t}\n"
      "}\n"
      "MOTION\n"
      "Frames: 1\n"
      "Frame Time: 0.01\n"
      "7 8 9\n";

  const Clip clip = Parse(text);

  ASSERT_EQ(clip.skeleton.joints.size(), 3u);
  EXPECT_EQ(ChannelNames(clip, 0), (std::vector<std::string>{"Yposition"}));
  EXPECT_TRUE(clip.skeleton.joints[1].channels.empty());
  EXPECT_EQ(ChannelNames(clip, 2), (std::vector<std::string>{"Xrotation", "Zrotation"}));
  EXPECT_EQ(clip.skeleton.joints[2].parent, 1);
  EXPECT_EQ(clip.channels[2].samples, std::vector<double>{9});
}

TEST(BvhReaderTest, MultipleRootsEachStartTheirOwnTree) {
  const std::string text =
      "HIERARCHY\n"
      "ROOT Actor\n"
      "{\n"
      "  OFFSET 0 0 0\n"
      "  CHANNELS 3 Xposition Yposition Zposition\n"
      "  End Site\n"
      "  {\n"
      "    OFFSET 0 1 0\n"
      "  }\n"
      "}\n"
      "ROOT Prop\n"
      "{\n"
      "  OFFSET 5 0 0\n"
      "  CHANNELS 3 Yrotation Xrotation Zrotation\n"
      "  JOINT Lid\n"
      "  {\n"
      "    OFFSET 0 0.5 0\n"
      "    CHANNELS 1 Xrotation\n"
      "  }\n"
      "}\n"
      "MOTION\n"
      "Frames: 2\n"
      "Frame Time: 0.04\n"
      "1 2 3 4 5 6 7\n"
      "8 9 10 11 12 13 14\n";

  const Clip clip = Parse(text);

  ASSERT_EQ(clip.skeleton.joints.size(), 3u);
  EXPECT_EQ(clip.skeleton.joints[0].parent, -1);
  EXPECT_EQ(clip.skeleton.joints[1].name, "Prop");
  EXPECT_EQ(clip.skeleton.joints[1].parent, -1);
  EXPECT_EQ(clip.skeleton.joints[2].parent, 1);
  ASSERT_EQ(clip.channels.size(), 7u);
  EXPECT_EQ(clip.channels[3].joint, 1);
  EXPECT_EQ(clip.channels[3].kind, ChannelKind::kYRotation);
  EXPECT_EQ(clip.channels[6].samples, (std::vector<double>{7, 14}));
  EXPECT_TRUE(ValidateClip(clip).ok());
}

TEST(BvhReaderTest, AcceptsByteOrderMarkAndUtf8JointNames) {
  const std::string text = "\xEF\xBB\xBF" + ReplaceAll(kUnixText, "Spine", "R\xC3\xBC" "cken");

  const Clip clip = Parse(text);

  EXPECT_EQ(clip.skeleton.joints[1].name, "R\xC3\xBC" "cken");
}

TEST(BvhReaderTest, LastRowWithoutNewlineParses) {
  std::string text = kUnixText;
  text.pop_back();

  const Clip clip = Parse(text);

  EXPECT_EQ(clip, Parse(kUnixText));
}

// A clip built by hand with awkward numbers, two roots and differing channel orders.
Clip AwkwardClip() {
  Clip clip;
  clip.name = "awkward";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = 3;
  auto add_joint = [&](std::string name, int parent, Vec3 offset,
                       std::vector<ChannelKind> kinds) {
    Joint joint;
    joint.name = std::move(name);
    joint.parent = parent;
    joint.offset = offset;
    const int index = static_cast<int>(clip.skeleton.joints.size());
    for (ChannelKind kind : kinds) {
      joint.channels.push_back(static_cast<int>(clip.channels.size()));
      clip.channels.push_back(Channel{index, kind, "", {}});
    }
    clip.skeleton.joints.push_back(std::move(joint));
    return index;
  };
  add_joint("Hips", -1, {0.1, 0.2, 0.30000000000000004},
            {ChannelKind::kXPosition, ChannelKind::kYPosition, ChannelKind::kZPosition,
             ChannelKind::kYRotation, ChannelKind::kXRotation, ChannelKind::kZRotation});
  // Every number within the ranges a clip may hold (clip.h), the extremes included.
  const int spine = add_joint("Spine", 0, {-0.0, 1e-300, 1e9},
                              {ChannelKind::kXRotation, ChannelKind::kZRotation,
                               ChannelKind::kYRotation});
  clip.skeleton.joints[spine].end_sites = {{1.0 / 3.0, 2.0 / 3.0, -5e-324}, {7, 8, 9}};
  add_joint("Prop", -1, {3, 2, 1}, {ChannelKind::kZRotation});
  const double awkward[] = {0.1, -0.0, 5e-324, 1.0 / 3.0, 1e9, -123456789.123456789,
                            2.2250738585072014e-308, 999999999.99999988, 0.30000000000000004,
                            6.02214076e-23};
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    for (std::size_t f = 0; f < 3; ++f) {
      const double value = awkward[(3 * c + f) % 10];
      clip.channels[c].samples.push_back(f == 1 ? -value : value);
    }
  }
  return clip;
}

TEST(BvhWriterTest, WriterOutputRereadsBitForBit) {
  const Clip clip = AwkwardClip();

  absl::StatusOr<std::string> text = FormatBvh(clip);
  ASSERT_TRUE(text.ok()) << text.status();
  Clip reread = Parse(*text, "awkward.bvh");

  EXPECT_EQ(reread, clip);  // == on doubles misses -0.0 versus 0.0; the bits below do not
  EXPECT_TRUE(SameBits(reread.frame_time_seconds, clip.frame_time_seconds));
  EXPECT_TRUE(SameBits(reread.skeleton.joints[1].offset[0], -0.0));
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    EXPECT_EQ(std::memcmp(reread.channels[c].samples.data(), clip.channels[c].samples.data(),
                          3 * sizeof(double)),
              0)
        << "channel " << c;
  }
}

TEST(BvhWriterTest, WritesTabIndentedHierarchyAndShortestNumbers) {
  Clip clip;
  clip.frame_time_seconds = 0.0083333;
  clip.frame_count = 2;
  clip.skeleton.joints = {
      Joint{"Hips", -1, {0, 0.5, 0}, {0, 1}, {}},
      Joint{"Head", 0, {0, 10, 0}, {2}, {{0, 1.5, 0}}},
  };
  clip.channels = {
      Channel{0, ChannelKind::kYPosition, "", {1.5, 2}},
      Channel{0, ChannelKind::kZRotation, "", {-0.0, 0.1}},
      Channel{1, ChannelKind::kXRotation, "", {1e-07, 1e9}},
  };

  absl::StatusOr<std::string> text = FormatBvh(clip);

  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_EQ(*text,
            "HIERARCHY\n"
            "ROOT Hips\n"
            "{\n"
            "\tOFFSET 0 0.5 0\n"
            "\tCHANNELS 2 Yposition Zrotation\n"
            "\tJOINT Head\n"
            "\t{\n"
            "\t\tOFFSET 0 10 0\n"
            "\t\tCHANNELS 1 Xrotation\n"
            "\t\tEnd Site\n"
            "\t\t{\n"
            "\t\t\tOFFSET 0 1.5 0\n"
            "\t\t}\n"
            "\t}\n"
            "}\n"
            "MOTION\n"
            "Frames: 2\n"
            "Frame Time: 0.0083333\n"
            "1.5 -0 1e-07\n"
            "2 0.1 1e+09\n");
}

TEST(BvhWriterTest, WritesJointsDepthFirstWhateverTheirOrder) {
  // Joint order Hips, LeftLeg, RightLeg, LeftFoot: valid (parents first) but not depth-first.
  Clip clip;
  clip.frame_count = 1;
  clip.skeleton.joints = {
      Joint{"Hips", -1, {}, {0}, {}},
      Joint{"LeftLeg", 0, {}, {1}, {}},
      Joint{"RightLeg", 0, {}, {2}, {}},
      Joint{"LeftFoot", 1, {}, {3}, {}},
  };
  for (int j = 0; j < 4; ++j) {
    clip.channels.push_back(Channel{j, ChannelKind::kXRotation, "", {static_cast<double>(j)}});
  }

  absl::StatusOr<std::string> text = FormatBvh(clip);
  ASSERT_TRUE(text.ok()) << text.status();
  const Clip reread = Parse(*text);

  ASSERT_EQ(reread.skeleton.joints.size(), 4u);
  EXPECT_EQ(reread.skeleton.joints[2].name, "LeftFoot");
  EXPECT_EQ(reread.skeleton.joints[2].parent, 1);
  EXPECT_EQ(reread.skeleton.joints[3].name, "RightLeg");
  EXPECT_EQ(reread.skeleton.joints[3].parent, 0);
  // Each joint keeps its own samples: the columns moved with the joints.
  for (int j = 0; j < 4; ++j) {
    const Joint& joint = reread.skeleton.joints[j];
    const int original = clip.skeleton.FindJoint(joint.name);
    EXPECT_EQ(reread.channels[joint.channels[0]].samples,
              std::vector<double>{static_cast<double>(original)})
        << joint.name;
  }
}

TEST(BvhWriterTest, RefusesClipWithoutSkeleton) {
  Clip clip;
  clip.frame_count = 1;
  clip.channels = {Channel{-1, ChannelKind::kScalar, "weight", {1.0}}};

  absl::StatusOr<std::string> text = FormatBvh(clip);

  ASSERT_FALSE(text.ok());
  EXPECT_EQ(std::string(text.status().message()),
            "cannot write BVH: the clip has no skeleton (write plain channels as CSV)");
}

TEST(BvhWriterTest, RefusesChannelsThatAreNotOnJoints) {
  Clip clip;
  clip.frame_count = 1;
  clip.skeleton.joints = {Joint{"Hips", -1, {}, {0}, {}}};
  clip.channels = {Channel{0, ChannelKind::kXRotation, "", {1.0}},
                   Channel{-1, ChannelKind::kScalar, "weight", {1.0}}};

  absl::StatusOr<std::string> text = FormatBvh(clip);

  ASSERT_FALSE(text.ok());
  EXPECT_EQ(std::string(text.status().message()),
            "cannot write BVH: channel 1 (weight) is not a joint's position or rotation (write "
            "plain channels as CSV)");
}

TEST(BvhWriterTest, RefusesJointNamesThatWouldNotReadBack) {
  Clip clip;
  clip.frame_count = 1;
  clip.skeleton.joints = {Joint{"Left Hand", -1, {}, {0}, {}}};
  clip.channels = {Channel{0, ChannelKind::kXRotation, "", {1.0}}};

  absl::StatusOr<std::string> text = FormatBvh(clip);

  ASSERT_FALSE(text.ok());
  EXPECT_EQ(std::string(text.status().message()),
            "cannot write BVH: joint 0 name \"Left Hand\" contains whitespace, a brace or a "
            "control character");
}

TEST(BvhWriterTest, RefusesInvalidClip) {
  Clip clip = AwkwardClip();
  clip.channels[4].samples[1] = std::nan("");

  absl::StatusOr<std::string> text = FormatBvh(clip);

  ASSERT_FALSE(text.ok());
  EXPECT_EQ(std::string(text.status().message()), "channel 4 (Hips.Xrotation): sample 1 is NaN");
}

std::vector<std::string> DirectoryEntries(const std::string& directory) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(directory)) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

TEST(BvhFileTest, WriteThenReadIsExactAndLeavesNoTemporaryFiles) {
  const std::string directory = testing::MakeTempDir();
  const std::string path = directory + "/awkward.bvh";
  const Clip clip = AwkwardClip();

  absl::Status written = WriteBvhFile(path, clip);
  absl::StatusOr<Clip> reread = ReadBvhFile(path);

  ASSERT_TRUE(written.ok()) << written;
  ASSERT_TRUE(reread.ok()) << reread.status();
  EXPECT_EQ(*reread, clip);
  EXPECT_EQ(DirectoryEntries(directory), std::vector<std::string>{"awkward.bvh"});
}

TEST(BvhFileTest, FailedWriteLeavesNoFileBehind) {
  const std::string directory = testing::MakeTempDir();
  // The target is an existing directory: the rename fails after the data was written.
  std::filesystem::create_directory(directory + "/taken.bvh");

  absl::Status written = WriteBvhFile(directory + "/taken.bvh", AwkwardClip());

  EXPECT_FALSE(written.ok());
  EXPECT_EQ(DirectoryEntries(directory), std::vector<std::string>{"taken.bvh"});
  EXPECT_TRUE(std::filesystem::is_directory(directory + "/taken.bvh"));
}

TEST(BvhFileTest, ReadingCapsTheFileSizeByTheLimits) {
  const std::string directory = testing::MakeTempDir();
  const std::string path = directory + "/padded.bvh";
  // Valid BVH followed by 20000 bytes of trailing blanks.
  ASSERT_TRUE(WriteBvhFile(path, AwkwardClip()).ok());
  absl::StatusOr<std::string> text = ReadFile(path);
  ASSERT_TRUE(text.ok());
  ASSERT_TRUE(WriteFileAtomically(path, *text + std::string(20000, ' ')).ok());
  const std::int64_t size = static_cast<std::int64_t>(text->size()) + 20000;
  ClipLimits limits;
  limits.max_samples = 100;
  limits.max_joints = 3;

  absl::StatusOr<Clip> clip = ReadBvhFile(path, limits);

  // Cap: 4096 + 25 bytes x 100 samples + 1024 bytes x 3 joints = 9668 bytes.
  ASSERT_FALSE(clip.ok());
  EXPECT_EQ(std::string(clip.status().message()),
            path + ": file is " + std::to_string(size) + " bytes, over the limit of 9668");
}

TEST(BvhFileTest, MissingFileIsNotFoundWithItsPath) {
  const std::string path = testing::MakeTempDir() + "/missing.bvh";

  absl::StatusOr<Clip> clip = ReadBvhFile(path);

  EXPECT_EQ(clip.status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(std::string(clip.status().message()), path + ": no such file");
}

TEST(BvhFileTest, ErrorsInFilesNameThePath) {
  const std::string path = testing::MakeTempDir() + "/bad.bvh";
  ASSERT_TRUE(WriteFileAtomically(path, "HIERARCHY\nROOT Hips\n{\n  OFSET 0 0 0\n").ok());

  absl::StatusOr<Clip> clip = ReadBvhFile(path);

  EXPECT_EQ(std::string(clip.status().message()), path + ":4:3: expected OFFSET, got \"OFSET\"");
}

}  // namespace
}  // namespace tempokey::core
