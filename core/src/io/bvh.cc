#include "tempokey/core/io/bvh.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <limits>
#include <system_error>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "tempokey/core/io/file_io.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"
#include "text_scan.h"

namespace tempokey::core {
namespace {

constexpr int kMaxChannelsPerJoint = 6;
// ReadBvhFile's size cap: enough for every allowed sample written in the longest shortest
// round-trip form plus a separator, and for a generous hierarchy line budget per joint.
constexpr std::int64_t kFileBytesPerSample = kMaxDoubleChars + 1;
constexpr std::int64_t kFileBytesPerJoint = 1024;
constexpr std::int64_t kFileBytesBase = 4096;

using text_scan::FindNonText;
using text_scan::IsBlank;
using text_scan::IsControl;
using text_scan::IsLineBreak;
using text_scan::IsSpace;

inline bool IsBrace(char c) { return c == '{' || c == '}'; }

struct Location {
  std::int64_t line = 1;
  std::int64_t column = 1;
};

struct Token {
  std::string_view text;  // empty at the end of a line or of the file
  Location location;
  bool at_end_of_file = false;
};

// A joint whose '{' is open, with what may come next in its body.
struct OpenJoint {
  enum class Stage { kExpectOffset, kExpectChannelsOrChildren, kExpectChildren };
  int index = 0;
  Stage stage = Stage::kExpectOffset;
};

class BvhParser {
 public:
  BvhParser(std::string_view text, std::string_view source_name, const ClipLimits& limits)
      : begin_(text.data()),
        end_(text.data() + text.size()),
        p_(begin_),
        line_start_(begin_),
        source_name_(source_name),
        limits_(limits) {}

  absl::StatusOr<Clip> Parse() {
    if (begin_ == end_) return Error({1, 1}, "expected HIERARCHY, got an empty file");
    // A UTF-8 byte order mark is harmless; columns on line 1 count from after it.
    if (std::string_view(begin_, end_ - begin_).substr(0, 3) == "\xEF\xBB\xBF") {
      p_ += 3;
      line_start_ = p_;
    }
    clip_.name = text_scan::FileStem(source_name_);
    TEMPOKEY_RETURN_IF_ERROR(ParseHierarchy());
    TEMPOKEY_RETURN_IF_ERROR(ParseMotionHeader());
    TEMPOKEY_RETURN_IF_ERROR(ParseMotionRows());
    // Everything ValidateClipLayout() checks was checked above with a location; this guards the
    // parser itself.
    if (absl::Status layout = ValidateClipLayout(clip_, limits_); !layout.ok()) {
      return absl::InternalError(
          absl::StrCat(AsAbsl(source_name_), ": parser produced an invalid clip: ",
                       layout.message()));
    }
    return std::move(clip_);
  }

 private:
  // --- Cursor -------------------------------------------------------------------------------

  Location Here() const { return {line_, p_ - line_start_ + 1}; }
  bool AtEnd() const { return p_ == end_; }
  bool AtLineEnd() const { return p_ == end_ || IsLineBreak(*p_); }

  void SkipBlanks() {
    while (p_ != end_ && IsBlank(*p_)) ++p_;
  }
  // Precondition: at '\r' or '\n'. Consumes one line break ("\r\n", "\n" or "\r").
  void SkipLineBreak() {
    if (*p_ == '\r' && p_ + 1 != end_ && p_[1] == '\n') ++p_;
    ++p_;
    ++line_;
    line_start_ = p_;
  }
  void SkipSpace() {
    for (;;) {
      SkipBlanks();
      if (p_ == end_ || !IsLineBreak(*p_)) return;
      SkipLineBreak();
    }
  }

  // The token at the cursor: a brace alone, or a run of characters up to whitespace or a brace.
  std::string_view TokenText() const {
    if (p_ == end_ || IsSpace(*p_)) return {};
    if (IsBrace(*p_)) return {p_, 1};
    const char* q = p_;
    while (q != end_ && !IsSpace(*q) && !IsBrace(*q)) ++q;
    return {p_, static_cast<std::size_t>(q - p_)};
  }
  // The run of non-space characters at `at` (what a number error quotes).
  std::string_view WordAt(const char* at) const {
    const char* q = at;
    while (q != end_ && !IsSpace(*q)) ++q;
    return {at, static_cast<std::size_t>(q - at)};
  }

