// CSV channel tables: joint and scalar columns, exact round trips, located errors.
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/csv.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

constexpr double kFrameTime = 1.0 / 30.0;

bool SameBits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

Clip Parse(const std::string& text) {
  absl::StatusOr<Clip> clip = ParseCsv(text, "takes/walk.csv", kFrameTime);
  EXPECT_TRUE(clip.ok()) << clip.status();
  return clip.ok() ? *std::move(clip) : Clip{};
}

std::string ErrorOf(const std::string& text, const ClipLimits& limits = {}) {
  absl::StatusOr<Clip> clip = ParseCsv(text, "x.csv", kFrameTime, limits);
  if (clip.ok()) return "parsed";
  EXPECT_EQ(clip.status().code(), absl::StatusCode::kInvalidArgument);
  return std::string(clip.status().message());
}

TEST(CsvReaderTest, JointColumnsBuildFlatJointsAndOthersBecomeScalars) {
  const Clip clip = Parse(
      "Hips.Xposition,Hips.Zrotation,Spine.Yrotation,weight\n"
      "1,2,3,4\n"
      "5,6,7,8\n");

  EXPECT_EQ(clip.name, "walk");
  EXPECT_EQ(clip.frame_count, 2);
  EXPECT_EQ(clip.frame_time_seconds, kFrameTime);
  ASSERT_EQ(clip.skeleton.joints.size(), 2u);
  EXPECT_EQ(clip.skeleton.joints[0].name, "Hips");
  EXPECT_EQ(clip.skeleton.joints[0].channels, (std::vector<int>{0, 1}));
  EXPECT_EQ(clip.skeleton.joints[1].parent, -1);
  ASSERT_EQ(clip.channels.size(), 4u);
  EXPECT_EQ(clip.channels[1].kind, ChannelKind::kZRotation);
  EXPECT_EQ(clip.channels[3].joint, -1);
  EXPECT_EQ(clip.channels[3].kind, ChannelKind::kScalar);
  EXPECT_EQ(clip.channels[3].name, "weight");
  EXPECT_EQ(clip.channels[2].samples, (std::vector<double>{3, 7}));
  EXPECT_TRUE(ValidateClip(clip).ok());
}

TEST(CsvReaderTest, JointsFollowFirstAppearanceAndKeepColumnOrder) {
  const Clip clip = Parse(
      "Spine.Zrotation,Hips.Yrotation,Spine.Xrotation,rig.v2.Yposition\n"
      "1,2,3,4\n");

  ASSERT_EQ(clip.skeleton.joints.size(), 3u);
  EXPECT_EQ(clip.skeleton.joints[0].name, "Spine");
  EXPECT_EQ(clip.skeleton.joints[0].channels, (std::vector<int>{0, 2}));
  EXPECT_EQ(clip.skeleton.joints[1].name, "Hips");
  EXPECT_EQ(clip.skeleton.joints[2].name, "rig.v2");  // the joint is before the last dot
}

TEST(CsvReaderTest, SkipsATimeOrFrameFirstColumn) {
  for (const std::string index : {"time", "Frame", "TIME"}) {
    const Clip clip = Parse(index + ",Hips.Xrotation\n0.0,1.5\n0.033,2.5\n");

    ASSERT_EQ(clip.channels.size(), 1u) << index;
    EXPECT_EQ(clip.channels[0].samples, (std::vector<double>{1.5, 2.5})) << index;
  }
}

TEST(CsvReaderTest, CrlfBlanksAndBlankLinesParseLikePlainText) {
  const Clip plain = Parse("a,b\n1,2\n3,4\n");

  const Clip messy = Parse("\r\n a , b \r\n 1 ,\t2\r\n\r\n  \n3,4");

  EXPECT_EQ(messy, plain);
}

TEST(CsvReaderTest, ReadsExponentAndSignedNumbersExactly) {
  const Clip clip = Parse("a,b,c,d\n1.2e-05,-3E+2,+0.5,-0\n");

  EXPECT_TRUE(SameBits(clip.channels[0].samples, {1.2e-05}));
  EXPECT_TRUE(SameBits(clip.channels[1].samples, {-300.0}));
  EXPECT_TRUE(SameBits(clip.channels[2].samples, {0.5}));
  EXPECT_TRUE(SameBits(clip.channels[3].samples, {-0.0}));
}

