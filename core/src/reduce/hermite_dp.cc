// The paper's Hermite DP fit (SPEC 4.1); definitions in hermite_dp.h.
#include "tempokey/core/reduce/hermite_dp.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <stop_token>
#include <utility>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"
#include "simd.h"

namespace tempokey::core {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kStates = 81;
constexpr int kCenterState = 40;
constexpr int kMaxIterationsLimit = 1000;

// ---- initial keys -------------------------------------------------------------------------------

// Kernel taps of the smoothing between two looks at the stop token.
constexpr std::int64_t kSmoothStopCheckTaps = std::int64_t{1} << 20;

std::vector<double> GaussianSmooth(std::span<const double> samples, double sigma,
                                   const std::stop_token& stop = {}) {
  std::vector<double> out(samples.begin(), samples.end());
  if (sigma <= 0.0 || samples.size() < 2) return out;
  const int n = static_cast<int>(samples.size());
  const int radius = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  std::vector<double> kernel(static_cast<std::size_t>(radius) + 1);
  for (int k = 0; k <= radius; ++k) {
    kernel[k] = std::exp(-0.5 * (k * k) / (sigma * sigma));
  }
  // Wide kernels on long channels are seconds of work: look at the stop token every so many taps.
  const int frames_per_check =
      static_cast<int>(std::max<std::int64_t>(1, kSmoothStopCheckTaps / (2 * radius + 1)));
  for (int f = 0; f < n; ++f) {
    if (f % frames_per_check == 0 && stop.stop_requested()) return out;
    double sum = 0.0;
    double weight = 0.0;
    for (int k = -radius; k <= radius; ++k) {
      const int g = f + k;
      if (g < 0 || g >= n) continue;
      const double w = kernel[static_cast<std::size_t>(std::abs(k))];
      sum += w * samples[g];
      weight += w;
    }
    out[f] = sum / weight;
  }
  return out;
}

// Frames where `derivative` (defined on 1..n-2) crosses zero: an exact zero at f, or a sign
// change between f and f+1 (then whichever of the two is nearer zero).
std::vector<int> ZeroCrossings(const std::vector<double>& derivative) {
  std::vector<int> frames;
  const int n = static_cast<int>(derivative.size());
  for (int f = 1; f <= n - 2; ++f) {
    const double here = derivative[f];
    if (here == 0.0) {
      frames.push_back(f);
      continue;
    }
    if (f + 1 > n - 2) break;
    const double next = derivative[f + 1];
    if ((here < 0.0 && next > 0.0) || (here > 0.0 && next < 0.0)) {
      frames.push_back(std::abs(next) < std::abs(here) ? f + 1 : f);
    }
  }
  return frames;
}

// Central first and second differences of `smooth` on 1..n-2 (zero elsewhere).
std::pair<std::vector<double>, std::vector<double>> Differences(const std::vector<double>& smooth) {
  const std::size_t n = smooth.size();
  std::vector<double> first(n, 0.0);
  std::vector<double> second(n, 0.0);
  for (std::size_t f = 1; f + 1 < n; ++f) {
    first[f] = 0.5 * (smooth[f + 1] - smooth[f - 1]);
    second[f] = smooth[f + 1] - 2.0 * smooth[f] + smooth[f - 1];
  }
  return {std::move(first), std::move(second)};
}

// Slope per frame of `smooth` at `f`: central inside, one-sided at the ends.
double SlopeAt(const std::vector<double>& smooth, int f) {
  const int n = static_cast<int>(smooth.size());
  if (n < 2) return 0.0;
  if (f == 0) return smooth[1] - smooth[0];
  if (f == n - 1) return smooth[n - 1] - smooth[n - 2];
  return 0.5 * (smooth[f + 1] - smooth[f - 1]);
}

// ---- direct evaluation --------------------------------------------------------------------------

struct Basis {
  double h00, h10, h01, h11;
};

Basis HermiteBasis(double s) {
  const double s2 = s * s;
  const double s3 = s2 * s;
  return {2.0 * s3 - 3.0 * s2 + 1.0, s3 - 2.0 * s2 + s, -2.0 * s3 + 3.0 * s2, s3 - s2};
}

// x(s) - ax of a segment in power form, ((a s + b) s + c) s, from its Bezier x-controls
// ax, ax + atx / 3, bx - btx / 3, bx, measured from ax.
struct SegmentCubic {
  double a, b, c, span;

  static SegmentCubic Of(double length, double atx, double btx) {
    const double d1 = atx / 3.0;
    const double d2 = length - btx / 3.0;
    return {length - 3.0 * d2 + 3.0 * d1, 3.0 * d2 - 6.0 * d1, 3.0 * d1, length};
  }

