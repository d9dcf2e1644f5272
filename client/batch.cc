#include "client/batch.h"

#include <sys/stat.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <random>
#include <system_error>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_format.h"
#include "client/batch_manifest.h"
#include "client/cli_errors.h"
#include "client/test_hook.h"
#include "proto/clip_digest.h"
#include "proto/retry_hint.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::optional<FileFormat> InputFormat(const fs::path& path, bool include_csv) {
  constexpr FileFormat kBvhOnly[] = {FileFormat::kBvh};
  absl::StatusOr<FileFormat> format =
      FormatForPath("", path.string(), include_csv ? std::span<const FileFormat>(kSampledFormats)
                                                   : std::span<const FileFormat>(kBvhOnly));
  if (!format.ok()) return std::nullopt;
  return *format;
}

bool IsHidden(const fs::path& relative) {
  for (const fs::path& part : relative) {
    if (part.string().rfind('.', 0) == 0) return true;
  }
  return false;
}

// A test hook: SIGINT raised right after the N-th output staged beside its input is written,
// before it replaces the input (TEMPOKEY_TEST_BATCH_INTERRUPT_AFTER_STAGING=N; 0 or unset: never).
long InterruptAfterStagingForTesting() {
  static const long n = TestHookCount("TEMPOKEY_TEST_BATCH_INTERRUPT_AFTER_STAGING");
  return n;
}

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Whether another attempt at the same file may succeed, and after how long.
std::optional<std::chrono::milliseconds> RetryDelay(const absl::Status& status, int attempt,
                                                    const BatchOptions& options,
                                                    std::mt19937& random) {
  const std::optional<std::chrono::milliseconds> hint = wire::GetRetryAfter(status);
  const bool retryable = status.code() == absl::StatusCode::kUnavailable ||
                         (status.code() == absl::StatusCode::kResourceExhausted && hint);
  if (!retryable || attempt >= options.max_attempts) return std::nullopt;
  if (hint) {
    // The hint is when the server expects room; the files it refused together wait a random
    // share longer (up to twice the hint), so they do not all come back at that moment.
    std::uniform_real_distribution<double> jitter(1.0, 2.0);
    return std::chrono::milliseconds(
        static_cast<std::int64_t>(std::ceil(static_cast<double>(hint->count()) * jitter(random))));
  }
  // Exponential backoff with jitter, so files that failed together do not retry together.
  const double ceiling = std::min(options.max_backoff_seconds,
                                  options.initial_backoff_seconds * std::pow(2.0, attempt - 1));
  std::uniform_real_distribution<double> jitter(0.5 * ceiling, ceiling);
  return std::chrono::milliseconds(static_cast<std::int64_t>(1000.0 * jitter(random)));
}

// The batch's calls in flight, at most `size` (--jobs), fewer once a server was busy: a call
// refused for the moment (RESOURCE_EXHAUSTED with a retry hint: its queue full, no stream slot,
// its memory budget in use) while n of the batch's calls were in flight shows that the servers
// take at most n - 1 of them, so the batch keeps at most that many in flight (never fewer than
// one). Its refused files then wait for one of its own calls to end rather than spend their
// attempts on a server the batch itself keeps busy. The room comes back one call at a time,
// after 4 x the limit calls in a row succeed (the server may have been busy with another
// client's work, or one small server among several).
class CallWindow {
 public:
  enum class Outcome { kOk, kBusy, kOther };

  explicit CallWindow(int size) : size_(std::max(1, size)), limit_(size_) {}

  // Waits until a call may start, and counts it.
  void Enter() {
    std::unique_lock<std::mutex> lock(mutex_);
    room_.wait(lock, [this] { return in_flight_ < limit_; });
    ++in_flight_;
  }
  // A call ended with `outcome`.
  void Leave(Outcome outcome) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (outcome == Outcome::kBusy) {
        limit_ = std::max(1, std::min(limit_, in_flight_ - 1));
        successes_ = 0;
      } else if (outcome == Outcome::kOk && limit_ < size_ && ++successes_ >= 4 * limit_) {
        ++limit_;
        successes_ = 0;
      }
      --in_flight_;
    }
    room_.notify_all();
  }

 private:
  const int size_;
  std::mutex mutex_;
  std::condition_variable room_;
  int in_flight_ = 0;
  int limit_;
  int successes_ = 0;  // calls in a row that succeeded since the limit last changed
};

