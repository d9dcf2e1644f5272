// The cubic Hermite basis of glTF's CUBICSPLINE interpolation (glTF 2.0, "Appendix C: Spline
// Interpolation"), for the evaluators that must give the same bits: the quaternion curves
// (quaternion_fit.cc) and a keyed glTF's translations as its joint bound measures them
// (io/gltf_joint_bound.cc). Internal to tempokey_core.
#ifndef TEMPOKEY_CORE_SRC_MODEL_HERMITE_BASIS_H_
#define TEMPOKEY_CORE_SRC_MODEL_HERMITE_BASIS_H_

#include <array>

namespace tempokey::core {

// The weights {h00, h10, h01, h11} at `s` (0 at the segment's start, 1 at its end) of a segment
// `interval` seconds long: of its start value, its start's out-tangent, its end value and its
// end's in-tangent. The tangent weights include the interval, so they multiply tangents per
// second. Every caller gets the same operations in the same order, so the same bits.
inline std::array<double, 4> HermiteBasis(double s, double interval) {
  const double s2 = s * s;
  const double s3 = s2 * s;
  return {2 * s3 - 3 * s2 + 1, (s3 - 2 * s2 + s) * interval, -2 * s3 + 3 * s2,
          (s3 - s2) * interval};
}

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_SRC_MODEL_HERMITE_BASIS_H_
