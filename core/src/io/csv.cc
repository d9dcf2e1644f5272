#include "tempokey/core/io/csv.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"
#include "text_scan.h"

namespace tempokey::core {
namespace {

using text_scan::FindNonText;
using text_scan::IsBlank;
using text_scan::IsLineBreak;

// ReadCsvFile's size cap per allowed sample: the longest shortest round-trip double plus a
// separator, with room for padding around fields.
constexpr std::int64_t kFileBytesPerSample = 2 * (kMaxDoubleChars + 1);
constexpr std::int64_t kFileBytesBase = 1 << 20;  // the header row

// A first column with one of these names (any case) holds times or frame numbers: skipped.
bool IsIndexColumnName(std::string_view name) {
  return absl::EqualsIgnoreCase(AsAbsl(name), "time") ||
         absl::EqualsIgnoreCase(AsAbsl(name), "frame");
}

// "Hips.Xrotation" -> joint "Hips", kind kXRotation; otherwise nullopt (a scalar column).
struct JointColumn {
  std::string_view joint;
  ChannelKind kind;
};
std::optional<JointColumn> SplitJointColumn(std::string_view name) {
  const std::size_t dot = name.rfind('.');
  if (dot == std::string_view::npos || dot == 0) return std::nullopt;
  const std::optional<ChannelKind> kind = ParseChannelKind(name.substr(dot + 1));
  if (!kind) return std::nullopt;
  return JointColumn{name.substr(0, dot), *kind};
}

struct Location {
  std::int64_t line = 1;
  std::int64_t column = 1;
};

// One field of a row: its text without surrounding blanks, and where that text starts.
struct Field {
  std::string_view text;
  Location location;
};

class CsvParser {
 public:
  CsvParser(std::string_view text, std::string_view source_name, double frame_time_seconds,
            const ClipLimits& limits)
      : begin_(text.data()),
        end_(text.data() + text.size()),
        p_(begin_),
        line_start_(begin_),
        source_name_(source_name),
        frame_time_seconds_(frame_time_seconds),
        limits_(limits) {}

  absl::StatusOr<Clip> Parse() {
    TEMPOKEY_RETURN_IF_ERROR(CheckFrameTime(frame_time_seconds_));
    if (std::string_view(begin_, end_ - begin_).substr(0, 3) == "\xEF\xBB\xBF") {
      p_ += 3;
      line_start_ = p_;
    }
    clip_.name = text_scan::FileStem(source_name_);
    clip_.frame_time_seconds = frame_time_seconds_;
    TEMPOKEY_RETURN_IF_ERROR(ParseHeader());
    TEMPOKEY_RETURN_IF_ERROR(ParseRows());
    if (absl::Status layout = ValidateClipLayout(clip_, limits_); !layout.ok()) {
      return absl::InternalError(absl::StrCat(
          AsAbsl(source_name_), ": parser produced an invalid clip: ", layout.message()));
    }
    return std::move(clip_);
  }

 private:
  Location Here() const { return {line_, p_ - line_start_ + 1}; }
  bool AtLineEnd() const { return p_ == end_ || IsLineBreak(*p_); }

  absl::Status Error(Location at, std::string_view message) const {
    return absl::InvalidArgumentError(absl::StrCat(AsAbsl(source_name_), ":", at.line, ":",
                                                   at.column, ": ", AsAbsl(message)));
  }

  // Skips lines holding only blanks; stops at the first character of a non-blank line (or at
  // the end of the text).
  void SkipBlankLines() {
    for (;;) {
      const char* q = p_;
      while (q != end_ && IsBlank(*q)) ++q;
      if (q == end_) {
        p_ = q;
        return;
      }
      if (!IsLineBreak(*q)) return;
      p_ = q;
      SkipLineBreak();
    }
  }
  void SkipLineBreak() {
    if (p_ == end_) return;
    if (*p_ == '\r' && p_ + 1 != end_ && p_[1] == '\n') ++p_;
    ++p_;
    ++line_;
    line_start_ = p_;
  }

