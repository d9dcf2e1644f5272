#include "client/batch_manifest.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <set>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/clip_files.h"
#include "client/json_members.h"
#include "client/test_hook.h"
#include "google/protobuf/io/coded_stream.h"
#include "google/protobuf/io/zero_copy_stream_impl_lite.h"
#include "proto/clip_digest.h"
#include "proto/operations_convert.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using core::AsAbsl;
using core::JsonValue;

constexpr std::string_view kManifestFormat = "tempokey.batch_manifest";
constexpr int kManifestVersion = 1;
constexpr std::int64_t kMaxManifestBytes = std::int64_t{256} << 20;
// A save may take at most this share of the time between saves (see SaveWhenDue()).
constexpr int kSaveCostFactor = 10;
// The journal beside a manifest (".tempokey-batch.journal"): records of outputs written over
// their own inputs, a line each, appended and fsynced as each is written.
constexpr std::string_view kJournalSuffix = ".journal";

// The bytes of `message` in deterministic serialization, length-prefixed.
void AppendOperation(std::string& out, const v1::Operation& operation) {
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    operation.SerializeToCodedStream(&coded);
  }
  absl::StrAppend(&out, bytes.size(), ":", bytes);
}

using Place = JsonPlace;

absl::StatusOr<std::string> StringMember(const Place& place, const JsonValue& object,
                                         std::string_view name) {
  TEMPOKEY_ASSIGN_OR_RETURN(const JsonValue* value,
                            JsonMember(place, object, name, JsonValue::Type::kString, true));
  return value->text;
}

absl::StatusOr<ManifestRecord> ParseRecord(const Place& place, const std::string& output,
                                           const JsonValue& value) {
  if (value.type != JsonValue::Type::kObject) {
    return place.Fail(value, "an output's record must be an object");
  }
  ManifestRecord record;
  record.output = output;
  TEMPOKEY_ASSIGN_OR_RETURN(record.input, StringMember(place, value, "input"));
  TEMPOKEY_ASSIGN_OR_RETURN(record.input_id, StringMember(place, value, "input_id"));
  TEMPOKEY_ASSIGN_OR_RETURN(record.pipeline, StringMember(place, value, "pipeline"));
  TEMPOKEY_ASSIGN_OR_RETURN(record.output_id, StringMember(place, value, "output_id"));
  TEMPOKEY_ASSIGN_OR_RETURN(record.output_bytes, JsonCount(place, value, "output_bytes"));
  TEMPOKEY_ASSIGN_OR_RETURN(record.frames, JsonCount(place, value, "frames"));
  TEMPOKEY_ASSIGN_OR_RETURN(record.keys, JsonCount(place, value, "keys"));
  TEMPOKEY_ASSIGN_OR_RETURN(record.max_error, JsonNonNegative(place, value, "max_error"));
  return record;
}

// The size and id of the file at `path` as it is now.
absl::StatusOr<std::pair<std::int64_t, std::string>> FileIdentity(const std::string& path) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::string bytes, core::ReadFile(path));
  return std::make_pair(static_cast<std::int64_t>(bytes.size()), wire::Sha256Id(bytes));
}