  // Reads the token at the cursor, refusing bytes that are not text.
  absl::StatusOr<Token> TakeToken() {
    Token token{TokenText(), Here(), AtEnd()};
    if (std::size_t bad = FindNonText(token.text); bad != std::string_view::npos) {
      return NotText(token, bad);
    }
    p_ += token.text.size();
    return token;
  }
  // The next token after any whitespace and line breaks.
  absl::StatusOr<Token> NextToken() {
    SkipSpace();
    return TakeToken();
  }
  // The next token on this line; empty at the end of the line.
  absl::StatusOr<Token> NextTokenOnLine() {
    SkipBlanks();
    return TakeToken();
  }

  // "end of file", "end of line" or the quoted token.
  static std::string Describe(const Token& token) {
    if (!token.text.empty()) return QuoteForMessage(token.text);
    return token.at_end_of_file ? "end of file" : "end of line";
  }

  // --- Errors -------------------------------------------------------------------------------

  absl::Status Error(Location at, std::string_view message) const {
    return absl::InvalidArgumentError(absl::StrCat(AsAbsl(source_name_), ":", at.line, ":",
                                                   at.column, ": ", AsAbsl(message)));
  }
  absl::Status Expected(std::string_view what, const Token& got) const {
    return Error(got.location, absl::StrCat("expected ", AsAbsl(what), ", got ", Describe(got)));
  }
  absl::Status NotText(const Token& token, std::size_t offset) const {
    Location at = token.location;
    at.column += static_cast<std::int64_t>(offset);
    return Error(at, absl::StrFormat("unexpected byte 0x%02x; the file looks binary, not BVH text",
                                     static_cast<unsigned char>(token.text[offset])));
  }
  // The error for a word at `at` that should have been a number, or that ended wrongly.
  absl::Status BadNumber(const char* at, NumberError error) const {
    const std::string_view word = WordAt(at);
    const Location location{line_, at - line_start_ + 1};
    if (std::size_t bad = FindNonText(word); bad != std::string_view::npos) {
      return NotText(Token{word, location, false}, bad);
    }
    return Error(location, DescribeNumberError(error, word));
  }

  // --- Numbers ------------------------------------------------------------------------------

  // "sample 1e12 is beyond the +-1e+09 a clip may hold" (clip.h says why).
  static std::string OutOfRangeMessage(std::string_view what, std::string_view word) {
    return absl::StrCat(AsAbsl(what), " ", QuoteForMessage(word), " is beyond the +-",
                        DescribeDouble(kMaxSampleMagnitude), " a clip may hold");
  }

  // Reads one number at the cursor; it must end at whitespace or the end of the file.
  absl::StatusOr<double> TakeNumber() {
    const std::string_view word = WordAt(p_);
    double value = 0.0;
    const NumberError error = ParseDoubleToken(word, value);
    if (error != NumberError::kNone) return BadNumber(p_, error);
    p_ += word.size();
    return value;
  }

  // Reads the three numbers of an OFFSET line (the keyword already read).
  absl::StatusOr<Vec3> TakeOffset() {
    Vec3 offset{};
    for (int i = 0; i < 3; ++i) {
      SkipBlanks();
      if (AtLineEnd()) {
        return Error(Here(), absl::StrCat("expected 3 numbers after OFFSET, found ", i));
      }
      const Location at = Here();
      const std::string_view word = WordAt(p_);
      TEMPOKEY_ASSIGN_OR_RETURN(offset[i], TakeNumber());
      if (!(std::abs(offset[i]) <= kMaxSampleMagnitude)) {
        return Error(at, OutOfRangeMessage("offset", word));
      }
    }
    TEMPOKEY_ASSIGN_OR_RETURN(Token extra, NextTokenOnLine());
    if (!extra.text.empty()) {
      return Expected("end of line after the 3 numbers of OFFSET", extra);
    }
    return offset;
  }