  // Reads the field at the cursor up to ',' or the end of the line, leaving the cursor on
  // that ',' or line end.
  Field TakeField() {
    while (p_ != end_ && IsBlank(*p_)) ++p_;
    Field field{{}, Here()};
    const char* start = p_;
    while (p_ != end_ && *p_ != ',' && !IsLineBreak(*p_)) ++p_;
    const char* stop = p_;
    while (stop != start && IsBlank(stop[-1])) --stop;
    field.text = std::string_view(start, static_cast<std::size_t>(stop - start));
    return field;
  }

  absl::Status CheckText(const Field& field) const {
    const std::size_t bad = FindNonText(field.text);
    if (bad == std::string_view::npos) return absl::OkStatus();
    Location at = field.location;
    at.column += static_cast<std::int64_t>(bad);
    return Error(at, absl::StrFormat("unexpected byte 0x%02x; the file looks binary, not CSV text",
                                     static_cast<unsigned char>(field.text[bad])));
  }

  absl::Status ParseHeader() {
    SkipBlankLines();
    if (p_ == end_) {
      return Error(Here(), begin_ == end_
                               ? "expected a header row of column names, got an empty file"
                               : "expected a header row of column names, got end of file");
    }
    absl::flat_hash_map<std::string_view, std::int64_t> seen;  // name -> column (1-based)
    absl::flat_hash_map<std::string_view, int> joint_index;
    for (std::int64_t column = 1;; ++column) {
      const Field field = TakeField();
      TEMPOKEY_RETURN_IF_ERROR(CheckText(field));
      if (field.text.empty()) {
        return Error(field.location, "expected a column name, got an empty field");
      }
      if (field.text.find('"') != std::string_view::npos) {
        return Error(field.location, absl::StrCat("quoted column names are not supported, got ",
                                                  QuoteForMessage(field.text)));
      }
      ++field_count_;
      if (column == 1 && IsIndexColumnName(field.text)) {
        skip_first_field_ = true;
      } else {
        if (const auto [first, inserted] = seen.try_emplace(field.text, column); !inserted) {
          return Error(field.location,
                       absl::StrCat("duplicate column name ", QuoteForMessage(field.text),
                                    ", first in column ", first->second));
        }
        if (static_cast<std::int64_t>(clip_.channels.size()) >= limits_.max_channels) {
          return Error(field.location, absl::StrCat("more than ", limits_.max_channels,
                                                    " channel columns, the limit"));
        }
        Channel channel;
        if (const std::optional<JointColumn> joint_column = SplitJointColumn(field.text)) {
          auto [it, added] = joint_index.try_emplace(
              joint_column->joint, static_cast<int>(clip_.skeleton.joints.size()));
          if (added) {
            if (static_cast<std::int64_t>(clip_.skeleton.joints.size()) >= limits_.max_joints) {
              return Error(field.location, absl::StrCat("more than ", limits_.max_joints,
                                                        " joints, the limit"));
            }
            Joint joint;
            joint.name = std::string(joint_column->joint);
            clip_.skeleton.joints.push_back(std::move(joint));
          }
          Joint& joint = clip_.skeleton.joints[it->second];
          for (int existing : joint.channels) {
            if (clip_.channels[existing].kind == joint_column->kind) {
              // Unreachable after the duplicate-name check; kept so the skeleton invariant
              // does not rest on it.
              return Error(field.location, absl::StrCat("duplicate column name ",
                                                        QuoteForMessage(field.text)));
            }
          }
          channel.joint = it->second;
          channel.kind = joint_column->kind;
          joint.channels.push_back(static_cast<int>(clip_.channels.size()));
        } else {
          channel.name = std::string(field.text);
        }
        clip_.channels.push_back(std::move(channel));
      }
      if (AtLineEnd()) break;
      ++p_;  // ','
    }
    if (clip_.channels.empty()) {
      return Error(Here(), "expected at least one channel column after the index column");
    }
    SkipLineBreak();
    return absl::OkStatus();
  }

