// `tempokey batch` pipeline files (client/pipeline_file.h): a document is refused as a usage error
// naming its place, or gives steps that are validated on a small clip and, when cheap, run:
// whatever validation accepts must run and produce a valid clip or keyed clip.
#include <cstdint>

#include "client/pipeline_file.h"
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tempokey;
  using namespace tempokey::fuzz;
  const absl::StatusOr<std::vector<core::PipelineStep>> steps =
      client::ParsePipelineJson(AsText(data, size), "ops.json");
  if (!steps.ok()) {
    CheckCleanRefusal(steps.status(), "ParsePipelineJson");
    Check(steps.status().message().rfind("ops.json", 0) == 0, "pipeline error without place",
          Describe(steps.status()));
    return 0;
  }
  static const core::Clip clip = SmallClip();
  ValidateAndRunIfCheap(clip, *steps);
  return 0;
}
