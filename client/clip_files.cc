#include "client/clip_files.h"

#include <sched.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "client/cli_errors.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/csv.h"
#include "tempokey/core/io/file_formats.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/io/gltf.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/io/maya_anim.h"
#include "tempokey/core/model/status.h"

namespace tempokey::client {
namespace {

using core::AsAbsl;

struct FormatName {
  FileFormat format;
  std::string_view extension;
};
constexpr FormatName kFormatNames[] = {
    {FileFormat::kBvh, ".bvh"},
    {FileFormat::kCsv, ".csv"},
    {FileFormat::kKeyedJson, ".json"},
    {FileFormat::kMayaAnim, ".anim"},
    {FileFormat::kGltf, ".gltf"},
    {FileFormat::kGlb, ".glb"},
};

core::GltfContainer GltfContainerOf(FileFormat format) {
  return format == FileFormat::kGlb ? core::GltfContainer::kBinary : core::GltfContainer::kText;
}

std::string LowerExtension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension;
}

}  // namespace

std::string_view ExtensionOf(FileFormat format) {
  for (const FormatName& name : kFormatNames) {
    if (name.format == format) return name.extension;
  }
  return "";
}

bool IsKeyedFormat(FileFormat format) {
  return format == FileFormat::kKeyedJson || format == FileFormat::kMayaAnim;
}

bool IsGltfFormat(FileFormat format) {
  return format == FileFormat::kGltf || format == FileFormat::kGlb;
}

absl::StatusOr<FileFormat> FormatForPath(std::string_view flag, const std::string& path,
                                         std::span<const FileFormat> allowed) {
  const std::string extension = LowerExtension(path);
  for (FileFormat format : allowed) {
    if (extension == ExtensionOf(format)) return format;
  }
  std::vector<std::string> names;
  for (FileFormat format : allowed) names.emplace_back(ExtensionOf(format));
  const std::string what = extension.empty() ? std::string("no extension")
                                             : absl::StrCat("unknown format '", extension, "'");
  // A device or FIFO (/dev/null, /dev/stdout) has no extension of its own: a name that links to
  // it gives the format.
  std::error_code error;
  const std::filesystem::file_status status = std::filesystem::status(path, error);
  const bool stream = !error && (std::filesystem::is_character_file(status) ||
                                 std::filesystem::is_fifo(status));
  const std::string hint =
      stream && extension.empty()
          ? absl::StrCat("; a device or FIFO takes the format of a link's name to it: ln -s ",
                         path, " out", names.front())
          : "";
  return UsageError(absl::StrCat(AsAbsl(flag), flag.empty() ? "" : " ", path, ": ", what,
                                 " (expected ", absl::StrJoin(names, ", "), ")", hint));
}

