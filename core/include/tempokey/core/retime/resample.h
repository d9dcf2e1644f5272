// Resampling one clip's channels at the output sample positions of a time map (SPEC 3.3).
//
// The time map is shared by every channel, so the kernels are planned once per clip: for each
// output sample j, from its source position x_j (source frames) and local decimation ratio ρ_j,
// a ResamplePlan holds the span of source samples it reads and their weights. Applying the plan
// to a channel is then a tight loop of short dot products.
//
// Kernels (d = i - x_j for source sample i, L = N - 1 the last source index):
//   tent (default): the piecewise-linear reconstruction averaged with a continuous triangle of
//     half-width a = ρ·clamp(ρ - 1, 0, 1) source samples. Evaluated exactly: the weight of
//     sample i is hat(d) + E(d+1) - 2E(d) + E(d-1) with E(z) = max(a - |z|, 0)³ / (6a²), the
//     closed form of (hat ⊛ triangle)(d) (the second difference of the triangle's second
//     antiderivative, written without cancellation), so a -> 0 tends to linear interpolation
//     and every weight is accurate to rounding for any a.
//   box: the same reconstruction averaged over a box of half-width b = (ρ/2)·clamp(ρ - 1, 0, 1)
//     (the footprint ρ once compressing): weight hat(d) + F(d+1) - 2F(d) + F(d-1),
//     F(z) = max(b - |z|, 0)² / (4b).
//   linear: point sampling of the linear reconstruction (no anti-aliasing).
//   cubic: Catmull-Rom where a = 0, the tent where a > 0.
//   lanczos3: sinc(u)·sinc(u/3), |u| < 3, u = d / max(1, ρ), weights normalized to sum 1.
// Near the clip's ends the tent and box shrink symmetrically to fit inside [0, L] (a <= x_j,
// a <= L - x_j), so linear signals stay exact and the first and last samples are the source's;
// Catmull-Rom and Lanczos extend the signal by odd reflection about the end samples
// (f(-k) = 2f(0) - f(k)), which also keeps linear signals linear.
// A sample that falls exactly on a source sample with no filtering (a = 0), or exactly on the
// first or last source sample, is a copy: bit-exact.
//
// Rotations (ResampleRotation): Euler angles -> sign-continuous quaternions; slerp where the
// plan interpolates linearly, squad where it is Catmull-Rom, weighted sum then normalize where
// it filters (Markley's eigenvector mean when the taps spread over more than 30°); back to the
// joint's order, the Euler solution nearest the source's unwrapped angles at x_j (so the output
// is continuous wherever the source is), then each angle moved by whole turns to within 180° of
// the source's value at the nearest sample (so it keeps the source's wrapping convention).
// Adjacent source rotations more than 150° apart are treated as a discontinuity (a capture
// glitch or flipped solve, such as CMU's thumb flipping by 171-179° in a frame): interpolated
// samples between them copy the nearer source pose rather than invent a half turn on the
// geodesic. Turns up to 150° a frame (a fast spin at 24 or 30 fps) are interpolated.
#ifndef TEMPOKEY_CORE_RETIME_RESAMPLE_H_
#define TEMPOKEY_CORE_RETIME_RESAMPLE_H_

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <stop_token>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/model/rotation.h"

namespace tempokey::core {

// How one output sample is made from the source.
enum class SampleKind : std::uint8_t {
  kCopy,      // exactly one source sample, weight 1
  kLerp,      // two neighbours, weights (1 - t, t), t = x - first
  kCubic,     // Catmull-Rom over floor(x) - 1 .. floor(x) + 2 (folded at the ends)
  kWeighted,  // a filter kernel over [first, first + count)
};

struct ResamplePlan {
  std::int64_t source_count = 0;
  std::vector<double> position;       // x_j, source frames, clamped to [0, N - 1]
  std::vector<double> width;          // a_j (tent, cubic), b_j (box), Lanczos scale - 1; 0 = none
  std::vector<SampleKind> kind;
  std::vector<std::int64_t> first;    // first source index read
  std::vector<std::int64_t> offset;   // weights of sample j: [offset[j], offset[j + 1])
  std::vector<double> weights;
  std::int64_t filtered_count = 0;    // samples with width > 0
  std::int64_t copy_count = 0;        // samples of kind kCopy
  double max_ratio = 0.0;             // max ρ_j

