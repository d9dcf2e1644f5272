#include "tempokey/core/model/rotation.h"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cmath>
#include <numbers>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/src/simd/block_scan.h"
#include "core/src/simd/instruction_set.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;

// Below this |cos(middle angle)| the outer angles are no longer separable (gimbal lock); above
// it the closed form is accurate to rounding in the rotation it reconstructs.
constexpr double kGimbalCos = 1e-12;

// Rounds to the nearest integer (ties to even) for |x| < 2^51 without a libm call: adding
// 1.5·2^52 leaves no fraction bits. Plain IEEE arithmetic; the compiler may not fold it.
inline double RoundSmall(double x) {
  constexpr double kShifter = 6755399441055744.0;  // 1.5 · 2^52
  return (x + kShifter) - kShifter;
}

// sin(x) / x by its Taylor series, for |x| <= kSinRatioSeriesLimit: the first omitted term
// (x^16 / 17!) is below 1e-19.
constexpr double kSinRatioSeriesLimit = 0.5;
double SinRatio(double x) {
  const double x2 = x * x;
  return 1.0 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880 +
         x2 * (-1.0 / 39916800 + x2 * (1.0 / 6227020800 + x2 * (-1.0 / 1307674368000.0)))))));
}

double Norm(const Quat& q) { return std::sqrt(Dot(q, q)); }

Quat Scaled(const Quat& q, double s) { return {q.w * s, q.x * s, q.y * s, q.z * s}; }
Quat Added(const Quat& a, const Quat& b) { return {a.w + b.w, a.x + b.x, a.y + b.y, a.z + b.z}; }

// Candidate Euler triple in degrees, each angle moved to the turn nearest `reference`, and its
// squared distance to the reference.
struct Candidate {
  Vec3 angles;
  double cost;
};

Candidate NearestCandidate(double a, double b, double c, const Vec3& reference) {
  Candidate out;
  out.angles = {NearestTurn(a * kRadToDeg, reference[0]), NearestTurn(b * kRadToDeg, reference[1]),
                NearestTurn(c * kRadToDeg, reference[2])};
  out.cost = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double d = out.angles[i] - reference[i];
    out.cost += d * d;
  }
  return out;
}

// Cyclic Jacobi eigen-decomposition of a symmetric 4x4 matrix; returns the eigenvector of the
// largest eigenvalue. The sweeps go on until the off-diagonal part is below 1e-300, long after
// the eigenvectors and eigenvalues stop changing: each sweep squares the off-diagonal entries, so
// once a sweep leaves every eigenvector entry and every diagonal entry bit for bit as it was, with
// every rotation a tiny one (|tan| < 2^-30: the eigenvalue gaps dwarf what is left off the
// diagonal) and none skipped, the later sweeps' still smaller rotations cannot change them either,
// and the result is known without running them.
std::array<double, 4> PrincipalEigenvector(std::array<std::array<double, 4>, 4> a) {
  constexpr double kTinyRotation = 0x1p-30;
  std::array<std::array<double, 4>, 4> v{};
  for (int i = 0; i < 4; ++i) v[i][i] = 1.0;
  auto same_bits = [](double x, double y) {
    return std::bit_cast<std::uint64_t>(x) == std::bit_cast<std::uint64_t>(y);
  };
  for (int sweep = 0; sweep < 64; ++sweep) {
    double off = 0.0;
    for (int p = 0; p < 4; ++p) {
      for (int q = p + 1; q < 4; ++q) off += a[p][q] * a[p][q];
    }
    if (off < 1e-300) break;
    bool settled = true;
    for (int p = 0; p < 4; ++p) {
      for (int q = p + 1; q < 4; ++q) {
        if (a[p][q] == 0.0) {
          settled = false;
          continue;
        }
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t = (theta >= 0 ? 1.0 : -1.0) / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0);
        const double s = t * c;
        if (!(std::abs(t) < kTinyRotation)) settled = false;
        const double app = a[p][p];
        const double aqq = a[q][q];
        for (int k = 0; k < 4; ++k) {
          const double akp = a[k][p];
          const double akq = a[k][q];
          a[k][p] = c * akp - s * akq;
          a[k][q] = s * akp + c * akq;
        }
        for (int k = 0; k < 4; ++k) {
          const double apk = a[p][k];
          const double aqk = a[q][k];
          a[p][k] = c * apk - s * aqk;
          a[q][k] = s * apk + c * aqk;
        }
        if (!same_bits(a[p][p], app) || !same_bits(a[q][q], aqq)) settled = false;
        for (int k = 0; k < 4; ++k) {
          const double vkp = v[k][p];
          const double vkq = v[k][q];
          v[k][p] = c * vkp - s * vkq;
          v[k][q] = s * vkp + c * vkq;
          if (!same_bits(v[k][p], vkp) || !same_bits(v[k][q], vkq)) settled = false;
        }
      }
    }
    if (settled) break;
  }
  int best = 0;
  for (int i = 1; i < 4; ++i) {
    if (a[i][i] > a[best][best]) best = i;
  }
  return {v[0][best], v[1][best], v[2][best], v[3][best]};
}

}  // namespace

