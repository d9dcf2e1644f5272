#include "tempokey/core/model/keyed_clip.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/src/simd/instruction_set.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr double kDefaultWeight = 1.0 / 3.0;
// Samples baked between two looks at the stop token: well under a millisecond of work.
constexpr std::size_t kBakePiece = 65536;

absl::Status CheckFinite(std::string_view label, std::size_t key, std::string_view field,
                         double value) {
  if (std::isfinite(value)) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(AsAbsl(label), ": key ", key, ": ",
                                                 AsAbsl(field), " is ", DescribeDouble(value)));
}

// Finite and |value| <= bound (clip.h says why each bound).
absl::Status CheckBounded(std::string_view label, std::size_t key, std::string_view field,
                          double value, double bound) {
  TEMPOKEY_RETURN_IF_ERROR(CheckFinite(label, key, field, value));
  if (std::abs(value) <= bound) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(AsAbsl(label), ": key ", key, ": ",
                                                 AsAbsl(field), " ", DescribeDouble(value),
                                                 " is beyond the +-", DescribeDouble(bound),
                                                 " a keyed clip may hold"));
}

absl::Status CheckWeight(std::string_view label, std::size_t key, std::string_view field,
                         const std::optional<double>& weight) {
  if (!weight) return absl::OkStatus();
  TEMPOKEY_RETURN_IF_ERROR(CheckFinite(label, key, field, *weight));
  if (*weight <= 0.0 || *weight > 1.0) {
    return absl::InvalidArgumentError(absl::StrCat(AsAbsl(label), ": key ", key, ": ",
                                                   AsAbsl(field), " must be in (0, 1], got ",
                                                   *weight));
  }
  return absl::OkStatus();
}

// Value of the segment from `a` to `b` at `time_seconds`, a.time <= time <= b.time.
// Neither side weighted: time is linear in s, the plain cubic Hermite with tangents scaled by dt.
double EvaluatePlainSegment(const Key& a, const Key& b, double time_seconds) {
  const double dt = b.time_seconds - a.time_seconds;
  const double s = (time_seconds - a.time_seconds) / dt;
  const double s2 = s * s;
  const double s3 = s2 * s;
  const double h10 = s3 - 2 * s2 + s;
  const double h01 = -2 * s3 + 3 * s2;
  const double h11 = s3 - s2;
  // h00 = 1 - h01: written from a's value so that a flat segment gives exactly its value.
  return a.value + h01 * (b.value - a.value) + h10 * a.out_tangent * dt +
         h11 * b.in_tangent * dt;
}

// A weighted side: the 2D Bezier, its parameter solved from time.
double EvaluateWeightedSegment(const Key& a, const Key& b, double time_seconds) {
  const double dt = b.time_seconds - a.time_seconds;
  const double wa = a.out_weight.value_or(kDefaultWeight) * dt;
  const double wb = b.in_weight.value_or(kDefaultWeight) * dt;
  // Controls relative to a.time keep the solve well conditioned far from time 0.
  const double s = SolveBezierParameter(0.0, wa, dt - wb, dt, time_seconds - a.time_seconds);
  const double y0 = a.value;
  const double y1 = a.value + a.out_tangent * wa;
  const double y2 = b.value - b.in_tangent * wb;
  const double y3 = b.value;
  // de Casteljau with a + s (b - a) steps: equal controls give exactly their value.
  auto lerp = [s](double p, double q) { return p + s * (q - p); };
  const double y01 = lerp(y0, y1);
  const double y12 = lerp(y1, y2);
  const double y23 = lerp(y2, y3);
  return lerp(lerp(y01, y12), lerp(y12, y23));
}

bool IsPlainSegment(const Key& a, const Key& b) { return !a.out_weight && !b.in_weight; }

// Whether every key has the same value, not -0, with tangents of 0 and no weights (a constant
// channel's flat keys): then the curve is that value at every time, bit for bit. Between keys
// the plain segment adds terms that are all +-0 to the value (its rise is +0, its tangents 0),
// which leaves any value but -0 as it is.
bool IsFlatCurve(const std::vector<Key>& keys) {
  const double value = keys.front().value;
  if (value == 0.0 && std::signbit(value)) return false;
  for (const Key& key : keys) {
    if (std::bit_cast<std::uint64_t>(key.value) != std::bit_cast<std::uint64_t>(value) ||
        key.in_tangent != 0.0 || key.out_tangent != 0.0 || key.in_weight || key.out_weight) {
      return false;
    }
  }
  return true;
}