TEST(CsvReaderTest, MalformedTablesFailWithLocatedMessages) {
  ClipLimits small;
  small.max_samples = 3;
  ClipLimits few_frames;
  few_frames.max_frames = 1;

  EXPECT_EQ(ErrorOf(""), "x.csv:1:1: expected a header row of column names, got an empty file");
  EXPECT_EQ(ErrorOf("\n \n"), "x.csv:3:1: expected a header row of column names, got end of file");
  EXPECT_EQ(ErrorOf("a,b\n"),
            "x.csv:2:1: expected at least one row of values after the header, got end of file");
  EXPECT_EQ(ErrorOf("a,b\n1\n"), "x.csv:2:2: row 1 has 1 field, expected 2");
  EXPECT_EQ(ErrorOf("a,b\n1,2\n1,2,3\n"), "x.csv:3:5: row 2 has 3 fields, expected 2");
  EXPECT_EQ(ErrorOf("a,b\n1,x\n"), "x.csv:2:3: expected a number, got \"x\"");
  EXPECT_EQ(ErrorOf("a,b\n1,nan\n"), "x.csv:2:3: expected a finite number, got \"nan\"");
  EXPECT_EQ(ErrorOf("a,b\n1,-inf\n"), "x.csv:2:3: expected a finite number, got \"-inf\"");
  EXPECT_EQ(ErrorOf("a,b\n1, 1.2.3\n"), "x.csv:2:4: malformed number \"1.2.3\"");
  EXPECT_EQ(ErrorOf("a,b\n1,\n"), "x.csv:2:3: expected a number, got an empty field");
  EXPECT_EQ(ErrorOf("a,b\n1,2 3\n"), "x.csv:2:3: malformed number \"2 3\"");
  EXPECT_EQ(ErrorOf("a,a\n1,2\n"), "x.csv:1:3: duplicate column name \"a\", first in column 1");
  EXPECT_EQ(ErrorOf("a,,b\n1,2,3\n"), "x.csv:1:3: expected a column name, got an empty field");
  EXPECT_EQ(ErrorOf("\"a\",b\n1,2\n"),
            "x.csv:1:1: quoted column names are not supported, got \"\\\"a\\\"\"");
  EXPECT_EQ(ErrorOf(std::string("a,b\n1,\0\n", 8)),
            "x.csv:2:3: unexpected byte 0x00; the file looks binary, not CSV text");
  EXPECT_EQ(ErrorOf("time\n0\n"),
            "x.csv:1:5: expected at least one channel column after the index column");
  EXPECT_EQ(ErrorOf("a,b\n1,2\n3,4\n", small),
            "x.csv:3:1: 2 rows x 2 channels is over the limit of 3 samples");
  EXPECT_EQ(ErrorOf("a\n1\n2\n", few_frames), "x.csv:3:1: row 2 is over the limit of 1 frames");
}

TEST(CsvReaderTest, RefusesFrameTimeOutsideItsRange) {
  absl::StatusOr<Clip> zero = ParseCsv("a\n1\n", "x.csv", 0.0);
  absl::StatusOr<Clip> subnormal = ParseCsv("a\n1\n", "x.csv", 1e-320);

  EXPECT_EQ(std::string(zero.status().message()),
            "frame time must be in [1e-06, 3600] seconds, got 0");
  EXPECT_EQ(std::string(subnormal.status().message()),
            "frame time must be in [1e-06, 3600] seconds, got 9.99989e-321");
}

TEST(CsvReaderTest, RefusesSamplesBeyondABillionWithTheirPlace) {
  EXPECT_EQ(ErrorOf("a,b\n1,2\n3,-4e9\n"),
            "x.csv:3:3: sample \"-4e9\" is beyond the +-1e+09 a clip may hold");
}

TEST(CsvWriterTest, WritesHeaderThenOneRowPerFrame) {
  Clip clip;
  clip.frame_count = 2;
  clip.skeleton.joints = {Joint{"Hips", -1, {}, {0}, {}}};
  clip.channels = {Channel{0, ChannelKind::kYRotation, "", {0.1, -0.0}},
                   Channel{-1, ChannelKind::kScalar, "weight", {1e-07, 1e9}}};

  absl::StatusOr<std::string> text = FormatCsv(clip);

  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_EQ(*text, "Hips.Yrotation,weight\n0.1,1e-07\n-0,1e+09\n");
}

