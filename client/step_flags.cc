#include "client/step_flags.h"

#include <algorithm>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client/cli_errors.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;

// ---- retime -------------------------------------------------------------------------------------

constexpr std::string_view kDomains[] = {"source", "output"};
constexpr std::string_view kFilters[] = {"tent", "linear", "box", "cubic", "lanczos3"};
constexpr std::string_view kRetimeMethods[] = {"exact", "paper"};
constexpr std::string_view kRotationModes[] = {"quaternion", "euler"};

absl::StatusOr<std::vector<core::TimeMapKey>> ParseTimeMap(std::string_view text) {
  std::vector<core::TimeMapKey> keys;
  for (absl::string_view key : absl::StrSplit(AsAbsl(text), ',')) {
    TEMPOKEY_ASSIGN_OR_RETURN(auto pair, SplitPair("--time-map", core::AsStd(key), "OUT:SRC keys"));
    core::TimeMapKey parsed;
    TEMPOKEY_ASSIGN_OR_RETURN(parsed.output, ParseTimePoint("--time-map", pair.first));
    TEMPOKEY_ASSIGN_OR_RETURN(parsed.source, ParseTimePoint("--time-map", pair.second));
    keys.push_back(parsed);
  }
  return keys;
}

// The speed knots: core's parser; bad syntax or too many knots is a usage error, anything else
// (e.g. a build without retiming) a plain failure.
absl::StatusOr<std::vector<core::SpeedKnot>> ParseSpeed(const std::string& text) {
  absl::StatusOr<std::vector<core::SpeedKnot>> knots = core::ParseSpeedKnots(text);
  if (knots.ok()) return knots;
  absl::Status status = core::Annotate(knots.status(), "--speed");
  if (status.code() == absl::StatusCode::kInvalidArgument ||
      status.code() == absl::StatusCode::kResourceExhausted) {
    return AsUsageError(status);
  }
  return status;
}

absl::Status WarpFromFlags(const ParsedArgs& args, core::TimeWarpSpec& warp) {
  std::optional<std::string> speed = args.Value("--speed");
  std::optional<std::string> time_map = args.Value("--time-map");
  std::optional<std::string> domain = args.Value("--speed-over");
  if (speed && time_map) return UsageError("--speed and --time-map exclude each other");
  if (domain && !speed) return UsageError("--speed-over needs --speed");
  if (speed) {
    std::string_view over = "source";
    if (domain) { TEMPOKEY_ASSIGN_OR_RETURN(over, ParseChoice("--speed-over", *domain, kDomains)); }
    warp.domain = over == "source" ? core::WarpDomain::kSpeedOverSource
                                   : core::WarpDomain::kSpeedOverOutput;
    TEMPOKEY_ASSIGN_OR_RETURN(warp.speed, ParseSpeed(*speed));
  } else if (time_map) {
    warp.domain = core::WarpDomain::kTimeMapKeys;
    TEMPOKEY_ASSIGN_OR_RETURN(warp.keys, ParseTimeMap(*time_map));
  }
  for (const std::string& hold : args.Values("--hold")) {
    TEMPOKEY_ASSIGN_OR_RETURN(auto pair, SplitPair("--hold", hold, "T:DURATION, such as 2s:0.5s"));
    core::Hold parsed;
    TEMPOKEY_ASSIGN_OR_RETURN(parsed.at, ParseTimePoint("--hold", pair.first));
    TEMPOKEY_ASSIGN_OR_RETURN(parsed.duration_seconds, ParseSeconds("--hold", pair.second));
    warp.holds.push_back(parsed);
  }
  warp.reverse = args.Has("--reverse");
  return absl::OkStatus();
}

