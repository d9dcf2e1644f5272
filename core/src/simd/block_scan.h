// Scans of long arrays of doubles for the first of a few flagged samples (a value out of range,
// a change, a seam): blocks of kScanBlock samples, four at a time (one AVX2 register, two SSE2
// ones in the portable build), without an early exit inside a block, where a scalar loop with its
// exit compiles to a comparison and branch per sample. Most arrays are read to the end. Blocks of
// eight vectors with their lanes folded by shuffles before the one test: blocks of four tested
// lane by lane spent about as many instructions on the test as on the samples (paired runs of
// bench/retime_bench: the rotation-aware retime 2-4 % faster, the scalar path 6-9 %).
#ifndef TEMPOKEY_CORE_SRC_SIMD_BLOCK_SCAN_H_
#define TEMPOKEY_CORE_SRC_SIMD_BLOCK_SCAN_H_

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

namespace tempokey::core::simd {

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // always inlined: the by-value ABI never applies

using ScanVector = double __attribute__((vector_size(32)));
using ScanMask = std::int64_t __attribute__((vector_size(32)));  // all ones in a flagged lane
inline constexpr std::size_t kScanLanes = sizeof(ScanVector) / sizeof(double);
inline constexpr std::size_t kScanBlock = 8 * kScanLanes;

// The four samples at p, at any alignment.
[[gnu::always_inline]] inline ScanVector LoadScanVector(const double* p) {
  ScanVector v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

// Whether flagged(p) has a lane set for one of the vectors of the block at `block`.
template <class Flagged>
[[gnu::always_inline]] inline bool BlockFlagged(const double* block, Flagged flagged) {
  ScanMask any = {};
  for (std::size_t k = 0; k < kScanBlock; k += kScanLanes) any |= flagged(block + k);
  // The lanes folded by two shuffles, then one lane tested.
  any |= __builtin_shufflevector(any, any, 2, 3, 0, 1);
  any |= __builtin_shufflevector(any, any, 1, 0, 3, 2);
  return any[0] != 0;
}

// The start of the first whole block of [from, n) in which flagged(p) has a lane set for one of
// its vectors (p the vector's first sample in `data`); else n when nothing after the last whole
// block is flagged either, or the start of the samples after the last whole block: the caller
// finishes sample by sample from there. Those last samples are tested as the block that ends at
// n, which overlaps the last whole one (flagged(p) is read only for p in [from, n - 4]), when
// [from, n) holds a block: a short clip's channel (183 frames: 5 blocks and 23 samples) spent
// more on its last samples one by one than on its blocks. Always inlined, so it is built for
// the caller's clones (TEMPOKEY_CLONES_AVX2).
template <class Flagged>
[[gnu::always_inline]] inline std::size_t FirstFlaggedBlock(const double* data, std::size_t from,
                                                            std::size_t n, Flagged flagged) {
  std::size_t i = from;
  for (; i + kScanBlock <= n; i += kScanBlock) {
    if (BlockFlagged(data + i, flagged)) return i;
  }
  if (i < n && i > from && !BlockFlagged(data + (n - kScanBlock), flagged)) return n;
  return i;
}

// The flags of the four samples at p that are not a number or beyond `bound` in magnitude (|v| by
// clearing the sign bit; a NaN compares false, so it is flagged too).
[[gnu::always_inline]] inline ScanMask BeyondMagnitude(const double* p, double bound) {
  const ScanVector size =
      (ScanVector)((ScanMask)LoadScanVector(p) & std::numeric_limits<std::int64_t>::max());
  return !(size <= bound);
}

// The index of the first of data[0, n) that is not a number or beyond `bound` in magnitude, or
// n: the flagged block found in vectors, the sample in it one by one.
[[gnu::always_inline]] inline std::size_t FirstBeyondMagnitude(const double* data, std::size_t n,
                                                               double bound) {
  std::size_t i = FirstFlaggedBlock(data, 0, n, [bound](const double* p)
                                                    __attribute__((always_inline)) {
                                                      return BeyondMagnitude(p, bound);
                                                    });
  while (i < n && std::abs(data[i]) <= bound) ++i;
  return i;
}

#pragma GCC diagnostic pop

}  // namespace tempokey::core::simd

#endif  // TEMPOKEY_CORE_SRC_SIMD_BLOCK_SCAN_H_
