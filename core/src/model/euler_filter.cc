// The Euler filter (SPEC 4.3); definitions in euler_filter.h.
#include "tempokey/core/model/euler_filter.h"

#include <cmath>
#include <vector>

#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

// The sum of absolute differences (L1). Not the squared (L2) distance: at a real rotation jump
// both branches jump, and L2, which weighs one large step more than several moderate ones, picks
// the branch that spreads the jump over all three angles; L1 picks the one whose steps are
// smaller in total, which keeps the jump in fewer curves. On CMU 131_01's right thumb (frame
// 237, a 171 degree rotation change) L2 kept the branch whose three angles all step by 78-155
// degrees where L1 keeps the one whose steps add up to 16 degrees less; the tolerance fit keeps
// 2 keys fewer (bench/euler_filter_bench).
double AbsoluteDistance(const Vec3& a, const Vec3& b) {
  return std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
}

}  // namespace

Vec3 NearestEquivalentEuler(const Vec3& degrees, const Vec3& previous) {
  // Each branch's nearest member moves every angle to within 180 of the previous one.
  const Vec3 same = {NearestTurn(degrees[0], previous[0]), NearestTurn(degrees[1], previous[1]),
                     NearestTurn(degrees[2], previous[2])};
  const Vec3 flipped = {NearestTurn(degrees[0] + 180.0, previous[0]),
                        NearestTurn(180.0 - degrees[1], previous[1]),
                        NearestTurn(degrees[2] + 180.0, previous[2])};
  return AbsoluteDistance(flipped, previous) < AbsoluteDistance(same, previous) ? flipped : same;
}

absl::StatusOr<EulerFilterReport> ApplyEulerFilter(Clip& clip) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  EulerFilterReport report;
  for (const JointRotation& joint : JointRotations(clip)) {
    if (joint.channels.size() != 3) {
      for (int c : joint.channels) UnwrapDegrees(clip.channels[c].samples);
      continue;
    }
    ++report.joints_filtered;
    std::vector<double>& a = clip.channels[joint.channels[0]].samples;
    std::vector<double>& b = clip.channels[joint.channels[1]].samples;
    std::vector<double>& c = clip.channels[joint.channels[2]].samples;
    for (std::size_t f = 1; f < a.size(); ++f) {
      const Vec3 source = {a[f], b[f], c[f]};
      const Vec3 filtered = NearestEquivalentEuler(source, {a[f - 1], b[f - 1], c[f - 1]});
      if (filtered != source) {
        a[f] = filtered[0];
        b[f] = filtered[1];
        c[f] = filtered[2];
        ++report.frames_changed;
      }
    }
  }
  return report;
}

}  // namespace tempokey::core