absl::Status RetimeOptionsFromArgs(const ParsedArgs& args, core::RetimeOptions& options) {
  std::optional<std::string> fit_frames = args.Value("--fit-frames");
  std::optional<std::string> fit_seconds = args.Value("--fit-seconds");
  if (fit_frames && fit_seconds) return UsageError("--fit-frames and --fit-seconds exclude each other");
  if (fit_frames) { TEMPOKEY_ASSIGN_OR_RETURN(options.fit_frames, ParseInt64("--fit-frames", *fit_frames)); }
  if (fit_seconds) {
    TEMPOKEY_ASSIGN_OR_RETURN(options.fit_seconds, ParseSeconds("--fit-seconds", *fit_seconds));
  }
  options.fit_to_grid = !args.Has("--no-fit-to-grid");
  if (std::optional<std::string> fps = args.Value("--fps")) {
    TEMPOKEY_ASSIGN_OR_RETURN(options.output_rate, ParseFrameRate("--fps", *fps));
  }
  if (std::optional<std::string> filter = args.Value("--filter")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string_view name, ParseChoice("--filter", *filter, kFilters));
    constexpr core::ResampleFilter kByName[] = {
        core::ResampleFilter::kTent, core::ResampleFilter::kLinear, core::ResampleFilter::kBox,
        core::ResampleFilter::kCubic, core::ResampleFilter::kLanczos3};
    options.filter = kByName[std::find(std::begin(kFilters), std::end(kFilters), name) -
                             std::begin(kFilters)];
  }
  if (std::optional<std::string> method = args.Value("--method")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string_view name, ParseChoice("--method", *method, kRetimeMethods));
    options.method = name == "exact" ? core::RetimeMethod::kExact : core::RetimeMethod::kPaper;
  }
  if (std::optional<std::string> rotation = args.Value("--rotation")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string_view name, ParseChoice("--rotation", *rotation, kRotationModes));
    options.rotation_mode =
        name == "quaternion" ? core::RotationMode::kQuaternion : core::RotationMode::kEuler;
  }
  for (const std::string& pin : args.Values("--pin")) {
    TEMPOKEY_ASSIGN_OR_RETURN(auto pair, SplitPair("--pin", pin, "T:FRAME, such as 2s:60"));
    core::Pin parsed;
    TEMPOKEY_ASSIGN_OR_RETURN(parsed.source, ParseTimePoint("--pin", pair.first));
    TEMPOKEY_ASSIGN_OR_RETURN(parsed.output_frame, ParseInt64("--pin", pair.second));
    options.pins.push_back(parsed);
  }
  if (std::optional<std::string> v = args.Value("--min-speed")) {
    TEMPOKEY_ASSIGN_OR_RETURN(options.min_speed, ParsePositiveDouble("--min-speed", *v));
  }
  if (std::optional<std::string> v = args.Value("--max-speed")) {
    TEMPOKEY_ASSIGN_OR_RETURN(options.max_speed, ParsePositiveDouble("--max-speed", *v));
  }
  // The core refuses these too, in the names of the options' fields ("output_rate must be
  // unset"); a command line gets the flags' names.
  if (options.method == core::RetimeMethod::kPaper) {
    constexpr std::pair<const char*, const char*> kNotForPaper[] = {
        {"--fps", "the published procedure keeps the source's frame rate"},
        {"--fit-frames", "the published procedure rounds each region's frames itself"},
        {"--fit-seconds", "the published procedure rounds each region's frames itself"},
        {"--pin", "the published procedure has no pins"},
    };
    for (const auto& [flag, reason] : kNotForPaper) {
      if (args.Has(flag)) {
        return UsageError(absl::StrCat("--method paper takes no ", flag, ": ", reason));
      }
    }
    // Its own box is the one filter it takes (a pipeline may name it).
    if (std::optional<std::string> filter = args.Value("--filter"); filter && *filter != "box") {
      return UsageError("--method paper takes no --filter other than box: the published procedure "
                        "weights samples with its own box");
    }
  }
  return absl::OkStatus();
}

// ---- reduce -------------------------------------------------------------------------------------

