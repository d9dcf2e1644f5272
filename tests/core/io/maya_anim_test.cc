// Maya .anim export, checked by an evaluator written from Maya's published semantics
// (tests/testing/maya_anim_eval.h), never by re-reading with the writer's own conversions.
#include "tempokey/core/io/maya_anim.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <initializer_list>
#include <map>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/maya_anim_eval.h"
#include "tests/testing/test_paths.h"

namespace tempokey::core {
namespace {

using ::testing::HasSubstr;
using testing::EvaluateMayaCurve;
using testing::MayaAnimFile;
using testing::MayaCurveBlock;
using testing::MayaKeyLine;
using testing::ParseMayaAnimText;

// Values printed with 6 to 8 significant digits, as in the real Maya export below.
constexpr double kPrintedDigits = 1e-6;
// Our own files: shortest round-trip numbers, one atan/tan or atan2/cos/sin each way.
constexpr double kRoundTrip = 1e-9;

MayaAnimFile Parse(const std::string& text) {
  absl::StatusOr<MayaAnimFile> file = ParseMayaAnimText(text);
  EXPECT_TRUE(file.ok()) << file.status();
  return file.ok() ? *file : MayaAnimFile{};
}

double Eval(const MayaCurveBlock& curve, double frame) {
  absl::StatusOr<double> value = EvaluateMayaCurve(curve, frame);
  EXPECT_TRUE(value.ok()) << value.status();
  return value.value_or(std::nan(""));
}

std::string OneCurve(const std::string& weighted, const std::string& keys) {
  return "animVersion 1.1;\nmayaVersion 2020;\ntimeUnit ntsc;\nlinearUnit cm;\nangularUnit deg;\n"
         "startTime 1;\nendTime 30;\nanim translate.translateX translateX pCube1 0 1 0;\n"
         "animData {\n  input time;\n  output linear;\n  weighted " +
         weighted + ";\n  preInfinity constant;\n  postInfinity constant;\n  keys {\n" + keys +
         "  }\n}\n";
}

// ---- the evaluator against hand-computed cases ------------------------------------------------

TEST(MayaAnimEvaluatorTest, RealMayaFixedThenLinearKeysAreTheChordPerFrame) {
  // From a real Maya export (non-weighted): 42.792758 degrees is atan of the chord's slope per
  // frame, (1.721675 - 0.795937) / (1.9999796 - 1.00002) = 0.925775; per second it would be ~1.8.
  const MayaAnimFile file = Parse(OneCurve("0",
                                           "    1.00002 0.795937 fixed fixed 1 0 0 42.792758 1 "
                                           "42.792758 1;\n"
                                           "    1.9999796 1.721675 linear linear 1 0 0;\n"));
  ASSERT_EQ(file.curves.size(), 1u);
  const MayaCurveBlock& curve = file.curves[0];
  const double slope = (1.721675 - 0.795937) / (1.9999796 - 1.00002);

  EXPECT_NEAR(std::tan(42.792758 * std::numbers::pi / 180.0), slope, kPrintedDigits);
  for (double frame : {1.25, 1.5, 1.75}) {
    EXPECT_NEAR(Eval(curve, frame), 0.795937 + slope * (frame - 1.00002), kPrintedDigits) << frame;
  }
  EXPECT_DOUBLE_EQ(file.frames_per_second, 30.0);
}

TEST(MayaAnimEvaluatorTest, FlatDefaultWeightOnAThirtyFrameSegmentIsWeightTen) {
  // Flat handles of length 10 on 0..30: x controls 0, 10, 20, 30 (x linear in s), y = 10 * (3s^2
  // - 2s^3): at frame 7.5 (s = 0.25) 1.5625, at 15 exactly 5.
  const MayaAnimFile file = Parse(OneCurve("1",
                                           "    0 0 fixed fixed 1 0 0 0 10 0 10;\n"
                                           "    30 10 fixed fixed 1 0 0 0 10 0 10;\n"));
  const MayaCurveBlock& curve = file.curves[0];

  EXPECT_NEAR(Eval(curve, 7.5), 1.5625, 1e-12);
  EXPECT_NEAR(Eval(curve, 15.0), 5.0, 1e-12);
  EXPECT_NEAR(Eval(curve, 22.5), 8.4375, 1e-12);
}

TEST(MayaAnimEvaluatorTest, WeightedHandlesAreLengthsInFrameValueSpace) {
  // Out handle of key 0: angle 0, weight 5 -> (5, 0). In handle of key 1: angle 90, weight 3 ->
  // the control point at (10, 0 - 3). At s = 1/2: x = 5 * 3/8 + 10 * 3/8 + 10/8 = 6.875,
  // y = -3 * 3/8 = -1.125.
  const MayaAnimFile file = Parse(OneCurve("1",
                                           "    0 0 fixed fixed 0 0 0 0 5 0 5;\n"
                                           "    10 0 fixed fixed 0 0 0 90 3 90 3;\n"));

  EXPECT_NEAR(Eval(file.curves[0], 6.875), -1.125, 1e-12);
}

TEST(MayaAnimEvaluatorTest, NonWeightedCurvesIgnoreTheWeight) {
  // 45 degrees is a slope of 1 value unit per frame on both keys: the line y = frame, whatever
  // weight is written.
  const MayaAnimFile file = Parse(OneCurve("0",
                                           "    0 0 fixed fixed 1 0 0 45 7 45 7;\n"
                                           "    10 10 fixed fixed 1 0 0 45 0.1 45 0.1;\n"));

  EXPECT_NEAR(Eval(file.curves[0], 3.0), 3.0, 1e-12);
  EXPECT_NEAR(Eval(file.curves[0], 9.5), 9.5, 1e-12);
}

TEST(MayaAnimEvaluatorTest, StepHoldsAndFlatEasesAndEndsHoldConstant) {
  const MayaAnimFile file = Parse(OneCurve("0",
                                           "    0 2 flat step 1 0 0;\n"
                                           "    10 4 flat flat 1 0 0;\n"
                                           "    20 8 flat flat 1 0 0;\n"));
  const MayaCurveBlock& curve = file.curves[0];

  EXPECT_EQ(Eval(curve, 9.99), 2.0);
  EXPECT_NEAR(Eval(curve, 15.0), 6.0, 1e-12);  // flat-flat Hermite midpoint
  EXPECT_EQ(Eval(curve, -5.0), 2.0);
  EXPECT_EQ(Eval(curve, 25.0), 8.0);
}

TEST(MayaAnimEvaluatorTest, UnsupportedTangentTypesAreRefused) {
  const MayaAnimFile file = Parse(OneCurve("0",
                                           "    0 0 clamped clamped 1 0 0;\n"
                                           "    10 1 clamped clamped 1 0 0;\n"));

  const absl::StatusOr<double> value = EvaluateMayaCurve(file.curves[0], 5.0);

  EXPECT_EQ(value.status().message(), "tangent type 'clamped' is not supported");
}

// ---- the writer under that evaluator ---------------------------------------------------------

// A scalar channel at 30 fps with the given keys.
KeyedClip ScalarKeyed(std::vector<Key> keys, std::int64_t frame_count) {
  KeyedClip keyed;
  keyed.layout.frame_time_seconds = 1.0 / 30.0;
  keyed.layout.frame_count = frame_count;
  Channel channel;
  channel.name = "blend";
  keyed.layout.channels = {channel};
  keyed.curves = {Curve{std::move(keys)}};
  return keyed;
}

TEST(MayaAnimTest, UnweightedKeysAreWrittenNonWeightedWithAnglesPerFrame) {
  // 30 units per second at 30 fps is 1 per frame: 45 degrees. Keys on frames 0 and 30.
  Key a;
  a.in_tangent = a.out_tangent = 30.0;
  Key b;
  b.time_seconds = 1.0;
  b.value = 30.0;
  b.in_tangent = b.out_tangent = 30.0;

  const absl::StatusOr<std::string> text = FormatMayaAnim(ScalarKeyed({a, b}, 31));

  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_THAT(*text, HasSubstr("  weighted 0;\n"));
  EXPECT_THAT(*text, HasSubstr("    0 0 fixed fixed 1 0 0 45 1 45 1;\n"));
  EXPECT_THAT(*text, HasSubstr("    30 30 fixed fixed 1 0 0 45 1 45 1;\n"));
  const MayaAnimFile file = Parse(*text);
  EXPECT_NEAR(Eval(file.curves[0], 12.0), 12.0, kRoundTrip);
}

// A name is one word of a .anim line: one that holds the format's separators or comment marks is
// refused, naming it and why (it was written as it was, exit 0, into a file Maya cannot read:
// "anim left foot contact left foot contact left foot contact 0 0 0;"). Namespaced names stay.
TEST(MayaAnimTest, NamesThatCannotBeOneWordOfALineAreRefusedNamingThem) {
  Key a;
  Key b;
  b.time_seconds = 1.0;
  for (const auto& [name, problem] : std::vector<std::pair<std::string, std::string>>{
           {"left foot contact", "contains whitespace, where a .anim line splits into words"},
           {"Hips;evil", "contains ';', which ends a .anim statement"},
           {"arm{1}", "contains a brace, which opens or closes a .anim section"},
           {"take#2", "contains '#', which starts a .anim comment"},
           {"a//b", "contains '//', which starts a .anim comment"},
           {"tab\there", "contains whitespace, where a .anim line splits into words"},
           {"bell\x07", "contains a control character"}}) {
    KeyedClip keyed = ScalarKeyed({a, b}, 31);
    keyed.layout.channels[0].name = name;

    const absl::StatusOr<std::string> text = FormatMayaAnim(keyed);

    EXPECT_EQ(text.status().code(), absl::StatusCode::kInvalidArgument) << name;
    EXPECT_EQ(text.status().message(),
              absl::StrCat("cannot write .anim: channel 0 name ", QuoteForMessage(name), " ",
                           problem, "; rename it, or write .json"));
  }
  KeyedClip namespaced = ScalarKeyed({a, b}, 31);
  namespaced.layout.channels[0].name = "rig:blend_L.weight";
  const absl::StatusOr<std::string> text = FormatMayaAnim(namespaced);
  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_THAT(*text, HasSubstr("anim rig:blend_L.weight rig:blend_L.weight rig:blend_L.weight 0 0 0;\n"));
  EXPECT_EQ(Parse(*text).curves.size(), 1u);
}

TEST(MayaAnimTest, WeightedKeysAreHandleLengthsInFramesAndValues) {
  // A flat out handle of weight 1/3 on a 1 s (30-frame) segment: (10 frames, 0): angle 0,
  // weight 10. The in handle of key 1, weight 0.2 at slope 3 per second: 6 frames by 0.6 value.
  Key a;
  a.out_weight = 1.0 / 3.0;
  a.in_weight = 1.0 / 3.0;
  Key b;
  b.time_seconds = 1.0;
  b.value = 2.0;
  b.in_tangent = b.out_tangent = 3.0;
  b.in_weight = 0.2;
  b.out_weight = 0.2;
  const KeyedClip keyed = ScalarKeyed({a, b}, 31);

  const absl::StatusOr<std::string> text = FormatMayaAnim(keyed);

  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_THAT(*text, HasSubstr("  weighted 1;\n"));
  EXPECT_THAT(*text, HasSubstr("    0 0 fixed fixed 1 0 0 0 10 0 10;\n"));
  const MayaAnimFile file = Parse(*text);
  const MayaKeyLine& key1 = file.curves[0].keys[1];
  EXPECT_NEAR(key1.in_weight, std::hypot(6.0, 0.6), kRoundTrip);
  EXPECT_NEAR(std::tan(key1.in_angle_degrees * std::numbers::pi / 180.0), 0.1, kRoundTrip);
  for (int frame = 0; frame <= 30; ++frame) {
    EXPECT_NEAR(Eval(file.curves[0], frame), EvaluateCurve(keyed.curves[0], frame / 30.0),
                kRoundTrip)
        << frame;
  }
}

// A scalar channel of `frame_count` frames at `frame_time` keyed on `frames` (value the key's
// time, slope 1 per second), written as .anim and read back.
MayaAnimFile WrittenWithKeysOn(double frame_time, std::int64_t frame_count,
                               std::initializer_list<int> frames) {
  KeyedClip keyed = ScalarKeyed({}, frame_count);
  keyed.layout.frame_time_seconds = frame_time;
  for (int frame : frames) {
    Key key;
    key.time_seconds = frame * frame_time;
    key.value = key.time_seconds;
    key.in_tangent = key.out_tangent = 1.0;
    keyed.curves[0].keys.push_back(key);
  }
  const absl::StatusOr<std::string> text = FormatMayaAnim(keyed);
  EXPECT_TRUE(text.ok()) << text.status();
  return text.ok() ? Parse(*text) : MayaAnimFile{};
}

// The file frames of the one curve's keys.
std::vector<double> KeyFrames(const MayaAnimFile& file) {
  std::vector<double> frames;
  if (!file.curves.empty()) {
    for (const MayaKeyLine& key : file.curves[0].keys) frames.push_back(key.frame);
  }
  return frames;
}

TEST(MayaAnimTest, BvhRateNearAUnitWritesTheSourceFrameNumbers) {
  // 0.0333333 s is 30.0003 Hz, within 1e-4 of ntsc: key times are the frame numbers.
  const MayaAnimFile file = WrittenWithKeysOn(0.0333333, 994, {0, 500, 993});

  EXPECT_EQ(file.time_unit, "ntsc");
  EXPECT_EQ(KeyFrames(file), (std::vector<double>{0.0, 500.0, 993.0}));
  EXPECT_EQ(file.end_time, 993.0);
}

TEST(MayaAnimTest, A120HzBvhIsWrittenInNtscfWithEachFrameHalfAFileFrame) {
  // 0.0083333 s is 120.0005 Hz: no unit every Maya reads is 120 fps ("120fps" is refused by the
  // published reader), so ntscf, twice slower: source frame f is file frame f / 2 exactly, and
  // a slope of 1 unit per second is 1/60 per file frame.
  const MayaAnimFile file = WrittenWithKeysOn(0.0083333, 995, {0, 495, 994});

  EXPECT_EQ(file.time_unit, "ntscf");
  EXPECT_EQ(KeyFrames(file), (std::vector<double>{0.0, 247.5, 497.0}));
  EXPECT_EQ(file.end_time, 497.0);
  // Halfway between the keys at source frames 495 and 994, in Maya's frames of 1/60 s.
  ASSERT_FALSE(file.curves.empty());
  EXPECT_NEAR(Eval(file.curves[0], 372.25), 744.5 * 0.0083333, 1e-9);
}

TEST(MayaAnimTest, A12HzClipIsWrittenInFilmWithEachFrameTwoFileFrames) {
  // Animation "on twos": 12 Hz is no unit every Maya reads, but half of film's 24: source frame
  // f is file frame 2 f (the nearest unit, game, would have put it at 1.25 f).
  const MayaAnimFile file = WrittenWithKeysOn(1.0 / 12.0, 100, {0, 7, 99});

  EXPECT_EQ(file.time_unit, "film");
  EXPECT_EQ(KeyFrames(file), (std::vector<double>{0.0, 14.0, 198.0}));
  EXPECT_EQ(file.end_time, 198.0);
}

TEST(MayaAnimTest, RateOffEveryUnitWritesTimesInUnitFrames) {
  // 27 fps is nearest 25 (pal) but 8% off: times are seconds in pal frames.
  KeyedClip keyed = ScalarKeyed({}, 28);
  keyed.layout.frame_time_seconds = 1.0 / 27.0;
  Key a;
  Key b;
  b.time_seconds = 1.0;
  b.value = 1.0;
  b.in_tangent = b.out_tangent = 1.0;
  a.in_tangent = a.out_tangent = 1.0;
  keyed.curves[0].keys = {a, b};

  const absl::StatusOr<std::string> text = FormatMayaAnim(keyed);

  ASSERT_TRUE(text.ok()) << text.status();
  const MayaAnimFile file = Parse(*text);
  EXPECT_EQ(file.time_unit, "pal");
  EXPECT_NEAR(file.curves[0].keys[1].frame, 25.0, kRoundTrip);
  EXPECT_NEAR(Eval(file.curves[0], 12.5), 0.5, kRoundTrip);  // slope 1/s = 1/25 per pal frame
}

TEST(MayaAnimTest, TimeUnitIsTheNearestMayaUnit) {
  struct Case {
    double frame_time;
    const char* unit;
  } cases[] = {
      // Only the units every Maya reads: the clip's own, then the fastest that divides it, then
      // the nearest in ratio.
      {1.0 / 24.0, "film"},   {1001.0 / 24000.0, "film"}, {1.0 / 25.0, "pal"},
      {1.0 / 30.0, "ntsc"},   {1001.0 / 60000.0, "ntscf"}, {1.0 / 60.0, "ntscf"},
      {1.0 / 90.0, "ntsc"},   {1.0 / 100.0, "palf"},      {1.0 / 120.0, "ntscf"},
      {1.0 / 1000.0, "palf"}, {1.0 / 7.0, "game"},        {1.0 / 72.0, "film"},
      {1.0 / 12.0, "film"},   {1.0 / 10.0, "ntsc"},       {1.0 / 8.0, "film"},
      {10.0, "game"},         {1e-5, "ntscf"},            {1e-6, "ntscf"},
  };
  for (const Case& c : cases) {
    KeyedClip keyed = ScalarKeyed({Key{}, Key{}}, 2);
    keyed.layout.frame_time_seconds = c.frame_time;
    keyed.curves[0].keys[1].time_seconds = c.frame_time;

    const absl::StatusOr<std::string> text = FormatMayaAnim(keyed);

    ASSERT_TRUE(text.ok()) << text.status();
    EXPECT_THAT(*text, HasSubstr(std::string("\ntimeUnit ") + c.unit + ";\n")) << c.frame_time;
  }
}

// ---- rotation order ---------------------------------------------------------------------------

using Mat = std::array<std::array<double, 3>, 3>;

// Maya's row-vector axis matrices (p' = p * M), as the transform node reference prints them.
Mat RowAxis(char axis, double degrees) {
  const double r = degrees * std::numbers::pi / 180.0;
  const double c = std::cos(r);
  const double s = std::sin(r);
  if (axis == 'x') return Mat{{{1, 0, 0}, {0, c, s}, {0, -s, c}}};
  if (axis == 'y') return Mat{{{c, 0, -s}, {0, 1, 0}, {s, 0, c}}};
  return Mat{{{c, s, 0}, {-s, c, 0}, {0, 0, 1}}};
}

Mat Times(const Mat& a, const Mat& b) {
  Mat m{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) m[i][j] += a[i][k] * b[k][j];
  return m;
}

TEST(MayaAnimTest, HeaderGivesEachJointTheMayaRotateOrderOfItsBvhChannels) {
  // Maya applies rotateOrder "abc" as p * Ra * Rb * Rc (row vectors): the transpose of the
  // column-vector matrix the BVH order composes. Every order, checked on one rotation.
  const Vec3 angles = {37.0, -71.0, 12.5};
  const char* kAxes = "xyz";
  for (const EulerOrder order : {EulerOrder{0, 1, 2}, EulerOrder{0, 2, 1}, EulerOrder{1, 0, 2},
                                 EulerOrder{1, 2, 0}, EulerOrder{2, 0, 1}, EulerOrder{2, 1, 0}}) {
    const MayaRotateOrder maya = MayaRotateOrderOf(order);
    std::map<char, double> by_axis;
    for (int i = 0; i < 3; ++i) by_axis[kAxes[order[i]]] = angles[i];
    Mat row = RowAxis(maya.name[0], by_axis[maya.name[0]]);
    row = Times(row, RowAxis(maya.name[1], by_axis[maya.name[1]]));
    row = Times(row, RowAxis(maya.name[2], by_axis[maya.name[2]]));
    const Mat3 column = EulerToMatrix(order, angles);

    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(row[j][i], column[i][j], 1e-12) << maya.name;
    }
  }
  EXPECT_EQ(MayaRotateOrderOf({2, 0, 1}).name, "yxz");
  EXPECT_EQ(MayaRotateOrderOf({2, 0, 1}).value, 4);
  EXPECT_EQ(MayaRotateOrderOf({0, 1, 2}).name, "zyx");
  EXPECT_EQ(MayaRotateOrderOf({0, 1, 2}).value, 5);
  EXPECT_EQ(MayaRotateOrderOf({2, 1, 0}).value, 0);
}

// The rotateOrder lines of a file: joint -> Maya order name.
std::map<std::string, std::string> RotateOrders(const std::string& text) {
  std::map<std::string, std::string> orders;
  std::size_t at = 0;
  const std::string prefix = "// tempokey rotateOrder ";
  while ((at = text.find(prefix, at)) != std::string::npos) {
    const std::size_t end = text.find(';', at);
    std::istringstream line(text.substr(at + prefix.size(), end - at - prefix.size()));
    std::string joint, order;
    line >> joint >> order;
    orders[joint] = order;
    at = end;
  }
  return orders;
}

// A joint with two rotation channels, as Maya shows it once the header's orders are applied: its
// child placed by Maya's row-vector composition of the curves' values, against the BVH's meaning
// worked by hand. Without a line, Maya kept "xyz" and the end site sat 14.1 units away.
TEST(MayaAnimTest, AJointWithTwoRotationChannelsTurnsInItsBvhOrderInMaya) {
  for (const auto& [channels, expected] : std::vector<std::pair<std::string, Vec3>>{
           // R = Rx(90) Rz(90): Z turns the bone's (0, 10, 0) to (-10, 0, 0), X keeps it there.
           {"Xrotation Zrotation", {-10.0, 10.0, 0.0}},
           // R = Rz(90) Rx(90): X turns it to (0, 0, 10), Z keeps it there.
           {"Zrotation Xrotation", {0.0, 10.0, 10.0}},
           // R = Ry(90) Rz(90): Z turns it to (-10, 0, 0), Y to (0, 0, 10).
           {"Yrotation Zrotation", {0.0, 10.0, 10.0}}}) {
    const std::string bvh =
        "HIERARCHY\nROOT Root\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n"
        "  JOINT Arm\n  {\n    OFFSET 0 10 0\n    CHANNELS 2 " + channels +
        "\n    End Site\n    {\n      OFFSET 0 10 0\n    }\n  }\n}\nMOTION\nFrames: 2\n"
        "Frame Time: 0.0333333\n0 0 0 90 90\n0 0 0 90 90\n";
    const absl::StatusOr<Clip> clip = ParseBvh(bvh, "arm.bvh");
    ASSERT_TRUE(clip.ok()) << clip.status();
    const absl::StatusOr<ReduceResult> reduced = ReduceKeys(*clip, {});
    ASSERT_TRUE(reduced.ok()) << reduced.status();
    const absl::StatusOr<std::string> text = FormatMayaAnim(reduced->keyed);
    ASSERT_TRUE(text.ok()) << text.status();
    const std::map<std::string, std::string> orders = RotateOrders(*text);
    ASSERT_EQ(orders.count("Arm"), 1u) << *text;
    const std::string& order = orders.at("Arm");

    std::map<char, double> angle = {{'x', 0.0}, {'y', 0.0}, {'z', 0.0}};
    for (const MayaCurveBlock& curve : Parse(*text).curves) {
      if (curve.node == "Arm") angle[static_cast<char>(std::tolower(curve.attribute.back()))] = Eval(curve, 0.0);
    }
    Mat row = RowAxis(order[0], angle[order[0]]);
    row = Times(row, RowAxis(order[1], angle[order[1]]));
    row = Times(row, RowAxis(order[2], angle[order[2]]));
    const Vec3 bone = {0.0, 10.0, 0.0};
    Vec3 end_site = {0.0, 10.0, 0.0};  // the Arm's position, then its bone turned (p * M)
    for (int j = 0; j < 3; ++j) {
      for (int i = 0; i < 3; ++i) end_site[j] += bone[i] * row[i][j];
    }
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(end_site[j], expected[j], 1e-9) << channels << " " << order;
  }
}

// ---- every shared clip, reduced and evaluated the way Maya would --------------------------------

// Error of a .anim against the source at every source frame, two ways: at each frame's exact
// time in Maya's seconds (frame = t x the unit's rate) and at the frames animators see: the
// file's integer frames when its unit is the clip's rate, else i / n when the clip's rate is n
// times the unit's (120 Hz in ntscf: frame i at i / 2), else the exact times.
struct AnimErrors {
  double at_exact_times = 0.0;
  double at_integer_frames = 0.0;
  double exact_time_drift_allowance = 0.0;  // what the frame-number convention alone may add
};

AnimErrors MeasureAnim(const Clip& source, const MayaAnimFile& file) {
  AnimErrors errors;
  std::map<std::pair<std::string, std::string>, const MayaCurveBlock*> by_name;
  for (const MayaCurveBlock& curve : file.curves) by_name[{curve.node, curve.attribute}] = &curve;
  for (std::size_t c = 0; c < source.channels.size(); ++c) {
    const Channel& channel = source.channels[c];
    const std::string node = source.skeleton.joints[channel.joint].name;
    const char axis = "XYZ"[Axis(channel.kind)];
    const std::string attribute = IsRotation(channel.kind)
                                      ? std::string("rotate.rotate") + axis
                                      : std::string("translate.translate") + axis;
    const MayaCurveBlock* curve = by_name[{node, attribute}];
    EXPECT_NE(curve, nullptr) << node << "." << attribute;
    if (curve == nullptr) continue;
    const std::vector<double>& samples = channel.samples;
    // Rotations are fitted unwrapped: 361 degrees is the source's 1 degree, the same rotation.
    const bool angle = IsRotation(channel.kind);
    auto distance = [angle](double a, double b) {
      return angle ? std::abs(std::remainder(a - b, 360.0)) : std::abs(a - b);
    };
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const double exact_frame = static_cast<double>(i) * source.frame_time_seconds *
                                 file.frames_per_second;
      const double at_exact = Eval(*curve, exact_frame);
      const double at_integer = Eval(*curve, testing::FileFrameOfSourceFrame(
                                                 file, source.frame_time_seconds,
                                                 static_cast<std::int64_t>(i)));
      errors.at_exact_times = std::max(errors.at_exact_times, distance(at_exact, samples[i]));
      errors.at_integer_frames =
          std::max(errors.at_integer_frames, distance(at_integer, samples[i]));
      // Moving the query by |exact - i| frames moves the motion by at most that times its speed.
      const double speed =
          std::max(i > 0 ? distance(samples[i], samples[i - 1]) : 0.0,
                   i + 1 < samples.size() ? distance(samples[i + 1], samples[i]) : 0.0);
      errors.exact_time_drift_allowance = std::max(
          errors.exact_time_drift_allowance, 2.0 * speed * std::abs(exact_frame - static_cast<double>(i)));
    }
  }
  return errors;
}

