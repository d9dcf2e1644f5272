// The noise-aware key reduction (SPEC 4.3, method `noise`): estimate each channel's noise level
// from the data, take out what is consistent with that noise and nothing more, and keep the
// fewest least-squares C1 Hermite keys that follow what remains.
//
// 1. Noise level (EstimateNoiseSigma). White noise e of level sigma has k-th differences of
//    variance C(2k, k) sigma^2 (the sum of the squared binomial coefficients: 20 for k = 3, 924
//    for k = 6), and for a zero-mean Gaussian the median of |d| is 0.6744897502 (the 0.75
//    quantile of the standard normal) times its standard deviation, so for every order k
//      s_k = median |k-th difference| / (0.6744897502 sqrt(C(2k, k)))
//    reads sigma. The median ignores the few frames where motion does show (impacts, Euler
//    flips). A smooth motion of angular frequency w (radians per frame) adds to the k-th
//    difference its amplitude times (2 sin(w / 2))^k, and normalised as s_k that falls with k
//    (about sin(w / 2)^k): where s_k falls with the order, the differences are motion, where it
//    stays level they are white noise. Real captures at 30 fps have third differences of the
//    motion itself of 0.02-0.15 degrees (the shared Bandai clips), which s_3 alone reads as noise.
//    Hence:
//      level  s_3 (third differences: they cancel quadratic motion; the lowest order that does
//             keeps the estimate's spread small, 5-95 % within +-9 % on the jitter benchmark);
//      test   the white fraction r = (s_6 / s_3)^2: 1 for white noise (its standard deviation
//             about 1.85 / sqrt(n) over n samples), sigma^2 / (sigma^2 + motion's part) for
//             noise on motion, near 0 for motion alone (a sinusoid: (2 sin(w / 2))^6 20 / 924,
//             2e-6 at 1 Hz and 30 fps);
//      sigma  s_3 sqrt(min(1, r + m)) times a gate, m = 4.3 / sqrt(n) the white fraction's
//             sampling allowance (2.33 standard deviations: about 1 % of white-noise channels
//             fall below 1 - m). The square root takes out of s_3^2 the motion's part beyond
//             that allowance (white noise keeps s_3 whole); the gate is 1 from
//             r >= full = min(0.8, 1 - m), 0 below full - 0.2, linear in between.
//    So the estimate is the noise level where white noise makes up most of the third
//    differences and 0 where the motion does: noise well below the motion's own third
//    differences (0.1 degree on a 30 fps kick) is taken as motion and left in, which is what
//    keeps clean captures from being smoothed. (r is a whiteness test on the lag-1
//    autocorrelations rho_k of the k-th differences: s_{k+1}^2 / s_k^2 =
//    (1 - rho_k) (k + 1) / (2k + 1), and rho_k = -k / (k + 1) for white noise.) Fewer than 7
//    samples: 0. Measured (bench/noise_estimate_bench): the shared Bandai clips as they are read
//    a median of 0 over their rotation channels (the third-difference estimate alone: 0.085);
//    the few above 0.1 degree are hands, feet and toes whose s_3 to s_10 are level at 0.1-0.7
//    degree, white jitter of the capture; the jitter benchmark's channels read median 0.502,
//    5-95 % 0.460-0.545 for the true 0.5.
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
//    A block still over the guard at the lowest level searched (10^-3: a real jump, e.g. a
//    170-degree Euler flip, is moved by about lambda * 10 times its height) drops to 10^-12.
//
// 3. Keys: FitWithinTolerance() (tolerance_fit.h) on the denoised curve with the bound
//    key_sigmas * sigma: the fewest least-squares C1 Hermite keys on frames, slopes free, within
//    that small fraction of the noise of the denoised curve at every frame. The keyed curve is
//    therefore within (guard_sigmas + key_sigmas) * sigma of the data at every frame. The fit's
//    insertion starts from keys about as dense as that bound needs on the curve (2.5 times the L
//    at which a cubic segment's L^4 |fourth difference| / 384 reaches it, for the median fourth
//    difference, in [2, 16] frames) rather than 16 frames apart: at a bound this small the keys
//    end dense, and a fit that starts near its final density ends with fewer keys in fewer rounds.
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

// The noise level of `samples` in value units (step 1 above): s_3 = median |third difference| /
// (0.6744897502 sqrt(20)), gated by the white fraction (s_6 / s_3)^2, so 0 where the third
// differences are the motion's rather than white noise; 0 for fewer than 7 samples.
// Precondition: finite samples. Thread-safe.
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
// frame gives one key; a constant channel two flat keys. (ReduceKeys()'s `noise` method does this
// for every channel but one whose estimate is exactly 0, which it fits without step 2: reduce.h.)
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