  // The s of `target` (measured from ax), starting from a Newton step off `previous`, the
  // solution of a nearby target: frames advance by one, so it lands close.
  double SolveFrom(double previous, double target) const {
    const double slope = (3.0 * a * previous + 2.0 * b) * previous + c;
    const double guess =
        slope > 0.0 ? previous + (target - ((a * previous + b) * previous + c) * previous) / slope
                    : 0.5;
    return SolveMonotonicCubic(a, b, c, span, target, guess);
  }
};

// [first, end) frames of a segment from x = ax to x = bx.
std::pair<std::int64_t, std::int64_t> SegmentFrames(double ax, double bx, bool last) {
  const auto first = static_cast<std::int64_t>(std::ceil(ax));
  const auto end = last ? static_cast<std::int64_t>(std::floor(bx)) + 1
                        : static_cast<std::int64_t>(std::ceil(bx));
  return {first, end};
}

// ---- the optimized DP pass ----------------------------------------------------------------------

// The three values each component of a key offers in a pass.
struct KeyGrid {
  std::array<double, 3> x, y, tx, ty;
  bool x_fixed = false;
};

KeyGrid MakeGrid(const HermiteKey2D& key, const HermiteSteps& steps, bool x_fixed) {
  KeyGrid grid;
  for (int o = 0; o < 3; ++o) {
    const double d = static_cast<double>(o - 1);
    grid.x[o] = key.x + d * steps.x;
    grid.y[o] = key.y + d * steps.y;
    grid.tx[o] = key.tx + d * steps.tangent_x;
    grid.ty[o] = key.ty + d * steps.tangent_y;
  }
  grid.x_fixed = x_fixed;
  return grid;
}

// State s = sx * 9 + sy with sx = ix * 3 + itx and sy = iy * 3 + ity.
constexpr int XIndex(int sx) { return sx / 3; }
constexpr int TxIndex(int sx) { return sx % 3; }
// Offsets of the first and second component of a 9-state index (i * 3 + j).
constexpr std::array<double, 9> kOffsetHigh = {-1, -1, -1, 0, 0, 0, 1, 1, 1};
constexpr std::array<double, 9> kOffsetLow = {-1, 0, 1, -1, 0, 1, -1, 0, 1};

double TieTolerance(double m, double scale) {
  return kDpTieRelative * m + kDpTieAbsolute * scale;
}

// The chosen candidate of one target (the tie rule of hermite_dp.h) given the smallest, `m`:
// {value, state}, or {inf, -1} when none is finite.
std::pair<double, int> ChooseCandidate(const double* candidates, double m, double scale) {
  if (m == kInf) return {kInf, -1};
  const double threshold = m + TieTolerance(m, scale);
  if (candidates[kCenterState] <= threshold) return {candidates[kCenterState], kCenterState};
  for (int s = 0; s < kStates; ++s) {
    if (candidates[s] <= threshold) return {candidates[s], s};
  }
  return {m, -1};  // unreachable: m itself is <= threshold
}

// The error of one x-combination of a segment as a quadratic form in the y-offsets
// delta = (dy_a, dty_a, dy_b, dty_b) in {-1, 0, 1}^4:
//   E(delta) = e0 + g . delta + delta^T H delta,
// built from residuals at the grid centre so that no large sums cancel.
struct SegmentForm {
  double e0 = 0.0;
  std::array<double, 4> g{};
  std::array<std::array<double, 4>, 4> h{};
};

// The Hermite basis at every frame of one x-shape, shared by every segment and x-combination
// with that shape. A segment's x(s) depends only on its length L = bx - ax, the two tangent
// x-components and where the first frame falls (t0 = first frame - ax): the frames sit at
// t0, t0 + 1, ... <= L from the segment start. With integer steps most x-combinations of a pass,
// and many across segments and passes, share a shape, so each x(s) = frame solve runs once.
struct ShapeKey {
  double length, atx, btx, t0;
  friend bool operator==(const ShapeKey&, const ShapeKey&) = default;
  // One 64-bit word folded from the four values' bits (adding +0.0 first maps -0.0 to 0.0, which
  // == does not tell apart), then the table's own mixing: one combine instead of four.
  template <typename H>
  friend H AbslHashValue(H h, const ShapeKey& k) {
    const auto bits = [](double v) { return std::bit_cast<std::uint64_t>(v + 0.0); };
    const std::uint64_t folded = bits(k.length) * 0x9e3779b97f4a7c15u ^
                                 bits(k.atx) * 0xc2b2ae3d27d4eb4fu ^
                                 bits(k.btx) * 0x165667b19e3779f9u ^ bits(k.t0) * 0xd6e8feb86659fd93u;
    return H::combine(std::move(h), folded);
  }
};

// Per shape: `count` rows of the basis (h00, h10, h01, h11) at its frames, and the Gram sums
// sum h h^T (10 distinct entries) over all rows and over all but the last. A segment's frames are
// the shape's first `count` or `count - 1` targets (the last one is the segment end, which only
// the last segment of a channel takes), so those two sums are the only ones ever read.
struct ShapeEntry {
  // gram_but_last[10], gram_all[10], then `count` basis rows of kBasisStride.
  const double* record = nullptr;
  int count = 0;

  const double* gram_but_last() const { return record; }
  const double* gram_all() const { return record + 10; }
  const double* basis() const { return record + 20; }
};
constexpr int kBasisStride = 4;
constexpr int kGramSize = 10;

// Adds row `h` to the Gram sums `gram` (the order of additions is fixed: results are exact
// functions of the shape).
inline void AddToGram(const double* h, double* gram) {
  gram[0] += h[0] * h[0];
  gram[1] += h[0] * h[1];
  gram[2] += h[0] * h[2];
  gram[3] += h[0] * h[3];
  gram[4] += h[1] * h[1];
  gram[5] += h[1] * h[2];
  gram[6] += h[1] * h[3];
  gram[7] += h[2] * h[2];
  gram[8] += h[2] * h[3];
  gram[9] += h[3] * h[3];
}

// Shapes seen by one thread's fits. Entries are exact functions of their key, so a cache that
// lives across passes, channels and calls changes no result; it keeps its memory blocks when it
// is cleared, so a long fit does not fault fresh pages in over and over.
class ShapeCache {
 public:
  // The entry of `key`, computed on first use. Its pointers stay valid until the next trim.
  ShapeEntry Get(const ShapeKey& key) {
    auto [it, inserted] = entries_.try_emplace(key, ShapeEntry{});
    if (inserted) it->second = Compute(key);
    return it->second;
  }
  // Starts loading the hash slot of `key` (a hint; no effect on results).
  void Prefetch(const ShapeKey& key) const { entries_.prefetch(key); }
  // Bounds memory: past kMaxBlocks blocks (or a few oversized tables), forgets every entry and
  // reuses the blocks.
  void TrimIfLarge() {
    if (next_block_ > kMaxBlocks || oversized_.size() > kMaxOversized) {
      entries_.clear();
      oversized_.clear();
      next_block_ = 0;
      block_used_ = kBlockDoubles;
    }
  }

 private:
  static constexpr std::size_t kBlockDoubles = std::size_t{1} << 16;  // 512 KiB
  static constexpr std::size_t kMaxBlocks = 64;
  static constexpr std::size_t kMaxOversized = 4;

  // Room for `doubles` values that stays put until the next trim (entries point into it).
  double* Allocate(std::size_t doubles) {
    if (doubles > kBlockDoubles) {
      oversized_.push_back(std::make_unique_for_overwrite<double[]>(doubles));
      return oversized_.back().get();
    }
    if (block_used_ + doubles > kBlockDoubles) {
      if (next_block_ == blocks_.size()) {
        blocks_.push_back(std::make_unique_for_overwrite<double[]>(kBlockDoubles));
      }
      current_ = blocks_[next_block_++].get();
      block_used_ = 0;
    }
    double* out = current_ + block_used_;
    block_used_ += doubles;
    return out;
  }

