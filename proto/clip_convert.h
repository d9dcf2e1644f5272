// Clips, sample slices and keyed curves as tempokey.v1 messages (clip.proto), shared by the server
// and the client. They check what the encoding itself can get wrong (missing headers, indices out
// of range, overlapping or missing slices, unknown enum values) and hand the values to core, whose
// validators are the one set of rules and messages (core::ValidateClipLayout(),
// core::ValidateKeyedClip()).
#ifndef TEMPOKEY_PROTO_CLIP_CONVERT_H_
#define TEMPOKEY_PROTO_CLIP_CONVERT_H_

#include <cstdint>
#include <functional>
#include <map>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "google/protobuf/arena.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/v1/clip.pb.h"

namespace tempokey::wire {

namespace v1 = ::tempokey::v1;


// Default size of the samples carried by one ChannelSamples / KeyedCurve message.
inline constexpr std::int64_t kDefaultSliceBytes = 1 << 20;


// ---- clips --------------------------------------------------------------------------------------

// The layout of `clip` (everything but samples).
v1::ClipHeader ClipHeaderToProto(const core::Clip& clip);
// The same, built in `arena`, which owns it (nullptr: on the heap, the caller's): for a message
// assembled in place (set_allocated_..., AddAllocated() of a message in the same arena take it
// without a copy).
v1::ClipHeader* ClipHeaderOnArena(const core::Clip& clip, google::protobuf::Arena* arena);

// Calls `emit` with consecutive slices of `clip`'s samples, channel by channel, each carrying at
// most `slice_bytes` of samples (at least one sample; `slice_bytes` <= 0 means
// kDefaultSliceBytes). Stops at and returns the first error `emit` returns.
absl::Status ForEachSamplesSlice(const core::Clip& clip, std::int64_t slice_bytes,
                                 const std::function<absl::Status(v1::ChannelSamples&&)>& emit);

// As ForEachSamplesSlice(), but packing consecutive slices into batches of at most `slice_bytes`
// of samples in all (a channel's run split across batches where the budget ends), so a clip of
// many short channels takes a few messages.
absl::Status ForEachSamplesBatch(const core::Clip& clip, std::int64_t slice_bytes,
                                 const std::function<absl::Status(v1::SampleSlices&&)>& emit);

// ForEachSamplesBatch()'s batches one at a time, into a message the sender keeps: each batch is
// built in that message's arena (a scratch arena: scratch_arena.h), and a batch cleared with
// Clear() lends its slices and their arrays to the next, so a long upload's 1 MiB batches take no
// new memory after the first (a batch in a fresh arena each time cost a long upload a block of
// its size allocated, faulted in and given back per batch). `clip` must outlive the batcher.
class SamplesBatcher {
 public:
  SamplesBatcher(const core::Clip& clip, std::int64_t slice_bytes);

  // Adds the next batch to the empty (or cleared) `batch`; false once every sample was given.
  bool Next(v1::SampleSlices* batch);

 private:
  const core::Clip& clip_;
  std::int64_t budget_;  // samples per batch
  std::size_t channel_ = 0;
  std::int64_t first_ = 0;  // the next frame of channel_ to give
};

// Header plus one whole-channel slice per channel.
v1::Clip ClipToProto(const core::Clip& clip);

// How many doubles one slice of at most `slice_bytes` carries (>= 1; `slice_bytes` <= 0 means
// kDefaultSliceBytes; capped at 256 MiB so a slice always fits one message).
std::int64_t SamplesPerSlice(std::int64_t slice_bytes);

// Samples [first_frame, first_frame + count) of channel `channel_index` of `clip`.
// Precondition: the range lies inside the channel (callers iterate within it).
v1::ChannelSamples SamplesSliceToProto(const core::Clip& clip, int channel_index,
                                       std::int64_t first_frame, std::int64_t count);
// The same, built in `arena` (as ClipHeaderOnArena()).
v1::ChannelSamples* SamplesSliceOnArena(const core::Clip& clip, int channel_index,
                                        std::int64_t first_frame, std::int64_t count,
                                        google::protobuf::Arena* arena);

// The layout a header describes (every channel's samples empty), checked with
// core::ValidateClipLayout() against `limits`, and its markers (finite time, duration >= 0).
// Joint channel lists are rebuilt from ChannelInfo.joint_index in channel order.
// Errors: kInvalidArgument naming the field ("header.channels[3].kind: unknown value 12").
absl::StatusOr<core::Clip> ClipLayoutFromProto(const v1::ClipHeader& header,
                                               const core::ClipLimits& limits = {});

// Wire enum <-> core enum. Errors: kInvalidArgument for CHANNEL_KIND_UNSPECIFIED or an unknown
// value.
v1::ChannelKind ChannelKindToProto(core::ChannelKind kind);
absl::StatusOr<core::ChannelKind> ChannelKindFromProto(int kind);

// Called before a ClipAssembler allocates memory, with the bytes it is about to take (> 0), and
// after it frees some (< 0, the returned status ignored). A non-OK status refuses the message
// that needed the memory, before anything is allocated (the server charges its memory budget).
using AllocationHook = std::function<absl::Status(std::int64_t bytes)>;

// Rebuilds a clip from a header and slices arriving in any order. Every slice is checked as it
// arrives (channel index in range, frames in range, no overlap with what arrived before, finite
// samples), so a bad upload is refused at the first bad message.
//
// Memory follows the data that arrived, never the sizes the header declares: slices sent in
// order are appended to their channel (capacity growing at most to twice what arrived); a slice
// out of order is kept as its own run until the frames before it arrive, when it is appended in
// turn. So a header declaring 10 000 000 frames followed by one sample at the last frame holds
// one sample, not 80 MB. The header's counts are checked against `limits` before its layout is
// built.
//
// Errors: kInvalidArgument naming the channel, frame and value ("samples message 3: channel 7
// (Hips.Xrotation): frames 100..199 overlap frames 150..199 already received"), also for samples
// before the header, a second header, or Finish() without a header (a malformed stream is bad
// input); kResourceExhausted for a header over `limits`; any error of the allocation hook.
class ClipAssembler {
 public:
  explicit ClipAssembler(core::ClipLimits limits = {}, AllocationHook on_allocate = {});

