// Batch pipeline files: the operations `tempokey batch` runs on every file, as JSON.
//
//   {"operations": [
//     {"retime": {"speed": "0s:1,2s:0.5,4s:1", "fps": 30}},
//     {"reduce": {"tolerance": 0.5}}
//   ]}
//
// Each operation is an object with one member, retime, reduce, bake or convert, whose options are
// the flags of the matching command without their dashes (step_flags.h): "fit-frames" (or
// "fit_frames"), "speed-over", "pose-align", ... Values are strings or numbers as the flag would
// take them; a switch is `true` (or `false`, the same as leaving it out); a repeatable flag
// (hold, pin) takes an array. The pipeline is parsed by the same code as the command line, so
// `{"retime": {"speed": "0s:0.5"}}` means exactly `tempokey retime --speed 0s:0.5`.
#ifndef TEMPOKEY_CLIENT_PIPELINE_FILE_H_
#define TEMPOKEY_CLIENT_PIPELINE_FILE_H_

#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::client {

// Parses a pipeline document; `source` names it in messages.
// Errors (usage errors, exit 2), each with the place it points at:
//   "ops.json:3:17: operation 1 (retime): no option 'fsp' (options: speed, speed-over, ...)"
//   "ops.json:3:24: operation 1 (retime): --fps: expected a frame rate, got 'fast'"
//   "ops.json:4:5: operation 2: expected one of retime, reduce, bake, convert, got 'reduse'"
//   "ops.json:1:1: operation 2 (bake): needs a keyed clip, got a sampled clip"
// and JSON syntax errors with their line and column.
absl::StatusOr<std::vector<core::PipelineStep>> ParsePipelineJson(std::string_view text,
                                                                  std::string_view source);

// Reads and parses the pipeline file at `path` (at most 1 MiB).
absl::StatusOr<std::vector<core::PipelineStep>> ReadPipelineFile(const std::string& path);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_PIPELINE_FILE_H_
