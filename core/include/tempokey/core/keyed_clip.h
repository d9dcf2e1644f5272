// Key-reduced clips: per channel a cubic Hermite curve of keys (SPEC 1, 4.3).
#ifndef TEMPOKEY_CORE_KEYED_CLIP_H_
#define TEMPOKEY_CORE_KEYED_CLIP_H_

#include <optional>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/clip.h"

namespace tempokey::core {

// One key. Tangents are slopes in value units per second. Weights, when set, make the tangent
// 2D (Maya weighted tangents): the Bezier handle spans weight × (segment length in time) along
// the time axis, i.e. non-weighted keys behave as weights of 1/3.
struct Key {
  double time_seconds = 0.0;
  double value = 0.0;
  double in_tangent = 0.0;
  double out_tangent = 0.0;
  std::optional<double> in_weight;
  std::optional<double> out_weight;

  friend bool operator==(const Key&, const Key&) = default;
};

struct Curve {
  std::vector<Key> keys;  // sorted by strictly increasing time

  friend bool operator==(const Curve&, const Curve&) = default;
};

// The layout of the clip the curves came from (its samples empty) and one curve per channel.
struct KeyedClip {
  Clip layout;
  std::vector<Curve> curves;

  friend bool operator==(const KeyedClip&, const KeyedClip&) = default;
};

// Errors: kInvalidArgument naming channel and key: no keys, times not strictly increasing,
// non-finite values, weights not in (0, 1] when present, curve count != channel count.
absl::Status ValidateKeyedClip(const KeyedClip& keyed);

// The curve's value at `time_seconds`: the cubic Hermite of the two keys around it (Maya / glTF
// CUBICSPLINE semantics); constant before the first and after the last key.
double EvaluateCurve(const Curve& curve, double time_seconds);

// Samples every curve at i * frame_time_seconds for i = 0 .. floor(duration * rate + 1e-9),
// where duration is the layout's; unset `frame_time_seconds` keeps the layout's frame time.
// Errors: kInvalidArgument from ValidateKeyedClip() or a frame time that is not finite and > 0.
absl::StatusOr<Clip> Bake(const KeyedClip& keyed,
                          std::optional<double> frame_time_seconds = std::nullopt);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_KEYED_CLIP_H_
