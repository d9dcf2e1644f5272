// Clips, sample slices and keyed curves as tempokey.v1 messages (clip.proto).
#include "proto/clip_convert.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <map>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "proto/prefault.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::wire {
namespace {

// Largest slice we ever build, whatever the caller asks for: RepeatedField sizes are int.
constexpr std::int64_t kMaxSliceBytes = std::int64_t{1} << 28;

std::int64_t ValuesPerSlice(std::int64_t slice_bytes, std::int64_t bytes_per_value) {
  if (slice_bytes <= 0) slice_bytes = kDefaultSliceBytes;
  slice_bytes = std::min(slice_bytes, kMaxSliceBytes);
  return std::max<std::int64_t>(1, slice_bytes / bytes_per_value);
}

absl::Status Invalid(std::string message) { return absl::InvalidArgumentError(message); }

// What one out-of-order run costs beyond its samples: a map node and the vector's header.
constexpr std::int64_t kRunOverheadBytes = 96;

// Memory the layout of `header` takes once built (joints, channels, markers, their names and
// the assembler's per-channel state), from its counts and string sizes.
std::int64_t LayoutBytesEstimate(const v1::ClipHeader& header) {
  constexpr std::int64_t kPerChannel =
      sizeof(core::Channel) + sizeof(std::map<std::int64_t, std::vector<double>>) + sizeof(int);
  std::int64_t bytes = static_cast<std::int64_t>(header.name().size()) +
                       header.channels_size() * kPerChannel +
                       header.joints_size() * static_cast<std::int64_t>(sizeof(core::Joint)) +
                       header.markers_size() * static_cast<std::int64_t>(sizeof(core::Marker));
  for (const v1::Joint& joint : header.joints()) {
    bytes += static_cast<std::int64_t>(joint.name().size()) +
             joint.end_site_offsets_size() * static_cast<std::int64_t>(sizeof(core::Vec3));
  }
  for (const v1::ChannelInfo& channel : header.channels()) {
    bytes += static_cast<std::int64_t>(channel.name().size());
  }
  for (const v1::Marker& marker : header.markers()) {
    bytes += static_cast<std::int64_t>(marker.name().size());
  }
  return bytes;
}

// ---- clip header ---------------------------------------------------------------------------------

void SetVec3(const core::Vec3& v, v1::Vec3* out) {
  out->set_x(v[0]);
  out->set_y(v[1]);
  out->set_z(v[2]);
}

core::Vec3 Vec3FromProto(const v1::Vec3& v) { return {v.x(), v.y(), v.z()}; }

// "frames 100..199" (inclusive bounds, as people count frames).
std::string FrameRange(std::int64_t begin, std::int64_t end) {
  return absl::StrCat("frames ", begin, "..", end - 1);
}

// Fills the empty `header` with `clip`'s layout; every submessage lands in `header`'s arena.
void AppendClipHeader(const core::Clip& clip, v1::ClipHeader* header) {
  header->set_name(clip.name);
  header->set_frame_time_seconds(clip.frame_time_seconds);
  header->set_frame_count(clip.frame_count);
  header->mutable_joints()->Reserve(static_cast<int>(clip.skeleton.joints.size()));
  for (const core::Joint& joint : clip.skeleton.joints) {
    v1::Joint* j = header->add_joints();
    j->set_name(joint.name);
    j->set_parent_index(joint.parent);
    SetVec3(joint.offset, j->mutable_offset());
    for (const core::Vec3& end_site : joint.end_sites) {
      SetVec3(end_site, j->add_end_site_offsets());
    }
  }
  header->mutable_channels()->Reserve(static_cast<int>(clip.channels.size()));
  for (const core::Channel& channel : clip.channels) {
    v1::ChannelInfo* c = header->add_channels();
    if (channel.joint >= 0) c->set_joint_index(channel.joint);
    c->set_kind(ChannelKindToProto(channel.kind));
    c->set_name(channel.name);
  }
  for (const core::Marker& marker : clip.markers) {
    v1::Marker* m = header->add_markers();
    m->set_name(marker.name);
    m->set_time_seconds(marker.time_seconds);
    m->set_duration_seconds(marker.duration_seconds);
  }
}

// Fills the empty `slice` with samples [first_frame, first_frame + count) of a channel.
void AppendSamplesSlice(const core::Clip& clip, int channel_index, std::int64_t first_frame,
                        std::int64_t count, v1::ChannelSamples* slice) {
  const double* samples = clip.channels[channel_index].samples.data() + first_frame;
  slice->set_channel_index(channel_index);
  slice->set_first_frame(first_frame);
  slice->mutable_samples()->Add(samples, samples + count);
}

}  // namespace

