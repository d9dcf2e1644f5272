// The motion data model (SPEC 1): clips of sampled channels over an optional skeleton.
#ifndef TEMPOKEY_CORE_MODEL_CLIP_H_
#define TEMPOKEY_CORE_MODEL_CLIP_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"

namespace tempokey::core {

using Vec3 = std::array<double, 3>;

// What a channel animates. Rotations are Euler angles in degrees.
enum class ChannelKind {
  kXPosition,
  kYPosition,
  kZPosition,
  kXRotation,
  kYRotation,
  kZRotation,
  kScalar,
};

bool IsRotation(ChannelKind kind);
bool IsPosition(ChannelKind kind);
// Axis 0, 1, 2 for X, Y, Z position or rotation; -1 for kScalar.
int Axis(ChannelKind kind);
// The BVH spelling: "Xposition" ... "Zrotation"; "scalar" for kScalar.
std::string_view ChannelKindName(ChannelKind kind);
// Parses a BVH channel name (case-sensitive as BVH files write them, e.g. "Xrotation").
std::optional<ChannelKind> ParseChannelKind(std::string_view name);

// One joint in a flat skeleton. Joints are in file order and a parent always precedes its
// children, so `parent < own index`. No pointers: relations are indices.
struct Joint {
  std::string name;
  int parent = -1;                  // index into Skeleton::joints, -1 for a root
  Vec3 offset{};                    // from the parent, in file units
  std::vector<int> channels;        // indices into Clip::channels, in the joint's file order
  std::vector<Vec3> end_sites;      // End Site offsets below this joint

  friend bool operator==(const Joint&, const Joint&) = default;
};

struct Skeleton {
  std::vector<Joint> joints;

  bool empty() const { return joints.empty(); }
  // Joints plus end sites: the points forward kinematics places (SkeletonPoints()).
  std::int64_t point_count() const {
    std::int64_t count = static_cast<std::int64_t>(joints.size());
    for (const Joint& joint : joints) count += static_cast<std::int64_t>(joint.end_sites.size());
    return count;
  }
  // Index of the joint named `name`, or -1.
  int FindJoint(std::string_view name) const;

  friend bool operator==(const Skeleton&, const Skeleton&) = default;
};

// One sampled channel: one value per frame.
struct Channel {
  int joint = -1;                   // index into Skeleton::joints, -1 for none
  ChannelKind kind = ChannelKind::kScalar;
  std::string name;                 // for scalar channels; joint channels derive theirs
  std::vector<double> samples;

  friend bool operator==(const Channel&, const Channel&) = default;
};

// A timed annotation (foot contact, event); retiming maps it through the time map.
struct Marker {
  std::string name;
  double time_seconds = 0.0;
  double duration_seconds = 0.0;    // 0 for an instant

  friend bool operator==(const Marker&, const Marker&) = default;
};

// A uniformly sampled clip. Sample i of every channel is at time i * frame_time_seconds.
struct Clip {
  std::string name;
  // Seconds between samples, exactly as read (BVH "Frame Time: 0.0083333"); never snapped.
  double frame_time_seconds = 1.0 / 30.0;
  std::int64_t frame_count = 0;
  Skeleton skeleton;                // may be empty: then channels are plain named channels
  std::vector<Channel> channels;    // in motion-column (file) order
  std::vector<Marker> markers;

  double frame_rate() const { return 1.0 / frame_time_seconds; }
  // Time of the last sample: (frame_count - 1) * frame_time_seconds (not frame_count * ...).
  double duration_seconds() const;
  std::int64_t sample_count() const;

