// Reading what `tempokey batch` leaves behind, for the CLI tests of batches: its JSON summary
// (read with core's JSON reader, not with the client code that writes it), the files of an
// output folder and the lines of its stderr.
#ifndef TEMPOKEY_TESTS_TESTING_BATCH_UTIL_H_
#define TEMPOKEY_TESTS_TESTING_BATCH_UTIL_H_

#include <algorithm>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "absl/strings/str_split.h"
#include "gtest/gtest.h"
#include "tempokey/core/io/json.h"

namespace tempokey::testing {

// One entry of a batch summary's "results".
struct SummaryEntry {
  std::string input{};
  std::string output{};
  std::string status{};
  std::string code{};
  std::string error{};
  int attempts = 0;
  double keys = 0;
  double frames = 0;
  double max_error = 0;
};

struct Summary {
  int files = -1;
  int succeeded = -1;
  int done = -1;
  int skipped = -1;
  int failed = -1;
  std::string shard;     // "" when absent
  std::string pipeline;  // "" when absent
  int shards = -1;       // merged summaries only
  std::vector<std::string> missing_shards;
  std::vector<std::string> inputs;  // in order
  std::map<std::string, SummaryEntry> by_input;
};

inline std::string JsonText(const core::JsonValue* value) {
  return value ? value->text : std::string();
}
inline double JsonNumber(const core::JsonValue* value, double fallback = 0.0) {
  return value ? value->number : fallback;
}

// The summary printed by `tempokey batch` or `tempokey batch-summary`; a JSON error fails the
// calling test.
inline Summary ParseSummary(const std::string& json) {
  Summary summary;
  absl::StatusOr<core::JsonValue> root = core::ParseJson(json, "summary");
  EXPECT_TRUE(root.ok()) << root.status() << "\n" << json;
  if (!root.ok()) return summary;
  summary.files = static_cast<int>(JsonNumber(root->Find("files"), -1));
  summary.succeeded = static_cast<int>(JsonNumber(root->Find("succeeded"), -1));
  summary.done = static_cast<int>(JsonNumber(root->Find("done"), -1));
  summary.skipped = static_cast<int>(JsonNumber(root->Find("skipped"), -1));
  summary.failed = static_cast<int>(JsonNumber(root->Find("failed"), -1));
  summary.shard = JsonText(root->Find("shard"));
  summary.pipeline = JsonText(root->Find("pipeline"));
  summary.shards = static_cast<int>(JsonNumber(root->Find("shards"), -1));
  if (const core::JsonValue* missing = root->Find("missing_shards");
      missing != nullptr && missing->type == core::JsonValue::Type::kArray) {
    for (const core::JsonValue& item : *missing->array) summary.missing_shards.push_back(item.text);
  }
  const core::JsonValue* results = root->Find("results");
  if (results == nullptr || results->type != core::JsonValue::Type::kArray) return summary;
  for (const core::JsonValue& item : *results->array) {
    SummaryEntry entry{
        .input = JsonText(item.Find("input")),
        .output = JsonText(item.Find("output")),
        .status = JsonText(item.Find("status")),
        .code = JsonText(item.Find("code")),
        .error = JsonText(item.Find("error")),
        .attempts = static_cast<int>(JsonNumber(item.Find("attempts"))),
        .keys = JsonNumber(item.Find("keys")),
        .frames = JsonNumber(item.Find("frames")),
        .max_error = JsonNumber(item.Find("max_error")),
    };
    summary.inputs.push_back(entry.input);
    summary.by_input[entry.input] = entry;
  }
  return summary;
}

// The names of the regular files in `dir` (hidden ones included), sorted.
inline std::vector<std::string> FilesIn(const std::string& dir) {
  std::vector<std::string> names;
  std::error_code error;
  for (const auto& entry : std::filesystem::directory_iterator(dir, error)) {
    if (entry.is_regular_file()) names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

// The lines of `text`, without their line breaks.
inline std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines = absl::StrSplit(text, '\n');
  if (!lines.empty() && lines.back().empty()) lines.pop_back();
  return lines;
}

// The last line of `text` with its line break: where a failed batch puts its "error: ..." line
// after the lines of its files.
inline std::string LastLine(const std::string& text) {
  const std::vector<std::string> lines = Lines(text);
  return lines.empty() ? std::string() : lines.back() + "\n";
}

// The manifest a run without --shard keeps next to its outputs.
inline constexpr char kManifestName[] = ".tempokey-batch.json";

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_TESTING_BATCH_UTIL_H_