  ShapeEntry Compute(const ShapeKey& key) {
    const double length = key.length;
    const SegmentCubic cubic = SegmentCubic::Of(length, key.atx, key.btx);
    // The slack keeps a target that rounds a hair above the segment end (s = 1) in the table.
    const double last = std::floor(length - key.t0 + 1e-9);
    const int count = last >= 0.0 ? static_cast<int>(last) + 1 : 0;
    // One contiguous record, Gram sums first: a lookup reads it front to back.
    static_assert(kGramSize == 10, "ShapeEntry's accessors assume 10 Gram sums");
    double* record = Allocate(2 * kGramSize + static_cast<std::size_t>(count) * kBasisStride);
    double* gram_but_last = record;
    double* gram_all = record + kGramSize;
    double* out = record + 2 * kGramSize;
    ShapeEntry entry;
    entry.record = record;
    entry.count = count;
    std::fill(gram_but_last, gram_all + kGramSize, 0.0);
    double s = 0.0;
    for (int k = 0; k < count; ++k) {
      s = cubic.SolveFrom(s, key.t0 + static_cast<double>(k));
      const Basis h = HermiteBasis(s);
      double* row = out + static_cast<std::size_t>(k) * kBasisStride;
      row[0] = h.h00;
      row[1] = h.h10;
      row[2] = h.h01;
      row[3] = h.h11;
      if (k + 1 < count) AddToGram(row, gram_but_last);
    }
    std::copy(gram_but_last, gram_but_last + kGramSize, gram_all);
    if (count > 0) AddToGram(out + static_cast<std::size_t>(count - 1) * kBasisStride, gram_all);
    return entry;
  }