double NearestTurn(double angle, double reference) {
  return angle + 360.0 * RoundSmall((reference - angle) * (1.0 / 360.0));
}

namespace {

// std::round(x) (halves away from zero) without its libm call: for |x| < 2^52, x - trunc(x) is
// exact; beyond, x has no fraction.
inline double RoundHalfAway(double x) {
  if (!(std::abs(x) < 0x1p52)) return x;
  const auto whole = static_cast<double>(static_cast<std::int64_t>(x));
  const double fraction = x - whole;
  return fraction >= 0.5 ? whole + 1.0 : fraction <= -0.5 ? whole - 1.0 : whole;
}

}  // namespace

void UnwrapDegrees(std::span<double> degrees) {
  double shift = 0.0;
  for (std::size_t i = 1; i < degrees.size(); ++i) {
    const double raw_step = degrees[i] - (degrees[i - 1] - shift);
    // Turns to add so the step lands in [-180, 180]. A step under 180 degrees in size has a
    // quotient under 1/2 (correctly rounded: 180 - ulp(180) over 360 stays below 1/2), which
    // rounds to no turn: the division is skipped, the shift the same.
    if (std::abs(raw_step) < 180.0) {
      degrees[i] += shift;
      continue;
    }
    shift -= 360.0 * RoundHalfAway(raw_step / 360.0);
    degrees[i] += shift;
  }
}

namespace {

// The largest |v| WrapWithinBound() takes: the largest double below 2^51.
constexpr double kExactWrapBound = 0x1.fffffffffffffp50;

// v wrapped into (-180, 180] with the four operations alone, exactly, for |v| <= kExactWrapBound
// (so that a loop of them runs in vectors: std::remainder is a library call a sample, about 12 ns
// here, half a 132 x 128 convert call's time in the server):
// - n = v / 360 rounded to a whole number (RoundSmall()); the quotient's rounding may put n one
//   turn off when v / 360 lies within a few ulps of a half, which the two moves below mend;
// - v - 360 n is exact: 360 n is an integer below 2^52; when n != 0, |v| >= 128 and its last
//   place 2^(e - 52) (2^e <= |v| < 2^51) divides every integer, so v - 360 n is a multiple of it
//   under 181 in size, which 53 bits hold; when n = 0 it is v;
// - a result past 180, or at or below -180, moves by a turn, again exactly (under 256 in size, the
//   same multiple).
// std::remainder gives the exact v - 360 m for the m nearest v / 360, in [-180, 180]: the same
// angle of the turn, so the same bits once its -180 becomes 180, but for a zero, whose sign
// remainder takes from v (IEEE 754 remainder), where v - 360 n is +0 from -720.
[[gnu::always_inline]] inline double WrapWithinBound(double v) {
  double r = v - 360.0 * RoundSmall(v * (1.0 / 360.0));
  r = r > 180.0 ? r - 360.0 : r;
  r = r <= -180.0 ? r + 360.0 : r;
  return r == 0.0 ? std::copysign(0.0, v) : r;
}

}  // namespace

