// Speed of the paper's Hermite DP fit (SPEC 8): the whole CMU clip, and one DP pass of the
// optimized implementation beside the brute-force reference on the same small input.
#include <string>
#include <vector>

#include "benchmark/benchmark.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/reduce/hermite_dp.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/model/rotation.h"
#include "tests/core/reduce/hermite_reference.h"

namespace tempokey::core {
namespace {

const Clip& CmuClip() {
  static const Clip clip = [] {
    absl::StatusOr<Clip> read = ReadBvhFile(std::string(TEMPOKEY_SHARED_DIR) +
                                            "/data/bvh/cmu/131_01.bvh");
    if (!read.ok()) std::abort();
    return *read;
  }();
  return clip;
}

// `paper` on all 96 channels of cmu/131_01.bvh, 8 refinement iterations, one thread.
void BM_PaperCmuAllChannels(benchmark::State& state) {
  const Clip& clip = CmuClip();
  ReduceOptions options;
  options.method = ReduceMethod::kPaper;
  options.paper.max_iterations = 8;
  ReductionReport report;
  for (auto _ : state) {
    absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);
    if (!result.ok()) {
      state.SkipWithError("reduce failed");
      return;
    }
    report = result->report;
    benchmark::DoNotOptimize(result->keyed);
  }
  state.counters["keys_percent"] = report.key_percent();
  state.counters["rms"] = report.rms_error;
  state.counters["samples"] = static_cast<double>(report.sample_count);
}
BENCHMARK(BM_PaperCmuAllChannels)->Unit(benchmark::kMillisecond)->MinTime(2.0);

// A 60-frame slice of a CMU rotation channel and its initial keys.
struct Slice {
  std::vector<double> samples;
  std::vector<HermiteKey2D> keys;
};

Slice CmuSlice() {
  std::vector<double> samples = CmuClip().channels[10].samples;
  UnwrapDegrees(samples);
  Slice slice;
  slice.samples.assign(samples.begin() + 400, samples.begin() + 460);
  slice.keys = InitialHermiteKeys(slice.samples, 2.0, 4);
  return slice;
}

// One optimized DP pass over the slice; "segments" counts the segments it covers.
void BM_OptimizedPassOnSlice(benchmark::State& state) {
  const Slice slice = CmuSlice();
  for (auto _ : state) {
    benchmark::DoNotOptimize(RunHermiteDpPass(slice.samples, slice.keys, HermiteSteps{}));
  }
  state.counters["segments"] = static_cast<double>(slice.keys.size() - 1);
  state.counters["per_segment"] = benchmark::Counter(
      static_cast<double>(slice.keys.size() - 1),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_OptimizedPassOnSlice)->Unit(benchmark::kMicrosecond);

// The same pass by brute force: all 6561 combinations per segment, evaluated frame by frame.
void BM_BruteForcePassOnSlice(benchmark::State& state) {
  const Slice slice = CmuSlice();
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        testing::ReferenceDpPass(slice.samples, slice.keys, HermiteSteps{}));
  }
  state.counters["segments"] = static_cast<double>(slice.keys.size() - 1);
  state.counters["per_segment"] = benchmark::Counter(
      static_cast<double>(slice.keys.size() - 1),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_BruteForcePassOnSlice)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace tempokey::core

BENCHMARK_MAIN();
