// `tempokey retime IN -o OUT --speed KNOTS ...`: a RetimeStep built from flags, run on the server.
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "client/cli_errors.h"
#include "client/clip_files.h"
#include "client/clip_summary.h"
#include "client/command.h"
#include "tempokey/core/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;

constexpr std::string_view kInArgument[] = {"IN"};
constexpr std::string_view kDomains[] = {"source", "output"};
constexpr std::string_view kFilters[] = {"tent", "linear", "box", "cubic", "lanczos3"};
constexpr std::string_view kMethods[] = {"exact", "paper"};
constexpr std::string_view kRotationModes[] = {"quaternion", "euler"};

constexpr FlagSpec kRetimeFlags[] = {
    kOutputFlag,
    {"--speed", "", "KNOTS",
     "time:speed knots, e.g. \"0s:1,2.5s:0.5,4s:2\" (times in s or f)"},
    {"--speed-over", "", "source|output",
     "timeline of the knot times (default source: the paper's)"},
    {"--time-map", "", "KEYS", "direct time-map keys OUT:SRC, e.g. \"0s:0s,2s:1s\" (instead of --speed)"},
    {"--hold", "", "T:DURATION", "freeze the pose at source time T for DURATION seconds",
     true},
    {"--pin", "", "T:FRAME", "make source time T land exactly on output frame FRAME",
     true},
    {"--reverse", "", "", "play the clip backwards"},
    {"--fit-frames", "", "N", "scale all speeds so the output has N frames"},
    {"--fit-seconds", "", "S", "scale all speeds so the output lasts S seconds"},
    {"--no-fit-to-grid", "", "", "do not nudge speeds so the last output frame is the last pose"},
    {"--fps", "", "RATE", "output frame rate: 30, 29.97, 30000/1001 (default: the source's)"},
    {"--filter", "", "NAME", "resampling filter: tent (default), linear, box, cubic, lanczos3"},
    {"--method", "", "NAME", "exact (default) or paper (the published region procedure)"},
    {"--rotation", "", "MODE", "quaternion (default) or euler (angles as scalars)"},
    {"--min-speed", "", "V", "lowest speed allowed (default 0.01)"},
    {"--max-speed", "", "V", "highest speed allowed (default 100)"},
    kJobFlag,
    kDetachFlag,
    kLabelFlag,
    kInputFpsFlag,
};

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

// The speed knots: core's parser; bad syntax is a usage error, anything else (e.g. a build
// without retiming) a plain failure.
absl::StatusOr<std::vector<core::SpeedKnot>> ParseSpeed(const std::string& text) {
  absl::StatusOr<std::vector<core::SpeedKnot>> knots = core::ParseSpeedKnots(text);
  if (knots.ok()) return knots;
  absl::Status status = core::Annotate(knots.status(), "--speed");
  if (status.code() == absl::StatusCode::kInvalidArgument) return AsUsageError(status);
  return status;
}

absl::Status WarpFromFlags(const ParsedArgs& args, core::TimeWarpSpec& warp) {
  std::optional<std::string> speed = args.Value("--speed");
  std::optional<std::string> time_map = args.Value("--time-map");
  std::optional<std::string> domain = args.Value("--speed-over");
  if (speed && time_map) return UsageError("--speed and --time-map exclude each other");
  if (domain && !speed) return UsageError("--speed-over needs --speed");
  if (speed) {
    std::string over = "source";
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

absl::Status OptionsFromFlags(const ParsedArgs& args, core::RetimeOptions& options) {
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
    TEMPOKEY_ASSIGN_OR_RETURN(std::string name, ParseChoice("--filter", *filter, kFilters));
    constexpr core::ResampleFilter kByName[] = {
        core::ResampleFilter::kTent, core::ResampleFilter::kLinear, core::ResampleFilter::kBox,
        core::ResampleFilter::kCubic, core::ResampleFilter::kLanczos3};
    options.filter = kByName[std::find(std::begin(kFilters), std::end(kFilters), name) -
                             std::begin(kFilters)];
  }
  if (std::optional<std::string> method = args.Value("--method")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string name, ParseChoice("--method", *method, kMethods));
    options.method = name == "exact" ? core::RetimeMethod::kExact : core::RetimeMethod::kPaper;
  }
  if (std::optional<std::string> rotation = args.Value("--rotation")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string name, ParseChoice("--rotation", *rotation, kRotationModes));
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
  return absl::OkStatus();
}

absl::Status Retime(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> inputs, context.Positionals(kInArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string output, context.Required("--output"));
  TEMPOKEY_ASSIGN_OR_RETURN(FileFormat format, FormatForPath("-o", output, kSampledFormats));
  TEMPOKEY_ASSIGN_OR_RETURN(ExecutionMode mode, ExecutionModeFromFlags(context.args()));
  core::RetimeStep step;
  TEMPOKEY_RETURN_IF_ERROR(OptionsFromFlags(context.args(), step.options));
  TEMPOKEY_RETURN_IF_ERROR(WarpFromFlags(context.args(), step.warp));
  TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, ReadInputClip(context, inputs[0]));

  const core::PipelineStep steps[] = {std::move(step)};
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<core::PipelineResult> result,
                            ExecutePipeline(context, clip, steps, mode));
  if (!result) return absl::OkStatus();  // detached
  TEMPOKEY_RETURN_IF_ERROR(WriteOutput(output, format, result->output));
  if (!result->reports.empty()) {
    if (const auto* report = std::get_if<core::RetimeReport>(&result->reports.front())) {
      context.out() << FormatRetimeReport(*report);
    }
  }
  context.out() << SummaryLine("wrote", output)
                << FormatClipSummary(std::get<core::Clip>(result->output));
  return absl::OkStatus();
}

}  // namespace

const Command& RetimeCommand() {
  static const Command command{
      .name = "retime",
      .synopsis = "IN -o OUT [--speed KNOTS] [options]",
      .summary = "retime a clip along a speed curve on the server (.bvh or .csv out)",
      .description =
          "Reads IN (.bvh, or .csv with --input-fps), retimes it on the server and writes OUT\n"
          "atomically in the format of its extension (.bvh or .csv). Speed 1 plays normally,\n"
          "0.5 is half speed (slow motion), 2 double speed; between knots speed changes\n"
          "linearly, outside them it holds. Two knots at one time make a step. Without --speed\n"
          "or --time-map the timing is kept (a frame-rate change, a fit or a reverse alone).\n"
          "\n"
          "Examples:\n"
          "  tempokey retime walk.bvh -o slow.bvh --speed \"0s:1,2s:1,2s:0.5,4s:0.5,4s:1\"\n"
          "  tempokey retime walk.bvh -o walk30.bvh --fps 30\n"
          "  tempokey retime walk.bvh -o fit.bvh --speed \"0s:1,1s:2\" --fit-seconds 3\n",
      .flags = kRetimeFlags,
      .run = Retime,
  };
  return command;
}

}  // namespace tempokey::client