TEMPOKEY_CLONES_AVX2 void WrapDegrees(std::span<double> degrees) {
  double* d = degrees.data();
  const std::size_t n = degrees.size();
  // Validated samples lie within 1e9: the whole array in vectors; otherwise sample by sample,
  // the rare larger or non-finite ones through std::remainder.
  if (simd::FirstBeyondMagnitude(d, n, kExactWrapBound) == n) {
    for (std::size_t i = 0; i < n; ++i) d[i] = WrapWithinBound(d[i]);
    return;
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (std::abs(d[i]) <= kExactWrapBound) {
      d[i] = WrapWithinBound(d[i]);
    } else {
      const double w = std::remainder(d[i], 360.0);
      d[i] = w == -180.0 ? 180.0 : w;
    }
  }
}

bool IsValidEulerOrder(const EulerOrder& order) {
  unsigned seen = 0;
  for (int axis : order) {
    if (axis < 0 || axis > 2) return false;
    seen |= 1u << axis;
  }
  return seen == 7u;
}

std::string EulerOrderName(const EulerOrder& order) {
  std::string name;
  for (int axis : order) name.push_back(axis >= 0 && axis <= 2 ? "XYZ"[axis] : '?');
  return name;
}

absl::StatusOr<EulerOrder> ParseEulerOrder(std::string_view name) {
  EulerOrder order{-1, -1, -1};
  if (name.size() == 3) {
    for (int i = 0; i < 3; ++i) {
      const char c = name[static_cast<std::size_t>(i)];
      order[static_cast<std::size_t>(i)] = c == 'X' ? 0 : c == 'Y' ? 1 : c == 'Z' ? 2 : -1;
    }
  }
  if (!IsValidEulerOrder(order)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "euler order '", AsAbsl(name), "': needs three distinct axes from X, Y, Z"));
  }
  return order;
}

Quat Multiply(const Quat& a, const Quat& b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
          a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
          a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}

Quat Conjugate(const Quat& q) { return {q.w, -q.x, -q.y, -q.z}; }
Quat Negated(const Quat& q) { return {-q.w, -q.x, -q.y, -q.z}; }
double Dot(const Quat& a, const Quat& b) { return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z; }
Quat Normalized(const Quat& q) { return Scaled(q, 1.0 / Norm(q)); }

Quat AxisRotation(int axis, double degrees) {
  const double half = 0.5 * degrees * kDegToRad;
  const double s = std::sin(half);
  Quat q{std::cos(half), 0.0, 0.0, 0.0};
  if (axis == 0) q.x = s;
  if (axis == 1) q.y = s;
  if (axis == 2) q.z = s;
  return q;
}

Quat EulerToQuat(const EulerOrder& order, const Vec3& degrees) {
  return Multiply(Multiply(AxisRotation(order[0], degrees[0]), AxisRotation(order[1], degrees[1])),
                  AxisRotation(order[2], degrees[2]));
}

Mat3 QuatToMatrix(const Quat& q) {
  const double xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
  const double xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
  const double wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  return {{{1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)},
           {2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)},
           {2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)}}};
}

Mat3 AxisMatrix(int axis, double degrees) {
  const double r = degrees * kDegToRad;
  const double c = std::cos(r);
  const double s = std::sin(r);
  switch (axis) {
    case 0:
      return {{{1, 0, 0}, {0, c, -s}, {0, s, c}}};
    case 1:
      return {{{c, 0, s}, {0, 1, 0}, {-s, 0, c}}};
    default:
      return {{{c, -s, 0}, {s, c, 0}, {0, 0, 1}}};
  }
}

Mat3 MatMul(const Mat3& a, const Mat3& b) {
  Mat3 out{};
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      out[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
    }
  }
  return out;
}

