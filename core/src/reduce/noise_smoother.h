// The noise method's smoother with its constant-level factors shared between channels
// (noise_fit.h describes the method). At a constant level the smoother's band matrix depends only
// on the level and the number of frames, so one reduction factors each (level, length) once and
// every channel of the clip of that length, and every block window, reuses the factor: the
// results are bit for bit those of factoring each time.
#ifndef TEMPOKEY_CORE_SRC_REDUCE_NOISE_SMOOTHER_H_
#define TEMPOKEY_CORE_SRC_REDUCE_NOISE_SMOOTHER_H_

#include <cstddef>
#include <functional>
#include <memory>
#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/reduce/noise_fit.h"

namespace tempokey::core::reduce_internal {

// Factors kept for reuse, at most kMaxSmootherFactorBytes of them (beyond, the oldest go).
// Not thread-safe: one per thread (one reduction).
class SmootherFactors {
 public:
  SmootherFactors();
  ~SmootherFactors();
  SmootherFactors(const SmootherFactors&) = delete;
  SmootherFactors& operator=(const SmootherFactors&) = delete;

  struct Store;  // defined in noise_fit.cc
  Store& store() { return *store_; }

 private:
  std::unique_ptr<Store> store_;
};

inline constexpr std::size_t kMaxSmootherFactorBytes = std::size_t{32} << 20;

// Where one channel's smoothing looks at its stop token: between steps of a level search's window
// solves, between its phases (the whole channel's levels, the blocks' levels), every 65536
// penalty rows of a guard round's levels, and every 65536 rows of a band solve (forward, then
// back).
enum class SmootherStopSite { kSearchStep, kPhase, kLevelRows, kBandRows };

// A test's view of those looks: while one is in scope, `probe` is called on this thread with the
// site just before each look at the token, so that a test can request the stop at a chosen look
// (from inside the work, with no race between threads) and count the looks that follow. The
// smoothing runs on the thread that calls it. Probes nest: the innermost is called.
class ScopedSmootherStopProbe {
 public:
  explicit ScopedSmootherStopProbe(std::function<void(SmootherStopSite)> probe);
  ~ScopedSmootherStopProbe();
  ScopedSmootherStopProbe(const ScopedSmootherStopProbe&) = delete;
  ScopedSmootherStopProbe& operator=(const ScopedSmootherStopProbe&) = delete;

 private:
  std::function<void(SmootherStopSite)> probe_;
  const std::function<void(SmootherStopSite)>* outer_;
};

// SmoothToNoise() and FitToNoise() (noise_fit.h) reusing `factors`. Both look at `stop` every
// few milliseconds of work (between batches of window solves, per guard round, and every 65536
// rows of a band solve) and return kCancelled "cancelled" soon after a stop is requested; the
// results are otherwise the same, bit for bit, whatever the token.
absl::StatusOr<std::vector<double>> SmoothToNoise(std::span<const double> samples, double sigma,
                                                  const NoiseFitOptions& options,
                                                  SmootherFactors& factors, std::stop_token stop);
absl::StatusOr<SplineFit> FitToNoise(std::span<const double> samples, double sigma,
                                     const NoiseFitOptions& options, std::stop_token stop,
                                     SmootherFactors& factors);

// Channels whose smoothing SmoothGroupToNoise() does together.
inline constexpr std::size_t kSmootherGroup = 4;

// SmoothToNoise() of several channels, each with its own sigma (sigmas.size() ==
// channels.size()): the same curves bit for bit, faster (the guard rounds' band solves of up to
// kSmootherGroup consecutive channels of one length run side by side). Arguments as
// CheckNoiseFit() accepts them; the same stop behaviour.
absl::StatusOr<std::vector<std::vector<double>>> SmoothGroupToNoise(
    std::span<const std::span<const double>> channels, std::span<const double> sigmas,
    const NoiseFitOptions& options, SmootherFactors& factors, std::stop_token stop);

// FitToNoise()'s checks of its arguments: InvalidArgument naming the first bad sample, sigma or
// option.
absl::Status CheckNoiseFit(std::span<const double> samples, double sigma,
                           const NoiseFitOptions& options);

// FitToNoise()'s keys of `curve` at `sigma` (within key_sigmas * sigma at every frame): a
// channel SmoothToNoise() smoothed, or the samples themselves of a channel in which the estimate
// found no noise (FitNoiseCurves()). The fit's insertion starts from keys InitialKeySpacing()
// apart. kCancelled once a stop is requested.
absl::StatusOr<SplineFit> FitKeysToNoise(std::span<const double> curve, double sigma,
                                         const NoiseFitOptions& options, std::stop_token stop);

// The spacing, in frames, of the keys the fit of `curve` within `bound` (> 0) starts from: about
// as dense as the keys it will end with. A cubic Hermite segment of L frames follows a curve to
// within L^4 |fourth derivative| / 384, so the spacing is kInitialSpacingOverSegment times the L at
// which that reaches the bound for the median |fourth difference| of the curve, floored, within
// [kMinInitialKeySpacing, kMaxInitialKeySpacing] (the widest for fewer than 5 frames or a zero
// median: the tolerance method's 16). Measured on the shared clips (bench/noise_estimate_bench,
// bench/spec8_bench --only=noise): a fit started near its final density ends with fewer keys in
// fewer insertion rounds than one started 16 frames apart; started at L itself, some clips end
// with more (Bandai's bow 25.5 % of samples against 21.8 %), at 2.5 L none of them does.
inline constexpr double kInitialSpacingOverSegment = 2.5;
inline constexpr int kMinInitialKeySpacing = 2;
inline constexpr int kMaxInitialKeySpacing = ToleranceFitOptions{}.initial_spacing_frames;
int InitialKeySpacing(std::span<const double> curve, double bound);

}  // namespace tempokey::core::reduce_internal

#endif  // TEMPOKEY_CORE_SRC_REDUCE_NOISE_SMOOTHER_H_