  // --- Hierarchy ----------------------------------------------------------------------------

  absl::Status ParseHierarchy() {
    TEMPOKEY_ASSIGN_OR_RETURN(Token keyword, NextToken());
    if (keyword.text != "HIERARCHY") return Expected("HIERARCHY", keyword);
    for (;;) {
      TEMPOKEY_ASSIGN_OR_RETURN(Token token, NextToken());
      if (token.text == "ROOT") {
        TEMPOKEY_RETURN_IF_ERROR(ParseJointTree(token));
      } else if (token.text == "MOTION" && !clip_.skeleton.joints.empty()) {
        motion_location_ = token.location;
        return absl::OkStatus();
      } else {
        return Expected(clip_.skeleton.joints.empty() ? "ROOT" : "ROOT or MOTION", token);
      }
    }
  }

  // Reads a joint's name and '{' after ROOT or JOINT, adds the joint and opens it.
  absl::Status OpenJointAfter(const Token& keyword, int parent) {
    TEMPOKEY_ASSIGN_OR_RETURN(Token name, NextTokenOnLine());
    if (name.text.empty() || IsBrace(name.text[0])) {
      return Expected(absl::StrCat("a joint name after ", AsAbsl(keyword.text)), name);
    }
    const int depth = static_cast<int>(open_.size()) + 1;
    if (depth > limits_.max_depth) {
      return Error(keyword.location,
                   absl::StrCat("joint ", QuoteForMessage(name.text), " is nested ", depth,
                                " deep, over the limit of ", limits_.max_depth));
    }
    if (static_cast<std::int64_t>(clip_.skeleton.joints.size()) >= limits_.max_joints) {
      return Error(keyword.location,
                   absl::StrCat("joint ", QuoteForMessage(name.text), " is over the limit of ",
                                limits_.max_joints, " joints"));
    }
    const auto [first, inserted] = joint_lines_.try_emplace(name.text, name.location.line);
    if (!inserted) {
      return Error(name.location,
                   absl::StrCat("duplicate joint name ", QuoteForMessage(name.text),
                                ", first defined on line ", first->second));
    }
    TEMPOKEY_ASSIGN_OR_RETURN(Token brace, NextToken());
    if (brace.text != "{") return Expected("'{' after joint name", brace);

    Joint joint;
    joint.name = std::string(name.text);
    joint.parent = parent;
    clip_.skeleton.joints.push_back(std::move(joint));
    joint_opened_on_line_.push_back(brace.location.line);
    open_.push_back({static_cast<int>(clip_.skeleton.joints.size()) - 1,
                     OpenJoint::Stage::kExpectOffset});
    return absl::OkStatus();
  }

  // Reads a whole ROOT block. Iterative, so nesting depth costs heap, not stack.
  absl::Status ParseJointTree(const Token& root_keyword) {
    TEMPOKEY_RETURN_IF_ERROR(OpenJointAfter(root_keyword, -1));
    while (!open_.empty()) {
      OpenJoint& top = open_.back();
      TEMPOKEY_ASSIGN_OR_RETURN(Token token, NextToken());
      const std::string_view word = token.text;
      if (top.stage == OpenJoint::Stage::kExpectOffset) {
        if (word != "OFFSET") return Expected("OFFSET", token);
        TEMPOKEY_ASSIGN_OR_RETURN(clip_.skeleton.joints[top.index].offset, TakeOffset());
        top.stage = OpenJoint::Stage::kExpectChannelsOrChildren;
        continue;
      }
      if (word == "CHANNELS" && top.stage == OpenJoint::Stage::kExpectChannelsOrChildren) {
        TEMPOKEY_RETURN_IF_ERROR(ParseChannels(top.index));
        top.stage = OpenJoint::Stage::kExpectChildren;
      } else if (word == "JOINT") {
        top.stage = OpenJoint::Stage::kExpectChildren;
        // May reallocate open_: `top` is not used after this.
        TEMPOKEY_RETURN_IF_ERROR(OpenJointAfter(token, top.index));
      } else if (word == "End") {
        top.stage = OpenJoint::Stage::kExpectChildren;
        TEMPOKEY_RETURN_IF_ERROR(ParseEndSite(top.index));
      } else if (word == "}") {
        open_.pop_back();
      } else if (token.at_end_of_file) {
        const Joint& joint = clip_.skeleton.joints[top.index];
        return Expected(absl::StrCat("'}' closing joint ", QuoteForMessage(joint.name),
                                     " from line ", joint_opened_on_line_[top.index]),
                        token);
      } else {
        return Expected(top.stage == OpenJoint::Stage::kExpectChannelsOrChildren
                            ? "CHANNELS, JOINT, End Site or '}'"
                            : "JOINT, End Site or '}'",
                        token);
      }
    }
    return absl::OkStatus();
  }

