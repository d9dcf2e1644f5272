// `tempokey batch DIR -o OUTDIR --ops PIPELINE.json`: one pipeline over a folder of clips, for CI
// stages and bulk conversions. Prints a JSON summary on stdout (and to --summary FILE), progress
// on stderr (progress_bar.h), and fails (exit 1) if any file failed, after trying every file.
// Resumable (batch_manifest.h) and shardable (batch_shard.h).
#include <sys/ioctl.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <initializer_list>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "client/batch.h"
#include "client/batch_manifest.h"
#include "client/batch_shard.h"
#include "client/cli_errors.h"
#include "client/clip_files.h"
#include "client/command.h"
#include "client/pipeline_file.h"
#include "client/progress_bar.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/io/printable_text.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

constexpr std::string_view kDirArgument[] = {"DIR"};
constexpr std::string_view kFormats[] = {"bvh", "csv", "json", "anim", "gltf", "glb"};
constexpr FileFormat kFormatsByName[] = {FileFormat::kBvh,       FileFormat::kCsv,
                                         FileFormat::kKeyedJson, FileFormat::kMayaAnim,
                                         FileFormat::kGltf,      FileFormat::kGlb};
constexpr int kMaxJobs = 256;

constexpr FlagSpec kBatchFlags[] = {
    {"--output", "-o", "OUTDIR", "folder for the outputs (created if missing)"},
    {"--ops", "", "FILE", "the pipeline, as JSON (see tempokey batch --help)"},
    {"--jobs", "-j", "N", "files processed at once (default 4)"},
    {"--format", "", "NAME", "output format: bvh, csv, json, anim, gltf or glb (default: .json "
                             "for keyed results, the input's own otherwise)"},
    {"--summary", "", "FILE", "also write the JSON summary to FILE (atomically)"},
    {"--attempts", "", "N", "tries per server call when a server is unavailable or full (default 5)"},
    {"--recursive", "-r", "", "also process the sub-folders of DIR, mirrored under OUTDIR"},
    kInputFpsFlag,
    {"--shard", "", "I/N", "take only share I of N (0 <= I < N) of the files, by a hash of their "
                           "path"},
    {"--force", "", "", "redo every file, even those whose outputs are up to date"},
    {"--progress", "", "MODE", "auto (default: a bar on a terminal, else a line per file), bar, "
                               "lines or none"},
    {"--overwrite", "", "", "allow outputs to replace their own input files (OUTDIR = DIR)"},
};
constexpr std::string_view kProgressModes[] = {"auto", "bar", "lines", "none"};
constexpr int kDefaultTerminalWidth = 80;

// --progress; "auto" is a bar when stderr is a terminal, a line per file otherwise.
absl::StatusOr<ProgressMode> ProgressModeFromFlags(const CommandContext& context) {
  const std::string text = context.args().Value("--progress").value_or("auto");
  TEMPOKEY_ASSIGN_OR_RETURN(std::string_view mode, ParseChoice("--progress", text, kProgressModes));
  if (mode == "bar") return ProgressMode::kBar;
  if (mode == "lines") return ProgressMode::kLines;
  if (mode == "none") return ProgressMode::kNone;
  return context.show_progress() ? ProgressMode::kBar : ProgressMode::kLines;
}

int TerminalWidth() {
  winsize size{};
  if (ioctl(STDERR_FILENO, TIOCGWINSZ, &size) == 0 && size.ws_col > 0) return size.ws_col;
  return kDefaultTerminalWidth;
}

absl::StatusOr<BatchOptions> BatchOptionsFromFlags(const ParsedArgs& args) {
  BatchOptions options;
  if (std::optional<std::string> jobs = args.Value("--jobs")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t n, ParseInt64("--jobs", *jobs));
    if (n < 1 || n > kMaxJobs) {
      return UsageError(absl::StrCat("--jobs: expected 1 to ", kMaxJobs, ", got ", n));
    }
    options.jobs = static_cast<int>(n);
  }
  if (std::optional<std::string> attempts = args.Value("--attempts")) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::int64_t n, ParseInt64("--attempts", *attempts));
    if (n < 1 || n > 100) return UsageError(absl::StrCat("--attempts: expected 1 to 100, got ", n));
    options.max_attempts = static_cast<int>(n);
  }
  TEMPOKEY_ASSIGN_OR_RETURN(options.csv_frame_time_seconds, InputFrameTimeFromFlags(args));
  return options;
}

