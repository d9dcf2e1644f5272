#include "tempokey/core/retime/resample.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <numbers>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/src/simd/block_scan.h"
#include "core/src/simd/instruction_set.h"
#include "core/src/simd/vector_trig.h"
#include "core/src/simd/vectors.h"
#include "rotation_batch.h"

namespace tempokey::core {
namespace {

// Adjacent source rotations further apart than retime_internal::kDiscontinuityDot, 150 degrees,
// are a discontinuity (a capture glitch or a flipped solve: CMU 131_01's thumb flips by 171-179
// degrees between frames, and no other step of the shared clips exceeds 60). Interpolating
// across one would invent a half turn whose direction near 180 degrees is a coin toss, so samples
// between them take the nearer source pose instead. Real turns up to 150 degrees a frame (a fast
// spin at 24 or 30 fps) are interpolated: a threshold of 90 degrees held such spins in steps.
// Compared as |q_i·q_{i+1}| < cos(150° / 2).
using retime_internal::kDiscontinuityDot;

// Weights below this are dropped from the ends of a span; they are exact zeros analytically
// (outside the kernel's support) and only rounding makes them non-zero.
constexpr double kNegligibleWeight = 1e-300;

double Hat(double d) { return std::max(0.0, 1.0 - std::abs(d)); }

// Tent and box half-widths below this (source samples) count as no filter.
constexpr double kMinKernelWidth = 1e-100;

// Looks at a stop token once per kResampleStopCheckTaps units of work, given the running total.
class StopCheck {
 public:
  explicit StopCheck(const std::stop_token& stop) : stop_(stop) {}
  // True when `work` passed the next check point and a stop was requested.
  bool After(std::int64_t work) {
    if (work < next_) return false;
    next_ = work + kResampleStopCheckTaps;
    return stop_.stop_requested();
  }

 private:
  const std::stop_token& stop_;
  std::int64_t next_ = 0;
};

// Adds weight `w` for virtual index `i` to `taps`, folding indices outside [0, last] by odd
// reflection about the end sample: f(-k) = 2f(0) - f(k), f(L + k) = 2f(L) - f(L - k).
void AddFolded(std::int64_t i, double w, std::int64_t last, std::vector<std::pair<std::int64_t, double>>& taps) {
  if (i < 0) {
    AddFolded(0, 2.0 * w, last, taps);
    AddFolded(-i, -w, last, taps);
    return;
  }
  if (i > last) {
    AddFolded(last, 2.0 * w, last, taps);
    AddFolded(2 * last - i, -w, last, taps);
    return;
  }
  taps.emplace_back(i, w);
}

// Planning state for one output sample.
class PlanWriter {
 public:
  explicit PlanWriter(ResamplePlan& plan) : plan_(plan) {}

  void Copy(std::int64_t index) {
    ++plan_.copy_count;
    Begin(SampleKind::kCopy, index);
    plan_.weights.push_back(1.0);
    End();
  }

  void Lerp(std::int64_t i0, double t) {
    Begin(SampleKind::kLerp, i0);
    plan_.weights.push_back(1.0 - t);
    plan_.weights.push_back(t);
    End();
  }

  // A kernel given as (index, weight) pairs in any order, possibly repeated.
  void Taps(SampleKind kind, std::vector<std::pair<std::int64_t, double>>& taps) {
    std::sort(taps.begin(), taps.end());
    const std::int64_t lo = taps.front().first;
    const std::int64_t hi = taps.back().first;
    Begin(kind, lo);
    const std::size_t base = plan_.weights.size();
    plan_.weights.resize(base + static_cast<std::size_t>(hi - lo + 1), 0.0);
    for (const auto& [i, w] : taps) plan_.weights[base + static_cast<std::size_t>(i - lo)] += w;
    End();
  }

  // A kernel over the source indices whose offset d = i - x lies in (-support, support), trimmed
  // of zero weights at both ends: `weights(lo, x, w)` fills w[k] with the weight of offset
  // double(lo + k) - x for every k < w.size().
  template <class WeightsFn>
  void Kernel(double x, double support, std::int64_t last, WeightsFn weights) {
    std::int64_t lo = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor(x - support)));
    std::int64_t hi = std::min<std::int64_t>(last, static_cast<std::int64_t>(std::ceil(x + support)));
    std::vector<double>& w = scratch_;
    w.resize(static_cast<std::size_t>(hi - lo + 1));
    weights(lo, x, std::span<double>(w));
    std::size_t a = 0;
    std::size_t b = w.size();
    while (a + 1 < b && std::abs(w[a]) < kNegligibleWeight) ++a;
    while (b > a + 1 && std::abs(w[b - 1]) < kNegligibleWeight) --b;
    Begin(SampleKind::kWeighted, lo + static_cast<std::int64_t>(a));
    plan_.weights.insert(plan_.weights.end(), w.begin() + static_cast<std::ptrdiff_t>(a),
                         w.begin() + static_cast<std::ptrdiff_t>(b));
    End();
  }

 private:
  void Begin(SampleKind kind, std::int64_t first) {
    plan_.kind.push_back(kind);
    plan_.first.push_back(first);
  }
  void End() { plan_.offset.push_back(static_cast<std::int64_t>(plan_.weights.size())); }

  ResamplePlan& plan_;
  std::vector<double> scratch_;
};

void PlanCatmullRom(PlanWriter& writer, double x, std::int64_t last) {
  const std::int64_t i0 = std::min(static_cast<std::int64_t>(std::floor(x)), last - 1);
  const double t = x - static_cast<double>(i0);
  const double t2 = t * t;
  const double t3 = t2 * t;
  const double w[4] = {0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
                       0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2)};
  std::vector<std::pair<std::int64_t, double>> taps;
  for (int k = 0; k < 4; ++k) AddFolded(i0 - 1 + k, w[k], last, taps);
  writer.Taps(SampleKind::kCubic, taps);
}

void PlanLanczos(PlanWriter& writer, double x, double scale, std::int64_t last) {
  const double support = 3.0 * scale;
  const auto lo = static_cast<std::int64_t>(std::floor(x - support)) + 1;
  const auto hi = static_cast<std::int64_t>(std::ceil(x + support)) - 1;
  std::vector<std::pair<std::int64_t, double>> raw;
  double sum = 0.0;
  for (std::int64_t i = lo; i <= hi; ++i) {
    const double w = Lanczos3((static_cast<double>(i) - x) / scale);
    if (w == 0.0) continue;
    raw.emplace_back(i, w);
    sum += w;
  }
  std::vector<std::pair<std::int64_t, double>> taps;
  for (const auto& [i, w] : raw) AddFolded(i, w / sum, last, taps);
  writer.Taps(SampleKind::kWeighted, taps);
}

// The unwrapped copy of an angle channel, when it has any seam (a step over 180 degrees).
struct Unwrapped {
  std::vector<double> values;
  bool wraps = false;
};

