#include "rotation_batch.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numbers>
#include <vector>

#include "core/src/simd/instruction_set.h"
#include "core/src/simd/vector_trig.h"
#include "core/src/simd/vectors.h"

// The kernels are cloned with AVX2 (TEMPOKEY_CLONES_AVX2), not AVX: they select lanes by masks,
// which are 256-bit integer vectors (AVX alone splits them into 128-bit halves).
// The hottest kernels (conversions to quaternions and back, weighted means) also come as 8-lane
// variants for AVX-512 processors, chosen at run time: the same arithmetic lane by lane (no
// contraction into FMA: -ffp-contract=off), so the same bits, in about half the instructions.
// Built by GCC alone, without sanitizers (TEMPOKEY_WIDE_KERNELS: the fuzz stage's clang build
// keeps the portable code).

namespace tempokey::core::retime_internal {
namespace {

// Four lanes, one AVX register (GCC's lowering of wider vectors to two registers handles lane
// accesses poorly); the kernels take several vectors per step instead, so that independent chains
// of dependent operations are in flight through every polynomial and division.
using V = vector_trig::V4;
using Mask = vector_trig::MaskOf<V>;
constexpr std::size_t kLanes = 4;
// The 8-lane vectors of the AVX-512 variants. The helpers below take either width (LanesOf<V>).
using V8 = vector_trig::V8;
template <class T>
inline constexpr std::size_t LanesOf = sizeof(T) / sizeof(double);

// As rotation.cc.
constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kRadToDeg = 180.0 / std::numbers::pi;
constexpr double kSinRatioSeriesLimit = 0.5;

// Quaternions, one per lane.
template <class VT>
struct QuatLanesOf {
  VT w, x, y, z;
};
using QuatLanes = QuatLanesOf<V>;

[[gnu::always_inline]] inline V Broadcast(double v) { return vector_trig::Splat<V>(v); }

// Lane flags as doubles, 1 where set and 0 elsewhere, for the kernels that take either width: GCC
// 12 turns an 8-lane comparison held as a mask value (read lane by lane, combined with integer
// operations or passed on) into a comparison per lane, where a comparison used at once to select
// between two vectors stays one instruction. So conditions are written `cond ? one : zero`.
template <class VT>
struct FlagValues {
  const VT one = vector_trig::Splat<VT>(1.0);
  const VT zero = vector_trig::Splat<VT>(0.0);
};

// True when no lane of `flags` (ones and zeros) is set: the lanes summed over halves.
template <class VT>
[[gnu::always_inline]] inline bool NoneSet(VT flags) {
  using V2 = double __attribute__((vector_size(16)));
  V four;
  if constexpr (LanesOf<VT> == 8) {
    four = __builtin_shufflevector(flags, flags, 0, 1, 2, 3) +
           __builtin_shufflevector(flags, flags, 4, 5, 6, 7);
  } else {
    four = flags;
  }
  const V2 two = __builtin_shufflevector(four, four, 0, 1) + __builtin_shufflevector(four, four, 2, 3);
  return two[0] + two[1] == 0.0;
}

// Lanes [0, count) of `p` (count <= lanes), the missing lanes repeating lane 0: a partial group
// computes its padding on real values.
template <class VT = V>
[[gnu::always_inline]] inline VT LoadPartial(const double* p, std::size_t count) {
  VT v;
  if (count >= LanesOf<VT>) {
    std::memcpy(&v, p, sizeof v);
    return v;
  }
  v = vector_trig::Splat<VT>(p[0]);
  for (std::size_t lane = 1; lane < count; ++lane) v[lane] = p[lane];
  return v;
}

template <class VT>
[[gnu::always_inline]] inline void StorePartial(double* p, VT v, std::size_t count) {
  if (count >= LanesOf<VT>) {
    std::memcpy(p, &v, sizeof v);
    return;
  }
  for (std::size_t lane = 0; lane < count; ++lane) p[lane] = v[lane];
}

template <class VT = V>
[[gnu::always_inline]] inline QuatLanesOf<VT> LoadQuats(ConstQuatArrays q, std::size_t i,
                                                        std::size_t count) {
  return {LoadPartial<VT>(q.w + i, count), LoadPartial<VT>(q.x + i, count),
          LoadPartial<VT>(q.y + i, count), LoadPartial<VT>(q.z + i, count)};
}

template <class VT>
[[gnu::always_inline]] inline void StoreQuats(QuatArrays q, std::size_t i, const QuatLanesOf<VT>& v,
                                              std::size_t count) {
  StorePartial(q.w + i, v.w, count);
  StorePartial(q.x + i, v.x, count);
  StorePartial(q.y + i, v.y, count);
  StorePartial(q.z + i, v.z, count);
}

// The scalar functions of rotation.cc, lane by lane, in their order of operations.

template <class VT>
[[gnu::always_inline]] inline VT Dot(const QuatLanesOf<VT>& a, const QuatLanesOf<VT>& b) {
  return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
}

template <class VT>
[[gnu::always_inline]] inline QuatLanesOf<VT> Scaled(const QuatLanesOf<VT>& q, VT s) {
  return {q.w * s, q.x * s, q.y * s, q.z * s};
}

// std::sqrt lane by lane (one vsqrtpd where the target has it).
template <class VT>
[[gnu::always_inline]] inline VT Sqrt(VT v) {
  VT root;
  for (std::size_t lane = 0; lane < LanesOf<VT>; ++lane) root[lane] = std::sqrt(v[lane]);
  return root;
}

template <class VT>
[[gnu::always_inline]] inline QuatLanesOf<VT> Normalized(const QuatLanesOf<VT>& q) {
  return Scaled(q, 1.0 / Sqrt(Dot(q, q)));
}

// AxisRotation(axis, degrees) is (cos, sin along the axis) of the half angle
// 0.5 * degrees * kDegToRad.

// Multiply(q, AxisRotation(axis, .)) for the rotation (c, s along `axis`): Multiply()'s four
// products per component less the ones by the rotation's zero components. Those are exact zeros,
// and adding or subtracting an exact zero leaves a sum as it is, so every component has
// Multiply()'s value (up to the sign of a zero result).
template <class VT>
[[gnu::always_inline]] inline QuatLanesOf<VT> MultiplyByAxis(const QuatLanesOf<VT>& q, int axis,
                                                             VT s, VT c) {
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

template <class VT>
[[gnu::always_inline]] inline VT NearestTurn(VT angle, VT reference) {
  return angle + 360.0 * vector_trig::RoundSmall((reference - angle) * (1.0 / 360.0));
}

// True when every lane of the three `v` is below `limit` in size (the vector sine's accurate
// range).
template <class VT>
[[gnu::always_inline]] inline bool AllReducible(const VT (&v)[3], double limit) {
  // As integers, the bits of doubles without their sign bit order as the sizes do, a NaN above
  // every number: the largest over the lanes, compared once (integer operations only, which GCC
  // keeps as vector operations on 8 lanes too).
  using Bits = vector_trig::MaskOf<VT>;
  auto magnitude = [](VT x) __attribute__((always_inline)) { return (Bits)x & std::numeric_limits<std::int64_t>::max(); };
  auto larger = [](auto a, auto b) __attribute__((always_inline)) { return a > b ? a : b; };
  const Bits largest = larger(larger(magnitude(v[0]), magnitude(v[1])), magnitude(v[2]));
  vector_trig::MaskOf<V> four;
  if constexpr (LanesOf<VT> == 8) {
    four = larger(__builtin_shufflevector(largest, largest, 0, 1, 2, 3),
                  __builtin_shufflevector(largest, largest, 4, 5, 6, 7));
  } else {
    four = largest;
  }
  std::int64_t most = 0;
  for (std::size_t lane = 0; lane < kLanes; ++lane) most = larger(most, four[lane]);
  return most < std::bit_cast<std::int64_t>(limit);
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

// The 4-lane halves of an 8-lane vector, and back (shuffles: every bit kept).
[[maybe_unused, gnu::always_inline]] inline V LowHalf(V8 v) { return __builtin_shufflevector(v, v, 0, 1, 2, 3); }
[[maybe_unused, gnu::always_inline]] inline V HighHalf(V8 v) { return __builtin_shufflevector(v, v, 4, 5, 6, 7); }
[[maybe_unused, gnu::always_inline]] inline V8 Joined(V low, V high) {
  return __builtin_shufflevector(low, high, 0, 1, 2, 3, 4, 5, 6, 7);
}

// (w, x, y, z) of the first `count` lanes' quaternions as consecutive (w, x, y, z) groups.
[[gnu::always_inline]] inline void StoreInterleaved(double* out, const QuatLanes& q,
                                                    std::size_t count) {
  static_assert(kLanes == 4);
  V a = q.w, b = q.x, c = q.y, d = q.z;
  Transpose(a, b, c, d);
  simd::Store(out, a);
  if (count > 1) simd::Store(out + 4, b);
  if (count > 2) simd::Store(out + 8, c);
  if (count > 3) simd::Store(out + 12, d);
}
[[maybe_unused, gnu::always_inline]] inline void StoreInterleaved(double* out,
                                                                  const QuatLanesOf<V8>& q,
                                                                  std::size_t count) {
  if (count == 2 * kLanes) {
    // The 8x4 transpose on whole vectors: pairs of components, then quaternions two by two, then
    // the pairs of quaternions in order; 12 shuffles and 4 stores, where two 4x4 transposes of
    // the halves took 20 shuffles (the extractions among them) and 8 stores.
    const V8 wx_even = __builtin_shufflevector(q.w, q.x, 0, 8, 2, 10, 4, 12, 6, 14);
    const V8 wx_odd = __builtin_shufflevector(q.w, q.x, 1, 9, 3, 11, 5, 13, 7, 15);
    const V8 yz_even = __builtin_shufflevector(q.y, q.z, 0, 8, 2, 10, 4, 12, 6, 14);
    const V8 yz_odd = __builtin_shufflevector(q.y, q.z, 1, 9, 3, 11, 5, 13, 7, 15);
    const V8 q02 = __builtin_shufflevector(wx_even, yz_even, 0, 1, 8, 9, 2, 3, 10, 11);
    const V8 q13 = __builtin_shufflevector(wx_odd, yz_odd, 0, 1, 8, 9, 2, 3, 10, 11);
    const V8 q46 = __builtin_shufflevector(wx_even, yz_even, 4, 5, 12, 13, 6, 7, 14, 15);
    const V8 q57 = __builtin_shufflevector(wx_odd, yz_odd, 4, 5, 12, 13, 6, 7, 14, 15);
    const V8 rows[4] = {__builtin_shufflevector(q02, q13, 0, 1, 2, 3, 8, 9, 10, 11),
                        __builtin_shufflevector(q02, q13, 4, 5, 6, 7, 12, 13, 14, 15),
                        __builtin_shufflevector(q46, q57, 0, 1, 2, 3, 8, 9, 10, 11),
                        __builtin_shufflevector(q46, q57, 4, 5, 6, 7, 12, 13, 14, 15)};
    for (int r = 0; r < 4; ++r) std::memcpy(out + 8 * r, &rows[r], sizeof rows[r]);
    return;
  }
  StoreInterleaved(out, QuatLanes{LowHalf(q.w), LowHalf(q.x), LowHalf(q.y), LowHalf(q.z)}, count);
  if (count <= kLanes) return;
  StoreInterleaved(out + 4 * kLanes,
                   QuatLanes{HighHalf(q.w), HighHalf(q.x), HighHalf(q.y), HighHalf(q.z)},
                   count - kLanes);
}

// Quaternions (w, x, y, z) from `quats` at the indices `at`, one per lane.
template <class VT = V>
[[gnu::always_inline]] inline QuatLanesOf<VT> Gather(const double* quats, const std::int64_t* at) {
  if constexpr (LanesOf<VT> == 4) {
    V a = simd::Load(quats + 4 * at[0]), b = simd::Load(quats + 4 * at[1]),
      c = simd::Load(quats + 4 * at[2]), d = simd::Load(quats + 4 * at[3]);
    Transpose(a, b, c, d);
    return {a, b, c, d};
  } else {
    static_assert(LanesOf<VT> == 8);
    // Quaternions k and k + 4 side by side in one 8-lane vector, then the 4x4 transpose on both
    // halves at once: 4 insertions, 4 in-lane unpacks and 4 two-source permutes, where two 4-lane
    // transposes and their joins took 20 shuffles and as many register moves (a tap of a weighted
    // mean is mostly this).
    V8 pair[4];
    for (int k = 0; k < 4; ++k) {
      pair[k] = Joined(simd::Load(quats + 4 * at[k]), simd::Load(quats + 4 * at[k + 4]));
    }
    // (w0 w1 y0 y1 | w4 w5 y4 y5) and (x0 x1 z0 z1 | x4 x5 z4 z5) from quaternions 0, 1, 4, 5; the
    // same from 2, 3, 6, 7.
    const V8 wy01 = __builtin_shufflevector(pair[0], pair[1], 0, 8, 2, 10, 4, 12, 6, 14);
    const V8 xz01 = __builtin_shufflevector(pair[0], pair[1], 1, 9, 3, 11, 5, 13, 7, 15);
    const V8 wy23 = __builtin_shufflevector(pair[2], pair[3], 0, 8, 2, 10, 4, 12, 6, 14);
    const V8 xz23 = __builtin_shufflevector(pair[2], pair[3], 1, 9, 3, 11, 5, 13, 7, 15);
    return {__builtin_shufflevector(wy01, wy23, 0, 1, 8, 9, 4, 5, 12, 13),
            __builtin_shufflevector(xz01, xz23, 0, 1, 8, 9, 4, 5, 12, 13),
            __builtin_shufflevector(wy01, wy23, 2, 3, 10, 11, 6, 7, 14, 15),
            __builtin_shufflevector(xz01, xz23, 2, 3, 10, 11, 6, 7, 14, 15)};
  }
}

// Lanes [0, count) of `flags` (ones and zeros) as bytes 1 and 0 at p. A whole vector's in one
// store: the bits of 1.0 shifted down to 1 (and 0.0's to 0), the low bytes gathered by a
// shuffle, where a loop over the lanes took a comparison each (lane by lane on 8 lanes: GCC 12)
// and a branch for the count.
template <class VT>
[[gnu::always_inline]] inline void StoreFlags(unsigned char* p, VT flags, std::size_t count) {
  constexpr std::size_t L = LanesOf<VT>;
  if (count < L) {
    for (std::size_t lane = 0; lane < count; ++lane) p[lane] = flags[lane] != 0.0 ? 1 : 0;
    return;
  }
  const auto ones = ((vector_trig::MaskOf<VT>)flags >> 52) & 1;
  if constexpr (L == 8) {
    using Bytes = unsigned char __attribute__((vector_size(64)));
    using Out = unsigned char __attribute__((vector_size(8)));
    const Bytes bytes = (Bytes)ones;
    const Out out = __builtin_shufflevector(bytes, bytes, 0, 8, 16, 24, 32, 40, 48, 56);
    std::memcpy(p, &out, sizeof out);
  } else {
    static_assert(L == 4);
    using Bytes = unsigned char __attribute__((vector_size(32)));
    using Out = unsigned char __attribute__((vector_size(4)));
    const Bytes bytes = (Bytes)ones;
    const Out out = __builtin_shufflevector(bytes, bytes, 0, 8, 16, 24);
    std::memcpy(p, &out, sizeof out);
  }
}

// Lanes [0, count) of index array `p` into `at` (L entries), the missing lanes repeating lane 0.
template <std::size_t L = kLanes>
[[gnu::always_inline]] inline void LoadIndices(const std::int64_t* p, std::size_t count,
                                               std::int64_t (&at)[L]) {
  for (std::size_t lane = 0; lane < L; ++lane) at[lane] = p[lane < count ? lane : 0];
}

// Whether the L output indices follow one another (output[l] == output[0] + l for every lane).
template <std::size_t L>
[[gnu::always_inline]] inline bool Consecutive(const std::int64_t (&output)[L]) {
  bool consecutive = true;
  for (std::size_t lane = 1; lane < L; ++lane) {
    consecutive &= output[lane] == output[0] + static_cast<std::int64_t>(lane);
  }
  return consecutive;
}

// The kernels below are written for one Euler order (axes I, J, K) at a time: the axes then pick
// matrix entries and products at compile time rather than through memory.
template <int I, int J, int K, class VT>
[[gnu::always_inline]] inline QuatLanesOf<VT> AxesProduct(const VT (&sine)[3],
                                                          const VT (&cosine)[3]) {
  // EulerToQuat(): Multiply(Multiply(R0, R1), R2) with R_n = AxisRotation(axis n, angle n).
  const VT zero = vector_trig::Splat<VT>(0.0);
  const QuatLanesOf<VT> first = {cosine[0], I == 0 ? sine[0] : zero, I == 1 ? sine[0] : zero,
                                 I == 2 ? sine[0] : zero};
  return MultiplyByAxis(MultiplyByAxis(first, J, sine[1], cosine[1]), K, sine[2], cosine[2]);
}

template <int I, int J, int K, class VT>
[[gnu::always_inline]] inline void EulerToQuatsBody(const double* a, const double* b,
                                                    const double* c, std::size_t count,
                                                    double* out) {
  constexpr std::size_t L = LanesOf<VT>;
  constexpr EulerOrder order = {I, J, K};
  // Half angles (radians) beyond kMaxReducedRadians: far beyond any rotation channel's values.
  constexpr double kMaxDegrees = 2.0 * vector_trig::kMaxReducedRadians / kDegToRad;
  // Samples [i, i + lanes) with an angle beyond kMaxDegrees (or not a number) converted again,
  // one by one, by the scalar code: which samples take it depends on each sample alone, never on
  // its neighbours in a vector, so the result does not depend on the vectors' width.
  auto redo_unreducible = [&](std::size_t i, std::size_t lanes) {
    for (std::size_t lane = i; lane < i + lanes; ++lane) {
      if (std::abs(a[lane]) < kMaxDegrees && std::abs(b[lane]) < kMaxDegrees &&
          std::abs(c[lane]) < kMaxDegrees) {
        continue;
      }
      const Quat q = EulerToQuat(order, {a[lane], b[lane], c[lane]});
      double* p = out + 4 * lane;
      p[0] = q.w;
      p[1] = q.x;
      p[2] = q.y;
      p[3] = q.z;
    }
  };
  auto half_radians = [](VT degrees) __attribute__((always_inline)) { return 0.5 * degrees * kDegToRad; };
  std::size_t i = 0;
  // Angles below this many degrees have half angles SinCosSmall() takes (mocap joints mostly
  // stay within them: 95 % of CMU 131_01's blocks of 16 frames).
  constexpr double kSmallDegrees = 89.0;
  static_assert(0.5 * kSmallDegrees * kDegToRad < vector_trig::kMaxUnreducedRadians);
  // Two groups per step, their six sines and cosines side by side.
  for (; i + 2 * L <= count; i += 2 * L) {
    const VT angle[2][3] = {
        {simd::Load<VT>(a + i), simd::Load<VT>(b + i), simd::Load<VT>(c + i)},
        {simd::Load<VT>(a + i + L), simd::Load<VT>(b + i + L), simd::Load<VT>(c + i + L)}};
    VT sine[6], cosine[6];
    const VT half[6] = {half_radians(angle[0][0]), half_radians(angle[0][1]),
                        half_radians(angle[0][2]), half_radians(angle[1][0]),
                        half_radians(angle[1][1]), half_radians(angle[1][2])};
    const bool reducible = AllReducible(angle[0], kMaxDegrees) &&
                           AllReducible(angle[1], kMaxDegrees);
    if (AllReducible(angle[0], kSmallDegrees) && AllReducible(angle[1], kSmallDegrees)) {
      vector_trig::SinCosSmall<6>(half, sine, cosine);
    } else {
      vector_trig::SinCos<6>(half, sine, cosine);
    }
    for (std::size_t g = 0; g < 2; ++g) {
      const VT s[3] = {sine[3 * g], sine[3 * g + 1], sine[3 * g + 2]};
      const VT co[3] = {cosine[3 * g], cosine[3 * g + 1], cosine[3 * g + 2]};
      StoreInterleaved(out + 4 * (i + g * L), AxesProduct<I, J, K>(s, co), L);
    }
    if (!reducible) redo_unreducible(i, 2 * L);
  }
  for (; i < count; i += L) {
    const std::size_t lanes = std::min(L, count - i);
    const VT angle[3] = {LoadPartial<VT>(a + i, lanes), LoadPartial<VT>(b + i, lanes),
                         LoadPartial<VT>(c + i, lanes)};
    VT sine[3], cosine[3];
    vector_trig::SinCos<3>({half_radians(angle[0]), half_radians(angle[1]), half_radians(angle[2])},
                           sine, cosine);
    StoreInterleaved(out + 4 * i, AxesProduct<I, J, K>(sine, cosine), lanes);
    if (!AllReducible(angle, kMaxDegrees)) redo_unreducible(i, lanes);
  }
}

// The order's axes (0 X, 1 Y, 2 Z) as one number, for a switch over the six orders.
constexpr int OrderCode(int i, int j, int k) { return 9 * i + 3 * j + k; }
constexpr int OrderCode(const EulerOrder& order) { return OrderCode(order[0], order[1], order[2]); }

// Calls body<I, J, K, VT>(args...) for the order's axes. Precondition: valid order.
#define TEMPOKEY_FOR_ORDER(order, body, VT, ...)                          \
  switch (OrderCode(order)) {                                              \
    case OrderCode(0, 1, 2): return body<0, 1, 2, VT>(__VA_ARGS__);        \
    case OrderCode(0, 2, 1): return body<0, 2, 1, VT>(__VA_ARGS__);        \
    case OrderCode(1, 0, 2): return body<1, 0, 2, VT>(__VA_ARGS__);        \
    case OrderCode(1, 2, 0): return body<1, 2, 0, VT>(__VA_ARGS__);        \
    case OrderCode(2, 0, 1): return body<2, 0, 1, VT>(__VA_ARGS__);        \
    default: return body<2, 1, 0, VT>(__VA_ARGS__);                        \
  }

TEMPOKEY_CLONES_AVX2 void EulerToQuatsKernel(const EulerOrder& order, const double* a,
                                             const double* b, const double* c, std::size_t count,
                                             double* out) {
  TEMPOKEY_FOR_ORDER(order, EulerToQuatsBody, V, a, b, c, count, out);
}

// Groups of kLanes samples one slerp step takes together.
constexpr int kSlerpGroups = 2;

TEMPOKEY_CLONES_AVX2 void SlerpKernel(const double* quats, const std::int64_t* i0, const double* t,
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
          Normalized(QuatLanes{qa_g.w * wa + qb_g.w * wb, qa_g.x * wa + qb_g.x * wb,
                      qa_g.y * wa + qb_g.y * wb, qa_g.z * wa + qb_g.z * wb});
      // Exact ends: t <= 0 gives `from`, t >= 1 gives `to` (aligned).
      const Mask at_start = tt[g] <= 0.0;
      const Mask at_end = tt[g] >= 1.0;
      auto pick = [&](V from, V to, V middle) __attribute__((always_inline)) {
        return at_start ? from : (at_end ? to : middle);
      };
      if (lanes[g] == 0) continue;
      StoreQuats(out, first[g],
                 QuatLanes{pick(qa_g.w, qb_g.w, mixed.w), pick(qa_g.x, qb_g.x, mixed.x),
                  pick(qa_g.y, qb_g.y, mixed.y), pick(qa_g.z, qb_g.z, mixed.z)},
                 lanes[g]);
    }
  }
}

// Groups of LanesOf<VT> samples converted back together (on 4 and 8 lanes), their arctangents
// side by side: one group's chain of divisions and polynomials alone leaves the processor waiting.
constexpr int kEulerGroups = 2;

template <int I, int J, int K, class VT>
[[gnu::always_inline]] inline void ToEulerBody(ConstQuatArrays quats, const EulerTargets& targets,
                                               std::size_t count, unsigned char* ill_conditioned) {
  constexpr std::size_t L = LanesOf<VT>;
  auto broadcast = [](double v) __attribute__((always_inline)) { return vector_trig::Splat<VT>(v); };
  constexpr int i = I;
  constexpr int j = J;
  constexpr int k = K;
  constexpr double sign = ((j - i + 3) % 3 == 1) ? 1.0 : -1.0;
  // Two groups on 8 lanes as well: their six arctangents' polynomial chains overlap. (One group
  // had measured faster while every sample also took a normalization's square root and division;
  // without them two are 2-6 % faster, paired runs of bench/retime_bench. The same bits: each
  // lane's operations do not depend on the grouping.)
  constexpr int G = kEulerGroups;
  for (std::size_t start = 0; start < count; start += G * L) {
    // Group g's samples start at first[g]; a group past the end repeats group 0 and stores
    // nothing.
    std::size_t first[G], lanes[G];
    VT sin_b[G], cos_b[G], y[3 * G], x[3 * G];
    for (int g = 0; g < G; ++g) {
      const std::size_t begin = start + static_cast<std::size_t>(g) * L;
      first[g] = begin < count ? begin : start;
      lanes[g] = begin < count ? std::min(L, count - begin) : 0;
      // Not normalized again (QuatToEulerNearest() does): every quaternion given here is a unit
      // one within rounding, and a square root and a division per sample were about 4 % of the
      // rotation-aware retime. The angles move by a few units in the last place.
      const QuatLanesOf<VT> q = LoadQuats<VT>(quats, first[g], std::max<std::size_t>(lanes[g], 1));
      // QuatToMatrix().
      const VT xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
      const VT xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
      const VT wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
      const VT r[3][3] = {{1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)},
                          {2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)},
                          {2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)}};
      VT sb = sign * r[i][k];
      sin_b[g] = sb < -1.0 ? broadcast(-1.0) : (1.0 < sb ? broadcast(1.0) : sb);
      const VT cos_squared = r[i][i] * r[i][i] + r[i][j] * r[i][j];
      cos_b[g] = Sqrt(cos_squared);
      y[3 * g] = sin_b[g];
      x[3 * g] = cos_b[g];
      y[3 * g + 1] = -sign * r[j][k];
      x[3 * g + 1] = r[k][k];
      y[3 * g + 2] = -sign * r[i][j];
      x[3 * g + 2] = r[i][i];
    }
    VT bac[3 * G];
    vector_trig::Atan2<3 * G>(y, x, bac);
    for (int g = 0; g < G; ++g) {
      const VT b = bac[3 * g], a = bac[3 * g + 1], c = bac[3 * g + 2];
      const std::size_t n = std::max<std::size_t>(lanes[g], 1);
      std::int64_t at[L], nearest[L], output[L];
      LoadIndices(targets.i0 + first[g], n, at);
      LoadIndices(targets.nearest + first[g], n, nearest);
      LoadIndices(targets.output + first[g], n, output);
      const VT tt = LoadPartial<VT>(targets.t + first[g], n);
      // The source's unwrapped angles interpolated linearly at the sample, and its values at the
      // nearest sample.
      VT ref[3], turn[3];
      for (int axis = 0; axis < 3; ++axis) {
        VT v0, v1, nearest_value;
        for (std::size_t lane = 0; lane < L; ++lane) {
          v0[lane] = targets.reference[axis][at[lane]];
          v1[lane] = targets.reference[axis][at[lane] + 1];
          nearest_value[lane] = targets.turn[axis][nearest[lane]];
        }
        ref[axis] = v0 + tt * (v1 - v0);
        turn[axis] = nearest_value;
      }
      // The two Tait-Bryan solutions, each angle moved to the turn nearest the reference; the
      // nearer wins (NearestCandidate()).
      VT first_angles[3] = {NearestTurn(a * kRadToDeg, ref[0]), NearestTurn(b * kRadToDeg, ref[1]),
                            NearestTurn(c * kRadToDeg, ref[2])};
      VT second_angles[3] = {NearestTurn((a + std::numbers::pi) * kRadToDeg, ref[0]),
                             NearestTurn((std::numbers::pi - b) * kRadToDeg, ref[1]),
                             NearestTurn((c + std::numbers::pi) * kRadToDeg, ref[2])};
      VT first_cost = broadcast(0.0), second_cost = broadcast(0.0);
      for (int axis = 0; axis < 3; ++axis) {
        const VT d1 = first_angles[axis] - ref[axis];
        first_cost += d1 * d1;
        const VT d2 = second_angles[axis] - ref[axis];
        second_cost += d2 * d2;
      }
      VT angle[3];
      for (int axis = 0; axis < 3; ++axis) {
        const VT nearer =
            second_cost < first_cost ? second_angles[axis] : first_angles[axis];
        angle[axis] = NearestTurn(nearer, turn[axis]);
      }
      // Outputs one after the other (a decimation's weighted means, a slowed section's slerps)
      // take one vector store per axis. Every lane is checked: a group may straddle two kinds of
      // slot (BatchSlots orders a batch by kind), so its first and last outputs can be L - 1
      // apart while the ones between are not consecutive.
      if (lanes[g] == L && Consecutive(output)) {
        for (int axis = 0; axis < 3; ++axis) {
          simd::Store(targets.out[axis] + output[0], angle[axis]);
        }
      } else {
        for (int axis = 0; axis < 3; ++axis) {
          for (std::size_t lane = 0; lane < lanes[g]; ++lane) {
            targets.out[axis][output[lane]] = angle[axis][lane];
          }
        }
      }
      // Near gimbal lock: the caller's (gimbal lock itself, cos_b < 1e-12, among them).
      const VT near_lock = cos_b[g] < kBatchedMinMiddleCos ? broadcast(1.0) : broadcast(0.0);
      StoreFlags(ill_conditioned + first[g], near_lock, lanes[g]);
    }
  }
}

