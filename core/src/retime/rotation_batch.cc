#include "rotation_batch.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numbers>

#include "vector_trig.h"

// As simd.h's TEMPOKEY_AVX2_CLONES, with AVX2: the kernels select lanes by masks, which are
// 256-bit integer vectors (AVX alone splits them into 128-bit halves).
#if defined(TEMPOKEY_SANITIZED)
#define TEMPOKEY_AVX2_CLONES
#else
#define TEMPOKEY_AVX2_CLONES __attribute__((target_clones("avx2", "default")))
#endif

namespace tempokey::core::retime_internal {
namespace {

// Four lanes, one AVX register (GCC's lowering of wider vectors to two registers handles lane
// accesses poorly); the kernels take several vectors per step instead, so that independent chains
// of dependent operations are in flight through every polynomial and division.
using V = vector_trig::V4;
using Mask = vector_trig::MaskOf<V>;
constexpr std::size_t kLanes = 4;

// As rotation.cc.
constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
constexpr double kSinRatioSeriesLimit = 0.5;

// Quaternions, one per lane.
struct QuatLanes {
  V w, x, y, z;
};

[[gnu::always_inline]] inline V Broadcast(double v) { return vector_trig::Splat<V>(v); }

// Lanes [0, count) of `p` (count <= kLanes), the missing lanes repeating lane 0: a partial group
// computes its padding on real values.
[[gnu::always_inline]] inline V LoadPartial(const double* p, std::size_t count) {
  V v;
  if (count >= kLanes) {
    std::memcpy(&v, p, sizeof v);
    return v;
  }
  v = Broadcast(p[0]);
  for (std::size_t lane = 1; lane < count; ++lane) v[lane] = p[lane];
  return v;
}

[[gnu::always_inline]] inline void StorePartial(double* p, V v, std::size_t count) {
  if (count >= kLanes) {
    std::memcpy(p, &v, sizeof v);
    return;
  }
  for (std::size_t lane = 0; lane < count; ++lane) p[lane] = v[lane];
}

[[gnu::always_inline]] inline QuatLanes LoadQuats(ConstQuatArrays q, std::size_t i, std::size_t count) {
  return {LoadPartial(q.w + i, count), LoadPartial(q.x + i, count), LoadPartial(q.y + i, count),
          LoadPartial(q.z + i, count)};
}

[[gnu::always_inline]] inline void StoreQuats(QuatArrays q, std::size_t i, const QuatLanes& v,
                                              std::size_t count) {
  StorePartial(q.w + i, v.w, count);
  StorePartial(q.x + i, v.x, count);
  StorePartial(q.y + i, v.y, count);
  StorePartial(q.z + i, v.z, count);
}

// The scalar functions of rotation.cc, lane by lane, in their order of operations.

[[gnu::always_inline]] inline V Dot(const QuatLanes& a, const QuatLanes& b) {
  return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
}

[[gnu::always_inline]] inline QuatLanes Scaled(const QuatLanes& q, V s) {
  return {q.w * s, q.x * s, q.y * s, q.z * s};
}

// std::sqrt lane by lane (one vsqrtpd where the target has it).
[[gnu::always_inline]] inline V Sqrt(V v) {
  V root;
  for (std::size_t lane = 0; lane < kLanes; ++lane) root[lane] = std::sqrt(v[lane]);
  return root;
}

[[gnu::always_inline]] inline QuatLanes Normalized(const QuatLanes& q) {
  V norm;
  const V squared = Dot(q, q);
  for (std::size_t lane = 0; lane < kLanes; ++lane) norm[lane] = std::sqrt(squared[lane]);
  return Scaled(q, 1.0 / norm);
}

// AxisRotation(axis, degrees) is (cos, sin along the axis) of the half angle
// 0.5 * degrees * kDegToRad.

// Multiply(q, AxisRotation(axis, .)) for the rotation (c, s along `axis`): Multiply()'s four
// products per component less the ones by the rotation's zero components. Those are exact zeros,
// and adding or subtracting an exact zero leaves a sum as it is, so every component has
// Multiply()'s value (up to the sign of a zero result).
[[gnu::always_inline]] inline QuatLanes MultiplyByAxis(const QuatLanes& q, int axis, V s, V c) {
  switch (axis) {
    case 0:
      return {q.w * c - q.x * s, q.w * s + q.x * c, q.y * c + q.z * s, q.z * c - q.y * s};
    case 1:
      return {q.w * c - q.y * s, q.x * c - q.z * s, q.w * s + q.y * c, q.x * s + q.z * c};
    default:
      return {q.w * c - q.z * s, q.x * c + q.y * s, q.y * c - q.x * s, q.w * s + q.z * c};
  }
}

[[gnu::always_inline]] inline V SinRatio(V x) {
  const V x2 = x * x;
  return 1.0 + x2 * (-1.0 / 6 + x2 * (1.0 / 120 + x2 * (-1.0 / 5040 + x2 * (1.0 / 362880 +
         x2 * (-1.0 / 39916800 + x2 * (1.0 / 6227020800 + x2 * (-1.0 / 1307674368000.0)))))));
}

[[gnu::always_inline]] inline V NearestTurn(V angle, V reference) {
  return angle + 360.0 * vector_trig::RoundSmall((reference - angle) * (1.0 / 360.0));
}

// True when every lane of the three `v` is below `limit` in size (the vector sine's accurate
// range).
[[gnu::always_inline]] inline bool AllReducible(const V (&v)[3], double limit) {
  // |v| by clearing the sign bit; one test of the three masks together.
  using Bits = std::int64_t __attribute__((vector_size(sizeof(V))));
  auto abs = [](V x) __attribute__((always_inline)) { return (V)((Bits)x & std::numeric_limits<std::int64_t>::max()); };
  const Mask ok = (abs(v[0]) < limit) & (abs(v[1]) < limit) & (abs(v[2]) < limit);
  bool all = true;
  for (std::size_t lane = 0; lane < kLanes; ++lane) all = all && ok[lane] != 0;
  return all;
}

// The 4x4 transpose of rows a, b, c, d: quaternions stored (w, x, y, z) one after the other become
// one vector per component, and back. Shuffles only: no arithmetic, every bit kept
// (__builtin_shufflevector: GCC 12 and clang both have it).
[[gnu::always_inline]] inline void Transpose(V& a, V& b, V& c, V& d) {
  const V ab_even = __builtin_shufflevector(a, b, 0, 4, 2, 6);
  const V ab_odd = __builtin_shufflevector(a, b, 1, 5, 3, 7);
  const V cd_even = __builtin_shufflevector(c, d, 0, 4, 2, 6);
  const V cd_odd = __builtin_shufflevector(c, d, 1, 5, 3, 7);
  a = __builtin_shufflevector(ab_even, cd_even, 0, 1, 4, 5);
  b = __builtin_shufflevector(ab_odd, cd_odd, 0, 1, 4, 5);
  c = __builtin_shufflevector(ab_even, cd_even, 2, 3, 6, 7);
  d = __builtin_shufflevector(ab_odd, cd_odd, 2, 3, 6, 7);
}

// The kLanes doubles at p, and back: unaligned vector loads and stores (a V held in an array
// and copied lane by lane goes through the stack, and its loads then wait on the stores). A
// memcpy of the whole vector is one unaligned load or store for GCC and clang alike, and is
// defined for any address (clang ignores a lowered alignment on a vector typedef, and UBSan then
// flags the access).
[[gnu::always_inline]] inline V LoadV(const double* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
[[gnu::always_inline]] inline void StoreV(double* p, V v) { std::memcpy(p, &v, sizeof v); }

// (w, x, y, z) of the lanes' quaternions as consecutive (w, x, y, z) groups.
[[gnu::always_inline]] inline void StoreInterleaved(double* out, const QuatLanes& q,
                                                    std::size_t count) {
  static_assert(kLanes == 4);
  V a = q.w, b = q.x, c = q.y, d = q.z;
  Transpose(a, b, c, d);
  StoreV(out, a);
  if (count > 1) StoreV(out + 4, b);
  if (count > 2) StoreV(out + 8, c);
  if (count > 3) StoreV(out + 12, d);
}

// Quaternions (w, x, y, z) from `quats` at the indices `at`, one per lane.
[[gnu::always_inline]] inline QuatLanes Gather(const double* quats, const std::int64_t* at) {
  static_assert(kLanes == 4);
  V a = LoadV(quats + 4 * at[0]), b = LoadV(quats + 4 * at[1]), c = LoadV(quats + 4 * at[2]),
    d = LoadV(quats + 4 * at[3]);
  Transpose(a, b, c, d);
  return {a, b, c, d};
}

// Lanes [0, count) of index array `p` into `at`, the missing lanes repeating lane 0.
[[gnu::always_inline]] inline void LoadIndices(const std::int64_t* p, std::size_t count,
                                               std::int64_t at[kLanes]) {
  for (std::size_t lane = 0; lane < kLanes; ++lane) at[lane] = p[lane < count ? lane : 0];
}

// The kernels below are written for one Euler order (axes I, J, K) at a time: the axes then pick
// matrix entries and products at compile time rather than through memory.
template <int I, int J, int K>
[[gnu::always_inline]] inline QuatLanes AxesProduct(const V (&sine)[3], const V (&cosine)[3]) {
  // EulerToQuat(): Multiply(Multiply(R0, R1), R2) with R_n = AxisRotation(axis n, angle n).
  const V zero = Broadcast(0.0);
  const QuatLanes first = {cosine[0], I == 0 ? sine[0] : zero, I == 1 ? sine[0] : zero,
                           I == 2 ? sine[0] : zero};
  return MultiplyByAxis(MultiplyByAxis(first, J, sine[1], cosine[1]), K, sine[2], cosine[2]);
}

template <int I, int J, int K>
[[gnu::always_inline]] inline void EulerToQuatsBody(const double* a, const double* b,
                                                    const double* c, std::size_t count,
                                                    double* out) {
  constexpr EulerOrder order = {I, J, K};
  // Half angles (radians) beyond kMaxReducedRadians: far beyond any rotation channel's values.
  constexpr double kMaxDegrees = 2.0 * vector_trig::kMaxReducedRadians / kDegToRad;
  auto scalar = [&](std::size_t i, std::size_t lanes) {
    for (std::size_t lane = 0; lane < lanes; ++lane) {
      const Quat q = EulerToQuat(order, {a[i + lane], b[i + lane], c[i + lane]});
      double* p = out + 4 * (i + lane);
      p[0] = q.w;
      p[1] = q.x;
      p[2] = q.y;
      p[3] = q.z;
    }
  };
  auto half_radians = [](V degrees) __attribute__((always_inline)) { return 0.5 * degrees * kDegToRad; };
  std::size_t i = 0;
  // Two groups per step, their six sines and cosines side by side.
  for (; i + 2 * kLanes <= count; i += 2 * kLanes) {
    const V angle[2][3] = {{LoadV(a + i), LoadV(b + i), LoadV(c + i)},
                           {LoadV(a + i + kLanes), LoadV(b + i + kLanes), LoadV(c + i + kLanes)}};
    if (!AllReducible(angle[0], kMaxDegrees) || !AllReducible(angle[1], kMaxDegrees)) {
      scalar(i, 2 * kLanes);
      continue;
    }
    V sine[6], cosine[6];
    vector_trig::SinCos<6>({half_radians(angle[0][0]), half_radians(angle[0][1]),
                            half_radians(angle[0][2]), half_radians(angle[1][0]),
                            half_radians(angle[1][1]), half_radians(angle[1][2])},
                           sine, cosine);
    for (std::size_t g = 0; g < 2; ++g) {
      const V s[3] = {sine[3 * g], sine[3 * g + 1], sine[3 * g + 2]};
      const V co[3] = {cosine[3 * g], cosine[3 * g + 1], cosine[3 * g + 2]};
      StoreInterleaved(out + 4 * (i + g * kLanes), AxesProduct<I, J, K>(s, co), kLanes);
    }
  }
  for (; i < count; i += kLanes) {
    const std::size_t lanes = std::min(kLanes, count - i);
    const V angle[3] = {LoadPartial(a + i, lanes), LoadPartial(b + i, lanes),
                         LoadPartial(c + i, lanes)};
    if (!AllReducible(angle, kMaxDegrees)) {
      scalar(i, lanes);
      continue;
    }
    V sine[3], cosine[3];
    vector_trig::SinCos<3>({half_radians(angle[0]), half_radians(angle[1]), half_radians(angle[2])},
                           sine, cosine);
    StoreInterleaved(out + 4 * i, AxesProduct<I, J, K>(sine, cosine), lanes);
  }
}

// The order's axes (0 X, 1 Y, 2 Z) as one number, for a switch over the six orders.
constexpr int OrderCode(int i, int j, int k) { return 9 * i + 3 * j + k; }
constexpr int OrderCode(const EulerOrder& order) { return OrderCode(order[0], order[1], order[2]); }

// Calls body<I, J, K>(args...) for the order's axes. Precondition: valid order.
#define TEMPOKEY_FOR_ORDER(order, body, ...)                              \
  switch (OrderCode(order)) {                                              \
    case OrderCode(0, 1, 2): return body<0, 1, 2>(__VA_ARGS__);            \
    case OrderCode(0, 2, 1): return body<0, 2, 1>(__VA_ARGS__);            \
    case OrderCode(1, 0, 2): return body<1, 0, 2>(__VA_ARGS__);            \
    case OrderCode(1, 2, 0): return body<1, 2, 0>(__VA_ARGS__);            \
    case OrderCode(2, 0, 1): return body<2, 0, 1>(__VA_ARGS__);            \
    default: return body<2, 1, 0>(__VA_ARGS__);                            \
  }

TEMPOKEY_AVX2_CLONES void EulerToQuatsKernel(const EulerOrder& order, const double* a,
                                            const double* b, const double* c, std::size_t count,
                                            double* out) {
  TEMPOKEY_FOR_ORDER(order, EulerToQuatsBody, a, b, c, count, out);
}

// Groups of kLanes samples one slerp step takes together.
constexpr int kSlerpGroups = 2;

TEMPOKEY_AVX2_CLONES void SlerpKernel(const double* quats, const std::int64_t* i0, const double* t,
                                     std::size_t count, QuatArrays out,
                                     unsigned char* discontinuous) {
  // As ToEulerBody(): groups of samples side by side through the arctangent.
  constexpr int G = kSlerpGroups;
  for (std::size_t start = 0; start < count; start += G * kLanes) {
    std::size_t first[G], lanes[G];
    QuatLanes qa[G], qb[G];
    V tt[G], diff_norm[G], sum_norm[G];
    for (int g = 0; g < G; ++g) {
      const std::size_t begin = start + static_cast<std::size_t>(g) * kLanes;
      first[g] = begin < count ? begin : start;
      lanes[g] = begin < count ? std::min(kLanes, count - begin) : 0;
      const std::size_t n = std::max<std::size_t>(lanes[g], 1);
      std::int64_t at[kLanes], next[kLanes];
      LoadIndices(i0 + first[g], n, at);
      for (std::size_t lane = 0; lane < kLanes; ++lane) next[lane] = at[lane] + 1;
      qa[g] = Gather(quats, at);
      QuatLanes b = Gather(quats, next);
      tt[g] = LoadPartial(t + first[g], n);
      // b's sign aligned to a; the aligned dot product is the negated one, exactly.
      const V dot = Dot(qa[g], b);
      const Mask flip = dot < 0.0;
      qb[g] = {flip ? -b.w : b.w, flip ? -b.x : b.x, flip ? -b.y : b.y, flip ? -b.z : b.z};
      const Mask apart = (flip ? -dot : dot) < kDiscontinuityDot;
      for (std::size_t lane = 0; lane < lanes[g]; ++lane) {
        discontinuous[first[g] + lane] = apart[lane] ? 1 : 0;
      }
      const QuatLanes& a = qa[g];
      const QuatLanes diff = {a.w - qb[g].w, a.x - qb[g].x, a.y - qb[g].y, a.z - qb[g].z};
      const QuatLanes sum = {a.w + qb[g].w, a.x + qb[g].x, a.y + qb[g].y, a.z + qb[g].z};
      const V diff_squared = Dot(diff, diff);
      const V sum_squared = Dot(sum, sum);
      for (std::size_t lane = 0; lane < kLanes; ++lane) {
        diff_norm[g][lane] = std::sqrt(diff_squared[lane]);
        sum_norm[g][lane] = std::sqrt(sum_squared[lane]);
      }
    }
    V half_angle[G];
    vector_trig::Atan2<G>(diff_norm, sum_norm, half_angle);
    for (int g = 0; g < G; ++g) {
      const QuatLanes& qa_g = qa[g];
      const QuatLanes& qb_g = qb[g];
      const V angle = 2.0 * half_angle[g];
      V wa = 1.0 - tt[g];
      V wb = tt[g];
      const Mask series = angle <= kSinRatioSeriesLimit;
      V series_wa, series_wb;
      {
        const V inv = 1.0 / SinRatio(angle);
        series_wa = wa * (SinRatio(wa * angle) * inv);
        series_wb = wb * (SinRatio(wb * angle) * inv);
      }
      bool all_series = true;
      for (std::size_t lane = 0; lane < kLanes; ++lane) all_series = all_series && series[lane];
      if (all_series) {
        wa = series_wa;
        wb = series_wb;
      } else {
        V sine[3], cosine[3];
        vector_trig::SinCos<3>({angle, (1.0 - tt[g]) * angle, tt[g] * angle}, sine, cosine);
        const V inv_sin = 1.0 / sine[0];
        const V sine_wa = sine[1] * inv_sin;
        const V sine_wb = sine[2] * inv_sin;
        wa = series ? series_wa : sine_wa;
        wb = series ? series_wb : sine_wb;
      }
      const QuatLanes mixed =
          Normalized({qa_g.w * wa + qb_g.w * wb, qa_g.x * wa + qb_g.x * wb,
                      qa_g.y * wa + qb_g.y * wb, qa_g.z * wa + qb_g.z * wb});
      // Exact ends: t <= 0 gives `from`, t >= 1 gives `to` (aligned).
      const Mask at_start = tt[g] <= 0.0;
      const Mask at_end = tt[g] >= 1.0;
      auto pick = [&](V from, V to, V middle) __attribute__((always_inline)) {
        return at_start ? from : (at_end ? to : middle);
      };
      if (lanes[g] == 0) continue;
      StoreQuats(out, first[g],
                 {pick(qa_g.w, qb_g.w, mixed.w), pick(qa_g.x, qb_g.x, mixed.x),
                  pick(qa_g.y, qb_g.y, mixed.y), pick(qa_g.z, qb_g.z, mixed.z)},
                 lanes[g]);
    }
  }
}

// Groups of kLanes samples converted back together, their arctangents side by side: one group's
// chain of divisions and polynomials alone leaves the processor waiting.
constexpr int kEulerGroups = 2;

template <int I, int J, int K>
[[gnu::always_inline]] inline void ToEulerBody(ConstQuatArrays quats, const EulerTargets& targets,
                                               std::size_t count, unsigned char* ill_conditioned) {
  constexpr int i = I;
  constexpr int j = J;
  constexpr int k = K;
  constexpr double sign = ((j - i + 3) % 3 == 1) ? 1.0 : -1.0;
  constexpr int G = kEulerGroups;
  for (std::size_t start = 0; start < count; start += G * kLanes) {
    // Group g's samples start at first[g]; a group past the end repeats group 0 and stores
    // nothing.
    std::size_t first[G], lanes[G];
    V sin_b[G], cos_b[G], y[3 * G], x[3 * G];
    for (int g = 0; g < G; ++g) {
      const std::size_t begin = start + static_cast<std::size_t>(g) * kLanes;
      first[g] = begin < count ? begin : start;
      lanes[g] = begin < count ? std::min(kLanes, count - begin) : 0;
      const QuatLanes q =
          Normalized(LoadQuats(quats, first[g], std::max<std::size_t>(lanes[g], 1)));
      // QuatToMatrix().
      const V xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
      const V xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
      const V wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
      const V r[3][3] = {{1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)},
                          {2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)},
                          {2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)}};
      V sb = sign * r[i][k];
      sin_b[g] = sb < -1.0 ? Broadcast(-1.0) : (1.0 < sb ? Broadcast(1.0) : sb);
      const V cos_squared = r[i][i] * r[i][i] + r[i][j] * r[i][j];
      cos_b[g] = Sqrt(cos_squared);
      y[3 * g] = sin_b[g];
      x[3 * g] = cos_b[g];
      y[3 * g + 1] = -sign * r[j][k];
      x[3 * g + 1] = r[k][k];
      y[3 * g + 2] = -sign * r[i][j];
      x[3 * g + 2] = r[i][i];
    }
    V bac[3 * G];
    vector_trig::Atan2<3 * G>(y, x, bac);
    for (int g = 0; g < G; ++g) {
      const V b = bac[3 * g], a = bac[3 * g + 1], c = bac[3 * g + 2];
      const std::size_t n = std::max<std::size_t>(lanes[g], 1);
      std::int64_t at[kLanes], nearest[kLanes], output[kLanes];
      LoadIndices(targets.i0 + first[g], n, at);
      LoadIndices(targets.nearest + first[g], n, nearest);
      LoadIndices(targets.output + first[g], n, output);
      const V tt = LoadPartial(targets.t + first[g], n);
      // The source's unwrapped angles interpolated linearly at the sample, and its values at the
      // nearest sample.
      V ref[3], turn[3];
      for (int axis = 0; axis < 3; ++axis) {
        V v0, v1;
        for (std::size_t lane = 0; lane < kLanes; ++lane) {
          v0[lane] = targets.reference[axis][at[lane]];
          v1[lane] = targets.reference[axis][at[lane] + 1];
          turn[axis][lane] = targets.turn[axis][nearest[lane]];
        }
        ref[axis] = v0 + tt * (v1 - v0);
      }
      // The two Tait-Bryan solutions, each angle moved to the turn nearest the reference; the
      // nearer wins (NearestCandidate()).
      V first_angles[3] = {NearestTurn(a * kRadToDeg, ref[0]), NearestTurn(b * kRadToDeg, ref[1]),
                            NearestTurn(c * kRadToDeg, ref[2])};
      V second_angles[3] = {NearestTurn((a + std::numbers::pi) * kRadToDeg, ref[0]),
                             NearestTurn((std::numbers::pi - b) * kRadToDeg, ref[1]),
                             NearestTurn((c + std::numbers::pi) * kRadToDeg, ref[2])};
      V first_cost = Broadcast(0.0), second_cost = Broadcast(0.0);
      for (int axis = 0; axis < 3; ++axis) {
        const V d1 = first_angles[axis] - ref[axis];
        first_cost += d1 * d1;
        const V d2 = second_angles[axis] - ref[axis];
        second_cost += d2 * d2;
      }
      const Mask second = second_cost < first_cost;
      for (int axis = 0; axis < 3; ++axis) {
        const V angle = NearestTurn(second ? second_angles[axis] : first_angles[axis], turn[axis]);
        for (std::size_t lane = 0; lane < lanes[g]; ++lane) {
          targets.out[axis][output[lane]] = angle[lane];
        }
      }
      // Near gimbal lock: the caller's (gimbal lock itself, cos_b < 1e-12, among them).
      const Mask near_lock = cos_b[g] < kBatchedMinMiddleCos;
      for (std::size_t lane = 0; lane < lanes[g]; ++lane) {
        ill_conditioned[first[g] + lane] = near_lock[lane] ? 1 : 0;
      }
    }
  }
}

