// Content ids of the tempokey.v1 API: a clip's id, "sha256:<64 hex>" over a canonical
// serialization of its layout and samples, so the same clip gets the same id however it was
// sliced for upload (the server names stored clips by it; `tempokey batch` records it to know
// whether an input changed), and the same "sha256:<hex>" spelling for plain bytes.
//
// Canonical form: the tag "tempokey.clip.v1", then the name, frame time (IEEE bits), frame
// count, joints (name, parent, offset, end sites), channels (joint, kind, name) and markers,
// every string length-prefixed and every number little-endian 8 bytes; then the samples of
// channel 0, 1, ... each frame 0..N-1 as little-endian IEEE doubles.
#ifndef TEMPOKEY_PROTO_CLIP_DIGEST_H_
#define TEMPOKEY_PROTO_CLIP_DIGEST_H_

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "tempokey/core/model/clip.h"

namespace tempokey::wire {

// The content id of a whole clip. Thread-safe: a pure function.
std::string ClipContentId(const core::Clip& clip);

// "sha256:<64 lowercase hex>" of `bytes` (the same as `sha256sum`). Thread-safe.
std::string Sha256Id(std::string_view bytes);

// Where the canonical order of a clip's samples has reached: channel 0, 1, ... each frame 0..N-1.
class CanonicalSampleOrder {
 public:
  CanonicalSampleOrder(std::int64_t frame_count, int channel_count)
      : frame_count_(frame_count), channel_count_(channel_count) {}

  // Whether `count` samples of `channel` from `first_frame` come next in the order; if so, moves
  // past them.
  bool Advance(int channel, std::int64_t first_frame, std::size_t count);

  int channel() const { return channel_; }      // the next sample's channel (channel_count: none)
  std::int64_t frame() const { return frame_; }  // and frame

 private:
  std::int64_t frame_count_;
  int channel_count_;
  int channel_ = 0;
  std::int64_t frame_ = 0;
};

// Digests a clip while it is being assembled: samples that continue the canonical order are
// hashed as they arrive (uploads sent channel by channel in frame order cost nothing extra at
// the end); whatever arrived out of order is hashed from the finished clip by Finish().
// Not thread-safe: one per upload.
class IncrementalClipDigest {
 public:
  // Hashes the canonical header of `layout` (samples are not read).
  explicit IncrementalClipDigest(const core::Clip& layout);
  ~IncrementalClipDigest();
  IncrementalClipDigest(const IncrementalClipDigest&) = delete;
  IncrementalClipDigest& operator=(const IncrementalClipDigest&) = delete;

  // Offers samples of `channel` starting at `first_frame`, already accepted by the assembler.
  void Offer(int channel, std::int64_t first_frame, std::span<const double> samples);
  // Hashes the rest from `clip` (the assembled clip with the same layout) and returns the id.
  std::string Finish(const core::Clip& clip);

 private:
  struct Hasher;
  std::unique_ptr<Hasher> hasher_;
  std::int64_t frame_count_ = 0;
  int channel_count_ = 0;
  CanonicalSampleOrder hashed_;  // how far the samples hashed so far reach
};

}  // namespace tempokey::wire

#endif  // TEMPOKEY_PROTO_CLIP_DIGEST_H_