class MayaAnimCorpusTest : public ::testing::TestWithParam<double> {};

TEST_P(MayaAnimCorpusTest, EveryClipReproducesTheSourceWithinTheBoundUnderMayaSemantics) {
  const double tolerance = GetParam();
  for (const std::string& path : testing::AllSharedBvhFiles()) {
    absl::StatusOr<Clip> source = ReadBvhFile(path);
    ASSERT_TRUE(source.ok()) << source.status();
    ReduceOptions options;
    options.tolerance.max_rotation_error_degrees = tolerance;
    options.tolerance.max_position_error = tolerance;
    absl::StatusOr<ReduceResult> reduced = ReduceKeys(*source, options);
    ASSERT_TRUE(reduced.ok()) << reduced.status();

    const absl::StatusOr<std::string> text = FormatMayaAnim(reduced->keyed);
    ASSERT_TRUE(text.ok()) << text.status();
    const MayaAnimFile file = Parse(*text);
    const AnimErrors errors = MeasureAnim(*source, file);

    EXPECT_EQ(file.angular_unit, "deg");
    EXPECT_LE(errors.at_integer_frames, tolerance + kRoundTrip) << path;
    EXPECT_LE(errors.at_exact_times,
              tolerance + errors.exact_time_drift_allowance + kRoundTrip)
        << path;
  }
}

