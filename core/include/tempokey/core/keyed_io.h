// Keyed clips in files: JSON (read and write, exact) and Maya .anim export (SPEC 2).
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
// Maya .anim (ASCII, animVersion 1.1): one `anim` block per channel, attribute
// rotate.rotateX / translate.translateX ... (plain channels use their name), node = the joint
// name; `weighted 1`.
// Time: timeUnit is the Maya unit whose rate is nearest the clip's (in ratio): game 15, film 24,
// pal 25, ntsc 30, show 48, palf 50, ntscf 60, 23.976fps / 29.97fps / 47.952fps / 59.94fps (24,
// 30, 48, 60 x 1000/1001), or "<N>fps" for N in 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 40, 75, 80,
// 100, 120, 125, 150, 200, 240, 250, 300, 375, 400, 500, 600, 750, 1200, 1500, 2000, 3000, 6000
// (so 30000/1001 Hz is 29.97fps, and a BVH's 0.0083333 s frames are 120fps). Key times and
// endTime are in frames of that unit, time_seconds * unit rate, so Maya plays every key at its
// time whatever the clip's rate; keys of a clip off the unit's rate land between whole frames.
// Tangents: every key has fixed in and out tangents as angle and weight. A key side's Bezier
// handle spans dt = weight * T seconds (T the segment's duration, unset weights 1/3) and
// dv = slope * dt; Maya's tangent vector is (x, y) = (3 dt, 3 dv), time in seconds:
// angle = atan2(y, x) in degrees, weight = hypot(x, y). tanLock is 1 when in and out slopes are
// equal. Angular curves are degrees (angularUnit deg), linear ones the file's units written as
// linearUnit cm.
#ifndef TEMPOKEY_CORE_KEYED_IO_H_
#define TEMPOKEY_CORE_KEYED_IO_H_

#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/keyed_clip.h"

namespace tempokey::core {

// The JSON text of `keyed` (schema above), one channel per line.
// Errors: kInvalidArgument from ValidateKeyedClip(). Thread-safe.
absl::StatusOr<std::string> FormatKeyedClipJson(const KeyedClip& keyed);

// Parses JSON text of the schema above; `source_name` prefixes messages
// ("walk.json:3:14: expected ',' or ']', got '}'"). Nesting is limited to 64 levels.
// Errors: kInvalidArgument for malformed JSON, a missing or mistyped member, an unknown member,
// a wrong format or version, and anything ValidateKeyedClip() refuses. Thread-safe.
absl::StatusOr<KeyedClip> ParseKeyedClipJson(std::string_view text, std::string_view source_name);

// The Maya .anim text of `keyed` (conventions above).
// Errors: kInvalidArgument from ValidateKeyedClip(). Thread-safe.
absl::StatusOr<std::string> FormatMayaAnim(const KeyedClip& keyed);

// Format...() then WriteFileAtomically(); Read... is ReadFile() then ParseKeyedClipJson().
absl::Status WriteKeyedClipJsonFile(const std::string& path, const KeyedClip& keyed);
absl::StatusOr<KeyedClip> ReadKeyedClipJsonFile(const std::string& path);
absl::Status WriteMayaAnimFile(const std::string& path, const KeyedClip& keyed);

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_KEYED_IO_H_
