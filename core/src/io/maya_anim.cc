// Maya .anim export of keyed clips (conventions and sources in maya_anim.h).
//
// Everything Maya reads from a key line is in UI space: time in frames of the declared unit,
// values in the declared units, and a fixed tangent as an angle and weight in (frames, value)
// space. Our keys are in seconds with slopes per second, so each number goes through k, the file
// frames per second, exactly once.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <numbers>
#include <string>
#include <string_view>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/maya_anim.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr double kDefaultWeight = 1.0 / 3.0;

// A Maya time unit: its .anim name and its frames per second.
struct TimeUnit {
  const char* name;
  double rate;
};

// The units every version of Maya's .anim reader accepts: the published format (animVersion 1.1)
// and the devkit reader's animUnitNames::setFromName() know "game|film|pal|ntsc|show|palf|ntscf"
// (and hour|min|sec|millisec) and refuse any other name ("'120fps' is not a valid time unit"),
// so the numbered units of later Maya versions ("120fps") are not written. Lowest rate first.
// (The format's page: "timeUnit [game|film|pal|ntsc|show|palf|ntscf|hour|min|sec|millisec]",
// help.autodesk.com/cloudhelp/2016/ENU/Maya/files/GUID-87541258-2463-497A-A3D7-3DEA4C852644.htm.)
constexpr TimeUnit kTimeUnits[] = {
    {"game", 15.0}, {"film", 24.0}, {"pal", 25.0},   {"ntsc", 30.0},
    {"show", 48.0}, {"palf", 50.0}, {"ntscf", 60.0},
};

// A clip rate within this ratio of a Maya unit's rate, or of a whole multiple or fraction of it,
// keeps exact frames (BVH frame times are written rounded: 0.0083333 s is 120.0005 Hz).
constexpr double kSameRateTolerance = 1e-4;
// The largest whole multiple looked for either way.
constexpr double kMaxWholeMultiple = 1000.0;

// How a clip's frames sit on a unit's: file frame = source frame x `up` / `down`, one of them 1
// (both 1: the same rate). Zero when neither divides the other: times are then seconds x rate.
struct FrameRatio {
  int up = 0;
  int down = 0;
  bool exact() const { return up > 0; }
};

// `multiple` as a whole number within kSameRateTolerance (relative), or 0.
int WholeMultiple(double multiple) {
  const double whole = std::round(multiple);
  if (!(whole >= 1.0 && whole <= kMaxWholeMultiple)) return 0;
  return std::abs(multiple - whole) <= kSameRateTolerance * whole ? static_cast<int>(whole) : 0;
}

FrameRatio FrameRatioOf(double frame_rate, const TimeUnit& unit) {
  if (const int down = WholeMultiple(frame_rate / unit.rate); down > 0) return {1, down};
  if (const int up = WholeMultiple(unit.rate / frame_rate); up > 0) return {up, 1};
  return {};
}

// The unit of a clip at `frame_rate`, the first of: the unit of that rate (key times are the
// source's frame numbers); the fastest unit whose rate divides it (120 Hz is ntscf, a source frame
// half a file frame; 100 Hz palf); the slowest unit whose rate it divides (12 Hz is film, a source
// frame two file frames; 10 Hz ntsc); the unit nearest in ratio (rates beyond the table take its
// ends; an infinite rate from a subnormal frame time takes the fastest). Maya converts the file's
// times to the scene's rate on import, so a 120 fps scene shows a 120 Hz clip's keys on its whole
// frames either way.
const TimeUnit& TimeUnitFor(double frame_rate) {
  const TimeUnit* dividing = nullptr;
  const TimeUnit* divided = nullptr;
  for (const TimeUnit& unit : kTimeUnits) {  // slowest first
    const FrameRatio ratio = FrameRatioOf(frame_rate, unit);
    if (ratio.up == 1 && ratio.down == 1) return unit;
    if (ratio.down > 1) dividing = &unit;                     // the fastest that divides
    if (ratio.up > 1 && divided == nullptr) divided = &unit;  // the slowest it divides
  }
  if (dividing != nullptr) return *dividing;
  if (divided != nullptr) return *divided;
  const double rate = std::clamp(frame_rate, kTimeUnits[0].rate, std::end(kTimeUnits)[-1].rate);
  const TimeUnit* nearest = &kTimeUnits[0];
  double nearest_distance = std::numeric_limits<double>::infinity();
  for (const TimeUnit& unit : kTimeUnits) {
    const double distance = std::abs(std::log(rate / unit.rate));
    if (distance < nearest_distance) {
      nearest = &unit;
      nearest_distance = distance;
    }
  }
  return *nearest;
}

