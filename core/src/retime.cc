// Placeholder until the retiming engine lands (issue 5): every entry point answers UNIMPLEMENTED.
#include "tempokey/core/retime.h"

namespace tempokey::core {

absl::StatusOr<RetimeResult> Retime(const Clip&, const TimeWarpSpec&, const RetimeOptions&,
                                    const ProgressFn&, std::stop_token) {
  return absl::UnimplementedError("retime is not implemented by this server yet");
}

absl::Status ValidateRetime(const Clip&, const TimeWarpSpec&, const RetimeOptions&) {
  return absl::UnimplementedError("retime is not implemented by this server yet");
}

absl::StatusOr<std::vector<SpeedKnot>> ParseSpeedKnots(std::string_view) {
  return absl::UnimplementedError("retime is not implemented yet");
}

}  // namespace tempokey::core