INSTANTIATE_TEST_SUITE_P(Tolerances, MayaAnimCorpusTest, ::testing::Values(0.1, 0.5, 1.0));

TEST(MayaAnimTest, PaperMethodWeightedCurvesEvaluateInMayaAsInCore) {
  // The paper's keys are weighted 2D Hermite keys at fractional frames: Maya's Bezier evaluation
  // of the written angles and weights must give core's curve at every frame.
  absl::StatusOr<Clip> source = ReadBvhFile(testing::SharedBvh("cmu/131_01.bvh"));
  ASSERT_TRUE(source.ok()) << source.status();
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  options.paper.max_iterations = 1;
  absl::StatusOr<ReduceResult> reduced = ReduceKeys(*source, options);
  ASSERT_TRUE(reduced.ok()) << reduced.status();

  const absl::StatusOr<std::string> text = FormatMayaAnim(reduced->keyed);
  ASSERT_TRUE(text.ok()) << text.status();
  const MayaAnimFile file = Parse(*text);

  ASSERT_EQ(file.time_unit, "ntscf");
  ASSERT_EQ(file.curves.size(), source->channels.size());
  double worst = 0.0;
  for (std::size_t c = 0; c < file.curves.size(); ++c) {
    for (std::int64_t i = 0; i < source->frame_count; ++i) {
      // CMU's 120 Hz is written in ntscf: source frame i is file frame i / 2.
      const double maya = Eval(file.curves[c], static_cast<double>(i) / 2.0);
      const double core = EvaluateCurve(reduced->keyed.curves[c],
                                        static_cast<double>(i) * source->frame_time_seconds);
      worst = std::max(worst, std::abs(maya - core));
    }
  }
  EXPECT_LE(worst, 1e-6);
  EXPECT_THAT(*text, HasSubstr("// tempokey rotateOrder Hips "));
}

}  // namespace
}  // namespace tempokey::core