TEMPOKEY_AVX2_CLONES void ToEulerKernel(const EulerOrder& order, ConstQuatArrays quats,
                                       const EulerTargets& targets, std::size_t count,
                                       unsigned char* ill_conditioned) {
  TEMPOKEY_FOR_ORDER(order, ToEulerBody, quats, targets, count, ill_conditioned);
}

#undef TEMPOKEY_FOR_ORDER

// WeightedMeanRotation()'s arithmetic for kLanes output samples at once, one per lane, in its order
// of operations for every lane.
// True when the spread test of every lane's weighted mean is known to pass without testing each
// tap: with half-angles phi(p, q) = acos|p·q| (a metric on rotations), every tap is within
// phi(tap, pivot) + phi(pivot, mean) of the mean, so when the largest tap's and the mean's
// half-angles from the pivot add up to less than the spread's half-angle, by a margin far above
// rounding, no tap is outside it (and the tap-by-tap test, run otherwise, would say so too).
// `tap_cos` is min |tap·pivot|, `mean_cos` |mean·pivot|, `norm` the sum's norm (the test also
// fails a sum that does not normalize).
[[gnu::always_inline]] inline bool WithinSpread(V tap_cos, V mean_cos, V norm, double min_dot) {
  constexpr double kMargin = 1e-9;
  const V zero = Broadcast(0.0);
  const V tap_sin_squared = 1.0 - tap_cos * tap_cos;
  const V mean_sin_squared = 1.0 - mean_cos * mean_cos;
  const V sines_squared = (tap_sin_squared > 0.0 ? tap_sin_squared : zero) *
                          (mean_sin_squared > 0.0 ? mean_sin_squared : zero);
  // cos(phi_tap + phi_mean).
  const V sum_cos = tap_cos * mean_cos - Sqrt(sines_squared);
  const Mask within = sum_cos >= min_dot + kMargin && norm > 1e-9;
  bool all = true;
  for (std::size_t lane = 0; lane < kLanes; ++lane) all = all && within[lane] != 0;
  return all;
}

