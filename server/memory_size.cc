#include "server/memory_size.h"

#include <string>
#include <variant>
#include <vector>

namespace tempokey::server {
namespace {

std::int64_t StringBytes(const std::string& s) {
  // Short strings live inside the object (SSO); only longer ones own a buffer.
  return s.capacity() > 15 ? static_cast<std::int64_t>(s.capacity()) + 1 : 0;
}

template <typename T>
std::int64_t VectorBytes(const std::vector<T>& v) {
  return static_cast<std::int64_t>(v.capacity() * sizeof(T));
}

std::int64_t LayoutBytes(const core::Clip& clip) {
  std::int64_t bytes = static_cast<std::int64_t>(sizeof(core::Clip)) + StringBytes(clip.name) +
                       VectorBytes(clip.skeleton.joints) + VectorBytes(clip.channels) +
                       VectorBytes(clip.markers);
  for (const core::Joint& joint : clip.skeleton.joints) {
    bytes += StringBytes(joint.name) + VectorBytes(joint.channels) + VectorBytes(joint.end_sites);
  }
  for (const core::Channel& channel : clip.channels) bytes += StringBytes(channel.name);
  for (const core::Marker& marker : clip.markers) bytes += StringBytes(marker.name);
  return bytes;
}

std::int64_t StepBytes(const core::PipelineStep& step) {
  std::int64_t bytes = sizeof(core::PipelineStep);
  if (const auto* retime = std::get_if<core::RetimeStep>(&step)) {
    bytes += VectorBytes(retime->warp.speed) + VectorBytes(retime->warp.keys) +
             VectorBytes(retime->warp.holds) + VectorBytes(retime->options.pins);
  }
  return bytes;
}

}  // namespace

std::int64_t ClipBytes(const core::Clip& clip) {
  std::int64_t bytes = LayoutBytes(clip);
  for (const core::Channel& channel : clip.channels) bytes += VectorBytes(channel.samples);
  return bytes;
}

std::int64_t KeyedClipBytes(const core::KeyedClip& keyed) {
  std::int64_t bytes = static_cast<std::int64_t>(sizeof(core::KeyedClip)) + LayoutBytes(keyed.layout) +
                       VectorBytes(keyed.curves);
  for (const core::Curve& curve : keyed.curves) bytes += VectorBytes(curve.keys);
  return bytes;
}

std::int64_t PipelineResultBytes(const core::PipelineResult& result) {
  std::int64_t bytes = static_cast<std::int64_t>(sizeof(core::PipelineResult)) +
                       VectorBytes(result.reports);
  if (const auto* clip = std::get_if<core::Clip>(&result.output)) {
    bytes += ClipBytes(*clip);
  } else {
    bytes += KeyedClipBytes(std::get<core::KeyedClip>(result.output));
  }
  for (const core::StepReport& report : result.reports) {
    if (const auto* reduction = std::get_if<core::ReductionReport>(&report)) {
      bytes += VectorBytes(reduction->channels);
    }
  }
  return bytes;
}

std::int64_t StepsBytes(std::span<const core::PipelineStep> steps) {
  std::int64_t bytes = 0;
  for (const core::PipelineStep& step : steps) bytes += StepBytes(step);
  return bytes;
}

}  // namespace tempokey::server
