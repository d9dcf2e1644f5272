// The rotation-aware resampling of one joint as it was first written: sample by sample, each
// output converting its source quaternions, interpolating and converting back with the scalar
// functions of rotation.h. Kept as the reference the fast path (ResampleRotation()) is checked
// against: same kernel, same branch choices, results within rounding of the vectorised
// trigonometry. Its own output is pinned bit for bit by the identity tests, so it cannot drift.
#ifndef TEMPOKEY_TESTS_CORE_RETIME_ROTATION_REFERENCE_H_
#define TEMPOKEY_TESTS_CORE_RETIME_ROTATION_REFERENCE_H_

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "tempokey/core/model/rotation.h"
#include "tempokey/core/retime/resample.h"

namespace tempokey::testing {

namespace rotation_reference_internal {

using core::Quat;

// cos(150° / 2): adjacent rotations more than 150 degrees apart are a discontinuity (resample.h).
inline constexpr double kDiscontinuityDot = 0.25881904510252074;

inline bool HasWrap(std::span<const double> degrees) {
  for (std::size_t i = 1; i < degrees.size(); ++i) {
    if (std::abs(degrees[i] - degrees[i - 1]) > 180.0) return true;
  }
  return false;
}

inline std::int64_t NearestIndex(double x, std::int64_t last) {
  return std::clamp(static_cast<std::int64_t>(std::llround(x)), std::int64_t{0}, last);
}

inline double LerpAt(std::span<const double> values, double x) {
  const auto last = static_cast<std::int64_t>(values.size()) - 1;
  if (last <= 0) return values[0];
  const std::int64_t i0 = std::min(static_cast<std::int64_t>(std::floor(x)), last - 1);
  const double t = x - static_cast<double>(i0);
  const auto i = static_cast<std::size_t>(i0);
  return values[i] + t * (values[i + 1] - values[i]);
}

}  // namespace rotation_reference_internal

inline void ReferenceResampleRotation(const core::ResamplePlan& plan, const core::EulerOrder& order,
                                      const std::array<std::span<const double>, 3>& source,
                                      const std::array<std::span<double>, 3>& out) {
  using namespace core;
  using namespace rotation_reference_internal;
  const auto n = static_cast<std::size_t>(plan.source_count);
  const std::int64_t last = plan.source_count - 1;
  const std::size_t m = plan.position.size();
  if (plan.copy_count == plan.output_count()) {
    for (std::size_t j = 0; j < m; ++j) {
      const auto i = static_cast<std::size_t>(plan.first[j]);
      for (int c = 0; c < 3; ++c) out[c][j] = source[c][i];
    }
    return;
  }
  std::vector<Quat> quats(n);
  std::vector<unsigned char> converted(n, 0);
  auto quat = [&](std::size_t i) -> const Quat& {
    if (!converted[i]) {
      quats[i] = EulerToQuat(order, {source[0][i], source[1][i], source[2][i]});
      converted[i] = 1;
    }
    return quats[i];
  };
  std::array<std::vector<double>, 3> unwrapped;
  std::array<bool, 3> wraps{};
  for (int c = 0; c < 3; ++c) {
    wraps[c] = HasWrap(source[c]);
    if (wraps[c]) {
      unwrapped[c].assign(source[c].begin(), source[c].end());
      UnwrapDegrees(unwrapped[c]);
    }
  }
  auto reference_values = [&](int c) -> std::span<const double> {
    return wraps[c] ? std::span<const double>(unwrapped[c]) : source[c];
  };
  auto aligned = [](const Quat& q, const Quat& to) { return Dot(q, to) < 0.0 ? Negated(q) : q; };
  auto quat_at = [&](std::int64_t i) -> Quat {
    if (i < 0) return Multiply(Multiply(quat(0), Conjugate(quat(1))), quat(0));
    if (i > last) {
      const auto l = static_cast<std::size_t>(last);
      return Multiply(Multiply(quat(l), Conjugate(quat(l - 1))), quat(l));
    }
    return quat(static_cast<std::size_t>(i));
  };
  std::vector<Quat> taps;

  for (std::size_t j = 0; j < m; ++j) {
    const double x = plan.position[j];
    const std::int64_t first = plan.first[j];
    if (plan.kind[j] == SampleKind::kCopy) {
      for (int c = 0; c < 3; ++c) out[c][j] = source[c][static_cast<std::size_t>(first)];
      continue;
    }
    Quat q;
    const auto k = static_cast<std::size_t>(NearestIndex(x, last));
    switch (plan.kind[j]) {
      case SampleKind::kLerp:
      case SampleKind::kCubic: {
        const std::int64_t i0 = std::min(static_cast<std::int64_t>(std::floor(x)), last - 1);
        const auto i = static_cast<std::size_t>(i0);
        const double t = x - static_cast<double>(i0);
        const Quat& q1 = quat(i);
        const Quat q2 = aligned(quat(i + 1), q1);
        if (Dot(q1, q2) < kDiscontinuityDot) {
          for (int c = 0; c < 3; ++c) out[c][j] = source[c][k];
          continue;
        }
        if (plan.kind[j] == SampleKind::kLerp) {
          q = Slerp(q1, q2, t);
          break;
        }
        const Quat q0 = aligned(quat_at(i0 - 1), q1);
        const Quat q3 = aligned(quat_at(i0 + 2), q2);
        const bool smooth = Dot(q0, q1) >= kDiscontinuityDot && Dot(q2, q3) >= kDiscontinuityDot;
        q = smooth ? Squad(q0, q1, q2, q3, t) : Slerp(q1, q2, t);
        break;
      }
      default: {
        const std::int64_t count = plan.offset[j + 1] - plan.offset[j];
        taps.resize(static_cast<std::size_t>(count));
        for (std::int64_t tap = 0; tap < count; ++tap) {
          taps[static_cast<std::size_t>(tap)] = quat(static_cast<std::size_t>(first + tap));
        }
        const std::span<const double> w(plan.weights.data() + plan.offset[j],
                                        static_cast<std::size_t>(count));
        const std::int64_t pivot =
            std::clamp(static_cast<std::int64_t>(k) - first, std::int64_t{0}, count - 1);
        q = WeightedMeanRotation(taps, w, static_cast<std::size_t>(pivot));
        break;
      }
    }
    const Vec3 reference = {LerpAt(reference_values(0), x), LerpAt(reference_values(1), x),
                            LerpAt(reference_values(2), x)};
    const Vec3 angles = QuatToEulerNearest(q, order, reference);
    for (int c = 0; c < 3; ++c) out[c][j] = NearestTurn(angles[c], source[c][k]);
  }
}

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_CORE_RETIME_ROTATION_REFERENCE_H_