  std::string FieldCountMessage(std::int64_t row, std::int64_t found) const {
    return absl::StrCat("row ", row, " has ", found, found == 1 ? " field" : " fields",
                        ", expected ", field_count_);
  }

  absl::Status ParseRows() {
    const std::size_t channel_count = clip_.channels.size();
    const auto channels = static_cast<std::int64_t>(channel_count);
    // Size the columns for the rows there can be: at most one per line break, and a row of n
    // fields takes at least 2n - 1 bytes, so a short file cannot claim a large allocation.
    const auto line_breaks = static_cast<std::int64_t>(std::count(p_, end_, '\n')) + 1;
    const std::int64_t rows_that_fit = (end_ - p_) / (2 * field_count_ - 1) + 1;
    const std::int64_t expected_rows = std::min(
        {line_breaks, rows_that_fit, limits_.max_frames, limits_.max_samples / channels});
    for (Channel& channel : clip_.channels) {
      channel.samples.reserve(static_cast<std::size_t>(std::max<std::int64_t>(expected_rows, 0)));
    }

    std::int64_t rows = 0;
    for (;;) {
      SkipBlankLines();
      if (p_ == end_) break;
      const Location row_start = Here();
      ++rows;
      if (rows > limits_.max_frames) {
        return Error(row_start, absl::StrCat("row ", rows, " is over the limit of ",
                                             limits_.max_frames, " frames"));
      }
      if (rows > limits_.max_samples / channels) {
        return Error(row_start, absl::StrCat(rows, " rows x ", channels,
                                             " channels is over the limit of ",
                                             limits_.max_samples, " samples"));
      }
      std::size_t channel = 0;
      for (std::int64_t f = 0; f < field_count_; ++f) {
        if (f != 0) {
          if (AtLineEnd()) {
            return Error(Here(), FieldCountMessage(rows, f));
          }
          ++p_;  // ','
        }
        const Field field = TakeField();
        if (f == 0 && skip_first_field_) continue;
        double value = 0.0;
        const NumberError error = ParseDoubleToken(field.text, value);
        if (error != NumberError::kNone) {
          TEMPOKEY_RETURN_IF_ERROR(CheckText(field));
          return Error(field.location, DescribeNumberError(error, field.text));
        }
        if (!(std::abs(value) <= kMaxSampleMagnitude)) {
          return Error(field.location,
                       absl::StrCat("sample ", QuoteForMessage(field.text), " is beyond the +-",
                                    DescribeDouble(kMaxSampleMagnitude), " a clip may hold"));
        }
        clip_.channels[channel++].samples.push_back(value);
      }
      if (!AtLineEnd()) {
        const Location extra{line_, p_ - line_start_ + 2};  // just after the ','
        std::int64_t found = field_count_;
        while (!AtLineEnd()) {
          if (*p_ == ',') ++found;
          ++p_;
        }
        return Error(extra, FieldCountMessage(rows, found));
      }
      SkipLineBreak();
    }
    if (rows == 0) {
      return Error(Here(), "expected at least one row of values after the header, got end of file");
    }
    clip_.frame_count = rows;
    return absl::OkStatus();
  }

  const char* const begin_;
  const char* const end_;
  const char* p_;
  std::int64_t line_ = 1;
  const char* line_start_;
  std::string_view source_name_;
  double frame_time_seconds_;
  const ClipLimits& limits_;

