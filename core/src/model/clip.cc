#include "tempokey/core/model/clip.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <span>
#include <string>
#include <vector>

#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/src/simd/block_scan.h"
#include "core/src/simd/instruction_set.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr std::array<std::string_view, 7> kKindNames = {
    "Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation", "scalar"};

}  // namespace

bool IsRotation(ChannelKind kind) {
  return kind == ChannelKind::kXRotation || kind == ChannelKind::kYRotation ||
         kind == ChannelKind::kZRotation;
}

bool IsPosition(ChannelKind kind) {
  return kind == ChannelKind::kXPosition || kind == ChannelKind::kYPosition ||
         kind == ChannelKind::kZPosition;
}

int Axis(ChannelKind kind) {
  switch (kind) {
    case ChannelKind::kXPosition:
    case ChannelKind::kXRotation:
      return 0;
    case ChannelKind::kYPosition:
    case ChannelKind::kYRotation:
      return 1;
    case ChannelKind::kZPosition:
    case ChannelKind::kZRotation:
      return 2;
    case ChannelKind::kScalar:
      return -1;
  }
  return -1;
}

std::string_view ChannelKindName(ChannelKind kind) {
  return kKindNames[static_cast<std::size_t>(kind)];
}

std::optional<ChannelKind> ParseChannelKind(std::string_view name) {
  for (std::size_t i = 0; i + 1 < kKindNames.size(); ++i) {
    if (kKindNames[i] == name) return static_cast<ChannelKind>(i);
  }
  return std::nullopt;
}

