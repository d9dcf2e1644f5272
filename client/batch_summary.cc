#include "client/batch_summary.h"

#include <algorithm>
#include <limits>
#include <map>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "client/batch_shard.h"
#include "client/json_members.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;
using core::JsonValue;

using Place = JsonPlace;

std::optional<absl::StatusCode> CodeNamed(std::string_view name) {
  for (int code = 0; code <= static_cast<int>(absl::StatusCode::kUnauthenticated); ++code) {
    const auto status_code = static_cast<absl::StatusCode>(code);
    if (core::AsStd(absl::StatusCodeToString(status_code)) == name) return status_code;
  }
  return std::nullopt;
}

absl::StatusOr<BatchFileResult> ParseResult(const Place& place, const JsonValue& item) {
  if (item.type != JsonValue::Type::kObject) return place.Fail(item, "a result must be an object");
  BatchFileResult file;
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* input,
                            JsonMember(place, item, "input", JsonValue::Type::kString, true));
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* status,
                            JsonMember(place, item, "status", JsonValue::Type::kString, true));
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* output,
                            JsonMember(place, item, "output", JsonValue::Type::kString, false));
  file.name = input->text;
  if (output != nullptr) file.output_path = output->text;
  if (status->text == "failed") {
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* code,
                              JsonMember(place, item, "code", JsonValue::Type::kString, true));
    TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* error,
                              JsonMember(place, item, "error", JsonValue::Type::kString, true));
    const std::optional<absl::StatusCode> status_code = CodeNamed(code->text);
    if (!status_code || *status_code == absl::StatusCode::kOk) {
      return place.Fail(*code, absl::StrCat("unknown status code '", code->text, "'"));
    }
    file.status = absl::Status(*status_code, error->text);
  } else if (status->text == "skipped") {
    file.skipped = true;
  } else if (status->text != "ok") {
    return place.Fail(*status, absl::StrCat("status must be ok, skipped or failed, got '",
                                            status->text, "'"));
  }
  if (file.status.ok() && file.output_path.empty()) {
    return place.Fail(item, absl::StrCat("result for '", input->text, "' is ", status->text,
                                         " but names no \"output\""));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(const std::int64_t attempts,
                            JsonCount(place, item, "attempts", std::numeric_limits<int>::max()));
  file.attempts = static_cast<int>(attempts);
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<double> seconds,
                            JsonNonNegative(place, item, "seconds"));
  file.seconds = seconds.value_or(0.0);
  TEMPOKEY_ASSIGN_OR_RETURN(file.frames, JsonCount(place, item, "frames"));
  TEMPOKEY_ASSIGN_OR_RETURN(file.keys, JsonCount(place, item, "keys"));
  TEMPOKEY_ASSIGN_OR_RETURN(file.max_error, JsonNonNegative(place, item, "max_error"));
  TEMPOKEY_ASSIGN_OR_RETURN(file.max_joint_error, JsonNonNegative(place, item, "max_joint_error"));
  return file;
}

// Checks a printed count against the results.
absl::Status CheckCount(const Place& place, const JsonValue& root, std::string_view name,
                        int expected) {
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* value,
                            JsonMember(place, root, name, JsonValue::Type::kNumber, false));
  if (value != nullptr && value->number != expected) {
    return place.Fail(*value, absl::StrCat("\"", AsAbsl(name), "\" is ", value->text,
                                           " but the results count ", expected));
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<BatchSummary> ParseBatchSummary(std::string_view text, std::string_view source) {
  TEMPOKEY_ASSIGN_OR_RETURN(JsonValue root, core::ParseJson(text, source));
  const Place place(source);
  if (root.type != JsonValue::Type::kObject) return place.Fail(root, "expected an object");
  BatchSummary summary;
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* results,
                            JsonMember(place, root, "results", JsonValue::Type::kArray, true));
  for (const JsonValue& item : *results->array) {
    TEMPOKEY_ASSIGN_OR_RETURN(BatchFileResult file, ParseResult(place, item));
    summary.files.push_back(std::move(file));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<double> seconds, JsonNonNegative(place, root, "seconds"));
  summary.seconds = seconds.value_or(0.0);
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* shard,
                            JsonMember(place, root, "shard", JsonValue::Type::kString, false));
  if (shard != nullptr) {
    absl::StatusOr<BatchShard> parsed = ParseShard(shard->text);
    if (!parsed.ok()) return place.Fail(*shard, absl::StrCat("\"shard\" must be I/N, got '",
                                                             shard->text, "'"));
    summary.shard = *parsed;
  }
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* pipeline,
                            JsonMember(place, root, "pipeline", JsonValue::Type::kString, false));
  if (pipeline != nullptr) summary.pipeline = pipeline->text;
  TEMPOKEY_RETURN_IF_ERROR(
      CheckCount(place, root, "files", static_cast<int>(summary.files.size())));
  TEMPOKEY_RETURN_IF_ERROR(CheckCount(place, root, "failed", summary.failed_count()));
  TEMPOKEY_RETURN_IF_ERROR(CheckCount(place, root, "skipped", summary.skipped_count()));
  TEMPOKEY_RETURN_IF_ERROR(CheckCount(place, root, "done", summary.done_count()));
  return summary;
}

absl::StatusOr<BatchSummary> MergeBatchSummaries(std::span<const NamedSummary> summaries) {
  if (summaries.empty()) return absl::InvalidArgumentError("no summaries to merge");
  const NamedSummary& first = summaries.front();
  BatchSummary merged;
  std::map<int, std::string> source_of_shard;
  std::map<std::string, std::string> source_of_input;
  for (const NamedSummary& named : summaries) {
    const BatchSummary& summary = named.summary;
    if (!summary.shard) {
      return absl::InvalidArgumentError(absl::StrCat(
          named.source, ": not the summary of a shard (run batch with --shard I/N)"));
    }
    if (summary.shard->count != first.summary.shard->count) {
      return absl::InvalidArgumentError(absl::StrCat(
          named.source, ": shard ", summary.shard->Name(), " is not of the same split as ",
          first.source, " (", first.summary.shard->Name(), ")"));
    }
    if (summary.pipeline != first.summary.pipeline) {
      return absl::InvalidArgumentError(absl::StrCat(
          named.source, " and ", first.source, " ran different pipelines (",
          summary.pipeline.empty() ? "none recorded" : summary.pipeline, " and ",
          first.summary.pipeline.empty() ? "none recorded" : first.summary.pipeline, ")"));
    }
    const auto [shard_at, new_shard] =
        source_of_shard.emplace(summary.shard->index, named.source);
    if (!new_shard) {
      return absl::InvalidArgumentError(absl::StrCat("shard ", summary.shard->Name(),
                                                     " is given twice: ", shard_at->second,
                                                     " and ", named.source));
    }
    for (const BatchFileResult& file : summary.files) {
      const auto [input_at, new_input] = source_of_input.emplace(file.name, named.source);
      if (!new_input) {
        return absl::InvalidArgumentError(absl::StrCat(file.name, " is in two summaries: ",
                                                       input_at->second, " and ", named.source));
      }
      merged.files.push_back(file);
    }
    merged.seconds = std::max(merged.seconds, summary.seconds);
  }
  std::sort(merged.files.begin(), merged.files.end(),
            [](const BatchFileResult& a, const BatchFileResult& b) { return a.name < b.name; });
  merged.pipeline = first.summary.pipeline;
  merged.merged_shards = first.summary.shard->count;
  for (int index = 0; index < merged.merged_shards; ++index) {
    if (source_of_shard.count(index) == 0) merged.missing_shards.push_back(index);
  }
  return merged;
}

}  // namespace tempokey::client