// The channel scans are cloned with AVX2 (TEMPOKEY_CLONES_AVX2) beside the portable build.
TEMPOKEY_CLONES_AVX2 bool HasWrap(std::span<const double> degrees) {
  // Steps in blocks (simd/block_scan.h): most channels have no seam and are read to the end.
  using simd::ScanMask;
  using simd::ScanVector;
  const double* d = degrees.data();
  const std::size_t n = degrees.size();
  const auto seam = [](const double* p) __attribute__((always_inline)) {
    const ScanVector step = simd::LoadScanVector(p) - simd::LoadScanVector(p - 1);
    // |step| by clearing the sign bit.
    const ScanVector size =
        (ScanVector)((ScanMask)step & std::numeric_limits<std::int64_t>::max());
    return size > 180.0;
  };
  std::size_t i = simd::FirstFlaggedBlock(d, 1, n, seam);
  for (; i < n; ++i) {
    if (std::abs(d[i] - d[i - 1]) > 180.0) return true;
  }
  return false;
}

// True when every source sample of `channel` compares equal to the first one.
TEMPOKEY_CLONES_AVX2 bool IsConstant(std::span<const double> channel) {
  // In blocks (simd/block_scan.h; GCC left a scalar block loop as a comparison per sample): most
  // channels are read to the end or differ early.
  const double first = channel[0];
  const auto differs = [first](const double* p) __attribute__((always_inline)) {
    return simd::LoadScanVector(p) != first;
  };
  std::size_t i = simd::FirstFlaggedBlock(channel.data(), 0, channel.size(), differs);
  for (; i < channel.size(); ++i) {
    if (channel[i] != first) return false;
  }
  return true;
}

// IsConstant() in chunks, the stop token looked at between them (a long channel takes tens of
// milliseconds); false as well when a stop is requested (the caller looks at the token after).
bool IsConstantChannel(std::span<const double> channel, const std::stop_token& stop) {
  constexpr auto kChunk = static_cast<std::size_t>(kResampleStopCheckTaps);
  for (std::size_t begin = 0; begin < channel.size(); begin += kChunk) {
    if (stop.stop_requested()) return false;
    const std::span<const double> chunk =
        channel.subspan(begin, std::min(kChunk, channel.size() - begin));
    if (chunk[0] != channel[0] || !IsConstant(chunk)) return false;
  }
  return true;
}

// The first output in [from, end) of kind kCopy, or `end`: a byte search (SampleKind is one
// byte), where a loop over the kinds took a comparison and branch per output, for every joint
// (most outputs of a decimation or a slowed section are not copies).
std::size_t NextCopy(const ResamplePlan& plan, std::size_t from, std::size_t end) {
  static_assert(sizeof(SampleKind) == 1);
  if (from >= end) return end;
  const auto* kinds = reinterpret_cast<const unsigned char*>(plan.kind.data());
  // Runs of copies (identity stretches) take no call.
  if (kinds[from] == static_cast<unsigned char>(SampleKind::kCopy)) return from;
  const void* found = std::memchr(kinds + from, static_cast<int>(SampleKind::kCopy), end - from);
  return found == nullptr ? end
                          : static_cast<std::size_t>(static_cast<const unsigned char*>(found) - kinds);
}

// Calls copy(j) for every output j in [begin, end) of kind kCopy, in order, looking at `stop`
// once per kResampleStopCheckTaps outputs: false when a stop was requested on the way.
template <class CopyFn>
bool ForEachCopy(const ResamplePlan& plan, std::size_t begin, std::size_t end,
                 const std::stop_token& stop, CopyFn copy) {
  constexpr auto kChunk = static_cast<std::size_t>(kResampleStopCheckTaps);
  for (std::size_t chunk = begin; chunk < end; chunk += kChunk) {
    if (stop.stop_requested()) return false;
    const std::size_t chunk_end = std::min(end, chunk + kChunk);
    for (std::size_t j = NextCopy(plan, chunk, chunk_end); j < chunk_end;
         j = NextCopy(plan, j + 1, chunk_end)) {
      copy(j);
    }
  }
  return true;
}

// The outputs of a channel whose samples all compare equal (IsConstantChannel()): copies keep
// their own sample's bits (-0 and +0 compare equal), every other output is the first sample.
void WriteConstant(const ResamplePlan& plan, std::span<const double> source,
                   std::span<double> out, const std::stop_token& stop) {
  std::fill(out.begin(), out.end(), source[0]);
  // Non-zero doubles that compare equal have the same bits (and are not NaN), so the copies are
  // written already: only a channel of zeros can hold two different samples.
  if (source[0] != 0.0) return;
  ForEachCopy(plan, 0, out.size(), stop, [&](std::size_t j) {
    out[j] = source[static_cast<std::size_t>(plan.first[j])];
  });
}

void Unwrap(std::span<const double> degrees, Unwrapped& out) {
  out.wraps = HasWrap(degrees);
  if (!out.wraps) return;
  out.values.assign(degrees.begin(), degrees.end());
  UnwrapDegrees(out.values);
}

// `angle` moved by whole turns to within 180 degrees of `source_value`: results keep the
// source's own convention (wrapped into ±180, or unwrapped, whatever the file uses).
double InSourceTurn(double angle, double source_value) { return NearestTurn(angle, source_value); }

// std::llround(x) clamped to [0, last], for x >= 0 (positions are): halves away from zero, as
// llround does, without its libm call. x - trunc(x) is exact.
std::int64_t NearestIndex(double x, std::int64_t last) {
  auto i = static_cast<std::int64_t>(x);
  if (x - static_cast<double>(i) >= 0.5) ++i;
  return std::min(i, last);
}

// Dot() of rotation.h, inlined here: the per-sample loops call it for every tap.
inline double QuatDot(const Quat& a, const Quat& b) {
  return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
}

}  // namespace

double TentHalfWidth(double ratio) { return ratio * std::clamp(ratio - 1.0, 0.0, 1.0); }
double BoxHalfWidth(double ratio) { return 0.5 * ratio * std::clamp(ratio - 1.0, 0.0, 1.0); }

namespace {

// TentWeight() for a >= kMinKernelWidth, given inv = 1 / (6 a^2) (finite): a kernel's taps share
// one division.
double TentWeightWithInverse(double d, double a, double inv) {
  auto e = [&](double z) {
    // r clamped at zero, then cubed: (+0)^3 inv is the +0 a branch to 0.0 would give (GCC still
    // compiles the clamp to a branch here; TentWeights() evaluates it on vectors).
    const double r = a - std::abs(z);
    const double positive = r > 0.0 ? r : 0.0;
    return positive * positive * positive * inv;
  };
  return Hat(d) + e(d + 1.0) - 2.0 * e(d) + e(d - 1.0);
}

double TentInverse(double a) { return 1.0 / (6.0 * a * a); }

// weight(double(first + k) - x) into w[k] for every k in [from, w.size()), one at a time.
template <class WeightFn>
void WeightsOneByOne(std::int64_t first, double x, std::span<double> w, std::size_t from,
                     WeightFn weight) {
  for (std::size_t k = from; k < w.size(); ++k) {
    const auto i = first + static_cast<std::int64_t>(k);
    w[k] = weight(static_cast<double>(i) - x);
  }
}

// TentWeightWithInverse(double(first + k) - x, a, inv) into w[k] for every k: four offsets at a
// time on vectors (simd/vectors.h), each lane with the scalar's operations in its order, so the
// same bits. Evaluated one at a time, about 25 cycles a weight (the clamps compiled to branches),
// the weights were most of the plan's time (the plan: 5.7 % of 131_01 -> 30 fps; 3.7 % since, its
// weights 2.2 %).
TEMPOKEY_CLONES_AVX2 void TentWeights(std::int64_t first, double x, double a, double inv,
                                      std::span<double> w) {
  using simd::V4;
  const auto e = [a, inv](V4 z) __attribute__((always_inline)) {
    const V4 r = a - simd::Abs(z);
    const V4 positive = r > 0.0 ? r : 0.0;
    return positive * positive * positive * inv;
  };
  const auto weight = [&e](V4 d) __attribute__((always_inline)) {
    const V4 hat_arm = 1.0 - simd::Abs(d);
    const V4 hat = 0.0 < hat_arm ? hat_arm : 0.0;  // std::max(0.0, hat_arm)
    return hat + e(d + 1.0) - 2.0 * e(d) + e(d - 1.0);
  };
  std::size_t k = 0;
  const auto base = static_cast<double>(first);  // first + k is exact: indices are below 2^53
  for (; k + 4 <= w.size(); k += 4) {
    const auto kd = static_cast<double>(k);
    const V4 index = base + (kd + V4{0.0, 1.0, 2.0, 3.0});
    simd::Store(w.data() + k, weight(index - x));
  }
  WeightsOneByOne(first, x, w, k, [a, inv](double d) { return TentWeightWithInverse(d, a, inv); });
}

}  // namespace

