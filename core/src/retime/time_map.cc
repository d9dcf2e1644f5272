#include "tempokey/core/retime/time_map.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "retime_internal.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {

using retime_internal::DescribeHold;
using retime_internal::DescribeKey;
using retime_internal::DescribePin;
using retime_internal::DescribeSpeedKnot;
using retime_internal::DescribeTimePoint;
using retime_internal::FormatNumber;
using retime_internal::kMaxOutputFrames;
using retime_internal::kMaxWarpItems;

namespace {

// Below this |z| the log1p / expm1 ratios switch to their series (SPEC 3.1); the first omitted
// term is below 1e-24.
constexpr double kSeriesThreshold = 1e-6;
// M = floor(T_o·f_o + kGridSlack) + 1 (SPEC 3.1): a duration a rounding error short of a whole
// frame still ends on that frame.
constexpr double kGridSlack = 1e-9;
// Source positions within this many frames of the clip's ends (a time typed in seconds for the
// last frame) are taken as the end itself.
constexpr double kEndSnapFrames = 1e-9;
// Speed knots closer than this (in frames of their timeline) are a step, not a ramp: ramps
// divide by their span, which must not be subnormal (found by fuzzing: a ramp over 1e-313 s of
// output time made every source position NaN).
constexpr double kKnotMergeFrames = 1e-9;
// Relative slack when re-checking scaled speeds against [min_speed, max_speed], so a knot set
// exactly at a bound is not refused for a rounding error in a scale of 1 ± ulp.
constexpr double kRangeSlack = 1e-12;

std::string SourceTimeLabel(double seconds) {
  return absl::StrCat("source time ", FormatNumber(seconds), "s");
}

}  // namespace

double Log1pRatio(double z) {
  if (std::abs(z) < kSeriesThreshold) return 1.0 + z * (-0.5 + z * (1.0 / 3.0 - z * 0.25));
  return std::log1p(z) / z;
}

double Expm1Ratio(double z) {
  if (std::abs(z) < kSeriesThreshold) return 1.0 + z * (0.5 + z * (1.0 / 6.0 + z / 24.0));
  return std::expm1(z) / z;
}

// ---- segments ----------------------------------------------------------------------------------

double TimeMap::Segment::Advance(double s) const {
  switch (kind) {
    case SegmentKind::kLinear:
      return v0 * s;
    case SegmentKind::kSourceRamp: {
      const double m = (v1 - v0) / (x1 - x0);
      return v0 * s * Expm1Ratio(m * s);
    }
    case SegmentKind::kOutputRamp: {
      const double k = (v1 - v0) / duration;
      return s * (v0 + 0.5 * k * s);
    }
    case SegmentKind::kHold:
      return 0.0;
  }
  return 0.0;
}

double TimeMap::Segment::Elapsed(double u) const {
  switch (kind) {
    case SegmentKind::kLinear:
      return u / v0;
    case SegmentKind::kSourceRamp: {
      const double m = (v1 - v0) / (x1 - x0);
      return (u / v0) * Log1pRatio(m * u / v0);
    }
    case SegmentKind::kOutputRamp: {
      // The root of k/2·s² + v0·s - u = 0 in the form without cancellation.
      const double k = (v1 - v0) / duration;
      return 2.0 * u / (v0 + std::sqrt(std::max(0.0, v0 * v0 + 2.0 * k * u)));
    }
    case SegmentKind::kHold:
      return 0.0;
  }
  return 0.0;
}

double TimeMap::Segment::Rate(double s) const {
  switch (kind) {
    case SegmentKind::kLinear:
      return v0;
    case SegmentKind::kSourceRamp:
      return v0 * std::exp((v1 - v0) / (x1 - x0) * s);
    case SegmentKind::kOutputRamp:
      return v0 + (v1 - v0) / duration * s;
    case SegmentKind::kHold:
      return 0.0;
  }
  return 0.0;
}

void TimeMap::Segment::RecomputeDuration() {
  const double h = x1 - x0;
  if (kind == SegmentKind::kLinear) duration = h / v0;
  // h / L(v0, v1) with L the logarithmic mean: h·log1p(d/v0)/d.
  if (kind == SegmentKind::kSourceRamp) duration = (h / v0) * Log1pRatio((v1 - v0) / v0);
}

void TimeMap::Segment::Scale(double c) {
  if (kind == SegmentKind::kHold || c == 1.0) return;
  v0 *= c;
  v1 *= c;
  if (kind == SegmentKind::kOutputRamp) {
    duration /= c;
  } else {
    RecomputeDuration();
  }
}

// ---- compilation -------------------------------------------------------------------------------

class TimeMapBuilder {
 public:
  using Segment = TimeMap::Segment;
  using SegmentKind = TimeMap::SegmentKind;