  friend bool operator==(const Clip&, const Clip&) = default;
};

// "Hips.Xrotation" for a joint channel, the channel's name for a scalar one, "channel 7" when
// it has neither.
std::string ChannelName(const Clip& clip, int channel_index);
// "channel 14 (LeftKnee.Xrotation)": how messages refer to a channel.
std::string ChannelLabel(const Clip& clip, int channel_index);

// Ranges every number of a clip or keyed clip must lie in, checked by ValidateClipLayout(),
// ValidateClip() and ValidateKeyedClip(), chosen so that every operation's arithmetic stays
// finite and meaningful (no overflow to infinity, no ratio of a subnormal):
//   - frame time in [1e-6 s, 3600 s]: one megahertz (a hundred times any capture rate) to one
//     frame an hour (time-lapse). Slopes divide value differences by it (at most 2e9 / 1e-6 =
//     2e15 per second), retiming divides output by source frame times (a ratio within
//     [1e-5 / 3600, 3600 / 1e-6], speeds in frames therefore finite), and a clip of the most
//     frames (10^7) lasts at most 3.6e10 s, inside kMaxTimeSeconds.
//   - |sample| and |offset| <= 1e9 (file units or degrees): squared errors summed over the
//     largest clip stay below 1e27, distances through 256 nested joints below 1e12, and a
//     double still resolves 1e-7 at that magnitude.
//   - |time| <= 1e11 s for marker times and durations and key times: divided by the smallest
//     frame time that is 1e17 frames, exactly convertible to a 64-bit frame index.
//   - keyed clips: |value| <= 1e12 (room above the sample bound for unwrapped rotations and a
//     fit's overshoot) and |tangent| <= 1e100 per second, so a segment of the longest duration
//     evaluates below 1e112 and its squared error is finite.
inline constexpr double kMinFrameTimeSeconds = 1e-6;
inline constexpr double kMaxFrameTimeSeconds = 3600.0;
inline constexpr double kMaxSampleMagnitude = 1e9;
inline constexpr double kMaxTimeSeconds = 1e11;
inline constexpr double kMaxKeyValueMagnitude = 1e12;
inline constexpr double kMaxKeyTangent = 1e100;

// The index of the first of `samples` that is not a number or lies beyond kMaxSampleMagnitude,
// or samples.size() when every one is within it. Scans in vector blocks: every sample a clip
// takes in (ValidateClip(), a message off the wire, a baked curve) goes through here.
// Thread-safe (reads only `samples`).
std::size_t FirstSampleOutOfRange(std::span<const double> samples);

// OK when `seconds` is a frame time in [kMinFrameTimeSeconds, kMaxFrameTimeSeconds].
// Errors: kInvalidArgument "<what> must be in [1e-06, 3600] seconds, got 1e-320".
absl::Status CheckFrameTime(double seconds, std::string_view what = "frame time");

// Limits on untrusted input (server uploads, files). Defaults suit the largest real captures
// many times over.
struct ClipLimits {
  std::int64_t max_frames = 10'000'000;
  std::int64_t max_channels = 100'000;
  std::int64_t max_samples = 200'000'000;   // frames x channels (1.6 GB of doubles); also
                                             // frames x (joints + end sites)
  int max_joints = 10'000;
  int max_depth = 256;                       // joint nesting
};

// Checks every invariant of SPEC 1: frame time in [kMinFrameTimeSeconds, kMaxFrameTimeSeconds];
// frame_count >= 1; the limits (frames, channels, samples, joints, nesting, and frames x (joints
// + end sites) within max_samples); every channel has frame_count finite samples of magnitude at most
// kMaxSampleMagnitude; joint indices valid, parents before children, joint names non-empty and
// unique, offsets and end sites finite and within kMaxSampleMagnitude; each joint's channel list
// names channels of that joint, and every joint channel is in its joint's list; rotation channels
// of one joint name distinct axes; every marker has a time within +-kMaxTimeSeconds and a
// duration in [0, kMaxTimeSeconds].
//
// Errors: kInvalidArgument naming the channel, joint, marker (0-based index and quoted name),
// frame and value, e.g.
//   "channel 14 (LeftKnee.Xrotation): sample 40 is NaN",
//   "channel 3 (Hips.Xposition): sample 7 is 2e+12, beyond the +-1e9 a clip may hold",
//   "marker 2 (\"contact\"): duration_seconds must be in [0, 1e11], got -0.5".
absl::Status ValidateClip(const Clip& clip, const ClipLimits& limits = {});

// Same checks as ValidateClip() on the layout only (everything but the sample values, markers
// included), for a header received before its samples.
absl::Status ValidateClipLayout(const Clip& clip, const ClipLimits& limits = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_MODEL_CLIP_H_