// Takes an exclusive flock on the file at `path` (created if missing). Returns its descriptor,
// or -1 when the file system has no locks (ENOLCK, EOPNOTSUPP, ENOSYS). A holder removes the
// file before it lets go (so no lock file stays behind), hence the check that the locked file is
// still the one so named: a process that opened it just before the removal locks a file nobody
// else will, and retries. (On NFS that check may read a cached name: locking there needs the
// server's locks, README "Batches".)
absl::StatusOr<int> LockFile(const std::string& path, std::string_view manifest_name) {
  for (int attempt = 0;; ++attempt) {
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0666);
    if (fd < 0 && errno == ENOENT && attempt < 3) {
      // The folder was just removed by a run that created it and did nothing (see ~BatchManifest).
      std::error_code ignored;
      fs::create_directories(fs::path(path).parent_path(), ignored);
      continue;
    }
    if (fd < 0) {
      return absl::UnavailableError(
          absl::StrCat(path, ": cannot create the lock file: ", std::strerror(errno)));
    }
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      ::close(fd);
      if (error == EINTR) continue;
      if (error == EWOULDBLOCK) {
        return absl::FailedPreconditionError(absl::StrCat(
            path, ": another tempokey batch is running with this manifest (",
            AsAbsl(manifest_name), "); wait for it to end, or give this run another -o or --shard"));
      }
      if (error == ENOLCK || error == EOPNOTSUPP || error == ENOSYS) {
        return -1;  // no locks here: unlocked, as before locks existed (the command warns)
      }
      // ESTALE, EIO...: two runs might each think they hold it; better none runs.
      return absl::UnavailableError(
          absl::StrCat(path, ": cannot lock: ", std::strerror(error)));
    }
    struct stat held {};
    struct stat named {};
    if (::fstat(fd, &held) == 0 && ::stat(path.c_str(), &named) == 0 &&
        held.st_dev == named.st_dev && held.st_ino == named.st_ino) {
      return fd;
    }
    ::close(fd);
  }
}

// The file an in-place output replaces: its path, links followed as WriteFileAtomically()
// follows them (another user's link in a shared sticky folder refused).
absl::StatusOr<fs::path> ReplacedPath(const BatchItem& item) {
  TEMPOKEY_ASSIGN_OR_RETURN(std::string resolved, core::FollowLinks(item.output_path));
  return fs::path(std::move(resolved));
}

// TEMPOKEY_TEST_BATCH_KILL_AFTER_REPLACE (see ReplaceInPlace()): 0 when unset.
long KillAfterReplaceForTesting() {
  static const long n = TestHookCount("TEMPOKEY_TEST_BATCH_KILL_AFTER_REPLACE");
  return n;
}

}  // namespace

std::string PipelineDigest(std::span<const core::PipelineStep> steps,
                           std::optional<FileFormat> format) {
  std::string canonical = "tempokey.pipeline.v1\n";
  absl::StrAppend(&canonical, format ? AsAbsl(ExtensionOf(*format)) : "auto", "\n",
                  steps.size(), "\n");
  for (const core::PipelineStep& step : steps) {
    AppendOperation(canonical, wire::PipelineStepToProto(step));
  }
  return wire::Sha256Id(canonical);
}

std::string ManifestFileName(const std::optional<BatchShard>& shard) {
  if (!shard) return absl::StrCat(AsAbsl(kManifestPrefix), ".json");
  return absl::StrCat(AsAbsl(kManifestPrefix), ".shard-", shard->index, "-of-", shard->count,
                      ".json");
}

