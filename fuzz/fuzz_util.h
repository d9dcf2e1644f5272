// What the libFuzzer targets share: small limits (so one input stays fast), a clip to run fuzzed
// operations on, and the invariants every target checks. A broken invariant prints why and
// aborts, which libFuzzer records as a finding with the input that caused it.
#ifndef TEMPOKEY_FUZZ_FUZZ_UTIL_H_
#define TEMPOKEY_FUZZ_FUZZ_UTIL_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/pipeline/cost.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::fuzz {

// Limits on what a fuzzed input may declare or produce: large enough for every structure,
// small enough that no input costs more than milliseconds or megabytes.
inline core::ClipLimits FuzzLimits() {
  core::ClipLimits limits;
  limits.max_frames = 20'000;
  limits.max_channels = 512;
  limits.max_samples = 100'000;
  limits.max_joints = 256;
  limits.max_depth = 64;
  return limits;
}

// Pipelines predicted under this run for real (cost.h); the rest are only validated.
inline constexpr double kMaxRunSeconds = 0.02;

[[noreturn]] inline void Fail(std::string_view what, std::string_view detail = {}) {
  std::fprintf(stderr, "fuzz invariant broken: %.*s %.*s\n", static_cast<int>(what.size()),
               what.data(), static_cast<int>(detail.size()), detail.data());
  std::abort();
}

inline void Check(bool condition, std::string_view what, std::string_view detail = {}) {
  if (!condition) Fail(what, detail);
}

inline std::string Describe(const absl::Status& status) { return status.ToString(); }

// A refusal must be a clean one: INVALID_ARGUMENT (bad input) or RESOURCE_EXHAUSTED (a cap),
// never INTERNAL, UNKNOWN or anything that says the code itself broke.
inline void CheckCleanRefusal(const absl::Status& status, std::string_view where) {
  Check(status.code() == absl::StatusCode::kInvalidArgument ||
            status.code() == absl::StatusCode::kResourceExhausted,
        where, Describe(status));
  Check(!status.message().empty(), where, "refusal without a message");
}

// Two joints (a root with positions and Z X Y rotations, a child with three rotations) and a
// plain channel, 40 frames at 30 Hz, smooth values within a few hundred units: what fuzzed
// operations run on.
inline core::Clip SmallClip() {
  core::Clip clip;
  clip.name = "fuzz";
  clip.frame_time_seconds = 1.0 / 30.0;
  clip.frame_count = 40;
  core::Joint root;
  root.name = "Hips";
  core::Joint child;
  child.name = "Spine";
  child.parent = 0;
  child.offset = {0.0, 10.0, 0.0};
  child.end_sites = {{0.0, 5.0, 0.0}};
  const core::ChannelKind root_kinds[] = {
      core::ChannelKind::kXPosition, core::ChannelKind::kYPosition, core::ChannelKind::kZPosition,
      core::ChannelKind::kZRotation, core::ChannelKind::kXRotation, core::ChannelKind::kYRotation};
  const core::ChannelKind child_kinds[] = {core::ChannelKind::kZRotation,
                                           core::ChannelKind::kXRotation,
                                           core::ChannelKind::kYRotation};
  auto add = [&](int joint, core::ChannelKind kind) {
    core::Channel channel;
    channel.joint = joint;
    channel.kind = kind;
    const int index = static_cast<int>(clip.channels.size());
    for (std::int64_t f = 0; f < clip.frame_count; ++f) {
      const double t = static_cast<double>(f) / 30.0;
      channel.samples.push_back(170.0 * std::sin(1.7 * t + index) + 3.0 * index);
    }
    clip.channels.push_back(std::move(channel));
    (joint == 0 ? root : child).channels.push_back(index);
  };
  for (core::ChannelKind kind : root_kinds) add(0, kind);
  for (core::ChannelKind kind : child_kinds) add(1, kind);
  clip.skeleton.joints = {root, child};
  core::Channel blend;
  blend.name = "blend";
  for (std::int64_t f = 0; f < clip.frame_count; ++f) {
    blend.samples.push_back(f % 7 == 0 ? 1.0 : 0.25 * static_cast<double>(f % 5));
  }
  clip.channels.push_back(std::move(blend));
  return clip;
}

// Validates `steps` on `clip`; when they are valid and cheap, runs them. What validation accepts
// must run: a failure at run time means a check that should have refused the request before
// queueing did not (or a broken invariant); every result must be valid.
inline void ValidateAndRunIfCheap(const core::Clip& clip,
                                  std::span<const core::PipelineStep> steps) {
  const core::ClipLimits limits = FuzzLimits();
  const absl::StatusOr<core::PipelineCost> cost = core::EstimatePipelineCost(clip, steps, limits);
  if (!cost.ok()) {
    CheckCleanRefusal(cost.status(), "EstimatePipelineCost");
    return;
  }
  Check(std::isfinite(cost->seconds) && cost->seconds >= 0.0, "predicted cost not finite");
  if (cost->seconds > kMaxRunSeconds) return;
  const absl::StatusOr<core::PipelineResult> result =
      core::RunPipeline(clip, steps, {}, {}, limits);
  Check(result.ok(), "a validated pipeline failed when it ran", Describe(result.status()));
  if (const auto* sampled = std::get_if<core::Clip>(&result->output)) {
    const absl::Status valid = core::ValidateClip(*sampled, limits);
    Check(valid.ok(), "pipeline produced an invalid clip", Describe(valid));
  } else {
    const absl::Status valid = core::ValidateKeyedClip(std::get<core::KeyedClip>(result->output));
    Check(valid.ok(), "pipeline produced an invalid keyed clip", Describe(valid));
  }
}

inline std::string_view AsText(const std::uint8_t* data, std::size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

// A stream of messages in one input: records of [1 byte tag][2 bytes little-endian length]
// [payload]; a record running past the end takes what is left. seed_corpus.cc writes the same
// framing (AppendRecord()).
struct Record {
  std::uint8_t tag = 0;
  std::string_view payload;
};

inline std::vector<Record> Records(const std::uint8_t* data, std::size_t size) {
  std::vector<Record> records;
  std::size_t at = 0;
  while (at + 3 <= size) {
    const std::uint8_t tag = data[at];
    const std::size_t length = data[at + 1] | (static_cast<std::size_t>(data[at + 2]) << 8);
    at += 3;
    const std::size_t take = std::min(length, size - at);
    records.push_back({tag, AsText(data + at, take)});
    at += take;
  }
  return records;
}

inline void AppendRecord(std::string& out, std::uint8_t tag, std::string_view payload) {
  const std::size_t length = std::min<std::size_t>(payload.size(), 0xffff);
  out.push_back(static_cast<char>(tag));
  out.push_back(static_cast<char>(length & 0xff));
  out.push_back(static_cast<char>(length >> 8));
  out.append(payload.substr(0, length));
}

}  // namespace tempokey::fuzz

// For targets that parse protobuf messages: protobuf logs every malformed UTF-8 string it meets,
// which would bury libFuzzer's own output; the parse result is what the targets look at.
#define TEMPOKEY_FUZZ_QUIET_PROTOBUF()                                  \
  extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) { \
    google::protobuf::SetLogHandler(nullptr);                           \
    return 0;                                                           \
  }

#endif  // TEMPOKEY_FUZZ_FUZZ_UTIL_H_
