// Batch summaries read back, and the summaries of a sharded run merged into one
// (`tempokey batch-summary SUMMARY...`): the N shards of a run each print their own summary; the
// merge checks that they belong together and that none is missing, and gives the summary one
// unsharded run would have printed.
#ifndef TEMPOKEY_CLIENT_BATCH_SUMMARY_H_
#define TEMPOKEY_CLIENT_BATCH_SUMMARY_H_

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "client/batch.h"

namespace tempokey::client {

// Parses a summary printed by FormatBatchSummaryJson(); `source` names it in messages. Results
// keep their order; attempts, seconds, frames, keys and max_error come back as printed.
// Errors: kInvalidArgument "<source>:<line>:<column>: <what>" for a document that is not a batch
// summary (a missing or mistyped member, an unknown status or code, counts that disagree with
// the results).
absl::StatusOr<BatchSummary> ParseBatchSummary(std::string_view text, std::string_view source);

// One summary and the file it came from (for messages).
struct NamedSummary {
  std::string source;
  BatchSummary summary;
};

// The merge of the summaries of one sharded run: every result, sorted by input; seconds is the
// longest shard's (they run side by side); merged_shards is N and missing_shards the indexes no
// summary was given for (the merge of an incomplete run is still returned, so it can be shown).
// Errors (kInvalidArgument), each naming the files concerned: a summary without a shard, shards
// of different N, one shard given twice, different pipelines, one input in two summaries, no
// summary at all.
absl::StatusOr<BatchSummary> MergeBatchSummaries(std::span<const NamedSummary> summaries);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_BATCH_SUMMARY_H_