TEMPOKEY_CLONES_AVX2 void ToEulerKernel(const EulerOrder& order, ConstQuatArrays quats,
                                        const EulerTargets& targets, std::size_t count,
                                        unsigned char* ill_conditioned) {
  TEMPOKEY_FOR_ORDER(order, ToEulerBody, V, quats, targets, count, ill_conditioned);
}

#if TEMPOKEY_WIDE_KERNELS
TEMPOKEY_TARGET_AVX512 void EulerToQuatsKernel8(const EulerOrder& order, const double* a,
                                                const double* b, const double* c,
                                                std::size_t count, double* out) {
  TEMPOKEY_FOR_ORDER(order, EulerToQuatsBody, V8, a, b, c, count, out);
}

TEMPOKEY_TARGET_AVX512 void ToEulerKernel8(const EulerOrder& order, ConstQuatArrays quats,
                                           const EulerTargets& targets, std::size_t count,
                                           unsigned char* ill_conditioned) {
  TEMPOKEY_FOR_ORDER(order, ToEulerBody, V8, quats, targets, count, ill_conditioned);
}
#endif

#undef TEMPOKEY_FOR_ORDER

// WeightedMeanRotation()'s arithmetic for kLanes output samples at once, one per lane, in its order
// of operations for every lane.
// True when the spread test of every lane's weighted mean is known to pass without testing each
// tap: with half-angles phi(p, q) = acos|p·q| (a metric on rotations), every tap is within
// phi(tap, pivot) + phi(pivot, mean) of the mean, so when the largest tap's and the mean's
// half-angles from the pivot add up to less than the spread's half-angle, by a margin far above
// rounding, no tap is outside it (and the tap-by-tap test, run otherwise, would say so too).
// `tap_cos` is min |tap·pivot|, `mean_cos` |mean·pivot|, `unnormalizable` 1 in the lanes whose sum
// does not normalize (the test fails them too), 0 elsewhere.
template <class VT>
[[gnu::always_inline]] inline bool WithinSpread(VT tap_cos, VT mean_cos, VT unnormalizable,
                                                double min_dot) {
  constexpr double kMargin = 1e-9;
  const VT zero = vector_trig::Splat<VT>(0.0);
  const VT tap_sin_squared = 1.0 - tap_cos * tap_cos;
  const VT mean_sin_squared = 1.0 - mean_cos * mean_cos;
  const VT sines_squared = (tap_sin_squared > 0.0 ? tap_sin_squared : zero) *
                           (mean_sin_squared > 0.0 ? mean_sin_squared : zero);
  // cos(phi_tap + phi_mean) = tap_cos mean_cos - sqrt(sines_squared) >= min_dot + kMargin, as
  // excess = tap_cos mean_cos - min_dot - kMargin >= sqrt(sines_squared), that is
  // excess |excess| >= sines_squared: no square root (the divider it waited on also takes every
  // mean's normalization). The rounding of either form is far below kMargin.
  const VT excess = tap_cos * mean_cos - (min_dot + kMargin);
  const FlagValues<VT> flag;
  const VT outside =
      excess * vector_trig::Abs(excess) >= sines_squared ? unnormalizable : flag.one;
  return NoneSet(outside);
}

