#include "proto/clip_digest.h"

#include <openssl/evp.h>

#include <bit>
#include <cstring>
#include <string_view>

namespace tempokey::wire {

static_assert(std::endian::native == std::endian::little,
              "the canonical form stores samples as little-endian doubles");

namespace {

// SHA-256 of the canonical form, fed field by field.
struct Sha256 {
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();

  Sha256() { EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr); }
  ~Sha256() { EVP_MD_CTX_free(ctx); }
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;

  void Bytes(const void* data, std::size_t n) {
    if (n > 0) EVP_DigestUpdate(ctx, data, n);
  }
  void U64(std::uint64_t v) { Bytes(&v, sizeof v); }
  void I64(std::int64_t v) { U64(static_cast<std::uint64_t>(v)); }
  void F64(double v) { U64(std::bit_cast<std::uint64_t>(v)); }
  void Str(std::string_view s) {
    U64(s.size());
    Bytes(s.data(), s.size());
  }
  void Vec(const core::Vec3& v) {
    for (double x : v) F64(x);
  }

  std::string Hex() {
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int length = 0;
    EVP_DigestFinal_ex(ctx, digest, &length);
    static constexpr char kHex[] = "0123456789abcdef";
    std::string out = "sha256:";
    for (unsigned int i = 0; i < length; ++i) {
      out.push_back(kHex[digest[i] >> 4]);
      out.push_back(kHex[digest[i] & 15]);
    }
    return out;
  }
};

}  // namespace

struct IncrementalClipDigest::Hasher : Sha256 {};

bool CanonicalSampleOrder::Advance(int channel, std::int64_t first_frame, std::size_t count) {
  if (channel != channel_ || first_frame != frame_ || channel >= channel_count_) return false;
  frame_ += static_cast<std::int64_t>(count);
  if (frame_ == frame_count_) {
    ++channel_;
    frame_ = 0;
  }
  return true;
}

IncrementalClipDigest::IncrementalClipDigest(const core::Clip& layout)
    : hasher_(std::make_unique<Hasher>()),
      frame_count_(layout.frame_count),
      channel_count_(static_cast<int>(layout.channels.size())),
      hashed_(frame_count_, channel_count_) {
  Hasher& h = *hasher_;
  h.Str("tempokey.clip.v1");
  h.Str(layout.name);
  h.F64(layout.frame_time_seconds);
  h.I64(layout.frame_count);
  h.U64(layout.skeleton.joints.size());
  for (const core::Joint& joint : layout.skeleton.joints) {
    h.Str(joint.name);
    h.I64(joint.parent);
    h.Vec(joint.offset);
    h.U64(joint.end_sites.size());
    for (const core::Vec3& end_site : joint.end_sites) h.Vec(end_site);
  }
  h.U64(layout.channels.size());
  for (const core::Channel& channel : layout.channels) {
    h.I64(channel.joint);
    h.I64(static_cast<std::int64_t>(channel.kind));
    h.Str(channel.name);
  }
  h.U64(layout.markers.size());
  for (const core::Marker& marker : layout.markers) {
    h.Str(marker.name);
    h.F64(marker.time_seconds);
    h.F64(marker.duration_seconds);
  }
}

IncrementalClipDigest::~IncrementalClipDigest() = default;

void IncrementalClipDigest::Offer(int channel, std::int64_t first_frame,
                                  std::span<const double> samples) {
  if (hashed_.Advance(channel, first_frame, samples.size())) {
    hasher_->Bytes(samples.data(), samples.size_bytes());
  }
}

std::string IncrementalClipDigest::Finish(const core::Clip& clip) {
  for (int c = hashed_.channel(); c < channel_count_; ++c) {
    const std::int64_t from = c == hashed_.channel() ? hashed_.frame() : 0;
    const std::vector<double>& samples = clip.channels[c].samples;
    hasher_->Bytes(samples.data() + from,
                   static_cast<std::size_t>(frame_count_ - from) * sizeof(double));
  }
  return hasher_->Hex();
}

std::string ClipContentId(const core::Clip& clip) {
  IncrementalClipDigest digest(clip);
  return digest.Finish(clip);
}

std::string Sha256Id(std::string_view bytes) {
  Sha256 hasher;
  hasher.Bytes(bytes.data(), bytes.size());
  return hasher.Hex();
}

}  // namespace tempokey::wire