// ---- clips ---------------------------------------------------------------------------------------

v1::ChannelKind ChannelKindToProto(core::ChannelKind kind) {
  switch (kind) {
    case core::ChannelKind::kXPosition:
      return v1::CHANNEL_KIND_X_POSITION;
    case core::ChannelKind::kYPosition:
      return v1::CHANNEL_KIND_Y_POSITION;
    case core::ChannelKind::kZPosition:
      return v1::CHANNEL_KIND_Z_POSITION;
    case core::ChannelKind::kXRotation:
      return v1::CHANNEL_KIND_X_ROTATION;
    case core::ChannelKind::kYRotation:
      return v1::CHANNEL_KIND_Y_ROTATION;
    case core::ChannelKind::kZRotation:
      return v1::CHANNEL_KIND_Z_ROTATION;
    case core::ChannelKind::kScalar:
      return v1::CHANNEL_KIND_SCALAR;
  }
  return v1::CHANNEL_KIND_UNSPECIFIED;
}

absl::StatusOr<core::ChannelKind> ChannelKindFromProto(int kind) {
  switch (kind) {
    case v1::CHANNEL_KIND_X_POSITION:
      return core::ChannelKind::kXPosition;
    case v1::CHANNEL_KIND_Y_POSITION:
      return core::ChannelKind::kYPosition;
    case v1::CHANNEL_KIND_Z_POSITION:
      return core::ChannelKind::kZPosition;
    case v1::CHANNEL_KIND_X_ROTATION:
      return core::ChannelKind::kXRotation;
    case v1::CHANNEL_KIND_Y_ROTATION:
      return core::ChannelKind::kYRotation;
    case v1::CHANNEL_KIND_Z_ROTATION:
      return core::ChannelKind::kZRotation;
    case v1::CHANNEL_KIND_SCALAR:
      return core::ChannelKind::kScalar;
    case v1::CHANNEL_KIND_UNSPECIFIED:
      return Invalid("kind is CHANNEL_KIND_UNSPECIFIED");
    default:
      return Invalid(absl::StrCat("kind has unknown value ", kind));
  }
}

v1::ClipHeader ClipHeaderToProto(const core::Clip& clip) {
  v1::ClipHeader header;
  AppendClipHeader(clip, &header);
  return header;
}

v1::ClipHeader* ClipHeaderOnArena(const core::Clip& clip, google::protobuf::Arena* arena) {
  auto* header = google::protobuf::Arena::CreateMessage<v1::ClipHeader>(arena);
  AppendClipHeader(clip, header);
  return header;
}

absl::StatusOr<core::Clip> ClipLayoutFromProto(const v1::ClipHeader& header,
                                               const core::ClipLimits& limits) {
  // Counts first: a hostile header must not make us build large vectors before the checks.
  if (header.joints_size() > limits.max_joints) {
    return core::OverLimitError(absl::StrCat("header has ", header.joints_size(), " joints, over the limit of ",
                                limits.max_joints));
  }
  if (header.channels_size() > limits.max_channels) {
    return core::OverLimitError(absl::StrCat("header has ", header.channels_size(),
                                " channels, over the limit of ", limits.max_channels));
  }
  core::Clip clip;
  clip.name = header.name();
  clip.frame_time_seconds = header.frame_time_seconds();
  clip.frame_count = header.frame_count();
  clip.skeleton.joints.resize(static_cast<std::size_t>(header.joints_size()));
  for (int j = 0; j < header.joints_size(); ++j) {
    const v1::Joint& in = header.joints(j);
    core::Joint& joint = clip.skeleton.joints[j];
    joint.name = in.name();
    joint.parent = in.parent_index();
    joint.offset = Vec3FromProto(in.offset());
    joint.end_sites.reserve(static_cast<std::size_t>(in.end_site_offsets_size()));
    for (const v1::Vec3& end_site : in.end_site_offsets()) {
      joint.end_sites.push_back(Vec3FromProto(end_site));
    }
  }
  clip.channels.resize(static_cast<std::size_t>(header.channels_size()));
  for (int c = 0; c < header.channels_size(); ++c) {
    const v1::ChannelInfo& in = header.channels(c);
    core::Channel& channel = clip.channels[c];
    absl::StatusOr<core::ChannelKind> kind = ChannelKindFromProto(in.kind());
    if (!kind.ok()) {
      return core::Annotate(kind.status(), absl::StrCat("header.channels[", c, "]"));
    }
    channel.kind = *kind;
    channel.name = in.name();
    if (in.has_joint_index()) {
      if (in.joint_index() < 0 || in.joint_index() >= header.joints_size()) {
        return Invalid(absl::StrCat("header.channels[", c, "]: joint_index ", in.joint_index(),
                                    " out of range, the header has ", header.joints_size(),
                                    " joints"));
      }
      channel.joint = in.joint_index();
      clip.skeleton.joints[channel.joint].channels.push_back(c);
    }
  }
  clip.markers.reserve(static_cast<std::size_t>(header.markers_size()));
  for (int m = 0; m < header.markers_size(); ++m) {
    const v1::Marker& in = header.markers(m);
    clip.markers.push_back(core::Marker{.name = in.name(),
                                        .time_seconds = in.time_seconds(),
                                        .duration_seconds = in.duration_seconds()});
  }
  TEMPOKEY_RETURN_IF_ERROR(core::ValidateClipLayout(clip, limits));
  return clip;
}

