// Plain channel tables as CSV (SPEC 2): a header row of channel names ("Hips.Xrotation", or a
// scalar name), then one row per frame. The frame rate is not in the table: it is given.
#ifndef TEMPOKEY_CORE_CSV_H_
#define TEMPOKEY_CORE_CSV_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "tempokey/core/clip.h"

namespace tempokey::core {

// Parses a CSV table into a clip without skeleton. Columns named "Joint.Xrotation" (a BVH
// channel name after the last dot) become joint channels of a skeleton of flat root joints in
// order of first appearance; other columns become scalar channels. An optional first column
// named "time" or "frame" is ignored.
// Errors: kInvalidArgument "<source_name>:<line>:<column>: ..." for a row with the wrong number
// of fields, a field that is not a finite number, an empty table or duplicate column names.
absl::StatusOr<Clip> ParseCsv(std::string_view text, std::string_view source_name,
                              double frame_time_seconds, const ClipLimits& limits = {});

absl::StatusOr<Clip> ReadCsvFile(const std::string& path, double frame_time_seconds,
                                 const ClipLimits& limits = {});

// One header row of ChannelName()s, then one row per frame, numbers in shortest round-trip form.
absl::StatusOr<std::string> FormatCsv(const Clip& clip);
absl::Status WriteCsvFile(const std::string& path, const Clip& clip);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_CSV_H_
