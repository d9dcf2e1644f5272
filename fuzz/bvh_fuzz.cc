// BVH text: the reader refuses with a located INVALID_ARGUMENT or returns a valid clip that the
// writer writes and the reader reads back bit for bit; a small clip then goes through a retime
// and a reduction, which must run once validated.
#include <cstdint>
#include <cstring>

#include "fuzz/fuzz_util.h"
#include "tempokey/core/io/bvh.h"

namespace tempokey::fuzz {
namespace {

bool SameSamples(const core::Clip& a, const core::Clip& b) {
  if (a.channels.size() != b.channels.size()) return false;
  for (std::size_t c = 0; c < a.channels.size(); ++c) {
    const auto& x = a.channels[c].samples;
    const auto& y = b.channels[c].samples;
    if (x.size() != y.size() || std::memcmp(x.data(), y.data(), x.size() * sizeof(double)) != 0) {
      return false;
    }
  }
  return true;
}

}  // namespace
}  // namespace tempokey::fuzz

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  const core::ClipLimits limits = FuzzLimits();
  const absl::StatusOr<core::Clip> clip = core::ParseBvh(AsText(data, size), "fuzz.bvh", limits);
  if (!clip.ok()) {
    CheckCleanRefusal(clip.status(), "ParseBvh");
    Check(clip.status().message().rfind("fuzz.bvh:", 0) == 0, "ParseBvh message without place",
          Describe(clip.status()));
    return 0;
  }
  const absl::Status valid = core::ValidateClip(*clip, limits);
  Check(valid.ok(), "ParseBvh returned an invalid clip", Describe(valid));

  const absl::StatusOr<std::string> written = core::FormatBvh(*clip);
  Check(written.ok(), "FormatBvh refused a clip ParseBvh returned", Describe(written.status()));
  const absl::StatusOr<core::Clip> again = core::ParseBvh(*written, "fuzz.bvh", limits);
  Check(again.ok(), "ParseBvh refused FormatBvh's text", Describe(again.status()));
  Check(again->skeleton == clip->skeleton, "BVH round trip changed the skeleton");
  Check(again->frame_count == clip->frame_count &&
            std::memcmp(&again->frame_time_seconds, &clip->frame_time_seconds, sizeof(double)) == 0,
        "BVH round trip changed the timing");
  Check(SameSamples(*again, *clip), "BVH round trip changed samples");

  if (clip->sample_count() <= 2000) {
    core::RetimeStep retime;
    retime.warp.domain = core::WarpDomain::kSpeedOverSource;
    retime.warp.speed = {core::SpeedKnot{{0.0, false}, 0.5}, core::SpeedKnot{{0.1, false}, 2.0}};
    const core::PipelineStep steps[] = {retime, core::ReduceStep{}, core::BakeStep{}};
    ValidateAndRunIfCheap(*clip, steps);
  }
  return 0;
}