std::int64_t SamplesPerSlice(std::int64_t slice_bytes) {
  return ValuesPerSlice(slice_bytes, sizeof(double));
}

v1::ChannelSamples SamplesSliceToProto(const core::Clip& clip, int channel_index,
                                       std::int64_t first_frame, std::int64_t count) {
  v1::ChannelSamples slice;
  AppendSamplesSlice(clip, channel_index, first_frame, count, &slice);
  return slice;
}

v1::ChannelSamples* SamplesSliceOnArena(const core::Clip& clip, int channel_index,
                                        std::int64_t first_frame, std::int64_t count,
                                        google::protobuf::Arena* arena) {
  auto* slice = google::protobuf::Arena::CreateMessage<v1::ChannelSamples>(arena);
  AppendSamplesSlice(clip, channel_index, first_frame, count, slice);
  return slice;
}

absl::Status ForEachSamplesSlice(const core::Clip& clip, std::int64_t slice_bytes,
                                 const std::function<absl::Status(v1::ChannelSamples&&)>& emit) {
  const std::int64_t per_slice = SamplesPerSlice(slice_bytes);
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    const auto total = static_cast<std::int64_t>(clip.channels[c].samples.size());
    for (std::int64_t first = 0; first < total; first += per_slice) {
      TEMPOKEY_RETURN_IF_ERROR(emit(SamplesSliceToProto(clip, static_cast<int>(c), first,
                                                        std::min(per_slice, total - first))));
    }
  }
  return absl::OkStatus();
}

SamplesBatcher::SamplesBatcher(const core::Clip& clip, std::int64_t slice_bytes)
    : clip_(clip), budget_(SamplesPerSlice(slice_bytes)) {}

bool SamplesBatcher::Next(v1::SampleSlices* batch) {
  std::int64_t used = 0;
  while (channel_ < clip_.channels.size()) {
    const auto total = static_cast<std::int64_t>(clip_.channels[channel_].samples.size());
    if (first_ >= total) {
      ++channel_;
      first_ = 0;
      continue;
    }
    const std::int64_t n = std::min(budget_ - used, total - first_);
    AppendSamplesSlice(clip_, static_cast<int>(channel_), first_, n, batch->add_slices());
    first_ += n;
    used += n;
    if (used == budget_) return true;
  }
  return used > 0;
}

absl::Status ForEachSamplesBatch(const core::Clip& clip, std::int64_t slice_bytes,
                                 const std::function<absl::Status(v1::SampleSlices&&)>& emit) {
  SamplesBatcher batches(clip, slice_bytes);
  for (;;) {
    v1::SampleSlices batch;
    if (!batches.Next(&batch)) return absl::OkStatus();
    TEMPOKEY_RETURN_IF_ERROR(emit(std::move(batch)));
  }
}

