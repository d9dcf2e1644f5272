// The one error metric of key reduction (SPEC 4, STYLE: one metric for reduction, tests and
// benchmarks): keyed curves evaluated at every source frame against the unwrapped samples.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/src/simd/block_scan.h"
#include "core/src/simd/instruction_set.h"
#include "reduction_internal.h"
#include "world_error_internal.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/reduce/world_error.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace reduce_internal {
namespace {

struct ChannelErrors {
  ChannelReduction summary;
  double squared_sum = 0.0;
};

// Samples evaluated between two looks at the stop token.
constexpr std::size_t kMeasurePiece = 65536;
// A step between samples below this many degrees rounds to no turn in UnwrapDegrees() whatever
// the rounding of step / 360 (half a turn, less a wide margin).
constexpr double kSafeStepDegrees = 179.0;

// The errors of channel c, `fitted` being its curve sampled at every frame.
ChannelErrors CompareChannel(std::span<const double> samples, int c, const Curve& curve,
                             std::span<const double> fitted) {
  ChannelErrors out;
  out.summary.channel_index = c;
  out.summary.key_count = static_cast<std::int64_t>(curve.keys.size());
  out.summary.sample_count = static_cast<std::int64_t>(samples.size());
  // Every error 0 (a constant channel's flat keys): the loop below would only add zeros, one
  // after another, to a +0 sum; the same figures without its chain of additions.
  if (std::equal(samples.begin(), samples.end(), fitted.begin())) return out;
  for (std::size_t f = 0; f < samples.size(); ++f) {
    const double error = std::abs(fitted[f] - samples[f]);
    out.squared_sum += error * error;
    if (error > out.summary.max_error) {
      out.summary.max_error = error;
      out.summary.max_error_frame = static_cast<std::int64_t>(f);
    }
  }
  out.summary.rms_error =
      samples.empty() ? 0.0 : std::sqrt(out.squared_sum / static_cast<double>(samples.size()));
  return out;
}

ChannelErrors MeasureChannel(std::span<const double> samples, int c, const Curve& curve,
                             double frame_time_seconds, const std::stop_token& stop) {
  std::vector<double> fitted(samples.size());
  for (std::size_t first = 0; first < fitted.size(); first += kMeasurePiece) {
    if (stop.stop_requested()) {
      ChannelErrors out;
      out.summary.channel_index = c;
      out.summary.key_count = static_cast<std::int64_t>(curve.keys.size());
      out.summary.sample_count = static_cast<std::int64_t>(samples.size());
      return out;
    }
    const std::size_t count = std::min(kMeasurePiece, fitted.size() - first);
    SampleCurve(curve, frame_time_seconds, std::span<double>(fitted).subspan(first, count),
                static_cast<std::int64_t>(first));
  }
  return CompareChannel(samples, c, curve, fitted);
}

// Adds one channel's errors to `report`; `squared_sum` gathers every channel's.
void AddChannel(const ChannelErrors& errors, ReductionReport& report, double& squared_sum) {
  const ChannelReduction& channel = errors.summary;
  report.key_count += channel.key_count;
  report.sample_count += channel.sample_count;
  squared_sum += errors.squared_sum;
  if (channel.max_error > report.max_error) {
    report.max_error = channel.max_error;
    report.worst_channel_index = channel.channel_index;
    report.worst_frame = channel.max_error_frame;
  }
  report.channels.push_back(channel);
}

void FinishReport(double squared_sum, ReductionReport& report) {
  report.rms_error = report.sample_count > 0
                         ? std::sqrt(squared_sum / static_cast<double>(report.sample_count))
                         : 0.0;
}

// Whether UnwrapDegrees() leaves `degrees` as they are, bit for bit: every step well under half a
// turn, so its shift stays +0, and no -0 after the first sample, which adding that +0 would turn
// into +0. Scanned in vector blocks (simd/block_scan.h): most captures need no copy at all.
TEMPOKEY_CLONES_AVX2 bool UnwrapKeepsBits(std::span<const double> degrees) {
  using simd::ScanMask;
  using simd::ScanVector;
  const std::size_t n = degrees.size();
  const double* d = degrees.data();
  const auto flagged = [](const double* p) __attribute__((always_inline)) {
    const ScanVector v = simd::LoadScanVector(p);
    const ScanVector step = v - simd::LoadScanVector(p - 1);
    const ScanVector size =
        (ScanVector)((ScanMask)step & std::numeric_limits<std::int64_t>::max());
    // -0 is the bits of the smallest 64-bit integer.
    const ScanMask turn = !(size < kSafeStepDegrees);
    return turn | ((ScanMask)v == std::numeric_limits<std::int64_t>::min());
  };
  for (std::size_t i = n < 2 ? n : simd::FirstFlaggedBlock(d, 1, n, flagged); i < n; ++i) {
    if (!(std::abs(d[i] - d[i - 1]) < kSafeStepDegrees)) return false;
    if (d[i] == 0.0 && std::signbit(d[i])) return false;
  }
  return true;
}

}  // namespace