absl::StatusOr<std::optional<FileFormat>> FormatFromFlags(const ParsedArgs& args) {
  std::optional<std::string> text = args.Value("--format");
  if (!text) return std::optional<FileFormat>();
  TEMPOKEY_ASSIGN_OR_RETURN(std::string_view name, ParseChoice("--format", *text, kFormats));
  return kFormatsByName[std::find(std::begin(kFormats), std::end(kFormats), name) -
                        std::begin(kFormats)];
}

// The errors among `statuses` as one: the first one's code, their messages in order joined by
// "; and ". OK when all are.
absl::Status JoinErrors(std::initializer_list<absl::Status> statuses) {
  absl::StatusCode code = absl::StatusCode::kOk;
  std::vector<absl::string_view> messages;
  for (const absl::Status& status : statuses) {
    if (status.ok()) continue;
    if (code == absl::StatusCode::kOk) code = status.code();
    messages.push_back(status.message());
  }
  if (code == absl::StatusCode::kOk) return absl::OkStatus();
  return absl::Status(code, absl::StrJoin(messages, "; and "));
}

// Refuses a --summary that would replace the pipeline, an input, an output, or a manifest or
// journal of OUTDIR (any shard's: every run reads them all).
absl::Status CheckSummaryPath(const std::string& summary_path, const std::string& ops_path,
                              std::span<const BatchItem> items, const std::string& output_dir) {
  const std::filesystem::path summary(summary_path);
  const std::string folder =
      summary.parent_path().empty() ? std::string(".") : summary.parent_path().string();
  if (summary.filename().string().starts_with(kManifestPrefix) &&
      IsSameFile(folder, output_dir)) {
    return UsageError(absl::StrCat("--summary ", summary_path,
                                   " is a name the batch keeps its records under in OUTDIR; "
                                   "choose another file"));
  }
  std::vector<NamedFile> files = {{ops_path, "the pipeline"}};
  for (const BatchItem& item : items) {
    files.push_back({item.input_path, "the input"});
    files.push_back({item.output_path, absl::StrCat("the output of ", item.name)});
  }
  return CheckWritesNoneOf(summary_path, "--summary", files);
}

absl::Status Batch(CommandContext& context) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<std::string> dirs, context.Positionals(kDirArgument));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string output_dir, context.Required("--output"));
  TEMPOKEY_ASSIGN_OR_RETURN(std::string ops_path, context.Required("--ops"));
  TEMPOKEY_ASSIGN_OR_RETURN(BatchOptions options, BatchOptionsFromFlags(context.args()));
  TEMPOKEY_ASSIGN_OR_RETURN(std::optional<FileFormat> format, FormatFromFlags(context.args()));
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<core::PipelineStep> steps, ReadPipelineFile(ops_path));
  TEMPOKEY_ASSIGN_OR_RETURN(ProgressMode progress_mode, ProgressModeFromFlags(context));
  std::optional<BatchShard> shard;
  if (std::optional<std::string> text = context.args().Value("--shard")) {
    TEMPOKEY_ASSIGN_OR_RETURN(shard, ParseShard(*text));
  }

  // The manifests first: with OUTDIR inside DIR, the outputs they record are no inputs (with
  // OUTDIR = DIR they are: written over their own inputs, --overwrite). Open() locks this run's
  // manifest, so a second run of it (same OUTDIR, same shard) stops here, exit 1, before any
  // work: not 2, a usage error, which fails a whole Kubernetes Job; a retry later may run.
  TEMPOKEY_ASSIGN_OR_RETURN(std::unique_ptr<BatchManifest> manifest,
                            BatchManifest::Open(output_dir, shard, context.args().Has("--force")));
  const bool outputs_beside_inputs = IsSameFile(dirs[0], output_dir);
  BatchPlanOptions plan{
      .input_dir = dirs[0],
      .output_dir = output_dir,
      .output_format = format,
      .keyed_output = core::ProducesKeyedOutput(steps),
      .include_csv = options.csv_frame_time_seconds.has_value(),
      .recursive = context.args().Has("--recursive"),
      .is_own_output =
          [&](const std::string& path) {
            return !outputs_beside_inputs && manifest->IsRecordedOutput(path);
          },
  };
  TEMPOKEY_ASSIGN_OR_RETURN(std::vector<BatchItem> items, PlanBatch(plan));
  if (shard) {
    std::erase_if(items, [&](const BatchItem& item) { return !InShard(item.name, *shard); });
  }
  for (const BatchItem& item : items) {
    TEMPOKEY_RETURN_IF_ERROR(CheckOutputIsNotTheInput(
        item.input_path, item.output_path, context.args().Has("--overwrite"), "batch: output"));
    // The manifest (JSON) cannot record such a name, so a re-run could not tell the output
    // written over the clip from the clip, and would process it again.
    if (!core::IsUtf8(item.name) && IsSameFile(item.input_path, item.output_path)) {
      return UsageError(absl::StrCat("batch --overwrite: ", core::PrintableText(item.name),
                                     ": a file name that is not UTF-8 cannot be recorded, so a "
                                     "re-run would process its output again; rename it"));
    }
  }
  const std::optional<std::string> summary_path = context.args().Value("--summary");
  if (summary_path) {
    TEMPOKEY_RETURN_IF_ERROR(CheckSummaryPath(*summary_path, ops_path, items, output_dir));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(const Client* client, context.Connect());
  if (!manifest->locked()) {
    context.err() << "warning: " << output_dir
                  << ": this file system takes no locks: another run of this manifest would not "
                     "be refused, and leftovers of a killed run are not removed\n";
  }
  manifest->RemoveLeftoverTemporaries(items);
  options.manifest = manifest.get();

  BatchSummary summary;
  {
    BatchProgressDisplay progress(context.err(), progress_mode, static_cast<int>(items.size()),
                                  progress_mode == ProgressMode::kBar ? TerminalWidth() : 0);
    summary = RunBatch(*client, items, steps, options,
                       [&](const BatchFileResult& file, int, int) { progress.FileDone(file); });
  }
  summary.shard = shard;
  summary.pipeline = PipelineDigest(steps, format);
  const absl::Status recorded = manifest->Finish(items);
  const std::string json = FormatBatchSummaryJson(summary);
  context.out() << json;
  const absl::Status summarized =
      summary_path ? core::WriteFileAtomically(*summary_path, json) : absl::OkStatus();
  // One line for everything that went wrong: a manifest or summary that cannot be written does
  // not hide the files that failed, nor they it.
  return JoinErrors({summarized, recorded, summary.FailedFiles()});
}

}  // namespace

