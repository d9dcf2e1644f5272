// Maya .anim export of keyed clips (conventions in maya_anim.h).
//
// Per key and side, the Bezier handle of keyed_clip.h spans dt = weight * T seconds (T the
// segment's duration; unset weights are 1/3) and dv = slope * dt value units. Maya describes a
// tangent by the vector (x, y) = (3 dt, 3 dv), time in seconds: angle = atan2(y, x) in degrees
// and weight = hypot(x, y). The first key's in side and the last key's out side have no segment;
// they mirror the other side. Times are written in frames of the declared timeUnit, the Maya unit
// nearest the clip's rate, so they play at the right time whatever that rate is.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/maya_anim.h"
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

// The units Maya's .anim reader knows (MTime): the named ones, the NTSC fractional rates
// (N * 1000/1001) and the numbered "<N>fps" ones, lowest rate to highest.
constexpr TimeUnit kTimeUnits[] = {
    {"2fps", 2.0},       {"3fps", 3.0},       {"4fps", 4.0},
    {"5fps", 5.0},       {"6fps", 6.0},       {"8fps", 8.0},
    {"10fps", 10.0},     {"12fps", 12.0},     {"game", 15.0},
    {"16fps", 16.0},     {"20fps", 20.0},     {"23.976fps", 24000.0 / 1001.0},
    {"film", 24.0},      {"pal", 25.0},       {"29.97fps", 30000.0 / 1001.0},
    {"ntsc", 30.0},      {"40fps", 40.0},     {"47.952fps", 48000.0 / 1001.0},
    {"show", 48.0},      {"palf", 50.0},      {"59.94fps", 60000.0 / 1001.0},
    {"ntscf", 60.0},     {"75fps", 75.0},     {"80fps", 80.0},
    {"100fps", 100.0},   {"120fps", 120.0},   {"125fps", 125.0},
    {"150fps", 150.0},   {"200fps", 200.0},   {"240fps", 240.0},
    {"250fps", 250.0},   {"300fps", 300.0},   {"375fps", 375.0},
    {"400fps", 400.0},   {"500fps", 500.0},   {"600fps", 600.0},
    {"750fps", 750.0},   {"1200fps", 1200.0}, {"1500fps", 1500.0},
    {"2000fps", 2000.0}, {"3000fps", 3000.0}, {"6000fps", 6000.0},
};

// The unit whose rate is nearest `frame_rate` in ratio (rates beyond the table take its ends; an
// infinite rate from a subnormal frame time takes the fastest).
const TimeUnit& NearestTimeUnit(double frame_rate) {
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

// Converts seconds to frames of the declared unit: time * unit rate. When the clip's frame time
// is exactly one unit frame (to rounding), time / frame time gives the clip's own frame numbers
// without the rounding of the rate.
class UnitFrames {
 public:
  UnitFrames(double frame_time_seconds, const TimeUnit& unit)
      : frame_time_(frame_time_seconds),
        rate_(unit.rate),
        same_rate_(frame_time_seconds * unit.rate == 1.0) {}

  double operator()(double seconds) const {
    return same_rate_ ? seconds / frame_time_ : seconds * rate_;
  }

  // The unit frame of the clip's frame `frame`.
  double OfClipFrame(std::int64_t frame) const {
    const auto f = static_cast<double>(frame);
    return same_rate_ ? f : f * frame_time_ * rate_;
  }

 private:
  double frame_time_;
  double rate_;
  bool same_rate_;
};

struct Tangent {
  double angle_degrees;
  double weight;
};

Tangent MayaTangent(double slope, double weight, double segment_seconds) {
  const double x = 3.0 * weight * segment_seconds;
  const double y = x * slope;
  return {std::atan2(y, x) * 180.0 / std::numbers::pi, std::hypot(x, y)};
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

void AppendCurve(std::string& out, const KeyedClip& keyed, int c, const UnitFrames& frames) {
  const Clip& layout = keyed.layout;
  const Channel& channel = layout.channels[c];
  const std::string node = channel.joint >= 0 ? layout.skeleton.joints[channel.joint].name
                                              : ChannelName(layout, c);
  absl::StrAppend(&out, "anim ", Attribute(layout, c), " ", node, " 0 0 0;\n");
  absl::StrAppend(&out, "animData {\n  input time;\n  output ",
                  IsRotation(channel.kind)   ? "angular"
                  : IsPosition(channel.kind) ? "linear"
                                             : "unitless",
                  ";\n  weighted 1;\n  preInfinity constant;\n  postInfinity constant;\n"
                  "  keys {\n");
  const std::vector<Key>& keys = keyed.curves[c].keys;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const Key& key = keys[k];
    const double before =
        k > 0 ? key.time_seconds - keys[k - 1].time_seconds
              : (k + 1 < keys.size() ? keys[k + 1].time_seconds - key.time_seconds : 0.0);
    const double after = k + 1 < keys.size() ? keys[k + 1].time_seconds - key.time_seconds : before;
    const double in_weight = key.in_weight.value_or(kDefaultWeight);
    const double out_weight = key.out_weight.value_or(kDefaultWeight);
    const Tangent in = MayaTangent(key.in_tangent, in_weight, before);
    const Tangent tangent_out = MayaTangent(key.out_tangent, out_weight, after);
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

}  // namespace

absl::StatusOr<std::string> FormatMayaAnim(const KeyedClip& keyed) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateKeyedClip(keyed));
  const Clip& layout = keyed.layout;
  const TimeUnit& unit = NearestTimeUnit(layout.frame_rate());
  const UnitFrames frames(layout.frame_time_seconds, unit);
  std::string out = "animVersion 1.1;\nmayaVersion 2020;\n";
  absl::StrAppend(&out, "timeUnit ", unit.name, ";\n",
                  "linearUnit cm;\nangularUnit deg;\nstartTime 0;\nendTime ");
  AppendDouble(out, frames.OfClipFrame(layout.frame_count - 1));
  out += ";\n";
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