  absl::flat_hash_map<ShapeKey, ShapeEntry> entries_;
  std::vector<std::unique_ptr<double[]>> blocks_;
  std::vector<std::unique_ptr<double[]>> oversized_;
  std::size_t next_block_ = 0;
  double* current_ = nullptr;
  std::size_t block_used_ = kBlockDoubles;
};

// The calling thread's shape cache.
ShapeCache& ThreadShapeCache() {
  thread_local ShapeCache cache;
  return cache;
}

// One x-combination's frames and their shape.
struct SegmentShape {
  ShapeEntry entry;
  std::int64_t first = 0;  // first frame
  int n = 0;               // frames, 0 for none
  double squares = 0.0;    // sum of (sample - y_ref)^2 over the frames
};

// b += (sample[k] - y_ref) * basis row k over k < n: the data terms of a segment's form. Inlined
// into BuildRow()'s clones; every component is summed in the same order by all of them, so they
// agree bit for bit.
[[gnu::always_inline]] inline void SumDataTerms(const double* sample, const double* basis, int n,
                                                double y_ref, double* b) {
  using V = double __attribute__((vector_size(32)));
  V sum = {0.0, 0.0, 0.0, 0.0};
  for (int k = 0; k < n; ++k) {
    V h;
    std::memcpy(&h, basis + k * kBasisStride, sizeof(V));
    sum += (sample[k] - y_ref) * h;
  }
  std::memcpy(b, &sum, sizeof(V));
}

// Sum of (sample[k] - y_ref)^2 over k < n.
double SumSquares(const double* sample, int n, double y_ref) {
  double squares = 0.0;
  for (int k = 0; k < n; ++k) {
    const double d = sample[k] - y_ref;
    squares += d * d;
  }
  return squares;
}

// Builds the form of one x-combination from its shape: the Gram matrix of the basis over the
// segment's frames comes from the cache, the data terms are summed here in coordinates relative
// to `y_ref` (a sample near the segment) so the quadratic form does not cancel large sums.
[[gnu::always_inline]] inline SegmentForm BuildSegmentForm(std::span<const double> samples,
                                                           const SegmentShape& shape, double y_ref,
                                                           const std::array<double, 4>& centre_y,
                                                           const HermiteSteps& steps) {
  SegmentForm form;
  const int n = shape.n;
  if (n <= 0) return form;
  const ShapeEntry& entry = shape.entry;
  if (n < entry.count - 1 || n > entry.count) {  // unreachable: see ShapeEntry
    form.e0 = kInf;
    return form;
  }
  alignas(32) std::array<double, 4> b;
  SumDataTerms(samples.data() + shape.first, entry.basis(), n, y_ref, b.data());
  const double c = shape.squares;
  const double* g = n == entry.count ? entry.gram_all() : entry.gram_but_last();
  const std::array<double, 4> w = {centre_y[0] - y_ref, centre_y[1], centre_y[2] - y_ref,
                                   centre_y[3]};
  // E(w + D delta) = e0 + 2 (G w - b)^T D delta + delta^T D G D delta.
  const std::array<double, 4> gw = {
      g[0] * w[0] + g[1] * w[1] + g[2] * w[2] + g[3] * w[3],
      g[1] * w[0] + g[4] * w[1] + g[5] * w[2] + g[6] * w[3],
      g[2] * w[0] + g[5] * w[1] + g[7] * w[2] + g[8] * w[3],
      g[3] * w[0] + g[6] * w[1] + g[8] * w[2] + g[9] * w[3]};
  double wgw = 0.0;
  double bw = 0.0;
  for (int k = 0; k < 4; ++k) {
    wgw += w[k] * gw[k];
    bw += b[k] * w[k];
  }
  form.e0 = std::max(0.0, wgw - 2.0 * bw + c);
  const std::array<double, 4> d = {steps.y, steps.tangent_y, steps.y, steps.tangent_y};
  const int index[4][4] = {{0, 1, 2, 3}, {1, 4, 5, 6}, {2, 5, 7, 8}, {3, 6, 8, 9}};
  for (int k = 0; k < 4; ++k) {
    form.g[k] = 2.0 * d[k] * (gw[k] - b[k]);
    for (int l = k; l < 4; ++l) form.h[k][l] = d[k] * d[l] * g[index[k][l]];
  }
  return form;
}

// The inner loop of the DP pass: one predecessor x-state's rows toward all nine target x-states
// at once, in 11 vectors of 8 lanes. Vector tx < 9 holds target states (tx, 0..7), vector 9 the
// states (0..7, 8) and vector 10 the state (8, 8) and seven unused lanes: every lane of a vector
// then takes key a's terms from one row (a broadcast) or from consecutive rows (a load). For each
// of the nine predecessor y-states sy, candidate = a[sy] + ((b + u) + v) with u, v in
// {-z, 0, +z}, folded into the lane's smallest, second smallest and arg-smallest. Lanes of a
// target x-state without a row this time carry b = +inf and z = 0, so their candidates are +inf
// and change nothing. Written with 8-lane vector extensions and cloned for AVX-512 and AVX, where
// the machine has them; every clone computes the same values (no contraction into FMA:
// core/CMakeLists.txt sets -ffp-contract=off).
constexpr int kLaneVector = 8;
constexpr int kLaneVectors = 11;
constexpr int kTargetLanes = kLaneVectors * kLaneVector;

// The lane of target state (tx, ty) (see above).
constexpr int TargetLane(int tx, int ty) { return ty < 8 ? tx * 8 + ty : 72 + tx; }

// The row terms of one predecessor x-state (see UpdateTargetMinima()).
struct PredecessorLanes {
  alignas(64) std::array<std::array<double, 16>, 9> a;  // [sy][tx], tx 9..15 unused (0)
  alignas(64) std::array<double, kTargetLanes> b, z0, z1;
};

// Per target state (lane): smallest candidate, second smallest, and the state of the smallest.
// A target whose second smallest lies outside the tie window of the smallest has one candidate in
// the window, which the tie rule must choose; otherwise the window is rebuilt exactly from the
// rows (rare: real ties).
struct TargetMinima {
  alignas(64) std::array<double, kTargetLanes> least, second, state;
};

using Lanes8 = double __attribute__((vector_size(64)));

using LaneMask8 = std::int64_t __attribute__((vector_size(64)));

// Folds the nine candidates of the lanes at `lane` given key a's terms `a[sy]` for them; lanes
// outside `active` (when given) keep their minima: they hold no row this time, only what an
// earlier one left.
[[gnu::always_inline]] inline void FoldLanes(const Lanes8* a, const Lanes8* states,
                                             const PredecessorLanes& row, int lane,
                                             const LaneMask8* active, TargetMinima& minima) {
  Lanes8 least, second, state, b, z0, z1;
  std::memcpy(&least, minima.least.data() + lane, sizeof(Lanes8));
  std::memcpy(&second, minima.second.data() + lane, sizeof(Lanes8));
  std::memcpy(&state, minima.state.data() + lane, sizeof(Lanes8));
  std::memcpy(&b, row.b.data() + lane, sizeof(Lanes8));
  std::memcpy(&z0, row.z0.data() + lane, sizeof(Lanes8));
  std::memcpy(&z1, row.z1.data() + lane, sizeof(Lanes8));
  const Lanes8 zero = {};
  const Lanes8 with_u[3] = {b + (zero - z0), b + zero, b + z0};
  const Lanes8 with_v[3] = {zero - z1, zero, z1};
  for (int sy = 0; sy < 9; ++sy) {
    const Lanes8 c = a[sy] + (with_u[sy / 3] + with_v[sy % 3]);
    const Lanes8 larger = c > least ? c : least;
    second = larger < second ? larger : second;
    const auto smaller = c < least;
    state = smaller ? states[sy] : state;
    least = smaller ? c : least;
  }
  if (active != nullptr) {
    Lanes8 old;
    std::memcpy(&old, minima.least.data() + lane, sizeof(Lanes8));
    least = *active ? least : old;
    std::memcpy(&old, minima.second.data() + lane, sizeof(Lanes8));
    second = *active ? second : old;
    std::memcpy(&old, minima.state.data() + lane, sizeof(Lanes8));
    state = *active ? state : old;
  }
  std::memcpy(minima.least.data() + lane, &least, sizeof(Lanes8));
  std::memcpy(minima.second.data() + lane, &second, sizeof(Lanes8));
  std::memcpy(minima.state.data() + lane, &state, sizeof(Lanes8));
}

// `rows`: bit tx set when target x-state tx has a row in `row` this time.
TEMPOKEY_AVX512_CLONES void UpdateTargetMinima(const PredecessorLanes& row, int state_first,
                                               std::uint32_t rows, TargetMinima& minima) {
  Lanes8 states[9];
  for (int sy = 0; sy < 9; ++sy) {
    const double s = static_cast<double>(state_first + sy);
    states[sy] = Lanes8{s, s, s, s, s, s, s, s};
  }
  Lanes8 a[9] = {};
  for (int tx = 0; tx < 9; ++tx) {
    if ((rows >> tx & 1u) == 0) continue;
    for (int sy = 0; sy < 9; ++sy) {
      const double v = row.a[sy][tx];
      a[sy] = Lanes8{v, v, v, v, v, v, v, v};
    }
    FoldLanes(a, states, row, tx * kLaneVector, nullptr, minima);
  }
  // The target x-state of each lane of vectors 9 and 10 as a bit (0: an unused lane).
  constexpr std::int64_t kLaneRows[2][kLaneVector] = {{1, 2, 4, 8, 16, 32, 64, 128},
                                                      {256, 0, 0, 0, 0, 0, 0, 0}};
  const std::int64_t r = rows;
  const LaneMask8 present = {r, r, r, r, r, r, r, r};
  for (int k = 9; k < kLaneVectors; ++k) {
    if ((rows & (k == 9 ? 0xffu : 0x100u)) == 0) continue;
    LaneMask8 bits;
    std::memcpy(&bits, kLaneRows[k - 9], sizeof(LaneMask8));
    const LaneMask8 active = (bits & present) != 0;
    for (int sy = 0; sy < 9; ++sy) {
      std::memcpy(&a[sy], row.a[sy].data() + (k - 9) * kLaneVector, sizeof(Lanes8));
    }
    FoldLanes(a, states, row, k * kLaneVector, &active, minima);
  }
}

// The row of one x-combination (sx, tx) into the lanes of target x-state `tx` (see
// DpPass::Advance() for the candidates): the segment's form (BuildSegmentForm()) split into the
// terms of key a alone, a[sy] = in[sy] + alpha[sy], of key b alone, b[ty] = e0 + beta[ty], and
// the cross terms z0, z1. Cloned like UpdateTargetMinima(), each clone with the same operations.
TEMPOKEY_AVX512_CLONES void BuildRow(std::span<const double> samples, const SegmentShape& shape,
                                     double y_ref, const std::array<double, 4>& centre_y,
                                     const HermiteSteps& steps, const double* in_row, int tx,
                                     PredecessorLanes& lanes) {
  const SegmentForm form = BuildSegmentForm(samples, shape, y_ref, centre_y, steps);
  const auto& h = form.h;
  // alpha(d0, d1) = g0 d0 + g1 d1 + H00 d0^2 + 2 H01 d0 d1 + H11 d1^2, d in {-1, 0, 1}.
  const double a_minus = h[0][0] - form.g[0];
  const double a_plus = h[0][0] + form.g[0];
  const double b_minus = h[1][1] - form.g[1];
  const double b_plus = h[1][1] + form.g[1];
  const double ab = 2.0 * h[0][1];
  const std::array<double, 9> alpha = {a_minus + b_minus + ab, a_minus, a_minus + b_plus - ab,
                                       b_minus,                0.0,     b_plus,
                                       a_plus + b_minus - ab,  a_plus,  a_plus + b_plus + ab};
  const double c_minus = h[2][2] - form.g[2];
  const double c_plus = h[2][2] + form.g[2];
  const double d_minus = h[3][3] - form.g[3];
  const double d_plus = h[3][3] + form.g[3];
  const double cd = 2.0 * h[2][3];
  const std::array<double, 9> beta = {c_minus + d_minus + cd, c_minus, c_minus + d_plus - cd,
                                      d_minus,                0.0,     d_plus,
                                      c_plus + d_minus - cd,  c_plus,  c_plus + d_plus + cd};
  for (int sy = 0; sy < 9; ++sy) lanes.a[sy][tx] = in_row[sy] + alpha[sy];
  // z0 = 2 (H02 d2 + H03 d3), z1 = 2 (H12 d2 + H13 d3) over the nine (d2, d3).
  const double p0 = 2.0 * h[0][2];
  const double q0 = 2.0 * h[0][3];
  const double p1 = 2.0 * h[1][2];
  const double q1 = 2.0 * h[1][3];
  const std::array<double, 9> z0 = {-p0 - q0, -p0, -p0 + q0, -q0, 0.0, q0, p0 - q0, p0, p0 + q0};
  const std::array<double, 9> z1 = {-p1 - q1, -p1, -p1 + q1, -q1, 0.0, q1, p1 - q1, p1, p1 + q1};
  double* b = lanes.b.data() + tx * kLaneVector;
  double* z0_lanes = lanes.z0.data() + tx * kLaneVector;
  double* z1_lanes = lanes.z1.data() + tx * kLaneVector;
  for (int ty = 0; ty < 8; ++ty) {
    b[ty] = form.e0 + beta[ty];
    z0_lanes[ty] = z0[ty];
    z1_lanes[ty] = z1[ty];
  }
  lanes.b[TargetLane(tx, 8)] = form.e0 + beta[8];
  lanes.z0[TargetLane(tx, 8)] = z0[8];
  lanes.z1[TargetLane(tx, 8)] = z1[8];
}

// Viterbi tables of one pass.
class DpPass {
 public:
  DpPass(std::span<const double> samples, std::span<const HermiteKey2D> keys,
         const HermiteSteps& steps, ShapeCache& cache, std::stop_token stop = {})
      : samples_(samples),
        keys_(keys),
        steps_(steps),
        scale_(DpTieScale(samples)),
        last_frame_(static_cast<double>(samples.size()) - 1.0),
        cache_(cache),
        stop_(std::move(stop)) {
    const std::size_t k = keys.size();
    grids_.reserve(k);
    for (std::size_t i = 0; i < k; ++i) {
      grids_.push_back(MakeGrid(keys[i], steps, i == 0 || i + 1 == k));
    }
    cost_.assign(k, {});
    predecessor_.assign(k, {});
  }