v1::Clip ClipToProto(const core::Clip& clip) {
  v1::Clip out;
  *out.mutable_header() = ClipHeaderToProto(clip);
  out.mutable_samples()->Reserve(static_cast<int>(clip.channels.size()));
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    const std::vector<double>& samples = clip.channels[c].samples;
    v1::ChannelSamples* slice = out.add_samples();
    slice->set_channel_index(static_cast<std::int32_t>(c));
    slice->set_first_frame(0);
    slice->mutable_samples()->Add(samples.data(), samples.data() + samples.size());
  }
  return out;
}

ClipAssembler::ClipAssembler(core::ClipLimits limits, AllocationHook on_allocate)
    : limits_(limits), on_allocate_(std::move(on_allocate)) {}

absl::Status ClipAssembler::Allocate(std::int64_t bytes) {
  if (bytes <= 0) return absl::OkStatus();
  if (on_allocate_) TEMPOKEY_RETURN_IF_ERROR(on_allocate_(bytes));
  allocated_bytes_ += bytes;
  return absl::OkStatus();
}

void ClipAssembler::Free(std::int64_t bytes) {
  if (bytes <= 0) return;
  allocated_bytes_ -= bytes;
  if (on_allocate_) on_allocate_(-bytes).IgnoreError();
}

absl::Status ClipAssembler::Append(std::vector<double>& dest, const double* data, std::int64_t n,
                                   std::int64_t cap_limit) {
  const auto size = static_cast<std::int64_t>(dest.size());
  const auto capacity = static_cast<std::int64_t>(dest.capacity());
  if (size + n > capacity) {
    // Amortized growth, but only ever over samples that arrived: at most twice the new size,
    // never past what the channel can hold.
    const std::int64_t grown = std::min(cap_limit, std::max(size + n, 2 * capacity));
    TEMPOKEY_RETURN_IF_ERROR(
        Allocate((grown - capacity) * static_cast<std::int64_t>(sizeof(double))));
    dest.reserve(static_cast<std::size_t>(grown));
    // The capacity just charged is about to be filled: map it at once rather than page by page.
    PrefaultForWriting(dest.data() + size, (dest.capacity() - dest.size()) * sizeof(double));
  }
  dest.insert(dest.end(), data, data + n);
  return absl::OkStatus();
}

absl::Status ClipAssembler::AddHeader(const v1::ClipHeader& header) {
  if (has_header_) {
    return Invalid("a second clip header arrived; a clip has exactly one header, sent first");
  }
  // The layout is charged before it is built (its size follows the header's bytes, which have
  // arrived); counts over the limits are refused by ClipLayoutFromProto() before it builds.
  const std::int64_t layout_bytes = header.channels_size() <= limits_.max_channels &&
                                            header.joints_size() <= limits_.max_joints
                                        ? LayoutBytesEstimate(header)
                                        : 0;
  TEMPOKEY_RETURN_IF_ERROR(Allocate(layout_bytes));
  absl::StatusOr<core::Clip> layout = ClipLayoutFromProto(header, limits_);
  if (!layout.ok()) {
    Free(layout_bytes);
    return core::Annotate(layout.status(), "clip header");
  }
  clip_ = *std::move(layout);
  runs_.assign(clip_.channels.size(), {});
  has_header_ = true;
  return absl::OkStatus();
}

absl::Status ClipAssembler::AddSampleSlices(const v1::SampleSlices& batch) {
  // A batch of no slices brings no sample, as an empty slice does: a stream of them would keep
  // a call alive (each message resets its idle timeout) without ever completing the clip.
  if (batch.slices().empty()) {
    return Invalid(absl::StrCat("samples message ", messages_ + 1, ": carries no slices"));
  }
  for (const v1::ChannelSamples& slice : batch.slices()) {
    TEMPOKEY_RETURN_IF_ERROR(AddSamples(slice));
  }
  return absl::OkStatus();
}