TEMPOKEY_AVX2_CLONES void WeightedMeansKernel(const double* quats, MeanTables tables,
                                             std::size_t count, double min_dot, QuatArrays out,
                                             unsigned char* needs_markley) {
  static_assert(kLanes == kMeanLanes);
  for (std::size_t first = 0, g = 0; first < count; first += kLanes, ++g) {
    const std::size_t lanes = std::min(kLanes, count - first);
    const MeanGroup& group = tables.groups[g];
    const std::int64_t* source = tables.source + group.tap_begin;
    const double* weight = tables.weight + group.tap_begin;
    const QuatLanes ref = Gather(quats, group.pivot);
    QuatLanes sum = {Broadcast(0.0), Broadcast(0.0), Broadcast(0.0), Broadcast(0.0)};
    V nearest_pivot = Broadcast(1.0);  // min |q·pivot| over the taps
    for (std::int64_t n = 0; n < group.taps; ++n) {
      const QuatLanes q = Gather(quats, source + kLanes * n);
      const V w = LoadV(weight + kLanes * n);
      const V dot = Dot(q, ref);
      const V signed_w = dot < 0.0 ? -w : w;
      sum = {sum.w + q.w * signed_w, sum.x + q.x * signed_w, sum.y + q.y * signed_w,
             sum.z + q.z * signed_w};
      const V size = vector_trig::Abs(dot);
      nearest_pivot = size < nearest_pivot ? size : nearest_pivot;
    }
    const V squared = Dot(sum, sum);
    V norm;
    for (std::size_t lane = 0; lane < kLanes; ++lane) norm[lane] = std::sqrt(squared[lane]);
    const V inverse = 1.0 / norm;
    const QuatLanes mean = Scaled(sum, inverse);
    Mask markley = !(norm > 1e-9);
    if (!WithinSpread(nearest_pivot, vector_trig::Abs(Dot(mean, ref)), norm, min_dot)) {
      for (std::int64_t n = 0; n < group.taps; ++n) {
        const QuatLanes q = Gather(quats, source + kLanes * n);
        const V w = LoadV(weight + kLanes * n);
        markley = markley || (w != 0.0 && vector_trig::Abs(Dot(q, mean)) < min_dot);
      }
    }
    StoreQuats(out, first, mean, lanes);
    for (std::size_t lane = 0; lane < lanes; ++lane) needs_markley[first + lane] = markley[lane] ? 1 : 0;
  }
}

