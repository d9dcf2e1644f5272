// Batched rotation conversions for the rotation-aware resampling (resample.cc): the scalar
// functions of rotation.h (EulerToQuat(), Slerp(), WeightedMeanRotation(), MarkleyMean(),
// QuatToEulerNearest() then NearestTurn()) over many samples, four or (AVX-512) eight to a
// vector and several vectors per step. Each performs the scalar function's arithmetic in the
// same order. The weighted means use no trigonometry and give the scalar function's bits;
// Markley's means find the eigenvector by repeated squaring where that converges, within a few
// units in the last place of the scalar Jacobi sweeps (which they run, bit for bit, elsewhere);
// the others use the sines, cosines and arctangents of vector_trig.h instead of libm's: results
// within a few units in the last place of the scalar ones, the same branch choices except where
// a value lies within such rounding of a threshold.
// tests/core/retime/rotation_batch_test.cc checks both.
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

// Weighted means are computed kMeanLanes at a time, one output sample per lane, from tables laid
// out lane-major so that every tap of a group is contiguous: one load of weights and four of
// quaternions on 8-lane vectors (the 4-lane kernels take half a group at a time). The tables
// depend on the resampling plan alone: they are made once and shared by every joint
// (resample.cc's RotationSchedule).
inline constexpr std::size_t kMeanLanes = 8;

// kMeanLanes output samples of at most `taps` taps each: tap n of lane l reads the source
// quaternion source[tap_begin + kMeanLanes * n + l] with weight weight[tap_begin + kMeanLanes * n
// + l]. A lane with fewer taps (or a lane past the last sample) is padded with its pivot at weight
// 0, which leaves every sum as it is.
struct MeanGroup {
  std::size_t tap_begin;
  std::int64_t taps;
  std::int64_t pivot[kMeanLanes];  // source index each lane aligns its quaternions' signs to
};
struct MeanTables {
  const MeanGroup* groups;
  const std::int64_t* source;
  const double* weight;
};

// For the samples i < count of the groups (sample i is lane i % kMeanLanes of group
// i / kMeanLanes): WeightedMeanRotation() (rotation.h) of its taps of `quats` (as EulerToQuats()
// writes them) into out[i], where its spread test passes: no quaternion with a non-zero weight
// farther than min_dot (the cosine of half the spread) from the mean, and a sum that normalizes.
// Elsewhere needs_markley[i] is set to 1 (otherwise 0) and out[i] is unspecified: the caller takes
// Markley's mean.
void WeightedMeans(const double* quats, const MeanTables& tables, std::size_t count, double min_dot,
                   QuatArrays out, unsigned char* needs_markley);

// A weighted output sample: the source quaternions first .. first + count - 1 with the weights
// weights[weight_offset ...], signs aligned to the source quaternion `pivot`.
struct WeightedMeanJob {
  std::int64_t first;
  std::int64_t count;
  std::int64_t weight_offset;
  std::int64_t pivot;
};

// For i < count: MarkleyMean() (rotation.h) of job i's quaternions of `quats` (as EulerToQuats()
// writes them) into out[i]. Where the pivot's Rayleigh quotient on the job's matrix is at least
// 3/4 of its trace (after a shift that makes negative weights harmless; the largest eigenvalue is
// then at least three times the next), as it is for most spreads that ask for Markley's mean, the
// eigenvector of repeated squaring: within a few units in the last place of MarkleyMean()'s.
// Elsewhere MarkleyMean() bit for bit: the same Jacobi sweeps, lane by lane, for several jobs at
// once. Returns how many jobs took the sweeps.
std::size_t MarkleyMeans(const double* quats, const double* weights,
                         const WeightedMeanJob* jobs, std::size_t count, QuatArrays out);

// Adjacent source rotations with |q_i·q_{i+1}| below this, cos(150° / 2), are a discontinuity
// (resample.cc): a turn of more than 150 degrees in one frame.
inline constexpr double kDiscontinuityDot = 0.25881904510252074;

// For i < count, with a = quats[i0[i]] and b = quats[i0[i] + 1] (as EulerToQuats() writes them),
// b's sign aligned to a: out[i] = Slerp(a, b, t[i]), and discontinuous[i] = 1 where
// a·b < kDiscontinuityDot (out[i] is then unspecified), otherwise 0.
void SlerpQuats(const double* quats, const std::int64_t* i0, const double* t, std::size_t count,
                QuatArrays out, unsigned char* discontinuous);

// Near gimbal lock (the middle angle near +-90 degrees) the first and last angles are
// ill-conditioned: a rotation off by a unit in the last place moves them by that over the cosine
// of the middle angle. Below this cosine QuatsToEulerNearest() leaves a sample to the caller, whose
// scalar path then gives the scalar functions' results exactly: elsewhere the batched results
// stay within 1e-12 degrees of them (tests/core/retime/retime_identity_test.cc).
inline constexpr double kBatchedMinMiddleCos = 0.1;

// Where the angles of output samples go and what they are measured against: sample i lies at
// i0[i] + t[i] (source frames), its Euler angles are the ones nearest the reference
// reference[c][i0] + t (reference[c][i0 + 1] - reference[c][i0]) (the source's unwrapped angles
// interpolated linearly), each then moved by whole turns to within 180 degrees of
// turn[c][nearest[i]] (the source's value at the nearest sample), and stored at
// out[c][output[i]].
struct EulerTargets {
  const std::int64_t* i0;
  const double* t;
  const std::int64_t* nearest;
  const std::int64_t* output;
  const double* reference[3];
  const double* turn[3];
  double* out[3];
};

// For i < count: the angles QuatToEulerNearest(q[i], order, reference) then moved by NearestTurn()
// as `targets` says, stored as it says; except where the cosine of the middle angle is below
// kBatchedMinMiddleCos, where ill_conditioned[i] is set to 1 and the stored angles are
// unspecified (otherwise 0). Preconditions: valid order; every q[i] whose angles are used of unit
// length within rounding (as the functions above make them), which is taken as it is, not
// normalized again.
void QuatsToEulerNearest(const EulerOrder& order, ConstQuatArrays q, const EulerTargets& targets,
                         std::size_t count, unsigned char* ill_conditioned);

}  // namespace tempokey::core::retime_internal

#endif  // TEMPOKEY_CORE_SRC_RETIME_ROTATION_BATCH_H_
