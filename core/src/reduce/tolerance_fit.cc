// The error-bounded spline fit (SPEC 4.2); the method is described in tolerance_fit.h.
#include "tempokey/core/reduce/tolerance_fit.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/src/reduce/cubic_certificate.h"
#include "core/src/reduce/fewest_keys_fit.h"
#include "core/src/simd/block_scan.h"
#include "core/src/simd/instruction_set.h"
#include "core/src/simd/vectors.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"

// The kernels below use simd::V4 values; helpers that return them are always inlined (simd.h).
#pragma GCC diagnostic ignored "-Wpsabi"

// This file is built twice (core/CMakeLists.txt): for the baseline, and with
// TEMPOKEY_TOLERANCE_FIT_BUILD_AVX2 defined for AVX2, each build's fitter in a namespace of its
// own. FitWithinTolerance(), in the baseline build, runs the AVX2 build's on a processor with AVX2
// (simd::RunningInstructionSet(), so TEMPOKEY_MAX_ISA=baseline runs the other). Both perform the
// same operations on the same values (no contraction into fused multiply-adds:
// -ffp-contract=off; the compiler never reorders a floating-point sum), so they give the same
// bits; the wider build takes the four-frame blocks inlined in the fitter (the short segments'
// moments, the solves' 2 x 2 blocks) in one instruction where the baseline takes two (callgrind
// of ReduceKeys(), Bandai 775.5 -> 738.0 M instructions, CMU 144.5 -> 139.5 M; paired runs of
// spec8_bench --only=tolerance 5-8 % faster on Bandai, about 4 % on CMU).
// What a processor without AVX2 might run stays out of the AVX2 build's instructions:
// - only this file's own code is built for AVX2 (the pragma after the includes), not the
//   libraries' inline functions and templates it uses, of which the linker keeps one copy for
//   the whole program;
// - it holds nothing made before main(): the short segments' basis rows are the baseline
//   build's (kBasisRowTable, the same bits);
// - its kernels are plain functions, called directly (every processor that runs them has AVX,
//   so they need no AVX clone).
// tests/core/reduce/tolerance_fit_avx2_isolation.py holds the built object file to that (every
// function outside the build, and all that its static initializers reach), and the tests named
// baseline.* run the baseline build on this machine.
#if defined(TEMPOKEY_TOLERANCE_FIT_BUILD_AVX2)
#define TEMPOKEY_TOLERANCE_FIT_BUILD tolerance_fit_avx2
#undef TEMPOKEY_CLONES_AVX
#define TEMPOKEY_CLONES_AVX
#undef TEMPOKEY_CLONES_AVX2
#define TEMPOKEY_CLONES_AVX2
#pragma GCC target("avx2")
#else
#define TEMPOKEY_TOLERANCE_FIT_BUILD tolerance_fit_baseline
#endif

namespace tempokey::core {
// The AVX2 build's fit, when it is built (TEMPOKEY_TOLERANCE_FIT_AVX2).
namespace tolerance_fit_avx2 {
absl::StatusOr<SplineFit> Fit(std::span<const std::span<const double>> channels,
                              std::span<const double> max_errors,
                              const ToleranceFitOptions& options, std::stop_token stop);
}  // namespace tolerance_fit_avx2

// The basis of the segments up to 8 frames long, frame by frame: kBasisRowTable[length][4 k + r]
// is column r at frame k, the same values as BasisColumns holds (FillColumns() computes both),
// laid out so that one frame's four coefficients load together. One table for the process (3 KB,
// made before main() runs by the baseline build, and read by both), not per thread: the thread
// tables' static TLS sits in every thread's stack allocation (see ThreadHeapObject()).
namespace tolerance_fit_baseline {
inline constexpr std::int64_t kBasisRowLength = 8;  // the longest segment in the table
using BasisRowTable =
    std::array<std::array<double, 4 * (kBasisRowLength + 1)>, kBasisRowLength + 1>;
extern const BasisRowTable kBasisRowTable;
}  // namespace tolerance_fit_baseline

namespace TEMPOKEY_TOLERANCE_FIT_BUILD {
namespace {

// Fits aim a hair inside the bound, so that evaluating the same curve another way (keyed curves
// in seconds, EvaluateCurve()) rounds to within the bound too.
constexpr double kBoundMargin = 1e-9;
// Pulls each key's slope towards the samples' central difference and its value towards its
// sample, with this weight against 1 per fitted frame: negligible wherever frames determine the
// fit, and it keeps the normal equations regular where they do not (keys on consecutive frames).
constexpr double kRidge = 1e-9;
// Insertion rounds at most; each round at least halves every segment over the bound.
constexpr int kMaxInsertionRounds = 64;
// Samples of work (frames x channels fitted or measured) between two looks at the stop token:
// about a millisecond.
constexpr std::int64_t kStopCheckSamples = std::int64_t{1} << 16;
// Keys and frames a whole channel's solve takes between two counts of its work for the stop
// token: a small part of kStopCheckSamples, so that a stop is still seen about as soon.
constexpr std::int64_t kStopCountPiece = 4096;
// Elements a GrowTo() adds between two looks at the stop token.
constexpr std::size_t kGrowthPiece = 65536;
// A removal whose window misses the bound by up to this factor is worth reweighting.
constexpr double kLawsonReach = 1.5;
// A ratio known to be over the bound.
constexpr double kOver = std::numeric_limits<double>::infinity();
// Window of a removal: up to kWindowSide keys on each side of the removed one (fewer at the
// clip's ends), the removed key itself not among them.
constexpr int kWindowSide = 2;
constexpr int kWindowKeys = 2 * kWindowSide;

using Mat2 = std::array<double, 4>;  // row-major 2 x 2
using Vec2 = std::array<double, 2>;

// The coefficients of (v_a, m_a, v_b, m_b) at t in a segment of length L:
// (h00, h10 L, h01, h11 L).
inline std::array<double, 4> Coefficients(double t, double length) {
  const double t2 = t * t;
  const double t3 = t2 * t;
  return {2.0 * t3 - 3.0 * t2 + 1.0, (t3 - 2.0 * t2 + t) * length, -2.0 * t3 + 3.0 * t2,
          (t3 - t2) * length};
}

// Coefficients() at every frame k = 0..L of a segment, column by column (the coefficient of v_a
// at every frame, then of m_a, ...), so the per-frame loops run several frames per step.
// One basis column: storage that grows without being zeroed or copied first (Fill() writes every
// entry), so refilling a cache entry for another length costs only the fill.
class BasisColumn {
 public:
  const double* data() const { return data_.get(); }
  double* data() { return data_.get(); }
  double operator[](std::int64_t k) const { return data_[static_cast<std::size_t>(k)]; }
  bool empty() const { return size_ == 0; }
  void Resize(std::size_t size) {
    if (size > capacity_) {
      data_ = std::make_unique_for_overwrite<double[]>(size);
      capacity_ = size;
    }
    size_ = size;
  }

 private:
  std::unique_ptr<double[]> data_;
  std::size_t size_ = 0;
  std::size_t capacity_ = 0;
};

struct BasisColumns {
  std::array<BasisColumn, 4> column;

  void Fill(std::int64_t length);
};

// Coefficients() of four frames at once: every lane computes exactly what Coefficients() does
// (the same operations in the same order, no contraction: simd.h), so the columns are the same
// bits either way; long segments' columns are filled often enough for the speed to matter.
TEMPOKEY_CLONES_AVX void FillColumns(std::int64_t length, double* c0, double* c1, double* c2,
                                     double* c3) {
  using simd::V4;
  const auto l = static_cast<double>(length);
  const V4 lv = simd::Broadcast(l);
  std::int64_t k = 0;
  for (; k + 4 <= length + 1; k += 4) {
    const auto kd = static_cast<double>(k);
    const V4 t = V4{kd, kd + 1.0, kd + 2.0, kd + 3.0} / lv;
    const V4 t2 = t * t;
    const V4 t3 = t2 * t;
    simd::Store(c0 + k, 2.0 * t3 - 3.0 * t2 + 1.0);
    simd::Store(c1 + k, (t3 - 2.0 * t2 + t) * lv);
    simd::Store(c2 + k, -2.0 * t3 + 3.0 * t2);
    simd::Store(c3 + k, (t3 - t2) * lv);
  }
  for (; k <= length; ++k) {
    const std::array<double, 4> c = Coefficients(static_cast<double>(k) / l, l);
    c0[k] = c[0];
    c1[k] = c[1];
    c2[k] = c[2];
    c3[k] = c[3];
  }
}

void BasisColumns::Fill(std::int64_t length) {
  for (BasisColumn& c : column) c.Resize(static_cast<std::size_t>(length) + 1);
  FillColumns(length, column[0].data(), column[1].data(), column[2].data(), column[3].data());
}

constexpr std::int64_t kRowLength = tolerance_fit_baseline::kBasisRowLength;
using tolerance_fit_baseline::BasisRowTable;

// The rows of segments of `length` frames (at most kRowLength).
inline const double* BasisRows(std::int64_t length) {
  return tolerance_fit_baseline::kBasisRowTable[static_cast<std::size_t>(length)].data();
}

// This thread's T, made on its first use. On the heap: a thread_local object itself sits in every
// thread's static TLS block, which glibc carves from the thread's stack, whether or not the
// thread ever fits. Held in place, the basis tables (24.7 and 1.7 KB) took 26 KB of the 100 KB
// stacks of civetweb's workers as Debian builds it, and twice that with a second build of this
// file: a refused HTTP request's error page then ran the worker off its stack
// (HttpFrontEndTest.AmbiguousFramingIsRefusedAndNothingSmuggledIsAnswered;
// tests/server/http/worker_stack_test.cc holds the server executable's own TLS to 16 KB).
template <class T>
T& ThreadHeapObject() {
  thread_local const std::unique_ptr<T> object = std::make_unique<T>();
  return *object;
}

// Where a fit gets its basis columns: segments up to kTabledLength frames long from a table
// computed once per thread (about 1 MB) and fetched once per fit; longer ones up to
// kSharedLongLength from the thread's recently computed lengths (at most about 2 MB: a smooth
// channel's removal windows and its refits under a joint bound keep coming back to them); the
// rare longer ones from the fit's own few recent lengths. A returned reference stays valid until
// the next Get().
constexpr std::int64_t kTabledLength = 256;
constexpr std::int64_t kSharedLongLength = 4096;

class BasisSource {
 public:
  BasisSource() : tables_(ThreadTables()) {}

  // The common case, a tabled length already filled, inline; the rest out of line.
  const BasisColumns& Get(std::int64_t length) {
    if (length <= kTabledLength) {
      const BasisColumns& table = tables_[static_cast<std::size_t>(length)];
      if (!table.column[0].empty()) return table;
    }
    return Compute(length);
  }

 private:
  [[gnu::noinline]] const BasisColumns& Compute(std::int64_t length) {
    if (length <= kTabledLength) {
      BasisColumns& table = tables_[static_cast<std::size_t>(length)];
      table.Fill(length);
      return table;
    }
    if (length <= kSharedLongLength) return ThreadLongEntries().Get(length);
    return long_.Get(length);
  }

  using Tables = std::array<BasisColumns, kTabledLength + 1>;

  // The last few lengths filled, replaced in turn.
  template <std::size_t kCount>
  struct RecentLengths {
    struct Entry {
      std::int64_t length = -1;
      BasisColumns basis;
    };
    std::array<Entry, kCount> entries;
    std::size_t next = 0;

