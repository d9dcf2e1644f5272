// Shards of a batch: `tempokey batch ... --shard I/N` takes the files whose path hashes to I,
// so N processes (or the N pods of a Kubernetes Indexed Job) share one folder without talking to
// each other, and together cover every file exactly once.
//
// A file's shard depends on its own name only: the first 8 bytes of SHA-256 of its path relative
// to the batch folder ('/' separators, the bytes as stored), read as a big-endian integer, mod N.
// Adding or removing files never moves the others between shards; changing N does.
//   printf %s walk/0001.bvh | sha256sum   # its first 16 hex digits, mod N
#ifndef TEMPOKEY_CLIENT_BATCH_SHARD_H_
#define TEMPOKEY_CLIENT_BATCH_SHARD_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace tempokey::client {

inline constexpr int kMaxShards = 100000;

// One share of a batch: index in [0, count), count in [1, kMaxShards]. Indexes count from 0, as
// Kubernetes' JOB_COMPLETION_INDEX does.
struct BatchShard {
  int index = 0;
  int count = 1;

  // "2/4".
  std::string Name() const;
  bool operator==(const BatchShard&) const = default;
};

// Parses --shard: "I/N" with 0 <= I < N <= kMaxShards.
// Errors: usage errors naming the flag, e.g. "--shard: expected I/N with 0 <= I < N, got '4/4'".
absl::StatusOr<BatchShard> ParseShard(std::string_view text);

// The shard (0..count-1) of the file named `relative_name` (BatchItem::name). Precondition:
// count >= 1. Thread-safe: a pure function.
int ShardOfName(std::string_view relative_name, int count);

// Whether the file named `relative_name` belongs to `shard`.
inline bool InShard(std::string_view relative_name, const BatchShard& shard) {
  return ShardOfName(relative_name, shard.count) == shard.index;
}

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_BATCH_SHARD_H_