// The weighted means of the groups' samples, LanesOf<VT> lanes at a time: a group of kMeanLanes
// samples is one 8-lane vector or two 4-lane ones. Two vectors are in flight at once: their taps
// summed side by side, then both normalized (a square root, then a division: a long chain that
// one vector alone leaves waiting). Each lane's operations are the same either way: the same bits.
template <class VT>
[[gnu::always_inline]] inline void WeightedMeansBody(const double* quats, MeanTables tables,
                                                     std::size_t count, double min_dot,
                                                     QuatArrays out,
                                                     unsigned char* needs_markley) {
  constexpr std::size_t L = LanesOf<VT>;
  static_assert(kMeanLanes % L == 0);
  using Q = QuatLanesOf<VT>;
  const VT zero = vector_trig::Splat<VT>(0.0);
  // One vector's mean in the making: samples [first, first + L).
  struct Mean {
    std::size_t first;
    std::int64_t taps;
    const std::int64_t* source;
    const double* weight;
    Q ref;
    Q sum;
    VT nearest_pivot;  // min |q·pivot| over the taps
  };
  auto begin = [&](std::size_t first) __attribute__((always_inline)) {
    const MeanGroup& group = tables.groups[first / kMeanLanes];
    // This vector's lanes within the group's.
    const std::size_t part = first % kMeanLanes;
    return Mean{first,
                group.taps,
                tables.source + group.tap_begin + part,
                tables.weight + group.tap_begin + part,
                Gather<VT>(quats, group.pivot + part),
                {zero, zero, zero, zero},
                vector_trig::Splat<VT>(1.0)};
  };
  auto add_tap = [&](Mean& m, std::int64_t n) __attribute__((always_inline)) {
    const Q q = Gather<VT>(quats, m.source + kMeanLanes * n);
    const VT w = simd::Load<VT>(m.weight + kMeanLanes * n);
    const VT dot = Dot(q, m.ref);
    const VT signed_w = dot < 0.0 ? -w : w;
    m.sum = {m.sum.w + q.w * signed_w, m.sum.x + q.x * signed_w, m.sum.y + q.y * signed_w,
             m.sum.z + q.z * signed_w};
    const VT size = vector_trig::Abs(dot);
    m.nearest_pivot = size < m.nearest_pivot ? size : m.nearest_pivot;
  };
  // Taps [from, m.taps) of m.
  auto add_taps_from = [&](Mean& m, std::int64_t from) __attribute__((always_inline)) {
    for (std::int64_t n = from; n < m.taps; ++n) add_tap(m, n);
  };
  auto finish = [&](const Mean& m) __attribute__((always_inline)) {
    const std::size_t lanes = std::min(L, count - m.first);
    const VT norm = Sqrt(Dot(m.sum, m.sum));
    const VT inverse = 1.0 / norm;
    const Q mean = Scaled(m.sum, inverse);
    const FlagValues<VT> flag;
    // One comparison of the norm, its flags used twice (a comparison used in two places is
    // shared as a mask value, which GCC 12 makes lane by lane on 8 lanes).
    VT markley = norm > 1e-9 ? flag.zero : flag.one;
    if (!WithinSpread(m.nearest_pivot, vector_trig::Abs(Dot(mean, m.ref)), markley, min_dot)) {
      for (std::int64_t n = 0; n < m.taps; ++n) {
        const Q q = Gather<VT>(quats, m.source + kMeanLanes * n);
        const VT w = simd::Load<VT>(m.weight + kMeanLanes * n);
        markley = w != 0.0 && vector_trig::Abs(Dot(q, mean)) < min_dot ? flag.one : markley;
      }
    }
    StoreQuats(out, m.first, mean, lanes);
    StoreFlags(needs_markley + m.first, markley, lanes);
  };
  std::size_t first = 0;
  for (; first + L < count; first += 2 * L) {
    Mean a = begin(first);
    Mean b = begin(first + L);
    const std::int64_t both = std::min(a.taps, b.taps);
    std::int64_t n = 0;
    for (; n < both; ++n) {
      add_tap(a, n);
      add_tap(b, n);
    }
    add_taps_from(a, n);
    add_taps_from(b, n);
    finish(a);
    finish(b);
  }
  if (first < count) {
    Mean a = begin(first);
    add_taps_from(a, 0);
    finish(a);
  }
}

