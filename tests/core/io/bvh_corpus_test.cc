// Every shared capture reads, writes and reads back bit for bit, and reads as the file says.
#include <cctype>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tests/testing/bit_digest.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

// What a plain line-by-line scan of the text says, independently of ParseBvh's tokenizer.
struct ScannedBvh {
  std::vector<std::string> joint_names;               // ROOT and JOINT lines, in order
  std::vector<std::vector<std::string>> channel_lines;  // names on each CHANNELS line
  std::int64_t declared_channels = 0;                 // sum of the CHANNELS counts
  std::int64_t frames = -1;
  double frame_time = 0.0;
  std::vector<std::string> first_row;
  std::vector<std::string> last_row;
};

std::vector<std::string> SplitLines(const std::string& text) {
  std::vector<std::string> lines;
  std::string line;
  for (char c : text) {
    if (c == '\n') {
      lines.push_back(line);
      line.clear();
    } else if (c != '\r') {
      line += c;
    }
  }
  if (!line.empty()) lines.push_back(line);
  return lines;
}

std::vector<std::string> Words(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> words;
  for (std::string word; in >> word;) words.push_back(word);
  return words;
}

ScannedBvh Scan(const std::string& text) {
  ScannedBvh scanned;
  bool in_motion = false;
  std::vector<std::string> rows;
  for (const std::string& line : SplitLines(text)) {
    const std::vector<std::string> words = Words(line);
    if (words.empty()) continue;
    if (in_motion) {
      if (words[0] == "Frames:") {
        scanned.frames = std::strtoll(words[1].c_str(), nullptr, 10);
      } else if (words[0] == "Frame" && words.size() == 3) {
        scanned.frame_time = std::strtod(words[2].c_str(), nullptr);
      } else {
        rows.push_back(line);
      }
      continue;
    }
    if (words[0] == "ROOT" || words[0] == "JOINT") scanned.joint_names.push_back(words[1]);
    if (words[0] == "CHANNELS") {
      scanned.declared_channels += std::strtoll(words[1].c_str(), nullptr, 10);
      scanned.channel_lines.emplace_back(words.begin() + 2, words.end());
    }
    if (words[0] == "MOTION") in_motion = true;
  }
  if (!rows.empty()) {
    scanned.first_row = Words(rows.front());
    scanned.last_row = Words(rows.back());
  }
  return scanned;
}

using ::tempokey::testing::SameBits;

// Joints, parents, offsets, end sites, channel kinds and every sample bit for bit.
void ExpectBitIdentical(const Clip& expected, const Clip& actual) {
  EXPECT_TRUE(SameBits(expected.frame_time_seconds, actual.frame_time_seconds));
  EXPECT_EQ(expected.frame_count, actual.frame_count);
  ASSERT_EQ(expected.skeleton.joints.size(), actual.skeleton.joints.size());
  for (std::size_t j = 0; j < expected.skeleton.joints.size(); ++j) {
    const Joint& a = expected.skeleton.joints[j];
    const Joint& b = actual.skeleton.joints[j];
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.parent, b.parent) << a.name;
    EXPECT_EQ(a.channels, b.channels) << a.name;
    for (int axis = 0; axis < 3; ++axis) {
      EXPECT_TRUE(SameBits(a.offset[axis], b.offset[axis])) << a.name << " axis " << axis;
    }
    ASSERT_EQ(a.end_sites.size(), b.end_sites.size()) << a.name;
    for (std::size_t e = 0; e < a.end_sites.size(); ++e) {
      for (int axis = 0; axis < 3; ++axis) {
        EXPECT_TRUE(SameBits(a.end_sites[e][axis], b.end_sites[e][axis])) << a.name;
      }
    }
  }
  ASSERT_EQ(expected.channels.size(), actual.channels.size());
  for (std::size_t c = 0; c < expected.channels.size(); ++c) {
    const Channel& a = expected.channels[c];
    const Channel& b = actual.channels[c];
    EXPECT_EQ(a.joint, b.joint);
    EXPECT_EQ(a.kind, b.kind);
    ASSERT_EQ(a.samples.size(), b.samples.size());
    ASSERT_EQ(std::memcmp(a.samples.data(), b.samples.data(), a.samples.size() * sizeof(double)),
              0)
        << "channel " << c;
  }
}

class BvhCorpusTest : public ::testing::TestWithParam<std::string> {};

TEST_P(BvhCorpusTest, FormatThenParseIsBitIdentical) {
  absl::StatusOr<Clip> read = ReadBvhFile(GetParam());
  ASSERT_TRUE(read.ok()) << read.status();

  absl::StatusOr<std::string> written = FormatBvh(*read);
  ASSERT_TRUE(written.ok()) << written.status();
  absl::StatusOr<Clip> reread = ParseBvh(*written, "rewritten.bvh");

  ASSERT_TRUE(reread.ok()) << reread.status();
  ExpectBitIdentical(*read, *reread);
  EXPECT_EQ(reread->name, "rewritten");
}

