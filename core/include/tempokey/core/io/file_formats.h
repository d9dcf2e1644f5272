// The clip file formats as one list: which reader takes a file by its extension, and how a
// pipeline's output is written as a file. The server's downloads (ExportFile) and its clip-file
// parsing (ParseClipFile) go through these entries, which call the same core functions the CLI's
// readers and writers call (client/clip_files.cc), so a result downloaded from the studio page
// and the CLI's file for the same input and settings are the same bytes. A new output format is
// one more entry in kExportFormats (file_formats.cc).
#ifndef TEMPOKEY_CORE_IO_FILE_FORMATS_H_
#define TEMPOKEY_CORE_IO_FILE_FORMATS_H_

#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <string_view>
#include <variant>

#include "absl/status/statusor.h"
#include "tempokey/core/io/gltf.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/reduce.h"

namespace tempokey::core {

// What a file holds.
enum class FileContent {
  kSampled,  // uniformly sampled channels (.bvh, .csv)
  kKeyed,    // key-frame curves (.json, .anim)
  kEither,   // either, as it comes (.gltf, .glb: LINEAR or CUBICSPLINE samplers, core/io/gltf.h)
};

// One output format. Exactly one of the two formatters is set, the one of `content`; a kEither
// format (glTF) has neither and writes through gltf.h in the `gltf` container.
struct ExportFormat {
  std::string_view name;        // "bvh": what requests name
  std::string_view extension;   // ".bvh"
  std::string_view media_type;  // for downloads: "text/plain; charset=utf-8", ...
  FileContent content = FileContent::kSampled;
  absl::StatusOr<std::string> (*format_sampled)(const Clip& clip) = nullptr;
  absl::StatusOr<std::string> (*format_keyed)(const KeyedClip& keyed) = nullptr;
  GltfContainer gltf = GltfContainer::kText;
};

// What a keyed glTF needs besides the curves: the clip they were reduced from (its rotations are
// fitted again in glTF's quaternion semantics) and the bounds of that fit
// (GltfKeyedOptions: GltfRotationBoundDegrees() and GltfJointTolerance() of the reduction).
struct ExportSource {
  const Clip* clip = nullptr;
  double max_rotation_error_degrees = GltfKeyedOptions{}.max_rotation_error_degrees;
  std::optional<JointTolerance> joint_tolerance = std::nullopt;
};

// The bounds a keyed glTF of a reduction with `options` is fitted to. The CLI and the server's
// downloads both use them, so their files are the same bytes.
//
// GltfRotationBoundDegrees(): its rotation tolerance: every glTF rotation stays within it of the
// source's at every source frame. Unset: kNoRotationBoundDegrees (none) under the joint tolerance
// below, as the reduction lets the joint bound alone choose the bound of a rotation channel whose
// tolerance is not given (reduce.h); the default 0.5 degrees otherwise.
//
// GltfJointTolerance(): the `tolerance` method's joint tolerance: every joint and end site of the
// glTF, as glTF evaluates it, stays within it of its source position at every source frame,
// measured by forward kinematics as the reduction's own joint bound is (gltf.h, "The joint bound
// in glTF"), a rotation bound given holding too. None for the other methods, which take no
// joint tolerance, and under a key budget, which replaces the bounds by a scale of them (the
// reduction then keeps the scaled joint bound, whose keyed translations may be beyond the one
// given: the glTF keeps the rotation bound alone, as it does without a joint tolerance).
double GltfRotationBoundDegrees(const ReduceOptions& options);
std::optional<JointTolerance> GltfJointTolerance(const ReduceOptions& options);

// Every output format of this build, in a stable order (bvh, csv, json, anim, ...).
std::span<const ExportFormat> ExportFormats();

// The format named `name` ("bvh") or with that extension (".bvh"), case-insensitive; null when
// there is none.
const ExportFormat* FindExportFormat(std::string_view name);

// The file bytes of a pipeline output in `format`. A keyed output in a sampled format is baked at
// the rate of the clip its curves came from first (Bake() with no rate, held to `limits`): what
// `tempokey reduce IN -o OUT.bvh` gets from the server's reduce + bake. A keyed output in glTF is
// fitted against `source` (FormatGltfKeyed()).
// Errors: kInvalidArgument for a sampled output in a keyed format ("json holds key-frame curves;
// a sampled clip has none: reduce it first"); kFailedPrecondition for a keyed output in glTF
// without a source clip; the formatter's and Bake()'s errors; kCancelled when `stop` is
// requested during the work that grows faster than the file: a keyed glTF's formatting
// (FormatGltfKeyed(): its translation keys, rotations and rotation fits) and a bake (every 65536
// samples). Writing the bytes of a clip or of curves already made is not stopped: it is linear in
// the file's size, which `limits` bounds.
// Thread-safe: a pure function of its arguments.
absl::StatusOr<std::string> FormatOutput(const std::variant<Clip, KeyedClip>& output,
                                         const ExportFormat& format, const ClipLimits& limits = {},
                                         const ExportSource& source = {},
                                         std::stop_token stop = {});

// Parses the text of a clip file named `file_name` with the reader its extension picks (.bvh:
// ParseBvh(); .csv: ParseCsv() at `csv_frame_time_seconds`, which a CSV file does not store).
// `file_name` prefixes the readers' located messages ("walk.bvh:12:7: expected ...").
// Errors: kInvalidArgument for another extension ("walk.txt: unknown clip format '.txt'
// (expected .bvh, .csv)"), a .csv without a frame time, and the readers' errors.
// Thread-safe.
absl::StatusOr<Clip> ParseClipText(std::string_view text, std::string_view file_name,
                                   std::optional<double> csv_frame_time_seconds,
                                   const ClipLimits& limits = {});

}  // namespace tempokey::core

#endif  // TEMPOKEY_CORE_IO_FILE_FORMATS_H_
