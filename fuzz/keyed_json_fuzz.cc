// Keyed-clip JSON (core/io/keyed_json.h): refused cleanly, or a valid keyed clip that writes and
// reads back equal (bit-exact), exports as Maya .anim, and bakes (small ones) to a valid clip.
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/io/maya_anim.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  const absl::StatusOr<core::KeyedClip> keyed =
      core::ParseKeyedClipJson(AsText(data, size), "fuzz.json");
  if (!keyed.ok()) {
    CheckCleanRefusal(keyed.status(), "ParseKeyedClipJson");
    return 0;
  }
  const absl::Status valid = core::ValidateKeyedClip(*keyed);
  Check(valid.ok(), "ParseKeyedClipJson returned an invalid keyed clip", Describe(valid));

  const absl::StatusOr<std::string> written = core::FormatKeyedClipJson(*keyed);
  Check(written.ok(), "FormatKeyedClipJson refused a parsed clip", Describe(written.status()));
  const absl::StatusOr<core::KeyedClip> again = core::ParseKeyedClipJson(*written, "fuzz.json");
  Check(again.ok(), "ParseKeyedClipJson refused its own text", Describe(again.status()));
  Check(*again == *keyed, "keyed JSON round trip changed the clip");

  const absl::StatusOr<std::string> anim = core::FormatMayaAnim(*keyed);
  if (!anim.ok()) CheckCleanRefusal(anim.status(), "FormatMayaAnim");

  const core::ClipLimits limits = FuzzLimits();
  const absl::StatusOr<std::int64_t> frames = core::BakedFrameCount(
      keyed->layout.duration_seconds(), keyed->layout.channels.size(),
      keyed->layout.frame_time_seconds, limits);
  if (frames.ok() && *frames * static_cast<std::int64_t>(keyed->layout.channels.size()) <= 20'000) {
    const absl::StatusOr<core::Clip> baked = core::Bake(*keyed, std::nullopt, limits);
    if (baked.ok()) {
      const absl::Status baked_valid = core::ValidateClip(*baked, limits);
      Check(baked_valid.ok(), "Bake produced an invalid clip", Describe(baked_valid));
    } else {
      CheckCleanRefusal(baked.status(), "Bake");
    }
  }
  return 0;
}
