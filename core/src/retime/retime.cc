// Retime(): compile the warp into the one time map (or the paper's schedule), plan the kernels
// once, resample every channel through them, map the markers.
#include "tempokey/core/retime/retime.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "retime_internal.h"
#include "retime_paper.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/retime/resample.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/retime/time_map.h"

namespace tempokey::core {
namespace retime_internal {

std::string FormatNumber(double value) { return absl::StrFormat("%g", value); }

std::string DescribeTimePoint(const TimePoint& time) {
  return absl::StrCat(FormatNumber(time.value), time.in_frames ? "f" : "s");
}

std::string DescribeSpeedKnot(std::size_t index, const SpeedKnot& knot) {
  return absl::StrCat("speed knot ", index + 1, " (", DescribeTimePoint(knot.time), ":",
                      FormatNumber(knot.speed), ")");
}

std::string DescribeKey(std::size_t index, const TimeMapKey& key) {
  return absl::StrCat("time-map key ", index + 1, " (", DescribeTimePoint(key.output), " -> ",
                      DescribeTimePoint(key.source), ")");
}

std::string DescribeHold(std::size_t index, const Hold& hold) {
  return absl::StrCat("hold ", index + 1, " at ", DescribeTimePoint(hold.at));
}

std::string DescribePin(std::size_t index, const Pin& pin) {
  return absl::StrCat("pin ", index + 1, " (", DescribeTimePoint(pin.source), " -> frame ",
                      pin.output_frame, ")");
}

absl::Status ValidateSpeedRange(const RetimeOptions& options) {
  const std::string range =
      absl::StrCat("[", FormatNumber(kMinSpeedBound), ", ", FormatNumber(kMaxSpeedBound), "]");
  if (!(options.min_speed >= kMinSpeedBound && options.min_speed <= kMaxSpeedBound)) {
    return absl::InvalidArgumentError(absl::StrCat("min_speed must be in ", range, ", got ",
                                                   FormatNumber(options.min_speed)));
  }
  if (!(options.max_speed >= kMinSpeedBound && options.max_speed <= kMaxSpeedBound)) {
    return absl::InvalidArgumentError(absl::StrCat("max_speed must be in ", range, ", got ",
                                                   FormatNumber(options.max_speed)));
  }
  if (options.max_speed < options.min_speed) {
    return absl::InvalidArgumentError(absl::StrCat(
        "speed range [", FormatNumber(options.min_speed), ", ", FormatNumber(options.max_speed),
        "] is empty: max_speed must be >= min_speed"));
  }
  return absl::OkStatus();
}

absl::Status ValidateOutputRate(const FrameRate& rate) {
  if (rate.numerator <= 0 || rate.denominator <= 0) {
    return absl::InvalidArgumentError(absl::StrCat("output rate ", rate.numerator, "/",
                                                   rate.denominator,
                                                   " must have a positive numerator and denominator"));
  }
  if (rate.hz() > kMaxOutputRateHz) {
    return absl::InvalidArgumentError(absl::StrCat("output rate ", FormatNumber(rate.hz()),
                                                   " Hz is over the limit of ",
                                                   FormatNumber(kMaxOutputRateHz), " Hz"));
  }
  if (rate.hz() < kMinOutputRateHz) {
    return absl::InvalidArgumentError(absl::StrCat(
        "output rate ", rate.numerator, "/", rate.denominator, " (", FormatNumber(rate.hz()),
        " Hz) is under the limit of one frame an hour (", FormatNumber(kMinOutputRateHz),
        " Hz)"));
  }
  return absl::OkStatus();
}

absl::Status ValidateTimePoint(std::string_view what, const TimePoint& time) {
  if (!std::isfinite(time.value)) {
    return absl::InvalidArgumentError(
        absl::StrCat(AsAbsl(what), ": time is ", DescribeDouble(time.value)));
  }
  const double bound = time.in_frames ? kMaxTimeFrames : kMaxTimeSeconds;
  if (std::abs(time.value) > bound) {
    return absl::InvalidArgumentError(absl::StrCat(
        AsAbsl(what), ": time ", DescribeTimePoint(time), " is outside [-", FormatNumber(bound),
        ", ", FormatNumber(bound), "] ", time.in_frames ? "frames" : "s"));
  }
  return absl::OkStatus();
}

absl::Status ValidateDuration(std::string_view what, double seconds) {
  if (seconds > 0.0 && seconds <= kMaxTimeSeconds) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(AsAbsl(what), " must be in (0, ",
                                                 FormatNumber(kMaxTimeSeconds),
                                                 "] seconds, got ", FormatNumber(seconds)));
}

absl::Status ValidateSpeedKnots(std::span<const SpeedKnot> knots, double frame_time_seconds,
                                const RetimeOptions& options) {
  double previous = 0.0;
  for (std::size_t k = 0; k < knots.size(); ++k) {
    const SpeedKnot& knot = knots[k];
    TEMPOKEY_RETURN_IF_ERROR(ValidateTimePoint(absl::StrCat("speed knot ", k + 1), knot.time));
    if (!std::isfinite(knot.speed)) {
      return absl::InvalidArgumentError(absl::StrCat("speed knot ", k + 1, ": speed is ",
                                                     DescribeDouble(knot.speed)));
    }
    if (knot.speed <= 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat(DescribeSpeedKnot(k, knot), ": speed must be > 0"));
    }
    if (knot.speed < options.min_speed || knot.speed > options.max_speed) {
      return absl::InvalidArgumentError(absl::StrCat(
          DescribeSpeedKnot(k, knot), ": speed ", FormatNumber(knot.speed),
          " is outside the allowed range [", FormatNumber(options.min_speed), ", ",
          FormatNumber(options.max_speed), "]"));
    }
    const double seconds = knot.time.Seconds(frame_time_seconds);
    if (k > 0 && seconds < previous) {
      return absl::InvalidArgumentError(absl::StrCat(
          DescribeSpeedKnot(k, knot), ": time ", DescribeTimePoint(knot.time),
          " is before the previous knot's ", DescribeTimePoint(knots[k - 1].time)));
    }
    previous = seconds;
  }
  return absl::OkStatus();
}

}  // namespace retime_internal

