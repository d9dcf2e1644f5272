#include "tempokey/core/pipeline/pipeline.h"

#include "tempokey/core/model/euler_filter.h"

#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/pipeline/cost.h"

namespace tempokey::core {
namespace {

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

bool TakesKeyedClip(const PipelineStep& step) { return std::holds_alternative<BakeStep>(step); }
bool ProducesKeyedClip(const PipelineStep& step) {
  return std::holds_alternative<ReduceStep>(step);
}

std::string StepContext(std::size_t index, const PipelineStep& step) {
  return absl::StrCat("operation ", index + 1, " (", AsAbsl(StepName(step)), ")");
}

// Wraps every rotation angle into (-180, 180]; stops (the clip half wrapped) when `stop` is
// requested, which the caller checks.
Clip WrapRotations(Clip clip, const std::stop_token& stop) {
  for (Channel& channel : clip.channels) {
    if (stop.stop_requested()) break;
    if (IsRotation(channel.kind)) WrapDegrees(channel.samples);
  }
  return clip;
}

}  // namespace

std::string_view StepName(const PipelineStep& step) {
  return std::visit(Overloaded{
                        [](const RetimeStep&) { return std::string_view("retime"); },
                        [](const ReduceStep&) { return std::string_view("reduce"); },
                        [](const BakeStep&) { return std::string_view("bake"); },
                        [](const ConvertStep&) { return std::string_view("convert"); },
                    },
                    step);
}

namespace {

// What each step needs and leaves: whether its input clip is keyed, given the one before.
class StepChain {
 public:
  // Errors: "operation 2 (bake): needs a keyed clip, got a sampled clip".
  absl::Status Accept(std::size_t index, const PipelineStep& step) {
    if (TakesKeyedClip(step) != keyed_) {
      return absl::InvalidArgumentError(absl::StrCat(
          StepContext(index, step), ": needs a ", TakesKeyedClip(step) ? "keyed" : "sampled",
          " clip, got a ", keyed_ ? "keyed clip (add a bake operation first)" : "sampled clip"));
    }
    if (ProducesKeyedClip(step)) keyed_ = true;
    if (TakesKeyedClip(step)) keyed_ = false;
    return absl::OkStatus();
  }

 private:
  bool keyed_ = false;
};

}  // namespace

absl::Status ValidateStepCount(std::span<const PipelineStep> steps) {
  if (steps.empty()) return absl::InvalidArgumentError("the pipeline has no operations");
  if (steps.size() > kMaxPipelineSteps) {
    return OverLimitError(absl::StrCat("the pipeline has ", steps.size(),
                                       " operations, over the limit of ", kMaxPipelineSteps));
  }
  return absl::OkStatus();
}

absl::Status ValidateStepChain(std::span<const PipelineStep> steps) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateStepCount(steps));
  StepChain chain;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    TEMPOKEY_RETURN_IF_ERROR(chain.Accept(i, steps[i]));
  }
  return absl::OkStatus();
}

absl::Status ValidatePipeline(const Clip& clip, std::span<const PipelineStep> steps,
                              const ClipLimits& limits) {
  // One walk validates and predicts (cost.h): every step against the exact shape of its input.
  return EstimatePipelineCost(clip, steps, limits).status();
}

bool ProducesKeyedOutput(std::span<const PipelineStep> steps) {
  // In a valid chain every step's output kind is its own: only a reduce leaves a keyed clip.
  return !steps.empty() && ProducesKeyedClip(steps.back());
}

absl::StatusOr<PipelineResult> RunPipeline(const Clip& clip, std::span<const PipelineStep> steps,
                                           const ProgressFn& progress, std::stop_token stop,
                                           const ClipLimits& limits) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  TEMPOKEY_RETURN_IF_ERROR(ValidatePipeline(clip, steps, limits));

  PipelineResult result;
  // The sampled clip the next step reads: the caller's until a step makes one of its own, so the
  // input is copied only if a step must change it in place (convert first).
  const Clip* input = &clip;
  auto own_input = [&]() -> Clip& {
    if (input != std::get_if<Clip>(&result.output)) result.output = *input;
    input = std::get_if<Clip>(&result.output);
    return std::get<Clip>(result.output);
  };
  const double step_share = 1.0 / static_cast<double>(steps.size());
  for (std::size_t i = 0; i < steps.size(); ++i) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const PipelineStep& step = steps[i];
    const double base = static_cast<double>(i) * step_share;
    // Empty without a listener, so that the steps make no labels for nobody.
    ProgressFn step_progress;
    if (progress) {
      step_progress = [&](double fraction, std::string_view stage) {
        progress(base + fraction * step_share, stage);
      };
    }
    ReportProgress(progress, base, StepName(step));

    absl::Status status = std::visit(
        Overloaded{
            [&](const RetimeStep& s) -> absl::Status {
              TEMPOKEY_ASSIGN_OR_RETURN(
                  RetimeResult r,
                  Retime(*input, s.warp, s.options, step_progress, stop, limits));
              result.output = std::move(r.clip);
              input = std::get_if<Clip>(&result.output);
              if (s.euler_filter) {
                TEMPOKEY_RETURN_IF_ERROR(ApplyEulerFilter(std::get<Clip>(result.output)).status());
              }
              result.reports.emplace_back(r.report);
              return absl::OkStatus();
            },
            [&](const ReduceStep& s) -> absl::Status {
              TEMPOKEY_ASSIGN_OR_RETURN(
                  ReduceResult r,
                  ReduceKeys(*input, s.options, step_progress, stop));
              result.output = std::move(r.keyed);
              input = nullptr;
              result.reports.emplace_back(std::move(r.report));
              return absl::OkStatus();
            },
            [&](const BakeStep& s) -> absl::Status {
              std::optional<double> frame_time;
              if (s.rate) {
                frame_time = static_cast<double>(s.rate->denominator) /
                             static_cast<double>(s.rate->numerator);
              }
              TEMPOKEY_ASSIGN_OR_RETURN(
                  Clip baked,
                  Bake(std::get<KeyedClip>(result.output), frame_time, limits, stop));
              result.output = std::move(baked);
              input = std::get_if<Clip>(&result.output);
              return absl::OkStatus();
            },
            [&](const ConvertStep& s) -> absl::Status {
              Clip& owned = own_input();
              if (s.euler_filter) TEMPOKEY_RETURN_IF_ERROR(ApplyEulerFilter(owned).status());
              if (s.wrap_rotations) owned = WrapRotations(std::move(owned), stop);
              return CheckNotCancelled(stop);
            },
        },
        step);
    if (!status.ok()) return Annotate(status, StepContext(i, step));
  }
  ReportProgress(progress, 1.0, "done");
  return result;
}

}  // namespace tempokey::core
