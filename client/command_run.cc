// `tempokey run IN -o OUT`: the foundation job. The clip goes to the server and comes back
// through the whole job path (upload, submit, watch, result), so one command shows the service
// works end to end; the output equals the input unless --wrap-rotations is given.
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

constexpr FlagSpec kRunCommandFlags[] = {
    kOutputFlag,
    kOverwriteFlag,
};
constexpr FlagSpec kRunModeFlags[] = {
    {"--process", "", "", "use one stateless Process call instead of a stored job"},
    kDetachFlag,
    kLabelFlag,
    kInputFpsFlag,
};
constexpr auto kRunFlags = JoinFlags(kRunCommandFlags, kConvertStepFlags, kRunModeFlags);

absl::Status Run(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> inputs, context.Positionals(kInArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string output, context.Required("--output"));
  TEMPOKEY_RETURN_IF_ERROR(
      CheckOutputIsNotTheInput(inputs[0], output, context.args().Has("--overwrite")));
  TEMPOKEY_ASSIGN_OR_RETURN(FileFormat format, FormatForPath("-o", output, kSampledFormats));
  ExecutionMode mode;
  mode.as_job = !context.args().Has("--process");
  mode.detach = context.args().Has("--detach");
  if (mode.detach && !mode.as_job) return UsageError("--detach and --process exclude each other");
  TEMPOKEY_ASSIGN_OR_RETURN(mode.labels, LabelsFromFlags(context.args()));
  if (!mode.labels.empty() && !mode.as_job) return UsageError("--label applies to jobs, not --process");
  TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, ReadInputClip(context, inputs[0]));

  TEMPOKEY_ASSIGN_OR_RETURN(core::ConvertStep convert, ConvertStepFromArgs(context.args()));
  const core::PipelineStep steps[] = {convert};
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<core::PipelineResult> result,
                            ExecutePipeline(context, clip, steps, mode));
  if (!result) return absl::OkStatus();  // detached
  TEMPOKEY_RETURN_IF_ERROR(WriteOutput(output, format, result->output));
  context.out() << SummaryLine("wrote", output)
                << FormatClipSummary(std::get<core::Clip>(result->output));
  return absl::OkStatus();
}

}  // namespace

const Command& RunCommand() {
  static const Command command{
      .name = "run",
      .synopsis = "IN -o OUT [options]",
      .summary = "send a clip through a server job and write it back (.bvh or .csv)",
      .description =
          "Reads IN (.bvh, or .csv with --input-fps), uploads it, runs it as a job on the server\n"
          "(a convert operation: the clip is validated and comes back unchanged, or with its\n"
          "rotations wrapped), follows the job, fetches the result and writes OUT atomically in\n"
          "the format of its extension. Prints the clip id, the job id and the output's\n"
          "summary.\n",
      .flags = kRunFlags,
      .run = Run,
  };
  return command;
}

}  // namespace tempokey::client
