// Batch summaries read back and merged (client/batch_summary.h): a printed summary parses to
// what was printed, shards of one run merge into one summary, and summaries that do not belong
// together are refused naming the files.
#include "client/batch_summary.h"

#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tempokey::client {
namespace {

using ::testing::HasSubstr;

BatchFileResult Ok(const std::string& name) {
  return {.name = name, .output_path = "out/" + name, .attempts = 1, .seconds = 0.25,
          .keys = 12, .max_error = 0.49977981950762285, .max_joint_error = 1.8706};
}

BatchFileResult Skipped(const std::string& name) {
  return {.name = name, .output_path = "out/" + name, .skipped = true, .frames = 90};
}

BatchFileResult Failed(const std::string& name) {
  return {.name = name, .status = absl::UnavailableError(name + ": server: UNAVAILABLE: gone"),
          .attempts = 5, .seconds = 3.5};
}

BatchSummary Shard(int index, int count, std::vector<BatchFileResult> files,
                   const std::string& pipeline = "sha256:p") {
  BatchSummary summary;
  summary.files = std::move(files);
  summary.seconds = 1.0 + index;
  summary.shard = BatchShard{.index = index, .count = count};
  summary.pipeline = pipeline;
  return summary;
}

TEST(BatchSummaryTest, PrintedSummaryParsesBackToTheSameResults) {
  const BatchSummary summary = Shard(1, 4, {Ok("b.bvh"), Skipped("a.bvh"), Failed("c.bvh")});

  absl::StatusOr<BatchSummary> parsed =
      ParseBatchSummary(FormatBatchSummaryJson(summary), "s.json");

  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(FormatBatchSummaryJson(*parsed), FormatBatchSummaryJson(summary));
  EXPECT_EQ(parsed->shard, summary.shard);
  EXPECT_EQ(parsed->pipeline, "sha256:p");
  ASSERT_EQ(parsed->files.size(), 3u);
  EXPECT_EQ(parsed->files[2].status, summary.files[2].status);
  EXPECT_EQ(parsed->files[0].max_error, summary.files[0].max_error);
  EXPECT_EQ(parsed->files[0].max_joint_error, summary.files[0].max_joint_error);
}

TEST(BatchSummaryTest, ShardsMergeIntoOneSummarySortedByInput) {
  const std::vector<NamedSummary> shards = {
      {"s2.json", Shard(2, 3, {Ok("e.bvh"), Failed("b.bvh")})},
      {"s0.json", Shard(0, 3, {Skipped("d.bvh"), Ok("a.bvh")})},
      {"s1.json", Shard(1, 3, {Ok("c.bvh")})},
  };

  absl::StatusOr<BatchSummary> merged = MergeBatchSummaries(shards);

  ASSERT_TRUE(merged.ok()) << merged.status();
  std::vector<std::string> inputs;
  for (const BatchFileResult& file : merged->files) inputs.push_back(file.name);
  EXPECT_EQ(inputs, (std::vector<std::string>{"a.bvh", "b.bvh", "c.bvh", "d.bvh", "e.bvh"}));
  EXPECT_EQ(merged->done_count(), 3);
  EXPECT_EQ(merged->skipped_count(), 1);
  EXPECT_EQ(merged->failed_count(), 1);
  EXPECT_EQ(merged->seconds, 3.0);  // the longest shard
  EXPECT_EQ(merged->merged_shards, 3);
  EXPECT_TRUE(merged->missing_shards.empty());
  EXPECT_THAT(FormatBatchSummaryJson(*merged),
              ::testing::StartsWith("{\"files\": 5, \"succeeded\": 4, \"done\": 3, \"skipped\": 1, "
                                    "\"failed\": 1, \"seconds\": 3.000, \"shards\": 3, "
                                    "\"missing_shards\": [], \"pipeline\": \"sha256:p\", "));
}

TEST(BatchSummaryTest, MissingShardsAreListed) {
  const std::vector<NamedSummary> shards = {{"s1.json", Shard(1, 4, {Ok("a.bvh")})}};

  absl::StatusOr<BatchSummary> merged = MergeBatchSummaries(shards);

  ASSERT_TRUE(merged.ok()) << merged.status();
  EXPECT_EQ(merged->missing_shards, (std::vector<int>{0, 2, 3}));
  EXPECT_THAT(FormatBatchSummaryJson(*merged),
              HasSubstr("\"shards\": 4, \"missing_shards\": [\"0/4\", \"2/4\", \"3/4\"]"));
}

TEST(BatchSummaryTest, SummariesThatDoNotBelongTogetherAreRefusedNamingTheFiles) {
  BatchSummary unsharded = Shard(0, 2, {Ok("a.bvh")});
  unsharded.shard.reset();
  struct Case {
    std::vector<NamedSummary> summaries;
    std::string message;
  };
  const std::vector<Case> cases = {
      {{}, "no summaries to merge"},
      {{{"s.json", unsharded}}, "s.json: not the summary of a shard (run batch with --shard I/N)"},
      {{{"a.json", Shard(0, 2, {Ok("a.bvh")})}, {"b.json", Shard(1, 3, {Ok("b.bvh")})}},
       "b.json: shard 1/3 is not of the same split as a.json (0/2)"},
      {{{"a.json", Shard(0, 2, {Ok("a.bvh")})}, {"b.json", Shard(0, 2, {Ok("b.bvh")})}},
       "shard 0/2 is given twice: a.json and b.json"},
      {{{"a.json", Shard(0, 2, {Ok("a.bvh")})}, {"b.json", Shard(1, 2, {Ok("b.bvh")}, "sha256:q")}},
       "b.json and a.json ran different pipelines (sha256:q and sha256:p)"},
      {{{"a.json", Shard(0, 2, {Ok("a.bvh")})}, {"b.json", Shard(1, 2, {Failed("a.bvh")})}},
       "a.bvh is in two summaries: a.json and b.json"},
  };
  for (const Case& c : cases) {
    absl::StatusOr<BatchSummary> merged = MergeBatchSummaries(c.summaries);

    ASSERT_FALSE(merged.ok()) << c.message;
    EXPECT_EQ(merged.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_EQ(merged.status().message(), c.message);
  }
}

TEST(BatchSummaryTest, DocumentsThatAreNotSummariesAreRefusedWithTheirPlace) {
  struct Case {
    std::string text;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"[]", "s.json:1:1: expected an object"},
      {R"({"files": 1})", "s.json:1:1: missing \"results\""},
      {R"({"results": [{"input": "a.bvh", "status": "great"}]})",
       "s.json:1:43: status must be ok, skipped or failed, got 'great'"},
      {R"({"results": [{"input": "a.bvh", "status": "failed", "code": "OOPS", "error": "x"}]})",
       "s.json:1:61: unknown status code 'OOPS'"},
      {R"({"files": 2, "results": [{"input": "a.bvh", "output": "a.json", "status": "ok"}]})",
       "s.json:1:11: \"files\" is 2 but the results count 1"},
      {R"({"shard": "4/4", "results": []})", "s.json:1:11: \"shard\" must be I/N, got '4/4'"},
      // A summary's numbers are counts and measures: never negative, counts whole, and none
      // cast to an integer it cannot hold.
      {R"({"results": [{"input": "a.bvh", "output": "a.json", "status": "ok", "attempts": 1e300}]})",
       "s.json:1:81: \"attempts\" must be a whole number from 0 to 2147483647"},
      {R"({"results": [{"input": "a.bvh", "output": "a.json", "status": "ok", "frames": 2.5}]})",
       "s.json:1:79: \"frames\" must be a whole number from 0 to 9007199254740992"},
      {R"({"results": [{"input": "a.bvh", "output": "a.json", "status": "ok", "seconds": -1e300}]})",
       "s.json:1:80: \"seconds\" must be >= 0"},
      {R"({"results": [{"input": "a.bvh", "output": "a.json", "status": "ok", "max_error": -1}]})",
       "s.json:1:82: \"max_error\" must be >= 0"},
      {R"({"seconds": -2, "results": []})", "s.json:1:13: \"seconds\" must be >= 0"},
      // A done or skipped file has an output; a name given twice is not settled by the first.
      {R"({"results": [{"input": "a.bvh", "status": "ok"}]})",
       "s.json:1:14: result for 'a.bvh' is ok but names no \"output\""},
      {R"({"results": [], "results": [{"input": "a.bvh", "status": "failed", "code": "INTERNAL", "error": "x"}]})",
       "s.json:1:28: \"results\" given twice"},
  };
  for (const Case& c : cases) {
    absl::StatusOr<BatchSummary> parsed = ParseBatchSummary(c.text, "s.json");

    ASSERT_FALSE(parsed.ok()) << c.text;
    EXPECT_EQ(parsed.status().message(), c.message);
  }
}

}  // namespace
}  // namespace tempokey::client