  TimeMapBuilder(double source_frame_time, std::int64_t frame_count, const TimeWarpSpec& warp,
                 const RetimeOptions& options)
      : warp_(warp), options_(options) {
    map_.source_frame_time_ = source_frame_time;
    map_.x_end_ = static_cast<double>(frame_count - 1);
    map_.reverse_ = warp.reverse;
    frame_count_ = frame_count;
  }

  absl::StatusOr<TimeMap> Build() && {
    TEMPOKEY_RETURN_IF_ERROR(CheckTimingAndOptions());
    TEMPOKEY_RETURN_IF_ERROR(BuildBaseSegments());
    TEMPOKEY_RETURN_IF_ERROR(InsertHolds());
    TEMPOKEY_RETURN_IF_ERROR(SplitAtPins());
    TEMPOKEY_RETURN_IF_ERROR(ScaleAndLayOut());
    return std::move(map_);
  }

 private:
  double x_end() const { return map_.x_end_; }
  double dt_s() const { return map_.source_frame_time_; }
  double dt_o() const { return map_.output_frame_time_; }
  // Speeds in seconds per second -> source frames per output frame.
  double r() const { return ratio_; }

  double SourceFrames(const TimePoint& time) const {
    return time.in_frames ? time.value : time.value / dt_s();
  }
  double OutputFrames(const TimePoint& time) const {
    return time.in_frames ? time.value : time.value / dt_o();
  }
  std::string SourceSpan() const {
    return absl::StrCat("0s..", FormatNumber(x_end() * dt_s()), "s");
  }

  absl::Status CheckTimingAndOptions();
  absl::Status BuildBaseSegments();
  absl::Status BuildIdentity();
  absl::Status BuildSpeedOverSource();
  absl::Status BuildSpeedOverOutput();
  absl::Status BuildTimeMapKeys();
  absl::Status InsertHolds();
  absl::Status SplitAtPins();
  absl::Status ScaleAndLayOut();

  // Which pin interval a segment belongs to: the number of pins at or before its start.
  std::size_t IntervalOf(const Segment& s) const {
    return static_cast<std::size_t>(std::upper_bound(pin_x_.begin(), pin_x_.end(), s.x0) -
                                    pin_x_.begin());
  }
  // Indexes segments_ by pin interval (IntervalSegments()), once they are final: an interval's
  // scale reads only its own segments, so that many pins cost one pass over the segments rather
  // than one per pin.
  void IndexIntervals();
  // The segments of one pin interval, in order. Intervals never decrease along segments_ (its
  // segments are in source order, a hold between the segments it splits).
  std::span<const Segment> IntervalSegments(std::size_t interval) const {
    return std::span<const Segment>(segments_).subspan(
        interval_begin_[interval], interval_begin_[interval + 1] - interval_begin_[interval]);
  }
  std::pair<Segment, Segment> SplitAt(const Segment& s, double x) const;
  // The scale c for one interval given its speed-segment duration, hold duration and target;
  // checks the scaled speeds. `context` names what sets the target.
  absl::StatusOr<double> IntervalScale(std::size_t interval, double target,
                                       const std::string& context, bool in_seconds) const;
  absl::Status CheckScaledRange(std::size_t interval, double c, const std::string& context) const;

  TimeMap map_;
  const TimeWarpSpec& warp_;
  const RetimeOptions& options_;
  std::int64_t frame_count_ = 1;
  double ratio_ = 1.0;
  std::vector<Segment> segments_;
  std::vector<double> pin_x_;  // pinned source positions, increasing
  // IndexIntervals(): interval i is segments_[interval_begin_[i], interval_begin_[i + 1]).
  std::vector<std::size_t> interval_begin_;
};

absl::Status TimeMapBuilder::CheckTimingAndOptions() {
  TEMPOKEY_RETURN_IF_ERROR(CheckFrameTime(dt_s(), "source frame time"));
  if (frame_count_ < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("a clip needs at least 1 frame, got ", frame_count_));
  }
  TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateSpeedRange(options_));
  map_.output_frame_time_ = dt_s();
  ratio_ = 1.0;
  if (options_.output_rate) {
    TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateOutputRate(*options_.output_rate));
    const auto num = static_cast<double>(options_.output_rate->numerator);
    const auto den = static_cast<double>(options_.output_rate->denominator);
    map_.output_frame_time_ = den / num;
    ratio_ = den / (num * dt_s());
  }
  if (options_.fit_seconds && options_.fit_frames) {
    return absl::InvalidArgumentError("fit_seconds and fit_frames are both set; give at most one");
  }
  if (options_.fit_seconds) {
    TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateDuration("fit_seconds", *options_.fit_seconds));
  }
  if (options_.fit_frames && *options_.fit_frames < 2) {
    return absl::InvalidArgumentError(absl::StrCat(
        "fit_frames must be >= 2 (one frame has no duration to fit), got ", *options_.fit_frames));
  }
  if (options_.fit_frames && *options_.fit_frames > kMaxOutputFrames) {
    return absl::InvalidArgumentError(absl::StrCat("fit_frames ", *options_.fit_frames,
                                                   " is over the limit of ", kMaxOutputFrames));
  }
  const std::pair<const char*, std::size_t> counts[] = {{"speed knots", warp_.speed.size()},
                                                         {"time-map keys", warp_.keys.size()},
                                                         {"holds", warp_.holds.size()},
                                                         {"pins", options_.pins.size()}};
  for (const auto& [what, count] : counts) {
    if (count > kMaxWarpItems) {
      return OverLimitError(
          absl::StrCat("too many ", what, ": ", count, ", over the limit of ", kMaxWarpItems));
    }
  }
  return absl::OkStatus();
}