double TentWeight(double d, double a) {
  // Below kMinKernelWidth (the plan's floor) 1 / (6 a^2) would be infinite.
  if (a < kMinKernelWidth) return Hat(d);
  return TentWeightWithInverse(d, a, TentInverse(a));
}

double BoxWeight(double d, double b) {
  if (b <= 0.0) return Hat(d);
  const double inv = 1.0 / (4.0 * b);
  auto f = [&](double z) {
    const double r = b - std::abs(z);
    return r > 0.0 ? r * r * inv : 0.0;
  };
  return Hat(d) + f(d + 1.0) - 2.0 * f(d) + f(d - 1.0);
}

double Lanczos3(double u) {
  const double au = std::abs(u);
  if (au >= 3.0) return 0.0;
  if (au < 1e-12) return 1.0;
  const double pu = std::numbers::pi * u;
  return 3.0 * std::sin(pu) * std::sin(pu / 3.0) / (pu * pu);
}

absl::StatusOr<ResamplePlan> MakeResamplePlan(std::span<const double> positions,
                                              std::span<const double> ratios,
                                              std::int64_t source_count, ResampleFilter filter,
                                              std::stop_token stop) {
  if (positions.size() != ratios.size()) {
    return absl::InvalidArgumentError(absl::StrCat("resample plan: ", positions.size(),
                                                   " positions but ", ratios.size(), " ratios"));
  }
  if (source_count < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("resample plan: the source needs at least 1 sample, got ", source_count));
  }
  const std::size_t m = positions.size();
  ResamplePlan plan;
  plan.source_count = source_count;
  plan.position.resize(m);
  plan.width.resize(m);
  plan.kind.reserve(m);
  plan.first.reserve(m);
  plan.offset.reserve(m + 1);
  plan.offset.push_back(0);
  plan.weights.reserve(m * 2);
  PlanWriter writer(plan);
  const std::int64_t last = source_count - 1;
  const auto last_d = static_cast<double>(last);

  StopCheck check(stop);
  for (std::size_t j = 0; j < m; ++j) {
    if (check.After(static_cast<std::int64_t>(plan.weights.size()))) {
      return absl::CancelledError("cancelled");
    }
    const double rho = ratios[j];
    if (!std::isfinite(positions[j]) || !std::isfinite(rho) || rho < 0.0) {
      return absl::InvalidArgumentError(absl::StrCat("resample plan: output sample ", j,
                                                     " has position ", positions[j],
                                                     " and ratio ", rho));
    }
    const double x = std::clamp(positions[j], 0.0, last_d);
    plan.position[j] = x;
    plan.max_ratio = std::max(plan.max_ratio, rho);
    if (last == 0) {
      writer.Copy(0);
      continue;
    }
    const bool at_end = x == 0.0 || x == last_d;
    const bool on_sample = x == std::floor(x);

    double width = 0.0;
    switch (filter) {
      case ResampleFilter::kLinear:
        break;
      case ResampleFilter::kTent:
      case ResampleFilter::kCubic:
        width = std::min({TentHalfWidth(rho), x, last_d - x});
        break;
      case ResampleFilter::kBox:
        width = std::min({BoxHalfWidth(rho), x, last_d - x});
        break;
      case ResampleFilter::kLanczos3:
        width = std::max(1.0, rho) - 1.0;
        break;
    }
    // A narrower tent or box changes no sample beyond rounding, and its weights would divide by
    // a width squared to zero (found by fuzzing: a position 1e-315 frames from the start got a
    // subnormal width and NaN weights).
    if (filter != ResampleFilter::kLanczos3 && width < kMinKernelWidth) width = 0.0;
    plan.width[j] = width;
    if (width > 0.0) ++plan.filtered_count;

    if (at_end || (on_sample && width == 0.0)) {
      writer.Copy(static_cast<std::int64_t>(x));
      continue;
    }
    switch (filter) {
      case ResampleFilter::kLanczos3:
        PlanLanczos(writer, x, width + 1.0, last);
        continue;
      case ResampleFilter::kBox:
        if (width > 0.0) {
          writer.Kernel(x, 1.0 + width, last,
                        [width](std::int64_t first, double at, std::span<double> w) {
                          WeightsOneByOne(first, at, w, 0,
                                          [width](double d) { return BoxWeight(d, width); });
                        });
          continue;
        }
        break;
      case ResampleFilter::kTent:
      case ResampleFilter::kCubic:
        if (width > 0.0) {
          const double inv = TentInverse(width);
          writer.Kernel(x, 1.0 + width, last,
                        [width, inv](std::int64_t first, double at, std::span<double> w) {
                          TentWeights(first, at, width, inv, w);
                        });
          continue;
        }
        if (filter == ResampleFilter::kCubic) {
          PlanCatmullRom(writer, x, last);
          continue;
        }
        break;
      case ResampleFilter::kLinear:
        break;
    }
    const std::int64_t i0 = std::min(static_cast<std::int64_t>(std::floor(x)), last - 1);
    writer.Lerp(i0, x - static_cast<double>(i0));
  }
  return plan;
}

void ResampleScalar(const ResamplePlan& plan, std::span<const double> source,
                    std::span<double> out, std::stop_token stop) {
  // A channel that never changes (most position channels of a BVH file are its bones' offsets:
  // 60 of each Bandai clip's 66) resamples to its own value at every output, for every filter:
  // each output's weights sum to one, and the odd reflection past the ends keeps a constant. The
  // value itself is the exact answer, where the weighted sums give it to within a unit or so in
  // the last place.
  if (!source.empty() && IsConstantChannel(source, stop)) {
    WriteConstant(plan, source, out, stop);
    return;
  }
  if (stop.stop_requested()) return;
  const double* src = source.data();
  const double* weights = plan.weights.data();
  const std::int64_t* first = plan.first.data();
  const std::int64_t* offset = plan.offset.data();
  const std::size_t m = out.size();
  StopCheck check(stop);
  for (std::size_t j = 0; j < m; ++j) {
    if (check.After(offset[j])) return;
    const double* s = src + first[j];
    const double* w = weights + offset[j];
    const std::int64_t n = offset[j + 1] - offset[j];
    double acc = w[0] * s[0];
    for (std::int64_t k = 1; k < n; ++k) acc += w[k] * s[k];
    out[j] = acc;
  }
}