// out[i] = EvaluatePlainSegment(a, b, (first_frame + i) * frame_time_seconds) for every i, on
// vectors of frames. The frame number is first_frame + i with i converted from a 32-bit integer
// (exact, as the sum is): x86 converts those on vectors, where it converts 64-bit ones one by one.
[[gnu::always_inline]] inline void EvaluatePlainRunOnVectors(const Key& a, const Key& b,
                                                             double frame_time_seconds,
                                                             double first_frame, double* out,
                                                             std::size_t n) {
  const double a_time = a.time_seconds;
  const double dt = b.time_seconds - a.time_seconds;
  const double a_value = a.value;
  const double rise = b.value - a.value;
  const double out_tangent = a.out_tangent;
  const double in_tangent = b.in_tangent;
  for (std::int32_t i = 0; i < static_cast<std::int32_t>(n); ++i) {
    const double t = (first_frame + static_cast<double>(i)) * frame_time_seconds;
    const double s = (t - a_time) / dt;
    const double s2 = s * s;
    const double s3 = s2 * s;
    const double h10 = s3 - 2 * s2 + s;
    const double h01 = -2 * s3 + 3 * s2;
    const double h11 = s3 - s2;
    out[i] = a_value + h01 * rise + h10 * out_tangent * dt + h11 * in_tangent * dt;
  }
}

// EvaluatePlainRunOnVectors() built for each instruction set, the running machine's chosen at run
// time (every build gives the same bits).
void EvaluatePlainRun(const Key& a, const Key& b, double frame_time_seconds, double first_frame,
                      double* out, std::size_t n) {
  // In runs of at most 2^31 - 1 frames (the 32-bit count above).
  constexpr std::size_t kMostFrames = 0x7fffffff;
  for (std::size_t done = 0; done < n; done += kMostFrames) {
    const std::size_t count = std::min(kMostFrames, n - done);
    simd::RunForInstructionSet([&]() __attribute__((always_inline)) {
      EvaluatePlainRunOnVectors(a, b, frame_time_seconds, first_frame + static_cast<double>(done),
                                out + done, count);
    });
  }
}

double EvaluateSegment(const Key& a, const Key& b, double time_seconds) {
  return IsPlainSegment(a, b) ? EvaluatePlainSegment(a, b, time_seconds)
                              : EvaluateWeightedSegment(a, b, time_seconds);
}

}  // namespace

double SolveBezierParameter(double x0, double x1, double x2, double x3, double x,
                            std::optional<double> guess) {
  // x(s) - x0 = ((a s + b) s + c) s with the power-basis coefficients of the Bezier.
  const double d1 = x1 - x0;
  const double d2 = x2 - x0;
  const double d3 = x3 - x0;
  const double a = d3 - 3.0 * d2 + 3.0 * d1;
  const double b = 3.0 * d2 - 6.0 * d1;
  const double c = 3.0 * d1;
  const double target = x - x0;
  return SolveMonotonicCubic(a, b, c, d3, target, guess.value_or(target / d3));
}

namespace {

// A weight CheckWeight() accepts.
bool WeightWithin(const std::optional<double>& weight) {
  return !weight || (*weight > 0.0 && *weight <= 1.0);
}

// Whether ValidateCurve() accepts `keys` (not empty): the same conditions, taken in one pass
// without a status per check. A NaN or an infinity in any field fails that field's bound (and a
// weight sum counts only beside weights that passed theirs, as in ValidateCurve()). The keys of
// every fitted curve are checked (ReduceKeys()), so this runs once per key of every result; the
// checks that build the message run only when this says no.
bool KeysWithinLimits(const std::vector<Key>& keys) {
  bool within = true;
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const Key& key = keys[k];
    within &= std::abs(key.time_seconds) <= kMaxTimeSeconds;
    within &= std::abs(key.value) <= kMaxKeyValueMagnitude;
    within &= std::abs(key.in_tangent) <= kMaxKeyTangent;
    within &= std::abs(key.out_tangent) <= kMaxKeyTangent;
    within &= WeightWithin(key.in_weight) && WeightWithin(key.out_weight);
    if (k == 0) continue;
    const Key& previous = keys[k - 1];
    within &= key.time_seconds > previous.time_seconds;
    within &= previous.out_weight.value_or(kDefaultWeight) +
                  key.in_weight.value_or(kDefaultWeight) <=
              1.0 + kWeightSumSlack;
  }
  return within;
}

}  // namespace