TEST(CsvWriterTest, FormatThenParseKeepsNamesAndSamplesBitForBit) {
  absl::StatusOr<Clip> bvh = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(bvh.ok()) << bvh.status();

  absl::StatusOr<std::string> text = FormatCsv(*bvh);
  ASSERT_TRUE(text.ok()) << text.status();
  absl::StatusOr<Clip> csv = ParseCsv(*text, "131_01.csv", bvh->frame_time_seconds);

  ASSERT_TRUE(csv.ok()) << csv.status();
  EXPECT_EQ(csv->frame_count, bvh->frame_count);
  ASSERT_EQ(csv->channels.size(), bvh->channels.size());
  for (std::size_t c = 0; c < bvh->channels.size(); ++c) {
    const int index = static_cast<int>(c);
    EXPECT_EQ(ChannelName(*csv, index), ChannelName(*bvh, index));
    EXPECT_TRUE(SameBits(csv->channels[c].samples, bvh->channels[c].samples)) << "channel " << c;
  }
  // Joints come back flat, in order of first appearance, which for BVH is file order.
  ASSERT_EQ(csv->skeleton.joints.size(), bvh->skeleton.joints.size());
  for (std::size_t j = 0; j < bvh->skeleton.joints.size(); ++j) {
    EXPECT_EQ(csv->skeleton.joints[j].name, bvh->skeleton.joints[j].name);
    EXPECT_EQ(csv->skeleton.joints[j].channels, bvh->skeleton.joints[j].channels);
    EXPECT_EQ(csv->skeleton.joints[j].parent, -1);
  }
}

TEST(CsvWriterTest, RefusesNamesThatWouldNotReadBack) {
  auto error_for = [](const std::string& name) {
    Clip clip;
    clip.frame_count = 1;
    clip.channels = {Channel{-1, ChannelKind::kScalar, name, {1.0}}};
    absl::StatusOr<std::string> text = FormatCsv(clip);
    return text.ok() ? std::string("written") : std::string(text.status().message());
  };

  EXPECT_EQ(error_for("a,b"),
            "cannot write CSV: channel 0 (a,b): the column name contains a comma, a quote or a "
            "line break");
  EXPECT_EQ(error_for("Hips.Xrotation"),
            "cannot write CSV: channel 0 (Hips.Xrotation): a scalar channel named like a joint "
            "channel reads back as one");
  EXPECT_EQ(error_for("time"),
            "cannot write CSV: channel 0 (time): a first column named time or frame is read back "
            "as an index and skipped");
  EXPECT_EQ(error_for(" pad"),
            "cannot write CSV: channel 0 ( pad): the column name starts or ends with whitespace");
  EXPECT_EQ(error_for("weight"), "written");
}

TEST(CsvWriterTest, FirstColumnNamedWithAByteOrderMarkIsRefusedNotRenamed) {
  // Found by fuzzing (csv_fuzz): "\r\xEF\xBB\xBF\r2" reads as one column named by the byte order
  // mark (not at the start of the text, so not dropped); written, the mark leads the text, the
  // reader drops it and finds no rows at all.
  absl::StatusOr<Clip> clip = ParseCsv("\r\xEF\xBB\xBF\r2", "bom.csv", kFrameTime);
  ASSERT_TRUE(clip.ok()) << clip.status();
  ASSERT_EQ(clip->channels.size(), 1u);

  const absl::StatusOr<std::string> text = FormatCsv(*clip);

  EXPECT_EQ(text.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(text.status().message()),
            "cannot write CSV: channel 0 (\xEF\xBB\xBF): a first column name starting with a byte "
            "order mark loses it when read back");
}

TEST(CsvWriterTest, RefusesTwoChannelsWithOneName) {
  Clip clip;
  clip.frame_count = 1;
  clip.channels = {Channel{-1, ChannelKind::kScalar, "w", {1.0}},
                   Channel{-1, ChannelKind::kScalar, "w", {2.0}}};

  absl::StatusOr<std::string> text = FormatCsv(clip);

  ASSERT_FALSE(text.ok());
  EXPECT_EQ(std::string(text.status().message()),
            "cannot write CSV: channel 1 (w) has the same name as channel 0 (w)");
}

TEST(CsvFileTest, WriteThenReadIsExact) {
  const std::string path = testing::MakeTempDir() + "/table.csv";
  Clip clip;
  clip.frame_count = 3;
  clip.frame_time_seconds = 0.0083333;
  clip.channels = {Channel{-1, ChannelKind::kScalar, "a", {0.1, 0.30000000000000004, 5e-324}}};

  absl::Status written = WriteCsvFile(path, clip);
  absl::StatusOr<Clip> read = ReadCsvFile(path, clip.frame_time_seconds);

  ASSERT_TRUE(written.ok()) << written;
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_TRUE(SameBits(read->channels[0].samples, clip.channels[0].samples));
  EXPECT_EQ(read->name, "table");
}

}  // namespace
}  // namespace tempokey::core