absl::Status TimeMapBuilder::BuildBaseSegments() {
  const bool speeds = warp_.domain == WarpDomain::kSpeedOverSource ||
                      warp_.domain == WarpDomain::kSpeedOverOutput;
  if (!speeds && !warp_.speed.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "speed knots are given but the warp domain is ",
        warp_.domain == WarpDomain::kIdentity ? "identity" : "time-map keys",
        "; set it to speed over source or over output time"));
  }
  if (warp_.domain != WarpDomain::kTimeMapKeys && !warp_.keys.empty()) {
    return absl::InvalidArgumentError(
        "time-map keys are given but the warp domain is not time-map keys");
  }
  switch (warp_.domain) {
    case WarpDomain::kIdentity:
      return BuildIdentity();
    case WarpDomain::kSpeedOverSource:
      return BuildSpeedOverSource();
    case WarpDomain::kSpeedOverOutput:
      return BuildSpeedOverOutput();
    case WarpDomain::kTimeMapKeys:
      return BuildTimeMapKeys();
  }
  return absl::InvalidArgumentError("unknown warp domain");
}

absl::Status TimeMapBuilder::BuildIdentity() {
  if (x_end() <= 0.0) return absl::OkStatus();
  Segment s;
  s.kind = SegmentKind::kLinear;
  s.x0 = 0.0;
  s.x1 = x_end();
  s.v0 = s.v1 = r();
  s.label0 = s.label1 = "the clip";
  s.RecomputeDuration();
  segments_.push_back(std::move(s));
  return absl::OkStatus();
}

absl::Status TimeMapBuilder::BuildSpeedOverSource() {
  const auto& knots = warp_.speed;
  if (knots.empty()) {
    return absl::InvalidArgumentError("speed over source time needs at least one speed knot");
  }
  TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateSpeedKnots(knots, dt_s(), options_));
  if (x_end() <= 0.0) return absl::OkStatus();

  // Pieces of the speed curve over the whole line: flat before the first knot, linear between
  // knots (two knots at one time make a step), flat after the last; each clipped to [0, x_end].
  struct Piece {
    double xa, xb, va, vb;
    std::size_t ka, kb;
  };
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<Piece> pieces;
  const std::size_t n = knots.size();
  std::vector<double> x(n);
  for (std::size_t k = 0; k < n; ++k) {
    x[k] = SourceFrames(knots[k].time);
    // Knots closer than this are one step: a ramp over a subnormal span has an infinite slope.
    if (k > 0 && x[k] - x[k - 1] <= kKnotMergeFrames) x[k] = x[k - 1];
  }
  pieces.push_back({-inf, x[0], knots[0].speed, knots[0].speed, 0, 0});
  for (std::size_t k = 0; k + 1 < n; ++k) {
    if (x[k + 1] > x[k]) pieces.push_back({x[k], x[k + 1], knots[k].speed, knots[k + 1].speed, k, k + 1});
  }
  pieces.push_back({x[n - 1], inf, knots[n - 1].speed, knots[n - 1].speed, n - 1, n - 1});

  for (const Piece& p : pieces) {
    const double lo = std::max(p.xa, 0.0);
    const double hi = std::min(p.xb, x_end());
    if (!(hi > lo)) continue;
    auto speed_at = [&](double xx) {
      if (p.va == p.vb || std::isinf(p.xa) || std::isinf(p.xb)) return p.va;
      return p.va + (p.vb - p.va) * ((xx - p.xa) / (p.xb - p.xa));
    };
    Segment s;
    s.x0 = lo;
    s.x1 = hi;
    s.v0 = speed_at(lo) * r();
    s.v1 = speed_at(hi) * r();
    s.kind = s.v0 == s.v1 ? SegmentKind::kLinear : SegmentKind::kSourceRamp;
    s.label0 = (lo == p.xa || std::isinf(p.xa)) ? DescribeSpeedKnot(p.ka, knots[p.ka])
                                                : SourceTimeLabel(lo * dt_s());
    s.label1 = (hi == p.xb || std::isinf(p.xb)) ? DescribeSpeedKnot(p.kb, knots[p.kb])
                                                : SourceTimeLabel(hi * dt_s());
    s.RecomputeDuration();
    segments_.push_back(std::move(s));
  }
  return absl::OkStatus();
}