absl::StatusOr<std::vector<ManifestRecord>> ParseManifest(std::string_view text,
                                                          std::string_view source) {
  TEMPOKEY_ASSIGN_OR_RETURN(JsonValue root, core::ParseJson(text, source));
  const Place place(source);
  if (root.type != JsonValue::Type::kObject) return place.Fail(root, "expected an object");
  const JsonValue* format = root.Find("format");
  const JsonValue* version = root.Find("version");
  if (format == nullptr || format->text != kManifestFormat) {
    return place.Fail(format ? *format : root,
                      absl::StrCat("not a batch manifest (\"format\" must be \"",
                                   AsAbsl(kManifestFormat), "\")"));
  }
  if (version == nullptr || version->type != JsonValue::Type::kNumber ||
      version->number != kManifestVersion) {
    return place.Fail(version ? *version : root,
                      absl::StrCat("unsupported manifest version (this tempokey reads ",
                                   kManifestVersion, ")"));
  }
  const JsonValue* outputs = root.Find("outputs");
  if (outputs == nullptr || outputs->type != JsonValue::Type::kObject) {
    return place.Fail(outputs ? *outputs : root, "\"outputs\" must be an object");
  }
  std::vector<ManifestRecord> records;
  std::set<std::string> seen;
  for (const auto& [output, value] : *outputs->object) {
    if (!seen.insert(output).second) {
      return place.Fail(value, absl::StrCat("output \"", output, "\" is listed twice"));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(ManifestRecord record, ParseRecord(place, output, value));
    records.push_back(std::move(record));
  }
  return records;
}

// A record's members (input, input_id, pipeline, output_bytes, output_id, frames, keys,
// max_error), without braces.
void AppendRecordFields(std::string& out, const ManifestRecord& r) {
  out += "\"input\": ";
  core::AppendJsonString(out, r.input);
  out += ", \"input_id\": ";
  core::AppendJsonString(out, r.input_id);
  out += ", \"pipeline\": ";
  core::AppendJsonString(out, r.pipeline);
  absl::StrAppend(&out, ", \"output_bytes\": ", r.output_bytes, ", \"output_id\": ");
  core::AppendJsonString(out, r.output_id);
  if (r.frames > 0) absl::StrAppend(&out, ", \"frames\": ", r.frames);
  if (r.keys > 0) absl::StrAppend(&out, ", \"keys\": ", r.keys);
  if (r.max_error) absl::StrAppend(&out, ", \"max_error\": ", core::FormatDouble(*r.max_error));
}

// One journal line: {"output": ..., <the record's members>}.
std::string FormatJournalLine(const ManifestRecord& r) {
  std::string out = "{\"output\": ";
  core::AppendJsonString(out, r.output);
  out += ", ";
  AppendRecordFields(out, r);
  out += "}\n";
  return out;
}

// The records of a journal's lines. A line that does not parse (a write cut short by a kill or
// a full disk; an empty line) is left out: it costs at most that file being done again.
std::vector<ManifestRecord> ParseJournal(std::string_view text, std::string_view source) {
  std::vector<ManifestRecord> records;
  const Place place(source);
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    absl::StatusOr<JsonValue> line = core::ParseJson(text.substr(start, end - start), source);
    if (line.ok()) {
      absl::StatusOr<const JsonValue*> output =
          JsonMember(place, *line, "output", JsonValue::Type::kString, true);
      if (output.ok()) {
        absl::StatusOr<ManifestRecord> record = ParseRecord(place, (*output)->text, *line);
        if (record.ok()) records.push_back(*std::move(record));
      }
    }
    start = end + 1;
  }
  return records;
}

std::string FormatManifest(const std::vector<ManifestRecord>& records,
                           const std::optional<BatchShard>& shard) {
  std::vector<const ManifestRecord*> sorted;
  for (const ManifestRecord& record : records) sorted.push_back(&record);
  std::sort(sorted.begin(), sorted.end(),
            [](const ManifestRecord* a, const ManifestRecord* b) { return a->output < b->output; });
  std::string out = absl::StrCat("{\"format\": \"", AsAbsl(kManifestFormat),
                                 "\", \"version\": ", kManifestVersion);
  if (shard) absl::StrAppend(&out, ", \"shard\": \"", shard->Name(), "\"");
  out += ", \"outputs\": {";
  for (std::size_t i = 0; i < sorted.size(); ++i) {
    const ManifestRecord& r = *sorted[i];
    out += i == 0 ? "\n  " : ",\n  ";
    core::AppendJsonString(out, r.output);
    out += ": {";
    AppendRecordFields(out, r);
    out += '}';
  }
  out += sorted.empty() ? "}}\n" : "\n}}\n";
  return out;
}