  std::int64_t output_count() const { return static_cast<std::int64_t>(position.size()); }
};

// Tent half-width a = ρ·clamp(ρ - 1, 0, 1) in source samples.
double TentHalfWidth(double ratio);
// Box half-width b = (ρ/2)·clamp(ρ - 1, 0, 1) in source samples.
double BoxHalfWidth(double ratio);
// Weight of a source sample at offset d = i - x under the tent of half-width a (a >= 0; a = 0 is
// linear interpolation).
double TentWeight(double d, double a);
// Weight under the box of half-width b (b >= 0).
double BoxWeight(double d, double b);
// The Lanczos-3 kernel sinc(u)·sinc(u/3) for |u| < 3, else 0.
double Lanczos3(double u);

// Cancellation: the functions below look at `stop` after every kResampleStopCheckTaps kernel
// taps (a few milliseconds of work at most, whatever the decimation ratio), so a request is seen
// promptly even on a channel of millions of samples.
inline constexpr std::int64_t kResampleStopCheckTaps = 1 << 16;

// Plans the kernels for output samples at `positions` (source frames) with local decimation
// ratios `ratios`, over a source of `source_count` samples.
// Errors: kInvalidArgument when the spans differ in length, source_count < 1, or a position or
// ratio is not finite (ratios must be >= 0); kCancelled when `stop` is requested.
// Thread-safe: a pure function of its arguments.
absl::StatusOr<ResamplePlan> MakeResamplePlan(std::span<const double> positions,
                                              std::span<const double> ratios,
                                              std::int64_t source_count, ResampleFilter filter,
                                              std::stop_token stop = {});

// out[j] = Σ weights · source over sample j's span; for a channel whose samples all compare
// equal, that value itself at every output (the sum's exact value), a copy keeping its own
// sample's bits (-0 and +0 compare equal). Preconditions: source has plan.source_count values,
// out has plan.output_count(). When `stop` is requested it returns early with `out` incomplete:
// the caller checks `stop` afterwards.
void ResampleScalar(const ResamplePlan& plan, std::span<const double> source, std::span<double> out,
                    std::stop_token stop = {});

// Angles in degrees treated as a scalar after unwrapping: resamples the unwrapped channel and
// moves each result by whole turns to within 180° of the source's value at the nearest sample;
// copies are the raw source values. Same preconditions and cancellation as ResampleScalar().
void ResampleAngle(const ResamplePlan& plan, std::span<const double> degrees, std::span<double> out,
                   std::stop_token stop = {});

// One joint's three rotation channels (degrees, listed in `order`), resampled as rotations (see
// the file comment). Preconditions: valid order, each source span has plan.source_count values,
// each output span plan.output_count(). Cancellation as ResampleScalar().
void ResampleRotation(const ResamplePlan& plan, const EulerOrder& order,
                      const std::array<std::span<const double>, 3>& source,
                      const std::array<std::span<double>, 3>& out, std::stop_token stop = {});

// The part of ResampleRotation() that depends on the plan alone (which source samples the joints'
// rotations are read at; for each output sample that interpolates, between which samples and
// where), made once per plan and shared by every joint. Retime() makes one per call. Memory: the
// per-sample tables of a clip that needs at most 64 MB of them are laid out here, once; a longer
// clip's are laid out one batch of outputs at a time as each joint is resampled (the schedule
// then holds a few bytes per batch and the runs of source samples read).
class RotationSchedule {
 public:
  // Cancellation as MakeResamplePlan(): when `stop` is requested the schedule may be left
  // incomplete; the caller looks at `stop` right after and then never uses it (ResampleRotation()
  // with an incomplete schedule writes nothing).
  explicit RotationSchedule(const ResamplePlan& plan, std::stop_token stop = {});
  ~RotationSchedule();
  RotationSchedule(RotationSchedule&&) noexcept;
  RotationSchedule& operator=(RotationSchedule&&) noexcept;

  struct Data;  // resample.cc
  const Data& data() const { return *data_; }

 private:
  std::unique_ptr<Data> data_;
};

// The memory ResampleRotation() works in, handed from one joint to the next: the joint's source
// rotations, unwrapped angles and one batch's scratch, each grown to the largest joint and batch
// it has served. The results do not depend on what it served before. One joint at a time: not
// for several threads at once. A moved-from scratch holds nothing and must not be used again.
class RotationScratch {
 public:
  RotationScratch();
  ~RotationScratch();
  RotationScratch(RotationScratch&&) noexcept;
  RotationScratch& operator=(RotationScratch&&) noexcept;

  // The buffers themselves, for ResampleRotation() (defined in resample.cc).
  struct Buffers;
  Buffers& buffers() { return *buffers_; }

 private:
  std::unique_ptr<Buffers> buffers_;
};

// ResampleRotation() with the schedule of `plan` made beforehand, in `scratch` (Retime() makes
// one of each per call). Same results and cancellation.
void ResampleRotation(const ResamplePlan& plan, const RotationSchedule& schedule,
                      RotationScratch& scratch, const EulerOrder& order,
                      const std::array<std::span<const double>, 3>& source,
                      const std::array<std::span<double>, 3>& out, std::stop_token stop = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_RETIME_RESAMPLE_H_
