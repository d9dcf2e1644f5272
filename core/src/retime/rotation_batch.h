// Batched rotation conversions for the rotation-aware resampling (resample.cc): the scalar
// functions of rotation.h (EulerToQuat(), Slerp(), QuatToEulerNearest() then NearestTurn()) over
// many samples, eight at a time. Each performs the scalar function's arithmetic in the same order,
// with the sines, cosines and arctangents of vector_trig.h instead of libm's: results within a
// few units in the last place of the scalar ones, the same branch choices except where a value
// lies within such rounding of a threshold.
#ifndef TEMPOKEY_CORE_SRC_RETIME_ROTATION_BATCH_H_
#define TEMPOKEY_CORE_SRC_RETIME_ROTATION_BATCH_H_

#include <cstddef>
#include <cstdint>

#include "tempokey/core/model/rotation.h"

namespace tempokey::core::retime_internal {

// Quaternions as four arrays of components (the i-th quaternion is w[i], x[i], y[i], z[i]).
struct QuatArrays {
  double* w;
  double* x;
  double* y;
  double* z;
};
struct ConstQuatArrays {
  const double* w;
  const double* x;
  const double* y;
  const double* z;
};

// EulerToQuat(order, {a[i], b[i], c[i]}) for i < count (angles in degrees), quaternion i into
// out[4 i .. 4 i + 3] as (w, x, y, z). Precondition: valid order.
void EulerToQuats(const EulerOrder& order, const double* a, const double* b, const double* c,
                  std::size_t count, double* out);

// A weighted output sample: the quaternions first .. first + count - 1 of the source, with the
// weights weights[weight_offset ...], each aligned to the sign of the source quaternion `pivot`.
struct WeightedMeanJob {
  std::int64_t first;
  std::int64_t count;
  std::int64_t weight_offset;
  std::int64_t pivot;
};

// For i < count: WeightedMeanRotation() (rotation.h) of job i's quaternions (`quats` as
// EulerToQuats() writes them) into out[i], where its spread test passes: no quaternion with a
// non-zero weight farther than min_dot (the cosine of half the spread) from the mean, and a sum
// that normalizes. Elsewhere needs_markley[i] is set to 1 (otherwise 0) and out[i] is unspecified:
// the caller takes Markley's mean.
void WeightedMeans(const double* quats, const double* weights, const WeightedMeanJob* jobs,
                   std::size_t count, double min_dot, QuatArrays out, unsigned char* needs_markley);

// out[i] = Slerp(from[i], to[i], t[i]) for i < count.
void SlerpQuats(ConstQuatArrays from, ConstQuatArrays to, const double* t, std::size_t count,
                QuatArrays out);

// Near gimbal lock (the middle angle near +-90 degrees) the first and last angles are
// ill-conditioned: a rotation off by a unit in the last place moves them by that over the cosine
// of the middle angle. Below this cosine QuatsToEulerNearest() leaves a sample to the caller, whose
// scalar path then gives the scalar functions' results exactly: elsewhere the batched results
// stay within 1e-12 degrees of them (tests/core/retime/retime_identity_test.cc).
inline constexpr double kBatchedMinMiddleCos = 0.1;

// For i < count: the angles QuatToEulerNearest(q[i], order, {reference[0][i], reference[1][i],
// reference[2][i]}), each then moved by NearestTurn() to within 180 degrees of turn[c][i], into
// out[c][i]; except where the cosine of the middle angle is below kBatchedMinMiddleCos, where
// ill_conditioned[i] is set to 1 and out[.][i] is left unspecified (otherwise 0).
// Precondition: valid order.
void QuatsToEulerNearest(const EulerOrder& order, ConstQuatArrays q,
                         const double* const reference[3], const double* const turn[3],
                         std::size_t count, double* const out[3], unsigned char* ill_conditioned);

}  // namespace tempokey::core::retime_internal

#endif  // TEMPOKEY_CORE_SRC_RETIME_ROTATION_BATCH_H_
