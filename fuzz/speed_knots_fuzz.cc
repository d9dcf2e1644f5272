// The CLI and pipeline-file speed syntax ("0s:1,2s:0.5,4s:1"): parsed knots are finite; as a
// retime over source or output time (the first byte chooses) they are validated against a small
// clip, and run when cheap: what validation accepts must run, and its output must be valid.
#include <cmath>
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "tempokey/core/retime/retime.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  if (size == 0) return 0;
  const std::uint8_t mode = data[0];
  const absl::StatusOr<std::vector<core::SpeedKnot>> knots =
      core::ParseSpeedKnots(AsText(data + 1, size - 1));
  if (!knots.ok()) {
    CheckCleanRefusal(knots.status(), "ParseSpeedKnots");
    return 0;
  }
  Check(!knots->empty(), "ParseSpeedKnots returned no knot");
  for (const core::SpeedKnot& knot : *knots) {
    Check(std::isfinite(knot.time.value) && std::isfinite(knot.speed), "a parsed knot is not finite");
  }
  static const core::Clip clip = SmallClip();
  core::RetimeStep retime;
  retime.warp.domain = (mode & 1) ? core::WarpDomain::kSpeedOverOutput
                                  : core::WarpDomain::kSpeedOverSource;
  retime.warp.speed = *knots;
  retime.warp.reverse = (mode & 2) != 0;
  retime.options.fit_to_grid = (mode & 4) == 0;
  constexpr core::ResampleFilter kFilters[] = {
      core::ResampleFilter::kTent, core::ResampleFilter::kLinear, core::ResampleFilter::kBox,
      core::ResampleFilter::kCubic, core::ResampleFilter::kLanczos3};
  retime.options.filter = kFilters[(mode >> 3) % std::size(kFilters)];
  if (mode & 0x80) retime.options.method = core::RetimeMethod::kPaper;
  const core::PipelineStep steps[] = {retime};
  ValidateAndRunIfCheap(clip, steps);
  return 0;
}
