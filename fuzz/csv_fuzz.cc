// CSV text at a frame time chosen by the first byte (valid ones and the edges of the range): the
// reader refuses cleanly or returns a valid clip whose channel names, kinds and samples survive
// the writer and the reader again, bit for bit.
#include <cstdint>
#include <cstring>

#include "fuzz/fuzz_util.h"
#include "tempokey/core/io/csv.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  if (size == 0) return 0;
  constexpr double kFrameTimes[] = {1.0 / 30.0, 1.0 / 120.0, 1e-6, 3600.0, 0.0, 1e-320};
  const double frame_time = kFrameTimes[data[0] % std::size(kFrameTimes)];
  const core::ClipLimits limits = FuzzLimits();
  const absl::StatusOr<core::Clip> clip =
      core::ParseCsv(AsText(data + 1, size - 1), "fuzz.csv", frame_time, limits);
  if (!clip.ok()) {
    CheckCleanRefusal(clip.status(), "ParseCsv");
    return 0;
  }
  const absl::Status valid = core::ValidateClip(*clip, limits);
  Check(valid.ok(), "ParseCsv returned an invalid clip", Describe(valid));

  const absl::StatusOr<std::string> written = core::FormatCsv(*clip);
  if (!written.ok()) {
    // Column names CSV cannot hold are refused by the writer, with a reason.
    CheckCleanRefusal(written.status(), "FormatCsv");
    return 0;
  }
  const absl::StatusOr<core::Clip> again = core::ParseCsv(*written, "fuzz.csv", frame_time, limits);
  Check(again.ok(), "ParseCsv refused FormatCsv's text", Describe(again.status()));
  Check(again->channels.size() == clip->channels.size(), "CSV round trip changed the channels");
  for (std::size_t c = 0; c < clip->channels.size(); ++c) {
    const core::Channel& a = clip->channels[c];
    const core::Channel& b = again->channels[c];
    Check(core::ChannelName(*clip, static_cast<int>(c)) ==
              core::ChannelName(*again, static_cast<int>(c)),
          "CSV round trip changed a channel name");
    Check(a.kind == b.kind, "CSV round trip changed a channel kind");
    Check(a.samples.size() == b.samples.size() &&
              std::memcmp(a.samples.data(), b.samples.data(), a.samples.size() * sizeof(double)) == 0,
          "CSV round trip changed samples");
  }
  return 0;
}