// File frames of the declared unit. When the clip's rate and the unit's are whole multiples of
// one another (FrameRatioOf()), a source frame f is file frame f x up / down (the frame numbers
// themselves at the same rate; to the printed precision when `down` is not a power of two);
// otherwise a file frame is one unit frame (time = seconds x rate).
class FileFrames {
 public:
  FileFrames(double frame_time_seconds, const TimeUnit& unit)
      : frame_time_(frame_time_seconds),
        ratio_(FrameRatioOf(1.0 / frame_time_seconds, unit)),
        per_second_(ratio_.exact() ? ratio_.up / (frame_time_seconds * ratio_.down) : unit.rate) {}

  // File frames per second (k in maya_anim.h).
  double per_second() const { return per_second_; }

  // The file frame of a time in seconds. On an exact ratio a key on a source frame lands on that
  // frame's file frame exactly (the division's rounding is undone).
  double operator()(double seconds) const {
    if (!ratio_.exact()) return seconds * per_second_;
    const double frames = seconds / frame_time_;
    const double whole = std::round(frames);
    const bool on_frame = std::abs(frames - whole) <= 1e-9 * std::max(1.0, std::abs(whole));
    return (on_frame ? whole : frames) * ratio_.up / ratio_.down;
  }

  // The file frame of the clip's frame `frame`.
  double OfClipFrame(std::int64_t frame) const {
    const auto f = static_cast<double>(frame);
    return ratio_.exact() ? f * ratio_.up / ratio_.down : f * frame_time_ * per_second_;
  }

 private:
  double frame_time_;
  FrameRatio ratio_;
  double per_second_;
};

struct Tangent {
  double angle_degrees;
  double weight;
};

constexpr double kDegreesPerRadian = 180.0 / std::numbers::pi;

// A non-weighted curve: only the slope matters (per file frame); Maya ignores the weight.
Tangent PlainTangent(double slope_per_second, double frames_per_second) {
  return {std::atan(slope_per_second / frames_per_second) * kDegreesPerRadian, 1.0};
}

// A weighted curve: the handle spans weight * segment seconds, i.e. (DF, DV) in UI space.
Tangent WeightedTangent(double slope_per_second, double weight, double segment_seconds,
                        double frames_per_second) {
  const double handle_seconds = weight * segment_seconds;
  const double df = handle_seconds * frames_per_second;
  const double dv = handle_seconds * slope_per_second;
  return {std::atan2(dv, df) * kDegreesPerRadian, std::hypot(df, dv)};
}

bool IsWeighted(const Curve& curve) {
  return std::any_of(curve.keys.begin(), curve.keys.end(),
                     [](const Key& key) { return key.in_weight || key.out_weight; });
}

// "rotate.rotateX rotateX" for the attribute of a channel kind, the channel name for scalars.
std::string Attribute(const Clip& layout, int c) {
  const Channel& channel = layout.channels[c];
  const char axis = "XYZ"[std::max(0, Axis(channel.kind))];
  if (IsRotation(channel.kind)) return absl::StrCat("rotate.rotate", std::string(1, axis), " rotate", std::string(1, axis));
  if (IsPosition(channel.kind)) {
    return absl::StrCat("translate.translate", std::string(1, axis), " translate",
                        std::string(1, axis));
  }
  const std::string name = ChannelName(layout, c);
  return absl::StrCat(name, " ", name);
}

