// `tempokey jobs list|get|watch|result|cancel|delete`.
#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "client/cli_errors.h"
#include "client/clip_files.h"
#include "client/clip_summary.h"
#include "client/command.h"
#include "google/protobuf/util/time_util.h"
#include "proto/operations_convert.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;

constexpr std::string_view kJobArgument[] = {"JOB"};
// The largest file `jobs result` takes from the server's export: a BVH of the default clip
// limit (32 Mi samples) is about 640 MB of text.
constexpr std::int64_t kMaxExportedFileBytes = std::int64_t{2} << 30;
constexpr std::string_view kStates[] = {"queued", "running", "succeeded", "failed", "cancelled"};

constexpr FlagSpec kListFlags[] = {
    {"--state", "", "STATE",
     "only jobs in STATE: queued, running, succeeded, failed, cancelled", true},
    {"--label", "", "KEY=VALUE", "only jobs carrying this label", true},
    {"--limit", "", "N", "list at most N jobs (default: all)"},
};
constexpr FlagSpec kResultFlags[] = {kOutputFlag};

std::string Percent(double fraction) {
  return absl::StrFormat("%d%%", static_cast<int>(std::clamp(fraction, 0.0, 1.0) * 100.0));
}

std::string Labels(const google::protobuf::Map<std::string, std::string>& labels) {
  std::vector<std::string> sorted;
  for (const auto& [key, value] : labels) sorted.push_back(absl::StrCat(key, "=", value));
  std::sort(sorted.begin(), sorted.end());
  return absl::StrJoin(sorted, ",");
}

std::string OperationNames(const v1::Job& job) {
  std::vector<std::string> names;
  for (const v1::Operation& operation : job.operations()) {
    switch (operation.kind_case()) {
      case v1::Operation::kRetime: names.emplace_back("retime"); break;
      case v1::Operation::kReduce: names.emplace_back("reduce"); break;
      case v1::Operation::kBake: names.emplace_back("bake"); break;
      case v1::Operation::kConvert: names.emplace_back("convert"); break;
      case v1::Operation::KIND_NOT_SET: names.emplace_back("?"); break;
    }
  }
  return absl::StrJoin(names, ", ");
}

std::string FormatReports(const google::protobuf::RepeatedPtrField<v1::OperationReport>& reports,
                          const core::Clip& layout) {
  std::string text;
  for (const v1::OperationReport& report : reports) {
    const core::StepReport step = wire::StepReportFromProto(report);
    if (const auto* retime = std::get_if<core::RetimeReport>(&step)) {
      absl::StrAppend(&text, FormatRetimeReport(*retime));
    } else if (const auto* reduction = std::get_if<core::ReductionReport>(&step)) {
      absl::StrAppend(&text, FormatReductionReport(*reduction, layout));
    }
  }
  return text;
}

std::string FormatJob(const v1::Job& job) {
  using google::protobuf::util::TimeUtil;
  std::string text = absl::StrCat(
      SummaryLine("job", job.job_id()), SummaryLine("state", JobStateName(job.state())),
      SummaryLine("progress", Percent(job.progress())), SummaryLine("stage", job.stage()),
      SummaryLine("clip id", job.clip_id()), SummaryLine("operations", OperationNames(job)));
  if (!job.labels().empty()) absl::StrAppend(&text, SummaryLine("labels", Labels(job.labels())));
  if (!job.request_id().empty()) absl::StrAppend(&text, SummaryLine("request id", job.request_id()));
  if (job.has_create_time()) {
    absl::StrAppend(&text, SummaryLine("created", TimeUtil::ToString(job.create_time())));
  }
  if (job.has_start_time()) {
    absl::StrAppend(&text, SummaryLine("started", TimeUtil::ToString(job.start_time())));
  }
  if (job.has_end_time()) {
    absl::StrAppend(&text, SummaryLine("ended", TimeUtil::ToString(job.end_time())));
  }
  if (job.error_code() != 0 || !job.error_message().empty()) {
    absl::StrAppend(&text, SummaryLine("error", absl::StrCat(absl::StatusCodeToString(
                                                                 static_cast<absl::StatusCode>(
                                                                     job.error_code())),
                                                             ": ", job.error_message())));
  }
  absl::StrAppend(&text, FormatReports(job.reports(), core::Clip()));
  return text;
}