// Lanes whose two vectors differ in any bit (-0 and +0 differ; no NaN arises here).
using Bits = std::int64_t __attribute__((vector_size(sizeof(V))));
[[gnu::always_inline]] inline Mask Differ(V a, V b) { return (Bits)a != (Bits)b; }
[[gnu::always_inline]] inline bool Any(Mask m) {
  bool any = false;
  for (std::size_t lane = 0; lane < kLanes; ++lane) any = any || m[lane] != 0;
  return any;
}

// PrincipalEigenvector() of rotation.cc, one symmetric 4x4 matrix per lane of each of G groups:
// the cyclic Jacobi sweeps with its stopping rules, each lane stopping where the scalar function
// would (a lane that has stopped, or whose rotation the scalar function skips, keeps its values).
// Every rotation waits on the previous one's divisions and square roots: the G groups' chains run
// side by side.
template <int G>
[[gnu::always_inline]] inline void PrincipalEigenvectors(V (&a)[G][4][4], V (&e)[G][4]) {
  constexpr double kTinyRotation = 0x1p-30;
  const V zero = Broadcast(0.0);
  const V one = Broadcast(1.0);
  V v[G][4][4];
  Mask done[G];
  for (int g = 0; g < G; ++g) {
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) v[g][r][c] = r == c ? one : zero;
    }
    done[g] = zero != zero;
  }
  for (int sweep = 0; sweep < 64; ++sweep) {
    bool any_active = false;
    Mask settled[G];
    for (int g = 0; g < G; ++g) {
      V off = zero;
      for (int p = 0; p < 4; ++p) {
        for (int q = p + 1; q < 4; ++q) off += a[g][p][q] * a[g][p][q];
      }
      done[g] = done[g] || off < 1e-300;
      any_active = any_active || Any(!done[g]);
      settled[g] = !done[g];
    }
    if (!any_active) break;
    for (int p = 0; p < 4; ++p) {
      for (int q = p + 1; q < 4; ++q) {
        V c[G], s[G];
        Mask rotate[G];
        for (int g = 0; g < G; ++g) {
          const Mask skipped = a[g][p][q] == 0.0;
          settled[g] = settled[g] && !skipped;
          rotate[g] = !done[g] && !skipped;
          const V theta = (a[g][q][q] - a[g][p][p]) / (2.0 * a[g][p][q]);
          const V t =
              (theta >= 0 ? one : -one) / (vector_trig::Abs(theta) + Sqrt(theta * theta + 1.0));
          c[g] = 1.0 / Sqrt(t * t + 1.0);
          s[g] = t * c[g];
          settled[g] = settled[g] && !(rotate[g] && !(vector_trig::Abs(t) < kTinyRotation));
        }
        for (int g = 0; g < G; ++g) {
          const V app = a[g][p][p];
          const V aqq = a[g][q][q];
          for (int k = 0; k < 4; ++k) {
            const V akp = a[g][k][p];
            const V akq = a[g][k][q];
            a[g][k][p] = rotate[g] ? c[g] * akp - s[g] * akq : akp;
            a[g][k][q] = rotate[g] ? s[g] * akp + c[g] * akq : akq;
          }
          for (int k = 0; k < 4; ++k) {
            const V apk = a[g][p][k];
            const V aqk = a[g][q][k];
            a[g][p][k] = rotate[g] ? c[g] * apk - s[g] * aqk : apk;
            a[g][q][k] = rotate[g] ? s[g] * apk + c[g] * aqk : aqk;
          }
          settled[g] = settled[g] && !(Differ(a[g][p][p], app) || Differ(a[g][q][q], aqq));
          for (int k = 0; k < 4; ++k) {
            const V vkp = v[g][k][p];
            const V vkq = v[g][k][q];
            v[g][k][p] = rotate[g] ? c[g] * vkp - s[g] * vkq : vkp;
            v[g][k][q] = rotate[g] ? s[g] * vkp + c[g] * vkq : vkq;
            settled[g] = settled[g] && !(Differ(v[g][k][p], vkp) || Differ(v[g][k][q], vkq));
          }
        }
      }
    }
    for (int g = 0; g < G; ++g) done[g] = done[g] || settled[g];
  }
  for (int g = 0; g < G; ++g) {
    V best = a[g][0][0];
    for (int r = 0; r < 4; ++r) e[g][r] = v[g][r][0];
    for (int i = 1; i < 4; ++i) {
      const Mask larger = a[g][i][i] > best;
      best = larger ? a[g][i][i] : best;
      for (int r = 0; r < 4; ++r) e[g][r] = larger ? v[g][r][i] : e[g][r];
    }
  }
}