void AppendCurve(std::string& out, const KeyedClip& keyed, int c, const FileFrames& frames) {
  const Clip& layout = keyed.layout;
  const Channel& channel = layout.channels[c];
  const std::string node = channel.joint >= 0 ? layout.skeleton.joints[channel.joint].name
                                              : ChannelName(layout, c);
  const Curve& curve = keyed.curves[c];
  const bool weighted = IsWeighted(curve);
  absl::StrAppend(&out, "anim ", Attribute(layout, c), " ", node, " 0 0 0;\n");
  absl::StrAppend(&out, "animData {\n  input time;\n  output ",
                  IsRotation(channel.kind)   ? "angular"
                  : IsPosition(channel.kind) ? "linear"
                                             : "unitless",
                  ";\n  weighted ", weighted ? 1 : 0,
                  ";\n  preInfinity constant;\n  postInfinity constant;\n  keys {\n");
  const std::vector<Key>& keys = curve.keys;
  const double k_rate = frames.per_second();
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const Key& key = keys[k];
    const double before =
        k > 0 ? key.time_seconds - keys[k - 1].time_seconds
              : (k + 1 < keys.size() ? keys[k + 1].time_seconds - key.time_seconds : 0.0);
    const double after = k + 1 < keys.size() ? keys[k + 1].time_seconds - key.time_seconds : before;
    Tangent in = PlainTangent(key.in_tangent, k_rate);
    Tangent tangent_out = PlainTangent(key.out_tangent, k_rate);
    if (weighted) {
      in = WeightedTangent(key.in_tangent, key.in_weight.value_or(kDefaultWeight), before, k_rate);
      tangent_out = WeightedTangent(key.out_tangent, key.out_weight.value_or(kDefaultWeight), after,
                                    k_rate);
    }
    out += "    ";
    AppendDouble(out, frames(key.time_seconds));
    out += ' ';
    AppendDouble(out, key.value);
    absl::StrAppend(&out, " fixed fixed ", key.in_tangent == key.out_tangent ? 1 : 0, " 0 0 ");
    AppendDouble(out, in.angle_degrees);
    out += ' ';
    AppendDouble(out, in.weight);
    out += ' ';
    AppendDouble(out, tangent_out.angle_degrees);
    out += ' ';
    AppendDouble(out, tangent_out.weight);
    out += ";\n";
  }
  out += "  }\n}\n";
}

// The three axes of a joint's rotation channels in listed order: a joint with fewer than three
// takes its missing axes (in x, y, z order) in front, where their zero angles leave the product
// of the listed ones as it is. `Xrotation Zrotation` (R = Rx·Rz: Z acts first) becomes
// {Y, X, Z}, whose Maya order "zxy" also turns Z first; Maya's default "xyz" turned X first
// and put such a joint's children up to a bone's length away.
EulerOrder CompletedOrder(const Clip& layout, const JointRotation& rotation) {
  std::vector<int> listed;
  for (int c : rotation.channels) {
    listed.push_back(Axis(layout.channels[static_cast<std::size_t>(c)].kind));
  }
  EulerOrder order{};
  std::size_t next = 0;
  for (int axis = 0; axis < 3; ++axis) {
    if (std::find(listed.begin(), listed.end(), axis) == listed.end()) order[next++] = axis;
  }
  for (int axis : listed) order[next++] = axis;
  return order;
}

// "// tempokey rotateOrder Hips yxz 4;" for every joint with rotation channels (one, two or
// three).
void AppendRotateOrders(std::string& out, const Clip& layout) {
  bool first = true;
  for (const JointRotation& rotation : JointRotations(layout)) {
    if (first) {
      out +=
          "// Rotation orders: Maya must have these on the joints before the import (README).\n";
      first = false;
    }
    const MayaRotateOrder order = MayaRotateOrderOf(CompletedOrder(layout, rotation));
    absl::StrAppend(&out, "// tempokey rotateOrder ", layout.skeleton.joints[rotation.joint].name,
                    " ", order.name, " ", order.value, ";\n");
  }
}