namespace {

using retime_internal::FormatNumber;

absl::Status ValidateEnums(const RetimeOptions& options) {
  const auto filter = static_cast<int>(options.filter);
  if (filter < static_cast<int>(ResampleFilter::kTent) ||
      filter > static_cast<int>(ResampleFilter::kLanczos3)) {
    return absl::InvalidArgumentError(absl::StrCat("unknown resample filter ", filter));
  }
  const auto method = static_cast<int>(options.method);
  if (method < static_cast<int>(RetimeMethod::kExact) || method > static_cast<int>(RetimeMethod::kPaper)) {
    return absl::InvalidArgumentError(absl::StrCat("unknown retime method ", method));
  }
  const auto mode = static_cast<int>(options.rotation_mode);
  if (mode < static_cast<int>(RotationMode::kQuaternion) ||
      mode > static_cast<int>(RotationMode::kEuler)) {
    return absl::InvalidArgumentError(absl::StrCat("unknown rotation mode ", mode));
  }
  return absl::OkStatus();
}

// The output's size against `limits` (a server passes its own, tighter than core's).
absl::Status CheckOutputSize(std::int64_t frames, std::size_t channels, const ClipLimits& limits) {
  if (frames > limits.max_frames) {
    return absl::InvalidArgumentError(absl::StrCat("the retimed clip would have ", frames,
                                                   " frames, over the limit of ",
                                                   limits.max_frames, " frames"));
  }
  const std::int64_t limit = limits.max_samples;
  if (channels > 0 && frames > limit / static_cast<std::int64_t>(channels)) {
    return absl::InvalidArgumentError(absl::StrCat("the retimed clip would have ", frames,
                                                   " frames x ", channels,
                                                   " channels, over the limit of ", limit,
                                                   " samples"));
  }
  return absl::OkStatus();
}

// Where every output sample reads the source, and how times map: from the exact map or the
// paper's schedule.
struct Schedule {
  std::vector<double> positions;
  std::vector<double> ratios;
  double output_frame_time = 1.0;
  double output_duration = 0.0;
  double fit_factor = 1.0;
  ResampleFilter filter = ResampleFilter::kTent;
  std::optional<TimeMap> map;  // exact method only
};

absl::StatusOr<Schedule> MakeSchedule(const Clip& clip, const TimeWarpSpec& warp,
                                      const RetimeOptions& options, std::stop_token stop) {
  Schedule schedule;
  if (options.method == RetimeMethod::kPaper) {
    TEMPOKEY_ASSIGN_OR_RETURN(retime_internal::PaperSchedule paper,
                              retime_internal::MakePaperSchedule(clip.frame_time_seconds,
                                                                 clip.frame_count, warp, options,
                                                                 stop));
    schedule.positions = std::move(paper.positions);
    schedule.ratios = std::move(paper.ratios);
    schedule.output_frame_time = clip.frame_time_seconds;
    schedule.output_duration =
        static_cast<double>(paper.output_count - 1) * clip.frame_time_seconds;
    schedule.filter = ResampleFilter::kBox;
    return schedule;
  }
  TEMPOKEY_ASSIGN_OR_RETURN(
      TimeMap map, TimeMap::Compile(clip.frame_time_seconds, clip.frame_count, warp, options));
  const auto m = static_cast<std::size_t>(map.output_frame_count());
  schedule.positions.resize(m);
  schedule.ratios.resize(m);
  map.SampleOutputGrid(schedule.positions, schedule.ratios);
  schedule.output_frame_time = map.output_frame_time_seconds();
  schedule.output_duration = map.output_duration_seconds();
  schedule.fit_factor = map.fit_factor();
  schedule.filter = options.filter;
  schedule.map = std::move(map);
  return schedule;
}

// Output time in seconds of source time `seconds`: through the exact map, or by inverting the
// paper's monotonic positions.
double MapTime(const Schedule& schedule, double source_frame_time, double seconds) {
  if (schedule.map) return schedule.map->OutputTime(seconds);
  const std::vector<double>& p = schedule.positions;
  const double x = seconds / source_frame_time;
  if (p.size() < 2) return 0.0;
  const bool forward = p.back() >= p.front();
  // First output index whose position passes x.
  std::size_t hi = forward ? static_cast<std::size_t>(std::lower_bound(p.begin(), p.end(), x) - p.begin())
                           : static_cast<std::size_t>(std::lower_bound(p.begin(), p.end(), x, std::greater<>()) - p.begin());
  double frame = 0.0;
  if (hi == 0) {
    frame = 0.0;
  } else if (hi >= p.size()) {
    frame = static_cast<double>(p.size() - 1);
  } else {
    const double a = p[hi - 1];
    const double b = p[hi];
    frame = static_cast<double>(hi - 1) + (b != a ? (x - a) / (b - a) : 0.0);
  }
  return frame * schedule.output_frame_time;
}

// Markers are finite with durations >= 0: ValidateClip() checked them.
std::vector<Marker> MapMarkers(const Clip& clip, const Schedule& schedule) {
  std::vector<Marker> out;
  out.reserve(clip.markers.size());
  for (const Marker& marker : clip.markers) {
    const double a = MapTime(schedule, clip.frame_time_seconds, marker.time_seconds);
    const double b = marker.duration_seconds > 0.0
                         ? MapTime(schedule, clip.frame_time_seconds,
                                   marker.time_seconds + marker.duration_seconds)
                         : a;
    out.push_back({marker.name, std::min(a, b), std::abs(b - a)});
  }
  return out;
}

}  // namespace

