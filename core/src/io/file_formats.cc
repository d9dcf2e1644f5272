#include "tempokey/core/io/file_formats.h"

#include <algorithm>
#include <cctype>
#include <utility>

#include "absl/strings/str_cat.h"
#include "tempokey/core/io/bvh.h"
#include "tempokey/core/io/csv.h"
#include "tempokey/core/io/gltf.h"
#include "tempokey/core/io/keyed_json.h"
#include "tempokey/core/io/maya_anim.h"
#include "tempokey/core/model/status.h"

namespace tempokey::core {
namespace {

constexpr std::string_view kText = "text/plain; charset=utf-8";

// The list: what the CLI writes for each -o extension (client/clip_files.cc), same functions.
constexpr ExportFormat kExportFormats[] = {
    {.name = "bvh", .extension = ".bvh", .media_type = kText, .content = FileContent::kSampled,
     .format_sampled = &FormatBvh},
    {.name = "csv", .extension = ".csv", .media_type = "text/csv; charset=utf-8",
     .content = FileContent::kSampled, .format_sampled = &FormatCsv},
    {.name = "json", .extension = ".json", .media_type = "application/json",
     .content = FileContent::kKeyed, .format_keyed = &FormatKeyedClipJson},
    {.name = "anim", .extension = ".anim", .media_type = kText, .content = FileContent::kKeyed,
     .format_keyed = &FormatMayaAnim},
    // Media types registered with IANA by Khronos (glTF 2.0 specification, "File Extensions and
    // Media Types").
    {.name = "gltf", .extension = ".gltf", .media_type = "model/gltf+json",
     .content = FileContent::kEither, .gltf = GltfContainer::kText},
    {.name = "glb", .extension = ".glb", .media_type = "model/gltf-binary",
     .content = FileContent::kEither, .gltf = GltfContainer::kBinary},
};

bool EqualsIgnoringCase(std::string_view a, std::string_view b) {
  return a.size() == b.size() &&
         std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) ==
                  std::tolower(static_cast<unsigned char>(y));
         });
}

// ".bvh" of "dir/walk.BVH"; "" without a dot in the last path component.
std::string_view ExtensionOf(std::string_view file_name) {
  const std::size_t slash = file_name.find_last_of("/\\");
  const std::string_view base =
      slash == std::string_view::npos ? file_name : file_name.substr(slash + 1);
  const std::size_t dot = base.rfind('.');
  if (dot == std::string_view::npos || dot == 0) return {};
  return base.substr(dot);
}

}  // namespace

std::span<const ExportFormat> ExportFormats() { return kExportFormats; }

const ExportFormat* FindExportFormat(std::string_view name) {
  for (const ExportFormat& format : kExportFormats) {
    if (EqualsIgnoringCase(name, format.name) || EqualsIgnoringCase(name, format.extension)) {
      return &format;
    }
  }
  return nullptr;
}

double GltfRotationBoundDegrees(const ReduceOptions& options) {
  if (options.tolerance.max_rotation_error_degrees) {
    return *options.tolerance.max_rotation_error_degrees;
  }
  return GltfJointTolerance(options) ? kNoRotationBoundDegrees : kDefaultMaxRotationErrorDegrees;
}

std::optional<JointTolerance> GltfJointTolerance(const ReduceOptions& options) {
  if (options.method != ReduceMethod::kTolerance || options.tolerance.key_budget) {
    return std::nullopt;
  }
  return options.tolerance.joint_tolerance;
}

namespace {

absl::StatusOr<std::string> FormatGltf(const std::variant<Clip, KeyedClip>& output,
                                       const ExportFormat& format, const ExportSource& source,
                                       std::stop_token stop) {
  if (const auto* clip = std::get_if<Clip>(&output)) {
    TEMPOKEY_ASSIGN_OR_RETURN(GltfFile file, FormatGltfSampled(*clip, format.gltf));
    return std::move(file.bytes);
  }
  if (source.clip == nullptr) {
    return absl::FailedPreconditionError(absl::StrCat(
        "a keyed ", AsAbsl(format.name), " file is fitted against the clip the curves were "
        "reduced from, which is not available"));
  }
  TEMPOKEY_ASSIGN_OR_RETURN(
      GltfFile file,
      FormatGltfKeyed(
          *source.clip, std::get<KeyedClip>(output),
          GltfKeyedOptions{.max_rotation_error_degrees = source.max_rotation_error_degrees,
                           .joint_tolerance = source.joint_tolerance},
          format.gltf, std::move(stop)));
  return std::move(file.bytes);
}

}  // namespace

absl::StatusOr<std::string> FormatOutput(const std::variant<Clip, KeyedClip>& output,
                                         const ExportFormat& format, const ClipLimits& limits,
                                         const ExportSource& source, std::stop_token stop) {
  if (format.content == FileContent::kEither) {
    return FormatGltf(output, format, source, std::move(stop));
  }
  if (const auto* keyed = std::get_if<KeyedClip>(&output)) {
    if (format.content == FileContent::kKeyed) return format.format_keyed(*keyed);
    TEMPOKEY_ASSIGN_OR_RETURN(Clip baked, Bake(*keyed, std::nullopt, limits, std::move(stop)));
    return format.format_sampled(baked);
  }
  if (format.content == FileContent::kKeyed) {
    return absl::InvalidArgumentError(absl::StrCat(
        AsAbsl(format.name), " holds key-frame curves; a sampled clip has none: reduce it first"));
  }
  return format.format_sampled(std::get<Clip>(output));
}

absl::StatusOr<Clip> ParseClipText(std::string_view text, std::string_view file_name,
                                   std::optional<double> csv_frame_time_seconds,
                                   const ClipLimits& limits) {
  const std::string_view extension = ExtensionOf(file_name);
  if (EqualsIgnoringCase(extension, ".bvh")) return ParseBvh(text, file_name, limits);
  if (EqualsIgnoringCase(extension, ".csv")) {
    if (!csv_frame_time_seconds) {
      return absl::InvalidArgumentError(
          absl::StrCat(AsAbsl(file_name), ": a CSV file does not store its frame rate; give it"));
    }
    return ParseCsv(text, file_name, *csv_frame_time_seconds, limits);
  }
  const std::string what = extension.empty()
                               ? std::string("no extension")
                               : absl::StrCat("unknown clip format '", AsAbsl(extension), "'");
  return absl::InvalidArgumentError(
      absl::StrCat(AsAbsl(file_name), ": ", what, " (expected .bvh, .csv)"));
}

}  // namespace tempokey::core