    const BasisColumns& Get(std::int64_t length) {
      for (Entry& entry : entries) {
        if (entry.length == length) return entry.basis;
      }
      Entry& entry = entries[next++ % kCount];
      entry.length = length;
      entry.basis.Fill(length);
      return entry.basis;
    }
  };

  static Tables& ThreadTables() { return ThreadHeapObject<Tables>(); }

  static RecentLengths<16>& ThreadLongEntries() { return ThreadHeapObject<RecentLengths<16>>(); }

  Tables& tables_;
  RecentLengths<4> long_;
};

// ---- kernels over the interior frames k = 1 .. n-1 of a segment --------------------------------

// Which of a segment's two keys a solve fits: both, or only one when the other is a fixed key at
// the edge of a removal window. A segment's sums feed only the rows of its free keys (the Gram
// sums pair each basis column of the segment's start key, columns 0 and 1, and of its end key,
// columns 2 and 3), so a segment with a fixed end needs only the moments of its free key's
// columns and the Gram sums that involve them; each sum kept is accumulated exactly as before.
enum class FreeEnds { kBoth, kStartOnly, kEndOnly };

// Whether moment r, or the Gram sum (r, q) with r <= q, feeds the rows of the free keys.
constexpr bool NeedsMoment(FreeEnds ends, int r) {
  return ends == FreeEnds::kBoth || (ends == FreeEnds::kStartOnly ? r < 2 : r >= 2);
}
constexpr bool NeedsGram(FreeEnds ends, int r, int q) {
  return ends == FreeEnds::kBoth || (ends == FreeEnds::kStartOnly ? r < 2 : q >= 2);
}

// moments[r] = sum of data[k] * column r at k.
TEMPOKEY_CLONES_AVX void DataMoments(const double* data, const BasisColumns& basis,
                                     std::int64_t n, double* moments) {
  using simd::V4;
  const double* c0 = basis.column[0].data();
  const double* c1 = basis.column[1].data();
  const double* c2 = basis.column[2].data();
  const double* c3 = basis.column[3].data();
  V4 m0 = simd::Broadcast(0.0), m1 = m0, m2 = m0, m3 = m0;
  std::int64_t k = 1;
  for (; k + 4 <= n; k += 4) {
    const V4 d = simd::Load(data + k);
    m0 += d * simd::Load(c0 + k);
    m1 += d * simd::Load(c1 + k);
    m2 += d * simd::Load(c2 + k);
    m3 += d * simd::Load(c3 + k);
  }
  double t0 = 0.0, t1 = 0.0, t2 = 0.0, t3 = 0.0;
  for (; k < n; ++k) {
    t0 += data[k] * c0[k];
    t1 += data[k] * c1[k];
    t2 += data[k] * c2[k];
    t3 += data[k] * c3[k];
  }
  moments[0] = simd::Sum(m0) + t0;
  moments[1] = simd::Sum(m1) + t1;
  moments[2] = simd::Sum(m2) + t2;
  moments[3] = simd::Sum(m3) + t3;
}

// DataMoments() of two columns only, ca and cb, into moments[0] and moments[1]: each the same
// operations in the same order as DataMoments() gives that column.
TEMPOKEY_CLONES_AVX void DataMomentPair(const double* data, const double* ca, const double* cb,
                                        std::int64_t n, double* moments) {
  using simd::V4;
  V4 ma = simd::Broadcast(0.0), mb = ma;
  std::int64_t k = 1;
  for (; k + 4 <= n; k += 4) {
    const V4 d = simd::Load(data + k);
    ma += d * simd::Load(ca + k);
    mb += d * simd::Load(cb + k);
  }
  double ta = 0.0, tb = 0.0;
  for (; k < n; ++k) {
    ta += data[k] * ca[k];
    tb += data[k] * cb[k];
  }
  moments[0] = simd::Sum(ma) + ta;
  moments[1] = simd::Sum(mb) + tb;
}

// The scalar tail of WeightedSums() and ShortWeightedSums(): frames [k, n) added, in frame order,
// to the moments `mt` and the upper triangle of the Gram sums `gt`.
// Only the sums `kEnds` needs are added.
template <FreeEnds kEnds>
[[gnu::always_inline]] inline void AddWeightedTail(const double* data, const double* w,
                                                   const BasisColumns& basis, std::int64_t k,
                                                   std::int64_t n, std::array<double, 4>& mt,
                                                   std::array<double, 16>& gt) {
  for (; k < n; ++k) {
    const double wd = w[k] * data[k];
    for (int r = 0; r < 4; ++r) {
      const double cr = basis.column[r][k];
      if (NeedsMoment(kEnds, r)) mt[r] += wd * cr;
      for (int q = r; q < 4; ++q) {
        if (NeedsGram(kEnds, r, q)) gt[4 * r + q] += w[k] * cr * basis.column[q][k];
      }
    }
  }
}

// moments[r] = sum of w[k] data[k] c_r(k); gram[4 r + q] = sum of w[k] c_r(k) c_q(k): the sums
// `kEnds` needs (the others are left as they were).
template <FreeEnds kEnds>
[[gnu::always_inline]] inline void WeightedSumsOf(const double* data, const double* w,
                                                  const BasisColumns& basis, std::int64_t n,
                                                  double* moments, double* gram) {
  using simd::V4;
  // Only the upper triangle of the Gram sums is accumulated (and zeroed: zeroing the whole
  // arrays costs a string instruction's start-up, more than a short segment's sums).
  std::array<V4, 4> m;
  std::array<V4, 16> g;
  std::array<double, 4> mt;
  std::array<double, 16> gt;
  for (int r = 0; r < 4; ++r) {
    m[r] = simd::Broadcast(0.0);
    mt[r] = 0.0;
    for (int q = r; q < 4; ++q) {
      g[4 * r + q] = simd::Broadcast(0.0);
      gt[4 * r + q] = 0.0;
    }
  }
  std::int64_t k = 1;
  for (; k + 4 <= n; k += 4) {
    const V4 wk = simd::Load(w + k);
    const V4 wd = wk * simd::Load(data + k);
    std::array<V4, 4> c;
    for (int r = 0; r < 4; ++r) c[r] = simd::Load(basis.column[r].data() + k);
    for (int r = 0; r < 4; ++r) {
      if (NeedsMoment(kEnds, r)) m[r] += wd * c[r];
      const V4 wc = wk * c[r];
      for (int q = r; q < 4; ++q) {
        if (NeedsGram(kEnds, r, q)) g[4 * r + q] += wc * c[q];
      }
    }
  }
  AddWeightedTail<kEnds>(data, w, basis, k, n, mt, gt);
  for (int r = 0; r < 4; ++r) {
    if (NeedsMoment(kEnds, r)) moments[r] = simd::Sum(m[r]) + mt[r];
    for (int q = r; q < 4; ++q) {
      if (!NeedsGram(kEnds, r, q)) continue;
      gram[4 * r + q] = simd::Sum(g[4 * r + q]) + gt[4 * r + q];
      gram[4 * q + r] = gram[4 * r + q];
    }
  }
}

TEMPOKEY_CLONES_AVX void WeightedSums(const double* data, const double* w,
                                      const BasisColumns& basis, std::int64_t n, double* moments,
                                      double* gram) {
  WeightedSumsOf<FreeEnds::kBoth>(data, w, basis, n, moments, gram);
}
TEMPOKEY_CLONES_AVX void WeightedSumsStart(const double* data, const double* w,
                                           const BasisColumns& basis, std::int64_t n,
                                           double* moments, double* gram) {
  WeightedSumsOf<FreeEnds::kStartOnly>(data, w, basis, n, moments, gram);
}
TEMPOKEY_CLONES_AVX void WeightedSumsEnd(const double* data, const double* w,
                                         const BasisColumns& basis, std::int64_t n,
                                         double* moments, double* gram) {
  WeightedSumsOf<FreeEnds::kEndOnly>(data, w, basis, n, moments, gram);
}

// Segments this short (at most kShortInterior interior frames) reach at most one of the kernels'
// 4-frame blocks: their sums are computed inline below without a call, with the kernels'
// operations in the kernels' order (each lane from 0, the lanes summed pairwise, then the scalar
// tail from 0), so the same bits. (Their largest errors, from 4 interior frames, are one call:
// OverlappingBlocksMaxError().)
constexpr std::int64_t kShortInterior = 7;

// DataMoments() of a short segment (n - 1 <= kShortInterior): the moments `kEnds` needs, two at
// a time (the start key's pair, columns 0 and 1, and the end key's, 2 and 3) from the basis
// rows (BasisRows()), each lane the kernel's operations on its column in the kernel's order
// (callgrind, Bandai: 759.2 -> 746.7 M instructions against a column at a time).
template <FreeEnds kEnds>
inline void ShortDataMoments(const double* data, std::int64_t n, double* moments) {
  static_assert(kShortInterior + 1 <= kRowLength);
  // One block of four frames and a tail of three cover every short segment's interior.
  static_assert(kShortInterior == 4 + 3);
  using V2 = double __attribute__((vector_size(16)));
  const double* rows = BasisRows(n);
  // Branch-free: which frames the block and the tail take varies from call to call, and a
  // mispredicted branch costs more than the few products spent on frames that add +-0
  // (Bandai: 746.7 -> 775.8 M instructions under callgrind, 0.77 M fewer mispredictions in
  // cachegrind's model of 7.80 M, about 3 % less time in paired runs; CMU within its spread).
  const auto has_block = static_cast<std::int64_t>(n >= 5);
  const std::int64_t tail_first = 1 + 4 * has_block;
  auto pair_of = [&](int half) __attribute__((always_inline)) {
    const double* row = rows + 2 * half;
    // Frame k's term when `taken`, else +-0: frame 0's sample (finite) times 0. Reads stay
    // within the segment's frames 0..n - 1 and the table's rows (k <= 7).
    auto term = [&](std::int64_t k, std::int64_t taken) __attribute__((always_inline)) {
      const double d = data[k * taken] * static_cast<double>(taken);
      return V2{d, d} * simd::Load<V2>(row + 4 * k);
    };
    const V2 zero = {0.0, 0.0};
    // Without a block (frames 1..4 not taken) it sums to +0, as the kernel's empty lanes do.
    const V2 block = ((zero + term(1, has_block)) + (zero + term(2, has_block))) +
                     ((zero + term(3, has_block)) + (zero + term(4, has_block)));
    // The tail from +0: never -0, so the +-0 terms past the interior leave it as it is.
    V2 tail = zero;
    for (std::int64_t k = tail_first; k < tail_first + 3; ++k) {
      tail += term(k, static_cast<std::int64_t>(k < n));
    }
    simd::Store(moments + 2 * half, block + tail);
  };
  if (NeedsMoment(kEnds, 0)) pair_of(0);
  if (NeedsMoment(kEnds, 2)) pair_of(1);
}

// WeightedSums() of a short segment (n - 1 <= kShortInterior): the sums `kEnds` needs.
template <FreeEnds kEnds>
inline void ShortWeightedSums(const double* data, const double* w, const BasisColumns& basis,
                              std::int64_t n, double* moments, double* gram) {
  // Only the sums `kEnds` needs are zeroed, read and written: zeroing the whole arrays costs a
  // string instruction's start-up, about as much as a short segment's sums.
  std::array<double, 4> m = {0.0, 0.0, 0.0, 0.0};
  std::array<double, 4> mt = {0.0, 0.0, 0.0, 0.0};
  std::array<double, 16> g;
  std::array<double, 16> gt;
  for (int r = 0; r < 4; ++r) {
    for (int q = r; q < 4; ++q) {
      if (NeedsGram(kEnds, r, q)) g[4 * r + q] = gt[4 * r + q] = 0.0;
    }
  }
  std::int64_t k = 1;
  if (k + 4 <= n) {
    // One block: lane j holds frame 1 + j, from 0; the lanes summed pairwise.
    std::array<double, 4> wd;
    for (int j = 0; j < 4; ++j) wd[j] = w[1 + j] * data[1 + j];
    for (int r = 0; r < 4; ++r) {
      const double* cr = basis.column[r].data() + 1;
      std::array<double, 4> lane;
      if (NeedsMoment(kEnds, r)) {
        for (int j = 0; j < 4; ++j) lane[j] = 0.0 + wd[j] * cr[j];
        m[r] = (lane[0] + lane[1]) + (lane[2] + lane[3]);
      }
      for (int q = r; q < 4; ++q) {
        if (!NeedsGram(kEnds, r, q)) continue;
        const double* cq = basis.column[q].data() + 1;
        for (int j = 0; j < 4; ++j) lane[j] = 0.0 + (w[1 + j] * cr[j]) * cq[j];
        g[4 * r + q] = (lane[0] + lane[1]) + (lane[2] + lane[3]);
      }
    }
    k = 5;
  }
  AddWeightedTail<kEnds>(data, w, basis, k, n, mt, gt);
  for (int r = 0; r < 4; ++r) {
    if (NeedsMoment(kEnds, r)) moments[r] = m[r] + mt[r];
    for (int q = r; q < 4; ++q) {
      if (!NeedsGram(kEnds, r, q)) continue;
      gram[4 * r + q] = g[4 * r + q] + gt[4 * r + q];
      gram[4 * q + r] = gram[4 * r + q];
    }
  }
}

// ScaleByResiduals() of a short segment (n - 1 <= kShortInterior): frame by frame, the same
// products, added to `total` the same way.
inline double ShortScaleByResiduals(const double* data, const BasisColumns& basis, std::int64_t n,
                                    const double* x, double floor, double* weights,
                                    double total) {
  for (std::int64_t k = 1; k < n; ++k) {
    const double y = (basis.column[0][k] * x[0] + basis.column[1][k] * x[1]) +
                     (basis.column[2][k] * x[2] + basis.column[3][k] * x[3]);
    weights[k] *= std::abs(y - data[k]) + floor;
    total += weights[k];
  }
  return total;
}

// |curve - data| at the four frames from `at`, the curve's coefficients broadcast in `x`: each
// lane the scalar formula's operations, (c0 x0 + c1 x1) + (c2 x2 + c3 x3), so the same bits.
[[gnu::always_inline]] inline simd::V4 BlockError(const double* data, const BasisColumns& basis,
                                                  std::int64_t at,
                                                  const std::array<simd::V4, 4>& x) {
  const simd::V4 y = ((simd::Load(basis.column[0].data() + at) * x[0] +
                       simd::Load(basis.column[1].data() + at) * x[1]) +
                      (simd::Load(basis.column[2].data() + at) * x[2] +
                       simd::Load(basis.column[3].data() + at) * x[3]));
  return simd::Abs(y - simd::Load(data + at));
}

// The largest |curve - data| over the interior frames of a segment with 4 to 7 of them: two
// blocks of four frames, the first from frame 1 and the second ending at frame n - 1, which
// overlap (a maximum does not mind a frame seen twice), each lane a frame's error as
// ShortMaxError() computes it, so the same maximum. In its own function
// for the AVX clone: inline in the fitter, whose code is built for the baseline, the blocks
// cost more than the scalar loop (callgrind, Bandai: 767.9 -> 788.6 M instructions against
// 759.2 M out of line).
TEMPOKEY_CLONES_AVX double OverlappingBlocksMaxError(const double* data, const BasisColumns& basis,
                                                     std::int64_t n, const double* x) {
  using simd::V4;
  const std::array<V4, 4> xv = {simd::Broadcast(x[0]), simd::Broadcast(x[1]),
                                simd::Broadcast(x[2]), simd::Broadcast(x[3])};
  const V4 e0 = BlockError(data, basis, 1, xv);
  const V4 e1 = BlockError(data, basis, n - 4, xv);
  V4 worst = simd::Broadcast(0.0);
  worst = e0 > worst ? e0 : worst;
  worst = e1 > worst ? e1 : worst;
  return simd::Max(worst);
}

// MaxError() of a short segment (n - 1 <= kShortInterior), exact (no early return: a value over
// the limit is one the callers accept).
inline double ShortMaxError(const double* data, const BasisColumns& basis, std::int64_t n,
                            const double* x) {
  if (n - 1 >= 4) return OverlappingBlocksMaxError(data, basis, n, x);
  double worst = 0.0;
  for (std::int64_t k = 1; k < n; ++k) {
    const double y = (basis.column[0][k] * x[0] + basis.column[1][k] * x[1]) +
                     (basis.column[2][k] * x[2] + basis.column[3][k] * x[3]);
    const double e = std::abs(y - data[k]);
    if (e > worst) worst = e;
  }
  return worst;
}

// The largest |curve - data| over the interior frames, the curve's coefficients `x` =
// (v_a, m_a, v_b, m_b); returns soon after a frame exceeds `limit` (some value above it: callers
// only compare it with the limit then).
TEMPOKEY_CLONES_AVX double MaxError(const double* data, const BasisColumns& basis,
                                    std::int64_t n, const double* x, double limit) {
  using simd::V4;
  const std::array<V4, 4> xv = {simd::Broadcast(x[0]), simd::Broadcast(x[1]),
                                simd::Broadcast(x[2]), simd::Broadcast(x[3])};
  const V4 limit_v = simd::Broadcast(limit);
  auto block_error = [&](std::int64_t at) __attribute__((always_inline)) {
    return BlockError(data, basis, at, xv);
  };
  V4 worst = simd::Broadcast(0.0);
  std::int64_t k = 1;
  // Two blocks per look at the limit: a maximum does not depend on how often it is looked at,
  // and past the limit any value above it will do.
  for (; k + 8 <= n; k += 8) {
    const V4 e0 = block_error(k);
    const V4 e1 = block_error(k + 4);
    worst = e0 > worst ? e0 : worst;
    worst = e1 > worst ? e1 : worst;
    if (simd::Any(worst > limit_v)) return simd::Max(worst);
  }
  if (k + 4 <= n) {
    const V4 e = block_error(k);
    worst = e > worst ? e : worst;
    if (simd::Any(worst > limit_v)) return simd::Max(worst);
    k += 4;
  }
  double tail = simd::Max(worst);
  for (; k < n; ++k) {
    const double y = (basis.column[0][k] * x[0] + basis.column[1][k] * x[1]) +
                     (basis.column[2][k] * x[2] + basis.column[3][k] * x[3]);
    const double e = std::abs(y - data[k]);
    if (e > tail) tail = e;
  }
  return tail;
}

// weights[k] *= |curve - data[k]| + floor over the interior frames, the curve as in MaxError(),
// each new weight then added to `total` in frame order; returns the sum: one Lawson round's
// reweighting of a segment and its part of the round's sum. The sum is a chain of dependent
// additions, the longest path of a round; the reweighting runs on vectors beside it, at no cost
// of its own.
TEMPOKEY_CLONES_AVX double ScaleByResiduals(const double* data, const BasisColumns& basis,
                                            std::int64_t n, const double* x, double floor,
                                            double* weights, double total) {
  using simd::V4;
  const V4 x0 = simd::Broadcast(x[0]), x1 = simd::Broadcast(x[1]);
  const V4 x2 = simd::Broadcast(x[2]), x3 = simd::Broadcast(x[3]);
  const V4 floor_v = simd::Broadcast(floor);
  std::int64_t k = 1;
  for (; k + 4 <= n; k += 4) {
    const V4 y = ((simd::Load(basis.column[0].data() + k) * x0 +
                   simd::Load(basis.column[1].data() + k) * x1) +
                  (simd::Load(basis.column[2].data() + k) * x2 +
                   simd::Load(basis.column[3].data() + k) * x3));
    const V4 e = simd::Abs(y - simd::Load(data + k));
    const V4 w = simd::Load(weights + k) * (e + floor_v);
    simd::Store(weights + k, w);
    total = (((total + w[0]) + w[1]) + w[2]) + w[3];
  }
  for (; k < n; ++k) {
    const double y = (basis.column[0][k] * x[0] + basis.column[1][k] * x[1]) +
                     (basis.column[2][k] * x[2] + basis.column[3][k] * x[3]);
    weights[k] *= std::abs(y - data[k]) + floor;
    total += weights[k];
  }
  return total;
}

// Sum of c c^T over the interior frames k = 1 .. L-1 of a segment of length L (c as
// Coefficients() at t = k / L), in closed form: each product is a polynomial of degree 6 in t,
// summed with the power sums of k (Faulhaber), so the cost does not grow with L.
std::array<double, 16> InteriorGram(std::int64_t length) {
  const auto l = static_cast<double>(length);
  const double n = l - 1.0;
  // p[e] = sum over k = 1..n of (k / L)^e.
  const double n1 = n + 1.0;
  const double s1 = n * n1 / 2.0;
  std::array<double, 7> p = {
      n,
      s1,
      n * n1 * (2.0 * n + 1.0) / 6.0,
      s1 * s1,
      n * n1 * (2.0 * n + 1.0) * (3.0 * n * n + 3.0 * n - 1.0) / 30.0,
      n * n * n1 * n1 * (2.0 * n * n + 2.0 * n - 1.0) / 12.0,
      n * n1 * (2.0 * n + 1.0) * (3.0 * n * n * n * n + 6.0 * n * n * n - 3.0 * n + 1.0) / 42.0};
  double scale = 1.0;
  for (double& sum : p) {
    sum /= scale;
    scale *= l;
  }
  // The four coefficients as cubics in t (constant term first).
  const std::array<std::array<double, 4>, 4> poly = {{{1.0, 0.0, -3.0, 2.0},
                                                      {0.0, l, -2.0 * l, l},
                                                      {0.0, 0.0, 3.0, -2.0},
                                                      {0.0, 0.0, -l, l}}};
  std::array<double, 16> gram{};
  for (int r = 0; r < 4; ++r) {
    for (int q = r; q < 4; ++q) {
      double sum = 0.0;
      for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) sum += poly[r][i] * poly[q][j] * p[i + j];
      }
      gram[r * 4 + q] = sum;
      gram[q * 4 + r] = sum;
    }
  }
  return gram;
}

Mat2 Inverse(const Mat2& m) {
  const double inverse_det = 1.0 / (m[0] * m[3] - m[1] * m[2]);
  return {m[3] * inverse_det, -m[1] * inverse_det, -m[2] * inverse_det, m[0] * inverse_det};
}
Mat2 Multiply(const Mat2& a, const Mat2& b) {
  return {a[0] * b[0] + a[1] * b[2], a[0] * b[1] + a[1] * b[3], a[2] * b[0] + a[3] * b[2],
          a[2] * b[1] + a[3] * b[3]};
}
Vec2 Apply(const Mat2& a, const Vec2& v) {
  return {a[0] * v[0] + a[1] * v[1], a[2] * v[0] + a[3] * v[1]};
}

// The curve of one segment at interior frame k.
inline double SegmentValue(const std::array<double, 4>& c, double va, double ma, double vb,
                           double mb) {
  return c[0] * va + c[1] * ma + c[2] * vb + c[3] * mb;
}

double CentralDifference(std::span<const double> s, std::int64_t f) {
  const auto n = static_cast<std::int64_t>(s.size());
  if (n < 2) return 0.0;
  if (f == 0) return s[1] - s[0];
  if (f == n - 1) return s[n - 1] - s[n - 2];
  return 0.5 * (s[f + 1] - s[f - 1]);
}

// A key's own terms in its blocks, from zero: its sample weighted by `w` (the frame's weight plus
// the ridge), and the ridge pulling its slope towards the samples' central difference.
inline void KeyTerms(std::span<const double> s, std::int64_t frame, double w, Mat2& diag,
                     Vec2& rhs) {
  diag = {0.0 + w, 0.0, 0.0, 0.0 + kRidge};
  rhs = {0.0 + w * s[frame], 0.0 + kRidge * CentralDifference(s, frame)};
}

// Forward elimination's step from one key to the next: the next key's blocks less what the key
// before gives through their coupling `upper` (its eliminated block `eliminated` and right-hand
// side `rhs_before`): D' = D - U^T E, r' = r - U^T r_before.
inline void SubtractCoupling(const Mat2& upper, const Mat2& eliminated, const Vec2& rhs_before,
                             Mat2& diag, Vec2& rhs) {
  const Mat2 lower = {upper[0], upper[2], upper[1], upper[3]};  // U transposed
  const Mat2 lc = Multiply(lower, eliminated);
  diag = {diag[0] - lc[0], diag[1] - lc[1], diag[2] - lc[2], diag[3] - lc[3]};
  const Vec2 ld = Apply(lower, rhs_before);
  rhs = {rhs[0] - ld[0], rhs[1] - ld[1]};
}

// Whether a and b are the same double, bit for bit (so +0 and -0 differ).
inline bool SameBits(double a, double b) {
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

// A run of keys of one channel: frames shared, values and slopes its own.
struct KeyRun {
  const std::int64_t* frames;
  double* values;
  double* slopes;
  int count;
};

// InteriorGram() of recent lengths. Its entries are exact functions of the length, so one table
// per thread, shared by every fit the thread runs, changes no result.
class GramCache {
 public:
  // On the heap (ThreadHeapObject()): held in place, its 70 KB kept a library that starts
  // threads with small stacks (CivetWeb's metrics threads) from starting them.
  static GramCache& ForThread() { return ThreadHeapObject<GramCache>(); }

  const std::array<double, 16>& Get(std::int64_t length) {
    Entry& entry = entries_[static_cast<std::size_t>(length) % entries_.size()];
    if (entry.length != length) entry = {length, InteriorGram(length)};
    return entry.gram;
  }

 private:
  struct Entry {
    std::int64_t length = -1;
    std::array<double, 16> gram{};
  };
  std::array<Entry, 512> entries_;
};

// The blocks and weights a fit solves with, lent by each thread to one fit at a time: a
// reduction runs one fit per channel (hundreds a clip), and each fit growing its own from nothing
// cost about twenty allocations, which with the rest of a fit's (about fifty) took about 4 % of
// `tolerance` on Bandai's clips (perf). What one fit leaves in them is never read by the next:
// every solve writes what it reads (the blocks a solve keeps from the one before are tracked per
// fit). A vector is given back emptied of its memory when it holds more than kKeptScratchBytes,
// so a fit of millions of keys leaves nothing behind on the thread. A fit started on a thread
// whose vectors are lent already (none is today: fits do not nest) gets vectors of its own.
struct FitScratch {
  std::vector<Mat2> upper, eliminated;
  std::vector<Vec2> rhs;
  std::vector<double> lawson;
  bool lent = false;
};

constexpr std::size_t kKeptScratchBytes = std::size_t{1} << 20;

class ScratchLease {
 public:
  ScratchLease() {
    FitScratch& thread = ForThread();
    if (thread.lent) {
      own_ = std::make_unique<FitScratch>();
      scratch_ = own_.get();
    } else {
      scratch_ = &thread;
    }
    scratch_->lent = true;
  }
  ScratchLease(const ScratchLease&) = delete;
  ScratchLease& operator=(const ScratchLease&) = delete;
  ~ScratchLease() {
    if (own_) return;
    Trim(scratch_->upper);
    Trim(scratch_->eliminated);
    Trim(scratch_->rhs);
    Trim(scratch_->lawson);
    scratch_->lent = false;
  }

  FitScratch& scratch() { return *scratch_; }

 private:
  static FitScratch& ForThread() { return ThreadHeapObject<FitScratch>(); }

  template <class T>
  static void Trim(std::vector<T>& v) {
    if (v.capacity() * sizeof(T) > kKeptScratchBytes) std::vector<T>().swap(v);
  }

  FitScratch* scratch_ = nullptr;
  std::unique_ptr<FitScratch> own_;
};

class Fitter {
 public:
  Fitter(std::span<const std::span<const double>> channels, std::span<const double> max_errors,
         const ToleranceFitOptions& options)
      : channels_(channels), options_(options), frame_count_(channels.front().size()) {
    bounds_.reserve(max_errors.size());
    for (double bound : max_errors) bounds_.push_back(bound * (1.0 - kBoundMargin));
  }

  absl::StatusOr<SplineFit> Run(std::stop_token stop) {
    stop_ = std::move(stop);
    SplineFit fit;
    const std::size_t c_count = channels_.size();
    fit.values.resize(c_count);
    fit.slopes.resize(c_count);
    if (frame_count_ == 1) {
      fit.frames = {0};
      for (std::size_t c = 0; c < c_count; ++c) {
        fit.values[c] = {channels_[c][0]};
        fit.slopes[c] = {0.0};
      }
      return fit;
    }
    // Each phase returns early, its fit incomplete, once a stop was seen.
    Insert(fit);
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop_));
    Remove(fit);
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop_));
    Repair(fit);
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop_));
    return fit;
  }

 private:
  // Counts `samples` of work (one channel's frames fitted or measured) and looks at the stop
  // token once per kStopCheckSamples of it, so a stop is seen within milliseconds on any input.
  bool Stopping(std::int64_t samples) {
    if (stopped_) return true;
    work_ += samples;
    if (work_ < kStopCheckSamples) return false;
    work_ = 0;
    stopped_ = stop_.stop_requested();
    return stopped_;
  }

  // Makes `v` hold at least `n` elements, of which the first `keep` (at most v.size()) keep their
  // values; the others are whatever they were or zero. Memory is touched a piece at a time, looking
  // at the stop token between pieces: a noisy channel keys almost every frame, and its solve's
  // vectors are then hundreds of megabytes to fault in and to copy. Outgrowing its capacity, a
  // buffer is replaced: with nothing to keep, its memory is given back first (the peak is the new
  // buffer alone); else the kept elements are copied a piece at a time. A short buffer gets room
  // for the next insertion round's keys (at most twice as many, up to a key a frame), so that it
  // grows once rather than every round; a long one gets just its size, as the peak memory of a
  // noisy channel's fit (a key almost every frame) matters more. False when a stop was seen.
  template <class T>
  bool GrowTo(std::vector<T>& v, std::int64_t n, std::int64_t keep = 0) {
    const auto size = static_cast<std::size_t>(n);
    if (size <= v.size()) return true;
    if (size > v.capacity()) {
      const std::size_t capacity =
          size <= kGrowthPiece ? std::max(size, std::min(2 * size, frame_count_)) : size;
      const auto kept = static_cast<std::size_t>(keep);
      if (kept == 0) {
        std::vector<T>().swap(v);
        v.reserve(capacity);
      } else {
        std::vector<T> grown;
        grown.reserve(capacity);
        for (std::size_t done = 0; done < kept;) {
          const std::size_t next = std::min(kept, done + kGrowthPiece);
          grown.insert(grown.end(), v.begin() + static_cast<std::ptrdiff_t>(done),
                       v.begin() + static_cast<std::ptrdiff_t>(next));
          if (Stopping(static_cast<std::int64_t>(next - done))) return false;
          done = next;
        }
        v.swap(grown);
      }
    }
    for (std::size_t done = v.size(); done < size;) {
      const std::size_t next = std::min(size, done + kGrowthPiece);
      v.resize(next);
      if (Stopping(static_cast<std::int64_t>(next - done))) return false;
      done = next;
    }
    return true;
  }

  // ---- least squares ---------------------------------------------------------------------------

  // Fits the values and slopes of keys [first, last] of `run` to channel `s` by least squares, the
  // other keys fixed: the key frames themselves, the interior frames of every segment that touches
  // a free key, and the ridge. `weights` (optional) weighs each frame, indexed from
  // weights_origin. Block-tridiagonal elimination over the free keys.
  //
  // `kept` (a whole channel's unweighted solve, first == 0, last == run.count - 1, more than
  // kWindowKeys keys, right after another such solve of the same channel, by FitAll()): the first
  // `kept` keys' eliminated blocks (eliminated_, rhs_, upper_) are those the previous solve left,
  // and are what this one would compute (KeptKeys()); the elimination resumes after them.
  void Solve(std::span<const double> s, const KeyRun& run, int first, int last,
             const double* weights = nullptr, std::int64_t weights_origin = 0, int kept = 0) {
    const int n = last - first + 1;
    long_solve_keys_ = 0;
    if (first == 1 && last == 2 && run.count == 4) {
      SolveInnerPair(s, run, weights, weights_origin);
      return;
    }
    if (n <= kWindowKeys) {
      // A removal window's solve (or a short channel's): its blocks on the stack, only the n
      // couplings in use zeroed (zeroing whole arrays costs a string instruction's start-up, more
      // than the solve). The caller counts the window's work for the stop token.
      std::array<Mat2, kWindowKeys> diag, upper, eliminated;
      std::array<Vec2, kWindowKeys> rhs;
      for (int i = 0; i < n; ++i) upper[i] = {0.0, 0.0, 0.0, 0.0};
      SolveIn({diag.data(), upper.data(), rhs.data(), eliminated.data()}, s, run, first, last,
              weights, weights_origin);
      return;
    }
    // Longer: FitAll()'s solve of a whole channel (first == 0, last == run.count - 1, no
    // weights), the only solve of more than a window's keys.
    SolveRun(s, run, kept);
  }

  // The sums of one segment of `length` >= 2 frames starting at `data` that the rows of its free
  // keys need (FreeEnds): its moments into `moment` (moment[0..1] of the start key's columns,
  // moment[2..3] of the end key's) and its Gram sums, returned (weighted by `segment_weights`,
  // indexed like `data`, when given). The returned sums stay valid until the next call.
  template <FreeEnds kEnds>
  const double* SegmentSums(const double* data, std::int64_t length,
                            const double* segment_weights, double* moment) {
    const BasisColumns& basis = basis_.Get(length);
    const bool short_segment = length - 1 <= kShortInterior;
    if (segment_weights == nullptr) {
      if (short_segment) {
        ShortDataMoments<kEnds>(data, length, moment);
      } else if (kEnds == FreeEnds::kBoth) {
        DataMoments(data, basis, length, moment);
      } else if (kEnds == FreeEnds::kStartOnly) {
        DataMomentPair(data, basis.column[0].data(), basis.column[1].data(), length, moment);
      } else {
        DataMomentPair(data, basis.column[2].data(), basis.column[3].data(), length, moment + 2);
      }
      return grams_.Get(length).data();
    }
    double* sums = weighted_gram_.data();
    if (short_segment) {
      ShortWeightedSums<kEnds>(data, segment_weights, basis, length, moment, sums);
    } else if (kEnds == FreeEnds::kBoth) {
      WeightedSums(data, segment_weights, basis, length, moment, sums);
    } else if (kEnds == FreeEnds::kStartOnly) {
      WeightedSumsStart(data, segment_weights, basis, length, moment, sums);
    } else {
      WeightedSumsEnd(data, segment_weights, basis, length, moment, sums);
    }
    return sums;
  }

  // Solve() of the usual removal window: four keys, the outer two fixed, the inner two free. The
  // same operations on the same values, in the same order, as SolveIn() takes for it (its key
  // terms, then segments 0, 1 and 2 each followed by the elimination of the key it completes,
  // then back substitution), written out without its loops and index bookkeeping: most removal
  // trials and Lawson rounds are this solve.
  void SolveInnerPair(std::span<const double> s, const KeyRun& run, const double* weights,
                      std::int64_t weights_origin) {
    const std::int64_t* f = run.frames;
    // A free key's own terms: its sample (weighted) and the ridge, added to zero blocks.
    auto key_terms = [&](std::int64_t frame, Mat2& diag, Vec2& rhs) {
      KeyTerms(s, frame, (weights ? weights[frame - weights_origin] : 1.0) + kRidge, diag, rhs);
    };
    auto segment_weights = [&](std::int64_t fa) {
      return weights ? weights + (fa - weights_origin) : nullptr;
    };
    Mat2 d1, d2;
    Vec2 r1, r2;
    Mat2 u1 = {0.0, 0.0, 0.0, 0.0};
    std::array<double, 4> moment;
    // Key 1's own terms and segment 0 (key 0 fixed, key 1 free): unweighted, they depend only
    // on the channel, frames 0 and 1 and key 0, which a candidate's slide trials share; the
    // blocks of the last such solve are kept and reused when those are the same (to the bit).
    PairHead& head = pair_head_;
    const bool reuse = weights == nullptr && head.samples == s.data() && head.f0 == f[0] &&
                       head.f1 == f[1] && SameBits(head.v0, run.values[0]) &&
                       SameBits(head.m0, run.slopes[0]);
    if (reuse) {
      d1 = head.d1;
      r1 = head.r1;
    } else {
      key_terms(f[1], d1, r1);
      if (f[1] - f[0] >= 2) {
        const double* g = SegmentSums<FreeEnds::kEndOnly>(s.data() + f[0], f[1] - f[0],
                                                           segment_weights(f[0]), moment.data());
        const double v = run.values[0];
        const double m = run.slopes[0];
        for (int r = 2; r < 4; ++r) moment[r] -= g[4 * r] * v + g[4 * r + 1] * m;
        d1 = {d1[0] + g[10], d1[1] + g[11], d1[2] + g[14], d1[3] + g[15]};
        r1 = {r1[0] + moment[2], r1[1] + moment[3]};
      }
      if (weights == nullptr) {
        head = {s.data(), f[0], f[1], run.values[0], run.slopes[0], d1, r1};
      }
    }
    key_terms(f[2], d2, r2);
    // Segment 1: both keys free; then key 1 is complete.
    if (f[2] - f[1] >= 2) {
      const double* g = SegmentSums<FreeEnds::kBoth>(s.data() + f[1], f[2] - f[1],
                                                      segment_weights(f[1]), moment.data());
      d1 = {d1[0] + g[0], d1[1] + g[1], d1[2] + g[4], d1[3] + g[5]};
      r1 = {r1[0] + moment[0], r1[1] + moment[1]};
      d2 = {d2[0] + g[10], d2[1] + g[11], d2[2] + g[14], d2[3] + g[15]};
      r2 = {r2[0] + moment[2], r2[1] + moment[3]};
      u1 = {u1[0] + g[2], u1[1] + g[3], u1[2] + g[6], u1[3] + g[7]};
    }
    const Mat2 inverse1 = Inverse(d1);
    const Mat2 e1 = Multiply(inverse1, u1);
    r1 = Apply(inverse1, r1);
    // Segment 2: key 2 free, key 3 fixed; then key 2 is complete.
    if (f[3] - f[2] >= 2) {
      const double* g = SegmentSums<FreeEnds::kStartOnly>(s.data() + f[2], f[3] - f[2],
                                                           segment_weights(f[2]), moment.data());
      const double v = run.values[3];
      const double m = run.slopes[3];
      for (int r = 0; r < 2; ++r) moment[r] -= g[4 * r + 2] * v + g[4 * r + 3] * m;
      d2 = {d2[0] + g[0], d2[1] + g[1], d2[2] + g[4], d2[3] + g[5]};
      r2 = {r2[0] + moment[0], r2[1] + moment[1]};
    }
    SubtractCoupling(u1, e1, r1, d2, r2);
    const Vec2 x2 = Apply(Inverse(d2), r2);
    run.values[2] = x2[0];
    run.slopes[2] = x2[1];
    const Vec2 next = Apply(e1, x2);
    run.values[1] = r1[0] - next[0];
    run.slopes[1] = r1[1] - next[1];
  }

  // The blocks of one solve, per free key: its diagonal block and right-hand side (set from the
  // key's own terms first), the block coupling it to the next free key (zero to start with), and
  // the eliminated coupling.
  struct SolveBlocks {
    Mat2* diag;
    Mat2* upper;
    Vec2* rhs;
    Mat2* eliminated;
  };

  // Solve() of a window (at most kWindowKeys keys, n = last - first + 1 of them free) on
  // `blocks`, their couplings zero to start with.
  void SolveIn(SolveBlocks blocks, std::span<const double> s, const KeyRun& run, int first,
               int last, const double* weights, std::int64_t weights_origin) {
    const int n = last - first + 1;
    Mat2* diag = blocks.diag;
    Mat2* upper = blocks.upper;
    Vec2* rhs = blocks.rhs;
    Mat2* eliminated = blocks.eliminated;
    auto weight = [&](std::int64_t f) { return weights ? weights[f - weights_origin] : 1.0; };
    for (int i = 0; i < n; ++i) {
      const std::int64_t f = run.frames[first + i];
      KeyTerms(s, f, weight(f) + kRidge, diag[i], rhs[i]);
    }
    // Segment j's sums added to the blocks of its free keys: kEnds says which are free (only
    // the first and last segments of a solve can have a fixed end).
    auto add_segment = [&]<FreeEnds kEnds>(int j, std::int64_t fa, std::int64_t length) {
      constexpr bool a_free = kEnds != FreeEnds::kEndOnly;
      constexpr bool b_free = kEnds != FreeEnds::kStartOnly;
      std::array<double, 4> moment;
      const double* gram = SegmentSums<kEnds>(
          s.data() + fa, length, weights ? weights + (fa - weights_origin) : nullptr,
          moment.data());
      // What a fixed end contributes comes off the right-hand side: the moments of
      // (data - c . x_fixed) are the data's moments minus gram x_fixed (in the free key's rows,
      // the only ones used).
      if (!a_free) {
        const double v = run.values[j];
        const double m = run.slopes[j];
        for (int r = 2; r < 4; ++r) moment[r] -= gram[4 * r] * v + gram[4 * r + 1] * m;
      }
      if (!b_free) {
        const double v = run.values[j + 1];
        const double m = run.slopes[j + 1];
        for (int r = 0; r < 2; ++r) moment[r] -= gram[4 * r + 2] * v + gram[4 * r + 3] * m;
      }
      if (a_free) {
        const int ia = j - first;
        diag[ia] = {diag[ia][0] + gram[0], diag[ia][1] + gram[1], diag[ia][2] + gram[4],
                    diag[ia][3] + gram[5]};
        rhs[ia] = {rhs[ia][0] + moment[0], rhs[ia][1] + moment[1]};
      }
      if (b_free) {
        const int ib = j + 1 - first;
        diag[ib] = {diag[ib][0] + gram[10], diag[ib][1] + gram[11], diag[ib][2] + gram[14],
                    diag[ib][3] + gram[15]};
        rhs[ib] = {rhs[ib][0] + moment[2], rhs[ib][1] + moment[3]};
      }
      if (a_free && b_free) {
        const int ia = j - first;
        upper[ia] = {upper[ia][0] + gram[2], upper[ia][1] + gram[3],
                     upper[ia][2] + gram[6], upper[ia][3] + gram[7]};
      }
    };
    // Forward elimination of free key i (eliminated[i] = D'_i^-1 U_i, with D'_i = D_i - U_{i-1}^T
    // eliminated[i-1]) once every segment touching it has been added: done right after its last
    // segment, so that the next segments' sums can proceed while its divisions complete (the same
    // operations on the same values as eliminating after all segments).
    auto eliminate = [&](int i) __attribute__((always_inline)) {
      if (i > 0) SubtractCoupling(upper[i - 1], eliminated[i - 1], rhs[i - 1], diag[i], rhs[i]);
      const Mat2 inverse = Inverse(diag[i]);
      // The last key couples to nothing after it: its eliminated block is never read.
      if (i + 1 < n) eliminated[i] = Multiply(inverse, upper[i]);
      rhs[i] = Apply(inverse, rhs[i]);
    };
    const int seg_first = std::max(first - 1, 0);
    const int seg_last = std::min(last, run.count - 2);
    for (int j = seg_first; j <= seg_last; ++j) {
      const std::int64_t fa = run.frames[j];
      const std::int64_t length = run.frames[j + 1] - fa;
      if (length >= 2) {
        if (j < first) {
          add_segment.template operator()<FreeEnds::kEndOnly>(j, fa, length);
        } else if (j + 1 > last) {
          add_segment.template operator()<FreeEnds::kStartOnly>(j, fa, length);
        } else {
          add_segment.template operator()<FreeEnds::kBoth>(j, fa, length);
        }
      }
      if (j >= first) eliminate(j - first);  // key j's last segment
    }
    // The last key when it has no segment after it; then back substitution.
    for (int i = std::max(seg_last - first + 1, 0); i < n; ++i) eliminate(i);
    BackSubstitute(run, first, n, rhs, eliminated);
  }

  // Back substitution of the `n` free keys from `first` of `run`, eliminated into `rhs` and
  // `eliminated` (SolveIn(), SolveRun()).
  static void BackSubstitute(const KeyRun& run, int first, int n, const Vec2* rhs,
                             const Mat2* eliminated) {
    Vec2 x = rhs[n - 1];
    run.values[first + n - 1] = x[0];
    run.slopes[first + n - 1] = x[1];
    for (int i = n - 2; i >= 0; --i) {
      const Vec2 next = Apply(eliminated[i], x);
      x = {rhs[i][0] - next[0], rhs[i][1] - next[1]};
      run.values[first + i] = x[0];
      run.slopes[first + i] = x[1];
    }
  }

  // Solve() of every key of `run`, all free and unweighted (FitAll()'s solve of a channel), in
  // one pass over the keys: each key's blocks (its own terms, then the end-key sums of the
  // segment before it, then the start-key sums and the coupling of the segment after it) are
  // built in registers and the key eliminated at once. Those are the operations SolveIn() takes
  // for each of a window's keys (on zeroed blocks: the key's terms, its segments' sums, its
  // elimination), on the same values in the same order, so the same bits as solving the whole
  // channel that way; only the eliminated blocks, right-hand sides and couplings are stored
  // (eliminated_, rhs_, upper_).
  //
  // `kept`: the first `kept` keys' stored blocks are those the previous solve of this channel
  // left, and are what this one would compute (KeptKeys()): the elimination resumes after them.
  // A solve counts its keys and frames for the stop token (a whole noisy channel is millions of
  // keys); once a stop is seen it returns, its result not to be used.
  void SolveRun(std::span<const double> s, const KeyRun& run, int kept) {
    const int n = run.count;
    if (!GrowTo(eliminated_, n, kept) || !GrowTo(upper_, n, kept) || !GrowTo(rhs_, n, kept)) {
      return;
    }
    Mat2* eliminated = eliminated_.data();
    Mat2* upper = upper_.data();
    Vec2* rhs = rhs_.data();
    const double w = 1.0 + kRidge;  // an unweighted key's own weight, with the ridge
    // The end-key sums of the segment before key i (zero-length segments add none).
    bool carry = false;
    std::array<double, 4> carry_gram;
    Vec2 carry_moment;
    if (kept > 0) {
      const std::int64_t fa = run.frames[kept - 1];
      const std::int64_t length = run.frames[kept] - fa;
      if (length >= 2) {
        std::array<double, 4> moment;
        const double* g =
            SegmentSums<FreeEnds::kEndOnly>(s.data() + fa, length, nullptr, moment.data());
        carry = true;
        carry_gram = {g[10], g[11], g[14], g[15]};
        carry_moment = {moment[2], moment[3]};
      }
    }
    std::int64_t pending = 0;  // work not yet counted for the stop token
    for (int i = kept; i < n; ++i) {
      const std::int64_t f = run.frames[i];
      Mat2 d;
      Vec2 r;
      KeyTerms(s, f, w, d, r);
      if (carry) {
        d = {d[0] + carry_gram[0], d[1] + carry_gram[1], d[2] + carry_gram[2],
             d[3] + carry_gram[3]};
        r = {r[0] + carry_moment[0], r[1] + carry_moment[1]};
      }
      Mat2 u = {0.0, 0.0, 0.0, 0.0};
      carry = false;
      pending += 1;
      if (i + 1 < n) {
        const std::int64_t length = run.frames[i + 1] - f;
        pending += length;
        if (length >= 2) {
          std::array<double, 4> moment;
          const double* g =
              SegmentSums<FreeEnds::kBoth>(s.data() + f, length, nullptr, moment.data());
          d = {d[0] + g[0], d[1] + g[1], d[2] + g[4], d[3] + g[5]};
          r = {r[0] + moment[0], r[1] + moment[1]};
          u = {u[0] + g[2], u[1] + g[3], u[2] + g[6], u[3] + g[7]};
          carry = true;
          carry_gram = {g[10], g[11], g[14], g[15]};
          carry_moment = {moment[2], moment[3]};
        }
      }
      if (i > 0) SubtractCoupling(upper[i - 1], eliminated[i - 1], rhs[i - 1], d, r);
      const Mat2 inverse = Inverse(d);
      upper[i] = u;
      // The last key couples to nothing after it: its eliminated block is never read.
      if (i + 1 < n) eliminated[i] = Multiply(inverse, u);
      rhs[i] = Apply(inverse, r);
      if (pending >= kStopCountPiece) {
        if (Stopping(pending)) return;
        pending = 0;
      }
    }
    if (Stopping(pending)) return;
    BackSubstitute(run, 0, n, rhs, eliminated);
    long_solve_keys_ = n;
  }

  // ---- errors ----------------------------------------------------------------------------------

  // `limit`: stop at the first frame whose error exceeds it (the caller only needs to know).
  // The largest interior error of segment j of `run` (exact up to `limit`).
  double SegmentMax(std::span<const double> s, const KeyRun& run, int j,
                    double limit = std::numeric_limits<double>::infinity()) {
    const std::int64_t fa = run.frames[j];
    const std::int64_t length = run.frames[j + 1] - fa;
    if (length < 2) return 0.0;
    const std::array<double, 4> x = {run.values[j], run.slopes[j], run.values[j + 1],
                                     run.slopes[j + 1]};
    const BasisColumns& basis = basis_.Get(length);
    if (length - 1 <= kShortInterior) {
      return ShortMaxError(s.data() + fa, basis, length, x.data());
    }
    return MaxError(s.data() + fa, basis, length, x.data(), limit);
  }

  // The interior frame of segment j where the error is largest.
  std::int64_t WorstFrame(std::span<const double> s, const KeyRun& run, int j) {
    const std::int64_t fa = run.frames[j];
    const std::int64_t length = run.frames[j + 1] - fa;
    std::int64_t at = fa + length / 2;
    double worst = -1.0;
    ForEachResidual(s, run, j, [&](std::int64_t f, double residual) {
      if (f != fa && f != fa + length && std::abs(residual) > worst) {
        worst = std::abs(residual);
        at = f;
      }
    });
    return at;
  }

  // Worst error, relative to the bound, over the keys [key_first, key_last] and the interior of
  // the segments between them, for channel c of `run`; stops early once it exceeds `limit`.
  // `worst_key` (optional) receives the window position of the worst key frame or the start of
  // the worst segment.
  // Out of line: inlined into the removal loop, with the rest of that loop around it, GCC kept
  // its running maximum in memory, a store and a load per key (paired runs of spec8_bench
  // --only=tolerance: Bandai 83.4-85.4 -> 81.5-82.1 ms per M samples out of line; CMU within its
  // spread). Also tried, and no faster: FitWindow() out of line as well; the keys' maximum taken
  // as a tree (Bandai 88-90).
  [[gnu::noinline]] double WindowRatio(std::size_t c, const KeyRun& run, int key_first,
                                       int key_last,
                                       double limit = std::numeric_limits<double>::infinity(),
                                       int* worst_key = nullptr) {
    const std::span<const double> s = channels_[c];
    const double error_limit = limit * bounds_[c];
    double worst = 0.0;
    int where = key_first;
    for (int i = key_first; i <= key_last; ++i) {
      const double e = std::abs(run.values[i] - s[run.frames[i]]);
      if (e > worst) {
        worst = e;
        where = i;
      }
    }
    for (int j = key_first; j < key_last && worst <= error_limit; ++j) {
      const double e = SegmentMax(s, run, j, error_limit);
      if (e > worst) {
        worst = e;
        where = j;
      }
    }
    if (worst_key != nullptr) *worst_key = where;
    return worst / bounds_[c];
  }

  // ---- 1. insertion -----------------------------------------------------------------------------

  void Insert(SplineFit& fit) {
    const auto last = static_cast<std::int64_t>(frame_count_ - 1);
    if (!options_.initial_frames.empty()) {
      fit.frames.assign(options_.initial_frames.begin(), options_.initial_frames.end());
    } else {
      const std::int64_t spacing = options_.initial_spacing_frames;
      fit.frames.reserve(static_cast<std::size_t>(last / spacing) + 2);
      for (std::int64_t f = 0; f < last; f += spacing) fit.frames.push_back(f);
      fit.frames.push_back(last);
    }
    std::vector<std::int64_t> next;
    int kept = 0;
    for (int round = 0; round < kMaxInsertionRounds; ++round) {
      const int count = static_cast<int>(fit.frames.size());
      FitAll(fit, kept);
      if (stopped_) return;
      next.clear();
      next.reserve(2 * static_cast<std::size_t>(count));  // a key at most per segment and key
      bool inserted = false;
      std::int64_t pending = 0;  // work not yet counted for the stop token
      for (int j = 0; j + 1 < count; ++j) {
        next.push_back(fit.frames[j]);
        const std::int64_t length = fit.frames[j + 1] - fit.frames[j];
        pending += length * static_cast<std::int64_t>(channels_.size());
        if (pending >= kStopCountPiece) {
          if (Stopping(pending)) return;
          pending = 0;
        }
        if (length < 2) continue;
        // The channel most over its bound decides where the new key goes: at its worst frame,
        // or mid-segment when it is a key frame that is over (it is its segments' problem too).
        double ratio = 0.0;
        double worst_interior = 0.0;  // the interior ratio of the channel most over
        std::size_t worst_channel = 0;
        for (std::size_t c = 0; c < channels_.size(); ++c) {
          const KeyRun run = RunOf(fit, c);
          const double interior = SegmentMax(channels_[c], run, j) / bounds_[c];
          const double r = std::max({interior, KeyRatio(fit, c, j), KeyRatio(fit, c, j + 1)});
          if (r > ratio) {
            ratio = r;
            worst_interior = interior;
            worst_channel = c;
          }
        }
        if (ratio > 1.0) {
          const std::span<const double> s = channels_[worst_channel];
          const KeyRun run = RunOf(fit, worst_channel);
          const std::int64_t frame = worst_interior >= ratio ? WorstFrame(s, run, j)
                                                             : fit.frames[j] + length / 2;
          next.push_back(frame);
          inserted = true;
        }
      }
      if (Stopping(pending)) return;  // the round's last piece of work counts too
      next.push_back(fit.frames.back());
      kept = KeptKeys(fit.frames, next);
      fit.frames.swap(next);
      if (!inserted) return;
    }
    FitAll(fit, kept);
  }

  // The keys whose elimination the next FitAll() can keep from the last one, with key frames
  // going from `old_frames` to `new_frames`: those before the key ahead of the first frame that
  // differs (keys 0 .. p-2 when frames 0 .. p-1 agree: their segments and every block they touch
  // are the same). Only a lone channel's solve leaves its blocks behind, and only a completed
  // long solve (long_solve_keys_).
  int KeptKeys(std::span<const std::int64_t> old_frames,
               std::span<const std::int64_t> new_frames) const {
    if (channels_.size() != 1 || long_solve_keys_ != static_cast<int>(old_frames.size())) return 0;
    std::size_t p = 0;
    while (p < old_frames.size() && p < new_frames.size() && old_frames[p] == new_frames[p]) ++p;
    return p >= 2 ? static_cast<int>(p) - 1 : 0;
  }

  double KeyRatio(const SplineFit& fit, std::size_t c, int i) const {
    return std::abs(fit.values[c][i] - channels_[c][fit.frames[i]]) / bounds_[c];
  }

  // `kept`: for a lone channel, how many leading keys the previous FitAll()'s forward
  // elimination, still in the solve's blocks, has eliminated exactly as this one would (their
  // segments unchanged; see Solve()).
  void FitAll(SplineFit& fit, int kept = 0) {
    const int count = static_cast<int>(fit.frames.size());
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      if (Stopping(static_cast<std::int64_t>(frame_count_))) return;
      const auto keys = static_cast<std::int64_t>(fit.frames.size());
      // Every value and slope is written by the solve.
      if (!GrowTo(fit.values[c], keys) || !GrowTo(fit.slopes[c], keys)) return;
      fit.values[c].resize(static_cast<std::size_t>(keys));
      fit.slopes[c].resize(static_cast<std::size_t>(keys));
      Solve(channels_[c], RunOf(fit, c), 0, count - 1, nullptr, 0, kept);
    }
  }

  static KeyRun RunOf(SplineFit& fit, std::size_t c) {
    return {fit.frames.data(), fit.values[c].data(), fit.slopes[c].data(),
            static_cast<int>(fit.frames.size())};
  }

  // ---- 2. removal -------------------------------------------------------------------------------

  // A window of keys: up to kWindowKeys frames, per channel values and slopes.
  struct Window {
    std::array<std::int64_t, kWindowKeys> frames{};
    std::vector<std::array<double, kWindowKeys>> values, slopes;
    int count = 0;
    int free_first = 0;
    int free_last = 0;

    KeyRun Run(std::size_t c) {
      return {frames.data(), values[c].data(), slopes[c].data(), count};
    }

    // Assignment from a window of as many channels, element by element (a vector's assignment
    // goes through a library copy per channel: a removal copies windows for most trials).
    void CopyFrom(const Window& other) {
      frames = other.frames;
      for (std::size_t c = 0; c < values.size(); ++c) {
        values[c] = other.values[c];
        slopes[c] = other.slopes[c];
      }
      count = other.count;
      free_first = other.free_first;
      free_last = other.free_last;
    }
  };

  // Least-squares fit of the free keys of every channel of `w`; returns the worst error relative
  // to the bound over the window and all channels, exact up to `limit` (beyond it, some value
  // above it).
  template <bool kLone>
  double FitWindow(Window& w, double limit, int* worst_key = nullptr) {
    double worst = 0.0;
    const std::size_t c_count = kLone ? 1 : channels_.size();
    for (std::size_t c = 0; c < c_count && worst <= limit; ++c) {
      KeyRun run = w.Run(c);
      Solve(channels_[c], run, w.free_first, w.free_last);
      int where = 0;
      const double ratio = WindowRatio(c, run, 0, w.count - 1, limit, &where);
      if (ratio > worst) {
        worst = ratio;
        if (worst_key != nullptr) *worst_key = where;
      }
    }
    return worst;
  }

  // Lawson's iteration on the channels of `w` that are over their bound: each round multiplies
  // every frame's weight by its error and refits, so the fit leans towards the minimax one. True
  // once every channel is within its bound; false when one stays over, or once a stop was seen
  // (each round counts the window's frames). Precondition: `w` is over the bound (FitWindow()).
  bool LawsonWindow(Window& w) {
    const std::int64_t origin = w.frames[0];
    const std::int64_t span = w.frames[w.count - 1] - origin + 1;
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      const std::span<const double> s = channels_[c];
      KeyRun run = w.Run(c);
      // Only whether each ratio is over 1 matters: the scans may stop there. A lone channel is
      // over (its window missed the bound: the caller's trial).
      double ratio = channels_.size() == 1 ? kOver : WindowRatio(c, run, 0, w.count - 1, 1.0);
      lawson_.assign(static_cast<std::size_t>(span), 1.0);
      for (int round = 0; round < options_.lawson_iterations && ratio > 1.0; ++round) {
        // A round reweights, refits and measures the window's frames: up to 100 rounds on a
        // window of thousands of frames, so each one counts for the stop token.
        if (Stopping(span)) return false;
        const double total = Reweight(s, run, 1e-3 * bounds_[c], origin);
        const double scale = static_cast<double>(span) / total;
        for (double& weight : lawson_) weight *= scale;
        Solve(s, run, w.free_first, w.free_last, lawson_.data(), origin);
        ratio = WindowRatio(c, run, 0, w.count - 1, 1.0);
      }
      if (ratio > 1.0) return false;
    }
    return true;
  }

  // Multiplies each frame's Lawson weight (lawson_, from `origin`) by its |curve - sample| +
  // floor over the frames of `run`, which cover lawson_; returns the new weights' sum, added in
  // frame order.
  double Reweight(std::span<const double> s, const KeyRun& run, double floor,
                  std::int64_t origin) {
    double total = 0.0;
    auto at_key = [&](int i) {
      const std::int64_t f = run.frames[i];
      lawson_[f - origin] *= std::abs(run.values[i] - s[f]) + floor;
      total += lawson_[f - origin];
    };
    for (int j = 0; j + 1 < run.count; ++j) {
      at_key(j);
      const std::int64_t fa = run.frames[j];
      const std::int64_t length = run.frames[j + 1] - fa;
      if (length >= 2) {
        const std::array<double, 4> x = {run.values[j], run.slopes[j], run.values[j + 1],
                                         run.slopes[j + 1]};
        const BasisColumns& basis = basis_.Get(length);
        double* weights = lawson_.data() + (fa - origin);
        if (length - 1 <= kShortInterior) {
          total = ShortScaleByResiduals(s.data() + fa, basis, length, x.data(), floor, weights,
                                        total);
        } else {
          total = ScaleByResiduals(s.data() + fa, basis, length, x.data(), floor, weights, total);
        }
      }
    }
    at_key(run.count - 1);
    return total;
  }

  // Calls fn(frame, curve - sample) for the frames [a, b) of segment j of `run`, and b too when
  // it is the run's last segment.
  template <typename Fn>
  void ForEachResidual(std::span<const double> s, const KeyRun& run, int j, Fn fn) {
    const std::int64_t fa = run.frames[j];
    const std::int64_t length = run.frames[j + 1] - fa;
    const BasisColumns& basis = basis_.Get(length);
    fn(fa, run.values[j] - s[fa]);
    for (std::int64_t k = 1; k < length; ++k) {
      const double y = (basis.column[0][k] * run.values[j] + basis.column[1][k] * run.slopes[j]) +
                       (basis.column[2][k] * run.values[j + 1] +
                        basis.column[3][k] * run.slopes[j + 1]);
      fn(fa + k, y - s[fa + k]);
    }
    if (j + 2 == run.count) fn(fa + length, run.values[j + 1] - s[fa + length]);
  }

  void Remove(SplineFit& fit) {
    if (channels_.size() == 1) {
      RemoveKeys<true>(fit);
    } else {
      RemoveKeys<false>(fit);
    }
  }

  // Remove() of a lone channel (kLone: its loops over channels known to take one) or a group.
  template <bool kLone>
  void RemoveKeys(SplineFit& fit) {
    const std::size_t c_count = kLone ? 1 : channels_.size();
    const int count = static_cast<int>(fit.frames.size());
    if (count <= 2) return;
    SplineFit out;
    out.values.resize(c_count);
    out.slopes.resize(c_count);
    // At most every key is kept: room for all of them up front, no regrowing.
    const auto capacity = static_cast<std::size_t>(count);
    out.frames.reserve(capacity);
    for (std::size_t c = 0; c < c_count; ++c) {
      out.values[c].reserve(capacity);
      out.slopes[c].reserve(capacity);
    }
    auto push = [&](int i) {
      out.frames.push_back(fit.frames[i]);
      for (std::size_t c = 0; c < c_count; ++c) {
        out.values[c].push_back(fit.values[c][i]);
        out.slopes[c].push_back(fit.slopes[c][i]);
      }
    };
    push(0);
    Window trial;
    trial.values.resize(c_count);
    trial.slopes.resize(c_count);
    Window base = trial;
    Window miss = trial;
    for (int i = 1; i + 1 < count; ++i) {
      // Keys around the candidate: up to two accepted ones before, two remaining after.
      const int before = std::min<int>(kWindowSide, static_cast<int>(out.frames.size()));
      const int after = std::min(kWindowSide, count - 1 - i);
      base.count = before + after;
      for (int k = 0; k < before; ++k) {
        const std::size_t o = out.frames.size() - before + k;
        base.frames[k] = out.frames[o];
        for (std::size_t c = 0; c < c_count; ++c) {
          base.values[c][k] = out.values[c][o];
          base.slopes[c][k] = out.slopes[c][o];
        }
      }
      for (int k = 0; k < after; ++k) {
        base.frames[before + k] = fit.frames[i + 1 + k];
        for (std::size_t c = 0; c < c_count; ++c) {
          base.values[c][before + k] = fit.values[c][i + 1 + k];
          base.slopes[c][before + k] = fit.slopes[c][i + 1 + k];
        }
      }
      // The outermost keys stay fixed unless they are the clip's first or last.
      base.free_first = before == kWindowSide ? 1 : 0;
      base.free_last = after == kWindowSide ? base.count - 2 : base.count - 1;
      // The key after the removed one may slide, unless it is the clip's last.
      const bool can_slide = i + 1 < count - 1;
      // The merged segment runs from the last accepted key to the key after the removed one
      // (wherever it slides): no longer than kMaxMergedSegmentFrames, or the key stays.
      const std::int64_t merge_start = base.frames[before - 1];
      if (fit.frames[i + 1] - merge_start > kMaxMergedSegmentFrames) {
        push(i);
        continue;
      }
      // A slide back towards the removed key lengthens the segment after the slid key: no
      // further than the limit either, unless it was longer already (a start's).
      const std::int64_t after_limit =
          can_slide ? std::max(kMaxMergedSegmentFrames, fit.frames[i + 2] - fit.frames[i + 1])
                    : 0;
      // Every trial's merged segment, and so the curve of its Lawson rounds, is one cubic over
      // the frames from the last accepted key to the key after the removed one slid as far back
      // as it may go, and each of those frames is measured: when no cubic comes within the bound
      // there, no trial can fit and none is made; the key stays, as it would after them.
      // (Shared clips: 5.6 % of Bandai's candidates and 13 % of CMU's, whose trials all miss.)
      const std::int64_t common_end =
          can_slide ? std::max(fit.frames[i + 1] - options_.slide_frames, merge_start + 1)
                    : fit.frames[i + 1];
      if (common_end - merge_start >= 4 && NoCurveCanMerge(merge_start, common_end)) {
        push(i);
        continue;
      }
      // Samples of work of one trial (a fit and a measure of the window's frames, every channel):
      // a candidate may take up to slide_frames + 1 trials, each counted for the stop token.
      const std::int64_t trial_work = (base.frames[base.count - 1] - base.frames[0] + 1) *
                                      static_cast<std::int64_t>(c_count);

      // Least squares on the window as it is and with the next key slid; the first that fits is
      // taken, else Lawson's iteration on the closest miss.
      const double reach = options_.lawson_iterations > 0 ? kLawsonReach : 1.0;
      bool removed = false;
      double closest = std::numeric_limits<double>::infinity();
      // Slides go the way the unslid fit misses: towards the removed key when the worst error
      // lies before the key that slides (the merged segment is too long), away from it when it
      // lies after.
      int direction = 0;
      for (int d = 0; !removed && d <= (can_slide ? options_.slide_frames : 0); ++d) {
        const std::int64_t moved = base.frames[before] + direction * d;
        if (d > 0 && (moved <= base.frames[before - 1] || moved >= fit.frames[i + 2] ||
                      moved - merge_start > kMaxMergedSegmentFrames ||
                      fit.frames[i + 2] - moved > after_limit)) {
          break;
        }
        // A solve writes only the free keys, so after the first trial the fixed keys still hold
        // the base's values and only the frames need resetting.
        if (d == 0) {
          trial.CopyFrom(base);
        } else {
          trial.frames = base.frames;
        }
        trial.frames[before] = moved;
        if (Stopping(trial_work)) return;
        int worst_key = 0;
        const double ratio = FitWindow<kLone>(trial, reach, &worst_key);
        if (ratio <= 1.0) {
          removed = true;
          break;
        }
        if (ratio < closest) {
          closest = ratio;
          miss.CopyFrom(trial);
        }
        if (d == 0) direction = worst_key < before ? -1 : 1;
      }
      if (!removed && closest <= reach && options_.lawson_iterations > 0 && LawsonWindow(miss)) {
        trial.CopyFrom(miss);
        removed = true;
      }
      if (stopped_) return;  // LawsonWindow() gave up at a stop: the fit is not to be used
      if (!removed) {
        push(i);
        continue;
      }
      // Write the refitted window back: accepted keys in `out`, the remaining ones in `fit`.
      for (int k = 0; k < before; ++k) {
        const std::size_t o = out.frames.size() - before + k;
        for (std::size_t c = 0; c < c_count; ++c) {
          out.values[c][o] = trial.values[c][k];
          out.slopes[c][o] = trial.slopes[c][k];
        }
      }
      for (int k = 0; k < after; ++k) {
        fit.frames[i + 1 + k] = trial.frames[before + k];
        for (std::size_t c = 0; c < c_count; ++c) {
          fit.values[c][i + 1 + k] = trial.values[c][before + k];
          fit.slopes[c][i + 1 + k] = trial.slopes[c][before + k];
        }
      }
    }
    push(count - 1);
    fit = std::move(out);
  }

  // Whether some channel's samples over frames [a, e] (e - a >= 4) are proved beyond the reach
  // of any cubic within its bound (cubic_certificate.h). A proof's five samples a channel are
  // counted for the stop token: a stop seen here sets stopped_, and the removal returns at its
  // next trial's count or its end (a kept key costs about a hundred instructions, so a channel of
  // a million keys kept this way finishes in tens of milliseconds). Testing stopped_ in the loop
  // itself changed GCC's inlining elsewhere in the fit (callgrind, Bandai: 5 M more
  // instructions). Out of line: inlined into the removal loop, the proof cost that loop more
  // than its own instructions (9.3 M against 6.0 M).
  [[gnu::noinline]] bool NoCurveCanMerge(std::int64_t a, std::int64_t e) {
    for (std::size_t c = 0; c < channels_.size(); ++c) {
      if (reduce_internal::NoCubicWithin(channels_[c].data(), a, e, bounds_[c])) {
        Stopping(5 * static_cast<std::int64_t>(channels_.size()));
        return true;
      }
    }
    return false;
  }

  // ---- 3. verification ---------------------------------------------------------------------------

  // Keys every frame of any segment (or at any key) still over the bound, with the samples'
  // values and central differences, until every frame is within it. Nothing is over the bound
  // after insertion and removal unless keys sit on consecutive frames; this is the guarantee.
  void Repair(SplineFit& fit) {
    for (;;) {
      std::vector<std::pair<std::int64_t, std::int64_t>> bad;
      const int count = static_cast<int>(fit.frames.size());
      for (std::size_t c = 0; c < channels_.size(); ++c) {
        if (Stopping(static_cast<std::int64_t>(frame_count_))) return;
        const KeyRun run = RunOf(fit, c);
        for (int j = 0; j + 1 < count; ++j) {
          if (Stopping(fit.frames[j + 1] - fit.frames[j])) return;
          const bool over = SegmentMax(channels_[c], run, j, bounds_[c]) > bounds_[c] ||
                            KeyRatio(fit, c, j) > 1.0 || KeyRatio(fit, c, j + 1) > 1.0;
          if (over) bad.emplace_back(fit.frames[j], fit.frames[j + 1]);
        }
      }
      if (bad.empty()) return;
      std::vector<char> exact(frame_count_, 0);
      std::vector<char> keyed(frame_count_, 0);
      for (std::int64_t f : fit.frames) keyed[f] = 1;
      for (const auto& [a, b] : bad) {
        for (std::int64_t f = a; f <= b; ++f) exact[f] = keyed[f] = 1;
      }
      SplineFit repaired;
      repaired.values.resize(channels_.size());
      repaired.slopes.resize(channels_.size());
      std::size_t old = 0;
      for (std::size_t f = 0; f < frame_count_; ++f) {
        if (!keyed[f]) continue;
        while (old < fit.frames.size() && fit.frames[old] < static_cast<std::int64_t>(f)) ++old;
        const bool had = old < fit.frames.size() && fit.frames[old] == static_cast<std::int64_t>(f);
        repaired.frames.push_back(static_cast<std::int64_t>(f));
        for (std::size_t c = 0; c < channels_.size(); ++c) {
          const bool take_sample = exact[f] || !had;
          repaired.values[c].push_back(take_sample ? channels_[c][f] : fit.values[c][old]);
          repaired.slopes[c].push_back(take_sample ? CentralDifference(channels_[c], f)
                                                   : fit.slopes[c][old]);
        }
      }
      fit = std::move(repaired);
    }
  }

  std::span<const std::span<const double>> channels_;
  std::stop_token stop_;
  std::int64_t work_ = 0;   // samples of work since the last look at stop_
  bool stopped_ = false;    // a stop was seen: every phase returns at once
  std::vector<double> bounds_;
  ToleranceFitOptions options_;
  std::size_t frame_count_;
  // SolveInnerPair()'s blocks of key 1 after segment 0 in its last unweighted solve, and what
  // they depend on.
  struct PairHead {
    const double* samples = nullptr;
    std::int64_t f0 = -1;
    std::int64_t f1 = -1;
    double v0 = 0.0;
    double m0 = 0.0;
    Mat2 d1{};
    Vec2 r1{};
  };
  PairHead pair_head_;
  ScratchLease lease_;
  std::vector<Mat2>& upper_ = lease_.scratch().upper;
  std::vector<Mat2>& eliminated_ = lease_.scratch().eliminated;
  // Keys of this fit's last solve if it was a completed SolveRun() (its blocks are in upper_ ...),
  // else 0.
  int long_solve_keys_ = 0;
  std::vector<Vec2>& rhs_ = lease_.scratch().rhs;
  std::vector<double>& lawson_ = lease_.scratch().lawson;
  GramCache& grams_ = GramCache::ForThread();
  BasisSource basis_;
  std::array<double, 16> weighted_gram_;
};

}  // namespace