absl::Status ClipAssembler::AddSamples(const v1::ChannelSamples& samples) {
  ++messages_;
  if (!has_header_) {
    return Invalid(
        absl::StrCat("samples message ", messages_, " arrived before the clip header"));
  }
  const int c = samples.channel_index();
  const auto channel_count = static_cast<int>(clip_.channels.size());
  if (c < 0 || c >= channel_count) {
    return Invalid(absl::StrCat("samples message ", messages_, ": channel index ", c,
                                " out of range, the clip has ", channel_count, " channels"));
  }
  const std::int64_t n = samples.samples_size();
  const std::int64_t first = samples.first_frame();
  const std::int64_t frames = clip_.frame_count;
  if (n == 0) {
    return Invalid(absl::StrCat("samples message ", messages_, ": ", core::ChannelLabel(clip_, c),
                                ": carries no samples"));
  }
  if (first < 0 || first >= frames) {
    return Invalid(absl::StrCat("samples message ", messages_, ": ", core::ChannelLabel(clip_, c),
                                ": first_frame ", first, " out of range, the clip has ", frames,
                                " frames (0..", frames - 1, ")"));
  }
  if (n > frames - first) {
    return Invalid(absl::StrCat("samples message ", messages_, ": ", core::ChannelLabel(clip_, c),
                                ": ", FrameRange(first, first + n), " run past the last frame ",
                                frames - 1));
  }
  const std::int64_t end = first + n;

  // What arrived: the gap-free start [0, start_end) and the runs after it.
  std::vector<double>& start = clip_.channels[c].samples;
  const auto start_end = static_cast<std::int64_t>(start.size());
  Runs& runs = runs_[c];
  auto overlap = [&](std::int64_t begin, std::int64_t stop) {
    return Invalid(absl::StrCat("samples message ", messages_, ": ", core::ChannelLabel(clip_, c),
                                ": ", FrameRange(first, end), " overlap ", FrameRange(begin, stop),
                                " already received"));
  };
  if (first < start_end) return overlap(first, std::min(end, start_end));
  auto next = runs.upper_bound(first);
  auto prev = next == runs.begin() ? runs.end() : std::prev(next);
  if (prev != runs.end()) {
    const std::int64_t prev_end = prev->first + static_cast<std::int64_t>(prev->second.size());
    if (prev_end > first) return overlap(first, std::min(end, prev_end));
  }
  if (next != runs.end() && next->first < end) {
    const std::int64_t next_end = next->first + static_cast<std::int64_t>(next->second.size());
    return overlap(next->first, std::min(end, next_end));
  }

  const double* data = samples.samples().data();
  if (const auto bad = static_cast<std::int64_t>(
          core::FirstSampleOutOfRange({data, static_cast<std::size_t>(n)}));
      bad < n) {
    return Invalid(absl::StrCat(
        "samples message ", messages_, ": ", core::ChannelLabel(clip_, c), ": sample at frame ",
        first + bad, " is ", core::DescribeDouble(data[bad]),
        std::isfinite(data[bad])
            ? absl::StrCat(", beyond the +-", core::DescribeDouble(core::kMaxSampleMagnitude),
                           " a clip may hold")
            : ""));
  }

  if (first == start_end) {
    // In order (what every sender does): append, then take in the runs it now reaches.
    TEMPOKEY_RETURN_IF_ERROR(Append(start, data, n, frames));
    while (!runs.empty() && runs.begin()->first == static_cast<std::int64_t>(start.size())) {
      std::vector<double>& run = runs.begin()->second;
      TEMPOKEY_RETURN_IF_ERROR(
          Append(start, run.data(), static_cast<std::int64_t>(run.size()), frames));
      Free(kRunOverheadBytes +
           static_cast<std::int64_t>(run.capacity() * sizeof(double)));
      runs.erase(runs.begin());
    }
    return absl::OkStatus();
  }
  if (prev != runs.end() &&
      prev->first + static_cast<std::int64_t>(prev->second.size()) == first) {
    return Append(prev->second, data, n, frames - prev->first);
  }
  // A new run: its own memory, sized by what arrived.
  TEMPOKEY_RETURN_IF_ERROR(
      Allocate(kRunOverheadBytes + n * static_cast<std::int64_t>(sizeof(double))));
  runs.emplace_hint(next, first, std::vector<double>(data, data + n));
  return absl::OkStatus();
}

absl::StatusOr<core::Clip> ClipAssembler::Finish() && {
  if (!has_header_) return Invalid("no clip header arrived");
  for (std::size_t c = 0; c < clip_.channels.size(); ++c) {
    const auto have = static_cast<std::int64_t>(clip_.channels[c].samples.size());
    if (have < clip_.frame_count) {
      const std::int64_t gap_end = runs_[c].empty() ? clip_.frame_count : runs_[c].begin()->first;
      return Invalid(absl::StrCat(core::ChannelLabel(clip_, static_cast<int>(c)), ": ",
                                  FrameRange(have, gap_end), " never arrived"));
    }
  }
  // The layout was checked by AddHeader(), every sample by AddSamples() and completeness above:
  // the clip is valid without another pass over its samples.
  has_header_ = false;
  runs_.clear();
  return std::move(clip_);
}

