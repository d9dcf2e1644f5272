// 4-lane double vectors (GCC vector extensions) and their small helpers, for the kernels cloned
// with TEMPOKEY_CLONES_AVX (core/src/simd/instruction_set.h): the reductions' kernels, and the
// vector sines and cosines (vector_trig.h) with their callers.
//
// Kernels written with 4-lane vectors compute every lane with the same operations in the same
// order whether the compiler emits one AVX instruction or two SSE2 ones, and contraction into FMA
// is off (-ffp-contract=off, core/CMakeLists.txt), so the AVX and portable clones agree bit for bit:
// results do not depend on the machine.
#ifndef TEMPOKEY_CORE_SRC_SIMD_VECTORS_H_
#define TEMPOKEY_CORE_SRC_SIMD_VECTORS_H_

#include <cstring>

#include "core/src/simd/instruction_set.h"

namespace tempokey::core::simd {

// The helpers return 4-lane vectors by value; they are always inlined into the kernels, so the
// ABI of such a return without AVX (-Wpsabi's note) never comes into play.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"

using V4 = double __attribute__((vector_size(32)));

// A vector V of doubles (4 lanes unless given) loaded or stored at any alignment. A memcpy of the
// whole vector is one unaligned load or store for GCC and clang alike, and is defined for any
// address (clang ignores a lowered alignment on a vector typedef, and UBSan then flags the
// access); a vector copied lane by lane through an array goes through the stack instead.
template <class V = V4>
[[gnu::always_inline]] inline V Load(const double* p) {
  V v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

template <class V>
[[gnu::always_inline]] inline void Store(double* p, V v) { std::memcpy(p, &v, sizeof v); }

[[gnu::always_inline]] inline V4 Broadcast(double x) { return V4{x, x, x, x}; }

// Lanes summed in a fixed order.
[[gnu::always_inline]] inline double Sum(V4 v) { return (v[0] + v[1]) + (v[2] + v[3]); }

[[gnu::always_inline]] inline V4 Abs(V4 v) { return v < 0.0 ? -v : v; }

[[gnu::always_inline]] inline double Max(V4 v) {
  const double a = v[0] > v[1] ? v[0] : v[1];
  const double b = v[2] > v[3] ? v[2] : v[3];
  return a > b ? a : b;
}

// A lane comparison's result (a < b gives -1 where true, 0 where false): whether any lane is true.
[[gnu::always_inline]] inline bool Any(decltype(V4{} < V4{}) mask) {
  return (mask[0] | mask[1] | mask[2] | mask[3]) != 0;
}

// Whether every lane is true.
[[gnu::always_inline]] inline bool All(decltype(V4{} < V4{}) mask) {
  return (mask[0] & mask[1] & mask[2] & mask[3]) != 0;
}

#pragma GCC diagnostic pop

}  // namespace tempokey::core::simd

#endif  // TEMPOKEY_CORE_SRC_SIMD_VECTORS_H_