  absl::Status ParseChannels(int joint_index) {
    TEMPOKEY_ASSIGN_OR_RETURN(Token count_token, NextTokenOnLine());
    int count = 0;
    const char* count_end = count_token.text.data() + count_token.text.size();
    const auto [end, ec] = std::from_chars(count_token.text.data(), count_end, count);
    if (count_token.text.empty() || ec != std::errc() || end != count_end || count < 1 ||
        count > kMaxChannelsPerJoint) {
      return Expected(absl::StrCat("a channel count from 1 to ", kMaxChannelsPerJoint,
                                   " after CHANNELS"),
                      count_token);
    }
    Joint& joint = clip_.skeleton.joints[joint_index];
    for (int i = 0; i < count; ++i) {
      TEMPOKEY_ASSIGN_OR_RETURN(Token name, NextTokenOnLine());
      if (name.text.empty()) {
        return Error(count_token.location,
                     absl::StrCat("CHANNELS declares ", count, " channels but ", i,
                                  i == 1 ? " name follows" : " names follow"));
      }
      const std::optional<ChannelKind> kind = ParseChannelKind(name.text);
      if (!kind) {
        return Error(name.location,
                     absl::StrCat("unknown channel name ", QuoteForMessage(name.text),
                                  ", expected Xposition, Yposition, Zposition, Xrotation, "
                                  "Yrotation or Zrotation"));
      }
      for (int existing : joint.channels) {
        if (clip_.channels[existing].kind == *kind) {
          return Error(name.location,
                       absl::StrCat("channel ", AsAbsl(name.text), " appears twice on joint ",
                                    QuoteForMessage(joint.name)));
        }
      }
      if (static_cast<std::int64_t>(clip_.channels.size()) >= limits_.max_channels) {
        return Error(name.location,
                     absl::StrCat("channel ", clip_.channels.size() + 1, " (", joint.name, ".",
                                  AsAbsl(name.text), ") is over the limit of ",
                                  limits_.max_channels, " channels"));
      }
      Channel channel;
      channel.joint = joint_index;
      channel.kind = *kind;
      joint.channels.push_back(static_cast<int>(clip_.channels.size()));
      clip_.channels.push_back(std::move(channel));
    }
    SkipBlanks();
    if (!AtLineEnd()) {
      int found = count;
      for (const char* q = p_; q != end_ && !IsLineBreak(*q);) {
        while (q != end_ && IsBlank(*q)) ++q;
        if (q == end_ || IsLineBreak(*q)) break;
        ++found;
        while (q != end_ && !IsSpace(*q)) ++q;
      }
      return Error(count_token.location, absl::StrCat("CHANNELS declares ", count,
                                                      " channels but ", found, " names follow"));
    }
    return absl::OkStatus();
  }

  // After "End": "Site { OFFSET x y z }".
  absl::Status ParseEndSite(int joint_index) {
    TEMPOKEY_ASSIGN_OR_RETURN(Token site, NextTokenOnLine());
    if (site.text != "Site") return Expected("Site after End", site);
    TEMPOKEY_ASSIGN_OR_RETURN(Token brace, NextToken());
    if (brace.text != "{") return Expected("'{' after End Site", brace);
    TEMPOKEY_ASSIGN_OR_RETURN(Token offset, NextToken());
    if (offset.text != "OFFSET") return Expected("OFFSET", offset);
    TEMPOKEY_ASSIGN_OR_RETURN(Vec3 end_site, TakeOffset());
    TEMPOKEY_ASSIGN_OR_RETURN(Token close, NextToken());
    if (close.text != "}") return Expected("'}' closing End Site", close);
    clip_.skeleton.joints[joint_index].end_sites.push_back(end_site);
    return absl::OkStatus();
  }

