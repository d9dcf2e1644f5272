// BVH reading and writing (SPEC 2).
#ifndef TEMPOKEY_CORE_BVH_H_
#define TEMPOKEY_CORE_BVH_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "tempokey/core/clip.h"

namespace tempokey::core {

// Parses BVH text in one pass. Accepts LF, CRLF and mixed line endings, tabs, exponent
// notation, End Site, any channel order, 3 or 6 (any 1..6 distinct) channels per joint and
// "Frame Time:" with any whitespace. `source_name` prefixes messages; the clip's name is the
// file stem of `source_name`.
//
// Errors: kInvalidArgument "<source_name>:<line>:<column>: expected X, got Y" for malformed
// text (unknown keyword, CHANNELS count not matching its names, wrong number of values in a
// motion row, fewer rows than Frames:, non-finite numbers, frame time <= 0, duplicate joint
// names, nesting deeper than limits.max_depth); kInvalidArgument when frames x channels exceeds
// `limits` (checked before any sample is stored).
absl::StatusOr<Clip> ParseBvh(std::string_view text, std::string_view source_name,
                              const ClipLimits& limits = {});

// ReadFile() then ParseBvh(); the file size is capped at 16 bytes per allowed sample.
absl::StatusOr<Clip> ReadBvhFile(const std::string& path, const ClipLimits& limits = {});

// Formats `clip` as BVH with the same hierarchy and channel orders and every number in the
// shortest form that reads back to the same double, so ParseBvh(FormatBvh(c)) == c bit for bit.
// Errors: kInvalidArgument when ValidateClip() fails or the clip has no skeleton, or a channel
// belongs to no joint (BVH cannot hold plain channels: use CSV).
absl::StatusOr<std::string> FormatBvh(const Clip& clip);

// FormatBvh() then WriteFileAtomically().
absl::Status WriteBvhFile(const std::string& path, const Clip& clip);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_BVH_H_
