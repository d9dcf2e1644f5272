// Quaternion keys fitted in glTF's CUBICSPLINE semantics (quaternion_fit.h).
#include "tempokey/core/reduce/quaternion_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/src/model/hermite_basis.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/reduce/tolerance_fit.h"

namespace tempokey::core {
namespace {

double ToFloat(double x) { return static_cast<double>(static_cast<float>(x)); }

Quat RoundedToFloat(const Quat& q) { return {ToFloat(q.w), ToFloat(q.x), ToFloat(q.y), ToFloat(q.z)}; }

Quat Scaled(const Quat& q, double f) { return {q.w * f, q.x * f, q.y * f, q.z * f}; }

double Norm(const Quat& q) { return std::sqrt(Dot(q, q)); }

std::array<double, 4> Components(const Quat& q) { return {q.w, q.x, q.y, q.z}; }

// Scales on the per-component bound sin(bound / 2) / 2, tried from the largest down; the first
// one whose measured error stays within the bound is kept (1 and below are safe before the key
// values are normalised and rounded, so the ladder rarely needs its lower rungs).
constexpr double kBoundScales[] = {4.0, 2.8, 2.0, 1.4, 1.0, 0.7, 0.5, 0.35, 0.25, 0.125};

// A key at every frame: the source rotations with central-difference tangents.
QuaternionCurve EveryFrame(std::span<const Quat> rotations, double frame_time) {
  QuaternionCurve curve;
  const std::size_t n = rotations.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Quat& before = rotations[i > 0 ? i - 1 : i];
    const Quat& after = rotations[i + 1 < n ? i + 1 : i];
    const double span = static_cast<double>((i + 1 < n ? i + 1 : i) - (i > 0 ? i - 1 : i));
    Quat slope{0, 0, 0, 0};
    if (span > 0) {
      const double f = 1.0 / (span * frame_time);
      slope = {(after.w - before.w) * f, (after.x - before.x) * f, (after.y - before.y) * f,
               (after.z - before.z) * f};
    }
    QuaternionKey key;
    key.time_seconds = ToFloat(static_cast<double>(i) * frame_time);
    key.value = RoundedToFloat(rotations[i]);
    key.in_tangent = key.out_tangent = RoundedToFloat(slope);
    curve.keys.push_back(key);
  }
  return curve;
}

// The spline of a component fit as glTF keys: normalised values, tangents per second scaled by
// the same factor, everything rounded to float32.
QuaternionCurve KeysOf(const SplineFit& fit, double frame_time) {
  QuaternionCurve curve;
  for (std::size_t k = 0; k < fit.frames.size(); ++k) {
    const Quat value{fit.values[0][k], fit.values[1][k], fit.values[2][k], fit.values[3][k]};
    const Quat slope{fit.slopes[0][k], fit.slopes[1][k], fit.slopes[2][k], fit.slopes[3][k]};
    const double norm = Norm(value);
    QuaternionKey key;
    key.time_seconds = ToFloat(static_cast<double>(fit.frames[k]) * frame_time);
    key.value = RoundedToFloat(Scaled(value, 1.0 / norm));
    key.in_tangent = key.out_tangent = RoundedToFloat(Scaled(slope, 1.0 / (norm * frame_time)));
    curve.keys.push_back(key);
  }
  return curve;
}

absl::Status CheckInputs(std::span<const Quat> rotations, double frame_time, double bound) {
  if (rotations.empty()) return absl::InvalidArgumentError("no rotations to fit");
  if (!std::isfinite(frame_time) || frame_time <= 0.0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "frame time must be finite and > 0 seconds, got ", DescribeDouble(frame_time)));
  }
  if (!std::isfinite(bound) || bound <= 0.0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "rotation bound must be finite and > 0 degrees, got ", DescribeDouble(bound)));
  }
  for (std::size_t i = 0; i < rotations.size(); ++i) {
    const double norm = Norm(rotations[i]);
    if (!std::isfinite(norm) || norm == 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat("rotation at frame ", i, " is not a finite non-zero quaternion"));
    }
  }
  // float32 key times must stay distinct (and increasing) at every frame.
  for (std::size_t i = 1; i < rotations.size(); ++i) {
    if (!(ToFloat(static_cast<double>(i) * frame_time) >
          ToFloat(static_cast<double>(i - 1) * frame_time))) {
      return absl::InvalidArgumentError(absl::StrCat(
          "frame time ", frame_time, " s is too small for float32 key times: frames ", i - 1,
          " and ", i, " fall on the same time"));
    }
  }
  return absl::OkStatus();
}

// Frames of the error pass between two looks at the stop token: well under a millisecond.
constexpr std::size_t kStopCheckFrames = std::size_t{1} << 16;

