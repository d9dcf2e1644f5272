// Speed of the joint world-position error (SPEC 4.4) on the largest shared capture (the Bandai
// dance, 21 joints, 1992 frames): forward kinematics of every point at every frame, the report
// of a reduction (both sources of points, compared), and a whole reduction at the default
// settings beside one with a 1 cm joint bound. Items are the clip's samples (frames x channels),
// so items per second compare with SPEC 8's "per million samples".
#include <string>

#include "benchmark/benchmark.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/reduce/world_error.h"

#pragma GCC diagnostic ignored "-Wmissing-field-initializers"

namespace tempokey::core {
namespace {

const Clip& DanceClip() {
  static const Clip clip = [] {
    absl::StatusOr<Clip> read = ReadBvhFile(std::string(TEMPOKEY_SHARED_DIR) +
                                            "/data/bvh/bandai/dataset-1_dance-short_normal_001.bvh");
    if (!read.ok()) std::abort();
    return *read;
  }();
  return clip;
}

const ReduceResult& DefaultReduction() {
  static const ReduceResult result = [] {
    absl::StatusOr<ReduceResult> reduced = ReduceKeys(DanceClip(), ReduceOptions{});
    if (!reduced.ok()) std::abort();
    return *reduced;
  }();
  return result;
}

void BM_WorldTrajectories(benchmark::State& state) {
  const Clip& clip = DanceClip();
  for (auto _ : state) {
    absl::StatusOr<PointTrajectories> world = WorldTrajectories(clip);
    benchmark::DoNotOptimize(world);
  }
  state.SetItemsProcessed(state.iterations() * clip.sample_count());
}
BENCHMARK(BM_WorldTrajectories)->Unit(benchmark::kMillisecond);

void BM_MeasureWorldError(benchmark::State& state) {
  const Clip& clip = DanceClip();
  const KeyedClip& keyed = DefaultReduction().keyed;
  for (auto _ : state) {
    absl::StatusOr<WorldErrorReport> report = MeasureWorldError(clip, keyed);
    benchmark::DoNotOptimize(report);
  }
  state.SetItemsProcessed(state.iterations() * clip.sample_count());
}
BENCHMARK(BM_MeasureWorldError)->Unit(benchmark::kMillisecond);

void BM_ReduceDefault(benchmark::State& state) {
  const Clip& clip = DanceClip();
  for (auto _ : state) {
    absl::StatusOr<ReduceResult> result = ReduceKeys(clip, ReduceOptions{});
    benchmark::DoNotOptimize(result);
  }
  state.SetItemsProcessed(state.iterations() * clip.sample_count());
}
BENCHMARK(BM_ReduceDefault)->Unit(benchmark::kMillisecond);

void BM_ReduceJointTolerance1cm(benchmark::State& state) {
  const Clip& clip = DanceClip();
  ReduceOptions options;
  options.tolerance.joint_tolerance = JointTolerance{.value = 1.0};
  for (auto _ : state) {
    absl::StatusOr<ReduceResult> result = ReduceKeys(clip, options);
    benchmark::DoNotOptimize(result);
  }
  state.SetItemsProcessed(state.iterations() * clip.sample_count());
}
BENCHMARK(BM_ReduceJointTolerance1cm)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace tempokey::core

BENCHMARK_MAIN();