Vec3 MatVec(const Mat3& m, const Vec3& v) {
  return {m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
          m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
          m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2]};
}

Mat3 EulerToMatrix(const EulerOrder& order, const Vec3& degrees) {
  return MatMul(MatMul(AxisMatrix(order[0], degrees[0]), AxisMatrix(order[1], degrees[1])),
                AxisMatrix(order[2], degrees[2]));
}

Vec3 QuatToEulerNearest(const Quat& q, const EulerOrder& order, const Vec3& reference) {
  const Mat3 r = QuatToMatrix(Normalized(q));
  const int i = order[0];
  const int j = order[1];
  const int k = order[2];
  // Even permutations of XYZ (XYZ, YZX, ZXY) have sign +1, odd ones -1; with it one closed form
  // serves all six orders: sin(b) = s·R[i][k], tan(a) = -s·R[j][k] / R[k][k],
  // tan(c) = -s·R[i][j] / R[i][i].
  const double s = ((j - i + 3) % 3 == 1) ? 1.0 : -1.0;
  const double sin_b = std::clamp(s * r[i][k], -1.0, 1.0);
  // Matrix entries are at most 1 in size: no overflow for hypot to guard against.
  const double cos_b = std::sqrt(r[i][i] * r[i][i] + r[i][j] * r[i][j]);
  const double b = std::atan2(sin_b, cos_b);

  if (cos_b < kGimbalCos) {
    // Gimbal lock: any first angle works; keep the reference's and solve the last from
    // R_k(c) = (R_i(a)·R_j(b))ᵀ·R.
    const double a_deg = reference[0];
    const Mat3 head = MatMul(AxisMatrix(i, a_deg), AxisMatrix(j, b * kRadToDeg));
    Mat3 rest{};
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) {
        rest[row][col] = head[0][row] * r[0][col] + head[1][row] * r[1][col] +
                         head[2][row] * r[2][col];
      }
    }
    const int p = (k + 1) % 3;
    const int qa = (k + 2) % 3;
    const double c = std::atan2(rest[qa][p], rest[p][p]);
    return {a_deg, NearestTurn(b * kRadToDeg, reference[1]),
            NearestTurn(c * kRadToDeg, reference[2])};
  }

  const double a = std::atan2(-s * r[j][k], r[k][k]);
  const double c = std::atan2(-s * r[i][j], r[i][i]);
  const Candidate first = NearestCandidate(a, b, c, reference);
  const Candidate second = NearestCandidate(a + std::numbers::pi, std::numbers::pi - b,
                                            c + std::numbers::pi, reference);
  return second.cost < first.cost ? second.angles : first.angles;
}

Quat Slerp(const Quat& a, Quat b, double t) {
  if (Dot(a, b) < 0.0) b = Negated(b);
  if (t <= 0.0) return a;
  if (t >= 1.0) return b;
  const Quat diff{a.w - b.w, a.x - b.x, a.y - b.y, a.z - b.z};
  const Quat sum = Added(a, b);
  // The angle between a and b as 4-vectors, accurate for small and large angles alike.
  const double angle = 2.0 * std::atan2(Norm(diff), Norm(sum));
  double wa = 1.0 - t;
  double wb = t;
  if (angle <= kSinRatioSeriesLimit) {
    // sin(kθ)/sin(θ) = k·S(kθ)/S(θ) with S(x) = sin(x)/x: no cancellation, no libm calls for
    // the small steps between neighbouring capture frames.
    const double inv = 1.0 / SinRatio(angle);
    wa *= SinRatio(wa * angle) * inv;
    wb *= SinRatio(wb * angle) * inv;
  } else {
    const double inv_sin = 1.0 / std::sin(angle);
    wa = std::sin((1.0 - t) * angle) * inv_sin;
    wb = std::sin(t * angle) * inv_sin;
  }
  return Normalized(Added(Scaled(a, wa), Scaled(b, wb)));
}

