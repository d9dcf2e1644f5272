// Placeholder until key reduction lands (issue 3): every entry point answers UNIMPLEMENTED.
#include "tempokey/core/reduce.h"

namespace tempokey::core {

absl::Status ValidateReduceOptions(const ReduceOptions&) {
  return absl::UnimplementedError("reduce is not implemented by this server yet");
}

absl::StatusOr<ReduceResult> ReduceKeys(const Clip&, const ReduceOptions&, const ProgressFn&,
                                        std::stop_token) {
  return absl::UnimplementedError("reduce is not implemented by this server yet");
}

absl::StatusOr<ReductionReport> MeasureReduction(const Clip&, const KeyedClip&) {
  return absl::UnimplementedError("reduce is not implemented yet");
}

absl::Status ValidateKeyedClip(const KeyedClip&) {
  return absl::UnimplementedError("keyed clips are not implemented yet");
}

double EvaluateCurve(const Curve&, double) { return 0.0; }

absl::StatusOr<Clip> Bake(const KeyedClip&, std::optional<double>) {
  return absl::UnimplementedError("bake is not implemented by this server yet");
}

}  // namespace tempokey::core