absl::Status ValidateRetime(const Clip& clip, const TimeWarpSpec& warp,
                            const RetimeOptions& options, const ClipLimits& limits) {
  return PlanRetimeOutput(clip.frame_time_seconds, clip.frame_count, clip.channels.size(), warp,
                          options, limits)
      .status();
}

absl::StatusOr<RetimeOutputShape> PlanRetimeOutput(double frame_time_seconds,
                                                   std::int64_t frame_count,
                                                   std::size_t channel_count,
                                                   const TimeWarpSpec& warp,
                                                   const RetimeOptions& options,
                                                   const ClipLimits& limits) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateEnums(options));
  RetimeOutputShape shape;
  if (options.method == RetimeMethod::kPaper) {
    TEMPOKEY_ASSIGN_OR_RETURN(retime_internal::PaperSchedule paper,
                              retime_internal::PlanPaperRegions(frame_time_seconds, frame_count,
                                                                warp, options));
    shape.frame_count = paper.output_count;
    shape.frame_time_seconds = frame_time_seconds;
  } else {
    TEMPOKEY_ASSIGN_OR_RETURN(TimeMap map,
                              TimeMap::Compile(frame_time_seconds, frame_count, warp, options));
    shape.frame_count = map.output_frame_count();
    shape.frame_time_seconds = map.output_frame_time_seconds();
  }
  TEMPOKEY_RETURN_IF_ERROR(CheckOutputSize(shape.frame_count, channel_count, limits));
  return shape;
}