void ResampleAngle(const ResamplePlan& plan, std::span<const double> degrees,
                   std::span<double> out, std::stop_token stop) {
  Unwrapped unwrapped;
  Unwrap(degrees, unwrapped);
  if (!unwrapped.wraps) {
    ResampleScalar(plan, degrees, out, stop);
    return;
  }
  ResampleScalar(plan, unwrapped.values, out, stop);
  if (stop.stop_requested()) return;
  const std::int64_t last = plan.source_count - 1;
  for (std::size_t j = 0; j < out.size(); ++j) {
    const auto k = static_cast<std::size_t>(NearestIndex(plan.position[j], last));
    out[j] = plan.kind[j] == SampleKind::kCopy
                 ? degrees[static_cast<std::size_t>(plan.first[j])]
                 : InSourceTurn(out[j], degrees[k]);
  }
}

namespace {

// A joint whose three angles never change (end effectors and unused joints of a skeleton: a
// quarter of CMU's) interpolates to its own rotation at every output. Its samples are then the
// source's angles themselves: the exact answer, where the conversions to a quaternion and back
// give it to a few units in the last place (the reference's results, within 1e-13 degrees of
// it while the middle angle's cosine stays above kBatchedMinMiddleCos, which bounds how much a
// rotation's rounding moves the outer angles; nearer gimbal lock the general path's own
// safeguards apply).
// False as well when a stop is requested while it reads (the caller looks at the token after).
bool IsFixedRotation(const std::array<std::span<const double>, 3>& source,
                     const std::stop_token& stop) {
  for (const std::span<const double>& channel : source) {
    if (!IsConstantChannel(channel, stop)) return false;
  }
  const double middle_cos = std::cos(source[1][0] * (std::numbers::pi / 180.0));
  return std::abs(middle_cos) >= retime_internal::kBatchedMinMiddleCos;
}

// Outputs converted back to Euler angles per batch: bounds the scratch memory of a long clip.
constexpr std::size_t kRotationBatch = 1024;
// Most source rotations the samples of one batch read (see the schedule's batches).
constexpr std::int64_t kRotationStopTaps = kResampleStopCheckTaps / 16;
// The schedule lays out every batch's slots beforehand, once for all joints, when they take at
// most this; on longer clips each joint lays out one batch at a time into scratch (a little
// slower, in memory bounded by a batch's).
constexpr std::size_t kPrebuiltSlotBytes = std::size_t{64} << 20;

// The source quaternions the plan reads (RotationSchedule's runs), converted once each: a copy
// reads none. No global sign continuity is imposed: each use aligns signs locally (slerp takes the
// short arc, the weighted mean aligns to its pivot, squad aligns its four inputs).
class SourceQuats {
 public:
  // Converts in chunks into `storage` (grown to the clip's length, kept from joint to joint), the
  // stop token looked at between them; when a stop is requested it returns early, its quaternions
  // incomplete: the caller looks at the token after.
  SourceQuats(std::span<const std::pair<std::size_t, std::size_t>> runs, const EulerOrder& order,
              const std::array<std::span<const double>, 3>& source, const std::stop_token& stop,
              std::vector<double>& storage)
      : quats_(Grown(storage, 4 * source[0].size())) {
    // A chunk of conversions takes about a millisecond.
    constexpr auto kChunk = static_cast<std::size_t>(kResampleStopCheckTaps / 2);
    for (const auto& [run_begin, run_end] : runs) {
      for (std::size_t begin = run_begin; begin < run_end; begin += kChunk) {
        if (stop.stop_requested()) return;
        const std::size_t end = std::min(run_end, begin + kChunk);
        retime_internal::EulerToQuats(order, source[0].data() + begin, source[1].data() + begin,
                                      source[2].data() + begin, end - begin,
                                      quats_ + 4 * begin);
      }
    }
  }

  Quat operator[](std::size_t i) const {
    const double* q = quats_ + 4 * i;
    return {q[0], q[1], q[2], q[3]};
  }
  // (w, x, y, z) of every quaternion, one after the other (EulerToQuats()); only the runs' are
  // set.
  const double* data() const { return quats_; }

 private:
  static double* Grown(std::vector<double>& storage, std::size_t size) {
    if (storage.size() < size) storage.resize(size);
    return storage.data();
  }

  double* quats_;
};

// An array of n values left uninitialized: every batch writes its slots before reading them, and
// zeroing the scratch of every joint cost more than the short clips' whole resampling.
template <class T>
std::unique_ptr<T[]> Scratch(std::size_t n) {
  return std::make_unique_for_overwrite<T[]>(n);
}

// Quaternion columns of a fixed size.
struct QuatColumns {
  std::unique_ptr<double[]> w, x, y, z;

  void Resize(std::size_t n) {
    for (std::unique_ptr<double[]>* c : {&w, &x, &y, &z}) *c = Scratch<double>(n);
  }
  void Set(std::size_t i, const Quat& q) {
    w[i] = q.w;
    x[i] = q.x;
    y[i] = q.y;
    z[i] = q.z;
  }
  Quat Get(std::size_t i) const { return {w[i], x[i], y[i], z[i]}; }
  retime_internal::QuatArrays Arrays() { return {w.get(), x.get(), y.get(), z.get()}; }
  retime_internal::ConstQuatArrays Arrays() const { return {w.get(), x.get(), y.get(), z.get()}; }
};

// WeightedMeanRotation() with its default spread (whose cosine it takes every call, here once).
Quat WeightedMean(std::span<const Quat> quats, std::span<const double> weights, std::size_t pivot,
                  double min_dot) {
  const Quat& ref = quats[pivot];
  Quat sum{0.0, 0.0, 0.0, 0.0};
  for (std::size_t n = 0; n < quats.size(); ++n) {
    const double w = QuatDot(quats[n], ref) < 0.0 ? -weights[n] : weights[n];
    sum = {sum.w + quats[n].w * w, sum.x + quats[n].x * w, sum.y + quats[n].y * w,
           sum.z + quats[n].z * w};
  }
  const double norm = std::sqrt(QuatDot(sum, sum));
  if (!(norm > 1e-9)) return MarkleyMean(quats, weights, pivot);
  const double inverse = 1.0 / norm;
  const Quat mean{sum.w * inverse, sum.x * inverse, sum.y * inverse, sum.z * inverse};
  for (std::size_t n = 0; n < quats.size(); ++n) {
    if (weights[n] != 0.0 && std::abs(QuatDot(quats[n], mean)) < min_dot) {
      return MarkleyMean(quats, weights, pivot);
    }
  }
  return mean;
}

// The per-sample path with the scalar functions throughout, the source converted by
// EulerToQuat() itself: for the samples near gimbal lock, where the batched conversion's few
// units in the last place would be magnified (rotation_batch.h).
class ScalarRotationPath {
 public:
  // What the path converts and gathers, kept from joint to joint (RotationScratch).
  struct Memory {
    std::vector<Quat> quats;
    std::vector<unsigned char> converted;
    std::vector<Quat> taps;
  };