absl::Status TimeMapBuilder::BuildSpeedOverOutput() {
  const auto& knots = warp_.speed;
  if (knots.empty()) {
    return absl::InvalidArgumentError("speed over output time needs at least one speed knot");
  }
  TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateSpeedKnots(knots, dt_o(), options_));
  if (x_end() <= 0.0) return absl::OkStatus();

  const double inf = std::numeric_limits<double>::infinity();
  const std::size_t n = knots.size();
  std::vector<double> y(n);
  for (std::size_t k = 0; k < n; ++k) {
    y[k] = OutputFrames(knots[k].time);
    if (k > 0 && y[k] - y[k - 1] <= kKnotMergeFrames) y[k] = y[k - 1];  // one step, as above
  }
  struct Piece {
    double ya, yb, sa, sb;
    std::size_t ka, kb;
  };
  std::vector<Piece> pieces;
  pieces.push_back({-inf, y[0], knots[0].speed, knots[0].speed, 0, 0});
  for (std::size_t k = 0; k + 1 < n; ++k) {
    if (y[k + 1] > y[k]) pieces.push_back({y[k], y[k + 1], knots[k].speed, knots[k + 1].speed, k, k + 1});
  }
  pieces.push_back({y[n - 1], inf, knots[n - 1].speed, knots[n - 1].speed, n - 1, n - 1});

  // Integrate τ(t) = ∫ s dt from t = 0 until the clip's end is reached.
  double x = 0.0;
  for (const Piece& p : pieces) {
    const double lo = std::max(p.ya, 0.0);
    const double hi = p.yb;
    if (!(hi > lo)) continue;
    auto speed_at = [&](double yy) {
      if (p.sa == p.sb || std::isinf(p.ya) || std::isinf(p.yb)) return p.sa;
      return p.sa + (p.sb - p.sa) * ((yy - p.ya) / (p.yb - p.ya));
    };
    Segment s;
    s.x0 = x;
    s.v0 = speed_at(lo) * r();
    s.label0 = (lo == p.ya || std::isinf(p.ya)) ? DescribeSpeedKnot(p.ka, knots[p.ka])
                                                : absl::StrCat("output time ", FormatNumber(lo * dt_o()), "s");
    s.label1 = DescribeSpeedKnot(p.kb, knots[p.kb]);
    if (std::isinf(hi)) {
      s.kind = SegmentKind::kLinear;
      s.v1 = s.v0;
      s.x1 = x_end();
      s.RecomputeDuration();
      segments_.push_back(std::move(s));
      return absl::OkStatus();
    }
    s.v1 = speed_at(hi) * r();
    s.duration = hi - lo;
    s.kind = s.v0 == s.v1 ? SegmentKind::kLinear : SegmentKind::kOutputRamp;
    const double advance = s.duration * 0.5 * (s.v0 + s.v1);
    if (x + advance >= x_end()) {
      // The clip ends inside this piece: cut it where the source reaches its last frame.
      const double w = s.Elapsed(x_end() - x);
      s.v1 = s.v0 + (s.v1 - s.v0) / s.duration * w;
      s.duration = w;
      s.x1 = x_end();
      s.label1 = SourceTimeLabel(x_end() * dt_s());
      if (s.kind == SegmentKind::kLinear) s.RecomputeDuration();
      segments_.push_back(std::move(s));
      return absl::OkStatus();
    }
    s.x1 = x + advance;
    x = s.x1;
    segments_.push_back(std::move(s));
  }
  return absl::OkStatus();
}