absl::Status ValidateCurve(const Curve& curve, std::string_view label) {
  if (curve.keys.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(AsAbsl(label), ": the curve has no keys"));
  }
  if (KeysWithinLimits(curve.keys)) return absl::OkStatus();
  for (std::size_t k = 0; k < curve.keys.size(); ++k) {
    const Key& key = curve.keys[k];
    TEMPOKEY_RETURN_IF_ERROR(CheckBounded(label, k, "time", key.time_seconds, kMaxTimeSeconds));
    TEMPOKEY_RETURN_IF_ERROR(
        CheckBounded(label, k, "value", key.value, kMaxKeyValueMagnitude));
    TEMPOKEY_RETURN_IF_ERROR(
        CheckBounded(label, k, "in tangent", key.in_tangent, kMaxKeyTangent));
    TEMPOKEY_RETURN_IF_ERROR(
        CheckBounded(label, k, "out tangent", key.out_tangent, kMaxKeyTangent));
    TEMPOKEY_RETURN_IF_ERROR(CheckWeight(label, k, "in weight", key.in_weight));
    TEMPOKEY_RETURN_IF_ERROR(CheckWeight(label, k, "out weight", key.out_weight));
    if (k == 0) continue;
    const Key& previous = curve.keys[k - 1];
    if (!(key.time_seconds > previous.time_seconds)) {
      return absl::InvalidArgumentError(absl::StrCat(
          AsAbsl(label), ": key ", k, ": time ", key.time_seconds,
          " s is not after the previous key's ", previous.time_seconds, " s"));
    }
    const double weight_sum =
        previous.out_weight.value_or(kDefaultWeight) + key.in_weight.value_or(kDefaultWeight);
    if (weight_sum > 1.0 + kWeightSumSlack) {
      return absl::InvalidArgumentError(absl::StrCat(
          AsAbsl(label), ": key ", k, ": in weight plus the previous key's out weight is ",
          weight_sum, ", over 1 (time would run backwards)"));
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateKeyedClip(const KeyedClip& keyed) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClipLayout(keyed.layout));
  if (keyed.curves.size() != keyed.layout.channels.size()) {
    return absl::InvalidArgumentError(absl::StrCat("keyed clip has ", keyed.curves.size(),
                                                   " curves for ", keyed.layout.channels.size(),
                                                   " channels"));
  }
  for (std::size_t c = 0; c < keyed.curves.size(); ++c) {
    TEMPOKEY_RETURN_IF_ERROR(
        ValidateCurve(keyed.curves[c], ChannelLabel(keyed.layout, static_cast<int>(c))));
  }
  return absl::OkStatus();
}

double EvaluateCurve(const Curve& curve, double time_seconds) {
  const std::vector<Key>& keys = curve.keys;
  if (keys.empty()) return 0.0;
  if (!(time_seconds > keys.front().time_seconds)) return keys.front().value;
  if (!(time_seconds < keys.back().time_seconds)) return keys.back().value;
  // First key strictly after the query; the segment starts one before it.
  const auto next = std::upper_bound(
      keys.begin(), keys.end(), time_seconds,
      [](double t, const Key& key) { return t < key.time_seconds; });
  const Key& b = *next;
  const Key& a = *(next - 1);
  return EvaluateSegment(a, b, time_seconds);
}