// A write error of an output staged beside the file it replaces (in place) names that file,
// with the staging file's name after it, rather than the hidden staging file alone.
absl::Status NameTheReplacedFile(const absl::Status& error, const std::string& staged,
                                 const std::string& output) {
  const std::string named = absl::StrCat(
      output, " (written first as ", fs::path(staged).filename().string(), ")");
  return absl::Status(error.code(),
                      absl::StrReplaceAll(error.message(), {{staged, named}}));
}

// Frames, keys and the last reduction's max error of a finished pipeline.
// A keyed output always comes from a reduction, whose report counts its keys.
void Describe(const core::PipelineResult& result, BatchFileResult& file) {
  if (const auto* clip = std::get_if<core::Clip>(&result.output)) file.frames = clip->frame_count;
  for (const core::StepReport& report : result.reports) {
    if (const auto* reduction = std::get_if<core::ReductionReport>(&report)) {
      file.keys = reduction->key_count;
      file.max_error = reduction->max_error;
      if (reduction->world) file.max_joint_error = reduction->world->max_error;
    }
  }
}

// Reads, processes (with retries) and writes one file. Failures come back with the file's name
// in front unless the message already starts with its path (reader errors do).
BatchFileResult ProcessFile(const Client& client, const BatchItem& item,
                            std::span<const core::PipelineStep> steps, const BatchOptions& options,
                            CallWindow& window, std::mt19937& random) {
  const Clock::time_point start = Clock::now();
  BatchFileResult file;
  file.name = item.name;
  file.output_path = item.output_path;
  auto finish = [&](absl::Status status) {
    if (!status.ok() && core::AsStd(status.message()).rfind(item.input_path, 0) != 0) {
      status = core::Annotate(status, item.name);
    }
    file.status = std::move(status);
    file.seconds = SecondsSince(start);
    return file;
  };

  absl::StatusOr<core::Clip> clip = ReadClipFile(item.input_path, options.csv_frame_time_seconds);
  if (!clip.ok()) return finish(clip.status());
  const std::vector<core::PipelineStep> file_steps = StepsForFormat(steps, item.output_format);
  std::string input_id;
  std::string pipeline;
  if (options.manifest != nullptr) {
    input_id = wire::ClipContentId(*clip);
    pipeline = PipelineDigest(file_steps, item.output_format);
    if (std::optional<ManifestRecord> record =
            options.manifest->FindUpToDate(item, input_id, pipeline)) {
      options.manifest->Keep(*record);
      file.skipped = true;
      file.frames = record->frames;
      file.keys = record->keys;
      file.max_error = record->max_error;
      return finish(absl::OkStatus());
    }
  }
  if (absl::Status valid = core::ValidatePipeline(*clip, file_steps); !valid.ok()) {
    return finish(valid);
  }
  auto process = [&](const core::Clip& input, std::span<const core::PipelineStep> part)
      -> absl::StatusOr<core::PipelineResult> {
    // Each call has its own --attempts (a keyed glTF after other steps makes two calls);
    // `attempts` counts every call made.
    for (int tries = 1;; ++tries) {
      ++file.attempts;
      window.Enter();
      absl::StatusOr<core::PipelineResult> result = client.Process(input, part);
      window.Leave(result.ok() ? CallWindow::Outcome::kOk
                   : result.status().code() == absl::StatusCode::kResourceExhausted &&
                           wire::GetRetryAfter(result.status()).has_value()
                       ? CallWindow::Outcome::kBusy
                       : CallWindow::Outcome::kOther);
      if (result.ok()) return result;
      const std::optional<std::chrono::milliseconds> delay =
          RetryDelay(result.status(), tries, options, random);
      if (!delay) return ServerError(result.status());
      std::this_thread::sleep_for(*delay);
    }
  };
  // A keyed glTF fits its rotations against the clip the final reduce took: the input, or what
  // the steps before that reduce make of it (fetched first, then reduced in a second call).
  GltfExportSource gltf;
  std::span<const core::PipelineStep> remaining(file_steps);
  core::Clip reduce_input;
  if (IsGltfFormat(item.output_format) && core::ProducesKeyedOutput(file_steps)) {
    const std::size_t last = file_steps.size() - 1;
    const auto& reduce = std::get<core::ReduceStep>(file_steps[last]);
    gltf.max_rotation_error_degrees = GltfRotationBoundDegrees(reduce);
    gltf.joint_tolerance = GltfJointTolerance(reduce);
    gltf.source = &*clip;
    if (last > 0) {
      absl::StatusOr<core::PipelineResult> before = process(*clip, remaining.first(last));
      if (!before.ok()) return finish(before.status());
      reduce_input = std::get<core::Clip>(std::move(before->output));
      gltf.source = &reduce_input;
      remaining = remaining.subspan(last);
    }
  }
  absl::StatusOr<core::PipelineResult> result =
      process(gltf.source != nullptr ? *gltf.source : *clip, remaining);
  if (!result.ok()) return finish(result.status());
  std::error_code ignored;
  fs::create_directories(fs::path(item.output_path).parent_path(), ignored);
  // An output replacing its own input (--overwrite) is written whole beside it first, and put
  // in place only once its record is on disk (BatchManifest::ReplaceInPlace()): a run stopped
  // in between must never take the output for an input.
  const bool in_place = options.manifest != nullptr &&
                        IsSameFile(item.input_path, item.output_path) &&
                        fs::is_regular_file(item.output_path, ignored);
  std::string write_path = item.output_path;
  // The staged output is removed by the signal handlers too until it has replaced the input (a
  // run interrupted in between left it beside the inputs until the next run).
  std::optional<core::PendingFile> staged_file;
  if (in_place) {
    absl::StatusOr<std::string> staged = options.manifest->StagingPath(item);
    if (!staged.ok()) return finish(staged.status());
    write_path = *std::move(staged);
    staged_file.emplace(write_path);
  }
  if (absl::Status written = WriteOutput(write_path, item.output_format, result->output, gltf);
      !written.ok()) {
    return finish(in_place ? NameTheReplacedFile(written, write_path, item.output_path) : written);
  }
  Describe(*result, file);
  if (in_place) {
    static std::atomic<long> staged_outputs{0};
    if (const long n = InterruptAfterStagingForTesting(); n > 0 && ++staged_outputs == n) {
      ::raise(SIGINT);
    }
    return finish(options.manifest->ReplaceInPlace(item, write_path, input_id, pipeline, file));
  }
  if (options.manifest != nullptr) {
    return finish(options.manifest->RecordWritten(item, input_id, pipeline, file));
  }
  return finish(absl::OkStatus());
}

