#include "client/batch_shard.h"

#include <algorithm>
#include <cstdint>

#include "absl/strings/str_cat.h"
#include "client/args.h"
#include "client/cli_errors.h"
#include "proto/clip_digest.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

constexpr std::string_view kShardFlag = "--shard";

absl::Status BadShard(std::string_view text) {
  return UsageError(absl::StrCat("--shard: expected I/N with 0 <= I < N <= ", kMaxShards,
                                 " (I counts from 0), got '", core::AsAbsl(text), "'"));
}

// The value of hex digit `c` ("sha256:" ids are lowercase).
std::uint64_t HexValue(char c) {
  return static_cast<std::uint64_t>(c <= '9' ? c - '0' : c - 'a' + 10);
}

}  // namespace

std::string BatchShard::Name() const { return absl::StrCat(index, "/", count); }

absl::StatusOr<BatchShard> ParseShard(std::string_view text) {
  const std::size_t slash = text.find('/');
  if (slash == std::string_view::npos) return BadShard(text);
  absl::StatusOr<std::int64_t> index = ParseInt64(kShardFlag, text.substr(0, slash));
  absl::StatusOr<std::int64_t> count = ParseInt64(kShardFlag, text.substr(slash + 1));
  if (!index.ok() || !count.ok() || *count < 1 || *count > kMaxShards || *index < 0 ||
      *index >= *count) {
    return BadShard(text);
  }
  return BatchShard{.index = static_cast<int>(*index), .count = static_cast<int>(*count)};
}

int ShardOfName(std::string_view relative_name, int count) {
  const std::string id = wire::Sha256Id(relative_name);  // "sha256:" + 64 hex digits
  std::uint64_t prefix = 0;
  for (std::size_t i = 7; i < 7 + 16; ++i) prefix = (prefix << 4) | HexValue(id[i]);
  return static_cast<int>(prefix % static_cast<std::uint64_t>(count));
}

}  // namespace tempokey::client