  ScalarRotationPath(const ResamplePlan& plan, const EulerOrder& order,
                     const std::array<std::span<const double>, 3>& source, double min_dot,
                     Memory& memory)
      : plan_(plan), order_(order), source_(source), min_dot_(min_dot), memory_(memory) {}

  // The interpolated rotation of output sample j (not a copy, not across a discontinuity).
  Quat Interpolated(std::size_t j) {
    const double x = plan_.position[j];
    const std::int64_t last = plan_.source_count - 1;
    const std::int64_t first = plan_.first[j];
    auto aligned = [](const Quat& q, const Quat& to) { return QuatDot(q, to) < 0.0 ? Negated(q) : q; };
    if (plan_.kind[j] == SampleKind::kLerp || plan_.kind[j] == SampleKind::kCubic) {
      const std::int64_t i0 = std::min(static_cast<std::int64_t>(std::floor(x)), last - 1);
      const double t = x - static_cast<double>(i0);
      const Quat q1 = At(i0);
      const Quat q2 = aligned(At(i0 + 1), q1);
      if (plan_.kind[j] == SampleKind::kLerp) return Slerp(q1, q2, t);
      const Quat q0 = aligned(At(i0 - 1), q1);
      const Quat q3 = aligned(At(i0 + 2), q2);
      const bool smooth = QuatDot(q0, q1) >= kDiscontinuityDot && QuatDot(q2, q3) >= kDiscontinuityDot;
      return smooth ? Squad(q0, q1, q2, q3, t) : Slerp(q1, q2, t);
    }
    const std::int64_t count = plan_.offset[j + 1] - plan_.offset[j];
    std::vector<Quat>& taps = memory_.taps;
    taps.resize(static_cast<std::size_t>(count));
    for (std::int64_t tap = 0; tap < count; ++tap) {
      taps[static_cast<std::size_t>(tap)] = At(first + tap);
    }
    const std::span<const double> w(plan_.weights.data() + plan_.offset[j],
                                    static_cast<std::size_t>(count));
    const auto k = NearestIndex(x, last);
    const std::int64_t pivot = std::clamp(k - first, std::int64_t{0}, count - 1);
    return WeightedMean(taps, w, static_cast<std::size_t>(pivot), min_dot_);
  }

 private:
  // Source rotation i, past the ends by reflection (q0·q1*·q0).
  Quat At(std::int64_t i) {
    const std::int64_t last = plan_.source_count - 1;
    if (i < 0) return Multiply(Multiply(Converted(0), Conjugate(Converted(1))), Converted(0));
    if (i > last) {
      return Multiply(Multiply(Converted(last), Conjugate(Converted(last - 1))), Converted(last));
    }
    return Converted(i);
  }

  const Quat& Converted(std::int64_t i) {
    // Set up on this joint's first use: most joints never take the scalar path.
    if (!started_) {
      memory_.quats.resize(static_cast<std::size_t>(plan_.source_count));
      memory_.converted.assign(memory_.quats.size(), 0);
      started_ = true;
    }
    const auto u = static_cast<std::size_t>(i);
    if (!memory_.converted[u]) {
      memory_.quats[u] = EulerToQuat(order_, {source_[0][u], source_[1][u], source_[2][u]});
      memory_.converted[u] = 1;
    }
    return memory_.quats[u];
  }

  const ResamplePlan& plan_;
  const EulerOrder& order_;
  const std::array<std::span<const double>, 3>& source_;
  double min_dot_;
  Memory& memory_;
  bool started_ = false;
};

}  // namespace


namespace {

// The interpolation interval and the nearest sample of output sample j (not a copy).
struct SlotPlace {
  std::int64_t i0;
  double t;
  std::int64_t nearest;
};

SlotPlace PlaceOf(const ResamplePlan& plan, std::size_t j) {
  const std::int64_t last = plan.source_count - 1;
  const double x = plan.position[j];
  const std::int64_t i0 =
      std::max<std::int64_t>(0, std::min(static_cast<std::int64_t>(std::floor(x)), last - 1));
  return {i0, x - static_cast<double>(i0), NearestIndex(x, last)};
}

// The samples of one batch that interpolate, in slots: the slerps, then the squads, then the
// weighted means. Per slot: the output index; the interval of the reference's linear
// interpolation (and of a slerp or squad), i0 = min(floor(x), last - 1) and t = x - i0; the
// nearest source sample. Either made once per batch by the schedule (short clips) or again for
// every batch of every joint into the same scratch (long clips: memory bounded by a batch's).
class BatchSlots {
 public:
  using Job = retime_internal::WeightedMeanJob;

  // The slots of the samples `interpolating` (output indices, ascending; at most kRotationBatch).
  // The storage only grows: made again for another batch, it keeps the larger one's.
  void Make(const ResamplePlan& plan, std::span<const std::size_t> interpolating) {
    std::size_t begin[3] = {0, 0, 0};  // lerps, cubics, weighted means (KindIndex())
    for (const std::size_t j : interpolating) ++begin[KindIndex(plan.kind[j])];
    size_ = interpolating.size();
    cubic_begin_ = begin[0];
    weighted_begin_ = begin[0] + begin[1];
    for (std::vector<std::int64_t>* v : {&output_, &i0_, &nearest_}) Grow(*v, size_);
    Grow(t_, size_);
    Grow(jobs_, begin[2]);
    Grow(groups_, (begin[2] + retime_internal::kMeanLanes - 1) / retime_internal::kMeanLanes);
    std::size_t next[3] = {0, cubic_begin_, weighted_begin_};
    for (const std::size_t j : interpolating) {
      const int kind = KindIndex(plan.kind[j]);
      const std::size_t slot = next[kind]++;
      const SlotPlace place = PlaceOf(plan, j);
      output_[slot] = static_cast<std::int64_t>(j);
      i0_[slot] = place.i0;
      t_[slot] = place.t;
      nearest_[slot] = place.nearest;
      if (kind != kWeightedIndex) continue;
      const std::int64_t first = plan.first[j];
      const std::int64_t count = plan.offset[j + 1] - plan.offset[j];
      jobs_[slot - weighted_begin_] = {
          first, count, plan.offset[j],
          first + std::clamp(place.nearest - first, std::int64_t{0}, count - 1)};
    }
    MakeMeanTables(plan);
  }

  std::size_t size() const { return size_; }
  std::size_t cubic_begin() const { return cubic_begin_; }
  std::size_t weighted_begin() const { return weighted_begin_; }
  const std::int64_t* output() const { return output_.data(); }
  const std::int64_t* i0() const { return i0_.data(); }
  const double* t() const { return t_.data(); }
  const std::int64_t* nearest() const { return nearest_.data(); }
  const Job& job(std::size_t s) const { return jobs_[s]; }
  retime_internal::MeanTables mean_tables() const {
    return {groups_.data(), tap_source_.data(), tap_weight_.data()};
  }

  // Bytes the slots of `slots` samples take, `means` of them weighted means in groups whose
  // tables hold `padded_taps` taps (MeanGroup).
  static std::size_t Bytes(std::size_t slots, std::size_t means, std::size_t padded_taps) {
    return slots * (3 * sizeof(std::int64_t) + sizeof(double)) + means * sizeof(Job) +
           (means / retime_internal::kMeanLanes + 1) * sizeof(retime_internal::MeanGroup) +
           padded_taps * (sizeof(std::int64_t) + sizeof(double));
  }