absl::Status TimeMapBuilder::BuildTimeMapKeys() {
  const auto& keys = warp_.keys;
  if (keys.size() < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat("time-map keys: need at least 2 keys, got ", keys.size()));
  }
  std::vector<double> y(keys.size());
  std::vector<double> x(keys.size());
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const TimeMapKey& key = keys[k];
    TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateTimePoint(
        absl::StrCat("time-map key ", k + 1, ": output"), key.output));
    TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateTimePoint(
        absl::StrCat("time-map key ", k + 1, ": source"), key.source));
    y[k] = OutputFrames(key.output);
    x[k] = SourceFrames(key.source);
    if (k == 0) continue;
    if (!(y[k] > y[k - 1])) {
      return absl::InvalidArgumentError(absl::StrCat(
          DescribeKey(k, key), ": output time must increase, the previous key is at ",
          DescribeTimePoint(keys[k - 1].output)));
    }
    if (x[k] < x[k - 1]) {
      return absl::InvalidArgumentError(absl::StrCat(
          DescribeKey(k, key), ": source time must not decrease, the previous key is at ",
          DescribeTimePoint(keys[k - 1].source), " (use reverse to play backwards)"));
    }
    if (x[k] > x[k - 1]) {
      const double speed = ((x[k] - x[k - 1]) * dt_s()) / ((y[k] - y[k - 1]) * dt_o());
      if (speed < options_.min_speed || speed > options_.max_speed) {
        return absl::InvalidArgumentError(absl::StrCat(
            "time-map keys ", k, "..", k + 1, ": speed ", FormatNumber(speed),
            " is outside the allowed range [", FormatNumber(options_.min_speed), ", ",
            FormatNumber(options_.max_speed), "]"));
      }
    }
  }
  if (x.front() > kEndSnapFrames || x.back() < x_end() - kEndSnapFrames) {
    const std::string covered = absl::StrCat(FormatNumber(x.front() * dt_s()), "s..",
                                             FormatNumber(x.back() * dt_s()), "s");
    // Ends a hair short print as the clip's own span in seconds: the frames say by how much.
    const std::string frames =
        covered == SourceSpan()
            ? absl::StrFormat(" (source frames %.12g..%.12g of 0..%.12g: the keys must reach "
                              "both ends within %g frames)",
                              x.front(), x.back(), x_end(), kEndSnapFrames)
            : "";
    return absl::InvalidArgumentError(absl::StrCat("time-map keys cover source ", covered,
                                                   ", the clip spans ", SourceSpan(), frames));
  }
  for (std::size_t k = 0; k + 1 < keys.size(); ++k) {
    const std::string label = absl::StrCat("time-map keys ", k + 1, "..", k + 2);
    Segment s;
    s.label0 = s.label1 = label;
    if (x[k + 1] == x[k]) {
      if (x[k] < -kEndSnapFrames || x[k] > x_end() + kEndSnapFrames) continue;
      s.kind = SegmentKind::kHold;
      s.x0 = s.x1 = std::clamp(x[k], 0.0, x_end());
      s.duration = y[k + 1] - y[k];
      segments_.push_back(std::move(s));
      continue;
    }
    const double lo = std::max(x[k], 0.0);
    const double hi = std::min(x[k + 1], x_end());
    if (!(hi > lo)) continue;
    s.kind = SegmentKind::kLinear;
    s.x0 = lo;
    s.x1 = hi;
    s.v0 = s.v1 = (x[k + 1] - x[k]) / (y[k + 1] - y[k]);
    s.RecomputeDuration();
    segments_.push_back(std::move(s));
  }
  return absl::OkStatus();
}

std::pair<TimeMap::Segment, TimeMap::Segment> TimeMapBuilder::SplitAt(const Segment& s,
                                                                      double x) const {
  Segment left = s;
  Segment right = s;
  left.x1 = x;
  right.x0 = x;
  left.label1 = right.label0 = SourceTimeLabel(x * dt_s());
  switch (s.kind) {
    case SegmentKind::kLinear:
      left.RecomputeDuration();
      right.RecomputeDuration();
      break;
    case SegmentKind::kSourceRamp: {
      const double v = s.v0 + (s.v1 - s.v0) * ((x - s.x0) / (s.x1 - s.x0));
      left.v1 = right.v0 = v;
      left.RecomputeDuration();
      right.RecomputeDuration();
      break;
    }
    case SegmentKind::kOutputRamp: {
      const double w = s.Elapsed(x - s.x0);
      const double v = s.v0 + (s.v1 - s.v0) / s.duration * w;
      left.v1 = right.v0 = v;
      left.duration = w;
      right.duration = s.duration - w;
      if (!(right.duration > 0.0)) {
        // Rounding left no output time: the remainder is a sliver at the end speed.
        right.kind = SegmentKind::kLinear;
        right.v0 = s.v1;
        right.RecomputeDuration();
      }
      break;
    }
    case SegmentKind::kHold:
      break;
  }
  return {std::move(left), std::move(right)};
}

absl::Status TimeMapBuilder::InsertHolds() {
  struct Pending {
    double x;
    double duration;
    std::size_t index;
  };
  std::vector<Pending> holds;
  holds.reserve(warp_.holds.size());
  for (std::size_t i = 0; i < warp_.holds.size(); ++i) {
    const Hold& hold = warp_.holds[i];
    TEMPOKEY_RETURN_IF_ERROR(
        retime_internal::ValidateTimePoint(absl::StrCat("hold ", i + 1, ": source"), hold.at));
    TEMPOKEY_RETURN_IF_ERROR(retime_internal::ValidateDuration(
        absl::StrCat(DescribeHold(i, hold), ": duration"), hold.duration_seconds));
    double x = SourceFrames(hold.at);
    if (x < -kEndSnapFrames || x > x_end() + kEndSnapFrames) {
      return absl::InvalidArgumentError(absl::StrCat(DescribeHold(i, hold),
                                                     ": outside the clip's source time ", SourceSpan()));
    }
    x = std::clamp(x, 0.0, x_end());
    holds.push_back({x, hold.duration_seconds / dt_o(), i});
  }
  if (holds.empty()) return absl::OkStatus();
  std::stable_sort(holds.begin(), holds.end(),
                   [](const Pending& a, const Pending& b) { return a.x < b.x; });

  auto make_hold = [&](const Pending& p) {
    Segment h;
    h.kind = SegmentKind::kHold;
    h.x0 = h.x1 = p.x;
    h.duration = p.duration;
    h.label0 = h.label1 = DescribeHold(p.index, warp_.holds[p.index]);
    return h;
  };
  std::vector<Segment> merged;
  merged.reserve(segments_.size() + 2 * holds.size());
  std::size_t next = 0;
  for (Segment& seg : segments_) {
    if (seg.kind == SegmentKind::kHold) {
      while (next < holds.size() && holds[next].x < seg.x0) merged.push_back(make_hold(holds[next++]));
      merged.push_back(std::move(seg));
      continue;
    }
    Segment cur = std::move(seg);
    while (next < holds.size() && holds[next].x < cur.x1) {
      if (holds[next].x > cur.x0) {
        auto [left, right] = SplitAt(cur, holds[next].x);
        merged.push_back(std::move(left));
        cur = std::move(right);
      }
      merged.push_back(make_hold(holds[next++]));
    }
    merged.push_back(std::move(cur));
  }
  while (next < holds.size()) merged.push_back(make_hold(holds[next++]));
  segments_ = std::move(merged);
  return absl::OkStatus();
}

