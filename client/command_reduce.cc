// `tempokey reduce IN -o OUT ...`: key reduction on the server; keyed exports (.json, .anim) or
// curves baked back to samples at the source rate (.bvh, .csv).
#include <optional>
#include <variant>

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
constexpr FlagSpec kReduceCommandFlags[] = {kOutputFlag, kOverwriteFlag};
constexpr FlagSpec kExecutionFlags[] = {kJobFlag, kDetachFlag, kLabelFlag, kInputFpsFlag};
constexpr auto kReduceFlags = JoinFlags(kReduceCommandFlags, kReduceStepFlags, kExecutionFlags);

absl::Status Reduce(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> inputs, context.Positionals(kInArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string output, context.Required("--output"));
  TEMPOKEY_RETURN_IF_ERROR(
      CheckOutputIsNotTheInput(inputs[0], output, context.args().Has("--overwrite")));
  TEMPOKEY_ASSIGN_OR_RETURN(FileFormat format, FormatForPath("-o", output, kAllFormats));
  TEMPOKEY_ASSIGN_OR_RETURN(ExecutionMode mode, ExecutionModeFromFlags(context.args()));
  TEMPOKEY_ASSIGN_OR_RETURN(core::ReduceStep reduce, ReduceStepFromArgs(context.args()));
  TEMPOKEY_ASSIGN_OR_RETURN(core::Clip clip, ReadInputClip(context, inputs[0]));

  // glTF keeps the curves too, its rotations fitted against this clip within the rotation bound
  // and the joint bound, a joint per CPU at once (seconds a joint on a long or slowed clip).
  const GltfExportSource gltf{.source = &clip,
                              .max_rotation_error_degrees = GltfRotationBoundDegrees(reduce),
                              .joint_tolerance = GltfJointTolerance(reduce),
                              .threads = LocalCpuCount()};
  // Sampled outputs are the curves baked back at the source rate. Built whole, not grown: a
  // push_back onto a vector of variants made g++ 12 at -O2 report -Wmaybe-uninitialized on the
  // inactive alternatives it moves (a false positive).
  const bool bake = !IsKeyedFormat(format) && !IsGltfFormat(format);
  const std::vector<core::PipelineStep> steps =
      bake ? std::vector<core::PipelineStep>{std::move(reduce), core::BakeStep{}}
           : std::vector<core::PipelineStep>{std::move(reduce)};
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<core::PipelineResult> result,
                            ExecutePipeline(context, clip, steps, mode));
  if (!result) return absl::OkStatus();  // detached
  // A keyed glTF's rotations are other curves than the report's: what the file holds is said too.
  std::optional<core::GltfStats> gltf_stats;
  const auto* keyed = std::get_if<core::KeyedClip>(&result->output);
  if (keyed != nullptr && IsGltfFormat(format)) {
    TEMPOKEY_ASSIGN_OR_RETURN(gltf_stats, WriteKeyedGltf(output, format, *keyed, gltf));
  } else {
    TEMPOKEY_RETURN_IF_ERROR(WriteOutput(output, format, result->output, gltf));
  }
  const core::ReductionReport* report =
      result->reports.empty() ? nullptr
                              : std::get_if<core::ReductionReport>(&result->reports.front());
  if (report != nullptr) context.out() << FormatReductionReport(*report, clip);
  if (gltf_stats) {
    const core::WorldErrorReport* world =
        report != nullptr && report->world ? &*report->world : nullptr;
    context.out() << FormatGltfStats(*gltf_stats, world);
  }
  context.out() << SummaryLine("wrote", output);
  return absl::OkStatus();
}

}  // namespace

const Command& ReduceCommand() {
  static const Command command{
      .name = "reduce",
      .synopsis = "IN -o OUT.json|OUT.anim|OUT.gltf|OUT.glb|OUT.bvh|OUT.csv [options]",
      .summary = "reduce a clip to key-frame curves on the server",
      .description =
          "Reads IN (.bvh, or .csv with --input-fps), fits few-key Hermite curves to every\n"
          "channel on the server and writes OUT atomically by extension: .json (keyed curves,\n"
          "README schema), .anim (Maya) or .gltf / .glb (glTF 2.0 CUBICSPLINE; rotations fitted\n"
          "as quaternions within --tolerance degrees of IN, and within --joint-tolerance when\n"
          "given, as glTF plays the file, that bound alone without --tolerance) keep the keys;\n"
          ".bvh or .csv bake the curves back to samples at the source rate (a filtered clip).\n"
          "A glTF's own keys and joint error follow the report. Prints the quality\n"
          "report: keys kept, RMS and max error (degrees for rotations, file units for\n"
          "positions) and the worst channel and frame, then the joints' world-position error\n"
          "through the skeleton (max with its joint and frame, RMS; file units and % of the\n"
          "figure's height, the vertical extent of every joint and end site at the first frame).\n"
          "--joint-tolerance 1 keeps every joint and end site within 1 file unit of its source\n"
          "position at every frame, --joint-tolerance 0.5% within 0.5% of the figure's height.\n",
      .flags = kReduceFlags,
      .run = Reduce,
  };
  return command;
}

}  // namespace tempokey::client
