// Malformed BVH input: each case fails with its exact message, location included; none crashes.
#include <ostream>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"

namespace tempokey::core {
namespace {

// A valid two-joint clip; cases edit one line of it. Line numbers, for reading the cases:
//  1 HIERARCHY            8     OFFSET 0 1 0            15 }
//  2 ROOT Hips            9     CHANNELS 3 Z.. X.. Y..  16 MOTION
//  3 {                   10     End Site                17 Frames: 2
//  4   OFFSET 0 0 0      11     {                       18 Frame Time: 0.0333333
//  5   CHANNELS 6 ...    12       OFFSET 0 1 0          19 0 1 2 3 4 5 6 7 8
//  6   JOINT Spine       13     }                       20 8 7 6 5 4 3 2 1 0
//  7   {                 14   }
const std::vector<std::string> kValidLines = {
    "HIERARCHY",
    "ROOT Hips",
    "{",
    "  OFFSET 0 0 0",
    "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
    "  JOINT Spine",
    "  {",
    "    OFFSET 0 1 0",
    "    CHANNELS 3 Zrotation Xrotation Yrotation",
    "    End Site",
    "    {",
    "      OFFSET 0 1 0",
    "    }",
    "  }",
    "}",
    "MOTION",
    "Frames: 2",
    "Frame Time: 0.0333333",
    "0 1 2 3 4 5 6 7 8",
    "8 7 6 5 4 3 2 1 0",
};

std::string Join(const std::vector<std::string>& lines) {
  std::string text;
  for (const std::string& line : lines) text += line + "\n";
  return text;
}

// The valid text with line `number` (1-based) replaced.
std::string WithLine(int number, const std::string& replacement) {
  std::vector<std::string> lines = kValidLines;
  lines[number - 1] = replacement;
  return Join(lines);
}

std::string WithoutLine(int number) {
  std::vector<std::string> lines = kValidLines;
  lines.erase(lines.begin() + (number - 1));
  return Join(lines);
}

// The first `count` lines of the valid text.
std::string FirstLines(int count) {
  return Join(std::vector<std::string>(kValidLines.begin(), kValidLines.begin() + count));
}

ClipLimits LimitsWith(void (*edit)(ClipLimits&)) {
  ClipLimits limits;
  edit(limits);
  return limits;
}

struct MalformedCase {
  std::string name;
  std::string text;
  std::string expected_message;
  ClipLimits limits = {};
};

std::vector<MalformedCase> Cases() {
  return {
      {"EmptyFile", "", "walk.bvh:1:1: expected HIERARCHY, got an empty file"},
      {"OnlyWhitespace", " \t\n\n", "walk.bvh:3:1: expected HIERARCHY, got end of file"},
      {"BinaryGarbage", std::string("\x7f" "ELF\x02\x01\x01\x00\x00", 9),
       "walk.bvh:1:1: unexpected byte 0x7f; the file looks binary, not BVH text"},
      {"NulByteInMotionRow", WithLine(19, std::string("0 1 2\0 3 4 5 6 7 8", 18)),
       "walk.bvh:19:6: unexpected byte 0x00; the file looks binary, not BVH text"},
      {"InvalidUtf8InJointName", WithLine(6, "  JOINT Sp\xffine"),
       "walk.bvh:6:11: unexpected byte 0xff; the file looks binary, not BVH text"},
      {"MissingHierarchyKeyword", WithoutLine(1), "walk.bvh:1:1: expected HIERARCHY, got \"ROOT\""},
      {"TruncatedHierarchy", FirstLines(9),
       "walk.bvh:10:1: expected '}' closing joint \"Spine\" from line 7, got end of file"},
      {"TruncatedInsideOffset", FirstLines(3) + "  OFFSET 0 0",
       "walk.bvh:4:13: expected 3 numbers after OFFSET, found 2"},
      {"UnknownKeyword", WithLine(9, "    ROTATION 3 Zrotation Xrotation Yrotation"),
       "walk.bvh:9:5: expected CHANNELS, JOINT, End Site or '}', got \"ROTATION\""},
      {"OffsetAfterChannels", WithLine(10, "    OFFSET 1 2 3"),
       "walk.bvh:10:5: expected JOINT, End Site or '}', got \"OFFSET\""},
      {"MissingOpeningBrace", WithoutLine(7),
       "walk.bvh:7:5: expected '{' after joint name, got \"OFFSET\""},
      {"MissingClosingBrace", WithoutLine(15),
       "walk.bvh:15:1: expected JOINT, End Site or '}', got \"MOTION\""},
      {"JointWithoutName", WithLine(6, "  JOINT"),
       "walk.bvh:6:8: expected a joint name after JOINT, got end of line"},
      {"EndWithoutSite", WithLine(10, "    End Sight"),
       "walk.bvh:10:9: expected Site after End, got \"Sight\""},
      {"ChannelCountAboveNames", WithLine(9, "    CHANNELS 4 Zrotation Xrotation Yrotation"),
       "walk.bvh:9:14: CHANNELS declares 4 channels but 3 names follow"},
      {"ChannelCountBelowNames", WithLine(9, "    CHANNELS 2 Zrotation Xrotation Yrotation"),
       "walk.bvh:9:14: CHANNELS declares 2 channels but 3 names follow"},
      {"ChannelCountNotANumber", WithLine(9, "    CHANNELS three Zrotation Xrotation Yrotation"),
       "walk.bvh:9:14: expected a channel count from 1 to 6 after CHANNELS, got \"three\""},
      {"ChannelCountOverSix", WithLine(9, "    CHANNELS 7 Zrotation Xrotation Yrotation"),
       "walk.bvh:9:14: expected a channel count from 1 to 6 after CHANNELS, got \"7\""},
      {"UnknownChannelName", WithLine(9, "    CHANNELS 3 Zrotation Xrot Yrotation"),
       "walk.bvh:9:26: unknown channel name \"Xrot\", expected Xposition, Yposition, Zposition, "
       "Xrotation, Yrotation or Zrotation"},
      {"DuplicateChannel", WithLine(9, "    CHANNELS 3 Zrotation Xrotation Zrotation"),
       "walk.bvh:9:36: channel Zrotation appears twice on joint \"Spine\""},
      {"DuplicateJointName", WithLine(6, "  JOINT Hips"),
       "walk.bvh:6:9: duplicate joint name \"Hips\", first defined on line 2"},
      {"NestedDeeperThanLimit", Join(kValidLines),
       "walk.bvh:6:3: joint \"Spine\" is nested 2 deep, over the limit of 1",
       LimitsWith([](ClipLimits& l) { l.max_depth = 1; })},
      {"MoreJointsThanLimit", Join(kValidLines),
       "walk.bvh:6:3: joint \"Spine\" is over the limit of 1 joints",
       LimitsWith([](ClipLimits& l) { l.max_joints = 1; })},
      {"MoreChannelsThanLimit", Join(kValidLines),
       "walk.bvh:9:36: channel 9 (Spine.Yrotation) is over the limit of 8 channels",
       LimitsWith([](ClipLimits& l) { l.max_channels = 8; })},
      {"OffsetOutOfRange", WithLine(8, "    OFFSET 0 1e999 0"),
       "walk.bvh:8:14: number \"1e999\" is out of range for a double"},
      {"OffsetNotANumber", WithLine(8, "    OFFSET 0 one 0"),
       "walk.bvh:8:14: expected a number, got \"one\""},
      {"MissingMotion", WithoutLine(16), "walk.bvh:16:1: expected ROOT or MOTION, got \"Frames:\""},
      {"MissingFrames", WithoutLine(17), "walk.bvh:17:1: expected \"Frames:\", got \"Frame\""},
      {"NegativeFrameCount", WithLine(17, "Frames: -3"),
       "walk.bvh:17:9: expected at least 1 frame after \"Frames:\", got \"-3\""},
      {"ZeroFrameCount", WithLine(17, "Frames: 0"),
       "walk.bvh:17:9: expected at least 1 frame after \"Frames:\", got \"0\""},
      {"FractionalFrameCount", WithLine(17, "Frames: 2.5"),
       "walk.bvh:17:9: expected a whole number of frames after \"Frames:\", got \"2.5\""},
      {"AbsurdFrameCount", WithLine(17, "Frames: 99999999999999999999999"),
       "walk.bvh:17:9: frame count \"99999999999999999999999\" is out of range"},
      {"FrameCountOverLimit", WithLine(17, "Frames: 20000000"),
       "walk.bvh:17:9: Frames: 20000000 is over the limit of 10000000 frames"},
      {"SamplesOverLimit", Join(kValidLines),
       "walk.bvh:17:9: 2 frames x 9 channels is over the limit of 10 samples",
       LimitsWith([](ClipLimits& l) { l.max_samples = 10; })},
      {"MissingFrameTime", WithoutLine(18), "walk.bvh:18:1: expected \"Frame Time:\", got \"0\""},
      {"FrameTimeWithoutValue", WithLine(18, "Frame Time:"),
       "walk.bvh:18:12: expected a frame time in seconds after \"Frame Time:\", got end of line"},
      {"ZeroFrameTime", WithLine(18, "Frame Time: 0"),
       "walk.bvh:18:13: expected a frame time > 0 seconds, got \"0\""},
      {"SubnormalFrameTime", WithLine(18, "Frame Time: 1e-320"),
       "walk.bvh:18:13: frame time must be in [1e-06, 3600] seconds, got 9.99989e-321"},
      {"HugeFrameTime", WithLine(18, "Frame Time: 1e308"),
       "walk.bvh:18:13: frame time must be in [1e-06, 3600] seconds, got 1e+308"},
      {"HugeOffset", WithLine(8, "    OFFSET 0 1e10 0"),
       "walk.bvh:8:14: offset \"1e10\" is beyond the +-1e+09 a clip may hold"},
      {"HugeSample", WithLine(20, "8 7 6 5 -2e9 3 2 1 0"),
       "walk.bvh:20:9: sample \"-2e9\" is beyond the +-1e+09 a clip may hold"},
      {"NegativeFrameTime", WithLine(18, "Frame Time: -0.0333333"),
       "walk.bvh:18:13: expected a frame time > 0 seconds, got \"-0.0333333\""},
      {"NanFrameTime", WithLine(18, "Frame Time: nan"),
       "walk.bvh:18:13: expected a finite number, got \"nan\""},
      {"NanSample", WithLine(19, "0 1 2 nan 4 5 6 7 8"),
       "walk.bvh:19:7: expected a finite number, got \"nan\""},
      {"InfinitySample", WithLine(20, "8 7 6 5 4 3 2 1 -inf"),
       "walk.bvh:20:17: expected a finite number, got \"-inf\""},
      {"MalformedNumber", WithLine(19, "0 1.2.3 2 3 4 5 6 7 8"),
       "walk.bvh:19:3: malformed number \"1.2.3\""},
      {"WordInMotionRow", WithLine(19, "0 1 2 3 four 5 6 7 8"),
       "walk.bvh:19:9: expected a number, got \"four\""},
      {"ShortMotionRow", WithLine(19, "0 1 2 3 4 5 6 7"),
       "walk.bvh:19:16: motion row 1 has 8 values, expected 9"},
      {"LongMotionRow", WithLine(20, "8 7 6 5 4 3 2 1 0 9 10"),
       "walk.bvh:20:19: motion row 2 has 11 values, expected 9"},
      {"FewerRowsThanFrames", WithoutLine(20),
       "walk.bvh:20:1: expected 2 motion rows (Frames: 2), found 1"},
      {"FrameCountFarBeyondText", WithLine(17, "Frames: 10000000"),
       "walk.bvh:21:1: expected 10000000 motion rows (Frames: 10000000), found 2"},
      {"RowCutShortAtEndOfFile", FirstLines(19) + "8 7 6",
       "walk.bvh:20:6: motion row 2 has 3 values, expected 9"},
      {"TextAfterLastRow", Join(kValidLines) + "junk\n",
       "walk.bvh:21:1: expected end of file after 2 motion rows, got \"junk\""},
  };
}

void PrintTo(const MalformedCase& c, std::ostream* os) { *os << c.name; }

class BvhMalformedTest : public ::testing::TestWithParam<MalformedCase> {};

TEST_P(BvhMalformedTest, FailsWithExactMessage) {
  const MalformedCase& c = GetParam();

  absl::StatusOr<Clip> clip = ParseBvh(c.text, "walk.bvh", c.limits);

  ASSERT_FALSE(clip.ok());
  EXPECT_EQ(clip.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(std::string(clip.status().message()), c.expected_message);
}

// Converting every line ending to CRLF changes neither the line nor the column of an error.
TEST_P(BvhMalformedTest, CrlfTextReportsTheSameLocationAsLf) {
  const MalformedCase& c = GetParam();
  std::string crlf;
  for (char ch : c.text) {
    if (ch == '\n') crlf += '\r';
    crlf += ch;
  }

  absl::StatusOr<Clip> clip = ParseBvh(crlf, "walk.bvh", c.limits);

  ASSERT_FALSE(clip.ok());
  EXPECT_EQ(std::string(clip.status().message()), c.expected_message);
}

INSTANTIATE_TEST_SUITE_P(Table, BvhMalformedTest, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<MalformedCase>& param) {
                           return param.param.name;
                         });

TEST(BvhMalformedTableTest, BaseTextIsValid) {
  const std::string text = Join(kValidLines);

  absl::StatusOr<Clip> clip = ParseBvh(text, "walk.bvh");

  // Otherwise a case could fail for a reason other than its own edit.
  ASSERT_TRUE(clip.ok()) << clip.status();
  EXPECT_EQ(clip->channels.size(), 9u);
  EXPECT_EQ(clip->frame_count, 2);
}

TEST(BvhMalformedTableTest, TableCoversAtLeastFifteenInputs) {
  EXPECT_GE(Cases().size(), 15u);
}

// Every proper prefix of a valid file fails, except the one missing only its final newline:
// no crash, no hang, no partial clip.
TEST(BvhMalformedTableTest, EveryTruncationFailsCleanly) {
  const std::string text = Join(kValidLines);

  for (std::size_t length = 0; length + 1 < text.size(); ++length) {
    absl::StatusOr<Clip> clip = ParseBvh(text.substr(0, length), "walk.bvh");

    EXPECT_FALSE(clip.ok()) << "prefix of " << length << " bytes";
  }
  EXPECT_TRUE(ParseBvh(text.substr(0, text.size() - 1), "walk.bvh").ok());
}

// A NUL byte anywhere is reported as binary data.
TEST(BvhMalformedTableTest, NulByteAnywhereIsReportedAsBinary) {
  const std::string text = Join(kValidLines);

  for (std::size_t i = 0; i < text.size(); ++i) {
    std::string corrupt = text;
    corrupt[i] = '\0';

    absl::StatusOr<Clip> clip = ParseBvh(corrupt, "walk.bvh");

    ASSERT_FALSE(clip.ok()) << "byte " << i;
    EXPECT_NE(clip.status().message().find("unexpected byte 0x00; the file looks binary"),
              absl::string_view::npos)
        << clip.status();
  }
}

// Any single byte replaced by a brace or a letter fails or yields a clip that passes
// ValidateClip(): the parser never hands out a broken clip.
TEST(BvhMalformedTableTest, SingleByteCorruptionFailsOrYieldsValidClip) {
  const std::string text = Join(kValidLines);

  for (char replacement : {'{', '}', 'x', '-', '.'}) {
    for (std::size_t i = 0; i < text.size(); ++i) {
      std::string corrupt = text;
      corrupt[i] = replacement;

      absl::StatusOr<Clip> clip = ParseBvh(corrupt, "walk.bvh");

      if (clip.ok()) {
        EXPECT_TRUE(ValidateClip(*clip).ok()) << "byte " << i << " -> " << replacement;
      } else {
        EXPECT_EQ(clip.status().code(), absl::StatusCode::kInvalidArgument);
      }
    }
  }
}

}  // namespace
}  // namespace tempokey::core
