// Whole-file reads with a size cap and atomic whole-file writes.
#ifndef TEMPOKEY_CORE_IO_FILE_IO_H_
#define TEMPOKEY_CORE_IO_FILE_IO_H_

#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tempokey::core {

// Reads all of `path` (any readable file, including pipes; the cap applies to the bytes read).
// Messages start with `path`.
// Errors: kNotFound missing file ("walk.bvh: no such file"); kInvalidArgument a directory
// ("walk.bvh: is a directory, not a file") or larger than `max_bytes` ("walk.bvh: file is
// 3000000000 bytes, over the limit of 1073741824"); kPermissionDenied unreadable; kUnavailable
// other I/O errors.
// Thread-safe.
absl::StatusOr<std::string> ReadFile(const std::string& path,
                                     std::int64_t max_bytes = std::int64_t{1} << 30);

// Writes `contents` to a temporary file beside `path` ("<path>.tmp-<8 random characters>",
// created exclusively, permissions from the umask or kept from the file it replaces), fsyncs
// it and renames it over `path`, so readers see the old file or the whole new one, never half
// of it. The temporary is removed on any failure; the target is then untouched.
// Errors (messages start with `path`): kNotFound the directory does not exist;
// kPermissionDenied it is not writable; kResourceExhausted the disk is full; kUnavailable other
// I/O errors, e.g. `path` is a directory ("cannot replace the file: is a directory").
// Thread-safe; concurrent writers to one path leave one complete version (the last rename).
absl::Status WriteFileAtomically(const std::string& path, std::string_view contents);

// Whether `file_name` is the name of a temporary WriteFileAtomically() makes for a file named
// `target_name` (both without folders): what a killed writer leaves behind. Thread-safe.
bool IsAtomicWriteTemporary(std::string_view file_name, std::string_view target_name);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_FILE_IO_H_
