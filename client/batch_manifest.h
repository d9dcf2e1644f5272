// The resume record of `tempokey batch`: a manifest next to the outputs saying, per output, which
// input content and which pipeline made it, so a re-run skips what is still right and redoes the
// rest (an input that changed, a pipeline that changed, an output missing or altered).
//
// File: OUTDIR/.tempokey-batch.json, or OUTDIR/.tempokey-batch.shard-I-of-N.json for --shard I/N,
// one per shard so concurrent shards never write the same file (no locking, which network file
// systems do not all honour). A run reads every .tempokey-batch*.json of OUTDIR, so records made
// by an earlier run with other shards still count. Written atomically (core::WriteFileAtomically),
// rewritten as files finish: a kill at any moment leaves the previous or the next version.
//
//   {"format": "tempokey.batch_manifest", "version": 1, "shard": "1/4", "outputs": {
//     "walk.json": {"input": "walk.bvh", "input_id": "sha256:...", "pipeline": "sha256:...",
//                   "output_bytes": 18231, "output_id": "sha256:...", "keys": 310,
//                   "max_error": 0.49}}}
//
// input_id is the clip's content id, the one the server gives an upload (proto/clip_digest.h):
// the same motion read from a re-saved file keeps it. pipeline is PipelineDigest(). output_id is
// the SHA-256 of the output file's bytes.
#ifndef TEMPOKEY_CLIENT_BATCH_MANIFEST_H_
#define TEMPOKEY_CLIENT_BATCH_MANIFEST_H_

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "client/batch.h"
#include "client/batch_shard.h"
#include "client/clip_files.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::client {

inline constexpr std::string_view kManifestPrefix = ".tempokey-batch";

// What one output was made from.
struct ManifestRecord {
  std::string output{};      // path relative to the output folder, '/' separators (the key)
  std::string input{};       // BatchItem::name
  std::string input_id{};    // "sha256:..." content id of the input clip
  std::string pipeline{};    // PipelineDigest() of the steps the file ran
  std::int64_t output_bytes = 0;
  std::string output_id{};   // "sha256:..." of the output file's bytes
  std::int64_t frames = 0;   // as BatchFileResult, for the summary of a skipped file
  std::int64_t keys = 0;
  std::optional<double> max_error{};

  bool operator==(const ManifestRecord&) const = default;
};

// "sha256:<hex>" of the canonical form of a pipeline as one file runs it: the tag
// "tempokey.pipeline.v1", the output format's extension ("auto" for nullopt: a run's outputs
// in their inputs' own formats, as a summary records it), then each step as its tempokey.v1
// Operation (what PipelineStepToProto() sends) in deterministic protobuf serialization,
// length-prefixed. The same options spelled differently in a pipeline file give the same
// digest; any change of a value, a step or the format changes it. A new tempokey whose
// defaults changed is not detected: run with --force after upgrading if that matters.
// Thread-safe: a pure function.
std::string PipelineDigest(std::span<const core::PipelineStep> steps,
                           std::optional<FileFormat> format);

// ".tempokey-batch.json", or ".tempokey-batch.shard-2-of-4.json" for shard 2/4.
std::string ManifestFileName(const std::optional<BatchShard>& shard);

// Parses a manifest document; `source` names it in messages.
// Errors: kInvalidArgument "<source>:<line>:<column>: <what>" for a document that is not a
// version 1 manifest.
absl::StatusOr<std::vector<ManifestRecord>> ParseManifest(std::string_view text,
                                                          std::string_view source);

// The manifest document of `records` (sorted by output), ending with a newline.
std::string FormatManifest(const std::vector<ManifestRecord>& records,
                           const std::optional<BatchShard>& shard);

// Removes what an interrupted run of the same files left behind: the temporaries of atomic
// writes ("<file>.tmp-xxxxxxxx") beside each item's output and beside `manifest_path`. Only
// those names are touched. Returns how many were removed.
int RemoveLeftoverTemporaries(std::span<const BatchItem> items, const std::string& manifest_path);

// One run's view of the manifests of an output folder. Changes are saved by a thread of its own
// soon after they happen: at once, unless rewriting the file takes more than a tenth of the time
// since the last save (large manifests then save less often, so their I/O stays under 10% of
// the run); a worker stalled elsewhere never holds a record back. Thread-safe: every method may
// be called from the batch's worker threads.
class BatchManifest {
 public:
  // Reads the manifests of `output_dir` (every .tempokey-batch*.json in it) unless `force`, and
  // starts this run's own file with the records of its previous version.
  // Errors: kInvalidArgument for a manifest that does not parse ("OUTDIR/.tempokey-batch.json:
  // 3:5: ...; remove it or run with --force"), read errors of the files.
  static absl::StatusOr<std::unique_ptr<BatchManifest>> Open(const std::string& output_dir,
                                                             const std::optional<BatchShard>& shard,
                                                             bool force);

