// The paper's literal retiming method against the exact time map (SPEC 3.1).
//
// First prints a table: for linear speed ramps of increasing steepness over a 4 s, 120 fps clip
// of the signal x(τ) = τ (so every output sample's value is the source time it shows), the
// output length each method produces and the paper's timing error, i.e. how far the source time
// shown at output frame j drifts from the exact map's τ(j / f) (compared over the frames both
// have; "end" is the error in total duration). Then times both methods with Google Benchmark.
//
//   retime_paper_bench                       table + timings
//   retime_paper_bench --benchmark_filter=-  table only
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "benchmark/benchmark.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::core {
namespace {

constexpr double kFrameTime = 1.0 / 120;
constexpr std::int64_t kFrames = 481;  // 4 s

Clip TimeSignal() {
  Clip clip;
  clip.name = "time";
  clip.frame_time_seconds = kFrameTime;
  clip.frame_count = kFrames;
  std::vector<double> tau(static_cast<std::size_t>(kFrames));
  for (std::size_t i = 0; i < tau.size(); ++i) tau[i] = static_cast<double>(i) * kFrameTime;
  clip.channels.push_back({.joint = -1, .kind = ChannelKind::kScalar, .name = "tau", .samples = tau});
  return clip;
}

TimeWarpSpec Ramp(double from, double to) {
  TimeWarpSpec warp;
  warp.domain = WarpDomain::kSpeedOverSource;
  warp.speed = {{.time = {0.0, false}, .speed = from}, {.time = {4.0, false}, .speed = to}};
  return warp;
}

// A ramp up then down: two monotonic regions, so the paper rounds twice.
TimeWarpSpec Hill(double low, double high) {
  TimeWarpSpec warp;
  warp.domain = WarpDomain::kSpeedOverSource;
  warp.speed = {{.time = {0.0, false}, .speed = low},
                {.time = {2.0, false}, .speed = high},
                {.time = {4.0, false}, .speed = low}};
  return warp;
}

void PrintTable() {
  const Clip clip = TimeSignal();
  struct Row {
    std::string name;
    TimeWarpSpec warp;
  };
  std::vector<Row> rows;
  for (double to : {1.0, 1.25, 1.5, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0}) {
    char name[32];
    std::snprintf(name, sizeof name, "ramp 1 -> %g", to);
    rows.push_back({name, Ramp(1.0, to)});
  }
  rows.push_back({"ramp 0.25 -> 4", Ramp(0.25, 4.0)});
  rows.push_back({"ramp 4 -> 0.25", Ramp(4.0, 0.25)});
  rows.push_back({"ramp 0.1 -> 1", Ramp(0.1, 1.0)});
  rows.push_back({"hill 1 -> 4 -> 1", Hill(1.0, 4.0)});
  rows.push_back({"hill 0.25 -> 1 -> 0.25", Hill(0.25, 1.0)});

  std::printf("\nPaper method vs exact map: 4 s at 120 fps, linear speed ramps, signal x(t) = t\n");
  std::printf("%-24s %8s %8s %7s %10s %10s %12s %12s\n", "warp", "exact M", "paper M", "diff",
              "exact T_o", "paper T_o", "max |dtau|", "at frame");
  std::printf("%-24s %8s %8s %7s %10s %10s %12s %12s\n", "", "frames", "frames", "frames", "s", "s",
              "ms", "");
  for (const Row& row : rows) {
    RetimeOptions exact_options;
    exact_options.fit_to_grid = false;
    RetimeOptions paper_options;
    paper_options.method = RetimeMethod::kPaper;
    const absl::StatusOr<RetimeResult> exact = Retime(clip, row.warp, exact_options);
    const absl::StatusOr<RetimeResult> paper = Retime(clip, row.warp, paper_options);
    if (!exact.ok() || !paper.ok()) {
      std::printf("%-24s error: %s %s\n", row.name.c_str(), std::string(exact.status().message()).c_str(),
                  std::string(paper.status().message()).c_str());
      continue;
    }
    const std::vector<double>& e = exact->clip.channels[0].samples;
    const std::vector<double>& p = paper->clip.channels[0].samples;
    double worst = 0.0;
    std::size_t worst_at = 0;
    for (std::size_t j = 0; j < std::min(e.size(), p.size()); ++j) {
      if (std::abs(p[j] - e[j]) > worst) {
        worst = std::abs(p[j] - e[j]);
        worst_at = j;
      }
    }
    std::printf("%-24s %8lld %8lld %+7lld %10.6f %10.6f %12.3f %12zu\n", row.name.c_str(),
                static_cast<long long>(exact->report.output_frame_count),
                static_cast<long long>(paper->report.output_frame_count),
                static_cast<long long>(paper->report.output_frame_count -
                                       exact->report.output_frame_count),
                exact->report.output_duration_seconds, paper->report.output_duration_seconds,
                worst * 1e3, worst_at);
  }
  std::printf("\n");
}

void BM_RetimeMethod(benchmark::State& state) {
  static const Clip* clip = new Clip(TimeSignal());
  const TimeWarpSpec warp = Ramp(0.25, 4.0);
  RetimeOptions options;
  options.method = state.range(0) == 0 ? RetimeMethod::kExact : RetimeMethod::kPaper;
  options.fit_to_grid = false;
  std::int64_t samples = 0;
  for (auto _ : state) {
    absl::StatusOr<RetimeResult> r = Retime(*clip, warp, options);
    if (!r.ok()) {
      state.SkipWithError(std::string(r.status().message()).c_str());
      return;
    }
    samples += r->clip.sample_count();
  }
  state.SetItemsProcessed(samples);
  state.SetLabel(state.range(0) == 0 ? "exact" : "paper");
}
BENCHMARK(BM_RetimeMethod)->Arg(0)->Arg(1);

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) {
  tempokey::core::PrintTable();
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