TEMPOKEY_CLONES_AVX2 void WeightedMeansKernel(const double* quats, MeanTables tables,
                                              std::size_t count, double min_dot, QuatArrays out,
                                              unsigned char* needs_markley) {
  WeightedMeansBody<V>(quats, tables, count, min_dot, out, needs_markley);
}

#if TEMPOKEY_WIDE_KERNELS
TEMPOKEY_TARGET_AVX512 void WeightedMeansKernel8(const double* quats, MeanTables tables,
                                                 std::size_t count, double min_dot, QuatArrays out,
                                                 unsigned char* needs_markley) {
  WeightedMeansBody<V8>(quats, tables, count, min_dot, out, needs_markley);
}
#endif

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
    _Pragma("GCC unroll 4") for (int p = 0; p < 4; ++p) {
      _Pragma("GCC unroll 4") for (int q = p + 1; q < 4; ++q) {
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

// The principal eigenvector by repeated squaring, where the matrix says it converges: per lane,
// S = M + sigma I (sigma the sum of the negative weights' sizes, so S is positive semidefinite up
// to rounding: every tap adds w q q^T, whose eigenvalues are w |q|^2 and 0, |q| = 1 within
// rounding), B = S / trace(S), whose eigenvalues mu_1 >= ... >= mu_4 >= 0 sum to 1. The Rayleigh
// quotient rho of the start vector v (the pivot) bounds mu_1 >= rho, so mu_2 <= 1 - rho: where
// rho >= kPowerMinRayleigh = 3/4, mu_2 / mu_1 <= 1/3 and v lies within 30 degrees of the
// eigenvector (tangent at most 1/sqrt(3)). kPowerSquarings squarings (each renormalized by its
// trace) make B^64, whose image of v is within (1/3)^64 / sqrt(3) < 1e-30 of the eigenvector
// before rounding (B^32 would leave up to 3e-16, more than half a unit in the last place: the
// sixth squaring is needed); rounding adds
// a few units in the last place, as the Jacobi sweeps' own does (the relative gap is at least
// 1/2). `accepted` is 1 in such lanes, 0 in the others (a broad or degenerate spread, a negative
// weight outweighing the rest, anything not a number), which the caller gives to the sweeps.
// Markley's means are taken where taps lie over 30 degrees from the mean, so most have rho near
// 1. The squarings are multiplications and additions, where each of the sweeps' rotations waits
// on three divisions and two square roots: Markley's share of Bandai's dance at 2.5x fell from
// 23 % of the retime to 6 %, the other jobs' sweeps included (README, "Measured").
constexpr double kPowerMinRayleigh = 0.75;
constexpr int kPowerSquarings = 6;

template <int G>
[[gnu::always_inline]] inline void PowerEigenvectors(const V (&m)[G][4][4], const V (&sigma)[G],
                                                     const QuatLanes (&start)[G], V (&e)[G][4],
                                                     V (&accepted)[G]) {
  const FlagValues<V> flag;
  for (int g = 0; g < G; ++g) {
    // The upper triangle of S (M's sums are symmetric but for rounding).
    V b[4][4];
    for (int r = 0; r < 4; ++r) {
      for (int c = r; c < 4; ++c) b[r][c] = r == c ? m[g][r][c] + sigma[g] : m[g][r][c];
    }
    const V trace = (b[0][0] + b[1][1]) + (b[2][2] + b[3][3]);
    const V inverse = 1.0 / trace;
    for (int r = 0; r < 4; ++r) {
      for (int c = r; c < 4; ++c) b[r][c] = b[r][c] * inverse;
    }
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < r; ++c) b[r][c] = b[c][r];
    }
    const V v[4] = {start[g].w, start[g].x, start[g].y, start[g].z};
    V bv[4];
    for (int r = 0; r < 4; ++r) {
      bv[r] = (b[r][0] * v[0] + b[r][1] * v[1]) + (b[r][2] * v[2] + b[r][3] * v[3]);
    }
    const V rayleigh = ((v[0] * bv[0] + v[1] * bv[1]) + (v[2] * bv[2] + v[3] * bv[3])) /
                       ((v[0] * v[0] + v[1] * v[1]) + (v[2] * v[2] + v[3] * v[3]));
    // Also false where anything is not a number.
    accepted[g] = trace > 1e-100 && rayleigh >= kPowerMinRayleigh ? flag.one : flag.zero;
    for (int k = 0; k < kPowerSquarings; ++k) {
      V square[4][4];
      for (int r = 0; r < 4; ++r) {
        for (int c = r; c < 4; ++c) {
          square[r][c] = (b[r][0] * b[0][c] + b[r][1] * b[1][c]) +
                         (b[r][2] * b[2][c] + b[r][3] * b[3][c]);
        }
      }
      const V scale = 1.0 / ((square[0][0] + square[1][1]) + (square[2][2] + square[3][3]));
      for (int r = 0; r < 4; ++r) {
        for (int c = r; c < 4; ++c) b[r][c] = b[c][r] = square[r][c] * scale;
      }
    }
    for (int r = 0; r < 4; ++r) {
      e[g][r] = (b[r][0] * v[0] + b[r][1] * v[1]) + (b[r][2] * v[2] + b[r][3] * v[3]);
    }
  }
}