absl::StatusOr<core::Clip> ClipFromProto(const v1::Clip& clip, const core::ClipLimits& limits,
                                         AllocationHook on_allocate) {
  if (!clip.has_header()) return Invalid("clip has no header");
  ClipAssembler assembler(limits, std::move(on_allocate));
  TEMPOKEY_RETURN_IF_ERROR(assembler.AddHeader(clip.header()));
  for (const v1::ChannelSamples& samples : clip.samples()) {
    TEMPOKEY_RETURN_IF_ERROR(assembler.AddSamples(samples));
  }
  return std::move(assembler).Finish();
}

// ---- keyed clips ---------------------------------------------------------------------------------

namespace {

bool IsWeighted(const core::Curve& curve) {
  return std::any_of(curve.keys.begin(), curve.keys.end(), [](const core::Key& k) {
    return k.in_weight.has_value() || k.out_weight.has_value();
  });
}

// Appends keys [begin, end) of `curve` to `out`'s columns.
void AppendKeys(const core::Curve& curve, std::size_t begin, std::size_t end, bool weighted,
                v1::KeyedCurve* out) {
  const int n = static_cast<int>(end - begin);
  out->mutable_time_seconds()->Reserve(out->time_seconds_size() + n);
  out->mutable_value()->Reserve(out->value_size() + n);
  out->mutable_in_tangent()->Reserve(out->in_tangent_size() + n);
  out->mutable_out_tangent()->Reserve(out->out_tangent_size() + n);
  if (weighted) {
    out->mutable_in_weight()->Reserve(out->in_weight_size() + n);
    out->mutable_out_weight()->Reserve(out->out_weight_size() + n);
  }
  constexpr double kUnweighted = 1.0 / 3.0;
  for (std::size_t i = begin; i < end; ++i) {
    const core::Key& k = curve.keys[i];
    out->add_time_seconds(k.time_seconds);
    out->add_value(k.value);
    out->add_in_tangent(k.in_tangent);
    out->add_out_tangent(k.out_tangent);
    if (weighted) {
      out->add_in_weight(k.in_weight.value_or(kUnweighted));
      out->add_out_weight(k.out_weight.value_or(kUnweighted));
    }
  }
}

// Fills the empty `piece` with keys [first_key, first_key + count) of `curve`.
void AppendCurveSlice(int channel_index, const core::Curve& curve, std::int64_t first_key,
                      std::int64_t count, v1::KeyedCurve* piece) {
  piece->set_channel_index(channel_index);
  AppendKeys(curve, static_cast<std::size_t>(first_key),
             static_cast<std::size_t>(first_key + count), IsWeighted(curve), piece);
}

}  // namespace

v1::KeyedCurve KeyedCurveToProto(int channel_index, const core::Curve& curve) {
  v1::KeyedCurve out;
  out.set_channel_index(channel_index);
  AppendKeys(curve, 0, curve.keys.size(), IsWeighted(curve), &out);
  return out;
}

v1::KeyedClip KeyedClipToProto(const core::KeyedClip& keyed) {
  v1::KeyedClip out;
  *out.mutable_header() = ClipHeaderToProto(keyed.layout);
  out.mutable_curves()->Reserve(static_cast<int>(keyed.curves.size()));
  for (std::size_t c = 0; c < keyed.curves.size(); ++c) {
    *out.add_curves() = KeyedCurveToProto(static_cast<int>(c), keyed.curves[c]);
  }
  return out;
}

v1::KeyedCurve KeyedCurveSliceToProto(int channel_index, const core::Curve& curve,
                                      std::int64_t first_key, std::int64_t count) {
  v1::KeyedCurve piece;
  AppendCurveSlice(channel_index, curve, first_key, count, &piece);
  return piece;
}

v1::KeyedCurve* KeyedCurveSliceOnArena(int channel_index, const core::Curve& curve,
                                       std::int64_t first_key, std::int64_t count,
                                       google::protobuf::Arena* arena) {
  auto* piece = google::protobuf::Arena::CreateMessage<v1::KeyedCurve>(arena);
  AppendCurveSlice(channel_index, curve, first_key, count, piece);
  return piece;
}