void SampleCurve(const Curve& curve, double frame_time_seconds, std::span<double> out,
                 std::int64_t first_frame) {
  const std::vector<Key>& keys = curve.keys;
  if (keys.empty()) {
    std::fill(out.begin(), out.end(), 0.0);
    return;
  }
  if (IsFlatCurve(keys)) {
    std::fill(out.begin(), out.end(), keys.front().value);
    return;
  }
  // `next` is the first key strictly after the current time, as EvaluateCurve()'s search finds
  // it; times only grow, so it only moves forward.
  std::size_t next = 1;
  if (first_frame > 0 && keys.size() > 1) {
    // A later piece starts its walk where its first time falls, not at the first key.
    const double t0 = static_cast<double>(first_frame) * frame_time_seconds;
    const auto after = std::upper_bound(keys.begin(), keys.end(), t0,
                                        [](double t, const Key& key) { return t < key.time_seconds; });
    next = std::clamp<std::size_t>(static_cast<std::size_t>(after - keys.begin()), 1,
                                   keys.size() - 1);
  }
  auto time = [&](std::size_t i) {
    return static_cast<double>(first_frame + static_cast<std::int64_t>(i)) * frame_time_seconds;
  };
  std::size_t i = 0;
  while (i < out.size()) {
    const double t = time(i);
    if (!(t > keys.front().time_seconds)) {
      out[i++] = keys.front().value;
      continue;
    }
    if (!(t < keys.back().time_seconds)) {
      out[i++] = keys.back().value;
      continue;
    }
    while (!(t < keys[next].time_seconds)) ++next;
    const Key& a = keys[next - 1];
    const Key& b = keys[next];
    // The run of frames in this segment: times only grow (an exact integer times a positive
    // frame time, rounded monotonically), so every frame of the run is after the first key and
    // before keys[next], where the checks above and the walk leave it as they do for frame i.
    std::size_t end = i + 1;
    while (end < out.size() && time(end) < b.time_seconds) ++end;
    if (IsPlainSegment(a, b)) {
      EvaluatePlainRun(a, b, frame_time_seconds,
                       static_cast<double>(first_frame + static_cast<std::int64_t>(i)),
                       out.data() + i, end - i);
    } else {
      for (std::size_t j = i; j < end; ++j) out[j] = EvaluateWeightedSegment(a, b, time(j));
    }
    i = end;
  }
}

absl::StatusOr<std::int64_t> BakedFrameCount(double duration, std::size_t channel_count,
                                             double frame_time, const ClipLimits& limits) {
  TEMPOKEY_RETURN_IF_ERROR(CheckFrameTime(frame_time, "bake frame time"));
  const double last_index = std::floor(duration / frame_time + 1e-9);
  const auto channels = static_cast<double>(std::max<std::size_t>(1, channel_count));
  if (last_index + 1.0 > static_cast<double>(limits.max_frames) ||
      last_index + 1.0 > static_cast<double>(limits.max_samples) / channels) {
    return absl::InvalidArgumentError(absl::StrCat(
        "bake at ", frame_time, " s per frame gives ", last_index + 1.0, " frames x ",
        channel_count, " channels, over the limit of ", limits.max_samples, " samples"));
  }
  return static_cast<std::int64_t>(last_index) + 1;
}

absl::StatusOr<Clip> Bake(const KeyedClip& keyed, std::optional<double> frame_time_seconds,
                          const ClipLimits& limits, std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateKeyedClip(keyed));
  const double frame_time = frame_time_seconds.value_or(keyed.layout.frame_time_seconds);
  TEMPOKEY_ASSIGN_OR_RETURN(const std::int64_t frame_count,
                            BakedFrameCount(keyed.layout.duration_seconds(),
                                            keyed.layout.channels.size(), frame_time, limits));
  Clip clip = keyed.layout;
  clip.frame_time_seconds = frame_time;
  clip.frame_count = frame_count;
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    if (stop.stop_requested()) return absl::CancelledError("cancelled");
    std::vector<double>& samples = clip.channels[c].samples;
    samples.resize(static_cast<std::size_t>(clip.frame_count));
    // In pieces, so a stop request is seen within one piece's work on the longest channel.
    for (std::size_t first = 0; first < samples.size(); first += kBakePiece) {
      if (stop.stop_requested()) return absl::CancelledError("cancelled");
      const std::size_t count = std::min(kBakePiece, samples.size() - first);
      SampleCurve(keyed.curves[c], frame_time, std::span<double>(samples).subspan(first, count),
                  static_cast<std::int64_t>(first));
    }
    if (const std::size_t f = FirstSampleOutOfRange(samples); f < samples.size()) {
      return absl::InvalidArgumentError(absl::StrCat(
          ChannelLabel(clip, static_cast<int>(c)), ": baked sample ", f, " is ",
          DescribeDouble(samples[f]), ", beyond the +-", DescribeDouble(kMaxSampleMagnitude),
          " a clip may hold (the curve's tangents overshoot)"));
    }
  }
  return clip;
}

}  // namespace tempokey::core