 private:
  template <class T>
  static void Grow(std::vector<T>& v, std::size_t n) {
    if (v.size() < n) v.resize(n);
  }

  static constexpr int kWeightedIndex = 2;
  static int KindIndex(SampleKind kind) {
    return kind == SampleKind::kLerp ? 0 : kind == SampleKind::kCubic ? 1 : kWeightedIndex;
  }

  // The lane-major tables of the weighted means (see MeanGroup).
  void MakeMeanTables(const ResamplePlan& plan) {
    constexpr std::size_t kLanes = retime_internal::kMeanLanes;
    const std::size_t end = size_ - weighted_begin_;
    std::size_t total = 0;
    for (std::size_t g = 0; g < end; g += kLanes) {
      std::int64_t taps = 0;
      for (std::size_t lane = 0; lane < kLanes && g + lane < end; ++lane) {
        taps = std::max(taps, jobs_[g + lane].count);
      }
      groups_[g / kLanes].taps = taps;
      total += kLanes * static_cast<std::size_t>(taps);
    }
    Grow(tap_source_, total);
    Grow(tap_weight_, total);
    std::size_t tap_begin = 0;
    for (std::size_t g = 0; g < end; g += kLanes) {
      retime_internal::MeanGroup& group = groups_[g / kLanes];
      group.tap_begin = tap_begin;
      for (std::size_t lane = 0; lane < kLanes; ++lane) {
        // Lanes past the last job repeat the first one, at weight 0.
        const bool real_lane = g + lane < end;
        const Job& job = jobs_[real_lane ? g + lane : g];
        group.pivot[lane] = job.pivot;
        const std::int64_t count = real_lane ? job.count : 0;
        std::int64_t* source = tap_source_.data() + tap_begin + lane;
        double* weight = tap_weight_.data() + tap_begin + lane;
        const double* w = plan.weights.data() + job.weight_offset;
        for (std::int64_t n = 0; n < count; ++n) {
          source[kLanes * static_cast<std::size_t>(n)] = job.first + n;
          weight[kLanes * static_cast<std::size_t>(n)] = w[n];
        }
        for (std::int64_t n = count; n < group.taps; ++n) {
          source[kLanes * static_cast<std::size_t>(n)] = job.pivot;
          weight[kLanes * static_cast<std::size_t>(n)] = 0.0;
        }
      }
      tap_begin += kLanes * static_cast<std::size_t>(group.taps);
    }
  }

  std::vector<std::int64_t> output_, i0_, nearest_;
  std::vector<double> t_;
  std::vector<Job> jobs_;
  std::vector<retime_internal::MeanGroup> groups_;
  std::vector<std::int64_t> tap_source_;
  std::vector<double> tap_weight_;
  std::size_t size_ = 0, cubic_begin_ = 0, weighted_begin_ = 0;
};

}  // namespace

struct RotationSchedule::Data {
  // Runs [begin, end) of the source samples some output reads.
  std::vector<std::pair<std::size_t, std::size_t>> runs;
  // The output samples in batches [begin, end) of consecutive samples, covering them all. A
  // batch's copies are written directly; its samples that interpolate (at most kRotationBatch,
  // reading at most about kRotationStopTaps source rotations) are laid out in slots (BatchSlots)
  // one batch at a time, so that the scratch is sized to one batch rather than to the clip.
  struct Batch {
    std::size_t begin, end;
  };
  std::vector<Batch> batches;
  std::size_t interpolating = 0;  // output samples that are not copies
  // The most samples that interpolate in one batch (at most kRotationBatch): the size of the
  // per-batch scratch (RotationScratch), so that a short clip's few outputs take only what they
  // use.
  std::size_t largest_batch = 0;
  // On clips whose slots take at most kPrebuiltSlotBytes, each batch's slots made once here and
  // shared by every joint (faster on the short clips most retimes see); empty otherwise.
  std::vector<BatchSlots> prebuilt;
  // False when the constructor saw a stop request and returned early: never used then.
  bool complete = false;
};

// What one joint's resampling allocates, kept for the next (RotationScratch): the batch arrays
// hold `capacity` slots, grown to the largest batch of the plans they serve. Allocated for each
// joint, a dozen allocations a joint, they took about a tenth of a short clip's retime (malloc and
// free in `perf record` of Bandai's walk at 2.5x, 146 frames); kept, that retime ran 14 % faster.
// Every buffer is written for the current joint before it is read: Unwrap() sets `wraps` each
// time, the scalar path clears its conversions on its first use for a joint, SourceQuats reads
// only the runs it has just converted, and each batch fills its slots and flags.
struct RotationScratch::Buffers {
  std::vector<double> source_quats;  // SourceQuats
  std::array<Unwrapped, 3> unwrapped;
  ScalarRotationPath::Memory scalar_path;
  std::vector<std::size_t> interpolating;
  BatchSlots slots;  // the batch's slots, on clips whose schedule has none prebuilt
  std::size_t capacity = 0;
  QuatColumns rotations;
  std::unique_ptr<unsigned char[]> copied;
  std::unique_ptr<unsigned char[]> ill_conditioned;
  // The weighted means whose spread asks for Markley's mean, and their slots.
  QuatColumns markley_means;
  std::unique_ptr<retime_internal::WeightedMeanJob[]> markley_jobs;
  std::unique_ptr<std::size_t[]> markley_slot;

  void Reserve(std::size_t batch) {
    if (batch <= capacity) return;
    capacity = batch;
    rotations.Resize(capacity);
    copied = Scratch<unsigned char>(capacity);
    ill_conditioned = Scratch<unsigned char>(capacity);
    markley_means.Resize(capacity);
    markley_jobs = Scratch<retime_internal::WeightedMeanJob>(capacity);
    markley_slot = Scratch<std::size_t>(capacity);
    interpolating.reserve(capacity);
  }
};

RotationScratch::RotationScratch() : buffers_(std::make_unique<Buffers>()) {}
RotationScratch::~RotationScratch() = default;
RotationScratch::RotationScratch(RotationScratch&&) noexcept = default;
RotationScratch& RotationScratch::operator=(RotationScratch&&) noexcept = default;

namespace {

// Marks the source samples output sample j (not a copy) reads.
void MarkNeeded(const ResamplePlan& plan, std::size_t j, std::vector<unsigned char>& needed) {
  const std::int64_t last = plan.source_count - 1;
  auto need = [&](std::int64_t i) {
    needed[static_cast<std::size_t>(std::clamp<std::int64_t>(i, 0, last))] = 1;
  };
  const std::int64_t first = plan.first[j];
  if (plan.kind[j] == SampleKind::kWeighted) {
    const std::int64_t end = first + plan.offset[j + 1] - plan.offset[j];
    for (std::int64_t i = first; i < end; ++i) need(i);
    return;
  }
  const std::int64_t i0 = PlaceOf(plan, j).i0;
  for (std::int64_t i = i0 - 1; i <= i0 + 2; ++i) need(i);
}

}  // namespace

