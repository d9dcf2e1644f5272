// Checks that a retimed clip's rotation channels move continuously: no frame-to-frame step the
// source does not have (used by the core corpus tests and the CLI end-to-end tests).
#ifndef TEMPOKEY_TESTS_TESTING_ANGLE_JUMPS_H_
#define TEMPOKEY_TESTS_TESTING_ANGLE_JUMPS_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "gtest/gtest.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/retime/resample.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/retime/time_map.h"

namespace tempokey::testing {

// The change of an angle from a to b the short way round (179 -> -179 is 2 degrees).
inline double AngleStep(double a, double b) { return std::abs(std::remainder(b - a, 360.0)); }

// Largest frame-to-frame change of an angle channel, measured the short way round.
inline double MaxAngleStep(const std::vector<double>& degrees) {
  double worst = 0.0;
  for (std::size_t i = 1; i < degrees.size(); ++i) {
    worst = std::max(worst, AngleStep(degrees[i - 1], degrees[i]));
  }
  return worst;
}

// Output steps of more than 20 degrees are only allowed where the source itself moves that
// much: the total variation (short-way steps summed) of the source over the frames the two
// output samples read (their positions widened by the tent's half-width and one frame) must
// cover the output step. A jump the source lacks, such as interpolating 180 -> -170 through 0,
// fails this.
constexpr double kJumpDegrees = 20.0;

struct Jump {
  std::size_t channel = 0;
  std::int64_t output_frame = 0;
  double output_step = 0.0;
  double source_variation = 0.0;
};

inline std::vector<Jump> JumpsTheSourceLacks(const core::Clip& source, const core::Clip& output,
                                             const core::TimeWarpSpec& warp,
                                             const core::RetimeOptions& options) {
  const absl::StatusOr<core::TimeMap> map =
      core::TimeMap::Compile(source.frame_time_seconds, source.frame_count, warp, options);
  EXPECT_TRUE(map.ok()) << map.status();
  std::vector<double> x(static_cast<std::size_t>(map->output_frame_count()));
  std::vector<double> rho(x.size());
  map->SampleOutputGrid(x, rho);
  const auto last = static_cast<double>(source.frame_count - 1);
  std::vector<Jump> jumps;
  for (std::size_t c = 0; c < source.channels.size(); ++c) {
    if (!core::IsRotation(source.channels[c].kind)) continue;
    const std::vector<double>& in = source.channels[c].samples;
    const std::vector<double>& out = output.channels[c].samples;
    for (std::size_t j = 1; j < out.size(); ++j) {
      const double step = AngleStep(out[j - 1], out[j]);
      if (step <= kJumpDegrees) continue;
      const double reach = 1.0 + std::max(core::TentHalfWidth(rho[j - 1]), core::TentHalfWidth(rho[j]));
      const auto lo = static_cast<std::size_t>(std::max(0.0, std::floor(std::min(x[j - 1], x[j]) - reach)));
      const auto hi = static_cast<std::size_t>(std::min(last, std::ceil(std::max(x[j - 1], x[j]) + reach)));
      double variation = 0.0;
      for (std::size_t i = lo + 1; i <= hi; ++i) variation += AngleStep(in[i - 1], in[i]);
      if (step > variation + 1e-9) {
        jumps.push_back({c, static_cast<std::int64_t>(j), step, variation});
      }
    }
  }
  return jumps;
}

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_TESTING_ANGLE_JUMPS_H_
