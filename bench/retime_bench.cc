// Retime throughput on real captures: output samples (frames x channels) per second on one core.
//
//   BM_Retime/<clip>/<warp>/<mode>  the whole Retime() call (validation, time map, kernel plan,
//                                   every channel, markers), default `tent` filter; mode
//                                   quaternion = rotation-aware joints (the default), euler =
//                                   every channel through the scalar path (angles unwrapped).
//   BM_ApplyTentPlan/<clip>/<warp>  only the per-channel inner loop: the plan built once, then
//                                   ResampleScalar() over every channel.
//   BM_ApplyRotations/<clip>/<warp> only the rotation-aware per-joint path over every 3-channel
//                                   joint.
// items_per_second is output samples per second.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "benchmark/benchmark.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/retime/resample.h"
#include "tempokey/core/retime/retime.h"
#include "tempokey/core/retime/time_map.h"

namespace tempokey::core {
namespace {

const Clip& LoadClip(const std::string& relative) {
  static auto* cache = new std::vector<std::pair<std::string, Clip>>();
  for (const auto& [name, clip] : *cache) {
    if (name == relative) return clip;
  }
  absl::StatusOr<Clip> clip = ReadBvhFile(std::string(TEMPOKEY_SHARED_DIR) + "/data/bvh/" + relative);
  if (!clip.ok()) {
    std::fprintf(stderr, "cannot read %s: %s\n", relative.c_str(), std::string(clip.status().message()).c_str());
    std::exit(1);
  }
  cache->emplace_back(relative, *std::move(clip));
  return cache->back().second;
}

constexpr const char* kCmu = "cmu/131_01.bvh";
constexpr const char* kBandai = "bandai/dataset-1_dance-short_normal_001.bvh";
// A short clip (146 frames at 30 fps): where the per-call work weighs most; the SPEC 8 table's
// slowest clip and warp on some machines (at 2.5x).
constexpr const char* kBandaiWalk = "bandai/dataset-1_walk_active_001.bvh";

struct Warp {
  TimeWarpSpec warp;
  RetimeOptions options;
};

// 0: the half-speed section "0s:1,2s:1,2s:0.5,4s:0.5,4s:1"; 1: 2.5x speed-up (filtered);
// 2: frame-rate change to 30 fps (120 -> 30 filters with a = 4 on CMU; identity rate on Bandai);
// 3: the identity (copies).
Warp MakeWarp(int index) {
  Warp w;
  switch (index) {
    case 0:
      w.warp.domain = WarpDomain::kSpeedOverSource;
      w.warp.speed = *ParseSpeedKnots("0s:1,2s:1,2s:0.5,4s:0.5,4s:1");
      break;
    case 1:
      w.warp.domain = WarpDomain::kSpeedOverSource;
      w.warp.speed = *ParseSpeedKnots("0s:2.5");
      break;
    case 2:
      w.options.output_rate = FrameRate{30, 1};
      break;
    default:
      break;
  }
  return w;
}

// 0: CMU 131_01; 1: Bandai's dance; 2: Bandai's active walk.
const char* ClipPath(int index) {
  constexpr const char* kPaths[] = {kCmu, kBandai, kBandaiWalk};
  return kPaths[index];
}

void BM_Retime(benchmark::State& state) {
  const Clip& clip = LoadClip(ClipPath(static_cast<int>(state.range(0))));
  Warp w = MakeWarp(static_cast<int>(state.range(1)));
  w.options.rotation_mode = state.range(2) == 0 ? RotationMode::kQuaternion : RotationMode::kEuler;
  std::int64_t samples = 0;
  for (auto _ : state) {
    absl::StatusOr<RetimeResult> r = Retime(clip, w.warp, w.options);
    if (!r.ok()) {
      state.SkipWithError(std::string(r.status().message()).c_str());
      return;
    }
    samples += r->clip.sample_count();
    benchmark::DoNotOptimize(r->clip.channels.data());
  }
  state.SetItemsProcessed(samples);
}

struct Planned {
  ResamplePlan plan;
  std::vector<std::vector<double>> out;
};

Planned PlanFor(const Clip& clip, const Warp& w) {
  const TimeMap map = *TimeMap::Compile(clip.frame_time_seconds, clip.frame_count, w.warp, w.options);
  std::vector<double> x(static_cast<std::size_t>(map.output_frame_count()));
  std::vector<double> rho(x.size());
  map.SampleOutputGrid(x, rho);
  Planned p{*MakeResamplePlan(x, rho, clip.frame_count, ResampleFilter::kTent), {}};
  p.out.assign(clip.channels.size(), std::vector<double>(x.size()));
  return p;
}

void BM_ApplyTentPlan(benchmark::State& state) {
  const Clip& clip = LoadClip(ClipPath(static_cast<int>(state.range(0))));
  Planned p = PlanFor(clip, MakeWarp(static_cast<int>(state.range(1))));
  for (auto _ : state) {
    for (std::size_t c = 0; c < clip.channels.size(); ++c) {
      ResampleScalar(p.plan, clip.channels[c].samples, p.out[c]);
    }
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * p.plan.output_count() *
                          static_cast<std::int64_t>(clip.channels.size()));
}

void BM_ApplyRotations(benchmark::State& state) {
  const Clip& clip = LoadClip(ClipPath(static_cast<int>(state.range(0))));
  Planned p = PlanFor(clip, MakeWarp(static_cast<int>(state.range(1))));
  std::vector<JointRotation> joints;
  for (JointRotation& j : JointRotations(clip)) {
    if (j.channels.size() == 3) joints.push_back(std::move(j));
  }
  for (auto _ : state) {
    for (const JointRotation& j : joints) {
      std::array<std::span<const double>, 3> in;
      std::array<std::span<double>, 3> out;
      for (int k = 0; k < 3; ++k) {
        const auto c = static_cast<std::size_t>(j.channels[static_cast<std::size_t>(k)]);
        in[k] = clip.channels[c].samples;
        out[k] = p.out[c];
      }
      ResampleRotation(p.plan, j.order, in, out);
    }
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * p.plan.output_count() * 3 *
                          static_cast<std::int64_t>(joints.size()));
}

void WarpArgs(benchmark::internal::Benchmark* b, bool modes) {
  b->ArgNames(modes ? std::vector<std::string>{"clip", "warp", "euler"}
                    : std::vector<std::string>{"clip", "warp"});
  for (int clip = 0; clip < 3; ++clip) {
    for (int warp = 0; warp < 4; ++warp) {
      if (modes) {
        b->Args({clip, warp, 0});
        b->Args({clip, warp, 1});
      } else {
        b->Args({clip, warp});
      }
    }
  }
}

BENCHMARK(BM_Retime)->Apply([](benchmark::internal::Benchmark* b) { WarpArgs(b, true); });
BENCHMARK(BM_ApplyTentPlan)->Apply([](benchmark::internal::Benchmark* b) { WarpArgs(b, false); });
BENCHMARK(BM_ApplyRotations)->Apply([](benchmark::internal::Benchmark* b) { WarpArgs(b, false); });

}  // namespace
}  // namespace tempokey::core

BENCHMARK_MAIN();
