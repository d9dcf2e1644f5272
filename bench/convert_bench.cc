// The convert operation's rotation wrap on the shared captures: the whole operation through
// RunPipeline() (a copy of the clip and the wrap of its rotation channels), and the wrap alone
// beside its reference, std::remainder(v, 360) a sample, which it replaced (WrapDegrees(): the
// same bits, rotation.h).
//
//   ninja -C build convert_bench && build/bench/convert_bench
//
// Items per second are samples: every channel's for the operation, the rotation channels' for
// the wraps.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::core {
namespace {

const char kDanceFile[] =
    TEMPOKEY_SHARED_DIR "/data/bvh/bandai/dataset-1_dance-short_normal_001.bvh";
const char kCmuFile[] = TEMPOKEY_SHARED_DIR "/data/bvh/cmu/131_01.bvh";

const Clip* ClipOrSkip(benchmark::State& state, const char* path) {
  static const absl::StatusOr<Clip> dance = ReadBvhFile(kDanceFile);
  static const absl::StatusOr<Clip> cmu = ReadBvhFile(kCmuFile);
  const absl::StatusOr<Clip>& clip = path == kDanceFile ? dance : cmu;
  if (!clip.ok()) {
    state.SkipWithError(std::string(clip.status().message()).c_str());
    return nullptr;
  }
  return &*clip;
}

// The rotation channels' samples of `clip`, one vector each.
std::vector<std::vector<double>> RotationSamples(const Clip& clip) {
  std::vector<std::vector<double>> out;
  for (const Channel& channel : clip.channels) {
    if (IsRotation(channel.kind)) out.push_back(channel.samples);
  }
  return out;
}

std::int64_t SampleCount(const std::vector<std::vector<double>>& channels) {
  std::int64_t count = 0;
  for (const std::vector<double>& c : channels) count += static_cast<std::int64_t>(c.size());
  return count;
}

void ConvertOperation(benchmark::State& state, const char* path) {
  const Clip* clip = ClipOrSkip(state, path);
  if (clip == nullptr) return;
  const std::vector<PipelineStep> steps = {ConvertStep{.wrap_rotations = true}};
  for (auto _ : state) {
    absl::StatusOr<PipelineResult> result = RunPipeline(*clip, steps);
    if (!result.ok()) {
      state.SkipWithError(std::string(result.status().message()).c_str());
      return;
    }
    benchmark::DoNotOptimize(std::get<Clip>(result->output).channels.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * clip->sample_count());
}

// Wraps the rotation channels of `path`'s clip with `wrap` (each pass on a fresh copy, outside
// the timing; wrapping twice would time already wrapped angles).
template <class Wrap>
void WrapChannels(benchmark::State& state, const char* path, Wrap wrap) {
  const Clip* clip = ClipOrSkip(state, path);
  if (clip == nullptr) return;
  const std::vector<std::vector<double>> source = RotationSamples(*clip);
  std::vector<std::vector<double>> work = source;
  for (auto _ : state) {
    state.PauseTiming();
    work = source;
    state.ResumeTiming();
    for (std::vector<double>& channel : work) wrap(channel);
    benchmark::DoNotOptimize(work.data());
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(state.iterations()) * SampleCount(source));
}

void ByWrapDegrees(std::vector<double>& channel) { WrapDegrees(channel); }

void ByRemainder(std::vector<double>& channel) {
  for (double& v : channel) {
    const double w = std::remainder(v, 360.0);
    v = w == -180.0 ? 180.0 : w;
  }
}

void BM_ConvertWrapCmu(benchmark::State& state) { ConvertOperation(state, kCmuFile); }
void BM_ConvertWrapBandaiDance(benchmark::State& state) { ConvertOperation(state, kDanceFile); }
void BM_WrapDegreesCmu(benchmark::State& state) { WrapChannels(state, kCmuFile, ByWrapDegrees); }
void BM_RemainderWrapCmu(benchmark::State& state) { WrapChannels(state, kCmuFile, ByRemainder); }
void BM_WrapDegreesBandaiDance(benchmark::State& state) {
  WrapChannels(state, kDanceFile, ByWrapDegrees);
}
void BM_RemainderWrapBandaiDance(benchmark::State& state) {
  WrapChannels(state, kDanceFile, ByRemainder);
}

BENCHMARK(BM_ConvertWrapCmu)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ConvertWrapBandaiDance)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_WrapDegreesCmu)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RemainderWrapCmu)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_WrapDegreesBandaiDance)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RemainderWrapBandaiDance)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace tempokey::core

BENCHMARK_MAIN();