// MarkleyMean() for several jobs at once, one per lane; a lane past its job's taps adds its pivot
// with weight 0, which leaves every sum as it is (a group past the last job repeats it and stores
// nothing).
// With kPowers, each lane's eigenvector by squarings where PowerEigenvectors() accepts it; the
// index of every job it does not accept goes to `retry`, its output unspecified. Without, the
// Jacobi sweeps for every job (MarkleyMean()'s bits).
template <bool kPowers>
[[gnu::always_inline]] inline void MarkleyMeansBody(const double* quats, const double* weights,
                                                    const WeightedMeanJob* jobs, std::size_t count,
                                                    QuatArrays out,
                                                    std::vector<std::size_t>* retry) {
  constexpr int G = kMarkleyGroups;
  for (std::size_t start = 0; start < count; start += G * kLanes) {
    std::size_t first[G], lanes[G];
    std::int64_t pivot[G][kLanes];
    V m[G][4][4];
    V sigma[G];
    for (int g = 0; g < G; ++g) {
      sigma[g] = Broadcast(0.0);
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
        if constexpr (kPowers) sigma[g] += w < 0.0 ? -w : Broadcast(0.0);
        const V component[4] = {q.w, q.x, q.y, q.z};
        for (int r = 0; r < 4; ++r) {
          const V weighted = w * component[r];
          for (int c = 0; c < 4; ++c) m[g][r][c] += weighted * component[c];
        }
      }
    }
    V e[G][4];
    QuatLanes pivots[G];
    for (int g = 0; g < G; ++g) pivots[g] = Gather(quats, pivot[g]);
    if constexpr (kPowers) {
      V accepted[G];
      PowerEigenvectors<G>(m, sigma, pivots, e, accepted);
      for (int g = 0; g < G; ++g) {
        for (std::size_t lane = 0; lane < lanes[g]; ++lane) {
          if (accepted[g][lane] == 0.0) retry->push_back(first[g] + lane);
        }
      }
    } else {
      PrincipalEigenvectors<G>(m, e);
    }
    for (int g = 0; g < G; ++g) {
      if (lanes[g] == 0) continue;
      QuatLanes mean = Normalized(QuatLanes{e[g][0], e[g][1], e[g][2], e[g][3]});
      const Mask flip = Dot(mean, pivots[g]) < 0.0;
      mean = {flip ? -mean.w : mean.w, flip ? -mean.x : mean.x, flip ? -mean.y : mean.y,
              flip ? -mean.z : mean.z};
      StoreQuats(out, first[g], mean, lanes[g]);
    }
  }
}