constexpr std::string_view kReduceMethods[] = {"tolerance", "paper", "noise"};
constexpr std::string_view kOnOff[] = {"on", "off"};
constexpr std::string_view kAlignments[] = {"none", "joint", "clip"};

constexpr std::string_view kToleranceOnly[] = {"--tolerance",      "--position-tolerance",
                                               "--scalar-tolerance", "--key-budget",
                                               "--pose-align",       "--joint-tolerance",
                                               "--fewest-keys"};
constexpr std::string_view kPaperOnly[] = {"--step-x",     "--step-y",     "--step-tangent-x",
                                           "--step-tangent-y", "--accuracy", "--iterations",
                                           "--smoothing-sigma", "--min-key-spacing"};
constexpr std::string_view kNoiseOnly[] = {"--noise", "--position-noise"};

// "auto" (nullopt: estimated) or a noise level; the range is core's to check.
absl::Status SetNoise(const ParsedArgs& args, std::string_view flag,
                      std::optional<double>& field) {
  if (std::optional<std::string> v = args.Value(flag)) {
    if (*v == "auto") {
      field.reset();
    } else {
      TEMPOKEY_ASSIGN_OR_RETURN(field, ParseDouble(flag, *v));
    }
  }
  return absl::OkStatus();
}

// Sets `field` from `flag` when given.
absl::Status SetDouble(const ParsedArgs& args, std::string_view flag, double& field) {
  if (std::optional<std::string> v = args.Value(flag)) {
    TEMPOKEY_ASSIGN_OR_RETURN(field, ParseDouble(flag, *v));
  }
  return absl::OkStatus();
}

absl::Status SetOptionalDouble(const ParsedArgs& args, std::string_view flag,
                               std::optional<double>& field) {
  if (std::optional<std::string> v = args.Value(flag)) {
    TEMPOKEY_ASSIGN_OR_RETURN(field, ParseDouble(flag, *v));
  }
  return absl::OkStatus();
}

// "1" (file units) or "0.5%" (of the figure's height). The value's range is core's to check.
absl::StatusOr<core::JointTolerance> ParseJointTolerance(std::string_view text) {
  core::JointTolerance tolerance;
  std::string_view number = text;
  if (!number.empty() && number.back() == '%') {
    tolerance.percent_of_height = true;
    number.remove_suffix(1);
  }
  absl::StatusOr<double> value = ParseDouble("--joint-tolerance", number);
  if (!value.ok()) {
    return UsageError(absl::StrCat(
        "--joint-tolerance: expected a distance in file units or a percentage of the figure's "
        "height (1, 0.5%), got '",
        core::AsAbsl(text), "'"));
  }
  tolerance.value = *value;
  return tolerance;
}

absl::Status SetInt(const ParsedArgs& args, std::string_view flag, int& field) {
  if (std::optional<std::string> v = args.Value(flag)) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t value, ParseInt64(flag, *v));
    if (value < INT32_MIN || value > INT32_MAX) {
      return UsageError(absl::StrCat(core::AsAbsl(flag), ": ", value, " is out of range"));
    }
    field = static_cast<int>(value);
  }
  return absl::OkStatus();
}