  // The Viterbi path; nullopt when `stop` was requested part way (see Stopping()).
  std::optional<HermiteDpPass> Run() {
    const std::size_t k = keys_.size();
    for (int s = 0; s < kStates; ++s) {
      cost_[0][s] = XIndex(s / 9) == 1 ? 0.0 : kInf;
    }
    for (std::size_t i = 0; i + 1 < k; ++i) {
      if (!Advance(i)) return std::nullopt;
    }
    const double lowest = *std::min_element(cost_[k - 1].begin(), cost_[k - 1].end());
    const auto [best, state] = ChooseCandidate(cost_[k - 1].data(), lowest, scale_);
    HermiteDpPass pass;
    pass.squared_error = best;
    pass.keys.resize(k);
    int current = state;
    for (std::size_t i = k; i-- > 0;) {
      pass.keys[i] = KeyOfState(i, current);
      if (current != kCenterState) pass.moved = true;
      if (i > 0) current = predecessor_[i][current];
    }
    return pass;
  }

 private:
  HermiteKey2D KeyOfState(std::size_t i, int state) const {
    const KeyGrid& grid = grids_[i];
    const int sx = state / 9;
    const int sy = state % 9;
    return {grid.x[XIndex(sx)], grid.y[sy / 3], grid.tx[TxIndex(sx)], grid.ty[sy % 3]};
  }

  // One predecessor x-state's contribution to the nine targets of one target x-state:
  //   candidate(sy, ty) = a[sy] + ((b[ty] + dy_a(sy) * z0[ty]) + dty_a(sy) * z1[ty])
  // with a = in + alpha (terms of key a alone), b = e0 + beta (key b alone) and z the cross
  // terms; the offsets are -1, 0, +1, so the products are exact and the fast pass and the tie
  // fallback below compute every candidate bit for bit alike. The rows of one predecessor
  // x-state toward the nine target x-states share a PredecessorLanes, one per predecessor
  // x-state folded (a slot), kept for the tie fallback.
  struct Workspace {
    std::array<PredecessorLanes, 9> slots;
    std::array<int, 9> slot_sx;
    std::array<std::uint32_t, 9> slot_rows;  // bit tx: target x-state tx has a row
    int slot_count = 0;
    TargetMinima minima;

    void Reset() {
      minima.least.fill(kInf);
      minima.second.fill(kInf);
      minima.state.fill(-1.0);
      slot_count = 0;
    }
  };

  // SegmentIsFeasible() with both keys inside the clip (hermite_dp.h): a grid offset can move an
  // interior key past the first or last frame, where there are no samples to measure it against.
  bool InsideAndFeasible(double ax, double atx, double bx, double btx) const {
    return ax >= 0.0 && bx <= last_frame_ && SegmentIsFeasible(ax, atx, bx, btx);
  }

  // Counts `frames` of work (a basis solve or a data sum per frame) and looks at the stop token
  // once per kDpStopCheckFrames of it: a few milliseconds of work, whether the segments are
  // short or a million frames long.
  bool Stopping(std::int64_t frames) {
    work_ += frames;
    if (work_ < kDpStopCheckFrames) return false;
    work_ = 0;
    return stop_.stop_requested();
  }