absl::StatusOr<RetimeResult> Retime(const Clip& clip, const TimeWarpSpec& warp,
                                    const RetimeOptions& options, const ProgressFn& progress,
                                    std::stop_token stop, const ClipLimits& limits) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  TEMPOKEY_RETURN_IF_ERROR(ValidateEnums(options));
  TEMPOKEY_ASSIGN_OR_RETURN(Schedule schedule, MakeSchedule(clip, warp, options, stop));
  const auto m = static_cast<std::int64_t>(schedule.positions.size());
  TEMPOKEY_RETURN_IF_ERROR(CheckOutputSize(m, clip.channels.size(), limits));
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  TEMPOKEY_ASSIGN_OR_RETURN(ResamplePlan plan,
                            MakeResamplePlan(schedule.positions, schedule.ratios, clip.frame_count,
                                             schedule.filter, stop));

  RetimeResult result;
  Clip& out = result.clip;
  out.name = clip.name;
  out.frame_time_seconds = schedule.output_frame_time;
  out.frame_count = m;
  out.skeleton = clip.skeleton;
  out.channels.resize(clip.channels.size());
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    out.channels[c].joint = clip.channels[c].joint;
    out.channels[c].kind = clip.channels[c].kind;
    out.channels[c].name = clip.channels[c].name;
    out.channels[c].samples.resize(static_cast<std::size_t>(m));
  }
  out.markers = MapMarkers(clip, schedule);

  // Channels resampled as one rotation (three rotation channels of a joint, quaternion mode);
  // every other channel is a scalar, rotation angles unwrapped first.
  std::vector<int> group_of(clip.channels.size(), -1);
  std::vector<JointRotation> groups;
  if (options.rotation_mode == RotationMode::kQuaternion) {
    for (JointRotation& rotation : JointRotations(clip)) {
      if (rotation.channels.size() != 3) continue;
      for (int c : rotation.channels) group_of[static_cast<std::size_t>(c)] = static_cast<int>(groups.size());
      groups.push_back(std::move(rotation));
    }
  }
  // What every joint's rotation resampling shares: made once, when a joint needs it.
  std::optional<RotationSchedule> rotation_schedule;
  RotationScratch rotation_scratch;
  const auto total = static_cast<double>(clip.channels.size());
  std::size_t done = 0;
  std::vector<bool> group_done(groups.size(), false);
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const Channel& channel = clip.channels[c];
    if (group_of[c] >= 0) {
      const auto g = static_cast<std::size_t>(group_of[c]);
      if (group_done[g]) continue;
      group_done[g] = true;
      const JointRotation& rotation = groups[g];
      std::array<std::span<const double>, 3> source;
      std::array<std::span<double>, 3> target;
      for (int k = 0; k < 3; ++k) {
        const auto index = static_cast<std::size_t>(rotation.channels[static_cast<std::size_t>(k)]);
        source[k] = clip.channels[index].samples;
        target[k] = out.channels[index].samples;
      }
      if (!rotation_schedule) {
        rotation_schedule.emplace(plan, stop);
        // Left incomplete when a stop was requested: never used then.
        TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
      }
      ResampleRotation(plan, *rotation_schedule, rotation_scratch, rotation.order, source, target,
                       stop);
      done += 3;
    } else if (IsRotation(channel.kind)) {
      ResampleAngle(plan, channel.samples, out.channels[c].samples, stop);
      ++done;
    } else {
      ResampleScalar(plan, channel.samples, out.channels[c].samples, stop);
      ++done;
    }
    // The resamplers return early, their output incomplete, when a stop was requested.
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    ReportProgressOf(progress, static_cast<double>(done) / total, "retime ", done, "/",
                     clip.channels.size());
  }

  RetimeReport& report = result.report;
  report.output_duration_seconds = schedule.output_duration;
  report.output_frame_count = m;
  report.fit_factor = schedule.fit_factor;
  report.max_decimation_ratio = plan.max_ratio;
  report.filtered_sample_count = plan.filtered_count;
  return result;
}