// Refuses a plan in which two inputs write one output (walk.bvh and walk.BVH, or walk.csv, whose
// runs would overwrite each other's), or an output is another file's input (it would replace a
// clip before or after that clip is read). An output that is its own input is left to
// CheckOutputIsNotTheInput() (--overwrite).
absl::Status CheckOutputsApart(std::span<const BatchItem> items) {
  std::map<std::string, const BatchItem*> writer_of;
  for (const BatchItem& item : items) {
    const auto [at, added] = writer_of.emplace(item.output_path, &item);
    if (!added) {
      return UsageError(absl::StrCat("batch: ", at->second->name, " and ", item.name,
                                     " would both be written to ", item.output_path,
                                     "; rename one, or run them in separate batches"));
    }
  }
  // Inputs by device and inode (an output that does not exist yet is no input).
  std::map<std::pair<dev_t, ino_t>, const BatchItem*> input_by_inode;
  for (const BatchItem& item : items) {
    struct stat info {};
    if (::stat(item.input_path.c_str(), &info) == 0) {
      input_by_inode.emplace(std::make_pair(info.st_dev, info.st_ino), &item);
    }
  }
  for (const BatchItem& item : items) {
    const BatchItem* input = nullptr;
    struct stat info {};
    if (::stat(item.output_path.c_str(), &info) == 0) {
      const auto at = input_by_inode.find({info.st_dev, info.st_ino});
      if (at != input_by_inode.end()) input = at->second;
    }
    if (input != nullptr && input != &item) {
      return UsageError(absl::StrCat("batch: the output of ", item.name, ", ", item.output_path,
                                     ", is the input ", input->name, "; choose another OUTDIR"));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::vector<BatchItem>> PlanBatch(const BatchPlanOptions& options) {
  if (options.output_format && IsKeyedFormat(*options.output_format) && !options.keyed_output) {
    return UsageError(absl::StrCat("--format ", core::AsAbsl(ExtensionOf(*options.output_format).substr(1)),
                                   " needs a pipeline that ends with reduce (it ends with samples)"));
  }
  std::error_code error;
  const fs::path root(options.input_dir);
  if (!fs::exists(root, error)) {
    return absl::NotFoundError(absl::StrCat(options.input_dir, ": no such folder"));
  }
  if (!fs::is_directory(root, error)) {
    return absl::InvalidArgumentError(absl::StrCat(options.input_dir, ": is a file, not a folder"));
  }
  std::vector<fs::path> found;
  auto consider = [&](const fs::directory_entry& entry) {
    const fs::path relative = entry.path().lexically_relative(root);
    // Every entry named as an input but a folder is one: a dangling or looping link, a FIFO or
    // a socket then fails when read, with the reader's message, instead of being left out of the
    // summary without a word.
    std::error_code entry_error;
    if (!IsHidden(relative) && InputFormat(relative, options.include_csv) &&
        !entry.is_directory(entry_error) &&
        !(options.is_own_output && options.is_own_output(entry.path().string()))) {
      found.push_back(relative);
    }
  };
  if (options.recursive) {
    // An OUTDIR inside DIR is walked too: a clip there is an input (unless is_own_output says it
    // is one of the batch's recorded outputs), and CheckOutputsApart() refuses a plan that would
    // write over one.
    fs::recursive_directory_iterator it(root, error);
    for (; !error && it != fs::recursive_directory_iterator(); it.increment(error)) consider(*it);
  } else {
    for (const auto& entry : fs::directory_iterator(root, error)) consider(entry);
  }
  if (error) {
    return absl::UnavailableError(absl::StrCat(options.input_dir, ": ", error.message()));
  }
  if (found.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        options.input_dir, ": no .bvh", options.include_csv ? " or .csv" : "", " files"));
  }
  std::sort(found.begin(), found.end());
  std::vector<BatchItem> items;
  for (const fs::path& relative : found) {
    BatchItem item;
    item.name = relative.generic_string();
    item.input_path = (root / relative).string();
    const FileFormat input_format = *InputFormat(relative, options.include_csv);
    item.output_format = options.output_format.value_or(
        options.keyed_output ? FileFormat::kKeyedJson : input_format);
    fs::path output = fs::path(options.output_dir) / relative;
    output.replace_extension(std::string(ExtensionOf(item.output_format)));
    item.output_path = output.string();
    items.push_back(std::move(item));
  }
  TEMPOKEY_RETURN_IF_ERROR(CheckOutputsApart(items));
  return items;
}

std::vector<core::PipelineStep> StepsForFormat(std::span<const core::PipelineStep> steps,
                                               FileFormat format) {
  const bool bake =
      core::ProducesKeyedOutput(steps) && !IsKeyedFormat(format) && !IsGltfFormat(format);
  // Sized once and filled in place: growing a vector of variants by push_back made g++ 12 at -O2
  // report -Wmaybe-uninitialized on the inactive alternatives it moves (a false positive).
  std::vector<core::PipelineStep> result(steps.size() + (bake ? 1 : 0),
                                         core::PipelineStep(core::BakeStep{}));
  std::copy(steps.begin(), steps.end(), result.begin());
  return result;
}

int BatchSummary::failed_count() const {
  return static_cast<int>(std::count_if(files.begin(), files.end(),
                                        [](const BatchFileResult& f) { return !f.status.ok(); }));
}

absl::Status BatchSummary::FailedFiles() const {
  const int failed = failed_count();
  if (failed == 0) return absl::OkStatus();
  const auto first = std::find_if(files.begin(), files.end(),
                                  [](const BatchFileResult& f) { return !f.status.ok(); });
  return absl::Status(first->status.code(),
                      absl::StrCat(failed, " of ", files.size(), " files failed; first: ",
                                   first->status.message()));
}

int BatchSummary::skipped_count() const {
  return static_cast<int>(std::count_if(files.begin(), files.end(), [](const BatchFileResult& f) {
    return f.status.ok() && f.skipped;
  }));
}

int BatchSummary::done_count() const {
  return static_cast<int>(files.size()) - failed_count() - skipped_count();
}

BatchSummary RunBatch(const Client& client, std::span<const BatchItem> items,
                      std::span<const core::PipelineStep> steps, const BatchOptions& options,
                      const BatchFileDoneFn& on_done) {
  const Clock::time_point start = Clock::now();
  BatchSummary summary;
  summary.files.resize(items.size());
  std::atomic<std::size_t> next{0};
  std::mutex done_mutex;
  int done = 0;
  CallWindow window(options.jobs);
  auto worker = [&](unsigned seed) {
    std::mt19937 random(seed);
    for (std::size_t i = next++; i < items.size(); i = next++) {
      summary.files[i] = ProcessFile(client, items[i], steps, options, window, random);
      if (options.manifest != nullptr && !summary.files[i].status.ok()) {
        options.manifest->Forget(items[i]);
      }
      std::lock_guard<std::mutex> lock(done_mutex);
      ++done;
      if (on_done) on_done(summary.files[i], done, static_cast<int>(items.size()));
    }
  };
  if (items.empty()) return summary;
  const int threads = std::clamp<int>(options.jobs, 1, static_cast<int>(items.size()));
  std::vector<std::jthread> pool;
  std::random_device seeds;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker, seeds());
  worker(seeds());
  pool.clear();  // joins
  summary.seconds = SecondsSince(start);
  return summary;
}

