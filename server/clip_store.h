// Uploaded clips by content id, with a cap on count and bytes (least recently used evicted
// first). Jobs hold their clip through a shared pointer, so evicting a clip never breaks a job.
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
  // At most `max_clips` clips and `max_bytes` bytes of samples (both >= 1).
  ClipStore(std::int64_t max_clips, std::int64_t max_bytes);

  struct PutResult {
    std::shared_ptr<const core::Clip> clip;
    bool already_stored = false;
  };
  // Stores `clip` under `id` unless a clip with that id is there already (then that one is kept,
  // marked recently used, and already_stored is true). Evicts least recently used clips to make
  // room. Errors: kResourceExhausted when the clip alone is larger than max_bytes.
  absl::StatusOr<PutResult> Put(const std::string& id, core::Clip clip);

  // Errors: kNotFound naming the id (never uploaded, or evicted).
  absl::StatusOr<std::shared_ptr<const core::Clip>> Get(std::string_view id);

  std::int64_t size() const;
  std::int64_t bytes() const;

 private:
  using Lru = std::list<std::string>;  // most recently used first
  struct Entry {
    std::shared_ptr<const core::Clip> clip;
    std::int64_t bytes = 0;
    Lru::iterator lru;
  };

  const std::int64_t max_clips_;
  const std::int64_t max_bytes_;
  mutable std::mutex mu_;
  std::unordered_map<std::string, Entry> clips_ ABSL_GUARDED_BY(mu_);
  Lru lru_ ABSL_GUARDED_BY(mu_);
  std::int64_t bytes_ ABSL_GUARDED_BY(mu_) = 0;
};

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_CLIP_STORE_H_