// Rows padded to the widest cell of each column, two spaces apart.
std::string FormatTable(const std::vector<std::vector<std::string>>& rows) {
  std::vector<std::size_t> widths;
  for (const auto& row : rows) {
    widths.resize(std::max(widths.size(), row.size()), 0);
    for (std::size_t i = 0; i < row.size(); ++i) widths[i] = std::max(widths[i], row[i].size());
  }
  std::string text;
  for (const auto& row : rows) {
    std::string line;
    for (std::size_t i = 0; i < row.size(); ++i) {
      std::string cell = row[i];
      if (i + 1 < row.size()) cell.resize(widths[i] + 2, ' ');
      line += cell;
    }
    line.erase(line.find_last_not_of(' ') + 1);
    absl::StrAppend(&text, line, "\n");
  }
  return text;
}

absl::Status List(CommandContext& context) {
  TEMPOKEY_RETURN_IF_ERROR(context.Positionals({}).status());
  v1::ListJobsRequest request;
  for (const std::string& state : context.args().Values("--state")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string_view name, ParseChoice("--state", state, kStates));
    const auto index = std::find(std::begin(kStates), std::end(kStates), name) - std::begin(kStates);
    request.add_states(static_cast<v1::JobState>(v1::JOB_STATE_QUEUED + index));
  }
  for (const std::string& label : context.args().Values("--label")) {
    TEMPOKEY_ASSIGN_OR_RETURN(auto pair, ParseLabel("--label", label));
    (*request.mutable_labels())[pair.first] = pair.second;
  }
  std::optional<std::int64_t> limit;
  if (std::optional<std::string> v = context.args().Value("--limit")) {
    TEMPOKEY_ASSIGN_OR_RETURN(limit, ParseInt64("--limit", *v));
    if (*limit <= 0) return UsageError(absl::StrCat("--limit: expected an integer > 0, got '", *v, "'"));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());

  std::vector<std::vector<std::string>> rows = {{"JOB", "STATE", "PROGRESS", "STAGE", "CLIP", "LABELS"}};
  while (!limit || static_cast<std::int64_t>(rows.size()) - 1 < *limit) {
    absl::StatusOr<v1::ListJobsResponse> page = client->ListJobs(request);
    if (!page.ok()) return ServerError(page.status());
    for (const v1::Job& job : page->jobs()) {
      if (limit && static_cast<std::int64_t>(rows.size()) - 1 >= *limit) break;
      rows.push_back({job.job_id(), JobStateName(job.state()), Percent(job.progress()), job.stage(),
                      job.clip_id().empty() ? "-" : job.clip_id(), Labels(job.labels())});
    }
    if (page->next_page_token().empty()) break;
    request.set_page_token(page->next_page_token());
  }
  context.out() << FormatTable(rows);
  return absl::OkStatus();
}

