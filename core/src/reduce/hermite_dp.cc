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

#include "absl/strings/str_cat.h"
#include "core/src/simd/vectors.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"
#include "lane_pack.h"

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

// The Hermite basis at every frame of one x-shape, shared by every segment and x-combination
// with that shape. A segment's x(s) depends only on its length L = bx - ax, the two tangent
// x-components and where the first frame falls (t0 = first frame - ax): the frames sit at
// t0, t0 + 1, ... <= L from the segment start. With integer steps most x-combinations of a pass,
// and many across segments and passes, share a shape, so each x(s) = frame solve runs once.
struct ShapeKey {
  double length, atx, btx, t0;
  friend bool operator==(const ShapeKey&, const ShapeKey&) = default;
};

// The hash of a shape key: one 64-bit word folded from the four values' bits (adding +0.0 first
// maps -0.0 to 0.0, which == does not tell apart), then mixed so that its low bits (the slot) and
// high bits (the tag) both depend on every value.
inline std::uint64_t HashShapeKey(const ShapeKey& k) {
  const auto bits = [](double v) { return std::bit_cast<std::uint64_t>(v + 0.0); };
  std::uint64_t h = bits(k.length) * 0x9e3779b97f4a7c15u ^ bits(k.atx) * 0xc2b2ae3d27d4eb4fu ^
                    bits(k.btx) * 0x165667b19e3779f9u ^ bits(k.t0) * 0xd6e8feb86659fd93u;
  h ^= h >> 32;
  h *= 0xd6e8feb86659fd93u;
  h ^= h >> 32;
  return h;
}