std::string FormatBatchSummaryJson(const BatchSummary& summary) {
  const int failed = summary.failed_count();
  const int total = static_cast<int>(summary.files.size());
  std::string out = absl::StrFormat(
      "{\"files\": %d, \"succeeded\": %d, \"done\": %d, \"skipped\": %d, \"failed\": %d, "
      "\"seconds\": %.3f",
      total, total - failed, summary.done_count(), summary.skipped_count(), failed,
      summary.seconds);
  if (summary.shard) absl::StrAppend(&out, ", \"shard\": \"", summary.shard->Name(), "\"");
  if (summary.merged_shards > 0) {
    absl::StrAppend(&out, ", \"shards\": ", summary.merged_shards, ", \"missing_shards\": [");
    for (std::size_t i = 0; i < summary.missing_shards.size(); ++i) {
      absl::StrAppend(&out, i == 0 ? "\"" : ", \"", summary.missing_shards[i], "/",
                      summary.merged_shards, "\"");
    }
    out += ']';
  }
  if (!summary.pipeline.empty()) {
    out += ", \"pipeline\": ";
    core::AppendJsonString(out, summary.pipeline);
  }
  out += ", \"results\": [";
  for (std::size_t i = 0; i < summary.files.size(); ++i) {
    const BatchFileResult& file = summary.files[i];
    out += i == 0 ? "\n  {\"input\": " : ",\n  {\"input\": ";
    core::AppendJsonString(out, file.name);
    if (file.status.ok()) {
      out += ", \"output\": ";
      core::AppendJsonString(out, file.output_path);
      out += file.skipped ? ", \"status\": \"skipped\"" : ", \"status\": \"ok\"";
    } else {
      out += ", \"status\": \"failed\", \"code\": ";
      core::AppendJsonString(out, absl::StatusCodeToString(file.status.code()));
      out += ", \"error\": ";
      core::AppendJsonString(out, core::AsStd(file.status.message()));
    }
    absl::StrAppendFormat(&out, ", \"attempts\": %d, \"seconds\": %.3f", file.attempts,
                          file.seconds);
    if (file.status.ok()) {
      if (file.frames > 0) absl::StrAppend(&out, ", \"frames\": ", file.frames);
      if (file.keys > 0) absl::StrAppend(&out, ", \"keys\": ", file.keys);
      if (file.max_error) absl::StrAppend(&out, ", \"max_error\": ", core::FormatDouble(*file.max_error));
      if (file.max_joint_error) {
        absl::StrAppend(&out, ", \"max_joint_error\": ", core::FormatDouble(*file.max_joint_error));
      }
    }
    out += '}';
  }
  out += summary.files.empty() ? "]}\n" : "\n]}\n";
  return out;
}

}  // namespace tempokey::client