  // Fills cost_[i + 1] and predecessor_[i + 1] from cost_[i] through segment i; false when a
  // stop was requested part way.
  bool Advance(std::size_t i) {
    if (Stopping(1)) return false;
    const bool last = i + 2 == keys_.size();
    const KeyGrid& ga = grids_[i];
    const KeyGrid& gb = grids_[i + 1];
    const std::array<double, kStates>& in = cost_[i];
    const std::array<double, 4> centre_y = {ga.y[1], ga.ty[1], gb.y[1], gb.ty[1]};
    const double last_frame = static_cast<double>(samples_.size() - 1);
    const double y_ref =
        samples_[static_cast<std::size_t>(std::clamp(std::ceil(ga.x[1]), 0.0, last_frame))];

    // Predecessor x-states by their cheapest state: the good ones first tighten the windows,
    // and the rest stop at the first whose cheapest state is above every target's window (its
    // candidates can only be larger, segment errors being sums of squares).
    std::array<double, 9> cheapest;
    std::array<int, 9> order;
    for (int sx = 0; sx < 9; ++sx) {
      cheapest[sx] = *std::min_element(in.begin() + sx * 9, in.begin() + sx * 9 + 9);
      order[sx] = sx;
    }
    std::stable_sort(order.begin(), order.end(),
                     [&](int l, int r) { return cheapest[l] < cheapest[r]; });

    // Every shape the segment may need, looked up before any is used, in two sweeps (keys and
    // slot prefetches, then lookups and record prefetches), so the memory accesses overlap
    // instead of stalling one by one. Visiting the combinations by the difference of their x
    // offsets puts equal shapes next to each other (same length, same tangents): about half of
    // them reuse the previous key.
    std::array<SegmentShape, kStates> shapes;
    // The frames, and so the sum of squares, depend on the x offsets alone.
    std::array<double, 9> squares;
    squares.fill(-1.0);
    std::array<ShapeKey, kStates> keys;
    std::array<std::int8_t, kStates> key_of_combo;
    std::array<std::int8_t, kStates> combos;
    int combo_count = 0;
    int key_count = 0;
    // Whether each combination passes InsideAndFeasible(), for the rows below.
    std::array<bool, kStates> feasible{};
    // SegmentFrames() of the three x values of each key: the first frame depends on key a's x
    // alone, the end on key b's.
    std::array<std::int64_t, 3> first_of, end_of;
    for (int o = 0; o < 3; ++o) {
      first_of[o] = SegmentFrames(ga.x[o], gb.x[o], last).first;
      end_of[o] = SegmentFrames(ga.x[o], gb.x[o], last).second;
    }
    for (int itx_a = 0; itx_a < 3; ++itx_a) {
      for (int itx_b = 0; itx_b < 3; ++itx_b) {
        for (int difference = -2; difference <= 2; ++difference) {
          for (int ix_a = std::max(0, -difference); ix_a < std::min(3, 3 - difference); ++ix_a) {
            const int ix_b = ix_a + difference;
            const int sx = ix_a * 3 + itx_a;
            const int tx = ix_b * 3 + itx_b;
            if (cheapest[sx] == kInf || (gb.x_fixed && ix_b != 1)) continue;
            const double ax = ga.x[ix_a];
            const double atx = ga.tx[itx_a];
            const double bx = gb.x[ix_b];
            const double btx = gb.tx[itx_b];
            if (!InsideAndFeasible(ax, atx, bx, btx)) continue;
            const int combo = tx * 9 + sx;
            feasible[combo] = true;
            SegmentShape& shape = shapes[combo];
            const std::int64_t first = first_of[ix_a];
            const std::int64_t end = end_of[ix_b];
            shape.first = first;
            shape.n = static_cast<int>(std::max<std::int64_t>(0, end - first));
            if (shape.n == 0) continue;
            double& offsets_squares = squares[ix_a * 3 + ix_b];
            if (offsets_squares < 0.0) {
              offsets_squares = SumSquares(samples_.data() + first, shape.n, y_ref);
            }
            shape.squares = offsets_squares;
            const ShapeKey key{bx - ax, atx, btx, static_cast<double>(first) - ax};
            if (key_count == 0 || !(key == keys[key_count - 1])) {
              keys[key_count++] = key;
              cache_.Prefetch(key);
            }
            key_of_combo[combo_count] = static_cast<std::int8_t>(key_count - 1);
            combos[combo_count++] = static_cast<std::int8_t>(combo);
          }
        }
      }
    }
    std::array<ShapeEntry, kStates> entries;
    for (int k = 0; k < key_count; ++k) {
      if (Stopping(static_cast<std::int64_t>(keys[k].length))) return false;
      entries[k] = cache_.Get(keys[k]);
      __builtin_prefetch(entries[k].record);
    }
    for (int c = 0; c < combo_count; ++c) shapes[combos[c]].entry = entries[key_of_combo[c]];

    Workspace& work = *work_space_;
    work.Reset();
    // The target x-states still open: a target x-state closes at the first predecessor whose
    // cheapest state is above every one of its targets' windows (later ones are dearer still).
    std::uint32_t open = 0;
    for (int tx = 0; tx < 9; ++tx) {
      if (!gb.x_fixed || XIndex(tx) == 1) open |= 1u << tx;
    }
    for (int sx : order) {
      if (cheapest[sx] == kInf || open == 0) break;
      PredecessorLanes& lanes = work.slots[work.slot_count];
      std::uint32_t rows = 0;
      for (int tx = 0; tx < 9; ++tx) {
        if ((open >> tx & 1u) == 0) continue;
        // The widest tie window of the nine targets is that of the largest smallest candidate
        // (TieTolerance() rounds monotonically).
        double largest = work.minima.least[TargetLane(tx, 8)];
        for (int ty = 0; ty < 8; ++ty) largest = std::max(largest, work.minima.least[tx * 8 + ty]);
        if (cheapest[sx] > largest + TieTolerance(largest, scale_)) {
          open &= ~(1u << tx);
          continue;
        }
        if (!feasible[tx * 9 + sx]) continue;
        if (Stopping(shapes[tx * 9 + sx].n)) return false;
        BuildRow(samples_, shapes[tx * 9 + sx], y_ref, centre_y, steps_, in.data() + sx * 9, tx,
                 lanes);
        rows |= 1u << tx;
      }
      if (rows == 0) continue;
      work.slot_sx[work.slot_count] = sx;
      work.slot_rows[work.slot_count] = rows;
      ++work.slot_count;
      UpdateTargetMinima(lanes, sx * 9, rows, work.minima);
    }
    for (int tx = 0; tx < 9; ++tx) {
      for (int ty = 0; ty < 9; ++ty) {
        const auto [value, state] = ChooseForTarget(work, tx, ty);
        cost_[i + 1][tx * 9 + ty] = value;
        predecessor_[i + 1][tx * 9 + ty] = static_cast<std::int8_t>(state);
      }
    }
    return true;
  }