const Command& BatchCommand() {
  static const Command command{
      .name = "batch",
      .synopsis = "DIR -o OUTDIR --ops PIPELINE.json [--jobs N] [--shard I/N] [options]",
      .summary = "run a pipeline on every clip of a folder (JSON summary, exit 1 if any failed)",
      .description =
          "Runs the operations of PIPELINE.json on every .bvh file of DIR (and .csv with\n"
          "--input-fps), --jobs files at a time, each in one stateless Process call, so a\n"
          "round-robin --server list or a load balancer spreads them over servers. A file whose\n"
          "server goes away or is full is retried whole (--attempts). Outputs go to OUTDIR\n"
          "under the input's name, written atomically. Prints a JSON summary of every file on\n"
          "stdout; exits 1 if any file failed, after trying them all.\n"
          "\n"
          "Resumable: OUTDIR/.tempokey-batch.json records, per output, the content id of its\n"
          "input and a digest of the pipeline and format; a re-run skips the outputs that are\n"
          "still on disk as recorded and redoes the others (input or pipeline changed, output\n"
          "missing or altered). --force redoes everything.\n"
          "\n"
          "Shards: --shard I/N (0 <= I < N) takes the files whose path relative to DIR hashes to\n"
          "I, so N runs (machines, or the pods of a Kubernetes Indexed Job) share the folder and\n"
          "together cover every file once; each keeps its own manifest\n"
          "(.tempokey-batch.shard-I-of-N.json). 'tempokey batch-summary' merges their summaries.\n"
          "\n"
          "PIPELINE.json lists operations whose options are the flags of the retime and\n"
          "reduce commands without their dashes (bake takes fps, convert wrap-rotations):\n"
          "  {\"operations\": [\n"
          "    {\"retime\": {\"speed\": \"0s:1,2s:0.5,4s:1\", \"fps\": 30}},\n"
          "    {\"reduce\": {\"tolerance\": 0.5}}]}\n"
          "A pipeline ending with reduce writes .json (keyed curves) unless --format says\n"
          "otherwise; bvh or csv then bake the curves back to samples; gltf or glb keep them\n"
          "(CUBICSPLINE) for keyed results and hold samples (LINEAR) for sampled ones.\n",
      .flags = kBatchFlags,
      .run = Batch,
  };
  return command;
}

}  // namespace tempokey::client