int Skeleton::FindJoint(std::string_view name) const {
  for (std::size_t i = 0; i < joints.size(); ++i) {
    if (joints[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

double Clip::duration_seconds() const {
  return frame_count > 0 ? static_cast<double>(frame_count - 1) * frame_time_seconds : 0.0;
}

std::int64_t Clip::sample_count() const {
  return frame_count * static_cast<std::int64_t>(channels.size());
}

std::string ChannelName(const Clip& clip, int channel_index) {
  if (channel_index < 0 || channel_index >= static_cast<int>(clip.channels.size())) {
    return absl::StrCat("channel ", channel_index);
  }
  const Channel& channel = clip.channels[channel_index];
  if (channel.joint >= 0 && channel.joint < static_cast<int>(clip.skeleton.joints.size()) &&
      channel.kind != ChannelKind::kScalar) {
    return absl::StrCat(clip.skeleton.joints[channel.joint].name, ".",
                        AsAbsl(ChannelKindName(channel.kind)));
  }
  if (!channel.name.empty()) return channel.name;
  return absl::StrCat("channel ", channel_index);
}

std::string ChannelLabel(const Clip& clip, int channel_index) {
  return absl::StrCat("channel ", channel_index, " (", ChannelName(clip, channel_index), ")");
}

absl::Status CheckFrameTime(double seconds, std::string_view what) {
  // Written so that NaN fails too.
  if (seconds >= kMinFrameTimeSeconds && seconds <= kMaxFrameTimeSeconds) {
    return absl::OkStatus();
  }
  return absl::InvalidArgumentError(absl::StrCat(AsAbsl(what), " must be in [",
                                                 DescribeDouble(kMinFrameTimeSeconds), ", ",
                                                 DescribeDouble(kMaxFrameTimeSeconds),
                                                 "] seconds, got ", DescribeDouble(seconds)));
}

namespace {

// A joint offset or end site: finite and within kMaxSampleMagnitude.
absl::Status CheckOffset(std::size_t j, const Joint& joint, std::string_view what,
                         const Vec3& offset) {
  for (double v : offset) {
    if (!std::isfinite(v)) {
      return absl::InvalidArgumentError(absl::StrCat("joint ", j, " (", joint.name, "): ",
                                                     AsAbsl(what), " is ", DescribeDouble(v)));
    }
    if (std::abs(v) > kMaxSampleMagnitude) {
      return absl::InvalidArgumentError(absl::StrCat(
          "joint ", j, " (", joint.name, "): ", AsAbsl(what), " ", DescribeDouble(v),
          " is beyond the +-", DescribeDouble(kMaxSampleMagnitude), " a clip may hold"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ValidateClipLayout(const Clip& clip, const ClipLimits& limits) {
  TEMPOKEY_RETURN_IF_ERROR(CheckFrameTime(clip.frame_time_seconds));
  if (clip.frame_count < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("a clip needs at least 1 frame, got ", clip.frame_count));
  }
  if (clip.frame_count > limits.max_frames) {
    return OverLimitError(absl::StrCat("clip has ", clip.frame_count,
                                                   " frames, over the limit of ",
                                                   limits.max_frames));
  }
  if (clip.channels.empty()) return absl::InvalidArgumentError("clip has no channels");
  const auto channel_count = static_cast<std::int64_t>(clip.channels.size());
  if (channel_count > limits.max_channels) {
    return OverLimitError(absl::StrCat("clip has ", channel_count,
                                                   " channels, over the limit of ",
                                                   limits.max_channels));
  }
  if (clip.frame_count > limits.max_samples / channel_count) {
    return OverLimitError(absl::StrCat(
        "clip has ", clip.frame_count, " frames x ", channel_count, " channels, over the limit of ",
        limits.max_samples, " samples"));
  }

  const auto& joints = clip.skeleton.joints;
  if (static_cast<std::int64_t>(joints.size()) > limits.max_joints) {
    return OverLimitError(absl::StrCat("skeleton has ", joints.size(),
                                                   " joints, over the limit of ",
                                                   limits.max_joints));
  }
  // Forward kinematics places every joint and end site at every frame (a reduction's world
  // error, the joint bound): as many positions as samples at most, or a few channels with many
  // end sites (which carry no samples) would cost memory and time the sample limit does not see.
  const std::int64_t points = clip.skeleton.point_count();
  if (points > 0 && clip.frame_count > limits.max_samples / points) {
    return OverLimitError(absl::StrCat(
        "skeleton has ", points, " joints and end sites x ", clip.frame_count,
        " frames, over the limit of ", limits.max_samples,
        " positions (as many as the sample limit: each is placed at every frame)"));
  }
  absl::flat_hash_set<std::string_view> names;
  std::vector<int> depth(joints.size(), 0);
  // Whether some joint lists the channel (only its own joint can: checked below), so that each
  // channel's check that its joint lists it is a lookup, not a search of the joint's list (one
  // joint may list up to every channel of the clip as scalars).
  std::vector<char> listed(static_cast<std::size_t>(channel_count), 0);
  for (std::size_t j = 0; j < joints.size(); ++j) {
    const Joint& joint = joints[j];
    if (joint.name.empty()) return absl::InvalidArgumentError(absl::StrCat("joint ", j, " has no name"));
    if (!names.insert(joint.name).second) {
      return absl::InvalidArgumentError(absl::StrCat("joint ", j, ": duplicate joint name \"", joint.name, "\""));
    }
    if (joint.parent < -1 || joint.parent >= static_cast<int>(j)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "joint ", j, " (", joint.name, "): parent index ", joint.parent,
          " must be -1 or an earlier joint"));
    }
    depth[j] = joint.parent < 0 ? 1 : depth[joint.parent] + 1;
    if (depth[j] > limits.max_depth) {
      return absl::InvalidArgumentError(absl::StrCat("joint ", j, " (", joint.name,
                                                     "): nesting deeper than ", limits.max_depth));
    }
    TEMPOKEY_RETURN_IF_ERROR(CheckOffset(j, joint, "offset", joint.offset));
    for (const Vec3& end_site : joint.end_sites) {
      TEMPOKEY_RETURN_IF_ERROR(CheckOffset(j, joint, "end site offset", end_site));
    }
    unsigned rotation_axes = 0;
    unsigned position_axes = 0;
    for (int c : joint.channels) {
      if (c < 0 || c >= channel_count) {
        return absl::InvalidArgumentError(absl::StrCat("joint ", j, " (", joint.name,
                                                       "): channel index ", c, " out of range"));
      }
      const Channel& channel = clip.channels[c];
      if (channel.joint != static_cast<int>(j)) {
        return absl::InvalidArgumentError(absl::StrCat(
            "joint ", j, " (", joint.name, ") lists ", ChannelLabel(clip, c),
            " which belongs to joint ", channel.joint));
      }
      listed[static_cast<std::size_t>(c)] = 1;
      if (channel.kind == ChannelKind::kScalar) continue;
      unsigned& seen = IsRotation(channel.kind) ? rotation_axes : position_axes;
      const unsigned bit = 1u << Axis(channel.kind);
      if (seen & bit) {
        return absl::InvalidArgumentError(absl::StrCat("joint ", j, " (", joint.name,
                                                       "): channel ", AsAbsl(ChannelKindName(channel.kind)),
                                                       " appears twice"));
      }
      seen |= bit;
    }
  }

  for (std::int64_t c = 0; c < channel_count; ++c) {
    const Channel& channel = clip.channels[c];
    const int ci = static_cast<int>(c);
    if (channel.joint < -1 || channel.joint >= static_cast<int>(joints.size())) {
      return absl::InvalidArgumentError(
          absl::StrCat(ChannelLabel(clip, ci), ": joint index ", channel.joint, " out of range"));
    }
    if (channel.joint >= 0) {
      if (!listed[static_cast<std::size_t>(c)]) {
        return absl::InvalidArgumentError(absl::StrCat(ChannelLabel(clip, ci),
                                                       " is missing from the channel list of joint ",
                                                       joints[channel.joint].name));
      }
    }
  }

  for (std::size_t m = 0; m < clip.markers.size(); ++m) {
    const Marker& marker = clip.markers[m];
    if (!(std::abs(marker.time_seconds) <= kMaxTimeSeconds)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "marker ", m, " (", QuoteForMessage(marker.name), "): time_seconds must be in [-",
          DescribeDouble(kMaxTimeSeconds), ", ", DescribeDouble(kMaxTimeSeconds), "], got ",
          DescribeDouble(marker.time_seconds)));
    }
    if (!(marker.duration_seconds >= 0.0 && marker.duration_seconds <= kMaxTimeSeconds)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "marker ", m, " (", QuoteForMessage(marker.name),
          "): duration_seconds must be in [0, ", DescribeDouble(kMaxTimeSeconds), "], got ",
          DescribeDouble(marker.duration_seconds)));
    }
  }
  return absl::OkStatus();
}

// Scanned in blocks (simd/block_scan.h): every sample of every clip is read here, before any
// work on it.
TEMPOKEY_CLONES_AVX2 std::size_t FirstSampleOutOfRange(std::span<const double> samples) {
  return simd::FirstBeyondMagnitude(samples.data(), samples.size(), kMaxSampleMagnitude);
}

absl::Status ValidateClip(const Clip& clip, const ClipLimits& limits) {
  if (absl::Status layout = ValidateClipLayout(clip, limits); !layout.ok()) return layout;
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    const auto& samples = clip.channels[c].samples;
    if (static_cast<std::int64_t>(samples.size()) != clip.frame_count) {
      return absl::InvalidArgumentError(absl::StrCat(ChannelLabel(clip, static_cast<int>(c)),
                                                     ": has ", samples.size(),
                                                     " samples, the clip has ", clip.frame_count,
                                                     " frames"));
    }
    if (const std::size_t i = FirstSampleOutOfRange(samples); i < samples.size()) {
      // Which rule failed is sorted out only on failure.
      if (!std::isfinite(samples[i])) {
        return absl::InvalidArgumentError(absl::StrCat(ChannelLabel(clip, static_cast<int>(c)),
                                                       ": sample ", i, " is ",
                                                       DescribeDouble(samples[i])));
      }
      return absl::InvalidArgumentError(absl::StrCat(
          ChannelLabel(clip, static_cast<int>(c)), ": sample ", i, " is ",
          DescribeDouble(samples[i]), ", beyond the +-", DescribeDouble(kMaxSampleMagnitude),
          " a clip may hold"));
    }
  }
  return absl::OkStatus();
}

}  // namespace tempokey::core
