// Uploaded clips by owner and content id, with a cap on count and bytes (least recently used
// evicted first). Jobs hold their clip through a shared pointer, so evicting a clip never breaks
// a job. Each owner (bearer token) sees only the clips it uploaded.
#ifndef TEMPOKEY_SERVER_CLIP_STORE_H_
#define TEMPOKEY_SERVER_CLIP_STORE_H_

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>

#include "absl/base/thread_annotations.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::server {

// Thread-safe.
class ClipStore {
 public:
  // At most `max_clips` clips and `max_bytes` bytes (ClipBytes()) in all (both >= 1).
  ClipStore(std::int64_t max_clips, std::int64_t max_bytes);

  struct PutResult {
    std::shared_ptr<const core::Clip> clip;
    bool already_stored = false;
  };
  // Stores `clip` (never null; its memory is counted by whatever reservation it carries) under
  // `owner` and `id` unless that owner already has a clip with that id (then that one is kept,
  // marked recently used, and already_stored is true). Evicts least recently used clips to make
  // room. Errors: kResourceExhausted when the clip alone is larger than max_bytes.
  absl::StatusOr<PutResult> Put(std::string_view owner, const std::string& id,
                                std::shared_ptr<const core::Clip> clip);

  // Errors: kNotFound naming the id (never uploaded by this owner, or evicted).
  absl::StatusOr<std::shared_ptr<const core::Clip>> Get(std::string_view owner, std::string_view id);

  // Evicts least recently used clips that nothing else holds until their bytes reach `wanted`
  // or none is left (the memory budget's reclaimer).
  void Reclaim(std::int64_t wanted);

  std::int64_t size() const;
  std::int64_t bytes() const;

 private:
  using Lru = std::list<std::string>;  // keys, most recently used first
  struct Entry {
    std::shared_ptr<const core::Clip> clip;
    std::int64_t bytes = 0;
    Lru::iterator lru;
  };

  void EraseLocked(std::unordered_map<std::string, Entry>::iterator it)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const std::int64_t max_clips_;
  const std::int64_t max_bytes_;
  mutable std::mutex mu_;
  std::unordered_map<std::string, Entry> clips_ ABSL_GUARDED_BY(mu_);
  Lru lru_ ABSL_GUARDED_BY(mu_);
  std::int64_t bytes_ ABSL_GUARDED_BY(mu_) = 0;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_CLIP_STORE_H_