// This build's fit of valid inputs (FitWithinTolerance() checks them).
absl::StatusOr<SplineFit> Fit(std::span<const std::span<const double>> channels,
                              std::span<const double> max_errors,
                              const ToleranceFitOptions& options, std::stop_token stop) {
  return Fitter(channels, max_errors, options).Run(stop);
}

}  // namespace TEMPOKEY_TOLERANCE_FIT_BUILD

#if !defined(TEMPOKEY_TOLERANCE_FIT_BUILD_AVX2)
namespace tolerance_fit_baseline {
namespace {

BasisRowTable MakeBasisRowTable() {
  BasisRowTable table{};
  for (std::int64_t length = 1; length <= kRowLength; ++length) {
    std::array<std::array<double, kRowLength + 1>, 4> c;
    FillColumns(length, c[0].data(), c[1].data(), c[2].data(), c[3].data());
    for (std::int64_t k = 0; k <= length; ++k) {
      for (int r = 0; r < 4; ++r) {
        table[static_cast<std::size_t>(length)][static_cast<std::size_t>(4 * k + r)] =
            c[static_cast<std::size_t>(r)][static_cast<std::size_t>(k)];
      }
    }
  }
  return table;
}

}  // namespace

const BasisRowTable kBasisRowTable = MakeBasisRowTable();

}  // namespace tolerance_fit_baseline