  // --- Motion -------------------------------------------------------------------------------

  // Matches `word` at the cursor, character by character (so "Frames:994" matches "Frames").
  bool TakeWord(std::string_view word) {
    if (static_cast<std::size_t>(end_ - p_) < word.size() ||
        std::string_view(p_, word.size()) != word) {
      return false;
    }
    p_ += word.size();
    return true;
  }

  // The token at the cursor for "expected X, got Y" (without consuming it).
  absl::StatusOr<Token> PeekToken() {
    Token token{TokenText(), Here(), AtEnd()};
    if (std::size_t bad = FindNonText(token.text); bad != std::string_view::npos) {
      return NotText(token, bad);
    }
    return token;
  }

  absl::Status ExpectedHere(std::string_view what) {
    TEMPOKEY_ASSIGN_OR_RETURN(Token got, PeekToken());
    return Expected(what, got);
  }

  // Reads ':' and whatever blanks surround it, after a header keyword.
  absl::Status TakeColon(std::string_view after) {
    SkipBlanks();
    if (AtEnd() || *p_ != ':') return ExpectedHere(absl::StrCat("':' after ", AsAbsl(after)));
    ++p_;
    SkipBlanks();
    return absl::OkStatus();
  }

  absl::Status ExpectLineEnd(std::string_view after) {
    SkipBlanks();
    if (!AtLineEnd()) return ExpectedHere(absl::StrCat("end of line after ", AsAbsl(after)));
    return absl::OkStatus();
  }

  absl::Status ParseMotionHeader() {
    SkipSpace();
    if (!TakeWord("Frames")) return ExpectedHere("\"Frames:\"");
    TEMPOKEY_RETURN_IF_ERROR(TakeColon("Frames"));
    const Location count_location = Here();
    if (AtLineEnd()) return ExpectedHere("a frame count after \"Frames:\"");
    const std::string_view count_text = WordAt(p_);
    std::int64_t frames = 0;
    const auto [end, ec] =
        std::from_chars(count_text.data(), count_text.data() + count_text.size(), frames);
    const bool whole = end == count_text.data() + count_text.size();
    if (ec == std::errc::result_out_of_range && whole) {
      return Error(count_location, absl::StrCat("frame count ", QuoteForMessage(count_text),
                                                " is out of range"));
    }
    if (ec != std::errc() || !whole) {
      return ExpectedHere("a whole number of frames after \"Frames:\"");
    }
    if (frames < 1) {
      return Error(count_location, absl::StrCat("expected at least 1 frame after \"Frames:\", got ",
                                                QuoteForMessage(count_text)));
    }
    if (frames > limits_.max_frames) {
      return Error(count_location, absl::StrCat("Frames: ", frames, " is over the limit of ",
                                                limits_.max_frames, " frames"));
    }
    p_ += count_text.size();
    TEMPOKEY_RETURN_IF_ERROR(ExpectLineEnd("the frame count"));

    SkipSpace();
    if (!TakeWord("Frame")) return ExpectedHere("\"Frame Time:\"");
    SkipBlanks();
    if (!TakeWord("Time")) return ExpectedHere("\"Time:\" after Frame");
    TEMPOKEY_RETURN_IF_ERROR(TakeColon("Frame Time"));
    const Location time_location = Here();
    if (AtLineEnd()) return ExpectedHere("a frame time in seconds after \"Frame Time:\"");
    const std::string_view time_text = WordAt(p_);
    TEMPOKEY_ASSIGN_OR_RETURN(const double frame_time, TakeNumber());
    if (frame_time <= 0.0) {
      return Error(time_location, absl::StrCat("expected a frame time > 0 seconds, got ",
                                               QuoteForMessage(time_text)));
    }
    if (absl::Status in_range = CheckFrameTime(frame_time); !in_range.ok()) {
      return Error(time_location, AsStd(in_range.message()));
    }
    TEMPOKEY_RETURN_IF_ERROR(ExpectLineEnd("the frame time"));

    const auto channels = static_cast<std::int64_t>(clip_.channels.size());
    if (channels == 0) {
      return Error(motion_location_, "the hierarchy declares no channels, so there is no motion");
    }
    if (frames > limits_.max_samples / channels) {
      return Error(count_location,
                   absl::StrCat(frames, " frames x ", channels, " channels is over the limit of ",
                                limits_.max_samples, " samples"));
    }
    clip_.frame_count = frames;
    clip_.frame_time_seconds = frame_time;
    return absl::OkStatus();
  }