TEST_P(BvhCorpusTest, ReadsWhatAPlainScanOfTheFileSays) {
  absl::StatusOr<std::string> text = ReadFile(GetParam());
  ASSERT_TRUE(text.ok()) << text.status();
  const ScannedBvh scanned = Scan(*text);

  absl::StatusOr<Clip> clip = ParseBvh(*text, GetParam());

  ASSERT_TRUE(clip.ok()) << clip.status();
  ASSERT_EQ(clip->skeleton.joints.size(), scanned.joint_names.size());
  for (std::size_t j = 0; j < scanned.joint_names.size(); ++j) {
    EXPECT_EQ(clip->skeleton.joints[j].name, scanned.joint_names[j]);
  }
  EXPECT_EQ(static_cast<std::int64_t>(clip->channels.size()), scanned.declared_channels);
  // Every CHANNELS line belongs to the joints in order; joints without channels have none.
  std::vector<std::vector<std::string>> parsed_lines;
  for (const Joint& joint : clip->skeleton.joints) {
    if (joint.channels.empty()) continue;
    std::vector<std::string> names;
    for (int c : joint.channels) names.emplace_back(ChannelKindName(clip->channels[c].kind));
    parsed_lines.push_back(names);
  }
  EXPECT_EQ(parsed_lines, scanned.channel_lines);
  EXPECT_EQ(clip->frame_count, scanned.frames);
  EXPECT_TRUE(SameBits(clip->frame_time_seconds, scanned.frame_time));
  // The first and last rows, transposed into channel-major storage, match strtod of the text.
  ASSERT_EQ(scanned.first_row.size(), clip->channels.size());
  ASSERT_EQ(scanned.last_row.size(), clip->channels.size());
  const std::size_t last = static_cast<std::size_t>(clip->frame_count) - 1;
  for (std::size_t c = 0; c < clip->channels.size(); ++c) {
    EXPECT_TRUE(SameBits(clip->channels[c].samples[0],
                         std::strtod(scanned.first_row[c].c_str(), nullptr)))
        << "channel " << c << " frame 0";
    EXPECT_TRUE(SameBits(clip->channels[c].samples[last],
                         std::strtod(scanned.last_row[c].c_str(), nullptr)))
        << "channel " << c << " last frame";
  }
}

std::string TestNameFromPath(const ::testing::TestParamInfo<std::string>& info) {
  std::string name;
  const std::string& path = info.param;
  const std::size_t slash = path.rfind('/');
  for (char c : path.substr(slash == std::string::npos ? 0 : slash + 1)) {
    name += std::isalnum(static_cast<unsigned char>(c)) ? c : '_';
  }
  return name;
}

INSTANTIATE_TEST_SUITE_P(SharedData, BvhCorpusTest,
                         ::testing::ValuesIn(testing::AllSharedBvhFiles()), TestNameFromPath);

TEST(BvhCorpusFilesTest, CorpusHoldsTheCmuAndBandaiCaptures) {
  const std::vector<std::string> files = testing::AllSharedBvhFiles();

  // One CMU and seven Bandai files; fewer would make the corpus tests prove less.
  EXPECT_GE(files.size(), 8u);
}

TEST(BvhCorpusFilesTest, CmuCaptureHasItsKnownShape) {
  const std::string path = testing::SharedBvh("cmu/131_01.bvh");
  absl::StatusOr<std::string> text = ReadFile(path);
  ASSERT_TRUE(text.ok()) << text.status();
  const ScannedBvh scanned = Scan(*text);

  absl::StatusOr<Clip> clip = ParseBvh(*text, path);

  ASSERT_TRUE(clip.ok()) << clip.status();
  EXPECT_EQ(scanned.joint_names.size(), 31u);
  EXPECT_EQ(clip->skeleton.joints.size(), 31u);
  EXPECT_EQ(clip->frame_count, 994);
  EXPECT_EQ(clip->channels.size(), 96u);
  EXPECT_TRUE(SameBits(clip->frame_time_seconds, 0.0083333));  // written ".0083333"
  EXPECT_EQ(clip->name, "131_01");
  const Joint& root = clip->skeleton.joints[0];
  EXPECT_EQ(root.name, "Hips");
  EXPECT_EQ(root.parent, -1);
  ASSERT_EQ(root.channels.size(), 6u);
  const ChannelKind expected_root[] = {ChannelKind::kXPosition, ChannelKind::kYPosition,
                                       ChannelKind::kZPosition, ChannelKind::kZRotation,
                                       ChannelKind::kYRotation, ChannelKind::kXRotation};
  for (int i = 0; i < 6; ++i) EXPECT_EQ(clip->channels[root.channels[i]].kind, expected_root[i]);
  for (std::size_t j = 1; j < clip->skeleton.joints.size(); ++j) {
    EXPECT_EQ(clip->skeleton.joints[j].channels.size(), 3u) << clip->skeleton.joints[j].name;
  }
}

TEST(BvhCorpusFilesTest, BandaiCapturesHaveSixZxyChannelsOnEveryJoint) {
  const ChannelKind expected[] = {ChannelKind::kXPosition, ChannelKind::kYPosition,
                                  ChannelKind::kZPosition, ChannelKind::kZRotation,
                                  ChannelKind::kXRotation, ChannelKind::kYRotation};
  int bandai_files = 0;
  for (const std::string& path : testing::AllSharedBvhFiles()) {
    if (path.find("/bandai/") == std::string::npos) continue;
    ++bandai_files;

    absl::StatusOr<Clip> clip = ReadBvhFile(path);

    ASSERT_TRUE(clip.ok()) << clip.status();
    EXPECT_EQ(clip->channels.size(), 132u) << path;
    EXPECT_TRUE(SameBits(clip->frame_time_seconds, 0.0333333)) << path;
    for (const Joint& joint : clip->skeleton.joints) {
      ASSERT_EQ(joint.channels.size(), 6u) << path << " " << joint.name;
      for (int i = 0; i < 6; ++i) {
        EXPECT_EQ(clip->channels[joint.channels[i]].kind, expected[i]) << path << " " << joint.name;
      }
    }
  }
  EXPECT_EQ(bandai_files, 7);
}

}  // namespace
}  // namespace tempokey::core