FittedSamples::FittedSamples(const Clip& clip) {
  unwrapped_.reserve(static_cast<std::size_t>(std::count_if(
      clip.channels.begin(), clip.channels.end(),
      [](const Channel& channel) { return IsRotation(channel.kind); })));
  channels_.reserve(clip.channels.size());
  for (const Channel& channel : clip.channels) {
    if (IsRotation(channel.kind) && !UnwrapKeepsBits(channel.samples)) {
      // Reserved above: the buffers the earlier spans point into never move.
      std::vector<double>& copy = unwrapped_.emplace_back(channel.samples);
      UnwrapDegrees(copy);
      channels_.emplace_back(copy);
    } else {
      channels_.emplace_back(channel.samples);
    }
  }
}

ReductionReport MeasureFitted(std::span<const std::span<const double>> samples,
                              std::span<const Curve> curves, double frame_time_seconds,
                              std::stop_token stop) {
  ReductionReport report;
  double squared_sum = 0.0;
  for (std::size_t c = 0; c < samples.size(); ++c) {
    if (stop.stop_requested()) return report;
    AddChannel(
        MeasureChannel(samples[c], static_cast<int>(c), curves[c], frame_time_seconds, stop),
        report, squared_sum);
  }
  FinishReport(squared_sum, report);
  return report;
}

ReductionReport MeasureBaked(std::span<const std::span<const double>> samples,
                             std::span<const Curve> curves,
                             std::span<const std::span<const double>> baked) {
  ReductionReport report;
  double squared_sum = 0.0;
  for (std::size_t c = 0; c < samples.size(); ++c) {
    AddChannel(CompareChannel(samples[c], static_cast<int>(c), curves[c], baked[c]), report,
               squared_sum);
  }
  FinishReport(squared_sum, report);
  return report;
}

absl::Status CheckCurvesFitClip(const Clip& clip, const KeyedClip& keyed) {
  if (keyed.layout.channels.size() != clip.channels.size()) {
    return absl::InvalidArgumentError(absl::StrCat("keyed clip has ", keyed.layout.channels.size(),
                                                   " channels, the clip has ",
                                                   clip.channels.size()));
  }
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    if (keyed.layout.channels[c].kind != clip.channels[c].kind) {
      return absl::InvalidArgumentError(absl::StrCat(
          ChannelLabel(clip, static_cast<int>(c)), ": the keyed clip's channel is ",
          AsAbsl(ChannelKindName(keyed.layout.channels[c].kind)), ", not ",
          AsAbsl(ChannelKindName(clip.channels[c].kind))));
    }
  }
  return absl::OkStatus();
}

}  // namespace reduce_internal

absl::StatusOr<ReductionReport> MeasureReduction(const Clip& clip, const KeyedClip& keyed) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  TEMPOKEY_RETURN_IF_ERROR(ValidateKeyedClip(keyed));
  TEMPOKEY_RETURN_IF_ERROR(reduce_internal::CheckCurvesFitClip(clip, keyed));
  const reduce_internal::FittedSamples samples(clip);
  ReductionReport report =
      reduce_internal::MeasureFitted(samples.channels(), keyed.curves, clip.frame_time_seconds);
  if (!clip.skeleton.empty()) {
    TEMPOKEY_ASSIGN_OR_RETURN(report.world, MeasureWorldError(clip, keyed));
  }
  return report;
}

}  // namespace tempokey::core
