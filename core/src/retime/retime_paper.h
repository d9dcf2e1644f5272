// The paper's literal retiming procedure (RetimeMethod::kPaper), kept for comparison with the
// exact map and for users who want the published behaviour (SPEC 3.1).
//
// 1. The speed curve over the clip splits into regions of monotonic speed (a rise and a fall
//    meet at a region boundary; flat stretches join their neighbours).
// 2. Per region, the ratio of areas c / n (c = the area under constant normal speed, i.e. the
//    region's length in source frames; n = the area under the speed curve) gives its new
//    sample count round(length · c / n), rounded per region as the paper does.
// 3. A discrete integral places the new samples: p_{k+1} = p_k + g·v(p_k) from the region's
//    start, with the one constant g that makes the last step land on the region's end.
// 4. Values: interpolation where a position falls between old samples, weighted averaging (the
//    box over the step, ResampleFilter::kBox) where several old samples fall into one new one.
//
// For a constant speed this agrees with the exact map; for a ramp the area under v is an
// arithmetic mean where the exact duration needs the logarithmic one (0.25 -> 4: 0.471 instead
// of 0.739 output frames per source frame).
#ifndef TEMPOKEY_CORE_SRC_RETIME_RETIME_PAPER_H_
#define TEMPOKEY_CORE_SRC_RETIME_RETIME_PAPER_H_

#include <cstdint>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::core::retime_internal {

struct PaperRegion {
  double x0 = 0.0;               // source frames
  double x1 = 0.0;
  double speed_area = 0.0;       // ∫ v dx over the region, speed × source frames
  std::int64_t new_count = 0;    // output samples the region contributes
};

struct PaperSchedule {
  std::vector<PaperRegion> regions;
  std::vector<double> positions;  // source frames, one per output sample
  std::vector<double> ratios;     // local step in source frames per output frame
  std::int64_t output_count = 1;
};

// The regions and the output count only (cheap: no positions). Checks that `warp` and
// `options` fit the method: speed over source time (or the identity), no holds, keys, pins,
// fit or output rate.
// Errors: kInvalidArgument naming the unsupported option or the bad knot.
absl::StatusOr<PaperSchedule> PlanPaperRegions(double source_frame_time_seconds,
                                               std::int64_t source_frame_count,
                                               const TimeWarpSpec& warp,
                                               const RetimeOptions& options);

// PlanPaperRegions() plus every output sample's source position and step (a bisection per
// region over its discrete integral: about sixty passes over the region's output samples).
// Errors: those of PlanPaperRegions(); kCancelled when `stop` is requested.
absl::StatusOr<PaperSchedule> MakePaperSchedule(double source_frame_time_seconds,
                                                std::int64_t source_frame_count,
                                                const TimeWarpSpec& warp,
                                                const RetimeOptions& options,
                                                std::stop_token stop = {});

}  // namespace tempokey::core::retime_internal

#endif  // TEMPOKEY_CORE_SRC_RETIME_RETIME_PAPER_H_
