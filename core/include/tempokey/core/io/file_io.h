// Whole-file reads with a size cap and atomic whole-file writes.
#ifndef TEMPOKEY_CORE_IO_FILE_IO_H_
#define TEMPOKEY_CORE_IO_FILE_IO_H_

#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tempokey::core {

// How long a pipe or FIFO may stay silent (no byte, no end) while ReadFile() reads it.
inline constexpr int kStreamIdleTimeoutMs = 10'000;

// Reads all of `path`: a regular file, or a pipe or FIFO read to its end (the cap applies to the
// bytes read). A FIFO is opened without waiting for a writer, and each read of it waits at most
// kStreamIdleTimeoutMs for data: one nobody writes to is refused, never read forever. Messages
// start with `path`.
// Errors: kNotFound missing file ("walk.bvh: no such file"); kInvalidArgument a directory
// ("walk.bvh: is a directory, not a file"), a device or socket ("/dev/zero: is a character
// device, not a file") or larger than `max_bytes` ("walk.bvh: file is 3000000000 bytes, over
// the limit of 1073741824"); kDeadlineExceeded a silent FIFO ("in.bvh: is a FIFO and nothing
// arrived for 10 s (no writer?)"); kPermissionDenied unreadable; others by their errno
// (FileErrorCode() in file_io.cc: kFailedPrecondition a name too long or a loop of links,
// kUnavailable what may pass if tried again, kDataLoss an I/O error, kUnknown the rest).
// Thread-safe.
absl::StatusOr<std::string> ReadFile(const std::string& path,
                                     std::int64_t max_bytes = std::int64_t{1} << 30);

// ReadFile() for text formats (BVH, CSV, JSON, PEM): also refuses, as soon as the chunk holding
// it arrives, a NUL byte, which no text file holds. So a large sparse or binary file costs one
// read chunk (64 KiB) of memory, not its size, before it is refused.
// Errors: those of ReadFile(); kInvalidArgument "big.bvh:1:1: unexpected byte 0x00; the file
// looks binary, not text" (line and column of the first NUL, counted from 1).
// Thread-safe.
absl::StatusOr<std::string> ReadTextFile(const std::string& path,
                                         std::int64_t max_bytes = std::int64_t{1} << 30);

// Writes `contents` to a temporary file beside `path` ("<path>.tmp-<8 random characters>", the
// file name cut short to fit 255 bytes, created exclusively, permissions from the umask or kept
// from the file it replaces), fsyncs it and renames it over `path`, so readers see the old file
// or the whole new one, never half of it. The temporary is removed on any failure; the target is
// then untouched.
// Errors (messages start with `path`): kNotFound the directory does not exist;
// kPermissionDenied it is not writable; kResourceExhausted the disk is full;
// kFailedPrecondition `path` is (or links to) a block device or a socket ("sda: is a block
// device, not a regular file; not replaced ..."), which is left as it is, or a directory
// ("cannot replace the file: is a directory"), or a name too long; kUnavailable a FIFO no
// process reads ("out.json: is a FIFO with no reader"); others by their errno as ReadFile().
// A FIFO or a character device (/dev/null, a terminal) is not replaced but written into, as a
// stream (a reader leaving midway is the writer's SIGPIPE, as for any pipe), by the name given.
// A symbolic link to a regular file is written through: the file it names (after every link;
// created if the link dangles) is replaced as above, in its own folder, messages then starting
// with that file, and the link stays (it used to be replaced by a plain file, its target left as
// it was). Another user's link in a sticky world-writable folder is not followed
// (kPermissionDenied), as the kernel's fs.protected_symlinks. A hard link is detached: the other
// names keep the old contents, as after any atomic replacement.
// Thread-safe; concurrent writers to one path leave one complete version (the last rename).
absl::Status WriteFileAtomically(const std::string& path, std::string_view contents);

// The file `path` names once its symbolic links are followed, as WriteFileAtomically() writes
// through them (a dangling link names its target; not a link: `path`). Another user's link in a
// sticky world-writable folder is not followed, as the kernel's fs.protected_symlinks.
// Errors: kPermissionDenied such a link; ELOOP's "too many levels of symbolic links" past 40;
// a link that cannot be read.
absl::StatusOr<std::string> FollowLinks(std::string path);

// Whether `file_name` is the name of a temporary WriteFileAtomically() makes for a file named
// `target_name` (both without folders): what a killed writer leaves behind. Thread-safe.
bool IsAtomicWriteTemporary(std::string_view file_name, std::string_view target_name);

// What the names of the temporaries WriteFileAtomically() makes for a file named `target_name`
// start with, before ".tmp-": the name itself, or for a name within 13 bytes of the 255 a file
// name may have, its first bytes (cut before a UTF-8 character). A view into `target_name`.
std::string_view AtomicWriteTemporaryStem(std::string_view target_name);
// Removes every temporary file WriteFileAtomically() has created and not yet renamed or removed,
// in this process. Async-signal-safe (it only reads lock-free slots and calls unlink()): a
// program's SIGINT / SIGTERM handler calls it so an interrupted write leaves no "*.tmp-*" file.
// At most kTrackedTempFiles writes at once are tracked (paths up to 4095 bytes); beyond that a
// temporary is still removed by its writer on any error, but not by this function.
inline constexpr int kTrackedTempFiles = 64;
void RemovePendingTempFiles();

// A whole file that is only a step on the way while this is held (a batch's output staged beside
// the input it replaces next): RemovePendingTempFiles() removes it too, so a run interrupted
// between its write and its rename leaves it nowhere. Takes one of the kTrackedTempFiles slots
// (none free: not tracked, as a temporary would not be). Not copyable; frees its slot when
// destroyed.
class PendingFile {
 public:
  explicit PendingFile(const std::string& path);
  ~PendingFile();
  PendingFile(const PendingFile&) = delete;
  PendingFile& operator=(const PendingFile&) = delete;

 private:
  int slot_;
};

// Test hook: called on the writing thread right after WriteFileAtomically() created (and
// registered) its temporary file, before any byte is written. Set once, before any write.
void SetTempFileCreatedHookForTesting(void (*hook)());

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_FILE_IO_H_
