// `tempokey batch-summary SUMMARY...`: merges the summaries of the shards of one batch run into
// the summary one unsharded run would have printed; exits 1 when shards are missing or files
// failed, so a night's last step can gate on it.
#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "client/batch.h"
#include "client/batch_summary.h"
#include "client/cli_errors.h"
#include "client/clip_files.h"
#include "client/command.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

constexpr std::int64_t kMaxSummaryBytes = std::int64_t{256} << 20;
// Missing shards named in the error line; the others are counted.
constexpr std::size_t kNamedMissingShards = 10;

constexpr FlagSpec kBatchSummaryFlags[] = {
    {"--output", "-o", "FILE", "also write the merged summary to FILE (atomically)"},
};

absl::Status BatchSummaryMerge(CommandContext& context) {
  const std::vector<std::string>& paths = context.args().positionals();
  if (paths.empty()) {
    return UsageError("batch-summary: missing SUMMARY (see tempokey batch-summary --help)");
  }
  const std::optional<std::string> output = context.args().Value("--output");
  if (output) {
    std::vector<NamedFile> inputs;
    for (const std::string& path : paths) inputs.push_back({path, "a summary to merge"});
    TEMPOKEY_RETURN_IF_ERROR(CheckWritesNoneOf(*output, "-o", inputs));
  }
  std::vector<NamedSummary> summaries;
  for (const std::string& path : paths) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string text, core::ReadFile(path, kMaxSummaryBytes));
    TEMPOKEY_ASSIGN_OR_RETURN(BatchSummary summary, ParseBatchSummary(text, path));
    summaries.push_back({.source = path, .summary = std::move(summary)});
  }
  TEMPOKEY_ASSIGN_OR_RETURN(BatchSummary merged, MergeBatchSummaries(summaries));

  const std::string json = FormatBatchSummaryJson(merged);
  context.out() << json;
  if (output) TEMPOKEY_RETURN_IF_ERROR(core::WriteFileAtomically(*output, json));
  if (!merged.missing_shards.empty()) {
    // The error is one line: the first shards missing, and how many more (the summary printed
    // lists them all).
    const std::size_t missing = merged.missing_shards.size();
    std::vector<std::string> names;
    for (std::size_t i = 0; i < std::min(missing, kNamedMissingShards); ++i) {
      names.push_back(absl::StrCat(merged.missing_shards[i], "/", merged.merged_shards));
    }
    const std::string more =
        missing > kNamedMissingShards
            ? absl::StrCat(" and ", missing - kNamedMissingShards, " more")
            : "";
    return absl::FailedPreconditionError(absl::StrCat(
        missing == 1 ? "shard " : "shards ", absl::StrJoin(names, ", "), more,
        " missing: the run is incomplete (run ", missing == 1 ? "it" : "them",
        " with batch --shard)"));
  }
  return merged.FailedFiles();
}

}  // namespace

const Command& BatchSummaryCommand() {
  static const Command command{
      .name = "batch-summary",
      .synopsis = "SUMMARY... [-o FILE]",
      .summary = "merge the summaries of the shards of a batch (exit 1 if incomplete or failed)",
      .description =
          "Reads the JSON summaries that 'tempokey batch --shard I/N --summary FILE' wrote, one\n"
          "per shard, checks that they are shards of one run (same N and pipeline, no shard or\n"
          "file twice) and prints the merged summary: every file once, sorted by input, with\n"
          "\"shards\": N and the shards still missing. Local, no server.\n"
          "Exits 0 when every shard is there and no file failed; 1 when shards are missing\n"
          "or files failed (the merged summary is printed either way).\n",
      .flags = kBatchSummaryFlags,
      .run = BatchSummaryMerge,
  };
  return command;
}

}  // namespace tempokey::client