absl::StatusOr<std::unique_ptr<BatchManifest>> BatchManifest::Open(
    const std::string& output_dir, const std::optional<BatchShard>& shard, bool force) {
  const std::string own_name = ManifestFileName(shard);
  auto manifest = std::unique_ptr<BatchManifest>(
      new BatchManifest(output_dir, (fs::path(output_dir) / own_name).string(), shard));
  // Locked before anything is read: a run that read the manifests while another still wrote
  // them could miss a record of an output written over its input, and process it again.
  std::error_code made;
  manifest->created_output_dir_ = fs::create_directories(output_dir, made);
  TEMPOKEY_ASSIGN_OR_RETURN(manifest->lock_fd_, LockFile(manifest->lock_path_, own_name));
  manifest->saver_ =
      std::jthread([m = manifest.get()](std::stop_token stop) { m->SaveWhenDue(stop); });
  if (force) return manifest;
  std::error_code error;
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(output_dir, error)) {
    const std::string name = entry.path().filename().string();
    if (name.starts_with(kManifestPrefix) &&
        (name.ends_with(".json") || name.ends_with(kJournalSuffix)) &&
        entry.is_regular_file(error)) {
      files.push_back(entry.path());
    }
  }
  // Manifests first, then journals, whose records are newer.
  std::sort(files.begin(), files.end(), [](const fs::path& a, const fs::path& b) {
    const bool a_journal = a.string().ends_with(kJournalSuffix);
    const bool b_journal = b.string().ends_with(kJournalSuffix);
    return a_journal != b_journal ? b_journal : a < b;
  });
  for (const fs::path& file : files) {
    TEMPOKEY_ASSIGN_OR_RETURN(std::string text, core::ReadFile(file.string(), kMaxManifestBytes));
    const bool journal = file.string().ends_with(kJournalSuffix);
    absl::StatusOr<std::vector<ManifestRecord>> records =
        journal ? absl::StatusOr<std::vector<ManifestRecord>>(ParseJournal(text, file.string()))
                : ParseManifest(text, file.string());
    if (!records.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(
          records.status().message(), "; remove the file or run with --force"));
    }
    const bool own = file.filename() == own_name || file.string() == manifest->journal_path_;
    std::lock_guard<std::mutex> lock(manifest->mutex_);
    for (ManifestRecord& record : *records) {
      if (own) manifest->own_[record.output] = record;
      manifest->known_.emplace(record.output, std::move(record));
    }
  }
  return manifest;
}

BatchManifest::~BatchManifest() {
  saver_.request_stop();
  changed_.notify_all();
  if (saver_.joinable()) saver_.join();
  if (lock_fd_ >= 0) {
    // Removed while held (see LockFile()).
    ::unlink(lock_path_.c_str());
    ::close(lock_fd_);
  }
  // A folder this run created and left empty (a usage error after Open(), every file failed)
  // goes again, as it did before the lock needed it; remove() takes only an empty folder.
  std::error_code ignored;
  if (created_output_dir_) fs::remove(output_dir_, ignored);
}

int BatchManifest::RemoveLeftoverTemporaries(std::span<const BatchItem> items) {
  if (lock_fd_ < 0) return 0;  // another run of this manifest may be writing them
  // Targets by folder, so each folder is listed once; with this manifest's staging files, by their
  // exact names (another manifest's differ), beside the file each replaces (a link's target may
  // be in another folder), and their temporaries.
  // A target is listed by what its temporaries' names start with: its name, cut short for a long
  // one (core::AtomicWriteTemporaryStem()).
  std::map<fs::path, std::set<std::string>> targets;
  std::set<fs::path> staged;
  auto add_target = [&](const fs::path& file) {
    targets[file.parent_path()].insert(
        std::string(core::AtomicWriteTemporaryStem(file.filename().string())));
  };
  add_target(fs::path(path_));
  for (const BatchItem& item : items) {
    add_target(fs::path(item.output_path));
    const absl::StatusOr<std::string> path = StagingPath(item);
    if (!path.ok()) continue;
    staged.insert(*path);
    add_target(fs::path(*path));
  }
  int removed = 0;
  for (const auto& [folder, names] : targets) {
    std::error_code error;
    std::vector<fs::path> leftovers;
    for (const auto& entry : fs::directory_iterator(folder.empty() ? "." : folder, error)) {
      const std::string name = entry.path().filename().string();
      const std::size_t mark = name.rfind(".tmp-");
      if (staged.count(entry.path()) > 0 ||
          (mark != std::string::npos && names.count(name.substr(0, mark)) > 0 &&
           core::IsAtomicWriteTemporary(name, name.substr(0, mark)))) {
        leftovers.push_back(entry.path());
      }
    }
    for (const fs::path& leftover : leftovers) removed += fs::remove(leftover, error) ? 1 : 0;
  }
  return removed;
}

