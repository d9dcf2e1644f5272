// Sine, cosine and arctangent on vectors of doubles (GCC vector extensions of any width: the
// kernels use 4 lanes, one AVX register, or 8 with AVX-512, and pass several vectors at once so
// that independent chains of dependent operations are in flight), for the batched rotation
// conversions of the rotation-aware resampling (retime/rotation_batch.h) and the rotations of
// forward kinematics (model/kinematics.cc). Plain IEEE arithmetic only, so every build of a
// kernel gives the same bits (core/src/simd/instruction_set.h).
//
// Accuracy (tests/core/simd/vector_trig_test.cc, against x87 long-double sinl, cosl, atan2l):
// within 2.5 units in the last place, where libm's are within one: the conversions that
// use them differ from the scalar ones (std::sin, std::cos, std::atan2) by a few units in the last
// place of their results.
//
// The polynomials are Chebyshev economizations, in exact rational arithmetic, of the Taylor series
// on the reduced ranges below (truncated where the dropped Chebyshev coefficients sum below
// 2e-17, a tenth of a unit in the last place), rounded to double.
#ifndef TEMPOKEY_CORE_SRC_SIMD_VECTOR_TRIG_H_
#define TEMPOKEY_CORE_SRC_SIMD_VECTOR_TRIG_H_

#include <cstdint>

#include "core/src/simd/vectors.h"

