// Keyed clips off the wire (results a client receives, curves in pieces): wire::
// KeyedClipFromProto() refuses cleanly or returns a valid keyed clip that converts to a message
// and back equal (but for what the encoding defines: on a curve with any weight, unset weights
// travel as 1/3, which is what they evaluate as).
#include <cstdint>

#include "fuzz/fuzz_util.h"
#include "google/protobuf/stubs/logging.h"
#include "proto/clip_convert.h"

namespace {

// Unset weights as 1/3 on every curve that has any weight (clip_convert.h).
tempokey::core::KeyedClip WeightsAsEncoded(tempokey::core::KeyedClip keyed) {
  for (tempokey::core::Curve& curve : keyed.curves) {
    bool weighted = false;
    for (const tempokey::core::Key& key : curve.keys) {
      weighted = weighted || key.in_weight.has_value() || key.out_weight.has_value();
    }
    if (!weighted) continue;
    for (tempokey::core::Key& key : curve.keys) {
      if (!key.in_weight) key.in_weight = 1.0 / 3.0;
      if (!key.out_weight) key.out_weight = 1.0 / 3.0;
    }
  }
  return keyed;
}

}  // namespace

TEMPOKEY_FUZZ_QUIET_PROTOBUF()

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  v1::KeyedClip message;
  if (!message.ParseFromArray(data, static_cast<int>(size))) return 0;
  const absl::StatusOr<core::KeyedClip> keyed = wire::KeyedClipFromProto(message, FuzzLimits());
  if (!keyed.ok()) {
    CheckCleanRefusal(keyed.status(), "KeyedClipFromProto");
    return 0;
  }
  const absl::Status valid = core::ValidateKeyedClip(*keyed);
  Check(valid.ok(), "KeyedClipFromProto returned an invalid keyed clip", Describe(valid));
  const absl::StatusOr<core::KeyedClip> again =
      wire::KeyedClipFromProto(wire::KeyedClipToProto(*keyed), FuzzLimits());
  Check(again.ok(), "KeyedClipFromProto refused KeyedClipToProto's message",
        Describe(again.status()));
  Check(WeightsAsEncoded(*again) == WeightsAsEncoded(*keyed),
        "keyed clip changed converting to a message and back");
  return 0;
}