absl::StatusOr<core::ReduceOptions> ReduceOptionsFromArgs(const ParsedArgs& args) {
  core::ReduceOptions options;
  std::string_view method = "tolerance";
  if (std::optional<std::string> v = args.Value("--method")) {
    TEMPOKEY_ASSIGN_OR_RETURN(method, ParseChoice("--method", *v, kReduceMethods));
  }
  options.method = method == "paper"   ? core::ReduceMethod::kPaper
                   : method == "noise" ? core::ReduceMethod::kNoise
                                       : core::ReduceMethod::kTolerance;
  for (const auto& [flags, owner] :
       {std::pair{std::span<const std::string_view>(kToleranceOnly), "tolerance"},
        std::pair{std::span<const std::string_view>(kPaperOnly), "paper"},
        std::pair{std::span<const std::string_view>(kNoiseOnly), "noise"}}) {
    if (method == owner) continue;
    for (std::string_view flag : flags) {
      if (args.Has(flag)) {
        return UsageError(absl::StrCat(core::AsAbsl(flag), " does not apply to --method ", core::AsAbsl(method)));
      }
    }
  }
  if (std::optional<std::string> v = args.Value("--euler-filter")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string_view on, ParseChoice("--euler-filter", *v, kOnOff));
    options.euler_filter = on == "on";
  }
  TEMPOKEY_RETURN_IF_ERROR(SetNoise(args, "--noise", options.noise.rotation_sigma_degrees));
  TEMPOKEY_RETURN_IF_ERROR(SetNoise(args, "--position-noise", options.noise.position_sigma));

  core::ToleranceParams& tolerance = options.tolerance;
  TEMPOKEY_RETURN_IF_ERROR(
      SetOptionalDouble(args, "--tolerance", tolerance.max_rotation_error_degrees));
  TEMPOKEY_RETURN_IF_ERROR(
      SetOptionalDouble(args, "--position-tolerance", tolerance.max_position_error));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--scalar-tolerance", tolerance.max_scalar_error));
  if (std::optional<std::string> v = args.Value("--joint-tolerance")) {
    TEMPOKEY_ASSIGN_OR_RETURN(tolerance.joint_tolerance, ParseJointTolerance(*v));
  }
  if (std::optional<std::string> v = args.Value("--key-budget")) {
    TEMPOKEY_ASSIGN_OR_RETURN(tolerance.key_budget, ParseInt64("--key-budget", *v));
  }
  tolerance.fewest_keys = args.Has("--fewest-keys");
  if (std::optional<std::string> v = args.Value("--pose-align")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string_view name, ParseChoice("--pose-align", *v, kAlignments));
    tolerance.pose_alignment = name == "none"    ? core::PoseAlignment::kNone
                               : name == "joint" ? core::PoseAlignment::kJoint
                                                 : core::PoseAlignment::kClip;
  }

  core::PaperParams& paper = options.paper;
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--step-x", paper.step_x_frames));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--step-y", paper.step_y));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--step-tangent-x", paper.step_tangent_x));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--step-tangent-y", paper.step_tangent_y));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--accuracy", paper.accuracy));
  TEMPOKEY_RETURN_IF_ERROR(SetInt(args, "--iterations", paper.max_iterations));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--smoothing-sigma", paper.smoothing_sigma_frames));
  TEMPOKEY_RETURN_IF_ERROR(SetInt(args, "--min-key-spacing", paper.min_key_spacing_frames));
  return options;
}

}  // namespace

absl::StatusOr<core::RetimeStep> RetimeStepFromArgs(const ParsedArgs& args) {
  core::RetimeStep step;
  TEMPOKEY_RETURN_IF_ERROR(RetimeOptionsFromArgs(args, step.options));
  TEMPOKEY_RETURN_IF_ERROR(WarpFromFlags(args, step.warp));
  step.euler_filter = args.Has("--euler-filter");
  return step;
}

absl::StatusOr<core::ReduceStep> ReduceStepFromArgs(const ParsedArgs& args) {
  TEMPOKEY_ASSIGN_OR_RETURN(core::ReduceOptions options, ReduceOptionsFromArgs(args));
  return core::ReduceStep{.options = options};
}

absl::StatusOr<core::BakeStep> BakeStepFromArgs(const ParsedArgs& args) {
  core::BakeStep step;
  if (std::optional<std::string> fps = args.Value("--fps")) {
    TEMPOKEY_ASSIGN_OR_RETURN(step.rate, ParseFrameRate("--fps", *fps));
  }
  return step;
}

absl::StatusOr<core::ConvertStep> ConvertStepFromArgs(const ParsedArgs& args) {
  return core::ConvertStep{.wrap_rotations = args.Has("--wrap-rotations"),
                           .euler_filter = args.Has("--euler-filter")};
}

}  // namespace tempokey::client
