// `tempokey reduce IN -o OUT ...`: key reduction on the server; keyed exports (.json, .anim) or
// curves baked back to samples at the source rate (.bvh, .csv).
#include "absl/strings/str_cat.h"
#include "client/cli_errors.h"
#include "client/clip_files.h"
#include "client/clip_summary.h"
#include "client/command.h"
#include "tempokey/core/status.h"

namespace tempokey::client {
namespace {

constexpr std::string_view kInArgument[] = {"IN"};
constexpr std::string_view kMethods[] = {"tolerance", "paper"};
constexpr std::string_view kAlignments[] = {"none", "joint", "clip"};

constexpr FlagSpec kReduceFlags[] = {
    kOutputFlag,
    {"--method", "", "NAME", "tolerance (default: fewest keys within a bound) or paper (Hermite DP)"},
    {"--tolerance", "", "DEG", "tolerance: max rotation error in degrees (default 0.5)"},
    {"--position-tolerance", "", "UNITS", "tolerance: max position error in file units (default 0.5)"},
    {"--scalar-tolerance", "", "V", "tolerance: max error of scalar channels (default 0.5)"},
    {"--key-budget", "", "N", "tolerance: at most N keys in all instead of an error bound"},
    {"--pose-align", "", "MODE", "tolerance: keys shared per none (default), joint or clip"},
    {"--step-x", "", "FRAMES", "paper: initial search step of key times (default 1)"},
    {"--step-y", "", "V", "paper: initial search step of key values (default 0.5)"},
    {"--step-tangent-x", "", "FRAMES", "paper: initial step of tangent x (default 1)"},
    {"--step-tangent-y", "", "V", "paper: initial step of tangent y (default 0.5)"},
    {"--accuracy", "", "A", "paper: stop when every step is below A (default 0.01)"},
    {"--iterations", "", "N", "paper: at most N refinement iterations (default 8)"},
    {"--smoothing-sigma", "", "FRAMES", "paper: smoothing used to find initial keys (default 2)"},
    {"--min-key-spacing", "", "FRAMES", "paper: minimum spacing of initial keys (default 4)"},
    kJobFlag,
    kDetachFlag,
    kLabelFlag,
    kInputFpsFlag,
};

constexpr std::string_view kToleranceOnly[] = {"--tolerance", "--position-tolerance",
                                               "--scalar-tolerance", "--key-budget", "--pose-align"};
constexpr std::string_view kPaperOnly[] = {"--step-x",     "--step-y",     "--step-tangent-x",
                                           "--step-tangent-y", "--accuracy", "--iterations",
                                           "--smoothing-sigma", "--min-key-spacing"};

// Sets `field` from `flag` when given.
absl::Status SetDouble(const ParsedArgs& args, std::string_view flag, double& field) {
  if (std::optional<std::string> v = args.Value(flag)) {
    TEMPOKEY_ASSIGN_OR_RETURN(field, ParseDouble(flag, *v));
  }
  return absl::OkStatus();
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

absl::StatusOr<core::ReduceOptions> OptionsFromFlags(const ParsedArgs& args) {
  core::ReduceOptions options;
  std::string method = "tolerance";
  if (std::optional<std::string> v = args.Value("--method")) {
    TEMPOKEY_ASSIGN_OR_RETURN(method, ParseChoice("--method", *v, kMethods));
  }
  options.method = method == "paper" ? core::ReduceMethod::kPaper : core::ReduceMethod::kTolerance;
  const auto& other_flags = method == "paper" ? std::span<const std::string_view>(kToleranceOnly)
                                              : std::span<const std::string_view>(kPaperOnly);
  for (std::string_view flag : other_flags) {
    if (args.Has(flag)) {
      return UsageError(absl::StrCat(core::AsAbsl(flag), " does not apply to --method ", method));
    }
  }

  core::ToleranceParams& tolerance = options.tolerance;
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--tolerance", tolerance.max_rotation_error_degrees));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--position-tolerance", tolerance.max_position_error));
  TEMPOKEY_RETURN_IF_ERROR(SetDouble(args, "--scalar-tolerance", tolerance.max_scalar_error));
  if (std::optional<std::string> v = args.Value("--key-budget")) {
    TEMPOKEY_ASSIGN_OR_RETURN(tolerance.key_budget, ParseInt64("--key-budget", *v));
  }
  if (std::optional<std::string> v = args.Value("--pose-align")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string name, ParseChoice("--pose-align", *v, kAlignments));
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

absl::Status Reduce(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> inputs, context.Positionals(kInArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string output, context.Required("--output"));
  TEMPOKEY_ASSIGN_OR_RETURN(FileFormat format, FormatForPath("-o", output, kAllFormats));
  TEMPOKEY_ASSIGN_OR_RETURN(ExecutionMode mode, ExecutionModeFromFlags(context.args()));
  TEMPOKEY_ASSIGN_OR_RETURN(core::ReduceOptions options, OptionsFromFlags(context.args()));
  TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, ReadInputClip(context, inputs[0]));

  std::vector<core::PipelineStep> steps = {core::ReduceStep{.options = options}};
  // Sampled outputs are the curves baked back at the source rate.
  if (!IsKeyedFormat(format)) steps.push_back(core::BakeStep{});
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<core::PipelineResult> result,
                            ExecutePipeline(context, clip, steps, mode));
  if (!result) return absl::OkStatus();  // detached
  TEMPOKEY_RETURN_IF_ERROR(WriteOutput(output, format, result->output));
  if (!result->reports.empty()) {
    if (const auto* report = std::get_if<core::ReductionReport>(&result->reports.front())) {
      context.out() << FormatReductionReport(*report, clip);
    }
  }
  context.out() << SummaryLine("wrote", output);
  return absl::OkStatus();
}

}  // namespace

const Command& ReduceCommand() {
  static const Command command{
      .name = "reduce",
      .synopsis = "IN -o OUT.json|OUT.anim|OUT.bvh|OUT.csv [options]",
      .summary = "reduce a clip to key-frame curves on the server",
      .description =
          "Reads IN (.bvh, or .csv with --input-fps), fits few-key Hermite curves to every\n"
          "channel on the server and writes OUT atomically by extension: .json (keyed curves,\n"
          "README schema) or .anim (Maya, weighted tangents) keep the keys; .bvh or .csv bake\n"
          "the curves back to samples at the source rate (a filtered clip). Prints the quality\n"
          "report: keys kept, RMS and max error (degrees for rotations, file units for\n"
          "positions) and the worst channel and frame.\n",
      .flags = kReduceFlags,
      .run = Reduce,
  };
  return command;
}

}  // namespace tempokey::client