TEMPOKEY_CLONES_AVX2 void MarkleyMeansKernel(const double* quats, const double* weights,
                                             const WeightedMeanJob* jobs, std::size_t count,
                                             QuatArrays out, std::vector<std::size_t>* retry) {
  if (retry != nullptr) {
    MarkleyMeansBody<true>(quats, weights, jobs, count, out, retry);
  } else {
    MarkleyMeansBody<false>(quats, weights, jobs, count, out, nullptr);
  }
}

#if TEMPOKEY_WIDE_KERNELS
// The same 4-lane code with AVX-512's 32 vector registers: the Jacobi sweeps' two groups of
// matrices (64 vectors) spill less.
TEMPOKEY_TARGET_AVX512 void MarkleyMeansKernel512(const double* quats, const double* weights,
                                                  const WeightedMeanJob* jobs, std::size_t count,
                                                  QuatArrays out,
                                                  std::vector<std::size_t>* retry) {
  if (retry != nullptr) {
    MarkleyMeansBody<true>(quats, weights, jobs, count, out, retry);
  } else {
    MarkleyMeansBody<false>(quats, weights, jobs, count, out, nullptr);
  }
}
#endif

#if TEMPOKEY_WIDE_KERNELS
// True where the 8-lane kernels run (instruction_set.h).
bool UseAvx512Kernels() {
  return simd::RunningInstructionSet() == simd::InstructionSet::kAvx512;
}
#endif

}  // namespace