namespace {

using tolerance_fit_baseline::Coefficients;
using tolerance_fit_baseline::SegmentValue;

// The index of the first of `samples` that is not finite, or samples.size(): in vector blocks
// (simd/block_scan.h), as every sample of every fitted channel is read here first.
TEMPOKEY_CLONES_AVX2 std::size_t FirstNonFinite(std::span<const double> samples) {
  return simd::FirstBeyondMagnitude(samples.data(), samples.size(),
                                    std::numeric_limits<double>::max());
}

absl::Status ValidateInputs(std::span<const std::span<const double>> channels,
                            std::span<const double> max_errors,
                            const ToleranceFitOptions& options) {
  if (channels.empty()) return absl::InvalidArgumentError("a fit needs at least one channel");
  if (max_errors.size() != channels.size()) {
    return absl::InvalidArgumentError(absl::StrCat("got ", max_errors.size(), " bounds for ",
                                                   channels.size(), " channels"));
  }
  const std::size_t n = channels.front().size();
  for (std::size_t c = 0; c < channels.size(); ++c) {
    if (channels[c].empty()) {
      return absl::InvalidArgumentError(absl::StrCat("channel ", c, " has no samples"));
    }
    if (channels[c].size() != n) {
      return absl::InvalidArgumentError(absl::StrCat("channel ", c, " has ", channels[c].size(),
                                                     " samples, channel 0 has ", n));
    }
    if (const std::size_t f = FirstNonFinite(channels[c]); f < n) {
      return absl::InvalidArgumentError(absl::StrCat(
          "channel ", c, ": sample ", f, " is ", std::isnan(channels[c][f]) ? "NaN" : "infinite"));
    }
    if (!(max_errors[c] > 0.0) || !std::isfinite(max_errors[c])) {
      return absl::InvalidArgumentError(absl::StrCat("channel ", c, ": the bound must be finite and > 0, got ", max_errors[c]));
    }
  }
  if (options.initial_spacing_frames < 1 || options.initial_spacing_frames > 1'000'000) {
    return absl::InvalidArgumentError(absl::StrCat(
        "initial_spacing_frames must be in [1, 1000000], got ", options.initial_spacing_frames));
  }
  if (!options.initial_frames.empty()) {
    const std::vector<std::int64_t>& frames = options.initial_frames;
    const auto last = static_cast<std::int64_t>(n) - 1;
    if (frames.front() != 0 || frames.back() != last) {
      return absl::InvalidArgumentError(absl::StrCat(
          "initial_frames must start at frame 0 and end at the last frame (", last, "), got ",
          frames.front(), " to ", frames.back()));
    }
    for (std::size_t k = 1; k < frames.size(); ++k) {
      if (frames[k] <= frames[k - 1]) {
        return absl::InvalidArgumentError(absl::StrCat(
            "initial_frames must be strictly increasing: key ", k, " at frame ", frames[k],
            " follows frame ", frames[k - 1]));
      }
    }
  }
  if (options.lawson_iterations < 0 || options.lawson_iterations > 100) {
    return absl::InvalidArgumentError(
        absl::StrCat("lawson_iterations must be in [0, 100], got ", options.lawson_iterations));
  }
  if (options.slide_frames < 0 || options.slide_frames > 1000) {
    return absl::InvalidArgumentError(
        absl::StrCat("slide_frames must be in [0, 1000], got ", options.slide_frames));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<SplineFit> FitWithinTolerance(std::span<const std::span<const double>> channels,
                                             std::span<const double> max_errors,
                                             const ToleranceFitOptions& options,
                                             std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateInputs(channels, max_errors, options));
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  if (options.fewest_keys) {
    // Both searches, the fewer keys kept (the usual fit's on a tie: its values and slopes are
    // least squares, which follow the motion): the search costs a hundred times the usual fit,
    // so the usual one's time hardly counts, and no input gets more keys for asking fewer.
    TEMPOKEY_ASSIGN_OR_RETURN(std::optional<SplineFit> searched,
                              reduce_internal::FitFewestKeys(channels, max_errors, stop));
    ToleranceFitOptions usual_options = options;
    usual_options.fewest_keys = false;
    TEMPOKEY_ASSIGN_OR_RETURN(SplineFit usual,
                              FitWithinTolerance(channels, max_errors, usual_options, stop));
    if (searched && searched->frames.size() < usual.frames.size()) return *std::move(searched);
    return usual;
  }
#if defined(TEMPOKEY_TOLERANCE_FIT_AVX2)
  if (simd::RunningInstructionSet() >= simd::InstructionSet::kAvx2) {
    return tolerance_fit_avx2::Fit(channels, max_errors, options, std::move(stop));
  }
#endif
  return tolerance_fit_baseline::Fit(channels, max_errors, options, std::move(stop));
}

std::vector<double> EvaluateSplineFit(const SplineFit& fit, std::size_t channel) {
  const std::int64_t last = fit.frames.back();
  std::vector<double> out(static_cast<std::size_t>(last) + 1);
  const std::vector<double>& v = fit.values[channel];
  const std::vector<double>& m = fit.slopes[channel];
  if (fit.frames.size() == 1) {
    out[0] = v[0];
    return out;
  }
  for (std::size_t j = 0; j + 1 < fit.frames.size(); ++j) {
    const std::int64_t fa = fit.frames[j];
    const std::int64_t length = fit.frames[j + 1] - fa;
    const auto l = static_cast<double>(length);
    for (std::int64_t k = 0; k < length; ++k) {
      out[fa + k] = SegmentValue(Coefficients(static_cast<double>(k) / l, l), v[j], m[j],
                                 v[j + 1], m[j + 1]);
    }
  }
  out[last] = v.back();
  return out;
}
#endif  // !defined(TEMPOKEY_TOLERANCE_FIT_BUILD_AVX2)

}  // namespace tempokey::core
