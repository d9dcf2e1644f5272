// Reading the CLI's input clips and writing its outputs, the format chosen by file extension.
// Every output is written atomically (core::WriteFileAtomically): a failed or interrupted run
// leaves the old file or none, never half of one.
#ifndef TEMPOKEY_CLIENT_CLIP_FILES_H_
#define TEMPOKEY_CLIENT_CLIP_FILES_H_

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <variant>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tempokey/core/io/gltf.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/pipeline/pipeline.h"
#include "tempokey/core/reduce/reduce.h"

namespace tempokey::client {

enum class FileFormat {
  kBvh,        // .bvh: hierarchy and motion
  kCsv,        // .csv: one column per channel; the rate is not stored
  kKeyedJson,  // .json: keyed curves (README schema)
  kMayaAnim,   // .anim: Maya ASCII animation curves
  kGltf,       // .gltf: glTF 2.0 (embedded buffer); keyed curves or samples
  kGlb,        // .glb: binary glTF 2.0; keyed curves or samples
};

// ".bvh" -> kBvh, ... (case-insensitive). Errors: a usage error naming `flag` and the path
// ("-o out.txt: unknown output format '.txt' (expected .bvh, .csv)") when the extension is
// not one of `allowed`.
absl::StatusOr<FileFormat> FormatForPath(std::string_view flag, const std::string& path,
                                         std::span<const FileFormat> allowed);

inline constexpr FileFormat kSampledFormats[] = {FileFormat::kBvh, FileFormat::kCsv};
// What a sampled result may be written as (retime): the sampled formats and glTF.
inline constexpr FileFormat kSampledOutputFormats[] = {FileFormat::kBvh, FileFormat::kCsv,
                                                       FileFormat::kGltf, FileFormat::kGlb};
inline constexpr FileFormat kAllFormats[] = {FileFormat::kBvh,       FileFormat::kCsv,
                                             FileFormat::kKeyedJson, FileFormat::kMayaAnim,
                                             FileFormat::kGltf,      FileFormat::kGlb};

// ".bvh", ".csv", ".json", ".anim", ".gltf" or ".glb".
std::string_view ExtensionOf(FileFormat format);

// Whether `format` holds keyed curves only (.json, .anim) rather than samples.
bool IsKeyedFormat(FileFormat format);

// Whether `format` is glTF (.gltf, .glb), which holds either: keyed results as CUBICSPLINE
// samplers, sampled ones as LINEAR samplers (core/io/gltf.h).
bool IsGltfFormat(FileFormat format);

// What a keyed glTF needs besides the curves: the clip that was reduced (its rotations are
// fitted again in glTF's quaternion semantics, core/io/gltf.h) and the bounds of that fit
// (GltfRotationBoundDegrees() and GltfJointTolerance() of the reduce step).
struct GltfExportSource {
  const core::Clip* source = nullptr;
  double max_rotation_error_degrees = core::kDefaultMaxRotationErrorDegrees;
  std::optional<core::JointTolerance> joint_tolerance = std::nullopt;
  // Joints whose rotations are fitted at once (core::GltfKeyedOptions::threads): the same file
  // for any count.
  int threads = 1;
};

// CPUs this process may run on (its affinity mask), at least 1: for work the CLI does itself.
int LocalCpuCount();

// The rotation bound a keyed glTF of `reduce`'s result is fitted to: its rotation tolerance, or
// the default 0.5 degrees when unset (also under a joint tolerance: the glTF's rotations then
// stay within 0.5 degrees of the source's, whatever budgets the Euler curves were given).
double GltfRotationBoundDegrees(const core::ReduceStep& reduce);
// The joint bound a keyed glTF of `reduce`'s result keeps, as glTF evaluates it: its joint
// tolerance (core::GltfJointTolerance(): none for other methods or under a key budget).
std::optional<core::JointTolerance> GltfJointTolerance(const core::ReduceStep& reduce);

// The largest input clip file the CLI reads (BVH or CSV text): a quarter of a gigabyte holds
// some 25 million samples, more than a server accepts by default (32 Mi samples of doubles).
inline constexpr std::int64_t kMaxInputFileBytes = std::int64_t{256} << 20;

// Reads a .bvh, or a .csv at `csv_frame_time_seconds` (the rate is not in the file), with bounded
// memory: a regular file over kMaxInputFileBytes is refused from its size before any byte is
// read, a pipe or FIFO is read up to that cap (and refused when silent for 10 s), a device is
// refused, and a NUL byte (a binary or sparse file) stops the read at its first chunk
// (core::ReadTextFile()).
// Errors: a usage error for another extension, or a .csv without a frame time; the readers'
// own errors ("walk.bvh:12:7: expected ..."; kNotFound "walk.bvh: no such file"; "big.bvh: file
// is 1073741824 bytes, over the limit of 268435456"; "/dev/zero: is a character device, not a
// file").
absl::StatusOr<core::Clip> ReadClipFile(const std::string& path,
                                        std::optional<double> csv_frame_time_seconds);

// Refuses to write `output` over `input`: the same file by device and inode (the same path,
// another path to it, a hard link, a symbolic link to it), unless `overwrite`. An output that
// does not exist yet is never the input.
// Errors: a usage error "-o walk.bvh is the input walk.bvh (the same file); choose another
// output, or give --overwrite to replace the input".
absl::Status CheckOutputIsNotTheInput(const std::string& input, const std::string& output,
                                      bool overwrite, std::string_view flag = "-o");

// A file a command reads or writes, and what it is to the command ("the pipeline").
struct NamedFile {
  std::string path;
  std::string what;
};

// Refuses to write `output` over any of `files` (IsSameFile()), with no way to allow it: for
// files a command writes besides its outputs (a summary), which never replace an input, an
// output or a record the command keeps.
// Errors: a usage error "--summary ops.json is the pipeline; choose another file", naming the
// file as given when the two paths differ: "--summary ./a.bvh is the input (in/a.bvh); ...".
absl::Status CheckWritesNoneOf(const std::string& output, std::string_view flag,
                               std::span<const NamedFile> files);

// Whether `a` and `b` name one file: the same device and inode (symbolic links followed), or,
// when one does not exist yet, the same absolute path once "." and ".." are resolved.
bool IsSameFile(const std::string& a, const std::string& b);

// Writes a sampled clip as .bvh or .csv. Errors: kInvalidArgument for a keyed format or a clip
// BVH cannot hold (no skeleton); write errors naming the path.
absl::Status WriteClipFile(const std::string& path, FileFormat format, const core::Clip& clip);

// Writes a keyed clip as .json or .anim. Errors: kInvalidArgument for a sampled format; write
// errors naming the path.
absl::Status WriteKeyedClipFile(const std::string& path, FileFormat format,
                                const core::KeyedClip& keyed);

// Writes a keyed clip as .gltf or .glb (`format` one of them), its rotations fitted against
// `gltf.source` (core::FormatGltfKeyed()), and returns what the file holds: its keys and, under a
// joint bound, its largest joint error as glTF plays it.
// Errors: kInternal without `gltf.source`; those of core::FormatGltfKeyed() and the write.
absl::StatusOr<core::GltfStats> WriteKeyedGltf(const std::string& path, FileFormat format,
                                               const core::KeyedClip& keyed,
                                               const GltfExportSource& gltf);

// Writes whichever `output` holds, checking that it suits `format`; a keyed result as glTF
// needs `gltf.source`.
// Errors: kInternal when a keyed result meets a sampled format or the reverse, or a keyed glTF
// lacks its source (the CLI builds pipelines so this cannot happen); those of the writers.
absl::Status WriteOutput(const std::string& path, FileFormat format,
                         const std::variant<core::Clip, core::KeyedClip>& output,
                         const GltfExportSource& gltf = {});

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_CLIP_FILES_H_