std::size_t MarkleyMeans(const double* quats, const double* weights,
                         const WeightedMeanJob* jobs, std::size_t count, QuatArrays out) {
  const auto kernel = [&](const WeightedMeanJob* some, std::size_t n, QuatArrays to,
                          std::vector<std::size_t>* retry) {
#if TEMPOKEY_WIDE_KERNELS
    if (UseAvx512Kernels()) return MarkleyMeansKernel512(quats, weights, some, n, to, retry);
#endif
    MarkleyMeansKernel(quats, weights, some, n, to, retry);
  };
  std::vector<std::size_t> retry;
  kernel(jobs, count, out, &retry);
  if (retry.empty()) return 0;
  // The jobs the squarings left: the sweeps, into their own slots.
  std::vector<WeightedMeanJob> again(retry.size());
  for (std::size_t i = 0; i < retry.size(); ++i) again[i] = jobs[retry[i]];
  std::vector<double> components(4 * retry.size());
  const QuatArrays swept = {components.data(), components.data() + retry.size(),
                            components.data() + 2 * retry.size(),
                            components.data() + 3 * retry.size()};
  kernel(again.data(), again.size(), swept, nullptr);
  for (std::size_t i = 0; i < retry.size(); ++i) {
    out.w[retry[i]] = swept.w[i];
    out.x[retry[i]] = swept.x[i];
    out.y[retry[i]] = swept.y[i];
    out.z[retry[i]] = swept.z[i];
  }
  return retry.size();
}