// Per shape: `count` rows of the basis (h00, h10, h01, h11) at its frames, and the Gram sums
// sum h h^T (10 distinct entries) over all rows and over all but the last. A segment's frames are
// the shape's first `count` or `count - 1` targets (the last one is the segment end, which only
// the last segment of a channel takes), so those two sums are the only ones ever read.
struct ShapeEntry {
  // gram_but_last[10], gram_all[10], then `count` basis rows of kBasisStride.
  const double* record;
  int count;

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
  // The entry of `key`, whose HashShapeKey() is `hash`, computed on first use. Its pointers stay
  // valid until the next trim.
  ShapeEntry Get(const ShapeKey& key, std::uint64_t hash) {
    const auto tag = static_cast<std::uint32_t>(hash >> 32);
    for (std::size_t i = hash & mask_;; i = (i + 1) & mask_) {
      const Slot slot = slots_[i];
      if (slot.index == 0) break;
      if (slot.tag != tag) continue;
      const ShapeEntry& entry = entries_[slot.index - 1];
      if (KeyOf(entry) == key) return entry;
    }
    return Insert(key, hash);
  }
  ShapeEntry Get(const ShapeKey& key) { return Get(key, HashShapeKey(key)); }
  // Starts loading the slot of `hash` (a hint; no effect on results).
  void Prefetch(std::uint64_t hash) const { __builtin_prefetch(&slots_[hash & mask_]); }
  // Bounds memory: past kMaxBlocks blocks (or a few oversized tables), forgets every entry and
  // reuses the blocks.
  void TrimIfLarge() {
    if (next_block_ > kMaxBlocks || oversized_.size() > kMaxOversized) {
      std::fill(slots_.begin(), slots_.end(), Slot{});
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
  static constexpr std::size_t kInitialSlots = std::size_t{1} << 12;
  // Each record starts with its key, kKeyDoubles values before the entry's Gram sums.
  static constexpr std::size_t kKeyDoubles = 4;

  // An open-addressing table (linear probing, at most half full) of 8-byte slots: a lookup
  // touches one small slot, then the record it needs anyway, where the key is compared.
  struct Slot {
    std::uint32_t tag = 0;    // the hash's high half
    std::uint32_t index = 0;  // 1 + the entry's index in entries_, 0 for an empty slot
  };

  static ShapeKey KeyOf(const ShapeEntry& entry) {
    const double* key = entry.record - kKeyDoubles;
    return {key[0], key[1], key[2], key[3]};
  }

  ShapeEntry Insert(const ShapeKey& key, std::uint64_t hash) {
    entries_.push_back(Compute(key));
    if (2 * entries_.size() > slots_.size()) {
      Rehash(std::max(kInitialSlots, 2 * slots_.size()));
    } else {
      Place(hash, static_cast<std::uint32_t>(entries_.size()));
    }
    return entries_.back();
  }

  // Puts entry `index` (1-based) of hash `hash` into the first free slot of its probe sequence.
  void Place(std::uint64_t hash, std::uint32_t index) {
    std::size_t i = hash & mask_;
    while (slots_[i].index != 0) i = (i + 1) & mask_;
    slots_[i] = {static_cast<std::uint32_t>(hash >> 32), index};
  }

  void Rehash(std::size_t slots) {
    slots_.assign(slots, Slot{});
    mask_ = slots - 1;
    for (std::size_t e = 0; e < entries_.size(); ++e) {
      Place(HashShapeKey(KeyOf(entries_[e])), static_cast<std::uint32_t>(e + 1));
    }
  }

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
    double* key_values =
        Allocate(kKeyDoubles + 2 * kGramSize + static_cast<std::size_t>(count) * kBasisStride);
    key_values[0] = key.length;
    key_values[1] = key.atx;
    key_values[2] = key.btx;
    key_values[3] = key.t0;
    double* record = key_values + kKeyDoubles;
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

  std::vector<Slot> slots_ = std::vector<Slot>(kInitialSlots);
  std::size_t mask_ = kInitialSlots - 1;
  std::vector<ShapeEntry> entries_;
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
// Left uninitialised where PrepareForms() declares them (only feasible combinations are read).
struct SegmentShape {
  ShapeEntry entry;
  std::int64_t first;  // first frame
  int n;               // frames, 0 for none
  double squares;      // sum of (sample - y_ref)^2 over the frames
};

// Sum of (sample[k] - y_ref)^2 over k < n.
double SumSquares(const double* sample, int n, double y_ref) {
  double squares = 0.0;
  for (int k = 0; k < n; ++k) {
    const double d = sample[k] - y_ref;
    squares += d * d;
  }
  return squares;
}

// ---- the rows of one segment, 81 x-combinations at once -----------------------------------------
//
// The error of one x-combination (sx, tx) of a segment is a quadratic form in the y-offsets
// delta = (dy_a, dty_a, dy_b, dty_b) in {-1, 0, 1}^4:
//   E(delta) = e0 + g . delta + delta^T H delta,
// built from residuals at the grid centre so that no large sums cancel: with y_ref a sample near
// the segment, w the centre's y-components relative to it, G the Gram matrix of the basis over
// the segment's frames (from the shape cache), b the data terms sum (sample - y_ref) h and c the
// sum of (sample - y_ref)^2, E(w + D delta) = e0 + 2 (G w - b)^T D delta + delta^T D G D delta.
// Its candidates split into the terms of key a alone, a[sy] = in[sy] + alpha[sy], of key b
// alone, b[ty] = e0 + beta[ty], and the cross terms z0, z1:
//   candidate(sy, ty) = a[sy] + ((b[ty] + dy_a(sy) * z0[ty]) + dty_a(sy) * z1[ty]);
// the offsets are -1, 0, +1, so the products are exact and the fast pass and the tie fallback
// compute every candidate bit for bit alike.
//
// The forms of all 81 combinations (index c = sx * 9 + tx) are computed together, lane c of
// 8-lane packs (lane_pack.h), each lane with the operations a single form takes in the same
// order: a lane computes what the form of its combination alone would.
constexpr int kLaneVector = 8;
constexpr int kComboLanes = 88;  // 81 combinations, 11 vectors of 8

// What the forms are built from, per combination (lane c): data terms, Gram sums (the 10
// distinct entries of G over the segment's frames) and the sum of squares. A combination without
// frames has all zero (its form is zero); one whose frames do not match its shape (unreachable)
// has c = +inf, so its e0 is +inf.
struct FormInputs {
  alignas(64) std::array<std::array<double, kComboLanes>, 4> data;
  alignas(64) std::array<std::array<double, kComboLanes>, kGramSize> gram;
  alignas(64) std::array<double, kComboLanes> squares;
};

// The split forms, per combination (lane c): alpha[sy], b[ty] = e0 + beta[ty], z0[ty], z1[ty].
struct RowTerms {
  alignas(64) std::array<std::array<double, kComboLanes>, 9> alpha, b, z0, z1;
};

// The data terms of the nine combinations that share their frames (the same x offsets, any
// tangents), frames k_begin .. k_end - 1 of them, added to `sums` (started from zero when k_begin
// is 0; sums[j] += (sample[k] - y_ref) * basis row k of combination j, one vector of 4 per
// combination, in frame order): a
// combination's sums are those its frames alone give, and the nine independent chains overlap.
// Cloned for AVX (TEMPOKEY_CLONES_AVX); every clone adds in the same order.
TEMPOKEY_CLONES_AVX void SumDataTerms(const double* sample, std::int64_t k_begin,
                                      std::int64_t k_end, double y_ref,
                                      const std::array<const double*, 9>& basis,
                                      std::array<std::array<double, 4>, 9>& sums) {
  using V = simd::V4;
  V acc[9];
  for (int j = 0; j < 9; ++j) {
    if (k_begin == 0) {
      acc[j] = V{};
    } else {
      std::memcpy(&acc[j], sums[j].data(), sizeof(V));
    }
  }
  for (std::int64_t k = k_begin; k < k_end; ++k) {
    const double d = sample[k] - y_ref;
    for (int j = 0; j < 9; ++j) {
      V h;
      std::memcpy(&h, basis[j] + k * kBasisStride, sizeof(V));
      acc[j] += d * h;
    }
  }
  for (int j = 0; j < 9; ++j) std::memcpy(sums[j].data(), &acc[j], sizeof(V));
}

// q(u, v) = h_uu u^2 + lin_u u + h_vv v^2 + lin_v v + cross u v at the nine steps (u, v) in
// {-1, 0, 1}^2, u major: the quadratic part of one pair of a combination's form.
template <typename P>
[[gnu::always_inline]] inline std::array<P, 9> StepPairTerms(P h_uu, P lin_u, P h_vv, P lin_v,
                                                             P cross, P zero) {
  const P u_minus = h_uu - lin_u;
  const P u_plus = h_uu + lin_u;
  const P v_minus = h_vv - lin_v;
  const P v_plus = h_vv + lin_v;
  return {u_minus + v_minus + cross, u_minus, u_minus + v_plus - cross,
          v_minus,                   zero,    v_plus,
          u_plus + v_minus - cross,  u_plus,  u_plus + v_plus + cross};
}

// The split forms of all combinations from their inputs; `centre` the centre's y-components
// relative to y_ref (w above), `d` the y-steps (y, tangent y, y, tangent y).
template <typename P>
[[gnu::always_inline]] inline void BuildRowTermsWith(const FormInputs& inputs,
                                                     const std::array<double, 4>& centre,
                                                     const std::array<double, 4>& d,
                                                     RowTerms& terms) {
  const P zero = P::Zero();
  const P two = P::Splat(2.0);
  P w_lanes[4], d2[4], dd[4][4];
  for (int k = 0; k < 4; ++k) {
    w_lanes[k] = P::Splat(centre[k]);
    d2[k] = P::Splat(2.0 * d[k]);
    for (int l = 0; l < 4; ++l) dd[k][l] = P::Splat(d[k] * d[l]);
  }
  for (int c = 0; c < kComboLanes; c += kLaneVector) {
    P g[kGramSize], b[4];
    for (int j = 0; j < kGramSize; ++j) g[j] = P::Load(inputs.gram[j].data() + c);
    for (int j = 0; j < 4; ++j) b[j] = P::Load(inputs.data[j].data() + c);
    const P squares = P::Load(inputs.squares.data() + c);
    const P* w = w_lanes;
    const P gw[4] = {g[0] * w[0] + g[1] * w[1] + g[2] * w[2] + g[3] * w[3],
                     g[1] * w[0] + g[4] * w[1] + g[5] * w[2] + g[6] * w[3],
                     g[2] * w[0] + g[5] * w[1] + g[7] * w[2] + g[8] * w[3],
                     g[3] * w[0] + g[6] * w[1] + g[8] * w[2] + g[9] * w[3]};
    P wgw = zero;
    P bw = zero;
    for (int k = 0; k < 4; ++k) {
      wgw = wgw + w[k] * gw[k];
      bw = bw + b[k] * w[k];
    }
    // std::max(0.0, x): x where 0 < x, else 0.
    const P e = wgw - two * bw + squares;
    const P e0 = P::Select(zero < e, e, zero);
    P lin[4];
    for (int k = 0; k < 4; ++k) lin[k] = d2[k] * (gw[k] - b[k]);
    const P h00 = dd[0][0] * g[0], h01 = dd[0][1] * g[1], h02 = dd[0][2] * g[2],
            h03 = dd[0][3] * g[3], h11 = dd[1][1] * g[4], h12 = dd[1][2] * g[5],
            h13 = dd[1][3] * g[6], h22 = dd[2][2] * g[7], h23 = dd[2][3] * g[8],
            h33 = dd[3][3] * g[9];
    // alpha(d0, d1) = g0 d0 + g1 d1 + H00 d0^2 + 2 H01 d0 d1 + H11 d1^2, d in {-1, 0, 1}; beta
    // the same in (d2, d3).
    const std::array<P, 9> alpha = StepPairTerms(h00, lin[0], h11, lin[1], two * h01, zero);
    const std::array<P, 9> beta = StepPairTerms(h22, lin[2], h33, lin[3], two * h23, zero);
    // z0 = 2 (H02 d2 + H03 d3), z1 = 2 (H12 d2 + H13 d3) over the nine (d2, d3).
    const P p0 = two * h02;
    const P q0 = two * h03;
    const P p1 = two * h12;
    const P q1 = two * h13;
    const P z0[9] = {-p0 - q0, -p0, -p0 + q0, -q0, zero, q0, p0 - q0, p0, p0 + q0};
    const P z1[9] = {-p1 - q1, -p1, -p1 + q1, -q1, zero, q1, p1 - q1, p1, p1 + q1};
    for (int k = 0; k < 9; ++k) {
      alpha[k].Store(terms.alpha[k].data() + c);
      (e0 + beta[k]).Store(terms.b[k].data() + c);
      z0[k].Store(terms.z0[k].data() + c);
      z1[k].Store(terms.z1[k].data() + c);
    }
  }
}

// BuildRowTermsWith() for the running machine.
void BuildRowTerms(const FormInputs& inputs, const std::array<double, 4>& centre,
                   const std::array<double, 4>& d, RowTerms& terms) {
  simd::RunOnPacks([&]<typename P>() __attribute__((always_inline)) {
    BuildRowTermsWith<P>(inputs, centre, d, terms);
  });
}

// ---- the fold of the candidates -----------------------------------------------------------------
//
// One predecessor x-state sx's rows toward all nine target x-states at once, in 11 vectors of 8
// lanes: vector ty < 9 holds the target states (0..7, ty), vector 9 the states (8, 0..7) and
// vector 10 the state (8, 8) and seven unused lanes, so that the lanes of vectors 0..8 read
// consecutive combinations sx * 9 + tx. For each of the nine predecessor y-states sy, candidate =
// a[sy] + ((b + u) + v) with u, v in {-z, 0, +z}, folded into the lane's smallest, second
// smallest and arg-smallest. Lanes of a target x-state without a row this time keep their
// minima. Written on 8-lane packs (lane_pack.h) and built for AVX-512, AVX2 and the baseline, the
// running machine's chosen at run time (UpdateTargetMinima()); every build computes the same
// values (no contraction into FMA: core/CMakeLists.txt sets -ffp-contract=off).
constexpr int kLaneVectors = 11;
constexpr int kTargetLanes = kLaneVectors * kLaneVector;

// The lane of target state (tx, ty) (see above).
constexpr int TargetLane(int tx, int ty) { return tx < 8 ? ty * 8 + tx : 72 + ty; }

// Per target state (lane): smallest candidate, second smallest, and the state of the smallest.
// A target whose second smallest lies outside the tie window of the smallest has one candidate in
// the window, which the tie rule must choose; otherwise the window is rebuilt exactly from the
// rows (rare: real ties).
// `largest[tx]` is the largest of the smallest candidates of target x-state tx's nine targets.
struct TargetMinima {
  alignas(64) std::array<double, kTargetLanes> least, second, state;
  alignas(64) std::array<double, 16> largest;  // [tx], 9..15 unused
};

// The states 0 .. 80 as 8 lanes of their number, read as packs.
struct StateLanes {
  alignas(64) double lane[kStates][kLaneVector];
};
constexpr StateLanes kStateLanes = [] {
  StateLanes table{};
  for (int s = 0; s < kStates; ++s) {
    for (int l = 0; l < kLaneVector; ++l) table.lane[s][l] = static_cast<double>(s);
  }
  return table;
}();

// Folds the nine candidates of the lanes at `lane`, given key a's terms a[sy], and b, z0, z1;
// `states` the lanes of the nine predecessor states; lanes outside `active` (when given) keep
// their minima.
template <typename P>
[[gnu::always_inline]] inline void FoldLanes(const P* a, const double* states, const P& b,
                                             const P& z0, const P& z1, int lane,
                                             const typename P::Mask* active,
                                             TargetMinima& minima) {
  const P old_least = P::Load(minima.least.data() + lane);
  const P old_second = P::Load(minima.second.data() + lane);
  const P old_state = P::Load(minima.state.data() + lane);
  P least = old_least, second = old_second, state = old_state;
  // b + u + v with u, v in {-z, 0, +z}: b is never -0 (e0 >= +0 and b = +inf in unused lanes),
  // nor is b -/+ z0, so x + 0 is x and x + (-z) is x - z bit for bit (IEEE defines x - z as
  // x + (-z); for z = +-0 both give x): the middle offsets skip their addition and the low ones
  // subtract.
  const P with_u[3] = {b - z0, b, b + z0};
  for (int sy = 0; sy < 9; ++sy) {
    const P& u = with_u[sy / 3];
    const P w = sy % 3 == 0 ? u - z1 : (sy % 3 == 1 ? u : u + z1);
    const P c = a[sy] + w;
    const P larger = P::Select(c > least, c, least);
    second = P::Select(larger < second, larger, second);
    const typename P::Mask smaller = c < least;
    state = P::Select(smaller, P::Load(states + sy * kLaneVector), state);
    least = P::Select(smaller, c, least);
  }
  if (active != nullptr) {
    least = P::Select(*active, least, old_least);
    second = P::Select(*active, second, old_second);
    state = P::Select(*active, state, old_state);
  }
  least.Store(minima.least.data() + lane);
  second.Store(minima.second.data() + lane);
  state.Store(minima.state.data() + lane);
}

// Folds predecessor x-state sx's rows, cost `in_row` of its nine states; `rows`: bit tx set when
// the combination (sx, tx) takes part.
template <typename P>
[[gnu::always_inline]] inline void UpdateTargetMinimaWith(const RowTerms& terms,
                                                          const double* in_row, int sx,
                                                          std::uint32_t rows,
                                                          TargetMinima& minima) {
  const int first = sx * 9;
  const double* states = kStateLanes.lane[first];
  P a[9];
  if ((rows & 0xffu) != 0) {
    for (int sy = 0; sy < 9; ++sy) {
      a[sy] = P::Splat(in_row[sy]) + P::Load(terms.alpha[sy].data() + first);
    }
    const typename P::Mask active = P::LaneBits(rows);
    const typename P::Mask* mask = (rows & 0xffu) == 0xffu ? nullptr : &active;
    for (int ty = 0; ty < 9; ++ty) {
      FoldLanes(a, states, P::Load(terms.b[ty].data() + first),
                P::Load(terms.z0[ty].data() + first), P::Load(terms.z1[ty].data() + first),
                ty * kLaneVector, mask, minima);
    }
  }
  if ((rows >> 8 & 1u) != 0) {
    const int c = first + 8;
    for (int sy = 0; sy < 9; ++sy) a[sy] = P::Splat(in_row[sy] + terms.alpha[sy][c]);
    // Lanes 0..7 of vector 9 are the target states (8, 0..7); lane 0 of vector 10 is (8, 8),
    // its unused lanes' candidates +inf (b = +inf, z = 0), which change nothing.
    alignas(64) double b[2][kLaneVector], z0[2][kLaneVector], z1[2][kLaneVector];
    for (int ty = 0; ty < kLaneVector; ++ty) {
      b[0][ty] = terms.b[ty][c];
      z0[0][ty] = terms.z0[ty][c];
      z1[0][ty] = terms.z1[ty][c];
      b[1][ty] = ty == 0 ? terms.b[8][c] : kInf;
      z0[1][ty] = ty == 0 ? terms.z0[8][c] : 0.0;
      z1[1][ty] = ty == 0 ? terms.z1[8][c] : 0.0;
    }
    for (int k = 0; k < 2; ++k) {
      FoldLanes(a, states, P::Load(b[k]), P::Load(z0[k]), P::Load(z1[k]), 72 + k * kLaneVector,
                static_cast<const typename P::Mask*>(nullptr), minima);
    }
  }
  // The largest of the nine targets' smallest candidates per target x-state (max is exact, so
  // the order does not matter).
  P largest = P::Load(minima.least.data());
  for (int ty = 1; ty < 9; ++ty) {
    const P least = P::Load(minima.least.data() + ty * kLaneVector);
    largest = P::Select(least > largest, least, largest);
  }
  largest.Store(minima.largest.data());
  double last = minima.least[80];
  for (int lane = 72; lane < 80; ++lane) last = std::max(last, minima.least[lane]);
  minima.largest[8] = last;
}

// UpdateTargetMinimaWith() for the running machine.
void UpdateTargetMinima(const RowTerms& terms, const double* in_row, int sx, std::uint32_t rows,
                        TargetMinima& minima) {
  simd::RunOnPacks([&]<typename P>() __attribute__((always_inline)) {
    UpdateTargetMinimaWith<P>(terms, in_row, sx, rows, minima);
  });
}

// What the form inputs of a segment depend on (DpPass::Advance()).
struct FormSignature {
  std::array<double, 12> x;  // x and tx of both keys' grids
  double y_ref = 0.0;
  std::uint32_t reachable = 0;
  bool last = false;
  friend bool operator==(const FormSignature&, const FormSignature&) = default;
};

// The form inputs of each segment of a fit as its last pass built them, so that the next pass
// can take those of combinations whose x values did not change: a segment whose grids, y_ref and
// reachable predecessors are the same takes them all as they were; one whose key moved by a grid
// step, or whose reachable predecessors changed, takes those of the combinations it shares with
// the last pass (same ax, a.tx, bx, b.tx) and builds the others. A combination's inputs and
// feasibility are exact functions of its four x values, y_ref and the samples (one fit, one
// channel), so taking them changes no value. One per thread, reused by its fits; it keeps the
// first kMaxSegments segments of a fit (16 MB), two buffers each (the last pass's and the one
// being built from it).
class FormMemo {
 public:
  static constexpr std::size_t kMaxSegments = 768;
  struct Buffer {
    std::array<bool, kStates> feasible;
    std::array<bool, kStates> known;  // the combination's inputs and feasibility are set
    FormInputs inputs;
  };
  struct Entry {
    bool valid = false;
    FormSignature signature;  // of buffers[current]
    int current = 0;
    std::array<Buffer, 2> buffers;
  };

  // Forgets every entry and makes room for the first segments of a fit of `segments`.
  void Start(std::size_t segments) {
    used_ = std::min(segments, kMaxSegments);
    if (entries_.size() < used_) entries_.resize(used_);
    for (std::size_t i = 0; i < used_; ++i) entries_[i].valid = false;
  }
  // The entry of segment `i`, or null past the first kMaxSegments.
  Entry* Segment(std::size_t i) { return i < used_ ? &entries_[i] : nullptr; }

 private:
  std::vector<Entry> entries_;
  std::size_t used_ = 0;
};

// The calling thread's form memo.
FormMemo& ThreadFormMemo() {
  thread_local FormMemo memo;
  return memo;
}

// Viterbi tables of one pass.
class DpPass {
 public:
  // `memo` (optional) carries the segments' form inputs from the fit's previous pass.
  DpPass(std::span<const double> samples, std::span<const HermiteKey2D> keys,
         const HermiteSteps& steps, ShapeCache& cache, std::stop_token stop = {},
         FormMemo* memo = nullptr)
      : samples_(samples),
        keys_(keys),
        steps_(steps),
        scale_(DpTieScale(samples)),
        last_frame_(static_cast<double>(samples.size()) - 1.0),
        cache_(cache),
        memo_(memo),
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

  // The forms of one segment and the minima of its 81 target states. The predecessor x-states
  // folded so far, in order (with the target x-states they had rows for), for the tie fallback.
  struct Workspace {
    FormInputs inputs;
    std::array<bool, kStates> feasible;
    RowTerms terms;
    TargetMinima minima;
    std::array<int, 9> folded_sx;
    std::array<std::uint32_t, 9> folded_rows;  // bit tx: the combination (sx, tx) took part
    int folded = 0;

    void Reset() {
      minima.least.fill(kInf);
      minima.second.fill(kInf);
      minima.state.fill(-1.0);
      minima.largest.fill(kInf);
      folded = 0;
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
    // A segment's fold is counted as kStates frames of work even when its form inputs come from
    // the memo (no frames summed): about a hundred such segments between looks at the token.
    if (Stopping(kStates)) return false;
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
    // A stable insertion sort (std::stable_sort allocates its buffer on every call).
    for (int k = 1; k < 9; ++k) {
      const int sx = order[k];
      int j = k;
      for (; j > 0 && cheapest[sx] < cheapest[order[j - 1]]; --j) order[j] = order[j - 1];
      order[j] = sx;
    }

    Workspace& work = *work_space_;
    work.Reset();
    // The forms' inputs depend on the x-grids, y_ref and which predecessor x-states are
    // reachable: a segment whose three did not change since the last pass takes them as they
    // were, one that changed takes those of the combinations it shares with the last pass
    // (FormMemo).
    const FormSignature signature = {{ga.x[0], ga.x[1], ga.x[2], ga.tx[0], ga.tx[1], ga.tx[2],
                                      gb.x[0], gb.x[1], gb.x[2], gb.tx[0], gb.tx[1], gb.tx[2]},
                                     y_ref,
                                     ReachableMask(cheapest),
                                     last};
    FormMemo::Entry* memo = memo_ != nullptr ? memo_->Segment(i) : nullptr;
    const FormInputs* inputs = nullptr;
    const std::array<bool, kStates>* feasible = nullptr;
    if (memo != nullptr && memo->valid && memo->signature == signature) {
      inputs = &memo->buffers[memo->current].inputs;
      feasible = &memo->buffers[memo->current].feasible;
    } else if (memo != nullptr) {
      const FormMemo::Buffer& previous = memo->buffers[memo->current];
      FormMemo::Buffer& next = memo->buffers[1 - memo->current];
      next.feasible.fill(false);
      std::array<bool, kStates> taken{};
      if (memo->valid && memo->signature.y_ref == y_ref && memo->signature.last == last) {
        TakeSharedInputs(memo->signature, ga, gb, cheapest, previous, next, taken);
      }
      memo->valid = false;
      if (!PrepareForms(ga, gb, last, cheapest, y_ref, &taken, next.feasible, next.inputs)) {
        return false;
      }
      MarkConsidered(gb, cheapest, next.known);
      memo->current = 1 - memo->current;
      memo->signature = signature;
      memo->valid = true;
      inputs = &next.inputs;
      feasible = &next.feasible;
    } else {
      work.feasible.fill(false);
      if (!PrepareForms(ga, gb, last, cheapest, y_ref, nullptr, work.feasible, work.inputs)) {
        return false;
      }
      inputs = &work.inputs;
      feasible = &work.feasible;
    }
    const std::array<double, 4> w = {centre_y[0] - y_ref, centre_y[1], centre_y[2] - y_ref,
                                     centre_y[3]};
    const std::array<double, 4> d = {steps_.y, steps_.tangent_y, steps_.y, steps_.tangent_y};
    BuildRowTerms(*inputs, w, d, work.terms);

    // The target x-states still open: a target x-state closes at the first predecessor whose
    // cheapest state is above every one of its targets' windows (later ones are dearer still).
    std::uint32_t open = 0;
    for (int tx = 0; tx < 9; ++tx) {
      if (!gb.x_fixed || XIndex(tx) == 1) open |= 1u << tx;
    }
    for (int sx : order) {
      if (cheapest[sx] == kInf || open == 0) break;
      std::uint32_t rows = 0;
      for (int tx = 0; tx < 9; ++tx) {
        if ((open >> tx & 1u) == 0) continue;
        // The widest tie window of the nine targets is that of the largest smallest candidate
        // (TieTolerance() rounds monotonically).
        // Where the largest is >= 0 so is its tolerance (the scale is a sum of squares), so a
        // cheapest state at or below it is inside the window without computing the tolerance.
        const double largest = work.minima.largest[tx];
        const bool inside = cheapest[sx] <= largest && largest >= 0.0;
        if (!inside && cheapest[sx] > largest + TieTolerance(largest, scale_)) {
          open &= ~(1u << tx);
          continue;
        }
        if ((*feasible)[sx * 9 + tx]) rows |= 1u << tx;
      }
      if (rows == 0) continue;
      work.folded_sx[work.folded] = sx;
      work.folded_rows[work.folded] = rows;
      ++work.folded;
      UpdateTargetMinima(work.terms, in.data() + sx * 9, sx, rows, work.minima);
    }
    for (int tx = 0; tx < 9; ++tx) {
      for (int ty = 0; ty < 9; ++ty) {
        const auto [value, state] = ChooseForTarget(work, in, tx, ty);
        cost_[i + 1][tx * 9 + ty] = value;
        predecessor_[i + 1][tx * 9 + ty] = static_cast<std::int8_t>(state);
      }
    }
    return true;
  }

  // Bit sx set when predecessor x-state sx has a finite cheapest state.
  static std::uint32_t ReachableMask(const std::array<double, 9>& cheapest) {
    std::uint32_t mask = 0;
    for (int sx = 0; sx < 9; ++sx) {
      if (cheapest[sx] != kInf) mask |= 1u << sx;
    }
    return mask;
  }

  // Whether combination (sx, tx) is looked at: its predecessor x-state reachable and, into the
  // last key, its target x offset 0.
  static bool Considered(const KeyGrid& gb, const std::array<double, 9>& cheapest, int sx,
                         int tx) {
    return cheapest[sx] != kInf && (!gb.x_fixed || XIndex(tx) == 1);
  }

  // known[sx * 9 + tx] = Considered(gb, cheapest, sx, tx), a row of nine at a time.
  static void MarkConsidered(const KeyGrid& gb, const std::array<double, 9>& cheapest,
                             std::array<bool, kStates>& known) {
    std::array<bool, 9> row;
    for (int tx = 0; tx < 9; ++tx) row[tx] = !gb.x_fixed || XIndex(tx) == 1;
    constexpr std::array<bool, 9> kNone{};
    for (int sx = 0; sx < 9; ++sx) {
      const std::array<bool, 9>& from = cheapest[sx] != kInf ? row : kNone;
      std::copy(from.begin(), from.end(), known.begin() + sx * 9);
    }
  }

  // Copies into `next` the inputs and feasibility of the combinations that `previous` (built for
  // the grids in `signature`) knows under the same four x values, marking them in `taken`.
  static void TakeSharedInputs(const FormSignature& signature, const KeyGrid& ga,
                               const KeyGrid& gb, const std::array<double, 9>& cheapest,
                               const FormMemo::Buffer& previous, FormMemo::Buffer& next,
                               std::array<bool, kStates>& taken) {
    // For each grid value of this pass, its index in the last pass's grid (-1: not there).
    const std::array<const std::array<double, 3>*, 4> grids = {&ga.x, &ga.tx, &gb.x, &gb.tx};
    std::array<std::array<int, 3>, 4> index;
    for (int k = 0; k < 4; ++k) {
      for (int o = 0; o < 3; ++o) {
        index[k][o] = -1;
        for (int m = 0; m < 3; ++m) {
          if ((*grids[k])[o] == signature.x[k * 3 + m]) index[k][o] = m;
        }
      }
    }
    for (int sx = 0; sx < 9; ++sx) {
      for (int tx = 0; tx < 9; ++tx) {
        if (!Considered(gb, cheapest, sx, tx)) continue;
        const int ix_a = index[0][XIndex(sx)], itx_a = index[1][TxIndex(sx)];
        const int ix_b = index[2][XIndex(tx)], itx_b = index[3][TxIndex(tx)];
        if (ix_a < 0 || itx_a < 0 || ix_b < 0 || itx_b < 0) continue;
        const int from = (ix_a * 3 + itx_a) * 9 + ix_b * 3 + itx_b;
        if (!previous.known[from]) continue;
        const int c = sx * 9 + tx;
        taken[c] = true;
        next.feasible[c] = previous.feasible[from];
        for (int l = 0; l < 4; ++l) next.inputs.data[l][c] = previous.inputs.data[l][from];
        for (int l = 0; l < kGramSize; ++l) next.inputs.gram[l][c] = previous.inputs.gram[l][from];
        next.inputs.squares[c] = previous.inputs.squares[from];
      }
    }
  }

  // The feasible combinations of segment ga -> gb and their form inputs, except those marked in
  // `taken` (when given), whose feasibility and inputs are already set; `feasible` starts all
  // false. False when a stop was requested part way.
  bool PrepareForms(const KeyGrid& ga, const KeyGrid& gb, bool last,
                    const std::array<double, 9>& cheapest, double y_ref,
                    const std::array<bool, kStates>* taken, std::array<bool, kStates>& feasible,
                    FormInputs& inputs) {
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
    std::array<std::uint64_t, kStates> hashes;
    std::array<std::int8_t, kStates> key_of_combo;
    std::array<std::int8_t, kStates> combos;
    int combo_count = 0;
    int key_count = 0;
    // Whether each combination passes InsideAndFeasible(), for the rows below.
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
            if (taken != nullptr && (*taken)[sx * 9 + tx]) continue;
            const double ax = ga.x[ix_a];
            const double atx = ga.tx[itx_a];
            const double bx = gb.x[ix_b];
            const double btx = gb.tx[itx_b];
            if (!InsideAndFeasible(ax, atx, bx, btx)) continue;
            const int combo = sx * 9 + tx;
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
              hashes[key_count] = HashShapeKey(key);
              cache_.Prefetch(hashes[key_count]);
              keys[key_count++] = key;
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
      entries[k] = cache_.Get(keys[k], hashes[k]);
      __builtin_prefetch(entries[k].record);
    }
    for (int c = 0; c < combo_count; ++c) shapes[combos[c]].entry = entries[key_of_combo[c]];

    return GatherFormInputs(shapes, feasible, taken, y_ref, inputs);
  }

  // The form inputs of every combination (FormInputs), the data terms summed for the nine
  // combinations of each pair of x offsets together (they share their frames), in pieces of
  // kDpStopCheckFrames frames between looks at the stop token; false when a stop was requested.
  bool GatherFormInputs(const std::array<SegmentShape, kStates>& shapes,
                        const std::array<bool, kStates>& feasible,
                        const std::array<bool, kStates>* taken, double y_ref,
                        FormInputs& inputs) {
    for (int ix_a = 0; ix_a < 3; ++ix_a) {
      for (int ix_b = 0; ix_b < 3; ++ix_b) {
        std::array<int, 9> combo;
        std::array<const double*, 9> basis{};
        std::array<bool, 9> used{};
        const SegmentShape* some = nullptr;
        for (int j = 0; j < 9; ++j) {
          const int sx = ix_a * 3 + j / 3;
          const int tx = ix_b * 3 + j % 3;
          combo[j] = sx * 9 + tx;
          if (taken != nullptr && (*taken)[combo[j]]) continue;
          const SegmentShape& shape = shapes[combo[j]];
          // A frame count that does not match the shape is unreachable (see ShapeEntry). An
          // infeasible combination's shape is left uninitialised: read only when feasible.
          used[j] = feasible[combo[j]] && shape.n > 0 && shape.n >= shape.entry.count - 1 &&
                    shape.n <= shape.entry.count;
          if (used[j]) {
            basis[j] = shape.entry.basis();
            some = &shape;
          }
        }
        std::array<std::array<double, 4>, 9> sums;  // set by SumDataTerms() from frame 0
        if (some != nullptr) {
          // Combinations not used sum along on a used one's rows (their sums are dropped).
          for (auto& row : basis) {
            if (row == nullptr) row = some->entry.basis();
          }
          const double* sample = samples_.data() + some->first;
          for (std::int64_t k = 0; k < some->n; k += kDpStopCheckFrames) {
            const std::int64_t end = std::min<std::int64_t>(some->n, k + kDpStopCheckFrames);
            SumDataTerms(sample, k, end, y_ref, basis, sums);
            if (Stopping(9 * (end - k))) return false;
          }
        }
        for (int j = 0; j < 9; ++j) {
          const int c = combo[j];
          if (taken != nullptr && (*taken)[c]) continue;
          const SegmentShape& shape = shapes[c];
          if (used[j]) {
            const double* g = shape.n == shape.entry.count ? shape.entry.gram_all()
                                                           : shape.entry.gram_but_last();
            for (int l = 0; l < 4; ++l) inputs.data[l][c] = sums[j][l];
            for (int l = 0; l < kGramSize; ++l) inputs.gram[l][c] = g[l];
            inputs.squares[c] = shape.squares;
          } else {
            for (int l = 0; l < 4; ++l) inputs.data[l][c] = 0.0;
            for (int l = 0; l < kGramSize; ++l) inputs.gram[l][c] = 0.0;
            const bool mismatched = feasible[c] && shape.n > 0;
            inputs.squares[c] = mismatched ? kInf : 0.0;
          }
        }
      }
    }
    return true;
  }

  // The candidate of predecessor state sx * 9 + sy for target state tx * 9 + ty, exactly as
  // UpdateTargetMinima() computes it.
  static double Candidate(const Workspace& work, const std::array<double, kStates>& in, int sx,
                          int sy, int tx, int ty) {
    const int c = sx * 9 + tx;
    const double d0 = kOffsetHigh[sy];
    const double d1 = kOffsetLow[sy];
    const RowTerms& t = work.terms;
    const double u = d0 < 0.0 ? -t.z0[ty][c] : (d0 > 0.0 ? t.z0[ty][c] : 0.0);
    const double v = d1 < 0.0 ? -t.z1[ty][c] : (d1 > 0.0 ? t.z1[ty][c] : 0.0);
    return (in[sx * 9 + sy] + t.alpha[sy][c]) + ((t.b[ty][c] + u) + v);
  }

  // The tie rule for target state (tx, ty) over the predecessors folded toward it.
  std::pair<double, int> ChooseForTarget(const Workspace& work,
                                         const std::array<double, kStates>& in, int tx,
                                         int ty) const {
    const int lane = TargetLane(tx, ty);
    const double m = work.minima.least[lane];
    if (m == kInf) return {kInf, -1};
    const double window = m + TieTolerance(m, scale_);
    if (work.minima.second[lane] > window) return {m, static_cast<int>(work.minima.state[lane])};
    // Several candidates in the window: state 40 if among them, else the lowest state.
    double best_value = kInf;
    int best_state = -1;
    for (int r = 0; r < work.folded; ++r) {
      if ((work.folded_rows[r] >> tx & 1u) == 0) continue;
      const int sx = work.folded_sx[r];
      for (int sy = 0; sy < 9; ++sy) {
        const double c = Candidate(work, in, sx, sy, tx, ty);
        if (!(c <= window)) continue;
        const int state = sx * 9 + sy;
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
  FormMemo* memo_;
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
  FormMemo& memo = ThreadFormMemo();
  memo.Start(result.keys.size() - 1);
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const double largest =
        std::max({steps.x, steps.y, steps.tangent_x, steps.tangent_y});
    if (largest < options.accuracy) break;
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    cache.TrimIfLarge();
    std::optional<HermiteDpPass> run =
        DpPass(samples, result.keys, steps, cache, stop, &memo).Run();
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
