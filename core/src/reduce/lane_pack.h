// Packs of 8 double lanes for kernels compiled once per instruction set: one AVX-512 vector
// (Pack512) or two 4-lane vectors (PackPair, for AVX2 and the baseline), and RunOnPacks(), which
// runs a kernel with the running machine's pack.
//
// GCC lowers an 8-lane vector type badly where the target has no 512-bit registers (element by
// element through the stack), so a kernel written once on 8-lane vectors and cloned with
// target_clones runs several times slower in its AVX2 and baseline clones than 4-lane code. A
// kernel written on a pack type instead is instantiated with Pack512 in an avx512f function and
// with PackPair elsewhere. Every lane goes through the same operations in the same order in both
// packs, and contraction into FMA is off (-ffp-contract=off, core/CMakeLists.txt), so the results
// agree bit for bit. All members are always inlined: a pack passed by value between code built
// for different targets would disagree on how it is passed (see deploy/unoptimized-kernel-tests.sh).
#ifndef TEMPOKEY_CORE_SRC_REDUCE_LANE_PACK_H_
#define TEMPOKEY_CORE_SRC_REDUCE_LANE_PACK_H_

#include <cstdint>
#include <cstring>

#include "core/src/simd/instruction_set.h"
#include "core/src/simd/vectors.h"

namespace tempokey::core::simd {

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"

// 8 lanes in one 512-bit vector.
struct Pack512 {
  using V = double __attribute__((vector_size(64)));
  using M = std::int64_t __attribute__((vector_size(64)));
  struct Mask {
    M m;
  };
  V v;

  [[gnu::always_inline]] static Pack512 Load(const double* p) {
    Pack512 r;
    std::memcpy(&r.v, p, sizeof r.v);
    return r;
  }
  [[gnu::always_inline]] void Store(double* p) const { std::memcpy(p, &v, sizeof v); }
  // Two 4-lane halves joined: GCC 12 builds V{x, x, ...} (or a shuffle of lane 0, which it folds
  // into that) stored to an array one masked broadcast per lane.
  [[gnu::always_inline]] static Pack512 Splat(double x) {
    const V4 half = {x, x, x, x};
    return {__builtin_shufflevector(half, half, 0, 1, 2, 3, 4, 5, 6, 7)};
  }
  [[gnu::always_inline]] static Pack512 Zero() { return {V{}}; }
  // Lane l is true where bit l of `bits` is set.
  [[gnu::always_inline]] static Mask LaneBits(std::uint32_t bits) {
    const std::int64_t b = bits;
    return {(M{1, 2, 4, 8, 16, 32, 64, 128} & M{b, b, b, b, b, b, b, b}) != 0};
  }
  // m ? a : b, lane by lane.
  [[gnu::always_inline]] static Pack512 Select(const Mask& m, const Pack512& a, const Pack512& b) {
    return {m.m ? a.v : b.v};
  }
  [[gnu::always_inline]] friend Pack512 operator+(const Pack512& a, const Pack512& b) {
    return {a.v + b.v};
  }
  [[gnu::always_inline]] friend Pack512 operator-(const Pack512& a, const Pack512& b) {
    return {a.v - b.v};
  }
  [[gnu::always_inline]] friend Pack512 operator*(const Pack512& a, const Pack512& b) {
    return {a.v * b.v};
  }
  [[gnu::always_inline]] friend Pack512 operator-(const Pack512& a) { return {-a.v}; }
  [[gnu::always_inline]] friend Mask operator<(const Pack512& a, const Pack512& b) {
    return {a.v < b.v};
  }
  [[gnu::always_inline]] friend Mask operator>(const Pack512& a, const Pack512& b) {
    return {a.v > b.v};
  }
};

// 8 lanes in two 256-bit vectors, lanes 0..3 and 4..7.
struct PackPair {
  using V = V4;
  using M = std::int64_t __attribute__((vector_size(32)));
  struct Mask {
    M lo, hi;
  };
  V lo, hi;

  [[gnu::always_inline]] static PackPair Load(const double* p) {
    PackPair r;
    std::memcpy(&r.lo, p, sizeof r.lo);
    std::memcpy(&r.hi, p + 4, sizeof r.hi);
    return r;
  }
  [[gnu::always_inline]] void Store(double* p) const {
    std::memcpy(p, &lo, sizeof lo);
    std::memcpy(p + 4, &hi, sizeof hi);
  }
  [[gnu::always_inline]] static PackPair Splat(double x) {
    const V all = {x, x, x, x};
    return {all, all};
  }
  [[gnu::always_inline]] static PackPair Zero() { return {V{}, V{}}; }
  [[gnu::always_inline]] static Mask LaneBits(std::uint32_t bits) {
    const std::int64_t b = bits;
    const M all = {b, b, b, b};
    return {(M{1, 2, 4, 8} & all) != 0, (M{16, 32, 64, 128} & all) != 0};
  }
  [[gnu::always_inline]] static PackPair Select(const Mask& m, const PackPair& a,
                                                const PackPair& b) {
    return {m.lo ? a.lo : b.lo, m.hi ? a.hi : b.hi};
  }
  [[gnu::always_inline]] friend PackPair operator+(const PackPair& a, const PackPair& b) {
    return {a.lo + b.lo, a.hi + b.hi};
  }
  [[gnu::always_inline]] friend PackPair operator-(const PackPair& a, const PackPair& b) {
    return {a.lo - b.lo, a.hi - b.hi};
  }
  [[gnu::always_inline]] friend PackPair operator*(const PackPair& a, const PackPair& b) {
    return {a.lo * b.lo, a.hi * b.hi};
  }
  [[gnu::always_inline]] friend PackPair operator-(const PackPair& a) { return {-a.lo, -a.hi}; }
  [[gnu::always_inline]] friend Mask operator<(const PackPair& a, const PackPair& b) {
    return {a.lo < b.lo, a.hi < b.hi};
  }
  [[gnu::always_inline]] friend Mask operator>(const PackPair& a, const PackPair& b) {
    return {a.lo > b.lo, a.hi > b.hi};
  }
};

#pragma GCC diagnostic pop

// Runs body.template operator()<P>(), an always_inline template callable, built for the running
// machine (RunningInstructionSet()): with P = Pack512 for AVX-512, PackPair for AVX2 and the
// baseline.
template <class Body>
void RunOnPacks(const Body& body) {
  if (RunningInstructionSet() == InstructionSet::kAvx512) {
    RunBuiltForAvx512(
        [&]() __attribute__((always_inline)) { body.template operator()<Pack512>(); });
    return;
  }
  RunForInstructionSet(
      [&]() __attribute__((always_inline)) { body.template operator()<PackPair>(); });
}

}  // namespace tempokey::core::simd

#endif  // TEMPOKEY_CORE_SRC_REDUCE_LANE_PACK_H_
