// Whole-file reads with a size cap and atomic whole-file writes.
#ifndef TEMPOKEY_CORE_FILE_IO_H_
#define TEMPOKEY_CORE_FILE_IO_H_

#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tempokey::core {

// Reads all of `path`.
// Errors: kNotFound missing file; kInvalidArgument a directory or larger than `max_bytes`
// ("walk.bvh: file is 3000000000 bytes, over the limit of 1073741824"); kUnavailable other I/O.
absl::StatusOr<std::string> ReadFile(const std::string& path,
                                     std::int64_t max_bytes = std::int64_t{1} << 30);

// Writes `contents` to a temporary file beside `path`, flushes it and renames it over `path`,
// so readers see the old file or the whole new one, never half of it. The temporary is removed
// on failure.
absl::Status WriteFileAtomically(const std::string& path, std::string_view contents);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_FILE_IO_H_
