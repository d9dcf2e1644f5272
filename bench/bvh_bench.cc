// BVH read and write speed on the shared captures (SPEC 8: parse >= 200 MB/s).
//
//   ninja -C build bvh_bench && build/bench/bvh_bench
//
// Bytes per second are bytes of BVH text: parsed for ParseBvh, produced for FormatBvh.
#include <benchmark/benchmark.h>

#include <cstdint>
#include <cstdlib>
#include <string>

#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/csv.h"
#include "tempokey/core/io/file_io.h"

namespace tempokey::core {
namespace {

const char kDanceFile[] =
    TEMPOKEY_SHARED_DIR "/data/bvh/bandai/dataset-1_dance-short_normal_001.bvh";
const char kCmuFile[] = TEMPOKEY_SHARED_DIR "/data/bvh/cmu/131_01.bvh";

std::string ReadOrDie(benchmark::State& state, const char* path) {
  absl::StatusOr<std::string> text = ReadFile(path);
  if (!text.ok()) {
    state.SkipWithError(std::string(text.status().message()).c_str());
    return {};
  }
  return *std::move(text);
}

void ParseFile(benchmark::State& state, const char* path) {
  const std::string text = ReadOrDie(state, path);
  if (text.empty()) return;
  for (auto _ : state) {
    absl::StatusOr<Clip> clip = ParseBvh(text, path);
    if (!clip.ok()) {
      state.SkipWithError(std::string(clip.status().message()).c_str());
      return;
    }
    benchmark::DoNotOptimize(clip->channels.data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(text.size()));
}

void FormatFile(benchmark::State& state, const char* path) {
  const std::string text = ReadOrDie(state, path);
  if (text.empty()) return;
  absl::StatusOr<Clip> clip = ParseBvh(text, path);
  if (!clip.ok()) {
    state.SkipWithError(std::string(clip.status().message()).c_str());
    return;
  }
  std::int64_t bytes = 0;
  for (auto _ : state) {
    absl::StatusOr<std::string> out = FormatBvh(*clip);
    if (!out.ok()) {
      state.SkipWithError(std::string(out.status().message()).c_str());
      return;
    }
    bytes += static_cast<std::int64_t>(out->size());
    benchmark::DoNotOptimize(out->data());
  }
  state.SetBytesProcessed(bytes);
  state.counters["samples/s"] = benchmark::Counter(
      static_cast<double>(clip->sample_count()) * static_cast<double>(state.iterations()),
      benchmark::Counter::kIsRate);
}

void CsvRoundTrip(benchmark::State& state, const char* path) {
  const std::string text = ReadOrDie(state, path);
  if (text.empty()) return;
  absl::StatusOr<Clip> clip = ParseBvh(text, path);
  absl::StatusOr<std::string> csv = clip.ok() ? FormatCsv(*clip) : clip.status();
  if (!csv.ok()) {
    state.SkipWithError(std::string(csv.status().message()).c_str());
    return;
  }
  for (auto _ : state) {
    absl::StatusOr<Clip> parsed = ParseCsv(*csv, "dance.csv", clip->frame_time_seconds);
    if (!parsed.ok()) {
      state.SkipWithError(std::string(parsed.status().message()).c_str());
      return;
    }
    benchmark::DoNotOptimize(parsed->channels.data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) *
                          static_cast<std::int64_t>(csv->size()));
}

void BM_ParseBvhBandaiDance(benchmark::State& state) { ParseFile(state, kDanceFile); }
void BM_ParseBvhCmu(benchmark::State& state) { ParseFile(state, kCmuFile); }
void BM_FormatBvhBandaiDance(benchmark::State& state) { FormatFile(state, kDanceFile); }
void BM_FormatBvhCmu(benchmark::State& state) { FormatFile(state, kCmuFile); }
void BM_ParseCsvBandaiDance(benchmark::State& state) { CsvRoundTrip(state, kDanceFile); }

BENCHMARK(BM_ParseBvhBandaiDance)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ParseBvhCmu)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FormatBvhBandaiDance)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_FormatBvhCmu)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ParseCsvBandaiDance)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace tempokey::core

BENCHMARK_MAIN();
