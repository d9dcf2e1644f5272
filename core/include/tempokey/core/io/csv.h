// Plain channel tables as CSV (SPEC 2): a header row of channel names ("Hips.Xrotation", or a
// scalar name), then one row per frame. The frame rate is not in the table: it is given.
#ifndef TEMPOKEY_CORE_IO_CSV_H_
#define TEMPOKEY_CORE_IO_CSV_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::core {

// Parses a CSV table into a clip. Columns named "Joint.Xrotation" (a BVH channel name after the
// last dot, a non-empty joint name before it) become joint channels of a skeleton of flat root
// joints (zero offsets) in order of first appearance, each joint's channel list in column
// order; other columns become scalar channels named after the column. A first column named
// "time" or "frame" (any case) is skipped and its values are not read. Fields are separated by
// ',' and trimmed of blanks; no quoting. Lines end in LF, CRLF or CR; blank lines are skipped.
// The clip is named after the file stem of `source_name`; its frame time is
// `frame_time_seconds`.
//
// Errors: kInvalidArgument "<source_name>:<line>:<column>: ..." for an empty table, a header
// without rows, an empty, quoted or duplicate column name, a row with the wrong number of fields
// ("row 3 has 5 fields, expected 6"), a field that is not a finite number (the messages of
// DescribeNumberError()), binary data, or more channels, joints, frames or frames x channels
// than `limits` allow (checked before the row is stored); kInvalidArgument without location for
// a frame time that is not finite and > 0.
// Thread-safe: a pure function of its arguments.
absl::StatusOr<Clip> ParseCsv(std::string_view text, std::string_view source_name,
                              double frame_time_seconds, const ClipLimits& limits = {});

// ReadFile() then ParseCsv(); the file size is capped at 50 bytes per allowed sample plus 1 MiB.
absl::StatusOr<Clip> ReadCsvFile(const std::string& path, double frame_time_seconds,
                                 const ClipLimits& limits = {});

// One header row of ChannelName()s ("Hips.Xrotation", a scalar's name; no index column), then
// one row per frame, numbers in shortest round-trip form (WriteDouble()), LF line endings, so
// ParseCsv(FormatCsv(c)) has the same channel names, kinds and samples bit for bit. The
// skeleton's hierarchy, offsets and end sites are not kept: joints read back as flat roots.
// Errors: kInvalidArgument when ValidateClip() fails, or a column name would not read back as
// the same channel (empty; contains ',', '"' or a line break; starts or ends with whitespace;
// a scalar named like "X.Xrotation"; a first column named time or frame, or starting with a
// UTF-8 byte order mark; two equal names).
// Thread-safe.
absl::StatusOr<std::string> FormatCsv(const Clip& clip);

// FormatCsv() then WriteFileAtomically().
absl::Status WriteCsvFile(const std::string& path, const Clip& clip);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_CSV_H_
