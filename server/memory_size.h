// Bytes that server-held values occupy, for the memory budget: vector capacities and string
// buffers plus each element's own size (allocator headers are not counted).
#ifndef TEMPOKEY_SERVER_MEMORY_SIZE_H_
#define TEMPOKEY_SERVER_MEMORY_SIZE_H_

#include <cstdint>
#include <span>

#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/pipeline/pipeline.h"

namespace tempokey::server {

std::int64_t ClipBytes(const core::Clip& clip);
std::int64_t KeyedClipBytes(const core::KeyedClip& keyed);
// The output and its reports.
std::int64_t PipelineResultBytes(const core::PipelineResult& result);
// The steps of a pipeline with their warps, pins and options.
std::int64_t StepsBytes(std::span<const core::PipelineStep> steps);

}  // namespace tempokey::server

#endif  // TEMPOKEY_SERVER_MEMORY_SIZE_H_