void EulerToQuats(const EulerOrder& order, const double* a, const double* b, const double* c,
                  std::size_t count, double* out) {
#if TEMPOKEY_WIDE_KERNELS
  if (UseAvx512Kernels()) return EulerToQuatsKernel8(order, a, b, c, count, out);
#endif
  EulerToQuatsKernel(order, a, b, c, count, out);
}

void WeightedMeans(const double* quats, const MeanTables& tables, std::size_t count, double min_dot,
                   QuatArrays out, unsigned char* needs_markley) {
#if TEMPOKEY_WIDE_KERNELS
  if (UseAvx512Kernels()) return WeightedMeansKernel8(quats, tables, count, min_dot, out, needs_markley);
#endif
  WeightedMeansKernel(quats, tables, count, min_dot, out, needs_markley);
}

void SlerpQuats(const double* quats, const std::int64_t* i0, const double* t, std::size_t count,
                QuatArrays out, unsigned char* discontinuous) {
  SlerpKernel(quats, i0, t, count, out, discontinuous);
}

void QuatsToEulerNearest(const EulerOrder& order, ConstQuatArrays q, const EulerTargets& targets,
                         std::size_t count, unsigned char* ill_conditioned) {
#if TEMPOKEY_WIDE_KERNELS
  if (UseAvx512Kernels()) return ToEulerKernel8(order, q, targets, count, ill_conditioned);
#endif
  ToEulerKernel(order, q, targets, count, ill_conditioned);
}

}  // namespace tempokey::core::retime_internal