// Groups of kLanes jobs one Markley step takes together.
constexpr int kMarkleyGroups = 2;

// MarkleyMean() for several jobs at once, one per lane; a lane past its job's taps adds its pivot
// with weight 0, which leaves every sum as it is (a group past the last job repeats it and stores
// nothing).
TEMPOKEY_AVX2_CLONES void MarkleyMeansKernel(const double* quats, const double* weights,
                                            const WeightedMeanJob* jobs, std::size_t count,
                                            QuatArrays out) {
  constexpr int G = kMarkleyGroups;
  for (std::size_t start = 0; start < count; start += G * kLanes) {
    std::size_t first[G], lanes[G];
    std::int64_t pivot[G][kLanes];
    V m[G][4][4];
    for (int g = 0; g < G; ++g) {
      const std::size_t begin = start + static_cast<std::size_t>(g) * kLanes;
      first[g] = begin < count ? begin : start;
      lanes[g] = begin < count ? std::min(kLanes, count - begin) : 0;
      const WeightedMeanJob* job[kLanes];
      std::int64_t longest = 0;
      for (std::size_t lane = 0; lane < kLanes; ++lane) {
        job[lane] = &jobs[first[g] + std::min(lane, std::max<std::size_t>(lanes[g], 1) - 1)];
        pivot[g][lane] = job[lane]->pivot;
        longest = std::max(longest, job[lane]->count);
      }
      // Σ w q qᵀ, every entry summed over the taps in order, as (w q_r) q_c.
      for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) m[g][r][c] = Broadcast(0.0);
      }
      for (std::int64_t n = 0; n < longest; ++n) {
        std::int64_t at[kLanes];
        V w;
        for (std::size_t lane = 0; lane < kLanes; ++lane) {
          const bool real = n < job[lane]->count;
          at[lane] = real ? job[lane]->first + n : pivot[g][lane];
          w[lane] = real ? weights[job[lane]->weight_offset + n] : 0.0;
        }
        const QuatLanes q = Gather(quats, at);
        const V component[4] = {q.w, q.x, q.y, q.z};
        for (int r = 0; r < 4; ++r) {
          const V weighted = w * component[r];
          for (int c = 0; c < 4; ++c) m[g][r][c] += weighted * component[c];
        }
      }
    }
    V e[G][4];
    PrincipalEigenvectors<G>(m, e);
    for (int g = 0; g < G; ++g) {
      if (lanes[g] == 0) continue;
      QuatLanes mean = Normalized({e[g][0], e[g][1], e[g][2], e[g][3]});
      const Mask flip = Dot(mean, Gather(quats, pivot[g])) < 0.0;
      mean = {flip ? -mean.w : mean.w, flip ? -mean.x : mean.x, flip ? -mean.y : mean.y,
              flip ? -mean.z : mean.z};
      StoreQuats(out, first[g], mean, lanes[g]);
    }
  }
}

}  // namespace

void MarkleyMeans(const double* quats, const double* weights, const WeightedMeanJob* jobs,
                  std::size_t count, QuatArrays out) {
  MarkleyMeansKernel(quats, weights, jobs, count, out);
}

void EulerToQuats(const EulerOrder& order, const double* a, const double* b, const double* c,
                  std::size_t count, double* out) {
  EulerToQuatsKernel(order, a, b, c, count, out);
}

void WeightedMeans(const double* quats, const MeanTables& tables, std::size_t count, double min_dot,
                   QuatArrays out, unsigned char* needs_markley) {
  WeightedMeansKernel(quats, tables, count, min_dot, out, needs_markley);
}

void SlerpQuats(const double* quats, const std::int64_t* i0, const double* t, std::size_t count,
                QuatArrays out, unsigned char* discontinuous) {
  SlerpKernel(quats, i0, t, count, out, discontinuous);
}

void QuatsToEulerNearest(const EulerOrder& order, ConstQuatArrays q, const EulerTargets& targets,
                         std::size_t count, unsigned char* ill_conditioned) {
  ToEulerKernel(order, q, targets, count, ill_conditioned);
}

}  // namespace tempokey::core::retime_internal
