// The predicted work of a pipeline on a clip, known before anything runs: what a server compares
// with its limit to refuse, up front, a request it could not finish in reasonable time.
//
// The prediction walks the steps with the shape each one leaves (frames, frame time, channels,
// sampled or keyed), computed exactly from the options: a retime's output frame count from its
// compiled time map (TimeMap::Compile(), no resampling), a bake's from the rate. Every step is
// validated against that shape on the way, so chained retimes whose output would exceed the
// limits and key budgets below 2 keys per channel are refused here, not after minutes of work.
//
// Each step's cost is a count of its inner-loop work times a constant measured for that loop on
// one core of the reference machine (the 2-core CI machine type; bench/cost_bench prints
// predicted against measured). Counts are upper bounds where the algorithm has one:
//   retime     channels x (source + output frames) x filter taps (2 tent/box/linear, 4 cubic,
//              6 lanczos3) x a per-tap constant (the rotation-aware path's, the slowest); the
//              paper method adds its bisections (about 60 passes over the output); both add
//              the time map's compilation, per speed knot, time-map key, hold and pin.
//   reduce     tolerance: channels x frames x fits, the fits 1 without a key budget, else the
//              budget search's (1 + up to 20 halvings or doublings up to the scale whose bounds
//              cover every channel's range, and there up to 1 + log2(frames) fits from evenly
//              spread keys, + 12 bisections); the per-sample constant is the one
//              measured on white noise, the worst input (every frame keyed; a smooth channel
//              costs less because a removal merges at most kMaxMergedSegmentFrames).
//              noise: channels x frames, the per-sample constant measured on white noise.
//              paper: channels x [frames x smoothing taps (2 ceil(3 sigma) + 1) + max_iterations
//              x (frames x 81 basis solves + keys x 81 x 81 DP states)], keys at most
//              frames / min_key_spacing + 2: the worst case of a pass, when steps have become
//              fractions and no segment shares a cached x(s) = frame solution.
//   bake       output samples x a weighted-Bezier evaluation.
//   convert    samples x a few nanoseconds.
// Predictions are deliberately pessimistic (a fit that converges early, or a tolerance fit on
// smooth motion, costs a fraction); they are for refusing what cannot be afforded, not for
// progress estimates.
#ifndef TEMPOKEY_CORE_PIPELINE_COST_H_
#define TEMPOKEY_CORE_PIPELINE_COST_H_

#include <cstddef>
#include <span>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::core {

struct StepCost {
  std::size_t index = 0;   // the operation, 0-based
  std::string work;        // "reduce (paper): 1 channel x 16000 frames x up to 1000 passes"
  double seconds = 0.0;    // predicted CPU seconds on one core of the reference machine
};

struct PipelineCost {
  std::vector<StepCost> steps;
  double seconds = 0.0;    // the sum

  // "predicted 128 s of work (operation 1, reduce (paper): 1 channel x 16000 frames x up to
  // 1000 passes, 128 s)": the total and its largest step, for messages.
  std::string Describe() const;
};

// Validates `steps` on `clip` as ValidatePipeline() does, walking the exact shape of every
// step's input (see the file comment), and predicts each step's work. `clip`'s samples are read
// when present (a key budget's search depends on the channels' ranges); a layout without
// samples gets the bound kMaxSampleMagnitude instead.
// Errors: those of ValidatePipeline().
// Thread-safe.
absl::StatusOr<PipelineCost> EstimatePipelineCost(const Clip& clip,
                                                  std::span<const PipelineStep> steps,
                                                  const ClipLimits& limits = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_PIPELINE_COST_H_