absl::StatusOr<std::string> BatchManifest::StagingPath(const BatchItem& item) const {
  TEMPOKEY_ASSIGN_OR_RETURN(const fs::path output, ReplacedPath(item));
  // The manifest's own path in the name: two manifests replacing files in one folder (`DIR -r`
  // and `DIR/sub`, in place) never share a staging file.
  const std::string digest = wire::Sha256Id(absl::StrCat(stem_, "\n", output.string()));
  const std::string hex = digest.substr(digest.find(':') + 1, 16);
  return (output.parent_path() /
          absl::StrCat(fs::path(stem_).filename().string(), ".staged-", hex))
      .string();
}

bool BatchManifest::IsRecordedOutput(const std::string& path) const {
  std::error_code error;
  const fs::path file = fs::absolute(path, error).lexically_normal();
  const fs::path folder = fs::absolute(output_dir_, error).lexically_normal();
  const std::string key = file.lexically_relative(folder).generic_string();
  return !key.empty() && !key.starts_with("..") && known_.count(key) > 0;
}

std::string BatchManifest::OutputKey(const BatchItem& item) const {
  return fs::path(item.output_path).lexically_relative(output_dir_).generic_string();
}

std::optional<ManifestRecord> BatchManifest::FindUpToDate(const BatchItem& item,
                                                          std::string_view input_id,
                                                          std::string_view pipeline) const {
  const auto [first, last] = known_.equal_range(OutputKey(item));
  std::optional<std::pair<std::int64_t, std::string>> on_disk;  // read once, when needed
  // An output written over its own input (--overwrite) is the next run's input: its record's
  // input id is the clip it was made from, and the file now holding the recorded output says
  // the file is done.
  const bool in_place = first != last && IsSameFile(item.input_path, item.output_path);
  for (auto it = first; it != last; ++it) {
    const ManifestRecord& record = it->second;
    if (record.input != item.name || (!in_place && record.input_id != input_id) ||
        record.pipeline != pipeline) {
      continue;
    }
    if (!on_disk) {
      std::error_code error;
      const auto size = fs::file_size(item.output_path, error);
      if (error || static_cast<std::int64_t>(size) != record.output_bytes) continue;
      absl::StatusOr<std::pair<std::int64_t, std::string>> identity =
          FileIdentity(item.output_path);
      if (!identity.ok()) return std::nullopt;
      on_disk = *std::move(identity);
    }
    if (on_disk->first == record.output_bytes && on_disk->second == record.output_id) {
      return record;
    }
  }
  return std::nullopt;
}

void BatchManifest::Keep(const ManifestRecord& record) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (auto it = own_.find(record.output); it != own_.end() && it->second == record) return;
    own_[record.output] = record;
    ++version_;
  }
  Changed();
}

absl::Status BatchManifest::RecordWritten(const BatchItem& item, std::string_view input_id,
                                          std::string_view pipeline,
                                          const BatchFileResult& file) {
  // Not recorded: an output that is no regular file (a FIFO, /dev/null: nothing to read back
  // and compare on a re-run), or a name that is not UTF-8 (JSON would record it with U+FFFD:
  // it could never match again, and two such names would collide).
  std::error_code error;
  if (!fs::is_regular_file(item.output_path, error) || !core::IsUtf8(item.name) ||
      !core::IsUtf8(OutputKey(item))) {
    Forget(item);
    return absl::OkStatus();
  }
  absl::StatusOr<ManifestRecord> made =
      MakeRecord(item, item.output_path, input_id, pipeline, file);
  if (!made.ok()) {
    Forget(item);
    return made.status();
  }
  ManifestRecord record = *std::move(made);
  const bool in_place = IsSameFile(item.input_path, item.output_path);
  // The input is gone: until this record is on disk, a re-run could not tell the output from a
  // clip to process again. Appended to the journal at once (a line, not the whole manifest).
  const absl::Status journaled =
      in_place ? AppendToJournal(FormatJournalLine(record)) : absl::OkStatus();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    own_[record.output] = std::move(record);
    ++version_;
  }
  if (!journaled.ok()) {
    // Then the whole manifest, now; only if that fails too does the file fail (and a re-run
    // may process its output again).
    std::lock_guard<std::mutex> save_lock(save_mutex_);
    if (absl::Status saved = Save(); !saved.ok()) {
      return absl::Status(saved.code(), absl::StrCat(journaled.message(), "; ", saved.message()));
    }
  }
  Changed();
  return absl::OkStatus();
}

