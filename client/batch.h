// `tempokey batch`: one pipeline over every clip file of a folder, several files at once, each
// through a stateless Process call (so a load balancer or a round-robin target spreads them), with
// whole-file retries when a server goes away or refuses a file for the moment (its queue full, no
// stream slot, its memory budget in use: a retry hint), and a summary a CI stage can
// read. The engine lives here, apart from the command's flags and terminal output.
#ifndef TEMPOKEY_CLIENT_BATCH_H_
#define TEMPOKEY_CLIENT_BATCH_H_

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "client/batch_shard.h"
#include "client/client.h"
#include "client/clip_files.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::client {

class BatchManifest;

// One file of a batch: where it is read from and written to, and how it is named in reports
// (its path relative to the input folder).
struct BatchItem {
  std::string name;
  std::string input_path;
  std::string output_path;
  FileFormat output_format = FileFormat::kBvh;
};

struct BatchPlanOptions {
  std::string input_dir;
  std::string output_dir;
  // Output format of every file; unset: the input's own (.bvh stays .bvh) for sampled results,
  // .json for keyed ones.
  std::optional<FileFormat> output_format;
  bool keyed_output = false;    // the pipeline ends with a keyed clip
  bool include_csv = false;     // also take .csv files (needs a frame rate)
  bool recursive = false;       // descend into sub-folders, mirroring them under output_dir
  // When set, files for which it is true (by their path under input_dir) are no inputs: a
  // batch's own recorded outputs, in an output_dir inside input_dir.
  std::function<bool(const std::string& path)> is_own_output;
};

// The files of `options.input_dir` (.bvh, and .csv if asked; hidden files skipped), sorted by
// name, with their output paths: output_dir/<name with the output format's extension>.
// Errors: kNotFound / kInvalidArgument for a missing input folder or one that is a file;
// kInvalidArgument "DIR: no .bvh files" when there is nothing to do; kUnavailable when a folder
// cannot be read; usage errors for a keyed output format with a pipeline that ends sampled, for
// two inputs with one output ("batch: walk.BVH and walk.bvh would both be written to
// out/walk.json; ...") and for an output that is another file's input (an output_dir inside
// input_dir whose clips, or last run's outputs, are inputs too).
absl::StatusOr<std::vector<BatchItem>> PlanBatch(const BatchPlanOptions& options);

// The pipeline a batch runs for `format`: `steps`, plus a bake at the source rate when they end
// keyed and `format` stores samples.
std::vector<core::PipelineStep> StepsForFormat(std::span<const core::PipelineStep> steps,
                                               FileFormat format);

struct BatchOptions {
  int jobs = 4;                          // files in flight at once, >= 1
  int max_attempts = 5;                  // per Process call, for UNAVAILABLE and a full queue
  double initial_backoff_seconds = 0.2;  // doubled per attempt, up to max_backoff_seconds,
  double max_backoff_seconds = 2.0;      // or the server's retry-after hint when it gave one
  std::optional<double> csv_frame_time_seconds;
  // When set, a file whose output the manifest shows up to date is skipped (read and checked,
  // not sent), and every output written is recorded in it (batch_manifest.h). Not owned.
  BatchManifest* manifest = nullptr;
};

// What happened to one file.
struct BatchFileResult {
  std::string name{};
  std::string output_path{};
  absl::Status status{};   // OK, or why the file failed (its message names the file)
  bool skipped = false;    // OK because the output from an earlier run is up to date
  int attempts = 0;        // Process calls made (0: refused before any call)
  double seconds = 0.0;    // wall time spent on the file, reading and writing included
  std::int64_t frames = 0;      // sampled output: frames written
  std::int64_t keys = 0;        // keyed output or reduction: keys kept
  std::optional<double> max_error{};  // the last reduction's max error, if the pipeline reduced
  // Its joint world-position error (file units), when the clip has a skeleton.
  std::optional<double> max_joint_error{};
};

struct BatchSummary {
  std::vector<BatchFileResult> files;  // in plan order
  double seconds = 0.0;
  std::optional<BatchShard> shard;     // the share of the folder this run took, if sharded
  std::string pipeline;                // PipelineDigest() of the run's steps and --format
  int merged_shards = 0;               // N for the merge of a sharded run's summaries
  std::vector<int> missing_shards;     // and the shards that merge lacks
  int failed_count() const;
  int skipped_count() const;
  int done_count() const;  // processed and written by this run
  // The files that failed, as one error ("2 of 9 files failed; first: ..."), with the first
  // failure's code; OK when none failed.
  absl::Status FailedFiles() const;
};

// Called once per finished file (from worker threads, one call at a time).
using BatchFileDoneFn = std::function<void(const BatchFileResult& result, int done, int total)>;

// Runs `steps` on every item: reads it, skips it when options.manifest says its output is up to
// date, checks the pipeline against it (core::ValidatePipeline),
// calls client.Process() (retrying the whole file on UNAVAILABLE, and on RESOURCE_EXHAUSTED when
// the server sent a retry hint), and writes the output atomically. A file that fails never
// stops the others and never leaves a partial output.
// Thread-safe use of `client` only; blocks until every file is done.
BatchSummary RunBatch(const Client& client, std::span<const BatchItem> items,
                      std::span<const core::PipelineStep> steps, const BatchOptions& options,
                      const BatchFileDoneFn& on_done = {});

// The summary as a JSON document (README: "batch summary"):
// {"files": 3, "succeeded": 2, "done": 1, "skipped": 1, "failed": 1, "seconds": 1.25,
//  "shard": "0/4", "pipeline": "sha256:...", "results": [{"input": "a.bvh",
//  "output": "out/a.json", "status": "ok", "attempts": 1, "seconds": 0.4, "keys": 310,
//  "max_error": 0.49, "max_joint_error": 0.98}, {"input": "c.bvh", "output": "out/c.json",
//  "status": "skipped", ...}, {"input": "b.bvh", "status": "failed", "code": "INVALID_ARGUMENT",
//  "error": "b.bvh:3:1: ...", "attempts": 0, "seconds": 0.01}, ...]}
// "succeeded" = done + skipped (every output is right); "shard" only for a sharded run,
// "pipeline" only when known; a merge (batch_summary.h) has "shards": N and
// "missing_shards": ["1/4", ...] instead of "shard".
std::string FormatBatchSummaryJson(const BatchSummary& summary);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_BATCH_H_
