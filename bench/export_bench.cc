// Export quality table: every shared clip reduced at 0.1, 0.5 and 1.0 (degrees and file units),
// written as Maya .anim and glTF, each measured by an evaluator that is not its writer:
//   - .anim: the Maya-semantics evaluator of the tests (tests/testing/maya_anim_eval.h), max
//     error over all channels at every source frame's exact time (frame = t x the unit's rate)
//     and at the frames animators see (FileFrameOfSourceFrame(); rotations compared modulo 360);
//   - .gltf: three.js (GLTFLoader + AnimationMixer under node, tests/export/three_check.mjs):
//     max rotation angle and max translation component error over all joints and frames.
// Keys: Euler keys of the rotation channels as % of their samples (frames x rotation channels),
// and glTF rotation sampler keys as % of theirs (frames x animated joints), from the same run.
//
//   export_bench [OUTDIR]     (files are kept in OUTDIR, default ./export_bench_out)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/gltf.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/io/maya_anim.h"
#include "tempokey/core/reduce/reduce.h"
#include "tests/testing/maya_anim_eval.h"

namespace tempokey::core {
namespace {

std::vector<std::string> SharedClips() {
  std::vector<std::string> files;
  for (const auto& entry :
       std::filesystem::recursive_directory_iterator(TEMPOKEY_SHARED_DIR "/data/bvh")) {
    if (entry.path().extension() == ".bvh") files.push_back(entry.path().string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

struct AnimErrors {
  double exact = 0.0;
  double integer = 0.0;
};

AnimErrors MeasureAnim(const Clip& source, const std::string& text) {
  AnimErrors errors;
  absl::StatusOr<testing::MayaAnimFile> file = testing::ParseMayaAnimText(text);
  if (!file.ok()) {
    std::fprintf(stderr, "anim: %s\n", std::string(file.status().message()).c_str());
    std::exit(1);
  }
  std::map<std::pair<std::string, std::string>, const testing::MayaCurveBlock*> curves;
  for (const auto& curve : file->curves) curves[{curve.node, curve.attribute}] = &curve;
  for (const Channel& channel : source.channels) {
    const char axis = "XYZ"[Axis(channel.kind)];
    const bool angle = IsRotation(channel.kind);
    const std::string attribute =
        angle ? std::string("rotate.rotate") + axis : std::string("translate.translate") + axis;
    const auto* curve = curves[{source.skeleton.joints[channel.joint].name, attribute}];
    for (std::size_t i = 0; i < channel.samples.size(); ++i) {
      const double frames[2] = {
          static_cast<double>(i) * source.frame_time_seconds * file->frames_per_second,
          testing::FileFrameOfSourceFrame(*file, source.frame_time_seconds,
                                          static_cast<std::int64_t>(i))};
      for (int k = 0; k < 2; ++k) {
        const double value = *testing::EvaluateMayaCurve(*curve, frames[k]);
        const double d = angle ? std::abs(std::remainder(value - channel.samples[i], 360.0))
                               : std::abs(value - channel.samples[i]);
        double& worst = k == 0 ? errors.exact : errors.integer;
        worst = std::max(worst, d);
      }
    }
  }
  return errors;
}

struct ThreeErrors {
  double rotation = -1.0;
  double translation = -1.0;
};

ThreeErrors RunThree(const std::string& bvh, const std::string& gltf) {
  const std::string command =
      absl::StrFormat("'%s' '%s/tests/export/three_check.mjs' '%s' '%s'", TEMPOKEY_NODE,
                      TEMPOKEY_SOURCE_DIR, bvh, gltf);
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(command.c_str(), "r"), pclose);
  std::string out;
  char buffer[4096];
  while (pipe && std::fgets(buffer, sizeof buffer, pipe.get()) != nullptr) out += buffer;
  ThreeErrors errors;
  absl::StatusOr<JsonValue> json = ParseJson(out, "three_check");
  if (!json.ok()) return errors;
  errors.rotation = json->Find("max_rotation_error_degrees")->number;
  errors.translation = json->Find("max_translation_error")->number;
  return errors;
}

int Main(int argc, char** argv) {
  // The files go to OUTDIR, by default a new folder under the temporary directory: never into
  // the folder the bench was started from (a checkout).
  std::string out_dir;
  if (argc > 1) {
    out_dir = argv[1];
  } else {
    std::string pattern =
        (std::filesystem::temp_directory_path() / "tempokey-export-bench-XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) {
      std::fprintf(stderr, "export_bench: cannot make a folder under %s\n", pattern.c_str());
      return 1;
    }
    out_dir = pattern;
  }
  std::filesystem::create_directories(out_dir);
  std::fprintf(stderr, "export_bench: files in %s\n", out_dir.c_str());
  std::printf(
      "%-38s %5s | %9s %9s | %9s %9s | %7s %7s\n", "clip", "tol", "anim exact", "anim int",
      "gltf rot", "gltf pos", "Euler%", "quat%");
  for (double tolerance : {0.1, 0.5, 1.0}) {
    for (const std::string& path : SharedClips()) {
      absl::StatusOr<Clip> source = ReadBvhFile(path);
      ReduceOptions options;
      options.tolerance.max_rotation_error_degrees = tolerance;
      options.tolerance.max_position_error = tolerance;
      absl::StatusOr<ReduceResult> reduced = ReduceKeys(*source, options);
      if (!source.ok() || !reduced.ok()) {
        std::fprintf(stderr, "%s: reduction failed\n", path.c_str());
        return 1;
      }
      const AnimErrors anim = MeasureAnim(*source, *FormatMayaAnim(reduced->keyed));
      std::int64_t euler_keys = 0;
      std::int64_t euler_samples = 0;
      for (std::size_t c = 0; c < source->channels.size(); ++c) {
        if (!IsRotation(source->channels[c].kind)) continue;
        euler_keys += static_cast<std::int64_t>(reduced->keyed.curves[c].keys.size());
        euler_samples += source->frame_count;
      }
      absl::StatusOr<GltfFile> gltf = FormatGltfKeyed(
          *source, reduced->keyed, {.max_rotation_error_degrees = tolerance}, GltfContainer::kText);
      if (!gltf.ok()) {
        std::fprintf(stderr, "%s: %s\n", path.c_str(), std::string(gltf.status().message()).c_str());
        return 1;
      }
      const std::string name = std::filesystem::path(path).stem().string();
      const std::string gltf_path = absl::StrFormat("%s/%s_%g.gltf", out_dir, name, tolerance);
      if (!WriteFileAtomically(gltf_path, gltf->bytes).ok()) return 1;
      const ThreeErrors three = RunThree(path, gltf_path);
      std::printf("%-38s %5.1f | %9.6f %9.6f | %9.6f %9.6f | %6.2f%% %6.2f%%\n", name.c_str(),
                  tolerance, anim.exact, anim.integer, three.rotation, three.translation,
                  100.0 * static_cast<double>(euler_keys) / static_cast<double>(euler_samples),
                  100.0 * static_cast<double>(gltf->stats.rotation_keys) /
                      static_cast<double>(gltf->stats.rotation_samples));
      std::fflush(stdout);
    }
  }
  return 0;
}

}  // namespace
}  // namespace tempokey::core

int main(int argc, char** argv) { return tempokey::core::Main(argc, argv); }
