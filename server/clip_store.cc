#include "server/clip_store.h"

#include <algorithm>
#include <vector>

#include "absl/strings/str_cat.h"
#include "server/memory_size.h"
#include "tempokey/core/model/status.h"

namespace tempokey::server {
namespace {

// Owners are hex digests or empty, ids printable: a newline cannot occur in either.
std::string Key(std::string_view owner, std::string_view id) {
  return absl::StrCat(core::AsAbsl(owner), "\n", core::AsAbsl(id));
}

}  // namespace

ClipStore::ClipStore(std::int64_t max_clips, std::int64_t max_bytes)
    : max_clips_(std::max<std::int64_t>(1, max_clips)),
      max_bytes_(std::max<std::int64_t>(1, max_bytes)) {}

void ClipStore::EraseLocked(std::unordered_map<std::string, Entry>::iterator it) {
  bytes_ -= it->second.bytes;
  lru_.erase(it->second.lru);
  clips_.erase(it);
}

absl::StatusOr<ClipStore::PutResult> ClipStore::Put(std::string_view owner, const std::string& id,
                                                    std::shared_ptr<const core::Clip> clip) {
  const std::int64_t size = ClipBytes(*clip);
  // Clips dropped here are released after the lock (their memory goes back to the budget).
  std::vector<std::shared_ptr<const core::Clip>> evicted;
  std::lock_guard lock(mu_);
  const std::string key = Key(owner, id);
  if (auto it = clips_.find(key); it != clips_.end()) {
    lru_.splice(lru_.begin(), lru_, it->second.lru);
    return PutResult{.clip = it->second.clip, .already_stored = true};
  }
  if (size > max_bytes_) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "clip ", id, " takes ", size, " bytes, over the limit of ", max_bytes_,
        " bytes of stored clips (--max_stored_clip_bytes)"));
  }
  while (!lru_.empty() && (static_cast<std::int64_t>(clips_.size()) >= max_clips_ ||
                           bytes_ + size > max_bytes_)) {
    auto victim = clips_.find(lru_.back());
    evicted.push_back(victim->second.clip);
    EraseLocked(victim);
  }
  lru_.push_front(key);
  clips_.emplace(key, Entry{.clip = clip, .bytes = size, .lru = lru_.begin()});
  bytes_ += size;
  return PutResult{.clip = std::move(clip), .already_stored = false};
}

absl::StatusOr<std::shared_ptr<const core::Clip>> ClipStore::Get(std::string_view owner,
                                                                 std::string_view id) {
  std::lock_guard lock(mu_);
  auto it = clips_.find(Key(owner, id));
  if (it == clips_.end()) {
    return absl::NotFoundError(absl::StrCat("clip \"", core::AsAbsl(id),
                                            "\" not found (never uploaded, or evicted: upload it "
                                            "again)"));
  }
  lru_.splice(lru_.begin(), lru_, it->second.lru);
  return it->second.clip;
}

void ClipStore::Reclaim(std::int64_t wanted) {
  std::vector<std::shared_ptr<const core::Clip>> evicted;
  {
    std::lock_guard lock(mu_);
    std::int64_t freed = 0;
    std::vector<std::string> keys;
    for (auto key = lru_.rbegin(); key != lru_.rend() && freed < wanted; ++key) {
      const Entry& entry = clips_.at(*key);
      // A clip a job still holds would stay in memory anyway: keep it findable.
      if (entry.clip.use_count() > 1) continue;
      freed += entry.bytes;
      keys.push_back(*key);
    }
    for (const std::string& key : keys) {
      auto it = clips_.find(key);
      evicted.push_back(it->second.clip);
      EraseLocked(it);
    }
  }
  // `evicted` goes out of scope here, outside the lock: the clips' reservations return to the
  // budget.
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