Quat LogUnit(const Quat& q) {
  const double vn = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
  if (vn < 1e-300) return {0.0, 0.0, 0.0, 0.0};
  const double angle = std::atan2(vn, q.w);
  const double f = angle / vn;
  return {0.0, q.x * f, q.y * f, q.z * f};
}

Quat ExpPure(const Quat& v) {
  const double angle = std::sqrt(v.x * v.x + v.y * v.y + v.z * v.z);
  if (angle < 1e-300) return {1.0, v.x, v.y, v.z};
  const double f = std::sin(angle) / angle;
  return {std::cos(angle), v.x * f, v.y * f, v.z * f};
}

Quat Squad(const Quat& q0, const Quat& q1, const Quat& q2, const Quat& q3, double t) {
  // Inner control points s_i = q_i·exp(-(log(q_i*·q_{i+1}) + log(q_i*·q_{i-1})) / 4).
  auto control = [](const Quat& prev, const Quat& cur, const Quat& next) {
    const Quat inv = Conjugate(cur);
    const Quat l1 = LogUnit(Multiply(inv, next));
    const Quat l0 = LogUnit(Multiply(inv, prev));
    return Normalized(Multiply(cur, ExpPure(Scaled(Added(l0, l1), -0.25))));
  };
  if (t <= 0.0) return q1;
  if (t >= 1.0) return q2;
  const Quat s1 = control(q0, q1, q2);
  const Quat s2 = control(q1, q2, q3);
  return Slerp(Slerp(q1, q2, t), Slerp(s1, s2, t), 2.0 * t * (1.0 - t));
}

void MakeSignContinuous(std::span<Quat> quats) {
  for (std::size_t i = 1; i < quats.size(); ++i) {
    if (Dot(quats[i], quats[i - 1]) < 0.0) quats[i] = Negated(quats[i]);
  }
}

Quat MarkleyMean(std::span<const Quat> quats, std::span<const double> weights, std::size_t pivot) {
  std::array<std::array<double, 4>, 4> m{};
  for (std::size_t n = 0; n < quats.size(); ++n) {
    const std::array<double, 4> v = {quats[n].w, quats[n].x, quats[n].y, quats[n].z};
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) m[r][c] += weights[n] * v[r] * v[c];
    }
  }
  const std::array<double, 4> e = PrincipalEigenvector(m);
  Quat mean = Normalized(Quat{e[0], e[1], e[2], e[3]});
  if (Dot(mean, quats[pivot]) < 0.0) mean = Negated(mean);
  return mean;
}

Quat WeightedMeanRotation(std::span<const Quat> quats, std::span<const double> weights,
                          std::size_t pivot, double markley_spread_degrees) {
  const Quat& ref = quats[pivot];
  Quat sum{0.0, 0.0, 0.0, 0.0};
  for (std::size_t n = 0; n < quats.size(); ++n) {
    const double w = Dot(quats[n], ref) < 0.0 ? -weights[n] : weights[n];
    sum = Added(sum, Scaled(quats[n], w));
  }
  const double norm = Norm(sum);
  if (!(norm > 1e-9)) return MarkleyMean(quats, weights, pivot);
  const Quat mean = Scaled(sum, 1.0 / norm);
  // A rotation of angle θ from the mean has |dot| = cos(θ / 2).
  const double min_dot = std::cos(0.5 * markley_spread_degrees * kDegToRad);
  for (std::size_t n = 0; n < quats.size(); ++n) {
    if (weights[n] != 0.0 && std::abs(Dot(quats[n], mean)) < min_dot) {
      return MarkleyMean(quats, weights, pivot);
    }
  }
  return mean;
}

double AngleBetweenDegrees(const Quat& a, const Quat& b) {
  const Quat rel = Multiply(Conjugate(a), b);
  const double vn = std::sqrt(rel.x * rel.x + rel.y * rel.y + rel.z * rel.z);
  return 2.0 * std::atan2(vn, std::abs(rel.w)) * kRadToDeg;
}

}  // namespace tempokey::core