absl::Status TimeMapBuilder::SplitAtPins() {
  const auto& pins = options_.pins;
  if (pins.empty()) return absl::OkStatus();
  if (warp_.reverse) {
    return absl::InvalidArgumentError(
        "pins cannot be combined with reverse; pin the forward retime and reverse it in a second "
        "operation");
  }
  double previous_frame = -1.0;
  for (std::size_t i = 0; i < pins.size(); ++i) {
    const Pin& pin = pins[i];
    TEMPOKEY_RETURN_IF_ERROR(
        retime_internal::ValidateTimePoint(absl::StrCat("pin ", i + 1, ": source"), pin.source));
    if (pin.output_frame < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(DescribePin(i, pin), ": output frame must be >= 0"));
    }
    if (pin.output_frame > kMaxOutputFrames) {
      return absl::InvalidArgumentError(absl::StrCat(DescribePin(i, pin),
                                                     ": output frame is over the limit of ",
                                                     kMaxOutputFrames));
    }
    double x = SourceFrames(pin.source);
    if (x < -kEndSnapFrames || x > x_end() + kEndSnapFrames) {
      return absl::InvalidArgumentError(absl::StrCat(DescribePin(i, pin),
                                                     ": outside the clip's source time ", SourceSpan()));
    }
    x = std::clamp(x, 0.0, x_end());
    const auto frame = static_cast<double>(pin.output_frame);
    if (i > 0 && !(x > pin_x_.back() && frame > previous_frame)) {
      return absl::InvalidArgumentError(absl::StrCat(
          DescribePin(i, pin), ": must come after ", DescribePin(i - 1, pins[i - 1]),
          " in both source time and output frame"));
    }
    pin_x_.push_back(x);
    previous_frame = frame;
  }
  std::vector<Segment> split;
  split.reserve(segments_.size() + pins.size());
  std::size_t next = 0;
  for (Segment& seg : segments_) {
    if (seg.kind == SegmentKind::kHold) {
      split.push_back(std::move(seg));
      continue;
    }
    while (next < pin_x_.size() && pin_x_[next] <= seg.x0) ++next;
    Segment cur = std::move(seg);
    while (next < pin_x_.size() && pin_x_[next] < cur.x1) {
      auto [left, right] = SplitAt(cur, pin_x_[next++]);
      split.push_back(std::move(left));
      cur = std::move(right);
    }
    split.push_back(std::move(cur));
  }
  segments_ = std::move(split);
  return absl::OkStatus();
}

