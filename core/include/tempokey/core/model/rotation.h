// Euler angles, quaternions and angle unwrapping for rotation channels (degrees throughout).
//
// Conventions (SPEC 1): a joint's rotation channels form one rotation whose order is the order
// they are listed in, BVH style: intrinsic, composed left to right, so the channels
// `Zrotation Xrotation Yrotation` with angles (a, b, c) mean R = Rz(a)·Rx(b)·Ry(c), applied to
// column vectors. Quaternions are unit (w, x, y, z) with the same composition: q = qz·qx·qy.
//
// Everything here is a pure function: thread-safe, no allocation unless it returns a vector.
#ifndef TEMPOKEY_CORE_MODEL_ROTATION_H_
#define TEMPOKEY_CORE_MODEL_ROTATION_H_

#include <array>
#include <span>
#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::core {

// Unwraps angles in degrees in place: adds multiples of 360 so consecutive samples differ by at
// most 180 degrees. The first sample is unchanged.
void UnwrapDegrees(std::span<double> degrees);

// Wraps angles in degrees in place into (-180, 180]: each becomes the angle of that range a whole
// number of turns away, exactly: the bits of std::remainder(v, 360) with -180 taken as 180 (a
// zero keeps v's sign). NaN and infinities become NaN, as std::remainder makes them.
void WrapDegrees(std::span<double> degrees);

// A quaternion w + xi + yj + zk. Rotations use unit quaternions; q and -q are the same rotation.
struct Quat {
  double w = 1.0;
  double x = 0.0;
  double y = 0.0;
  double z = 0.0;

  friend bool operator==(const Quat&, const Quat&) = default;
};

// Row-major 3x3 matrix acting on column vectors.
using Mat3 = std::array<std::array<double, 3>, 3>;

// The axes of three rotation channels in listed order: 0 = X, 1 = Y, 2 = Z. {2, 0, 1} is "ZXY":
// R = Rz(a0)·Rx(a1)·Ry(a2). Valid orders name three distinct axes (the six Tait-Bryan orders).
using EulerOrder = std::array<int, 3>;

// True when `order` names three distinct axes in 0..2.
bool IsValidEulerOrder(const EulerOrder& order);
// "ZXY" for {2, 0, 1}; "???" style placeholders are never produced for valid orders.
std::string EulerOrderName(const EulerOrder& order);
// Parses "XYZ", "ZXY", ... (upper case, three distinct letters).
// Errors: kInvalidArgument "euler order 'XXY': needs three distinct axes from X, Y, Z".
absl::StatusOr<EulerOrder> ParseEulerOrder(std::string_view name);

// Hamilton product a·b (apply b first, then a, to column vectors).
Quat Multiply(const Quat& a, const Quat& b);
Quat Conjugate(const Quat& q);
Quat Negated(const Quat& q);
double Dot(const Quat& a, const Quat& b);
// q / |q|. Precondition: q is not zero.
Quat Normalized(const Quat& q);

// Rotation by `degrees` about axis 0 (X), 1 (Y) or 2 (Z).
Quat AxisRotation(int axis, double degrees);
// The rotation of Euler angles `degrees` (listed in `order`). Precondition: valid order.
Quat EulerToQuat(const EulerOrder& order, const Vec3& degrees);
// The rotation matrix of a unit quaternion.
Mat3 QuatToMatrix(const Quat& q);
// The rotation matrix of Euler angles, built from the three axis matrices directly (no
// quaternions), R = R_{order[0]}·R_{order[1]}·R_{order[2]}.
Mat3 EulerToMatrix(const EulerOrder& order, const Vec3& degrees);
// The matrix of rotation by `degrees` about one axis.
Mat3 AxisMatrix(int axis, double degrees);
Mat3 MatMul(const Mat3& a, const Mat3& b);
Vec3 MatVec(const Mat3& m, const Vec3& v);

// `angle` moved by whole turns (multiples of 360) to within 180 of `reference`, degrees. Exact
// for |angle - reference| below 2^51 turns.
double NearestTurn(double angle, double reference);

// Euler angles in `order` (degrees) of the rotation `q`, choosing among all solutions (the two
// Tait-Bryan branches, each angle shifted by any multiple of 360) the one nearest `reference`
// (sum of squared differences). At gimbal lock (middle angle at ±90°, where only the sum or
// difference of the outer angles is defined) the first angle is taken from `reference`.
// Precondition: valid order, q unit (it is normalized anyway).
Vec3 QuatToEulerNearest(const Quat& q, const EulerOrder& order, const Vec3& reference);

// Spherical linear interpolation along the shorter arc, t in [0, 1]; exact endpoints: t = 0
// gives a, t = 1 gives b (or -b).
Quat Slerp(const Quat& a, Quat b, double t);

// Logarithm of a unit quaternion (a pure quaternion: w = 0, vector = half-angle × axis) and the
// exponential of a pure quaternion.
Quat LogUnit(const Quat& q);
Quat ExpPure(const Quat& v);

// Spherical cubic (squad) between q1 (t = 0) and q2 (t = 1) with neighbours q0 and q3: the
// rotation analogue of Catmull-Rom. Inputs must be sign-continuous (consecutive dots >= 0).
Quat Squad(const Quat& q0, const Quat& q1, const Quat& q2, const Quat& q3, double t);

// Makes consecutive quaternions sign-continuous in place: q[i] is negated when
// Dot(q[i], q[i-1]) < 0.
void MakeSignContinuous(std::span<Quat> quats);

// The weighted mean rotation of `quats` (same length as `weights`, weights summing to about 1,
// some possibly negative): the normalized weighted sum, each term first aligned to the sign of
// `quats[pivot]`. When any quaternion with non-zero weight is more than `markley_spread_degrees`
// from that mean, the result is Markley's mean instead: the principal eigenvector of
// Σ w q qᵀ. Precondition: non-empty, pivot in range.
Quat WeightedMeanRotation(std::span<const Quat> quats, std::span<const double> weights,
                          std::size_t pivot, double markley_spread_degrees = 30.0);

// Markley's mean: the unit eigenvector of the largest eigenvalue of Σ w q qᵀ (sign chosen so
// its dot with `quats[pivot]` is >= 0).
Quat MarkleyMean(std::span<const Quat> quats, std::span<const double> weights, std::size_t pivot);

// The angle in degrees of the rotation taking a to b (0..180).
double AngleBetweenDegrees(const Quat& a, const Quat& b);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_ROTATION_H_
