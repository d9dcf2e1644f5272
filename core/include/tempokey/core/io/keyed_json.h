// Keyed clips as JSON files (read and write, exact; SPEC 2).
//
// JSON schema ("tempokey.keyed_clip" version 1). Numbers are written in the shortest form that
// reads back to the same double, so ReadKeyedClipJson(FormatKeyedClipJson(k)) == k bit for bit.
//   {
//     "format": "tempokey.keyed_clip",
//     "version": 1,
//     "name": "131_01",                  // clip name
//     "frame_time_seconds": 0.0083333,   // of the source clip, exactly as read
//     "frame_count": 994,                // of the source clip
//     "joints": [                        // file order; parents precede children
//       {"name": "Hips", "parent": -1, "offset": [0, 0, 0],
//        "end_sites": [[0, 1, 0]],       // End Site offsets
//        "channels": [0, 1, 2]}          // indices into "channels", in the joint's file order
//     ],
//     "channels": [                      // motion-column order; one curve each
//       {"joint": 0,                     // -1 for a plain channel
//        "kind": "Xrotation",            // Xposition..Zrotation or "scalar"
//        "name": "",                     // for plain channels
//        "keys": [[0, 1.5, 0.25, 0.25],  // [time_seconds, value, in_tangent, out_tangent]
//                 [0.5, 2, 0, 0, 0.3, 0.2],   // + [in_weight, out_weight] when weighted
//                 [1, 3, 0, 0, null, 0.2]]}   // null: that side's weight is unset
//     ],
//     "markers": [{"name": "contact", "time_seconds": 0.5, "duration_seconds": 0}]
//   }
// Tangents are slopes in value units per second; rotations are degrees (unwrapped as fitted);
// weights are fractions of the segment's duration (keyed_clip.h). Unknown members are refused.
//
// A key weighted on one side only is written with null for the unset side (which evaluates as
// 1/3 but stays unset), so the round trip is exact for every combination of weights. Reading
// accepts null for either weight.
//
#ifndef TEMPOKEY_CORE_IO_KEYED_JSON_H_
#define TEMPOKEY_CORE_IO_KEYED_JSON_H_

#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/model/keyed_clip.h"

namespace tempokey::core {

// The JSON text of `keyed` (schema above), one channel per line.
// Errors: kInvalidArgument from ValidateKeyedClip(). Thread-safe.
absl::StatusOr<std::string> FormatKeyedClipJson(const KeyedClip& keyed);

// Parses JSON text of the schema above; `source_name` prefixes messages
// ("walk.json:3:14: expected ',' or ']', got '}'"). Nesting is limited to 64 levels.
// Errors: kInvalidArgument for malformed JSON, a missing or mistyped member, an unknown member,
// a wrong format or version, and anything ValidateKeyedClip() refuses. Thread-safe.
absl::StatusOr<KeyedClip> ParseKeyedClipJson(std::string_view text, std::string_view source_name);

// Format...() then WriteFileAtomically(); Read... is ReadFile() then ParseKeyedClipJson().
absl::Status WriteKeyedClipJsonFile(const std::string& path, const KeyedClip& keyed);
absl::StatusOr<KeyedClip> ReadKeyedClipJsonFile(const std::string& path);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_KEYED_JSON_H_
