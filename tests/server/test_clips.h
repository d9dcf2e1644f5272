// Synthetic clips, a start gate and process figures for server tests; no gRPC in here, so the job pool and
// job manager tests (run under ThreadSanitizer) use it too.
#ifndef TEMPOKEY_TESTS_SERVER_TEST_CLIPS_H_
#define TEMPOKEY_TESTS_SERVER_TEST_CLIPS_H_

#include <chrono>
#include <cmath>
#include <string_view>
#include <cstdint>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "tempokey/core/model/clip.h"
#include "tests/testing/start_gate.h"

namespace tempokey::testing {

// ---- clips --------------------------------------------------------------------------------------

// A clip of `joints` joints with 3 rotation channels each (Z, X, Y order) plus 3 root position
// channels, `frames` frames at 120 Hz. Values are smooth, distinct per channel and frame, and
// some rotations leave (-180, 180] so ConvertStep{wrap_rotations} changes them.
inline core::Clip MakeClip(int joints, std::int64_t frames, double seed = 0.0) {
  core::Clip clip;
  clip.name = "synthetic";
  clip.frame_time_seconds = 1.0 / 120.0;
  clip.frame_count = frames;
  for (int j = 0; j < joints; ++j) {
    core::Joint joint;
    joint.name = "joint" + std::to_string(j);
    joint.parent = j - 1;
    joint.offset = {0.0, 1.0 + j, 0.0};
    const std::vector<core::ChannelKind> kinds =
        j == 0 ? std::vector<core::ChannelKind>{core::ChannelKind::kXPosition,
                                                core::ChannelKind::kYPosition,
                                                core::ChannelKind::kZPosition,
                                                core::ChannelKind::kZRotation,
                                                core::ChannelKind::kXRotation,
                                                core::ChannelKind::kYRotation}
               : std::vector<core::ChannelKind>{core::ChannelKind::kZRotation,
                                                core::ChannelKind::kXRotation,
                                                core::ChannelKind::kYRotation};
    for (core::ChannelKind kind : kinds) {
      const int c = static_cast<int>(clip.channels.size());
      core::Channel channel;
      channel.joint = j;
      channel.kind = kind;
      channel.samples.resize(static_cast<std::size_t>(frames));
      for (std::int64_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 120.0;
        channel.samples[f] = 170.0 * std::sin(0.7 * t + 0.1 * c + seed) + 30.0 * std::cos(3.0 * t) +
                             0.001 * c;
      }
      joint.channels.push_back(c);
      clip.channels.push_back(std::move(channel));
    }
    clip.skeleton.joints.push_back(std::move(joint));
  }
  return clip;
}

// What ConvertStep{wrap_rotations = true} must produce: rotations wrapped into (-180, 180].
inline core::Clip WrappedCopy(core::Clip clip) {
  for (core::Channel& channel : clip.channels) {
    if (!core::IsRotation(channel.kind)) continue;
    for (double& v : channel.samples) {
      double w = std::remainder(v, 360.0);
      if (w == -180.0) w = 180.0;
      v = w;
    }
  }
  return clip;
}

// What an AddressSanitizer build adds to a process's resident set on top of what the code itself
// holds: freed blocks wait in ASan's quarantine (256 MiB by default on 64-bit, the
// quarantine_size_mb flag; compiler-rt asan_flags.cpp) before they are reused, plus redzones and
// shadow pages. A bound on a server's peak RSS adds this in sanitizer builds, so it still catches
// memory kept per request (hundreds of MiB and more) without measuring the sanitizer.
#if defined(TEMPOKEY_SANITIZED)
inline constexpr std::int64_t kSanitizerRssAllowanceKiB = std::int64_t{384} * 1024;
#else
inline constexpr std::int64_t kSanitizerRssAllowanceKiB = 0;
#endif

// Reads a "<field>: <n> kB" line of a /proc/<pid>/status file, in KiB; 0 when unavailable.
inline std::int64_t StatusKiB(const std::string& status_path, const char* field) {
  FILE* file = std::fopen(status_path.c_str(), "r");
  if (file == nullptr) return 0;
  char line[256];
  std::int64_t kib = 0;
  const std::string format = std::string(field) + ": %ld kB";
  while (std::fgets(line, sizeof line, file) != nullptr) {
    if (std::sscanf(line, format.c_str(), &kib) == 1) break;
  }
  std::fclose(file);
  return kib;
}

// Reads /proc/self/status VmHWM (peak resident set), in KiB; 0 when unavailable.
inline std::int64_t PeakRssKiB(const std::string& status_path = "/proc/self/status") {
  return StatusKiB(status_path, "VmHWM");
}

// The resident set now (VmRSS), in KiB; 0 when unavailable.
inline std::int64_t RssKiB(const std::string& status_path = "/proc/self/status") {
  return StatusKiB(status_path, "VmRSS");
}

// Resets the peak resident set (VmHWM) of process `pid` to its current size (Linux >= 4.0:
// writing 5 to /proc/<pid>/clear_refs). False when the kernel refuses.
inline bool ResetPeakRss(int pid) {
  FILE* file = std::fopen(("/proc/" + std::to_string(pid) + "/clear_refs").c_str(), "w");
  if (file == nullptr) return false;
  const bool written = std::fputs("5", file) >= 0;
  return std::fclose(file) == 0 && written;
}

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_SERVER_TEST_CLIPS_H_