absl::Status TimeMapBuilder::CheckScaledRange(std::size_t interval, double c,
                                              const std::string& context) const {
  if (c == 1.0) return absl::OkStatus();
  const double hi = options_.max_speed * (1.0 + kRangeSlack);
  const double lo = options_.min_speed * (1.0 - kRangeSlack);
  for (const Segment& s : IntervalSegments(interval)) {
    if (s.kind == SegmentKind::kHold) continue;
    for (int end = 0; end < 2; ++end) {
      const double speed = (end == 0 ? s.v0 : s.v1) / r() * c;
      const std::string& label = end == 0 ? s.label0 : s.label1;
      if (speed > hi || speed < lo) {
        return absl::InvalidArgumentError(absl::StrCat(
            context, ": needs speeds scaled by ", FormatNumber(c), ", so ", label,
            " would play at speed ", FormatNumber(speed),
            speed > hi ? ", over the maximum " : ", under the minimum ",
            FormatNumber(speed > hi ? options_.max_speed : options_.min_speed)));
      }
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<double> TimeMapBuilder::IntervalScale(std::size_t interval, double target,
                                                     const std::string& context,
                                                     bool in_seconds) const {
  double speed_frames = 0.0;
  double hold_frames = 0.0;
  for (const Segment& s : IntervalSegments(interval)) {
    (s.kind == SegmentKind::kHold ? hold_frames : speed_frames) += s.duration;
  }
  auto amount = [&](double frames) {
    return in_seconds ? absl::StrCat(FormatNumber(frames * dt_o()), " s")
                      : absl::StrCat(FormatNumber(frames), " frames");
  };
  const double available = target - hold_frames;
  if (speed_frames <= 0.0) {
    if (std::abs(available) > kGridSlack) {
      return absl::InvalidArgumentError(absl::StrCat(
          context, ": there is no source time to stretch over ", amount(target),
          hold_frames > 0.0 ? absl::StrCat(" (the holds last ", amount(hold_frames), ")") : ""));
    }
    return 1.0;
  }
  if (!(available > 0.0)) {
    if (hold_frames > 0.0) {
      return absl::InvalidArgumentError(absl::StrCat(context, ": the holds alone last ",
                                                     amount(hold_frames), ", leaving ",
                                                     amount(std::max(available, 0.0)),
                                                     " for the motion"));
    }
    return absl::InvalidArgumentError(
        absl::StrCat(context, ": leaves ", amount(std::max(target, 0.0)), " for the motion"));
  }
  const double c = speed_frames / available;
  TEMPOKEY_RETURN_IF_ERROR(CheckScaledRange(interval, c, context));
  return c;
}

void TimeMapBuilder::IndexIntervals() {
  const std::size_t intervals = pin_x_.size() + 1;
  interval_begin_.assign(intervals + 1, segments_.size());
  interval_begin_[0] = 0;
  std::size_t interval = 0;
  for (std::size_t k = 0; k < segments_.size(); ++k) {
    const std::size_t own = IntervalOf(segments_[k]);
    while (interval < own) interval_begin_[++interval] = k;
  }
}

absl::Status TimeMapBuilder::ScaleAndLayOut() {
  IndexIntervals();
  const std::size_t pins = pin_x_.size();
  std::vector<double> start(pins + 1, 0.0);
  for (std::size_t i = 0; i < pins; ++i) {
    start[i + 1] = static_cast<double>(options_.pins[i].output_frame);
  }
  std::vector<double> scale(pins + 1, 1.0);
  for (std::size_t i = 0; i < pins; ++i) {
    TEMPOKEY_ASSIGN_OR_RETURN(
        scale[i],
        IntervalScale(i, start[i + 1] - start[i], DescribePin(i, options_.pins[i]), false));
  }

  // The last interval: fit, fit to grid, or as drawn.
  double speed_frames = 0.0;
  double hold_frames = 0.0;
  for (const Segment& s : IntervalSegments(pins)) {
    (s.kind == SegmentKind::kHold ? hold_frames : speed_frames) += s.duration;
  }
  std::optional<double> end;  // the exact end, when a fit sets it
  if (options_.fit_frames) {
    const auto target = static_cast<double>(*options_.fit_frames - 1);
    TEMPOKEY_ASSIGN_OR_RETURN(
        scale[pins], IntervalScale(pins, target - start[pins],
                                   absl::StrCat("fit to ", *options_.fit_frames, " frames"), false));
    end = target;
  } else if (options_.fit_seconds) {
    double target = *options_.fit_seconds / dt_o();
    if (options_.fit_to_grid) target = std::round(target);
    TEMPOKEY_ASSIGN_OR_RETURN(
        scale[pins],
        IntervalScale(pins, target - start[pins],
                      absl::StrCat("fit to ", FormatNumber(*options_.fit_seconds), " s"), true));
    end = target;
  } else if (options_.fit_to_grid && speed_frames > 0.0) {
    // The whole frame nearest the natural end, or the one on the other side when the nearest
    // would push a speed out of range.
    const double natural = start[pins] + speed_frames + hold_frames;
    const double candidates[] = {std::round(natural), std::floor(natural), std::ceil(natural)};
    absl::Status first_error;
    for (double candidate : candidates) {
      absl::StatusOr<double> c = IntervalScale(
          pins, candidate - start[pins],
          absl::StrCat("fit to grid (", FormatNumber(candidate + 1), " frames)"), false);
      if (c.ok()) {
        scale[pins] = *c;
        end = candidate;
        break;
      }
      if (first_error.ok()) first_error = c.status();
    }
    if (!end) return first_error;
  }

  // Each interval scaled by its own factor and laid out from its start (the first from 0).
  double y = 0.0;
  for (std::size_t i = 0; i <= pins; ++i) {
    if (interval_begin_[i] == interval_begin_[i + 1]) continue;
    if (i > 0) y = start[i];
    for (std::size_t k = interval_begin_[i]; k < interval_begin_[i + 1]; ++k) {
      Segment& s = segments_[k];
      s.Scale(scale[i]);
      s.y0 = y;
      y += s.duration;
    }
  }
  map_.y_end_ = end ? *end : std::max(y, start[pins]);
  map_.fit_factor_ = scale[pins];
  map_.pin_factors_.assign(scale.begin(), scale.begin() + static_cast<std::ptrdiff_t>(pins));
  if (!(map_.y_end_ + kGridSlack < static_cast<double>(kMaxOutputFrames))) {
    return absl::InvalidArgumentError(absl::StrCat(
        "the retimed clip would last ", FormatNumber(map_.y_end_ * dt_o()), " s (",
        absl::StrFormat("%.0f", std::floor(map_.y_end_ + kGridSlack) + 1.0),
        " frames), over the limit of ", kMaxOutputFrames, " frames"));
  }
  map_.output_frame_count_ = static_cast<std::int64_t>(std::floor(map_.y_end_ + kGridSlack)) + 1;
  map_.segments_ = std::move(segments_);
  return absl::OkStatus();
}

absl::StatusOr<TimeMap> TimeMap::Compile(double source_frame_time_seconds,
                                         std::int64_t source_frame_count, const TimeWarpSpec& warp,
                                         const RetimeOptions& options) {
  return TimeMapBuilder(source_frame_time_seconds, source_frame_count, warp, options).Build();
}

// ---- evaluation --------------------------------------------------------------------------------

std::size_t TimeMap::SegmentAtOutput(double y) const {
  auto it = std::upper_bound(segments_.begin(), segments_.end(), y,
                             [](double value, const Segment& s) { return value < s.y0; });
  if (it == segments_.begin()) return 0;
  return static_cast<std::size_t>(it - segments_.begin()) - 1;
}

double TimeMap::ForwardSourceFrame(double y) const {
  if (segments_.empty()) return 0.0;
  if (y >= y_end_) return x_end_;
  const Segment& s = segments_[SegmentAtOutput(y)];
  const double x = s.x0 + s.Advance(std::max(y - s.y0, 0.0));
  return std::clamp(x, s.x0, s.x1);
}

double TimeMap::SourceFrame(double output_frame) const {
  const double y = std::clamp(output_frame, 0.0, y_end_);
  return ForwardSourceFrame(reverse_ ? y_end_ - y : y);
}

double TimeMap::DecimationRatio(double output_frame) const {
  if (segments_.empty()) return 0.0;
  double y = std::clamp(output_frame, 0.0, y_end_);
  if (reverse_) y = y_end_ - y;
  const Segment& s = segments_[SegmentAtOutput(y)];
  return s.Rate(std::clamp(y - s.y0, 0.0, s.duration));
}

double TimeMap::OutputFrame(double source_frame) const {
  const double x = std::clamp(source_frame, 0.0, x_end_);
  double y = 0.0;
  auto it = std::lower_bound(segments_.begin(), segments_.end(), x,
                             [](const Segment& s, double value) { return s.x1 < value; });
  if (it != segments_.end()) {
    const Segment& s = *it;
    y = s.y0;
    if (s.kind != SegmentKind::kHold) y += std::min(s.Elapsed(x - s.x0), s.duration);
    y = std::min(y, y_end_);
  } else if (!segments_.empty()) {
    y = y_end_;
  }
  return reverse_ ? y_end_ - y : y;
}

double TimeMap::SourceTime(double output_seconds) const {
  return SourceFrame(output_seconds / output_frame_time_) * source_frame_time_;
}

double TimeMap::OutputTime(double source_seconds) const {
  return OutputFrame(source_seconds / source_frame_time_) * output_frame_time_;
}

double TimeMap::SpeedAt(double output_seconds) const {
  return DecimationRatio(output_seconds / output_frame_time_) * source_frame_time_ /
         output_frame_time_;
}

void TimeMap::SampleOutputGrid(std::span<double> source_frames, std::span<double> ratios) const {
  const std::size_t m = source_frames.size();
  if (segments_.empty()) {
    std::fill(source_frames.begin(), source_frames.end(), 0.0);
    std::fill(ratios.begin(), ratios.end(), 0.0);
    return;
  }
  const std::size_t n = segments_.size();
  std::size_t seg = reverse_ ? n - 1 : 0;
  for (std::size_t j = 0; j < m; ++j) {
    // Output times come straight from the index: y_j = j, never accumulated.
    const double y_out = std::min(static_cast<double>(j), y_end_);
    const double y = reverse_ ? y_end_ - y_out : y_out;
    if (reverse_) {
      while (seg > 0 && segments_[seg].y0 > y) --seg;
    } else {
      while (seg + 1 < n && segments_[seg + 1].y0 <= y) ++seg;
    }
    const Segment& s = segments_[seg];
    const double into = std::clamp(y - s.y0, 0.0, s.duration);
    ratios[j] = s.Rate(into);
    source_frames[j] = y >= y_end_ ? x_end_ : std::clamp(s.x0 + s.Advance(into), s.x0, s.x1);
  }
}

}  // namespace tempokey::core