absl::StatusOr<ManifestRecord> BatchManifest::MakeRecord(const BatchItem& item,
                                                         const std::string& path,
                                                         std::string_view input_id,
                                                         std::string_view pipeline,
                                                         const BatchFileResult& file) const {
  TEMPOKEY_ASSIGN_OR_RETURN(auto identity, FileIdentity(path));
  return ManifestRecord{
      .output = OutputKey(item),
      .input = item.name,
      .input_id = std::string(input_id),
      .pipeline = std::string(pipeline),
      .output_bytes = identity.first,
      .output_id = identity.second,
      .frames = file.frames,
      .keys = file.keys,
      .max_error = file.max_error,
  };
}

absl::Status BatchManifest::ReplaceInPlace(const BatchItem& item, const std::string& staged_path,
                                           std::string_view input_id, std::string_view pipeline,
                                           const BatchFileResult& file) {
  auto fail = [&](absl::Status status) {
    std::error_code ignored;
    fs::remove(staged_path, ignored);
    Forget(item);
    return status;
  };
  // A name JSON cannot hold is not recorded (see RecordWritten()); the command refuses such a
  // name in place, so this only keeps the engine whole.
  const bool recordable = core::IsUtf8(item.name) && core::IsUtf8(OutputKey(item));
  if (recordable) {
    absl::StatusOr<ManifestRecord> made = MakeRecord(item, staged_path, input_id, pipeline, file);
    if (!made.ok()) return fail(made.status());
    const absl::Status journaled = AppendToJournal(FormatJournalLine(*made));
    {
      std::lock_guard<std::mutex> lock(mutex_);
      own_[made->output] = *std::move(made);
      ++version_;
    }
    if (!journaled.ok()) {
      // Then the whole manifest, now; if that fails too, the input stays as it is.
      std::lock_guard<std::mutex> save_lock(save_mutex_);
      if (absl::Status saved = Save(); !saved.ok()) {
        return fail(absl::Status(saved.code(),
                                 absl::StrCat(journaled.message(), "; ", saved.message())));
      }
    }
  }
  const absl::StatusOr<fs::path> resolved = ReplacedPath(item);
  if (!resolved.ok()) return fail(resolved.status());
  const fs::path& replaced = *resolved;
  // The output keeps the input's permission bits, as WriteFileAtomically() keeps them.
  if (struct stat input {}; ::stat(replaced.c_str(), &input) == 0 && S_ISREG(input.st_mode)) {
    ::chmod(staged_path.c_str(), input.st_mode & 07777);
  }
  if (::rename(staged_path.c_str(), replaced.c_str()) != 0) {
    return fail(absl::UnavailableError(absl::StrCat(
        item.output_path, ": cannot replace the file: ", std::strerror(errno))));
  }
  // The rename made durable, as WriteFileAtomically() does (a file system refusing it is fine).
  if (const int dir_fd = ::open(replaced.parent_path().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
      dir_fd >= 0) {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
  static std::atomic<long> replaces{0};
  if (const long n = KillAfterReplaceForTesting(); n > 0 && ++replaces == n) ::raise(SIGKILL);
  if (!recordable) Forget(item);
  Changed();
  return absl::OkStatus();
}

absl::Status BatchManifest::AppendToJournal(const std::string& line) {
  std::lock_guard<std::mutex> lock(journal_mutex_);
  const bool existed = ::access(journal_path_.c_str(), F_OK) == 0;
  const int fd = ::open(journal_path_.c_str(), O_RDWR | O_APPEND | O_CREAT | O_CLOEXEC, 0666);
  if (fd < 0) {
    return absl::UnavailableError(
        absl::StrCat(journal_path_, ": cannot open: ", std::strerror(errno)));
  }
  // A new journal's name made durable too: a power cut could keep a rename over an input (in
  // another folder) and lose the journal's entry, and the output would be taken as an input.
  if (!existed) {
    if (const int dir_fd = ::open(fs::path(journal_path_).parent_path().c_str(),
                                  O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        dir_fd >= 0) {
      ::fsync(dir_fd);
      ::close(dir_fd);
    }
  }
  // A line a kill cut short is ended first, so this record starts a line of its own.
  const off_t size = ::lseek(fd, 0, SEEK_END);
  char last = '\n';
  const std::string text =
      size > 0 && ::pread(fd, &last, 1, size - 1) == 1 && last != '\n' ? "\n" + line : line;
  std::size_t written = 0;
  while (written < text.size()) {
    const ssize_t n = ::write(fd, text.data() + written, text.size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    written += static_cast<std::size_t>(n);
  }
  const bool synced = written == text.size() && ::fsync(fd) == 0;
  // A short write (a full disk) is taken back, so the next record is not glued onto it.
  if (!synced && size >= 0 && ::ftruncate(fd, size) != 0) {
    // The torn line is left; the reader skips it.
  }
  ::close(fd);
  if (!synced) {
    return absl::UnavailableError(absl::StrCat(journal_path_, ": cannot write the record"));
  }
  return absl::OkStatus();
}

void BatchManifest::Forget(const BatchItem& item) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (own_.erase(OutputKey(item)) == 0) return;
    ++version_;
  }
  Changed();
}

absl::Status BatchManifest::Finish(std::span<const BatchItem> items) {
  std::set<std::string> planned;
  for (const BatchItem& item : items) planned.insert(OutputKey(item));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const std::size_t erased = std::erase_if(
        own_, [&](const auto& entry) { return planned.count(entry.first) == 0; });
    if (erased > 0) ++version_;
  }
  saver_.request_stop();
  changed_.notify_all();
  if (saver_.joinable()) saver_.join();
  std::lock_guard<std::mutex> save_lock(save_mutex_);
  absl::Status saved = Save();
  if (saved.ok() && first_save_error_.ok()) {
    // The journal's records are in the manifest now.
    std::error_code ignored;
    fs::remove(journal_path_, ignored);
  }
  return first_save_error_.ok() ? saved : first_save_error_;
}

void BatchManifest::Changed() { changed_.notify_all(); }

void BatchManifest::SaveWhenDue(std::stop_token stop) {
  while (!stop.stop_requested()) {
    Clock::duration pause{};
    {
      std::lock_guard<std::mutex> save_lock(save_mutex_);
      pause = kSaveCostFactor * last_save_cost_;
    }
    {
      // Sleeps `pause` (interruptible by stop), then waits for a change not saved yet.
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait_for(lock, stop, pause, [] { return false; });
      const bool changed = changed_.wait(lock, stop, [this] { return version_ != saved_version_; });
      if (!changed) return;
    }
    std::lock_guard<std::mutex> save_lock(save_mutex_);
    (void)Save();
  }
}

absl::Status BatchManifest::Save() {
  std::vector<ManifestRecord> records;
  std::uint64_t version = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    version = version_;
    if (saved_once_ && version == saved_version_) return absl::OkStatus();
    records.reserve(own_.size());
    for (const auto& [output, record] : own_) records.push_back(record);
  }
  const Clock::time_point start = Clock::now();
  saved_once_ = true;
  // A run that recorded nothing leaves no manifest behind (but empties one it had).
  std::error_code missing;
  if (!records.empty() || fs::exists(path_, missing)) {
    absl::Status written = core::WriteFileAtomically(path_, FormatManifest(records, shard_));
    last_save_cost_ = Clock::now() - start;
    if (!written.ok()) {
      if (first_save_error_.ok()) first_save_error_ = written;
      return written;
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  saved_version_ = version;
  return absl::OkStatus();
}

}  // namespace tempokey::client
