// An ordered pipeline of operations on one clip (retime, reduce, bake, convert): what a job runs.
#ifndef TEMPOKEY_CORE_PIPELINE_PIPELINE_H_
#define TEMPOKEY_CORE_PIPELINE_PIPELINE_H_

#include <cstddef>
#include <optional>
#include <span>
#include <stop_token>
#include <string_view>
#include <variant>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::core {

struct RetimeStep {
  TimeWarpSpec warp;
  RetimeOptions options;
  // The Euler filter (euler_filter.h) on the output. Off by default: the rotation-aware retime
  // already keeps the source's Euler branch, and its output keeps the source's conventions.
  bool euler_filter = false;
};

struct ReduceStep {
  ReduceOptions options;
};

// Keyed clip -> sampled clip; unset rate keeps the source frame time.
struct BakeStep {
  std::optional<FrameRate> rate;
};

// Sampled clip -> sampled clip.
struct ConvertStep {
  bool wrap_rotations = false;
  // The Euler filter (euler_filter.h), before any re-wrap. Off by default: a conversion keeps the
  // values it is given unless asked.
  bool euler_filter = false;
};

using PipelineStep = std::variant<RetimeStep, ReduceStep, BakeStep, ConvertStep>;
using StepReport = std::variant<RetimeReport, ReductionReport>;

struct PipelineResult {
  std::variant<Clip, KeyedClip> output;
  std::vector<StepReport> reports;  // one per retime or reduce step, in order
};

// "retime", "reduce", "bake" or "convert".
std::string_view StepName(const PipelineStep& step);

// At most this many operations in one pipeline.
inline constexpr std::size_t kMaxPipelineSteps = 64;

// Checks the number of operations: 1..kMaxPipelineSteps.
// Errors: kInvalidArgument "the pipeline has no operations"; kResourceExhausted "the pipeline has
// 65 operations, over the limit of 64".
absl::Status ValidateStepCount(std::span<const PipelineStep> steps);

// Checks the shape of a pipeline without a clip: 1..kMaxPipelineSteps operations, each taking
// what the one before produces (retime, reduce and convert a sampled clip, bake a keyed one).
// Errors: kInvalidArgument "operation 2 (bake): needs a keyed clip, got a sampled clip".
absl::Status ValidateStepChain(std::span<const PipelineStep> steps);

// Whether `steps` (a valid chain) end with a keyed clip (a reduce not baked afterwards).
bool ProducesKeyedOutput(std::span<const PipelineStep> steps);

// Checks, before anything is queued, that the steps fit together (retime, reduce and convert
// take a sampled clip; bake takes a keyed clip), that each step's options are valid (a reduce's
// also against `clip`'s layout: ValidateReduceOptionsForClip(), ValidateReduceForLayout()), and
// every step against the exact shape of its input: the first against `clip`, each later one
// against what the steps before it produce, computed from their options alone (a retime's output
// frames from its time map, a bake's from its rate; cost.h). So a chain of retimes whose output
// would exceed `limits` and a key budget below the keys the clip's channels need are refused here.
// Errors: kInvalidArgument "operation 2 (bake): needs a keyed clip, got a sampled clip",
// "operation 2 (retime): the retimed clip would have 40000001 frames, over the limit of ...";
// kFailedPrecondition for a joint tolerance on a clip without a skeleton.
// `limits` caps what the steps may produce (a retime's or bake's frames and samples).
absl::Status ValidatePipeline(const Clip& clip, std::span<const PipelineStep> steps,
                              const ClipLimits& limits = {});

// Runs `steps` in order on `clip` (read, not copied, unless a step must change it in place).
// Progress is reported over the whole pipeline; cancellation is checked between steps and,
// inside them, often enough to answer within milliseconds (retime.h, reduce.h, Bake()), so a
// cancelled job frees its worker promptly. Outputs are held to `limits`.
// Errors: kCancelled "cancelled" once `stop` is requested.
// Errors: those of ValidatePipeline() and of each step, prefixed "operation 1 (retime): ".
absl::StatusOr<PipelineResult> RunPipeline(const Clip& clip, std::span<const PipelineStep> steps,
                                           const ProgressFn& progress = {},
                                           std::stop_token stop = {},
                                           const ClipLimits& limits = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_PIPELINE_PIPELINE_H_
