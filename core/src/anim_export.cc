// Maya .anim export of keyed clips (conventions in keyed_io.h).
//
// Per key and side, the Bezier handle of keyed_clip.h spans dt = weight * T seconds (T the
// segment's duration; unset weights are 1/3) and dv = slope * dt value units. Maya describes a
// tangent by the vector (x, y) = (3 dt, 3 dv), time in seconds: angle = atan2(y, x) in degrees
// and weight = hypot(x, y). The first key's in side and the last key's out side have no segment;
// they mirror the other side. Times are written in frames of the clip's rate.
#include <cmath>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "tempokey/core/file_io.h"
#include "tempokey/core/keyed_io.h"
#include "tempokey/core/numbers.h"
#include "tempokey/core/status.h"

namespace tempokey::core {
namespace {

constexpr double kDefaultWeight = 1.0 / 3.0;

// Maya's name for a frame rate: the classic names, else "<n>fps".
std::string TimeUnit(double frame_rate) {
  struct Named {
    double rate;
    const char* name;
  };
  static constexpr Named kNames[] = {{15, "game"}, {24, "film"},  {25, "pal"},  {30, "ntsc"},
                                     {48, "show"}, {50, "palf"},  {60, "ntscf"}};
  for (const Named& named : kNames) {
    if (std::abs(frame_rate - named.rate) < 1e-3) return named.name;
  }
  return absl::StrCat(std::llround(frame_rate), "fps");
}

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

void AppendCurve(std::string& out, const KeyedClip& keyed, int c) {
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
    AppendDouble(out, key.time_seconds / layout.frame_time_seconds);
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
  std::string out = "animVersion 1.1;\nmayaVersion 2020;\n";
  absl::StrAppend(&out, "timeUnit ", TimeUnit(layout.frame_rate()), ";\n",
                  "linearUnit cm;\nangularUnit deg;\nstartTime 0;\nendTime ", layout.frame_count - 1,
                  ";\n");
  for (std::size_t c = 0; c < layout.channels.size(); ++c) {
    AppendCurve(out, keyed, static_cast<int>(c));
  }
  return out;
}

absl::Status WriteMayaAnimFile(const std::string& path, const KeyedClip& keyed) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::string text, FormatMayaAnim(keyed));
  return WriteFileAtomically(path, text);
}

}  // namespace tempokey::core