  absl::Status AddHeader(const v1::ClipHeader& header);
  absl::Status AddSamples(const v1::ChannelSamples& samples);
  // Each slice of `batch` in order, as if sent one by one (messages are counted per slice); a
  // batch of no slices is refused ("samples message 3: carries no slices").
  absl::Status AddSampleSlices(const v1::SampleSlices& batch);
  bool has_header() const { return has_header_; }
  // The clip being assembled: after AddHeader() its full layout; a channel's samples hold the
  // frames received from frame 0 on without a gap so far. Read the layout here; take samples
  // from the slices themselves.
  const core::Clip& clip() const { return clip_; }
  // Bytes of samples and runs held now (what the hook was told, net).
  std::int64_t allocated_bytes() const { return allocated_bytes_; }
  // The clip, once every sample of every channel has arrived (valid: ValidateClip() holds).
  // Errors: kInvalidArgument "channel 3 (Hips.Zrotation): frames 512..993 never arrived".
  absl::StatusOr<core::Clip> Finish() &&;

 private:
  // Frames of one channel that arrived beyond its gap-free start (clip_.channels[c].samples),
  // by first frame; disjoint, none touching the start.
  using Runs = std::map<std::int64_t, std::vector<double>>;

  absl::Status Allocate(std::int64_t bytes);
  void Free(std::int64_t bytes);
  // Appends `n` values to `dest`, whose final size is at most `cap_limit`, growing its capacity
  // at most to twice its new size (charged to the hook first).
  absl::Status Append(std::vector<double>& dest, const double* data, std::int64_t n,
                      std::int64_t cap_limit);

  core::ClipLimits limits_;
  AllocationHook on_allocate_;
  bool has_header_ = false;
  core::Clip clip_;
  std::vector<Runs> runs_;  // per channel
  std::int64_t allocated_bytes_ = 0;
  std::int64_t messages_ = 0;
};

// ClipAssembler over a whole Clip message.
absl::StatusOr<core::Clip> ClipFromProto(const v1::Clip& clip, const core::ClipLimits& limits = {},
                                         AllocationHook on_allocate = {});

// ---- keyed clips --------------------------------------------------------------------------------

// Column-wise curve. Weights: when any key of the curve has a weight, the weight columns carry
// one entry per key, keys without one getting 1/3 (what a non-weighted key behaves as).
v1::KeyedCurve KeyedCurveToProto(int channel_index, const core::Curve& curve);
v1::KeyedClip KeyedClipToProto(const core::KeyedClip& keyed);

// Keys [first_key, first_key + count) of `curve` as one KeyedCurve piece (weight columns as in
// KeyedCurveToProto(), decided over the whole curve so all pieces agree).
// Precondition: the range lies inside the curve.
v1::KeyedCurve KeyedCurveSliceToProto(int channel_index, const core::Curve& curve,
                                      std::int64_t first_key, std::int64_t count);
// The same, built in `arena` (as ClipHeaderOnArena()).
v1::KeyedCurve* KeyedCurveSliceOnArena(int channel_index, const core::Curve& curve,
                                       std::int64_t first_key, std::int64_t count,
                                       google::protobuf::Arena* arena);
// How many keys of `curve` one piece of at most `slice_bytes` carries (>= 1).
std::int64_t KeysPerSlice(const core::Curve& curve, std::int64_t slice_bytes);

// Calls `emit` with the curves of `keyed` in channel order, a curve with more than `slice_bytes`
// of columns split into several KeyedCurve messages of the same channel_index carrying
// consecutive keys (at least one key each; `slice_bytes` <= 0 means kDefaultSliceBytes).
// KeyedClipFromProto() joins such pieces again. Stops at and returns the first error of `emit`.
absl::Status ForEachKeyedCurveSlice(const core::KeyedClip& keyed, std::int64_t slice_bytes,
                                    const std::function<absl::Status(v1::KeyedCurve&&)>& emit);

// Curves may come in pieces: KeyedCurve messages with the same channel_index are joined in
// arrival order. Every channel of the header needs a curve.
// Errors: kInvalidArgument for a bad header, a channel index out of range, column length
// mismatches, a channel without a curve, and anything ValidateKeyedClip() refuses.
absl::StatusOr<core::KeyedClip> KeyedClipFromProto(const v1::KeyedClip& keyed,
                                                   const core::ClipLimits& limits = {});

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_CLIP_CONVERT_H_