RotationSchedule::RotationSchedule(const ResamplePlan& plan, std::stop_token stop)
    : data_(std::make_unique<Data>()) {
  Data& d = *data_;
  const auto n = static_cast<std::size_t>(plan.source_count);
  const std::size_t m = plan.position.size();
  std::vector<unsigned char> needed(n, 0);
  // The token is looked at once per kResampleStopCheckTaps outputs and taps.
  StopCheck check(stop);
  std::int64_t work = 0;
  // The size of the slots: the weighted means, and their tables' taps (a batch's weighted means
  // in groups of kMeanLanes, in order, each padded to its longest).
  std::size_t means = 0, padded_taps = 0;
  // A batch ends once kRotationBatch of its samples interpolate or they read kRotationStopTaps
  // source rotations, and the stop token is looked at between batches: a few milliseconds of
  // work at most, whatever the decimation ratio (batching changes no result: every step is per
  // sample).
  for (std::size_t j = 0; j < m;) {
    const std::size_t begin = j;
    std::size_t interpolating = 0, group_means = 0;
    std::int64_t group_taps = 0;
    for (std::int64_t taps_read = 0;
         j < m && interpolating < kRotationBatch && taps_read < kRotationStopTaps; ++j) {
      if (check.After(work)) return;
      ++work;
      if (plan.kind[j] == SampleKind::kCopy) continue;
      ++interpolating;
      const std::int64_t taps = plan.offset[j + 1] - plan.offset[j];
      taps_read += taps;
      work += taps;
      if (plan.kind[j] == SampleKind::kWeighted) {
        ++means;
        group_taps = std::max(group_taps, taps);
        if (++group_means == retime_internal::kMeanLanes) {
          padded_taps += retime_internal::kMeanLanes * static_cast<std::size_t>(group_taps);
          group_means = 0;
          group_taps = 0;
        }
      }
      MarkNeeded(plan, j, needed);
    }
    padded_taps += retime_internal::kMeanLanes * static_cast<std::size_t>(group_taps);
    d.interpolating += interpolating;
    d.largest_batch = std::max(d.largest_batch, interpolating);
    d.batches.push_back({begin, j});
  }
  for (std::size_t i = 0; i < n;) {
    if (check.After(work)) return;
    if (!needed[i]) {
      ++i;
      ++work;
      continue;
    }
    std::size_t end = i;
    while (end < n && needed[end]) ++end;
    d.runs.emplace_back(i, end);
    work += static_cast<std::int64_t>(end - i);
    i = end;
  }
  if (BatchSlots::Bytes(d.interpolating, means, padded_taps) <= kPrebuiltSlotBytes) {
    d.prebuilt.resize(d.batches.size());
    std::vector<std::size_t> interpolating;
    for (std::size_t b = 0; b < d.batches.size(); ++b) {
      if (stop.stop_requested()) return;
      interpolating.clear();
      for (std::size_t j = d.batches[b].begin; j < d.batches[b].end; ++j) {
        if (plan.kind[j] != SampleKind::kCopy) interpolating.push_back(j);
      }
      d.prebuilt[b].Make(plan, interpolating);
    }
  }
  d.complete = true;
}

RotationSchedule::~RotationSchedule() = default;
RotationSchedule::RotationSchedule(RotationSchedule&&) noexcept = default;
RotationSchedule& RotationSchedule::operator=(RotationSchedule&&) noexcept = default;

void ResampleRotation(const ResamplePlan& plan, const EulerOrder& order,
                      const std::array<std::span<const double>, 3>& source,
                      const std::array<std::span<double>, 3>& out, std::stop_token stop) {
  if (plan.copy_count == plan.output_count()) {
    for (std::size_t j = 0; j < plan.position.size(); ++j) {
      const auto i = static_cast<std::size_t>(plan.first[j]);
      for (int c = 0; c < 3; ++c) out[c][j] = source[c][i];
    }
    return;
  }
  const RotationSchedule schedule(plan, stop);
  // An incomplete schedule (a stop was requested) is never used.
  if (stop.stop_requested()) return;
  RotationScratch scratch;
  ResampleRotation(plan, schedule, scratch, order, source, out, stop);
}

namespace {

// The outputs of a joint whose rotation never changes (IsFixedRotation()): copies, and the
// source's angles everywhere else.
void WriteFixedRotation(const ResamplePlan& plan,
                        const std::array<std::span<const double>, 3>& source,
                        const std::array<std::span<double>, 3>& out, const std::stop_token& stop) {
  for (int c = 0; c < 3; ++c) WriteConstant(plan, source[c], out[c], stop);
}

// The first index in [from, end) where flags a[i] (or b[i], when b is given) are non-zero, or
// end: eight flags at a time (nearly all are zero, and a branch per flag cost more than the
// scalar fixes they mark).
std::size_t NextFlagged(const unsigned char* a, const unsigned char* b, std::size_t from,
                        std::size_t end) {
  std::size_t i = from;
  for (; i + 8 <= end; i += 8) {
    std::uint64_t word_a = 0, word_b = 0;
    std::memcpy(&word_a, a + i, sizeof word_a);
    if (b != nullptr) std::memcpy(&word_b, b + i, sizeof word_b);
    if ((word_a | word_b) != 0) break;
  }
  for (; i < end; ++i) {
    if (a[i] != 0 || (b != nullptr && b[i] != 0)) return i;
  }
  return end;
}

// Writes the copies among outputs [begin, end) and lists the others in `interpolating` (null when
// the schedule lists them already: the copies are then found by NextCopy()). A batch can span a
// long run of copies: false when a stop was requested on the way (`interpolating` then
// incomplete).
bool WriteCopies(const ResamplePlan& plan, std::size_t begin, std::size_t end,
                 const std::array<std::span<const double>, 3>& source,
                 const std::array<std::span<double>, 3>& out, const std::stop_token& stop,
                 std::vector<std::size_t>* interpolating) {
  auto write_copy = [&](std::size_t j) {
    const auto i = static_cast<std::size_t>(plan.first[j]);
    for (int c = 0; c < 3; ++c) out[c][j] = source[c][i];
  };
  if (interpolating == nullptr) return ForEachCopy(plan, begin, end, stop, write_copy);
  constexpr auto kChunk = static_cast<std::size_t>(kResampleStopCheckTaps);
  interpolating->clear();
  for (std::size_t j = begin; j < end; ++j) {
    if ((j - begin) % kChunk == kChunk - 1 && stop.stop_requested()) return false;
    if (plan.kind[j] != SampleKind::kCopy) {
      interpolating->push_back(j);
      continue;
    }
    write_copy(j);
  }
  return true;
}

}  // namespace