absl::Status Get(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> ids, context.Positionals(kJobArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  absl::StatusOr<v1::Job> job = client->GetJob(ids[0]);
  if (!job.ok()) return ServerError(job.status());
  context.out() << FormatJob(*job);
  return absl::OkStatus();
}

absl::Status Watch(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> ids, context.Positionals(kJobArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  absl::StatusOr<v1::Job> job = client->WatchJob(ids[0], [&](const v1::Job& update) {
    context.out() << absl::StrFormat("%-9s %4s  %s\n", JobStateName(update.state()),
                                     Percent(update.progress()), update.stage())
                  << std::flush;
  });
  if (!job.ok()) return ServerError(job.status());
  return JobOutcome(*job);
}

absl::Status Result(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> ids, context.Positionals(kJobArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string output, context.Required("--output"));
  TEMPOKEY_ASSIGN_OR_RETURN(FileFormat format, FormatForPath("-o", output, kAllFormats));
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  absl::StatusOr<core::PipelineResult> result = client->GetJobResult(ids[0]);
  if (!result.ok()) return ServerError(result.status());
  const bool keyed = std::holds_alternative<core::KeyedClip>(result->output);
  if (!keyed && IsKeyedFormat(format)) {
    return UsageError(absl::StrCat("-o ", output, ": job ", ids[0],
                                   " produced a sampled clip, which has no curves: write .bvh, "
                                   ".csv, .gltf or .glb"));
  }
  if (keyed && !IsKeyedFormat(format)) {
    // Curves as glTF are fitted against the job's input clip, and as samples baked: the server
    // holds both, and formats the file as `reduce --job` writes it.
    const absl::StatusOr<std::string> bytes = client->ExportJobFile(
        ids[0], std::string(ExtensionOf(format).substr(1)), kMaxExportedFileBytes);
    if (!bytes.ok()) return ServerError(bytes.status());
    TEMPOKEY_RETURN_IF_ERROR(core::WriteFileAtomically(output, *bytes));
  } else {
    TEMPOKEY_RETURN_IF_ERROR(WriteOutput(output, format, result->output));
  }
  const core::Clip& layout = keyed ? std::get<core::KeyedClip>(result->output).layout
                                   : std::get<core::Clip>(result->output);
  for (const core::StepReport& report : result->reports) {
    if (const auto* retime = std::get_if<core::RetimeReport>(&report)) {
      context.out() << FormatRetimeReport(*retime);
    } else if (const auto* reduction = std::get_if<core::ReductionReport>(&report)) {
      context.out() << FormatReductionReport(*reduction, layout);
    }
  }
  context.out() << SummaryLine("wrote", output);
  if (!keyed) context.out() << FormatClipSummary(layout);
  return absl::OkStatus();
}

absl::Status Cancel(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> ids, context.Positionals(kJobArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  absl::StatusOr<v1::Job> job = client->CancelJob(ids[0]);
  if (!job.ok()) return ServerError(job.status());
  context.out() << SummaryLine("job", job->job_id())
                << SummaryLine("state", JobStateName(job->state()));
  return absl::OkStatus();
}

absl::Status Delete(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> ids, context.Positionals(kJobArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  if (absl::Status deleted = client->DeleteJob(ids[0]); !deleted.ok()) return ServerError(deleted);
  context.out() << SummaryLine("deleted", ids[0]);
  return absl::OkStatus();
}

}  // namespace

const Command& JobsListCommand() {
  static const Command command{
      .name = "jobs list",
      .synopsis = "[--state STATE] [--label KEY=VALUE] [--limit N]",
      .summary = "list the server's jobs",
      .description = "Prints one row per job: id, state, progress, stage, clip id and labels.\n",
      .flags = kListFlags,
      .run = List,
  };
  return command;
}

const Command& JobsGetCommand() {
  static const Command command{
      .name = "jobs get",
      .synopsis = "JOB",
      .summary = "print one job",
      .description = "Prints a job's state, progress, clip, operations, times, error and reports.\n",
      .flags = {},
      .run = Get,
  };
  return command;
}

const Command& JobsWatchCommand() {
  static const Command command{
      .name = "jobs watch",
      .synopsis = "JOB",
      .summary = "follow a job until it ends",
      .description =
          "Prints a line \"STATE PROGRESS STAGE\" for each update of JOB until it ends. Exits 0\n"
          "when it succeeds, 1 when it fails or is cancelled (the error line gives the job's\n"
          "error).\n",
      .flags = {},
      .run = Watch,
  };
  return command;
}

const Command& JobsResultCommand() {
  static const Command command{
      .name = "jobs result",
      .synopsis = "JOB -o OUT",
      .summary = "fetch a succeeded job's result",
      .description =
          "Fetches the result of JOB and writes OUT atomically: .bvh, .csv, .gltf or .glb for a\n"
          "sampled clip; .json or .anim for keyed curves, or .gltf, .glb, .bvh or .csv as the\n"
          "server formats them (glTF fitted against the job's stored input clip, samples baked),\n"
          "as reduce --job writes them. Prints the job's reports.\n",
      .flags = kResultFlags,
      .run = Result,
  };
  return command;
}

const Command& JobsCancelCommand() {
  static const Command command{
      .name = "jobs cancel",
      .synopsis = "JOB",
      .summary = "cancel a job (idempotent)",
      .description =
          "Cancels JOB: a queued job never runs, a running one stops between channels. Prints\n"
          "the job's state afterwards (a job that already ended keeps its state).\n",
      .flags = {},
      .run = Cancel,
  };
  return command;
}

const Command& JobsDeleteCommand() {
  static const Command command{
      .name = "jobs delete",
      .synopsis = "JOB",
      .summary = "delete a job and its result",
      .description = "Deletes JOB and its stored result from the server.\n",
      .flags = {},
      .run = Delete,
  };
  return command;
}

}  // namespace tempokey::client
