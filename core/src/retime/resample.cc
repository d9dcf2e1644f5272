#include "tempokey/core/retime/resample.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

#include "absl/strings/str_cat.h"

namespace tempokey::core {
namespace {

// Adjacent source rotations further apart than this are a discontinuity (a capture glitch or a
// flipped solve: no joint turns 90 degrees in one frame at mocap rates). Interpolating across
// one would invent a pose on an arbitrary geodesic, so samples between them take the nearer
// source pose instead. Compared as |q_i·q_{i+1}| < cos(90° / 2).
constexpr double kDiscontinuityDot = 0.70710678118654752;

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

  // A kernel evaluated by `weight(d)` over the source indices whose offset d = i - x lies in
  // (-support, support), trimmed of zero weights at both ends.
  template <class WeightFn>
  void Kernel(double x, double support, std::int64_t last, WeightFn weight) {
    std::int64_t lo = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor(x - support)));
    std::int64_t hi = std::min<std::int64_t>(last, static_cast<std::int64_t>(std::ceil(x + support)));
    std::vector<double>& w = scratch_;
    w.clear();
    for (std::int64_t i = lo; i <= hi; ++i) w.push_back(weight(static_cast<double>(i) - x));
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

bool HasWrap(std::span<const double> degrees) {
  for (std::size_t i = 1; i < degrees.size(); ++i) {
    if (std::abs(degrees[i] - degrees[i - 1]) > 180.0) return true;
  }
  return false;
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

std::int64_t NearestIndex(double x, std::int64_t last) {
  return std::clamp(static_cast<std::int64_t>(std::llround(x)), std::int64_t{0}, last);
}

// Linear interpolation of `values` at x.
double LerpAt(std::span<const double> values, double x) {
  const auto last = static_cast<std::int64_t>(values.size()) - 1;
  if (last <= 0) return values[0];
  const std::int64_t i0 = std::min(static_cast<std::int64_t>(std::floor(x)), last - 1);
  const double t = x - static_cast<double>(i0);
  const auto i = static_cast<std::size_t>(i0);
  return values[i] + t * (values[i + 1] - values[i]);
}

}  // namespace

double TentHalfWidth(double ratio) { return ratio * std::clamp(ratio - 1.0, 0.0, 1.0); }
double BoxHalfWidth(double ratio) { return 0.5 * ratio * std::clamp(ratio - 1.0, 0.0, 1.0); }

double TentWeight(double d, double a) {
  if (a <= 0.0) return Hat(d);
  const double inv = 1.0 / (6.0 * a * a);
  auto e = [&](double z) {
    const double r = a - std::abs(z);
    return r > 0.0 ? r * r * r * inv : 0.0;
  };
  return Hat(d) + e(d + 1.0) - 2.0 * e(d) + e(d - 1.0);
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
          writer.Kernel(x, 1.0 + width, last, [width](double d) { return BoxWeight(d, width); });
          continue;
        }
        break;
      case ResampleFilter::kTent:
      case ResampleFilter::kCubic:
        if (width > 0.0) {
          writer.Kernel(x, 1.0 + width, last, [width](double d) { return TentWeight(d, width); });
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

void ResampleRotation(const ResamplePlan& plan, const EulerOrder& order,
                      const std::array<std::span<const double>, 3>& source,
                      const std::array<std::span<double>, 3>& out, std::stop_token stop) {
  const auto n = static_cast<std::size_t>(plan.source_count);
  const std::int64_t last = plan.source_count - 1;
  const std::size_t m = plan.position.size();
  if (plan.copy_count == plan.output_count()) {
    for (std::size_t j = 0; j < m; ++j) {
      const auto i = static_cast<std::size_t>(plan.first[j]);
      for (int c = 0; c < 3; ++c) out[c][j] = source[c][i];
    }
    return;
  }

  // Source quaternions, converted only when an output reads them (a copy never does). No
  // global sign continuity is imposed: each use aligns signs locally (slerp takes the short
  // arc, the weighted mean aligns to its pivot, squad aligns its four inputs).
  std::vector<Quat> quats(n);
  std::vector<unsigned char> converted(n, 0);
  auto quat = [&](std::size_t i) -> const Quat& {
    if (!converted[i]) {
      quats[i] = EulerToQuat(order, {source[0][i], source[1][i], source[2][i]});
      converted[i] = 1;
    }
    return quats[i];
  };
  std::array<Unwrapped, 3> unwrapped;
  for (int c = 0; c < 3; ++c) Unwrap(source[c], unwrapped[c]);
  auto reference_values = [&](int c) -> std::span<const double> {
    return unwrapped[c].wraps ? std::span<const double>(unwrapped[c].values) : source[c];
  };
  auto aligned = [](const Quat& q, const Quat& to) { return Dot(q, to) < 0.0 ? Negated(q) : q; };
  // Neighbours past the ends by reflection (q0·q1*·q0), matching the scalar path's odd
  // reflection.
  auto quat_at = [&](std::int64_t i) -> Quat {
    if (i < 0) return Multiply(Multiply(quat(0), Conjugate(quat(1))), quat(0));
    if (i > last) {
      const auto l = static_cast<std::size_t>(last);
      return Multiply(Multiply(quat(l), Conjugate(quat(l - 1))), quat(l));
    }
    return quat(static_cast<std::size_t>(i));
  };
  std::vector<Quat> taps;

  StopCheck check(stop);
  for (std::size_t j = 0; j < m; ++j) {
    // Rotations cost tens of nanoseconds a tap: look at the stop token more often.
    if (check.After(16 * plan.offset[j])) return;
    const double x = plan.position[j];
    const std::int64_t first = plan.first[j];
    if (plan.kind[j] == SampleKind::kCopy) {
      for (int c = 0; c < 3; ++c) out[c][j] = source[c][static_cast<std::size_t>(first)];
      continue;
    }
    Quat q;
    const auto k = static_cast<std::size_t>(NearestIndex(x, last));
    switch (plan.kind[j]) {
      case SampleKind::kLerp:
      case SampleKind::kCubic: {
        const std::int64_t i0 = std::min(static_cast<std::int64_t>(std::floor(x)), last - 1);
        const auto i = static_cast<std::size_t>(i0);
        const double t = x - static_cast<double>(i0);
        const Quat& q1 = quat(i);
        const Quat q2 = aligned(quat(i + 1), q1);
        if (Dot(q1, q2) < kDiscontinuityDot) {
          for (int c = 0; c < 3; ++c) out[c][j] = source[c][k];
          continue;
        }
        if (plan.kind[j] == SampleKind::kLerp) {
          q = Slerp(q1, q2, t);
          break;
        }
        const Quat q0 = aligned(quat_at(i0 - 1), q1);
        const Quat q3 = aligned(quat_at(i0 + 2), q2);
        const bool smooth = Dot(q0, q1) >= kDiscontinuityDot && Dot(q2, q3) >= kDiscontinuityDot;
        q = smooth ? Squad(q0, q1, q2, q3, t) : Slerp(q1, q2, t);
        break;
      }
      default: {
        const std::int64_t count = plan.offset[j + 1] - plan.offset[j];
        taps.resize(static_cast<std::size_t>(count));
        for (std::int64_t tap = 0; tap < count; ++tap) {
          taps[static_cast<std::size_t>(tap)] = quat(static_cast<std::size_t>(first + tap));
        }
        const std::span<const double> w(plan.weights.data() + plan.offset[j],
                                        static_cast<std::size_t>(count));
        const std::int64_t pivot =
            std::clamp(static_cast<std::int64_t>(k) - first, std::int64_t{0}, count - 1);
        q = WeightedMeanRotation(taps, w, static_cast<std::size_t>(pivot));
        break;
      }
    }
    const Vec3 reference = {LerpAt(reference_values(0), x), LerpAt(reference_values(1), x),
                            LerpAt(reference_values(2), x)};
    const Vec3 angles = QuatToEulerNearest(q, order, reference);
    for (int c = 0; c < 3; ++c) out[c][j] = InSourceTurn(angles[c], source[c][k]);
  }
}

}  // namespace tempokey::core