  // The candidate of (sy, tx * 9 + ty) in `row`, exactly as UpdateTargetMinima() computes it.
  static double Candidate(const PredecessorLanes& row, int sy, int tx, int ty) {
    const int lane = TargetLane(tx, ty);
    const double d0 = kOffsetHigh[sy];
    const double d1 = kOffsetLow[sy];
    const double u = d0 < 0.0 ? -row.z0[lane] : (d0 > 0.0 ? row.z0[lane] : 0.0);
    const double v = d1 < 0.0 ? -row.z1[lane] : (d1 > 0.0 ? row.z1[lane] : 0.0);
    return row.a[sy][tx] + ((row.b[lane] + u) + v);
  }

  // The tie rule for target state (tx, ty) over the rows of target x-state `tx`.
  std::pair<double, int> ChooseForTarget(const Workspace& work, int tx, int ty) const {
    const int lane = TargetLane(tx, ty);
    const double m = work.minima.least[lane];
    if (m == kInf) return {kInf, -1};
    const double window = m + TieTolerance(m, scale_);
    if (work.minima.second[lane] > window) return {m, static_cast<int>(work.minima.state[lane])};
    // Several candidates in the window: state 40 if among them, else the lowest state.
    double best_value = kInf;
    int best_state = -1;
    for (int r = 0; r < work.slot_count; ++r) {
      if ((work.slot_rows[r] >> tx & 1u) == 0) continue;
      for (int sy = 0; sy < 9; ++sy) {
        const double c = Candidate(work.slots[r], sy, tx, ty);
        if (!(c <= window)) continue;
        const int state = work.slot_sx[r] * 9 + sy;
        if (state == kCenterState) return {c, state};
        if (best_state < 0 || state < best_state) {
          best_state = state;
          best_value = c;
        }
      }
    }
    return {best_value, best_state};
  }

  std::span<const double> samples_;
  std::span<const HermiteKey2D> keys_;
  HermiteSteps steps_;
  double scale_;
  double last_frame_;
  std::vector<KeyGrid> grids_;
  std::vector<std::array<double, kStates>> cost_;
  std::vector<std::array<std::int8_t, kStates>> predecessor_;
  ShapeCache& cache_;
  std::stop_token stop_;
  std::int64_t work_ = 0;  // frames of work since the last look at stop_
  std::unique_ptr<Workspace> work_space_ = std::make_unique<Workspace>();
};

absl::Status CheckStep(const char* name, double value) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    return absl::InvalidArgumentError(
        absl::StrCat("step ", name, " must be finite and > 0, got ", value));
  }
  return absl::OkStatus();
}

// InitialKeyFrames() from the smoothed copy of the samples (InitialHermiteKeys() needs that copy
// too, so it is smoothed once).
std::vector<int> KeyFramesOfSmoothed(const std::vector<double>& smooth, int min_spacing_frames) {
  const int n = static_cast<int>(smooth.size());
  if (n <= 1) return {0};
  const auto [first, second] = Differences(smooth);
  std::vector<int> kept = {0, n - 1};
  if (n - 1 < min_spacing_frames) return kept;
  // Kept frames in order, so the spacing check looks at two neighbours only.
  std::vector<int> sorted = kept;
  auto try_keep = [&](int f) {
    const auto it = std::lower_bound(sorted.begin(), sorted.end(), f);
    if (it != sorted.end() && *it - f < min_spacing_frames) return;
    if (it != sorted.begin() && f - *(it - 1) < min_spacing_frames) return;
    sorted.insert(it, f);
  };
  for (int f : ZeroCrossings(first)) try_keep(f);
  for (int f : ZeroCrossings(second)) try_keep(f);
  return sorted;
}

}  // namespace

std::vector<int> InitialKeyFrames(std::span<const double> samples, double sigma_frames,
                                  int min_spacing_frames) {
  if (samples.size() <= 1) return {0};
  return KeyFramesOfSmoothed(GaussianSmooth(samples, sigma_frames), min_spacing_frames);
}

std::vector<HermiteKey2D> InitialHermiteKeys(std::span<const double> samples, double sigma_frames,
                                             int min_spacing_frames, std::stop_token stop) {
  const std::vector<double> smooth = GaussianSmooth(samples, sigma_frames, stop);
  if (stop.stop_requested()) return {};
  const std::vector<int> frames = KeyFramesOfSmoothed(smooth, min_spacing_frames);
  std::vector<HermiteKey2D> keys;
  keys.reserve(frames.size());
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const int f = frames[k];
    double gap = kInf;
    if (k > 0) gap = std::min(gap, static_cast<double>(f - frames[k - 1]));
    if (k + 1 < frames.size()) gap = std::min(gap, static_cast<double>(frames[k + 1] - f));
    if (gap == kInf) gap = 1.0;
    keys.push_back({static_cast<double>(f), samples[f], gap, gap * SlopeAt(smooth, f)});
  }
  return keys;
}

double HermiteValueAtFrame(const HermiteKey2D& a, const HermiteKey2D& b, double frame) {
  const double s = SolveBezierParameter(a.x, a.x + a.tx / 3.0, b.x - b.tx / 3.0, b.x, frame);
  const Basis h = HermiteBasis(s);
  return h.h00 * a.y + h.h10 * a.ty + h.h01 * b.y + h.h11 * b.ty;
}

namespace {

// The segment error (hermite_dp.h) on `cache`'s basis rows: the same x(s) = frame solutions the
// DP's forms are built from.
double SegmentErrorOnShape(std::span<const double> samples, ShapeCache& cache,
                           const HermiteKey2D& a, const HermiteKey2D& b, bool last) {
  const auto [first, end] = SegmentFrames(a.x, b.x, last);
  const int n = static_cast<int>(std::max<std::int64_t>(0, end - first));
  if (n == 0) return 0.0;
  const ShapeEntry entry = cache.Get({b.x - a.x, a.tx, b.tx, static_cast<double>(first) - a.x});
  double sum = 0.0;
  for (int k = 0; k < n; ++k) {
    const double* h = entry.basis() + k * kBasisStride;
    const double r = h[0] * a.y + h[1] * a.ty + h[2] * b.y + h[3] * b.ty - samples[first + k];
    sum += r * r;
  }
  return sum;
}

}  // namespace

