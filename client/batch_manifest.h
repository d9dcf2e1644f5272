// The resume record of `tempokey batch`: a manifest next to the outputs saying, per output, which
// input content and which pipeline made it, so a re-run skips what is still right and redoes the
// rest (an input that changed, a pipeline that changed, an output missing or altered).
//
// File: OUTDIR/.tempokey-batch.json, or OUTDIR/.tempokey-batch.shard-I-of-N.json for --shard I/N,
// one per shard so concurrent shards never write the same file. A run reads every
// .tempokey-batch*.json of OUTDIR, so records made by an earlier run with other shards still
// count. Written atomically (core::WriteFileAtomically), rewritten as files finish: a kill at any
// moment leaves the previous or the next version.
//
// One writer per manifest: a run holds an exclusive flock(2) on OUTDIR/<manifest stem>.lock
// (".tempokey-batch.lock", ".tempokey-batch.shard-I-of-N.lock") from Open() to its end, and a
// second run of the same manifest is refused at once. Only the holder removes the leftovers of
// earlier runs of that manifest. On a file system without locks (flock fails with other than
// EWOULDBLOCK) the run goes on unlocked and removes no leftovers.
//
// In place (--overwrite, an output replacing its own input) the record goes to the journal,
// durably, before the output replaces the input: the output is written whole to a staging file
// beside it (ReplaceInPlace()), its record appended, then the staging file renamed over the
// input. A run stopped at any point (SIGKILL, SIGTERM) leaves either the input untouched, which
// the next run redoes, or the output in place with its record, which the next run skips: an
// output is never processed again as an input.
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
  // Creates `output_dir` if missing and locks this run's manifest first (see above).
  // Errors: kFailedPrecondition "OUTDIR/.tempokey-batch.lock: another tempokey batch is running
  // with this manifest; ..." when another process holds the lock; kUnavailable when the lock
  // file cannot be created.
  static absl::StatusOr<std::unique_ptr<BatchManifest>> Open(const std::string& output_dir,
                                                             const std::optional<BatchShard>& shard,
                                                             bool force);

  ~BatchManifest();
  BatchManifest(const BatchManifest&) = delete;
  BatchManifest& operator=(const BatchManifest&) = delete;

  const std::string& path() const { return path_; }

  // Removes what an interrupted run of this manifest left behind: the temporaries of atomic
  // writes ("<file>.tmp-xxxxxxxx") beside each item's output and beside the manifest, and the
  // staging files of this manifest (StagingPath()) with their temporaries, in the items' output
  // folders. Nothing else is touched (another shard's files, another manifest's), and nothing at
  // all unless this run holds the manifest's lock. Returns how many files were removed.
  int RemoveLeftoverTemporaries(std::span<const BatchItem> items);
  // Whether this run holds the manifest's lock (false where the file system takes none).
  bool locked() const { return lock_fd_ >= 0; }

  // Where `item`'s output is written whole before ReplaceInPlace() puts it over its input: a
  // hidden file beside the file it replaces (a link's target, links followed as
  // core::FollowLinks()), "<manifest stem>.staged-<16 hex digits of this manifest's path and the
  // output's>" (never an input, and this manifest's alone, for RemoveLeftoverTemporaries()).
  // Errors: those of core::FollowLinks().
  absl::StatusOr<std::string> StagingPath(const BatchItem& item) const;

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
  // input is also appended to the journal at once; RunBatch() does not write such outputs
  // itself and calls ReplaceInPlace() instead, which journals before the input is replaced.
  // Not recorded: an output that is no regular file (a FIFO, /dev/null) or whose name is not
  // UTF-8 (JSON cannot hold it). Errors: read errors of the output (the record is then dropped,
  // so a re-run redoes the file); the journal's write error.
  absl::Status RecordWritten(const BatchItem& item, std::string_view input_id,
                             std::string_view pipeline, const BatchFileResult& file);

  // Puts the output staged at `staged_path` (StagingPath(item), written whole) over `item`'s
  // input, which is its output path (--overwrite): appends the output's record, as
  // RecordWritten() makes it, to the journal and fsyncs it (or, if that fails, saves the whole
  // manifest), and only then renames the staged file over the input. So a run stopped at any
  // point leaves the input untouched (the next run redoes it: the record's output id is not the
  // file's) or the output in place with its record (the next run skips it). Errors: read errors
  // of the staged file; the journal's and the manifest's write errors together (the input is
  // then untouched); the rename's error. On any error the staged file is removed and the record
  // dropped.
  // Test hook (tests/client): with TEMPOKEY_TEST_BATCH_KILL_AFTER_REPLACE=N in the environment,
  // the process kills itself (SIGKILL) right after the N-th rename of the process, as a crash
  // there would.
  absl::Status ReplaceInPlace(const BatchItem& item, const std::string& staged_path,
                              std::string_view input_id, std::string_view pipeline,
                              const BatchFileResult& file);

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
        stem_(path_.substr(0, path_.size() - std::string_view(".json").size())),
        journal_path_(stem_ + ".journal"),
        lock_path_(stem_ + ".lock"),
        shard_(std::move(shard)) {}

  std::string OutputKey(const BatchItem& item) const;
  // The record of `item`'s output whose bytes are at `path`.
  absl::StatusOr<ManifestRecord> MakeRecord(const BatchItem& item, const std::string& path,
                                            std::string_view input_id, std::string_view pipeline,
                                            const BatchFileResult& file) const;
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
  const std::string stem_;  // path_ without ".json"
  // Records of outputs written over their own inputs, a line each as they are written (a save
  // of the whole manifest per file cost the square of the files); read back by Open(), removed
  // by Finish() once the manifest holds them.
  const std::string journal_path_;
  std::mutex journal_mutex_;
  // The manifest's lock file and its descriptor, holding the flock; -1 when not locked (a file
  // system without locks). Removed, then closed, by the destructor.
  const std::string lock_path_;
  int lock_fd_ = -1;
  bool created_output_dir_ = false;  // Open() created output_dir_ (for the lock)
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
