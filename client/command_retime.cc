// `tempokey retime IN -o OUT --speed KNOTS ...`: a RetimeStep built from flags, run on the server.
#include "absl/strings/str_cat.h"
#include "client/cli_errors.h"
#include "client/clip_files.h"
#include "client/clip_summary.h"
#include "client/command.h"
#include "client/step_flags.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

constexpr std::string_view kInArgument[] = {"IN"};
constexpr FlagSpec kRetimeCommandFlags[] = {kOutputFlag, kOverwriteFlag};
constexpr FlagSpec kExecutionFlags[] = {kJobFlag, kDetachFlag, kLabelFlag, kInputFpsFlag};
constexpr auto kRetimeFlags = JoinFlags(kRetimeCommandFlags, kRetimeStepFlags, kExecutionFlags);

absl::Status Retime(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> inputs, context.Positionals(kInArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string output, context.Required("--output"));
  TEMPOKEY_RETURN_IF_ERROR(
      CheckOutputIsNotTheInput(inputs[0], output, context.args().Has("--overwrite")));
  TEMPOKEY_ASSIGN_OR_RETURN(FileFormat format, FormatForPath("-o", output, kSampledOutputFormats));
  TEMPOKEY_ASSIGN_OR_RETURN(ExecutionMode mode, ExecutionModeFromFlags(context.args()));
  TEMPOKEY_ASSIGN_OR_RETURN(core::RetimeStep step, RetimeStepFromArgs(context.args()));
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
      .summary = "retime a clip along a speed curve on the server (.bvh, .csv, .gltf, .glb out)",
      .description =
          "Reads IN (.bvh, or .csv with --input-fps), retimes it on the server and writes OUT\n"
          "atomically in the format of its extension (.bvh, .csv, or glTF 2.0 .gltf / .glb with\n"
          "one LINEAR key per frame). Speed 1 plays normally,\n"
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