namespace tempokey::core::vector_trig {

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"

// 4 and 8 lanes of doubles, and the masks their comparisons give (all bits set where true).
using V4 = simd::V4;
using V8 = double __attribute__((vector_size(64)));
template <class V>
using MaskOf = decltype(V{} < V{});

template <class V>
[[gnu::always_inline]] inline V Splat(double x) {
  return V{} + x;
}

template <class V>
[[gnu::always_inline]] inline V Abs(V v) {
  return v < 0.0 ? -v : v;
}

// Below this size an argument reduces exactly enough by three-part pi/2 (Cody and Waite): k pi/2
// with |k| < 2^23 is exact in each part.
inline constexpr double kMaxReducedRadians = 1.0e7;

// pi/2 in three parts, the first two of 30 significant bits.
inline constexpr double kHalfPi1 = 1.5707963276654482;
inline constexpr double kHalfPi2 = -8.705515692000731e-10;
inline constexpr double kHalfPi3 = -3.50343439808993e-19;
inline constexpr double kTwoOverPi = 0.6366197723675814;
// pi/4: the double nearest it has 50 significant bits, so 2, 3 and 4 times it are exact.
inline constexpr double kQuarterPiHi = 0.7853981633974483;
inline constexpr double kQuarterPiLo = 3.061616997868383e-17;
// tan(pi/8) = sqrt(2) - 1.
inline constexpr double kTanEighthPi = 0.41421356237309503;

// Rounds each lane to the nearest integer (ties to even) for |x| < 2^51: adding 1.5 * 2^52 leaves
// no fraction bits (as rotation.cc's RoundSmall()).
template <class V>
[[gnu::always_inline]] inline V RoundSmall(V x) {
  const V shifter = Splat<V>(6755399441055744.0);
  return (x + shifter) - shifter;
}

// Lanes whose sign bit is set (negative numbers and -0).
template <class V>
[[gnu::always_inline]] inline MaskOf<V> SignBit(V x) {
  return (MaskOf<V>)x < 0;
}

// Every function below takes N independent arguments (arrays of N vectors) and works on them
// statement by statement, each lane with the arithmetic of a single call: the N dependency chains
// of its polynomials and divisions sit side by side in the instruction stream, for the processor to
// overlap (one chain alone leaves it waiting on each multiply and add). `k` runs over the N.
#define TEMPOKEY_FOR_EACH(k, N) _Pragma("GCC unroll 8") for (int k = 0; k < (N); ++k)

// sin(r) and cos(r) for |r| <= pi/4 (reduced arguments).
template <int N, class V>
[[gnu::always_inline]] inline void SinCosReduced(const V (&r)[N], V (&sine)[N], V (&cosine)[N]) {
  V z[N], s[N], c[N];
  TEMPOKEY_FOR_EACH(k, N) z[k] = r[k] * r[k];
  // (sin(r) - r) / r^3 as a polynomial in z = r^2 on [0, 0.617].
  TEMPOKEY_FOR_EACH(k, N) s[k] = Splat<V>(1.5918101877910613e-10);
  TEMPOKEY_FOR_EACH(k, N) s[k] = s[k] * z[k] + -2.5051131474663988e-08;
  TEMPOKEY_FOR_EACH(k, N) s[k] = s[k] * z[k] + 2.7557316100836803e-06;
  TEMPOKEY_FOR_EACH(k, N) s[k] = s[k] * z[k] + -0.00019841269836755419;
  TEMPOKEY_FOR_EACH(k, N) s[k] = s[k] * z[k] + 0.008333333333330946;
  TEMPOKEY_FOR_EACH(k, N) s[k] = s[k] * z[k] + -0.16666666666666666;
  TEMPOKEY_FOR_EACH(k, N) sine[k] = r[k] + (r[k] * z[k]) * s[k];
  // (cos(r) - 1 + z / 2) / z^2 on the same range.
  TEMPOKEY_FOR_EACH(k, N) c[k] = Splat<V>(-1.1382614811253895e-11);
  TEMPOKEY_FOR_EACH(k, N) c[k] = c[k] * z[k] + 2.0876146029590015e-09;
  TEMPOKEY_FOR_EACH(k, N) c[k] = c[k] * z[k] + -2.755731727061801e-07;
  TEMPOKEY_FOR_EACH(k, N) c[k] = c[k] * z[k] + 2.480158729876363e-05;
  TEMPOKEY_FOR_EACH(k, N) c[k] = c[k] * z[k] + -0.0013888888888887395;
  TEMPOKEY_FOR_EACH(k, N) c[k] = c[k] * z[k] + 0.041666666666666664;
  // 1 - z/2 + z^2 c, with the rounding of 1 - z/2 carried into the small part.
  TEMPOKEY_FOR_EACH(k, N) {
    const V half_z = 0.5 * z[k];
    const V w = 1.0 - half_z;
    cosine[k] = w + (((1.0 - w) - half_z) + (z[k] * z[k]) * c[k]);
  }
}

// sin(x) and cos(x) for |x| < kMaxReducedRadians (larger lanes are not reduced accurately: the
// caller checks). x = k pi/2 + r, |r| <= pi/4, then the quadrant k mod 4 swaps and negates.
template <int N, class V>
[[gnu::always_inline]] inline void SinCos(const V (&x)[N], V (&sine)[N], V (&cosine)[N]) {
  V quadrant[N], r[N], s[N], c[N];
  TEMPOKEY_FOR_EACH(k, N) {
    quadrant[k] = RoundSmall(x[k] * kTwoOverPi);
    const V q = quadrant[k];
    r[k] = ((x[k] - q * kHalfPi1) - q * kHalfPi2) - q * kHalfPi3;
  }
  SinCosReduced<N>(r, s, c);
  // The quadrant k mod 4 from the bits of k + 1.5 * 2^52 (RoundSmall()'s shifted sum, whose low
  // bits are k's in two's complement): bit 0 swaps sine and cosine, bit 1 negates the sine, bit 1
  // of k + 1 the cosine. Integer operations select and negate (exactly: a sign flip), where
  // comparisons of the quadrant as a double made masks that GCC lowers lane by lane on 8-lane
  // vectors.
  using Bits = MaskOf<V>;
  constexpr std::int64_t kSignBit = INT64_MIN;
  TEMPOKEY_FOR_EACH(k, N) {
    const Bits shifted = (Bits)(quadrant[k] + Splat<V>(6755399441055744.0));
    const Bits odd = -(shifted & 1);
    // Bit 1 as the sign bit: all ones where set (no shift into the sign).
    const Bits sine_sign = -((shifted >> 1) & 1) & kSignBit;
    const Bits cosine_sign = -(((shifted + 1) >> 1) & 1) & kSignBit;
    const Bits s_bits = (Bits)s[k];
    const Bits c_bits = (Bits)c[k];
    sine[k] = (V)(((s_bits & ~odd) | (c_bits & odd)) ^ sine_sign);
    cosine[k] = (V)(((c_bits & ~odd) | (s_bits & odd)) ^ cosine_sign);
  }
}

// Arguments below this size have quadrant 0 in SinCos() (|x| 2/pi below a half, with room for
// the product's rounding) and reduce to themselves.
inline constexpr double kMaxUnreducedRadians = 0.78;

// SinCos() for |x| < kMaxUnreducedRadians (the caller checks), bit for bit, without the reduction
// and the quadrant's swaps: those leave such an argument as it is (but for -0, which the
// reduction's subtraction of -0 turns into +0, as the added +0 here) and change nothing.
template <int N, class V>
[[gnu::always_inline]] inline void SinCosSmall(const V (&x)[N], V (&sine)[N], V (&cosine)[N]) {
  V r[N];
  TEMPOKEY_FOR_EACH(k, N) r[k] = x[k] + 0.0;
  SinCosReduced<N>(r, sine, cosine);
}

template <class V>
[[gnu::always_inline]] inline void SinCos(V x, V& sine, V& cosine) {
  V s[1], c[1];
  SinCos<1>({x}, s, c);
  sine = s[0];
  cosine = c[0];
}

// atan(u) for |u| <= tan(pi/8).
template <int N, class V>
[[gnu::always_inline]] inline void AtanReduced(const V (&u)[N], V (&out)[N]) {
  V z[N], h[N];
  TEMPOKEY_FOR_EACH(k, N) z[k] = u[k] * u[k];
  // (atan(u) / u - 1) / z as a polynomial in z = u^2 on [0, 0.1716].
  TEMPOKEY_FOR_EACH(k, N) h[k] = Splat<V>(0.016305609739836996);
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + -0.03458942456554059;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + 0.04552367231875368;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + -0.05230633784275726;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + 0.05878954854801641;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + -0.06666427278780239;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + 0.07692296517303976;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + -0.09090908758775827;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + 0.11111111105269593;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + -0.14285714285661094;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + 0.1999999999999981;
  TEMPOKEY_FOR_EACH(k, N) h[k] = h[k] * z[k] + -0.3333333333333333;
  TEMPOKEY_FOR_EACH(k, N) out[k] = u[k] + (u[k] * z[k]) * h[k];
}

// atan2(y, x) in [-pi, pi], with std::atan2's signs and zeros: atan2(+-0, +0) = +-0,
// atan2(+-0, -0) = +-pi. Finite arguments.
template <int N, class V>
[[gnu::always_inline]] inline void Atan2(const V (&y)[N], const V (&x)[N], V (&out)[N]) {
  using Mask = MaskOf<V>;
  const V zero = Splat<V>(0.0);
  const V one = Splat<V>(1.0);
  V u[N], p[N];
  Mask swap[N], big[N];
  TEMPOKEY_FOR_EACH(k, N) {
    const V ax = Abs(x[k]);
    const V ay = Abs(y[k]);
    swap[k] = ay > ax;
    V num = swap[k] ? ax : ay;
    V den = swap[k] ? ay : ax;
    // Operands this small scaled by 2^54 (exactly; their ratio is the same): the comparison
    // below rounds its product absolutely near the subnormals, where it would pick the wrong
    // reduction (atan2(5e-324, 1e-323) came out thousands of units in the last place off).
    const V scale = den < 0x1p-968 ? Splat<V>(0x1p54) : one;
    num = num * scale;
    den = den * scale;
    // atan(t), t = num / den in [0, 1], is m pi/4 + sigma atan(u) with m = 0 or 1, then the
    // octant: the angle stays m pi/4 + sigma atan(u) with m in 0..4 and sigma = +-1, summed once
    // at the end. u is t, or (t - 1) / (t + 1) from the operands when t > tan(pi/8) (num - den is
    // exact for num >= den / 2, Sterbenz). The reduction is chosen on the operands, so that one
    // division gives u: t's division and u's were both made, and the divider's throughput bounds
    // the conversions back to angles (three arctangents a sample). Within rounding of the
    // boundary either u is accurate.
    big[k] = num > kTanEighthPi * den;
    const V u_num = big[k] ? num - den : num;
    const V u_den = big[k] ? num + den : den;
    u[k] = u_den > 0.0 ? u_num / u_den : zero;
  }
  AtanReduced<N>(u, p);
  TEMPOKEY_FOR_EACH(k, N) {
    V m = big[k] ? one : zero;  // atan(t)
    V sigma = one;
    m = swap[k] ? 2.0 - m : m;  // pi/2 - atan(t) when |y| > |x|
    sigma = swap[k] ? -sigma : sigma;
    const Mask negative_x = SignBit(x[k]);
    m = negative_x ? 4.0 - m : m;  // pi - angle when x < 0 or x is -0
    sigma = negative_x ? -sigma : sigma;
    const V angle = m * kQuarterPiHi + (sigma * p[k] + m * kQuarterPiLo);  // in [0, pi]
    out[k] = SignBit(y[k]) ? -angle : angle;
  }
}

template <class V>
[[gnu::always_inline]] inline V Atan2(V y, V x) {
  V out[1];
  Atan2<1>({y}, {x}, out);
  return out[0];
}

#undef TEMPOKEY_FOR_EACH

#pragma GCC diagnostic pop

}  // namespace tempokey::core::vector_trig

#endif  // TEMPOKEY_CORE_SRC_SIMD_VECTOR_TRIG_H_
