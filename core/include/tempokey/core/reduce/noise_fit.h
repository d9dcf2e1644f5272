// The noise-aware key reduction (SPEC 4.3, method `noise`): estimate each channel's noise level
// from the data, take out what is consistent with that noise and nothing more, and keep the
// fewest least-squares C1 Hermite keys that follow what remains.
//
// 1. Noise level (EstimateNoiseSigma). White noise e of level sigma has third differences
//    d_f = e_{f+3} - 3 e_{f+2} + 3 e_{f+1} - e_f of variance (1 + 9 + 9 + 1) sigma^2 = 20 sigma^2,
//    while a smooth motion's third difference is its third derivative times the frame time
//    cubed: small at capture rates. The median of |d| ignores the few frames where motion does
//    show (impacts, Euler flips); for a zero-mean Gaussian the median of |d| is 0.6744897502 (the
//    0.75 quantile of the standard normal) times its standard deviation, hence
//    sigma = median|d| / (0.6744897502 * sqrt(20)). Third rather than second differences: they
//    cancel quadratic motion too, so fast but smooth motion reads as little noise (a motion of
//    period P frames and amplitude A adds about A (2 pi / P)^3 to d, against (2 pi / P)^2).
//
// 2. Denoising (SmoothToNoise): the penalized least-squares curve y minimizing
//      sum_f (y_f - x_f)^2 + sum_r lambda_r (third difference r of y)^2
//    (a Whittaker-Henderson smoother, close kin of the quintic smoothing spline), with the
//    smoothing lambda chosen locally, per block of `block_frames` frames, by Stein's unbiased
//    risk estimate: SURE = RSS - n sigma^2 + 2 sigma^2 tr(S), the expected squared error against
//    the clean motion, where tr(S) is the smoother's degrees of freedom. Where the discrepancy
//    principle (RSS <= N sigma^2) accepts a bias as large as the noise it keeps, SURE balances the
//    two, and locally: quiet stretches are smoothed hard, quick ones lightly. tr(S) per frame is
//    that of the same smoother on an endless signal, (1 / pi) integral over w in [0, pi] of
//    1 / (1 + lambda (2 sin(w / 2))^6), exact away from the ends. Block lambdas are searched on a
//    grid of quarter decades around the channel's best single lambda, each block solved with
//    `block_frames` of context on each side, then interpolated geometrically between block
//    centres. Guard: in any block where the curve leaves a frame farther than guard_sigmas *
//    sigma from the data, the block's lambda is divided by 10 until none does (Gaussian noise
//    exceeds 5 sigma at one frame in 1.7 million, so with the default 5 the guard keeps real
//    motion the smoother would cut, impacts and quick turns, and almost never reacts to noise).
//
// 3. Keys: FitWithinTolerance() (tolerance_fit.h) on the denoised curve with the bound
//    key_sigmas * sigma: the fewest least-squares C1 Hermite keys on frames, slopes free, within
//    that small fraction of the noise of the denoised curve at every frame. The keyed curve is
//    therefore within (guard_sigmas + key_sigmas) * sigma of the data at every frame.
//
// Measured on the jitter benchmark (SPEC 8, bench/filter_bench): see README "Measured".
#ifndef TEMPOKEY_CORE_REDUCE_NOISE_FIT_H_
#define TEMPOKEY_CORE_REDUCE_NOISE_FIT_H_

#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/reduce/tolerance_fit.h"

namespace tempokey::core {

// The noise level of `samples` in value units: median |third difference| / (0.6744897502 *
// sqrt(20)); 0 for fewer than 4 samples. Precondition: finite samples. Thread-safe.
double EstimateNoiseSigma(std::span<const double> samples);

struct NoiseFitOptions {
  // The guard: the denoised curve within this many sigma of every sample; [2, 100].
  double guard_sigmas = 5.0;
  // The keys' bound on the denoised curve, in sigma; [0.01, 10].
  double key_sigmas = 0.2;
  // Frames per block of one smoothing level; [8, 1000000].
  int block_frames = 60;
};

// The denoised curve of step 2 for noise level `sigma` (> 0, finite), one value per sample.
// Fewer than 5 samples are returned as they are. Preconditions: finite samples, options in range
// (FitToNoise() checks them). Thread-safe.
std::vector<double> SmoothToNoise(std::span<const double> samples, double sigma,
                                  const NoiseFitOptions& options = {});

// Steps 2 and 3 on one channel's `samples` (finite) for noise level `sigma` (finite, > 0). One
// frame gives one key; a constant channel two flat keys.
//
// Errors: kInvalidArgument for no samples, a non-finite sample ("sample 40 is NaN"), sigma not
// finite and > 0, options out of range ("key_sigmas must be in [0.01, 10], got 0"); kCancelled
// when `stop` is requested.
// Thread-safe: a pure function of its arguments.
absl::StatusOr<SplineFit> FitToNoise(std::span<const double> samples, double sigma,
                                     const NoiseFitOptions& options = {},
                                     std::stop_token stop = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_REDUCE_NOISE_FIT_H_