absl::StatusOr<core::Clip> ReadClipFile(const std::string& path,
                                        std::optional<double> csv_frame_time_seconds) {
  TEMPOKEY_ASSIGN_OR_RETURN(FileFormat format, FormatForPath("", path, kSampledFormats));
  if (format == FileFormat::kCsv && !csv_frame_time_seconds) {
    return UsageError(absl::StrCat(path, ": a CSV file does not store its frame rate; give it with "
                                         "--input-fps"));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(const std::string text,
                            core::ReadTextFile(path, kMaxInputFileBytes));
  if (format == FileFormat::kBvh) return core::ParseBvh(text, path);
  return core::ParseCsv(text, path, *csv_frame_time_seconds);
}

namespace {

// Whether `a` and `b` both exist and are one file. stat() follows symbolic links: a link to a
// file is that file.
bool SameExistingFile(const std::string& a, const std::string& b) {
  struct stat sa {};
  struct stat sb {};
  if (::stat(a.c_str(), &sa) != 0 || ::stat(b.c_str(), &sb) != 0) return false;
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

}  // namespace

bool IsSameFile(const std::string& a, const std::string& b) {
  if (SameExistingFile(a, b)) return true;
  // One may not be there yet: the same path once both are made absolute and normal, the links
  // of their existing parts followed, without a trailing separator ("out/", "./out", "out/.").
  auto normal = [](const std::string& path, std::error_code& error) {
    namespace fs = std::filesystem;
    fs::path full = fs::weakly_canonical(fs::absolute(path, error), error).lexically_normal();
    return full.has_filename() ? full : full.parent_path();
  };
  std::error_code error_a, error_b;
  const std::filesystem::path pa = normal(a, error_a);
  const std::filesystem::path pb = normal(b, error_b);
  return !error_a && !error_b && pa == pb;
}

namespace {

// "-o walk.bvh is the input walk.bvh (the same file)"
std::string IsTheInput(std::string_view flag, const std::string& output,
                       const std::string& input) {
  const std::string same = input == output ? "" : absl::StrCat(" ", input);
  return absl::StrCat(AsAbsl(flag), " ", output, " is the input", same, " (the same file)");
}

}  // namespace

absl::Status CheckOutputIsNotTheInput(const std::string& input, const std::string& output,
                                      bool overwrite, std::string_view flag) {
  // No output yet (or no input: reading it reports that) is never the input.
  if (overwrite || !SameExistingFile(input, output)) return absl::OkStatus();
  return UsageError(absl::StrCat(IsTheInput(flag, output, input),
                                 "; choose another output, or give --overwrite to replace the "
                                 "input"));
}

absl::Status CheckWritesNoneOf(const std::string& output, std::string_view flag,
                               std::span<const NamedFile> files) {
  for (const NamedFile& file : files) {
    if (!IsSameFile(file.path, output)) continue;
    const std::string same = file.path == output ? "" : absl::StrCat(" (", file.path, ")");
    return UsageError(absl::StrCat(AsAbsl(flag), " ", output, " is ", AsAbsl(file.what), same,
                                   "; choose another file"));
  }
  return absl::OkStatus();
}

absl::Status WriteClipFile(const std::string& path, FileFormat format, const core::Clip& clip) {
  switch (format) {
    case FileFormat::kBvh:
      return core::WriteBvhFile(path, clip);
    case FileFormat::kCsv:
      return core::WriteCsvFile(path, clip);
    case FileFormat::kGltf:
    case FileFormat::kGlb: {
      TEMPOKEY_ASSIGN_OR_RETURN(core::GltfFile file, core::FormatGltfSampled(clip, GltfContainerOf(format)));
      return core::WriteFileAtomically(path, file.bytes);
    }
    case FileFormat::kKeyedJson:
    case FileFormat::kMayaAnim:
      break;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      path, ": ", AsAbsl(ExtensionOf(format)), " holds keyed curves, not a sampled clip"));
}

absl::Status WriteKeyedClipFile(const std::string& path, FileFormat format,
                                const core::KeyedClip& keyed) {
  switch (format) {
    case FileFormat::kKeyedJson:
      return core::WriteKeyedClipJsonFile(path, keyed);
    case FileFormat::kMayaAnim:
      return core::WriteMayaAnimFile(path, keyed);
    case FileFormat::kGltf:
    case FileFormat::kGlb:
      return absl::InternalError(absl::StrCat(path, ": a keyed glTF needs the source clip"));
    case FileFormat::kBvh:
    case FileFormat::kCsv:
      break;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      path, ": ", AsAbsl(ExtensionOf(format)), " holds sampled clips, not keyed curves"));
}

int LocalCpuCount() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0 && CPU_COUNT(&set) > 0) return CPU_COUNT(&set);
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

absl::StatusOr<core::GltfStats> WriteKeyedGltf(const std::string& path, FileFormat format,
                                               const core::KeyedClip& keyed,
                                               const GltfExportSource& gltf) {
  if (gltf.source == nullptr) {
    return absl::InternalError(absl::StrCat(path, ": a keyed glTF needs the source clip"));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(
      core::GltfFile file,
      core::FormatGltfKeyed(*gltf.source, keyed,
                            {.max_rotation_error_degrees = gltf.max_rotation_error_degrees,
                             .joint_tolerance = gltf.joint_tolerance,
                             .threads = gltf.threads},
                            GltfContainerOf(format)));
  TEMPOKEY_RETURN_IF_ERROR(core::WriteFileAtomically(path, file.bytes));
  return file.stats;
}

absl::Status WriteOutput(const std::string& path, FileFormat format,
                         const std::variant<core::Clip, core::KeyedClip>& output,
                         const GltfExportSource& gltf) {
  if (const auto* keyed = std::get_if<core::KeyedClip>(&output); keyed && IsGltfFormat(format)) {
    return WriteKeyedGltf(path, format, *keyed, gltf).status();
  }
  if (const auto* clip = std::get_if<core::Clip>(&output)) {
    if (IsKeyedFormat(format)) {
      return absl::InternalError(absl::StrCat(path, ": the server returned a sampled clip where "
                                                    "keyed curves were expected"));
    }
    return WriteClipFile(path, format, *clip);
  }
  if (!IsKeyedFormat(format) && !IsGltfFormat(format)) {
    return absl::InternalError(absl::StrCat(path, ": the server returned keyed curves where a "
                                                  "sampled clip was expected"));
  }
  return WriteKeyedClipFile(path, format, std::get<core::KeyedClip>(output));
}

double GltfRotationBoundDegrees(const core::ReduceStep& reduce) {
  return core::GltfRotationBoundDegrees(reduce.options);
}

std::optional<core::JointTolerance> GltfJointTolerance(const core::ReduceStep& reduce) {
  return core::GltfJointTolerance(reduce.options);
}

}  // namespace tempokey::client