  // The error for a row that ends (at the cursor) after `found` of its values.
  absl::Status RowLengthError(std::int64_t frame, std::int64_t found, Location at) const {
    return Error(at, absl::StrCat("motion row ", frame + 1, " has ", found,
                                  found == 1 ? " value" : " values", ", expected ",
                                  clip_.channels.size()));
  }

  // The hot loop: from_chars straight off the buffer, samples stored channel-major.
  absl::Status ParseMotionRows() {
    const std::size_t channel_count = clip_.channels.size();
    const auto frames = static_cast<std::size_t>(clip_.frame_count);
    // A row takes at least 2 bytes per value (a digit and a separator), so a short file that
    // claims many frames cannot make us allocate more than about 4 doubles per byte of text.
    const auto bytes_left = static_cast<std::size_t>(end_ - p_);
    const std::size_t rows_that_fit = bytes_left / (2 * channel_count) + 1;
    std::size_t allocated_rows = std::min(frames, rows_that_fit);
    std::vector<double*> columns(channel_count);
    auto allocate = [&](std::size_t rows) {
      allocated_rows = rows;
      for (std::size_t c = 0; c < channel_count; ++c) {
        clip_.channels[c].samples.resize(rows);
        columns[c] = clip_.channels[c].samples.data();
      }
    };
    allocate(allocated_rows);

    const char* const end = end_;
    for (std::size_t f = 0; f < frames; ++f) {
      if (f == allocated_rows) [[unlikely]] allocate(frames);  // the bound above was wrong
      SkipSpace();  // also skips blank lines between rows
      if (AtEnd()) {
        return Error(Here(), absl::StrCat("expected ", frames, " motion rows (Frames: ", frames,
                                          "), found ", f));
      }
      const char* p = p_;
      for (std::size_t c = 0; c < channel_count; ++c) {
        if (c != 0) {
          while (p != end && (*p == ' ' || *p == '\t')) ++p;
          if (p == end || IsSpace(*p)) {
            while (p != end && IsBlank(*p)) ++p;  // rare \v or \f between values
            if (p == end || IsLineBreak(*p)) {
              p_ = p;
              return RowLengthError(static_cast<std::int64_t>(f),
                                    static_cast<std::int64_t>(c), Here());
            }
          }
        }
        double value;
        const auto [next, ec] = std::from_chars(p, end, value);
        // One comparison catches NaN, infinities and magnitudes beyond a clip's range.
        if (ec != std::errc() || (next != end && !IsSpace(*next)) ||
            !(std::abs(value) <= kMaxSampleMagnitude)) [[unlikely]] {
          // Slow path: a leading '+' is fine; everything else is an error with its reason.
          const std::string_view word = WordAt(p);
          const NumberError error = ParseDoubleToken(word, value);
          if (error != NumberError::kNone) return BadNumber(p, error);
          if (!(std::abs(value) <= kMaxSampleMagnitude)) {
            return Error(Location{line_, p - line_start_ + 1}, OutOfRangeMessage("sample", word));
          }
          columns[c][f] = value;
          p = word.data() + word.size();
          continue;
        }
        columns[c][f] = value;
        p = next;
      }
      p_ = p;
      SkipBlanks();
      if (!AtLineEnd()) {
        const Location extra = Here();
        std::int64_t found = static_cast<std::int64_t>(channel_count);
        while (!AtLineEnd()) {
          ++found;
          while (!AtEnd() && !IsSpace(*p_)) ++p_;
          SkipBlanks();
        }
        return RowLengthError(static_cast<std::int64_t>(f), found, extra);
      }
    }
    SkipSpace();
    if (!AtEnd()) {
      TEMPOKEY_ASSIGN_OR_RETURN(Token extra, PeekToken());
      return Expected(absl::StrCat("end of file after ", frames, " motion rows"), extra);
    }
    return absl::OkStatus();
  }