absl::StatusOr<RetimePlan> PlanRetime(const Clip& clip, const TimeWarpSpec& warp,
                                      const RetimeOptions& options, const ClipLimits& limits) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateEnums(options));
  TEMPOKEY_ASSIGN_OR_RETURN(Schedule schedule, MakeSchedule(clip, warp, options, {}));
  const auto m = static_cast<std::int64_t>(schedule.positions.size());
  TEMPOKEY_RETURN_IF_ERROR(CheckOutputSize(m, clip.channels.size(), limits));
  TEMPOKEY_ASSIGN_OR_RETURN(ResamplePlan kernels,
                            MakeResamplePlan(schedule.positions, schedule.ratios, clip.frame_count,
                                             schedule.filter));
  RetimePlan plan;
  plan.report.output_duration_seconds = schedule.output_duration;
  plan.report.output_frame_count = m;
  plan.report.fit_factor = schedule.fit_factor;
  plan.report.max_decimation_ratio = kernels.max_ratio;
  plan.report.filtered_sample_count = kernels.filtered_count;
  plan.output_frame_time_seconds = schedule.output_frame_time;
  if (warp.domain == WarpDomain::kSpeedOverSource) {
    for (const SpeedKnot& knot : warp.speed) {
      plan.knot_output_seconds.push_back(
          MapTime(schedule, clip.frame_time_seconds, knot.time.Seconds(clip.frame_time_seconds)));
    }
  } else if (warp.domain == WarpDomain::kSpeedOverOutput && schedule.map && options.pins.empty()) {
    // The fit compresses an output-time curve by its factor (retime.h, kSpeedOverOutput).
    for (const SpeedKnot& knot : warp.speed) {
      const double output_seconds =
          knot.time.Seconds(schedule.output_frame_time) / schedule.map->fit_factor();
      plan.knot_source_seconds.push_back(schedule.map->reversed()
                                             ? schedule.map->SourceTime(
                                                   schedule.output_duration - output_seconds)
                                             : schedule.map->SourceTime(output_seconds));
    }
  }
  plan.source_frames = std::move(schedule.positions);
  plan.decimation_ratios = std::move(schedule.ratios);
  return plan;
}

std::string FormatSpeedKnots(std::span<const SpeedKnot> knots) {
  std::string text;
  for (const SpeedKnot& knot : knots) {
    if (!text.empty()) text += ',';
    AppendDouble(text, knot.time.value);
    text += knot.time.in_frames ? 'f' : 's';
    text += ':';
    AppendDouble(text, knot.speed);
  }
  return text;
}

absl::StatusOr<std::vector<SpeedKnot>> ParseSpeedKnots(std::string_view text) {
  auto trim = [](std::string_view s) {
    const auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; };
    while (!s.empty() && is_space(s.front())) s.remove_prefix(1);
    while (!s.empty() && is_space(s.back())) s.remove_suffix(1);
    return s;
  };
  text = trim(text);
  if (text.empty()) {
    return absl::InvalidArgumentError(
        "speed knots: empty, expected comma-separated time:speed knots such as 0s:1,2s:0.5");
  }
  std::vector<SpeedKnot> knots;
  std::size_t index = 0;
  while (true) {
    ++index;
    const std::size_t comma = text.find(',');
    const std::string_view raw = text.substr(0, comma);
    const std::string_view part = trim(raw);
    auto fail = [&](std::string_view what) {
      return absl::InvalidArgumentError(
          absl::StrCat("speed knot ", index, " '", AsAbsl(part), "': ", AsAbsl(what)));
    };
    // The one number parser of the file formats: finite, whole token, optional leading '+'.
    auto parse_number = [&](std::string_view field, std::string_view token,
                            double& value) -> absl::Status {
      const NumberError error = ParseDoubleToken(token, value);
      if (error == NumberError::kNone) return absl::OkStatus();
      return fail(absl::StrCat(AsAbsl(field), ": ", DescribeNumberError(error, token)));
    };
    if (index > retime_internal::kMaxWarpItems) {
      return OverLimitError(absl::StrCat("too many speed knots: over the limit of ",
                                         retime_internal::kMaxWarpItems));
    }
    const std::size_t colon = part.find(':');
    if (part.empty() || colon == std::string_view::npos) {
      return fail("expected time:speed, e.g. 2s:0.5");
    }
    if (part.find(':', colon + 1) != std::string_view::npos) {
      return fail("expected one ':' between time and speed");
    }
    const std::string_view time = trim(part.substr(0, colon));
    const std::string_view speed = trim(part.substr(colon + 1));
    SpeedKnot knot;
    if (time.empty()) return fail("time is missing");
    const char unit = time.back();
    if (unit != 's' && unit != 'f') return fail("time needs a unit, s or f");
    const std::string_view number = trim(time.substr(0, time.size() - 1));
    TEMPOKEY_RETURN_IF_ERROR(parse_number("time", number, knot.time.value));
    knot.time.in_frames = unit == 'f';
    TEMPOKEY_RETURN_IF_ERROR(parse_number("speed", speed, knot.speed));
    knots.push_back(knot);
    if (comma == std::string_view::npos) break;
    text = text.substr(comma + 1);
  }
  return knots;
}

}  // namespace tempokey::core