  ~BatchManifest();
  BatchManifest(const BatchManifest&) = delete;
  BatchManifest& operator=(const BatchManifest&) = delete;

  const std::string& path() const { return path_; }

  // Whether `path` is an output some manifest of OUTDIR records (read at Open()): with OUTDIR
  // inside DIR, last run's outputs are not this run's inputs.
  bool IsRecordedOutput(const std::string& path) const;

  // The record that lets `item` be skipped: one of any manifest for its output with this input
  // id and pipeline, whose output file exists with the recorded size and content (it is read
  // and hashed). An output that is its own input (--overwrite) needs no input id: the file
  // holding the recorded output is done. nullopt when there is none, or always after
  // Open(..., force = true).
  std::optional<ManifestRecord> FindUpToDate(const BatchItem& item, std::string_view input_id,
                                             std::string_view pipeline) const;

  // Puts `record` in this run's file (a skipped output keeps its record, wherever it was).
  void Keep(const ManifestRecord& record);

  // Records `item`'s output as just written by `file` from input `input_id` through
  // `pipeline`: reads the output back for its size and digest. An output written over its own
  // input is also appended to the journal at once (its input is gone; a run killed between the
  // write and this line, a few milliseconds, redoes the file from its output on the next run).
  // Not recorded: an output that is no regular file (a FIFO, /dev/null) or whose name is not
  // UTF-8 (JSON cannot hold it). Errors: read errors of the output (the record is then dropped,
  // so a re-run redoes the file); the journal's write error.
  absl::Status RecordWritten(const BatchItem& item, std::string_view input_id,
                             std::string_view pipeline, const BatchFileResult& file);

  // Drops this run's record of `item`'s output (the file failed: whatever output is there was
  // made from another input or pipeline).
  void Forget(const BatchItem& item);

  // Drops this run's records of outputs that are not in `items` (inputs removed since), stops
  // the saving thread and saves. Call once when every item was tried; no change after it.
  // Errors: the first save error of the run, if any (the outputs are fine; a re-run redoes the
  // files whose records were not saved).
  absl::Status Finish(std::span<const BatchItem> items);

 private:
  BatchManifest(std::string output_dir, std::string path, std::optional<BatchShard> shard)
      : output_dir_(std::move(output_dir)),
        path_(std::move(path)),
        journal_path_(path_.substr(0, path_.size() - std::string_view(".json").size()) +
                      ".journal"),
        shard_(std::move(shard)) {}

  std::string OutputKey(const BatchItem& item) const;
  // Tells the saving thread that own_ changed. Called without mutex_ held.
  void Changed();
  // The saving thread: saves each change once due, until `stop`.
  void SaveWhenDue(std::stop_token stop);
  // Writes own_ to path_ (atomically) unless that version is already saved.
  absl::Status Save();
  // Appends `line` to journal_path_ and fsyncs it.
  absl::Status AppendToJournal(const std::string& line);

  const std::string output_dir_;
  const std::string path_;
  // Records of outputs written over their own inputs, a line each as they are written (a save
  // of the whole manifest per file cost the square of the files); read back by Open(), removed
  // by Finish() once the manifest holds them.
  const std::string journal_path_;
  std::mutex journal_mutex_;
  const std::optional<BatchShard> shard_;
  // Records of every manifest read at Open(), by output key (several when manifests overlap).
  std::multimap<std::string, ManifestRecord> known_;

  mutable std::mutex mutex_;
  std::condition_variable_any changed_;
  std::map<std::string, ManifestRecord> own_ ABSL_GUARDED_BY(mutex_);
  std::uint64_t version_ ABSL_GUARDED_BY(mutex_) = 0;  // bumped by every change of own_
  std::uint64_t saved_version_ ABSL_GUARDED_BY(mutex_) = 0;

  std::mutex save_mutex_;  // one save at a time; taken before mutex_
  bool saved_once_ ABSL_GUARDED_BY(save_mutex_) = false;
  std::chrono::steady_clock::duration last_save_cost_ ABSL_GUARDED_BY(save_mutex_){};
  absl::Status first_save_error_ ABSL_GUARDED_BY(save_mutex_);

  std::jthread saver_;  // last: stops (and joins) first
};

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_BATCH_MANIFEST_H_