// Whether `curve` stays within `max_angle_degrees` of `rotations` at every frame: what
// MaxQuaternionCurveError() <= max_angle_degrees says (a NaN angle counts as within, as the
// maximum skips it), answered at the first frame over. kCancelled when `stop` is requested.
absl::StatusOr<bool> StaysWithin(const QuaternionCurve& curve, std::span<const Quat> rotations,
                                 double frame_time_seconds, double max_angle_degrees,
                                 const std::stop_token& stop) {
  for (std::size_t i = 0; i < rotations.size(); ++i) {
    if (i % kStopCheckFrames == kStopCheckFrames - 1) {
      TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    }
    const Quat q = EvaluateQuaternionCurve(curve, static_cast<double>(i) * frame_time_seconds);
    if (AngleBetweenDegrees(q, Normalized(rotations[i])) > max_angle_degrees) return false;
  }
  return true;
}

}  // namespace

Quat EvaluateQuaternionCurve(const QuaternionCurve& curve, double time_seconds) {
  const std::vector<QuaternionKey>& keys = curve.keys;
  if (!(time_seconds > keys.front().time_seconds)) return Normalized(keys.front().value);
  if (!(time_seconds < keys.back().time_seconds)) return Normalized(keys.back().value);
  const auto next = std::upper_bound(
      keys.begin(), keys.end(), time_seconds,
      [](double t, const QuaternionKey& key) { return t < key.time_seconds; });
  const QuaternionKey& a = *(next - 1);
  const QuaternionKey& b = *next;
  const double td = b.time_seconds - a.time_seconds;
  const double s = (time_seconds - a.time_seconds) / td;
  const auto [h00, h10, h01, h11] = HermiteBasis(s, td);
  const Quat p{h00 * a.value.w + h10 * a.out_tangent.w + h01 * b.value.w + h11 * b.in_tangent.w,
               h00 * a.value.x + h10 * a.out_tangent.x + h01 * b.value.x + h11 * b.in_tangent.x,
               h00 * a.value.y + h10 * a.out_tangent.y + h01 * b.value.y + h11 * b.in_tangent.y,
               h00 * a.value.z + h10 * a.out_tangent.z + h01 * b.value.z + h11 * b.in_tangent.z};
  return Normalized(p);
}

double MaxQuaternionCurveError(const QuaternionCurve& curve, std::span<const Quat> rotations,
                               double frame_time_seconds) {
  double worst = 0.0;
  for (std::size_t i = 0; i < rotations.size(); ++i) {
    const Quat q = EvaluateQuaternionCurve(curve, static_cast<double>(i) * frame_time_seconds);
    worst = std::max(worst, AngleBetweenDegrees(q, Normalized(rotations[i])));
  }
  return worst;
}

absl::StatusOr<QuaternionCurve> FitQuaternionCurve(std::span<const Quat> rotations,
                                                   double frame_time_seconds,
                                                   double max_angle_degrees,
                                                   std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  TEMPOKEY_RETURN_IF_ERROR(CheckInputs(rotations, frame_time_seconds, max_angle_degrees));
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  std::vector<Quat> continuous(rotations.size());
  for (std::size_t i = 0; i < rotations.size(); ++i) continuous[i] = Normalized(rotations[i]);
  MakeSignContinuous(continuous);
  if (continuous.size() == 1) return EveryFrame(continuous, frame_time_seconds);

  std::array<std::vector<double>, 4> components;
  for (const Quat& q : continuous) {
    const std::array<double, 4> c = Components(q);
    for (int j = 0; j < 4; ++j) components[j].push_back(c[j]);
  }
  const std::array<std::span<const double>, 4> channels = {components[0], components[1],
                                                           components[2], components[3]};
  // No two rotations are more than 180 degrees apart, so any larger bound is 180: taken as given,
  // sin(angle / 2) turns down past it and goes negative past 360 (a bound of 359 degrees asked
  // for ten times the keys of 180, one of 400 failed as "the bound must be > 0").
  const double angle = std::min(max_angle_degrees, 180.0);
  const double safe_bound = 0.5 * std::sin(0.5 * angle * std::numbers::pi / 180.0);
  double last_bound = -1.0;
  for (double scale : kBoundScales) {
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    const double bound = std::min(scale * safe_bound, 0.5);
    // A large angle (a joint bound alone allows up to 180 degrees) clamps several rungs to the
    // same bound: their fit would be the one just measured and refused.
    if (bound == last_bound) continue;
    last_bound = bound;
    const std::array<double, 4> bounds = {bound, bound, bound, bound};
    absl::StatusOr<SplineFit> fit = FitWithinTolerance(channels, bounds, {}, stop);
    if (!fit.ok()) return fit.status();
    QuaternionCurve curve = KeysOf(*fit, frame_time_seconds);
    TEMPOKEY_ASSIGN_OR_RETURN(
        const bool within,
        StaysWithin(curve, continuous, frame_time_seconds, max_angle_degrees, stop));
    if (within) return curve;
  }
  return EveryFrame(continuous, frame_time_seconds);
}

}  // namespace tempokey::core