double CurveSquaredError(std::span<const double> samples, std::span<const HermiteKey2D> keys) {
  ShapeCache& cache = ThreadShapeCache();
  cache.TrimIfLarge();
  double sum = 0.0;
  for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
    sum += SegmentErrorOnShape(samples, cache, keys[i], keys[i + 1], i + 2 == keys.size());
  }
  return sum;
}

double DpTieScale(std::span<const double> samples) {
  double scale = 0.0;
  for (double v : samples) {
    const double d = v - samples[0];
    scale += d * d;
  }
  return scale;
}

absl::Status ValidateHermiteKeys(std::span<const double> samples,
                                 std::span<const HermiteKey2D> keys) {
  if (samples.size() < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("a fit needs at least 2 samples, got ", samples.size()));
  }
  if (keys.size() < 2) {
    return absl::InvalidArgumentError(absl::StrCat("a fit needs at least 2 keys, got ", keys.size()));
  }
  for (std::size_t f = 0; f < samples.size(); ++f) {
    if (!std::isfinite(samples[f])) {
      return absl::InvalidArgumentError(absl::StrCat("sample ", f, " is ", samples[f]));
    }
  }
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const HermiteKey2D& key = keys[k];
    if (!std::isfinite(key.x) || !std::isfinite(key.y) || !std::isfinite(key.tx) ||
        !std::isfinite(key.ty)) {
      return absl::InvalidArgumentError(absl::StrCat("key ", k, " is not finite"));
    }
  }
  const double last_frame = static_cast<double>(samples.size() - 1);
  if (keys.front().x != 0.0 || keys.back().x != last_frame) {
    return absl::InvalidArgumentError(absl::StrCat("keys must span frames 0 to ", last_frame,
                                                   ", got ", keys.front().x, " to ",
                                                   keys.back().x));
  }
  for (std::size_t k = 0; k + 1 < keys.size(); ++k) {
    const HermiteKey2D& a = keys[k];
    const HermiteKey2D& b = keys[k + 1];
    if (!SegmentIsFeasible(a.x, a.tx, b.x, b.tx)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "key ", k, ": segment to key ", k + 1, " is not monotonic in time (x ", a.x, " to ",
          b.x, ", tx ", a.tx, " and ", b.tx, ")"));
    }
  }
  return absl::OkStatus();
}

HermiteDpPass RunHermiteDpPass(std::span<const double> samples,
                               std::span<const HermiteKey2D> keys, const HermiteSteps& steps) {
  ShapeCache& cache = ThreadShapeCache();
  cache.TrimIfLarge();
  return *DpPass(samples, keys, steps, cache).Run();  // no stop token: always a path
}

absl::StatusOr<HermiteFitResult> FitHermiteDp(std::span<const double> samples,
                                              std::vector<HermiteKey2D> initial,
                                              const HermiteFitOptions& options,
                                              std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateHermiteKeys(samples, initial));
  TEMPOKEY_RETURN_IF_ERROR(CheckStep("x", options.steps.x));
  TEMPOKEY_RETURN_IF_ERROR(CheckStep("y", options.steps.y));
  TEMPOKEY_RETURN_IF_ERROR(CheckStep("tangent_x", options.steps.tangent_x));
  TEMPOKEY_RETURN_IF_ERROR(CheckStep("tangent_y", options.steps.tangent_y));
  if (!(options.accuracy > 0.0) || !std::isfinite(options.accuracy)) {
    return absl::InvalidArgumentError(
        absl::StrCat("accuracy must be finite and > 0, got ", options.accuracy));
  }
  if (options.max_iterations < 0 || options.max_iterations > kMaxIterationsLimit) {
    return absl::InvalidArgumentError(absl::StrCat("max_iterations must be in [0, ",
                                                   kMaxIterationsLimit, "], got ",
                                                   options.max_iterations));
  }

  HermiteFitResult result;
  result.keys = std::move(initial);
  result.squared_error = CurveSquaredError(samples, result.keys);
  result.squared_error_history.push_back(result.squared_error);
  HermiteSteps steps = options.steps;
  ShapeCache& cache = ThreadShapeCache();
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const double largest =
        std::max({steps.x, steps.y, steps.tangent_x, steps.tangent_y});
    if (largest < options.accuracy) break;
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    cache.TrimIfLarge();
    std::optional<HermiteDpPass> run = DpPass(samples, result.keys, steps, cache, stop).Run();
    if (!run) return absl::CancelledError("cancelled");
    HermiteDpPass pass = *std::move(run);
    ++result.iterations;
    bool taken = false;
    if (pass.moved) {
      const double error = CurveSquaredError(samples, pass.keys);
      if (error <= result.squared_error) {
        result.keys = std::move(pass.keys);
        result.squared_error = error;
        taken = true;
      }
    }
    if (!taken) {
      steps.x *= 0.5;
      steps.y *= 0.5;
      steps.tangent_x *= 0.5;
      steps.tangent_y *= 0.5;
    }
    result.squared_error_history.push_back(result.squared_error);
  }
  result.final_steps = steps;
  return result;
}

Curve HermiteKeysToCurve(std::span<const HermiteKey2D> keys, double frame_time_seconds) {
  Curve curve;
  curve.keys.reserve(keys.size());
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const HermiteKey2D& key = keys[k];
    Key out;
    out.time_seconds = key.x * frame_time_seconds;
    out.value = key.y;
    if (keys.size() == 1) {
      curve.keys.push_back(out);
      continue;
    }
    const double slope = key.ty / (key.tx * frame_time_seconds);
    out.in_tangent = slope;
    out.out_tangent = slope;
    std::optional<double> in_weight;
    std::optional<double> out_weight;
    if (k > 0) in_weight = key.tx / (3.0 * (key.x - keys[k - 1].x));
    if (k + 1 < keys.size()) out_weight = key.tx / (3.0 * (keys[k + 1].x - key.x));
    out.in_weight = in_weight ? in_weight : out_weight;
    out.out_weight = out_weight ? out_weight : in_weight;
    curve.keys.push_back(out);
  }
  return curve;
}

}  // namespace tempokey::core
