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
#include <string>
#include <string_view>
#include <variant>

#include "absl/status/statusor.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"

namespace tempokey::core {

// What a file holds.
enum class FileContent {
  kSampled,  // uniformly sampled channels (.bvh, .csv)
  kKeyed,    // key-frame curves (.json, .anim)
};

// One output format. Exactly one of the two formatters is set, the one of `content`.
struct ExportFormat {
  std::string_view name;        // "bvh": what requests name
  std::string_view extension;   // ".bvh"
  std::string_view media_type;  // for downloads: "text/plain; charset=utf-8", ...
  FileContent content = FileContent::kSampled;
  absl::StatusOr<std::string> (*format_sampled)(const Clip& clip) = nullptr;
  absl::StatusOr<std::string> (*format_keyed)(const KeyedClip& keyed) = nullptr;
};

// Every output format of this build, in a stable order (bvh, csv, json, anim, ...).
std::span<const ExportFormat> ExportFormats();

// The format named `name` ("bvh") or with that extension (".bvh"), case-insensitive; null when
// there is none.
const ExportFormat* FindExportFormat(std::string_view name);

// The file bytes of a pipeline output in `format`. A keyed output in a sampled format is baked at
// the rate of the clip its curves came from first (Bake() with no rate, held to `limits`): what
// `tempokey reduce IN -o OUT.bvh` gets from the server's reduce + bake.
// Errors: kInvalidArgument for a sampled output in a keyed format ("json holds key-frame curves;
// a sampled clip has none: reduce it first"), and the formatter's and Bake()'s errors.
// Thread-safe: a pure function of its arguments.
absl::StatusOr<std::string> FormatOutput(const std::variant<Clip, KeyedClip>& output,
                                         const ExportFormat& format, const ClipLimits& limits = {});

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