void ResampleRotation(const ResamplePlan& plan, const RotationSchedule& schedule,
                      RotationScratch& scratch, const EulerOrder& order,
                      const std::array<std::span<const double>, 3>& source,
                      const std::array<std::span<double>, 3>& out, std::stop_token stop) {
  const RotationSchedule::Data& d = schedule.data();
  if (!d.complete || stop.stop_requested()) return;
  const std::int64_t last = plan.source_count - 1;
  if (d.interpolating == 0) {
    // Copies alone.
    for (const RotationSchedule::Data::Batch& batch : d.batches) {
      if (!WriteCopies(plan, batch.begin, batch.end, source, out, stop, nullptr)) return;
    }
    return;
  }
  if (IsFixedRotation(source, stop)) {
    WriteFixedRotation(plan, source, out, stop);
    return;
  }

  RotationScratch::Buffers& memory = scratch.buffers();
  const SourceQuats quats(d.runs, order, source, stop, memory.source_quats);
  if (stop.stop_requested()) return;
  // Each a pass or two over a channel: tens of milliseconds at most on the longest clips.
  std::array<Unwrapped, 3>& unwrapped = memory.unwrapped;
  for (int c = 0; c < 3; ++c) {
    Unwrap(source[c], unwrapped[c]);
    if (stop.stop_requested()) return;
  }
  std::array<const double*, 3> reference_values;
  for (int c = 0; c < 3; ++c) {
    reference_values[c] = unwrapped[c].wraps ? unwrapped[c].values.data() : source[c].data();
  }
  auto aligned = [](const Quat& q, const Quat& to) { return QuatDot(q, to) < 0.0 ? Negated(q) : q; };
  // Neighbours past the ends by reflection (q0·q1*·q0), matching the scalar path's odd
  // reflection.
  auto quat_at = [&](std::int64_t i) -> Quat {
    if (i < 0) return Multiply(Multiply(quats[0], Conjugate(quats[1])), quats[0]);
    if (i > last) {
      const auto l = static_cast<std::size_t>(last);
      return Multiply(Multiply(quats[l], Conjugate(quats[l - 1])), quats[l]);
    }
    return quats[static_cast<std::size_t>(i)];
  };
  // WeightedMeanRotation()'s default: a rotation of angle theta from the mean has
  // |dot| = cos(theta / 2).
  const double min_dot = std::cos(0.5 * 30.0 * (std::numbers::pi / 180.0));
  ScalarRotationPath scalar_path(plan, order, source, min_dot, memory.scalar_path);

  // Per batch, each output in its slot: the interpolated rotations (slerps and weighted means
  // batched), then all of them back to Euler angles, written in place; then the few samples the
  // batched steps leave to the scalar ones.
  memory.Reserve(d.largest_batch);
  QuatColumns& rotations = memory.rotations;
  unsigned char* const copied = memory.copied.get();
  unsigned char* const ill_conditioned = memory.ill_conditioned.get();
  QuatColumns& markley_means = memory.markley_means;
  retime_internal::WeightedMeanJob* const markley_jobs = memory.markley_jobs.get();
  std::size_t* const markley_slot = memory.markley_slot.get();
  std::vector<std::size_t>& interpolating = memory.interpolating;
  for (std::size_t b = 0; b < d.batches.size(); ++b) {
    if (stop.stop_requested()) return;
    const RotationSchedule::Data::Batch& batch = d.batches[b];
    const bool prebuilt = !d.prebuilt.empty();
    if (!WriteCopies(plan, batch.begin, batch.end, source, out, stop,
                     prebuilt ? nullptr : &interpolating)) {
      return;
    }
    if (!prebuilt) memory.slots.Make(plan, interpolating);
    const BatchSlots& slots = prebuilt ? d.prebuilt[b] : memory.slots;
    const std::size_t count = slots.size();
    const std::size_t slerps = slots.cubic_begin();
    retime_internal::SlerpQuats(quats.data(), slots.i0(), slots.t(), slerps,
                                rotations.Arrays(), copied);
    for (std::size_t slot = slerps; slot < slots.weighted_begin(); ++slot) {
      const auto i0 = slots.i0()[slot];
      const Quat q1 = quats[static_cast<std::size_t>(i0)];
      const Quat q2 = aligned(quats[static_cast<std::size_t>(i0) + 1], q1);
      copied[slot] = QuatDot(q1, q2) < kDiscontinuityDot;
      const Quat q0 = aligned(quat_at(i0 - 1), q1);
      const Quat q3 = aligned(quat_at(i0 + 2), q2);
      const bool smooth =
          QuatDot(q0, q1) >= kDiscontinuityDot && QuatDot(q2, q3) >= kDiscontinuityDot;
      rotations.Set(slot, copied[slot]          ? q1
                          : smooth ? Squad(q0, q1, q2, q3, slots.t()[slot])
                                   : Slerp(q1, q2, slots.t()[slot]));
    }
    // The weighted means; Markley's where their spread asks for it.
    const std::size_t weighted_slot = slots.weighted_begin();
    const std::size_t means = count - weighted_slot;
    const retime_internal::QuatArrays all = rotations.Arrays();
    const retime_internal::QuatArrays mean_slots = {all.w + weighted_slot, all.x + weighted_slot,
                                                    all.y + weighted_slot, all.z + weighted_slot};
    unsigned char* const needs_markley = copied + weighted_slot;
    retime_internal::WeightedMeans(quats.data(), slots.mean_tables(), means, min_dot, mean_slots,
                                   needs_markley);
    std::size_t markleys = 0;
    for (std::size_t s = NextFlagged(needs_markley, nullptr, 0, means); s < means;
         s = NextFlagged(needs_markley, nullptr, s + 1, means)) {
      // Not a copy: the slot's flag served as Markley's.
      needs_markley[s] = 0;
      markley_jobs[markleys] = slots.job(s);
      markley_slot[markleys++] = weighted_slot + s;
    }
    retime_internal::MarkleyMeans(quats.data(), plan.weights.data(), markley_jobs, markleys,
                                  markley_means.Arrays());
    for (std::size_t s = 0; s < markleys; ++s) rotations.Set(markley_slot[s], markley_means.Get(s));
    // Back to Euler angles nearest the source's unwrapped angles at x (linearly interpolated),
    // each then within 180 degrees of the source's value at the nearest sample (the source's own
    // convention).
    const retime_internal::EulerTargets targets = {
        .i0 = slots.i0(),
        .t = slots.t(),
        .nearest = slots.nearest(),
        .output = slots.output(),
        .reference = {reference_values[0], reference_values[1], reference_values[2]},
        .turn = {source[0].data(), source[1].data(), source[2].data()},
        .out = {out[0].data(), out[1].data(), out[2].data()}};
    retime_internal::QuatsToEulerNearest(order, std::as_const(rotations).Arrays(), targets, count,
                                         ill_conditioned);
    for (std::size_t slot = NextFlagged(copied, ill_conditioned, 0, count);
         slot < count; slot = NextFlagged(copied, ill_conditioned, slot + 1, count)) {
      const auto j = static_cast<std::size_t>(slots.output()[slot]);
      const auto nearest = static_cast<std::size_t>(slots.nearest()[slot]);
      if (copied[slot]) {
        // Across a discontinuity: the nearer source pose.
        for (int c = 0; c < 3; ++c) out[c][j] = source[c][nearest];
        continue;
      }
      const auto i = static_cast<std::size_t>(slots.i0()[slot]);
      Vec3 reference;
      for (int c = 0; c < 3; ++c) {
        const double* v = reference_values[c];
        reference[c] = v[i] + slots.t()[slot] * (v[i + 1] - v[i]);
      }
      const Vec3 exact = QuatToEulerNearest(scalar_path.Interpolated(j), order, reference);
      for (int c = 0; c < 3; ++c) out[c][j] = NearestTurn(exact[c], source[c][nearest]);
    }
  }
}

}  // namespace tempokey::core