  Clip clip_;
  std::int64_t field_count_ = 0;  // fields per row, the index column included
  bool skip_first_field_ = false;
};

// A column name that reads back as the same channel.
absl::Status CheckWritableColumnName(const Clip& clip, int index, std::string_view name,
                                     bool first) {
  auto refuse = [&](std::string_view why) {
    return absl::InvalidArgumentError(absl::StrCat("cannot write CSV: ", ChannelLabel(clip, index),
                                                   ": ", AsAbsl(why)));
  };
  if (name.empty()) return refuse("the column name is empty");
  if (name.find_first_of(",\"\r\n") != std::string_view::npos) {
    return refuse("the column name contains a comma, a quote or a line break");
  }
  if (IsBlank(name.front()) || IsBlank(name.back())) {
    return refuse("the column name starts or ends with whitespace");
  }
  if (FindNonText(name) != std::string_view::npos) {
    return refuse("the column name contains a control character or invalid UTF-8");
  }
  if (first && IsIndexColumnName(name)) {
    return refuse("a first column named time or frame is read back as an index and skipped");
  }
  // Found by fuzzing: a reader drops a byte order mark at the start of the text, so a first
  // column whose name begins with one would read back renamed (or, alone, not at all).
  if (first && name.substr(0, 3) == "\xEF\xBB\xBF") {
    return refuse("a first column name starting with a byte order mark loses it when read back");
  }
  const Channel& channel = clip.channels[index];
  const bool reads_as_joint = SplitJointColumn(name).has_value();
  const bool is_joint = channel.joint >= 0 && channel.kind != ChannelKind::kScalar;
  if (reads_as_joint != is_joint) {
    return refuse(is_joint ? "the joint name cannot be read back from the column name"
                           : "a scalar channel named like a joint channel reads back as one");
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<Clip> ParseCsv(std::string_view text, std::string_view source_name,
                              double frame_time_seconds, const ClipLimits& limits) {
  return CsvParser(text, source_name, frame_time_seconds, limits).Parse();
}

absl::StatusOr<Clip> ReadCsvFile(const std::string& path, double frame_time_seconds,
                                 const ClipLimits& limits) {
  constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
  const std::int64_t samples = std::max<std::int64_t>(limits.max_samples, 0);
  const std::int64_t max_bytes = samples > (kMax - kFileBytesBase) / kFileBytesPerSample
                                     ? kMax
                                     : kFileBytesBase + samples * kFileBytesPerSample;
  TEMPOKEY_ASSIGN_OR_RETURN(const std::string text, ReadFile(path, max_bytes));
  return ParseCsv(text, path, frame_time_seconds, limits);
}

absl::StatusOr<std::string> FormatCsv(const Clip& clip) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  std::string out;
  absl::flat_hash_map<std::string, int> names;
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    const int index = static_cast<int>(c);
    std::string name = ChannelName(clip, index);
    TEMPOKEY_RETURN_IF_ERROR(CheckWritableColumnName(clip, index, name, c == 0));
    if (c != 0) out += ',';
    out += name;
    if (const auto [first, inserted] = names.try_emplace(std::move(name), index); !inserted) {
      return absl::InvalidArgumentError(
          absl::StrCat("cannot write CSV: ", ChannelLabel(clip, index), " has the same name as ",
                       ChannelLabel(clip, first->second)));
    }
  }
  out += '\n';

  const std::size_t channel_count = clip.channels.size();
  const auto frames = static_cast<std::size_t>(clip.frame_count);
  const std::size_t row_bound = channel_count * (kMaxDoubleChars + 1) + 1;
  std::size_t used = out.size();
  out.resize(used + std::min<std::size_t>(frames, 64) * row_bound);
  for (std::size_t f = 0; f < frames; ++f) {
    if (out.size() - used < row_bound) out.resize(std::max(out.size() * 2, used + row_bound));
    char* p = out.data() + used;
    for (std::size_t c = 0; c < channel_count; ++c) {
      if (c != 0) *p++ = ',';
      p = WriteDouble(p, clip.channels[c].samples[f]);
    }
    *p++ = '\n';
    used = static_cast<std::size_t>(p - out.data());
  }
  out.resize(used);
  return out;
}

absl::Status WriteCsvFile(const std::string& path, const Clip& clip) {
  TEMPOKEY_ASSIGN_OR_RETURN(const std::string text, FormatCsv(clip));
  return WriteFileAtomically(path, text);
}

}  // namespace tempokey::core
