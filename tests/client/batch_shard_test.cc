// Shards of a batch (client/batch_shard.h): the --shard syntax, the hash against SHA-256 values
// published elsewhere, and that the shards of a split cover every name exactly once.
#include "client/batch_shard.h"

#include <map>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli_errors.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

TEST(BatchShardTest, ParsesIndexSlashCount) {
  absl::StatusOr<BatchShard> first = ParseShard("0/4");
  absl::StatusOr<BatchShard> last = ParseShard("3/4");
  absl::StatusOr<BatchShard> whole = ParseShard("0/1");

  ASSERT_TRUE(first.ok() && last.ok() && whole.ok());
  EXPECT_EQ(*first, (BatchShard{.index = 0, .count = 4}));
  EXPECT_EQ(*last, (BatchShard{.index = 3, .count = 4}));
  EXPECT_EQ(whole->Name(), "0/1");
}

TEST(BatchShardTest, MalformedShardsAreUsageErrorsQuotingTheText) {
  for (const std::string text : {"4/4", "-1/4", "1", "1/0", "a/4", "1/b", "", "1/4/2", "0/100001"}) {
    absl::StatusOr<BatchShard> shard = ParseShard(text);

    ASSERT_FALSE(shard.ok()) << text;
    EXPECT_TRUE(IsUsageError(shard.status())) << text;
    EXPECT_EQ(shard.status().message(),
              absl::StrCat("--shard: expected I/N with 0 <= I < N <= 100000 (I counts from 0), "
                           "got '", text, "'"))
        << text;
  }
}

// FIPS 180-2, appendix B.1: SHA-256("abc") = ba7816bf 8f01cfea ...; its first 8 bytes are
// 0xba7816bf8f01cfea = 13436514500253700074 (decimal), so mod 4 it is 2 and mod 1000 it is 74.
TEST(BatchShardTest, ShardIsTheFirstEightBytesOfTheSha256OfTheNameModN) {
  EXPECT_EQ(ShardOfName("abc", 1), 0);
  EXPECT_EQ(ShardOfName("abc", 4), 2);
  EXPECT_EQ(ShardOfName("abc", 1000), 74);
  // SHA-256 of the empty string (the same standard's test suites): e3b0c442 98fc1c14 ...
  constexpr unsigned long long kEmptyPrefix = 0xe3b0c44298fc1c14ull;
  EXPECT_EQ(ShardOfName("", 7), static_cast<int>(kEmptyPrefix % 7));
}

TEST(BatchShardTest, ShardsOfASplitCoverEveryNameExactlyOnce) {
  std::vector<std::string> names;
  for (int i = 0; i < 1000; ++i) names.push_back(absl::StrFormat("take%04d/clip_%d.bvh", i % 37, i));

  for (int count : {1, 2, 3, 4, 7, 16}) {
    std::map<std::string, int> owners;
    std::vector<int> sizes(static_cast<std::size_t>(count), 0);
    for (int index = 0; index < count; ++index) {
      for (const std::string& name : names) {
        if (InShard(name, BatchShard{.index = index, .count = count})) {
          ++owners[name];
          ++sizes[static_cast<std::size_t>(index)];
        }
      }
    }

    ASSERT_EQ(owners.size(), names.size()) << count;
    for (const auto& [name, owned] : owners) EXPECT_EQ(owned, 1) << name << " of " << count;
    // A fixed hash of fixed names: the spread is a fact, not a chance (1000 / N +- 25 %).
    for (int size : sizes) {
      EXPECT_GE(size, 750 / count) << count;
      EXPECT_LE(size, 1250 / count + 1) << count;
    }
  }
}

}  // namespace
}  // namespace tempokey::client