std::int64_t KeysPerSlice(const core::Curve& curve, std::int64_t slice_bytes) {
  return ValuesPerSlice(slice_bytes,
                        static_cast<std::int64_t>(sizeof(double)) * (IsWeighted(curve) ? 6 : 4));
}

absl::Status ForEachKeyedCurveSlice(const core::KeyedClip& keyed, std::int64_t slice_bytes,
                                    const std::function<absl::Status(v1::KeyedCurve&&)>& emit) {
  for (std::size_t c = 0; c < keyed.curves.size(); ++c) {
    const core::Curve& curve = keyed.curves[c];
    const std::int64_t per_slice = KeysPerSlice(curve, slice_bytes);
    const auto total = static_cast<std::int64_t>(curve.keys.size());
    std::int64_t first = 0;
    do {
      const std::int64_t n = std::min(per_slice, total - first);
      TEMPOKEY_RETURN_IF_ERROR(emit(KeyedCurveSliceToProto(static_cast<int>(c), curve, first, n)));
      first += n;
    } while (first < total);
  }
  return absl::OkStatus();
}

absl::StatusOr<core::KeyedClip> KeyedClipFromProto(const v1::KeyedClip& keyed,
                                                   const core::ClipLimits& limits) {
  if (!keyed.has_header()) return Invalid("keyed clip has no header");
  core::KeyedClip out;
  absl::StatusOr<core::Clip> layout = ClipLayoutFromProto(keyed.header(), limits);
  if (!layout.ok()) return core::Annotate(layout.status(), "keyed clip header");
  out.layout = *std::move(layout);
  const auto channel_count = static_cast<int>(out.layout.channels.size());
  out.curves.resize(static_cast<std::size_t>(channel_count));
  std::vector<bool> seen(static_cast<std::size_t>(channel_count), false);
  std::int64_t total_keys = 0;
  for (int m = 0; m < keyed.curves_size(); ++m) {
    const v1::KeyedCurve& in = keyed.curves(m);
    const int c = in.channel_index();
    if (c < 0 || c >= channel_count) {
      return Invalid(absl::StrCat("curve message ", m + 1, ": channel index ", c,
                                  " out of range, the clip has ", channel_count, " channels"));
    }
    const std::string where =
        absl::StrCat("curve message ", m + 1, ": ", core::ChannelLabel(out.layout, c));
    const int n = in.time_seconds_size();
    if (n == 0) return Invalid(absl::StrCat(where, ": carries no keys"));
    if (in.value_size() != n || in.in_tangent_size() != n || in.out_tangent_size() != n) {
      return Invalid(absl::StrCat(where, ": columns differ in length: time_seconds ", n,
                                  ", value ", in.value_size(), ", in_tangent ",
                                  in.in_tangent_size(), ", out_tangent ", in.out_tangent_size()));
    }
    if ((in.in_weight_size() != 0 && in.in_weight_size() != n) ||
        (in.out_weight_size() != 0 && in.out_weight_size() != n)) {
      return Invalid(absl::StrCat(where, ": weight columns must be empty or have one entry per key (",
                                  n, "), got in_weight ", in.in_weight_size(), ", out_weight ",
                                  in.out_weight_size()));
    }
    total_keys += n;
    if (total_keys > limits.max_samples) {
      return core::OverLimitError(absl::StrCat("keyed clip has more than ", limits.max_samples,
                                  " keys, over the limit"));
    }
    std::vector<core::Key>& keys = out.curves[c].keys;
    keys.reserve(keys.size() + static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      core::Key key;
      key.time_seconds = in.time_seconds(i);
      key.value = in.value(i);
      key.in_tangent = in.in_tangent(i);
      key.out_tangent = in.out_tangent(i);
      if (in.in_weight_size() != 0) key.in_weight = in.in_weight(i);
      if (in.out_weight_size() != 0) key.out_weight = in.out_weight(i);
      keys.push_back(key);
    }
    seen[c] = true;
  }
  for (int c = 0; c < channel_count; ++c) {
    if (!seen[c]) {
      return Invalid(absl::StrCat(core::ChannelLabel(out.layout, c), ": no curve arrived"));
    }
  }
  TEMPOKEY_RETURN_IF_ERROR(core::ValidateKeyedClip(out));
  return out;
}

}  // namespace tempokey::wire
