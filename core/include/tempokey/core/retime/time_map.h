// The one exact time map of a retime (SPEC 3.1, 3.2): every kind of warp (speed over source
// time, speed over output time, time-map keys, holds, reverse), fit to a duration or to the
// output grid, pinned poses and a frame-rate change compile into one monotonic map between
// output time t and source time τ, evaluated in closed form (no numeric integration, no
// per-region rounding).
//
// Internally the map works in frame units: source position x = τ·f_s (source frames, samples at
// integers 0..N-1) and output position y = t·f_o (output frames, samples at integers 0..M-1), so
// output sample j is at y = j exactly and an identity map gives x = j exactly. Speeds in the API
// are ratios of seconds (source seconds per output second); in frame units (source frames per
// output frame) they are multiplied by r = output frame time / source frame time = f_s / f_o.
//
// Segment kinds and their closed forms (s = output frames into the segment, u = source frames
// into it, h its source span):
//   speed over source, v linear in x from v0 to v1 (m = (v1 - v0) / h):
//     elapsed(u) = log1p(m·u / v0) / m,   advance(s) = v0·expm1(m·s) / m,   duration = h / L(v0, v1)
//   speed over output, s linear in y from s0 to s1 over duration D (k = (s1 - s0) / D):
//     advance(s) = s0·s + k·s²/2,  elapsed(u) = 2u / (s0 + sqrt(s0² + 2k·u))
//   linear (identity, time-map keys): advance(s) = v·s
//   hold: advance(s) = 0 for its whole duration.
// log1p(z)/z and expm1(z)/z use a short series when |z| < 1e-6.
#ifndef TEMPOKEY_CORE_RETIME_TIME_MAP_H_
#define TEMPOKEY_CORE_RETIME_TIME_MAP_H_

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::core {

// log1p(z) / z, accurate for every z > -1 (series near 0; 1 at z = 0).
double Log1pRatio(double z);
// expm1(z) / z, accurate for every z (series near 0; 1 at z = 0).
double Expm1Ratio(double z);

class TimeMap {
 public:
  // Compiles `warp` for a source of `source_frame_count` samples `source_frame_time_seconds`
  // apart, applying from `options`: fit_seconds / fit_frames, fit_to_grid, output_rate, pins,
  // min_speed / max_speed. (filter, method and rotation_mode are not the map's business.)
  //
  // Fit semantics: every speed segment of the scaled interval is scaled by one constant c (holds
  // keep their length). With fit_to_grid on, a fit_seconds target is rounded to the nearest
  // whole output frame. Pins split the clip into intervals at their source times, each scaled
  // by its own constant so the pinned source time lands exactly on its output frame; the
  // interval after the last pin is the one fit / fit-to-grid scale. A pinned source time with a
  // hold at the same time lands on the first frame of the hold.
  //
  // Reverse: the output plays the (fitted) map backwards: output time t shows τ(T_o - t).
  // Time-map keys: linear between keys, restricted to the clip's source span [0, T_s] (the keys
  // must cover it) and shifted so the output starts at 0; equal source times make a hold.
  //
  // Errors: kInvalidArgument naming the knot / key / hold / pin / option, e.g.
  //   "speed knot 3 (2s:-0.5): speed must be > 0",
  //   "fit to 0.001 s: needs speeds scaled by 8275, so the clip would play at speed 8275, over
  //    the maximum 100".
  // Thread-safe: a pure function of its arguments.
  static absl::StatusOr<TimeMap> Compile(double source_frame_time_seconds,
                                         std::int64_t source_frame_count,
                                         const TimeWarpSpec& warp, const RetimeOptions& options);

  double source_frame_time_seconds() const { return source_frame_time_; }
  // The output frame time: the output rate's denominator / numerator, or the source's frame
  // time when no output rate is set.
  double output_frame_time_seconds() const { return output_frame_time_; }
  // T_s = (N - 1) · source frame time.
  double source_duration_seconds() const { return x_end_ * source_frame_time_; }
  // T_o.
  double output_duration_seconds() const { return y_end_ * output_frame_time_; }
  // M = floor(T_o·f_o + 1e-9) + 1.
  std::int64_t output_frame_count() const { return output_frame_count_; }
  // The constant the last (or only) interval's speeds were scaled by: fit or fit to grid; 1
  // when neither applies.
  double fit_factor() const { return fit_factor_; }
  // One constant per pin interval (empty without pins), in pin order.
  const std::vector<double>& pin_factors() const { return pin_factors_; }
  bool reversed() const { return reverse_; }

  // τ(t) in seconds for output time t in seconds (clamped to [0, T_o]).
  double SourceTime(double output_seconds) const;
  // t(τ) in seconds for source time τ in seconds (clamped to [0, T_s]). Inside a hold τ(t) is
  // constant, so t(τ) returns the hold's first output time (its last when reversed).
  double OutputTime(double source_seconds) const;
  // dτ/dt (source seconds per output second, >= 0; 0 inside a hold) at output time t.
  double SpeedAt(double output_seconds) const;

  // Frame-unit versions: x(y) in source frames for output position y in output frames, and
  // |dx/dy|, the local decimation ratio ρ = |dτ/dt|·f_s/f_o.
  double SourceFrame(double output_frame) const;
  double DecimationRatio(double output_frame) const;
  // y(x) in output frames for source position x in source frames.
  double OutputFrame(double source_frame) const;

  // x_j and ρ_j for every output sample j = 0..M-1 (y_j = j), walking the segments once.
  // Precondition: both spans have output_frame_count() elements.
  void SampleOutputGrid(std::span<double> source_frames, std::span<double> ratios) const;

 private:
  enum class SegmentKind { kLinear, kSourceRamp, kOutputRamp, kHold };
  struct Segment {
    SegmentKind kind = SegmentKind::kLinear;
    double x0 = 0.0;        // source span, frames
    double x1 = 0.0;
    double y0 = 0.0;        // output start, frames (set when the map is laid out)
    double duration = 0.0;  // output frames
    double v0 = 0.0;        // source frames per output frame at the start and the end
    double v1 = 0.0;
    std::string label0;     // what sets the speed at each end, for messages
    std::string label1;

    double Advance(double s) const;  // source frames after s output frames
    double Elapsed(double u) const;  // output frames to advance u source frames
    double Rate(double s) const;     // dx/dy after s output frames
    void RecomputeDuration();
    void Scale(double c);
  };
  friend class TimeMapBuilder;

  // Index of the segment holding forward output position y.
  std::size_t SegmentAtOutput(double y) const;
  double ForwardSourceFrame(double y) const;

  double source_frame_time_ = 1.0;
  double output_frame_time_ = 1.0;
  double x_end_ = 0.0;
  double y_end_ = 0.0;
  std::int64_t output_frame_count_ = 1;
  double fit_factor_ = 1.0;
  std::vector<double> pin_factors_;
  bool reverse_ = false;
  std::vector<Segment> segments_;
};

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_RETIME_TIME_MAP_H_
