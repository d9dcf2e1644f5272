// BVH reading and writing (SPEC 2).
#ifndef TEMPOKEY_CORE_IO_BVH_H_
#define TEMPOKEY_CORE_IO_BVH_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"

namespace tempokey::core {

// Parses BVH text in one pass. Accepts LF, CRLF, CR and mixed line endings, tabs and any
// whitespace, a UTF-8 byte order mark, exponent notation and a leading '+' on numbers, End Site,
// any channel order, 1 to 6 distinct channels per joint (or no CHANNELS line), several ROOTs,
// blank lines between motion rows, and "Frames:" / "Frame Time:" with or without blanks around
// the ':' ("Frame Time:0.0083", "Frames:\t994"). Joint names are one token (no whitespace or
// braces) on the keyword's line; OFFSET values and channel names are on their keyword's line;
// each motion row is one line. The clip's name is the file stem of `source_name`; its frame
// time is the double read from the text, never snapped to a common rate. Channels are in
// motion-column order, each holding its samples (channel-major).
//
// Errors: kInvalidArgument "<source_name>:<line>:<column>: <expected X, got Y>", lines and
// columns counted from 1, columns in bytes (a tab is one column). Covers an empty file, binary
// data ("unexpected byte 0x00; the file looks binary, not BVH text"), an unknown keyword, a
// missing '{' or '}' or joint name, a truncated hierarchy, a CHANNELS count not matching its
// names, unknown or repeated channel names, duplicate joint names, a missing MOTION, "Frames:"
// or "Frame Time:", a frame count < 1 or over limits.max_frames, a frame time <= 0, malformed,
// out-of-range or non-finite numbers ("expected a finite number, got \"nan\""), a motion row
// with the wrong number of values ("motion row 5 has 95 values, expected 96"), fewer rows than
// "Frames:", text after the last row, nesting deeper than limits.max_depth, more joints or
// channels than limits allow, and frames x channels over limits.max_samples (checked before any
// sample is allocated).
// Thread-safe: a pure function of its arguments.
absl::StatusOr<Clip> ParseBvh(std::string_view text, std::string_view source_name,
                              const ClipLimits& limits = {});

// ReadFile() then ParseBvh() with `path` as the source name. The file size is capped at
// 4096 + 25 bytes per allowed sample (limits.max_samples) + 1024 bytes per allowed joint.
// Errors: those of ReadFile() and ParseBvh().
absl::StatusOr<Clip> ReadBvhFile(const std::string& path, const ClipLimits& limits = {});

// Formats `clip` as BVH: HIERARCHY with ROOT/JOINT/End Site blocks indented by tabs, OFFSET and
// CHANNELS lines in each joint's channel order, then MOTION, "Frames: N", "Frame Time: T" and
// one line per frame; every number in the shortest form that reads back to the same double. A
// clip whose joints are in depth-first order with channels in that column order (as ParseBvh()
// returns them) reads back with ParseBvh(FormatBvh(c)) == c bit for bit (name and markers aside);
// otherwise joints and columns come out depth-first.
// Errors: kInvalidArgument when ValidateClip() fails, the clip has no skeleton, a channel is not
// a position or rotation of a joint (BVH cannot hold plain channels: use CSV), or a joint name
// contains whitespace, a brace or a control character.
// Thread-safe.
absl::StatusOr<std::string> FormatBvh(const Clip& clip);

// FormatBvh() then WriteFileAtomically().
absl::Status WriteBvhFile(const std::string& path, const Clip& clip);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_BVH_H_