  const char* const begin_;
  const char* const end_;
  const char* p_;
  std::int64_t line_ = 1;
  const char* line_start_;
  std::string_view source_name_;
  const ClipLimits& limits_;

  Clip clip_;
  std::vector<OpenJoint> open_;
  std::vector<std::int64_t> joint_opened_on_line_;  // per joint, the line of its '{'
  absl::flat_hash_map<std::string_view, std::int64_t> joint_lines_;  // name -> line
  Location motion_location_;
};

// --- Writing ------------------------------------------------------------------------------

// A joint name the reader reads back as the same single token.
absl::Status CheckWritableJointName(const Clip& clip, int index) {
  const std::string& name = clip.skeleton.joints[index].name;
  for (char c : name) {
    if (IsSpace(c) || IsBrace(c) || IsControl(static_cast<unsigned char>(c))) {
      return absl::InvalidArgumentError(absl::StrCat(
          "cannot write BVH: joint ", index, " name ", QuoteForMessage(name),
          " contains whitespace, a brace or a control character"));
    }
  }
  if (FindNonText(name) != std::string_view::npos) {
    return absl::InvalidArgumentError(absl::StrCat("cannot write BVH: joint ", index, " name ",
                                                   QuoteForMessage(name),
                                                   " is not valid UTF-8"));
  }
  return absl::OkStatus();
}

void AppendIndent(std::string& out, int depth) {
  out.append(static_cast<std::size_t>(depth), '\t');
}

void AppendOffset(std::string& out, int depth, const Vec3& offset) {
  AppendIndent(out, depth);
  out += "OFFSET";
  for (double v : offset) {
    out += ' ';
    AppendDouble(out, v);
  }
  out += '\n';
}

}  // namespace

absl::StatusOr<Clip> ParseBvh(std::string_view text, std::string_view source_name,
                              const ClipLimits& limits) {
  return BvhParser(text, source_name, limits).Parse();
}

absl::StatusOr<Clip> ReadBvhFile(const std::string& path, const ClipLimits& limits) {
  // Saturating arithmetic: limits may be set near the int64 range.
  constexpr std::int64_t kMax = std::numeric_limits<std::int64_t>::max();
  std::int64_t max_bytes = kFileBytesBase;
  const std::int64_t samples = std::max<std::int64_t>(limits.max_samples, 0);
  const std::int64_t joints = std::max<std::int64_t>(limits.max_joints, 0);
  max_bytes = samples > (kMax - max_bytes) / kFileBytesPerSample
                  ? kMax
                  : max_bytes + samples * kFileBytesPerSample;
  max_bytes = joints > (kMax - max_bytes) / kFileBytesPerJoint
                  ? kMax
                  : max_bytes + joints * kFileBytesPerJoint;
  TEMPOKEY_ASSIGN_OR_RETURN(const std::string text, ReadFile(path, max_bytes));
  return ParseBvh(text, path, limits);
}

absl::StatusOr<std::string> FormatBvh(const Clip& clip) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  const auto& joints = clip.skeleton.joints;
  if (joints.empty()) {
    return absl::InvalidArgumentError(
        "cannot write BVH: the clip has no skeleton (write plain channels as CSV)");
  }
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    const Channel& channel = clip.channels[c];
    if (channel.joint < 0 || channel.kind == ChannelKind::kScalar) {
      return absl::InvalidArgumentError(
          absl::StrCat("cannot write BVH: ", ChannelLabel(clip, static_cast<int>(c)),
                       " is not a joint's position or rotation (write plain channels as CSV)"));
    }
  }
  std::vector<std::vector<int>> children(joints.size());
  std::vector<int> roots;
  for (std::size_t j = 0; j < joints.size(); ++j) {
    TEMPOKEY_RETURN_IF_ERROR(CheckWritableJointName(clip, static_cast<int>(j)));
    if (joints[j].parent < 0) {
      roots.push_back(static_cast<int>(j));
    } else {
      children[joints[j].parent].push_back(static_cast<int>(j));
    }
  }

  std::string out;
  out.reserve(joints.size() * 160 + 64);
  out += "HIERARCHY\n";
  // Depth-first, in joint order among siblings: the order a reader numbers joints and columns.
  std::vector<int> column_order;
  column_order.reserve(clip.channels.size());
  struct Visit {
    int joint;
    std::size_t next_child = 0;  // children[joint] already written
    bool opened = false;         // header, OFFSET and CHANNELS written
  };
  std::vector<Visit> stack;
  for (int root : roots) {
    stack.push_back({root});
    while (!stack.empty()) {
      Visit& top = stack.back();
      const Joint& joint = joints[top.joint];
      const int depth = static_cast<int>(stack.size()) - 1;
      if (!top.opened) {
        top.opened = true;
        AppendIndent(out, depth);
        absl::StrAppend(&out, joint.parent < 0 ? "ROOT " : "JOINT ", joint.name, "\n");
        AppendIndent(out, depth);
        out += "{\n";
        AppendOffset(out, depth + 1, joint.offset);
        if (!joint.channels.empty()) {
          AppendIndent(out, depth + 1);
          absl::StrAppend(&out, "CHANNELS ", joint.channels.size());
          for (int c : joint.channels) {
            absl::StrAppend(&out, " ", AsAbsl(ChannelKindName(clip.channels[c].kind)));
            column_order.push_back(c);
          }
          out += '\n';
        }
      }
      const std::vector<int>& kids = children[top.joint];
      if (top.next_child < kids.size()) {
        stack.push_back({kids[top.next_child++]});  // invalidates `top`
        continue;
      }
      for (const Vec3& end_site : joint.end_sites) {
        AppendIndent(out, depth + 1);
        out += "End Site\n";
        AppendIndent(out, depth + 1);
        out += "{\n";
        AppendOffset(out, depth + 2, end_site);
        AppendIndent(out, depth + 1);
        out += "}\n";
      }
      AppendIndent(out, depth);
      out += "}\n";
      stack.pop_back();
    }
  }

  absl::StrAppend(&out, "MOTION\nFrames: ", clip.frame_count, "\nFrame Time: ");
  AppendDouble(out, clip.frame_time_seconds);
  out += '\n';

  // Rows straight into the string: size for the worst case of one row, trim at the end.
  const std::size_t row_bound = column_order.size() * (kMaxDoubleChars + 1) + 1;
  const auto frames = static_cast<std::size_t>(clip.frame_count);
  std::size_t used = out.size();
  out.resize(used + std::min<std::size_t>(frames, 64) * row_bound);
  std::vector<const double*> columns;
  columns.reserve(column_order.size());
  for (int c : column_order) columns.push_back(clip.channels[c].samples.data());
  for (std::size_t f = 0; f < frames; ++f) {
    if (out.size() - used < row_bound) out.resize(std::max(out.size() * 2, used + row_bound));
    char* p = out.data() + used;
    for (std::size_t c = 0; c < columns.size(); ++c) {
      if (c != 0) *p++ = ' ';
      p = WriteDouble(p, columns[c][f]);
    }
    *p++ = '\n';
    used = static_cast<std::size_t>(p - out.data());
  }
  out.resize(used);
  return out;
}

absl::Status WriteBvhFile(const std::string& path, const Clip& clip) {
  TEMPOKEY_ASSIGN_OR_RETURN(const std::string text, FormatBvh(clip));
  return WriteFileAtomically(path, text);
}

}  // namespace tempokey::core