// Why `name` cannot be one word of a .anim line, or nullptr. The format splits its lines into
// words at whitespace, ends a statement at ';', opens and closes sections with braces, and takes
// '//' and '#' as comment marks (the format's description, "Anim File Format", Maya help); a name
// holding any of them makes the line something else, which Maya refuses or misreads.
const char* AnimWordProblem(std::string_view name) {
  if (name.empty()) return "is empty";
  for (char c : name) {
    const auto byte = static_cast<unsigned char>(c);
    if (c == ' ' || c == '\t') return "contains whitespace, where a .anim line splits into words";
    if (byte < 0x20 || byte == 0x7f) return "contains a control character";
    if (c == ';') return "contains ';', which ends a .anim statement";
    if (c == '{' || c == '}') return "contains a brace, which opens or closes a .anim section";
    if (c == '#') return "contains '#', which starts a .anim comment";
  }
  if (name.find("//") != std::string_view::npos) return "contains '//', which starts a .anim comment";
  return nullptr;
}

// Every name the file writes as a word (joints' names as nodes; a scalar channel's name as its
// node and attribute) can be read back as that word.
absl::Status CheckAnimNames(const Clip& layout) {
  for (std::size_t c = 0; c < layout.channels.size(); ++c) {
    const Channel& channel = layout.channels[c];
    const bool joint = channel.joint >= 0;
    const std::string name =
        joint ? layout.skeleton.joints[channel.joint].name : ChannelName(layout, static_cast<int>(c));
    if (const char* problem = AnimWordProblem(name)) {
      const std::int64_t index = joint ? channel.joint : static_cast<std::int64_t>(c);
      return absl::InvalidArgumentError(absl::StrCat(
          "cannot write .anim: ", joint ? "joint " : "channel ", index,
          " name ", QuoteForMessage(name), " ", problem, "; rename it, or write .json"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

MayaRotateOrder MayaRotateOrderOf(const std::array<int, 3>& order) {
  MayaRotateOrder result;
  for (int i = 2; i >= 0; --i) result.name += "xyz"[order[static_cast<std::size_t>(i)]];
  constexpr std::string_view kNames[] = {"xyz", "yzx", "zxy", "xzy", "yxz", "zyx"};
  for (int v = 0; v < 6; ++v) {
    if (kNames[v] == result.name) result.value = v;
  }
  return result;
}

absl::StatusOr<std::string> FormatMayaAnim(const KeyedClip& keyed) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateKeyedClip(keyed));
  TEMPOKEY_RETURN_IF_ERROR(CheckAnimNames(keyed.layout));
  const Clip& layout = keyed.layout;
  const TimeUnit& unit = TimeUnitFor(layout.frame_rate());
  const FileFrames frames(layout.frame_time_seconds, unit);
  std::string out = "animVersion 1.1;\nmayaVersion 2020;\n";
  absl::StrAppend(&out, "timeUnit ", unit.name, ";\n",
                  "linearUnit cm;\nangularUnit deg;\nstartTime 0;\nendTime ");
  AppendDouble(out, frames.OfClipFrame(layout.frame_count - 1));
  out += ";\n";
  AppendRotateOrders(out, layout);
  for (std::size_t c = 0; c < layout.channels.size(); ++c) {
    AppendCurve(out, keyed, static_cast<int>(c), frames);
  }
  return out;
}

absl::Status WriteMayaAnimFile(const std::string& path, const KeyedClip& keyed) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::string text, FormatMayaAnim(keyed));
  return WriteFileAtomically(path, text);
}

}  // namespace tempokey::core
