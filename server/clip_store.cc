#include "server/clip_store.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {

ClipStore::ClipStore(std::int64_t max_clips, std::int64_t max_bytes)
    : max_clips_(std::max<std::int64_t>(1, max_clips)),
      max_bytes_(std::max<std::int64_t>(1, max_bytes)) {}

absl::StatusOr<ClipStore::PutResult> ClipStore::Put(const std::string& id, core::Clip clip) {
  const std::int64_t size = clip.sample_count() * static_cast<std::int64_t>(sizeof(double));
  std::lock_guard lock(mu_);
  if (auto it = clips_.find(id); it != clips_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second.lru);
    return PutResult{.clip = it->second.clip, .already_stored = true};
  }
  if (size > max_bytes_) {
    return absl::ResourceExhaustedError(absl::StrCat("clip ", id, " has ", size,
                                                     " bytes of samples, over the store's limit of ",
                                                     max_bytes_, " bytes"));
  }
  while (!lru_.empty() && (static_cast<std::int64_t>(clips_.size()) >= max_clips_ ||
                           bytes_ + size > max_bytes_)) {
    auto victim = clips_.find(lru_.back());
    bytes_ -= victim->second.bytes;
    clips_.erase(victim);
    lru_.pop_back();
  }
  lru_.push_front(id);
  auto stored = std::make_shared<const core::Clip>(std::move(clip));
  clips_.emplace(id, Entry{.clip = stored, .bytes = size, .lru = lru_.begin()});
  bytes_ += size;
  return PutResult{.clip = std::move(stored), .already_stored = false};
}

absl::StatusOr<std::shared_ptr<const core::Clip>> ClipStore::Get(std::string_view id) {
  std::lock_guard lock(mu_);
  auto it = clips_.find(std::string(id));
  if (it == clips_.end()) {
    return absl::NotFoundError(absl::StrCat("clip \"", core::AsAbsl(id),
                                            "\" not found (never uploaded, or evicted: upload it "
                                            "again)"));
  }
  lru_.splice(lru_.begin(), lru_, it->second.lru);
  return it->second.clip;
}

std::int64_t ClipStore::size() const {
  std::lock_guard lock(mu_);
  return static_cast<std::int64_t>(clips_.size());
}

std::int64_t ClipStore::bytes() const {
  std::lock_guard lock(mu_);
  return bytes_;
}

}  // namespace tempokey::server
