// The Euler filter (SPEC 4.3); definitions in euler_filter.h.
#include "tempokey/core/model/euler_filter.h"

#include <vector>

#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

double SquaredDistance(const Vec3& a, const Vec3& b) {
  double sum = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double d = a[i] - b[i];
    sum += d * d;
  }
  return sum;
}

}  // namespace

Vec3 NearestEquivalentEuler(const Vec3& degrees, const Vec3& previous) {
  // Each branch's nearest member moves every angle to within 180 of the previous one.
  const Vec3 same = {NearestTurn(degrees[0], previous[0]), NearestTurn(degrees[1], previous[1]),
                     NearestTurn(degrees[2], previous[2])};
  const Vec3 flipped = {NearestTurn(degrees[0] + 180.0, previous[0]),
                        NearestTurn(180.0 - degrees[1], previous[1]),
                        NearestTurn(degrees[2] + 180.0, previous[2])};
  return SquaredDistance(flipped, previous) < SquaredDistance(same, previous) ? flipped : same;
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
