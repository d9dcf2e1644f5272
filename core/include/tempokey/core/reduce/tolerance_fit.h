// The error-bounded key reduction (SPEC 4.2): the fewest keys this fit finds such that a C1 cubic
// Hermite spline with keys on integer frames stays within a bound at every frame.
//
// The curve: keys at frames f_0 = 0 < f_1 < ... < f_K = N - 1, each with a value v and a slope m
// (value units per frame) shared by both its segments, so the spline is C1. Between keys a and b,
// L = f_b - f_a, at frame f_a + k, t = k / L:
//   y = h00(t) v_a + h10(t) L m_a + h01(t) v_b + h11(t) L m_b,
// the standard cubic Hermite (h as in hermite_dp.h); in time it is the non-weighted Hermite with
// tangents m / frame_time, which Maya and glTF evaluate identically.
//
// The method (values and slopes are always least-squares fits, which follow the motion and not
// its jitter, never interpolated samples):
//   1. Insertion. Keys every `initial_spacing_frames` (or on `initial_frames`); fit all values
//      and slopes by least squares (one block-tridiagonal solve); insert a key at the worst frame
//      of every segment over the bound; repeat until none is.
//   2. Removal, left to right. Try to drop each key: in a window of up to two keys on each side,
//      refit the nearest key on each side by least squares (the outer ones fixed unless they are
//      the clip's first or last), as it is and with the next key moved by up to `slide_frames`
//      frames (the way the unmoved fit misses); if none fits but the closest misses the bound by
//      at most 1.5 times, reweight that one towards its worst frames (Lawson's iteration towards
//      the minimax fit) for up to `lawson_iterations` rounds. Keep the first trial that fits.
//      No trial makes a segment longer than kMaxMergedSegmentFrames (by merging, or by a slide
//      that lengthens the segment after the slid key): a trial's work grows with its window, so
//      without a limit a smooth stretch merged key by key costs the square of its length (one
//      calm channel of 1 M frames took 132 s, 0.25 s with the limit: cost_bench).
//      A key stays without any trial, as it would after them, where no cubic can follow the
//      frames every trial's merged segment covers (from the key before to the next key slid as
//      far back as it may go) within the bound, proved by a fourth divided difference
//      (core/src/reduce/cubic_certificate.h).
//   3. Verification of every frame; a region that cannot be fitted (only possible with keys on
//      consecutive frames) is keyed at every frame with the samples' values.
// Channels fitted together (a joint's, or a whole clip's: pose-aligned keys) share key frames and
// each keeps its own values and slopes; a trial is kept only if every channel fits its bound.
//
// Measured on ../shared/data (rotation channels, 0.5°): see README "Measured".
#ifndef TEMPOKEY_CORE_REDUCE_TOLERANCE_FIT_H_
#define TEMPOKEY_CORE_REDUCE_TOLERANCE_FIT_H_

#include <cstdint>
#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"

namespace tempokey::core {

// The longest segment a removal makes, in frames (34 s at 120 fps). A start with longer segments
// (a wide initial_spacing_frames, or initial_frames) may keep them, never lengthened.
inline constexpr std::int64_t kMaxMergedSegmentFrames = 4096;

struct ToleranceFitOptions {
  // Spacing of the keys the insertion starts from, in frames; [1, 1000000].
  int initial_spacing_frames = 16;
  // Reweighting rounds towards the minimax fit when a removal misses the bound by less than its
  // size; [0, 100].
  int lawson_iterations = 3;
  // How far the key after a removed one may move to make the removal fit, in frames; [0, 1000].
  int slide_frames = 3;
  // When not empty, the key frames the insertion starts from, in place of keys
  // initial_spacing_frames apart (which is then not used, though still checked): strictly
  // increasing, from 0 to samples - 1. A refit at a tighter bound can start from the keys of its
  // fit at a looser one. Whatever the start, the fit keeps its bound.
  std::vector<std::int64_t> initial_frames = {};
  // Also place the keys by the fewest-keys search (core/src/reduce/fewest_keys_fit.h), and keep
  // whichever of the two fits has fewer keys (the usual one on a tie): the same curve and bound,
  // on the shared captures 14-20 % fewer keys for 150-410 times the time (README,
  // `--fewest-keys`), never more keys than without it. The search does not use the options
  // above (the usual fit does). Where it cannot conclude (a linear program without a verdict, a
  // frame past the bound by rounding: never on the shared captures) the usual fit is kept.
  bool fewest_keys = false;
};

// The fitted spline of a group of channels: shared key frames, per channel values and slopes.
struct SplineFit {
  std::vector<std::int64_t> frames;          // strictly increasing, frames.front() == 0,
                                             // frames.back() == samples - 1
  std::vector<std::vector<double>> values;   // [channel][key], value units
  std::vector<std::vector<double>> slopes;   // [channel][key], value units per frame
};

// Fits `channels` (equal lengths, finite samples) with shared key frames so that every channel c
// stays within `max_errors[c]` (> 0, finite) at every frame, with the spline above. One frame
// gives one key; constant channels cost nothing beyond the group's frames (a lone constant channel
// gets two flat keys).
//
// Errors: kInvalidArgument for no channels, channels of different or zero length, a non-finite
// sample ("channel 2: sample 40 is NaN"), a bound that is not finite and > 0, options out of
// range, initial_frames not from frame 0 to the last or not strictly increasing ("initial_frames
// must be strictly increasing: key 2 at frame 20 follows frame 20"); kCancelled when `stop` is
// requested (checked every 65536 samples of work: insertion rounds, segments, removal windows and
// verification alike).
// Thread-safe: a pure function of its arguments. Each calling thread keeps the fit's solve blocks
// and weights for its next fit (at most 1 MiB a vector, four vectors) until it exits.
absl::StatusOr<SplineFit> FitWithinTolerance(std::span<const std::span<const double>> channels,
                                             std::span<const double> max_errors,
                                             const ToleranceFitOptions& options = {},
                                             std::stop_token stop = {});

// The spline's value at every frame of channel `channel` (for tests and checks).
// Precondition: `fit` came from FitWithinTolerance() on that many frames.
std::vector<double> EvaluateSplineFit(const SplineFit& fit, std::size_t channel);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_TOLERANCE_FIT_H_
