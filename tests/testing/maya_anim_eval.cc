#include "tests/testing/maya_anim_eval.h"

#include <cmath>
#include <cstdlib>
#include <numbers>
#include <optional>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"

namespace tempokey::testing {
namespace {

// Statements of the file: whitespace-separated words up to ';', '{' or '}', with their line.
struct Statement {
  std::vector<std::string> words;
  char end = ';';  // ';', '{' or '}'
  int line = 1;
};

std::vector<Statement> SplitStatements(std::string_view text) {
  std::vector<Statement> statements;
  Statement current;
  std::string word;
  int line = 1;
  auto flush_word = [&] {
    if (!word.empty()) {
      if (current.words.empty()) current.line = line;
      current.words.push_back(word);
      word.clear();
    }
  };
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char ch = text[i];
    if (ch == '#' || (ch == '/' && i + 1 < text.size() && text[i + 1] == '/')) {
      while (i < text.size() && text[i] != '\n') ++i;
      flush_word();
      ++line;
      continue;
    }
    if (ch == '\n') ++line;
    if (ch == ';' || ch == '{' || ch == '}') {
      flush_word();
      if (current.words.empty()) current.line = line;
      current.end = ch;
      statements.push_back(current);
      current = Statement{};
      continue;
    }
    if (ch == ' ' || ch == '\t' || ch == '\r' || ch == '\n') {
      flush_word();
    } else {
      word += ch;
    }
  }
  return statements;
}

std::optional<double> Number(const std::string& word) {
  char* end = nullptr;
  const double value = std::strtod(word.c_str(), &end);
  if (end == word.c_str() || *end != '\0') return std::nullopt;
  return value;
}

// Frames per second of a time unit name, as the published reader takes them: Autodesk's "ANIM
// file format" (animVersion 1.1) and the devkit animImportExport's animUnitNames::setFromName()
// know game|film|pal|ntsc|show|palf|ntscf|hour|min|sec|millisec and refuse every other name
// ("'120fps' is not a valid time unit. Use game|film|pal|ntsc|show|palf|ntscf|hour|min|sec|
// millisec instead."), so a file that names another does not load in every Maya.
std::optional<double> UnitRate(const std::string& name) {
  static const std::pair<const char*, double> kNamed[] = {
      {"game", 15.0}, {"film", 24.0}, {"pal", 25.0},       {"ntsc", 30.0},
      {"show", 48.0}, {"palf", 50.0}, {"ntscf", 60.0},     {"hour", 1.0 / 3600.0},
      {"min", 1.0 / 60.0}, {"sec", 1.0}, {"millisec", 1000.0},
  };
  for (const auto& [unit, rate] : kNamed) {
    if (name == unit) return rate;
  }
  return std::nullopt;
}

absl::Status Fail(int line, std::string_view what) {
  return absl::InvalidArgumentError(absl::StrCat("line ", line, ": ", std::string(what)));
}

absl::StatusOr<MayaKeyLine> ParseKey(const Statement& s) {
  const std::vector<std::string>& w = s.words;
  if (w.size() < 7) return Fail(s.line, "a key line needs at least 7 fields");
  MayaKeyLine key;
  std::optional<double> frame = Number(w[0]);
  std::optional<double> value = Number(w[1]);
  if (!frame || !value) return Fail(s.line, "key time and value must be numbers");
  key.frame = *frame;
  key.value = *value;
  key.in_type = w[2];
  key.out_type = w[3];
  std::size_t at = 7;  // after tanLock, weightLock, breakdown
  auto pair = [&](double& angle, double& weight) -> absl::Status {
    if (at + 2 > w.size()) return Fail(s.line, "a fixed tangent needs an angle and a weight");
    std::optional<double> a = Number(w[at]);
    std::optional<double> b = Number(w[at + 1]);
    if (!a || !b) return Fail(s.line, "tangent angle and weight must be numbers");
    angle = *a;
    weight = *b;
    at += 2;
    return absl::OkStatus();
  };
  if (key.in_type == "fixed") {
    if (absl::Status st = pair(key.in_angle_degrees, key.in_weight); !st.ok()) return st;
  }
  if (key.out_type == "fixed") {
    if (absl::Status st = pair(key.out_angle_degrees, key.out_weight); !st.ok()) return st;
  }
  if (at != w.size()) return Fail(s.line, "extra fields after the key");
  return key;
}

// ---- evaluation ---------------------------------------------------------------------------------

struct Point {
  double x;
  double y;
};

// The handle of one side of a segment from a to b (vector from its key), weighted curves; or the
// slope (dy/dx) for non-weighted ones. `out` selects a's out side, else b's in side.
struct Side {
  double slope = 0.0;    // per frame
  Point handle{0, 0};    // weighted: from the key (out: forward; in: backward, as a positive vector)
  bool step = false;
  bool step_next = false;
  bool linear = false;
};

constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;

absl::StatusOr<Side> SideOf(const MayaCurveBlock& curve, std::size_t k, bool out) {
  const std::vector<MayaKeyLine>& keys = curve.keys;
  const MayaKeyLine& key = keys[k];
  // The segment this side borders.
  const MayaKeyLine& a = out ? key : keys[k - 1];
  const MayaKeyLine& b = out ? keys[k + 1] : key;
  const double dx = b.frame - a.frame;
  const double dy = b.value - a.value;
  const std::string& type = out ? key.out_type : key.in_type;
  Side side;
  double direction_x = 1.0;
  double direction_y = 0.0;
  double length = dx / 3.0;  // Maya's default handle: a third of the segment along x
  if (type == "fixed") {
    const double angle = (out ? key.out_angle_degrees : key.in_angle_degrees) * kRadiansPerDegree;
    direction_x = std::cos(angle);
    direction_y = std::sin(angle);
    side.slope = std::tan(angle);
    side.handle = {0, 0};
    const double weight = out ? key.out_weight : key.in_weight;
    side.handle = {weight * direction_x, weight * direction_y};
    return side;
  }
  if (type == "linear") {
    side.linear = true;
    side.slope = dy / dx;
    side.handle = {dx / 3.0, dy / 3.0};
    return side;
  }
  if (type == "flat") {
    side.slope = 0.0;
    side.handle = {length, 0.0};
    return side;
  }
  if (type == "step" || type == "stepnext") {
    side.step = type == "step";
    side.step_next = type == "stepnext";
    return side;
  }
  if (type == "spline") {
    // Slope through the key's neighbours (one-sided at the ends).
    const MayaKeyLine& before = k > 0 ? keys[k - 1] : key;
    const MayaKeyLine& after = k + 1 < keys.size() ? keys[k + 1] : key;
    side.slope = (after.value - before.value) / (after.frame - before.frame);
    direction_y = side.slope;
    side.handle = {length, length * direction_y};
    return side;
  }
  return absl::InvalidArgumentError(absl::StrCat("tangent type '", type, "' is not supported"));
}

double Hermite(double x0, double y0, double m0, double x1, double y1, double m1, double x) {
  const double h = x1 - x0;
  const double s = (x - x0) / h;
  const double s2 = s * s;
  const double s3 = s2 * s;
  return (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * h * m0 + (-2 * s3 + 3 * s2) * y1 +
         (s3 - s2) * h * m1;
}

double BezierAt(double p0, double p1, double p2, double p3, double s) {
  const double u = 1.0 - s;
  return u * u * u * p0 + 3 * u * u * s * p1 + 3 * u * s * s * p2 + s * s * s * p3;
}

// The Bezier's y where its x reaches `x` (x increasing in s): plain bisection to machine precision.
double Bezier(Point p0, Point p1, Point p2, Point p3, double x) {
  double lo = 0.0;
  double hi = 1.0;
  for (int i = 0; i < 200 && hi - lo > 0.0; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (mid == lo || mid == hi) break;
    if (BezierAt(p0.x, p1.x, p2.x, p3.x, mid) < x) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return BezierAt(p0.y, p1.y, p2.y, p3.y, 0.5 * (lo + hi));
}

}  // namespace

absl::StatusOr<MayaAnimFile> ParseMayaAnimText(std::string_view text) {
  const std::vector<Statement> statements = SplitStatements(text);
  MayaAnimFile file;
  std::size_t i = 0;
  std::optional<std::string> pending_node;
  std::optional<std::string> pending_attribute;
  while (i < statements.size()) {
    const Statement& s = statements[i];
    const std::vector<std::string>& w = s.words;
    if (w.empty()) return Fail(s.line, "empty statement");
    if (w[0] == "animData" && s.end == '{') {
      if (!pending_node) return Fail(s.line, "animData without an anim line");
      MayaCurveBlock curve;
      curve.attribute = *pending_attribute;
      curve.node = *pending_node;
      ++i;
      bool in_keys = false;
      while (true) {
        if (i >= statements.size()) return Fail(s.line, "unterminated animData");
        const Statement& t = statements[i];
        ++i;
        if (t.end == '}' && t.words.empty()) {
          if (in_keys) {
            in_keys = false;
            continue;
          }
          break;
        }
        if (in_keys) {
          absl::StatusOr<MayaKeyLine> key = ParseKey(t);
          if (!key.ok()) return key.status();
          curve.keys.push_back(*key);
          continue;
        }
        if (t.words.size() == 1 && t.words[0] == "keys" && t.end == '{') {
          in_keys = true;
          continue;
        }
        if (t.words.size() != 2 || t.end != ';') return Fail(t.line, "expected 'name value;'");
        if (t.words[0] == "output") curve.output = t.words[1];
        if (t.words[0] == "weighted") curve.weighted = t.words[1] == "1";
      }
      file.curves.push_back(std::move(curve));
      pending_node.reset();
      continue;
    }
    if (s.end != ';') return Fail(s.line, absl::StrCat("unexpected '", std::string(1, s.end), "'"));
    if (w[0] == "anim") {
      // anim [fullAttribute leafAttribute] node row child attr;
      if (w.size() != 7 && w.size() != 5) return Fail(s.line, "anim line needs 7 (or 5) words");
      pending_attribute = w.size() == 7 ? w[1] : "";
      pending_node = w.size() == 7 ? w[3] : w[1];
    } else if (w[0] == "timeUnit" && w.size() == 2) {
      file.time_unit = w[1];
      std::optional<double> rate = UnitRate(w[1]);
      if (!rate) return Fail(s.line, absl::StrCat("'", w[1], "' is not a valid time unit"));
      file.frames_per_second = *rate;
    } else if (w[0] == "linearUnit" && w.size() == 2) {
      file.linear_unit = w[1];
    } else if (w[0] == "angularUnit" && w.size() == 2) {
      file.angular_unit = w[1];
    } else if (w[0] == "endTime" && w.size() == 2) {
      file.end_time = Number(w[1]).value_or(0.0);
    }
    ++i;
  }
  if (file.time_unit.empty()) return Fail(1, "no timeUnit");
  return file;
}

absl::StatusOr<double> EvaluateMayaCurve(const MayaCurveBlock& curve, double frame) {
  const std::vector<MayaKeyLine>& keys = curve.keys;
  if (keys.empty()) return absl::InvalidArgumentError("curve has no keys");
  if (frame <= keys.front().frame) return keys.front().value;
  if (frame >= keys.back().frame) return keys.back().value;
  std::size_t k = 0;
  while (!(frame < keys[k + 1].frame)) ++k;
  const MayaKeyLine& a = keys[k];
  const MayaKeyLine& b = keys[k + 1];
  if (frame == a.frame) return a.value;
  absl::StatusOr<Side> out = SideOf(curve, k, true);
  if (!out.ok()) return out.status();
  absl::StatusOr<Side> in = SideOf(curve, k + 1, false);
  if (!in.ok()) return in.status();
  if (out->step) return a.value;
  if (out->step_next) return b.value;
  if (out->linear && in->linear) {
    return a.value + (b.value - a.value) * (frame - a.frame) / (b.frame - a.frame);
  }
  if (!curve.weighted) return Hermite(a.frame, a.value, out->slope, b.frame, b.value, in->slope, frame);
  const Point p0{a.frame, a.value};
  const Point p1{a.frame + out->handle.x, a.value + out->handle.y};
  const Point p2{b.frame - in->handle.x, b.value - in->handle.y};
  const Point p3{b.frame, b.value};
  return Bezier(p0, p1, p2, p3, frame);
}

double FileFrameOfSourceFrame(const MayaAnimFile& file, double frame_time_seconds,
                              std::int64_t frame) {
  const auto f = static_cast<double>(frame);
  const double down = 1.0 / (frame_time_seconds * file.frames_per_second);
  const double n = std::round(down);
  if (n >= 1.0 && std::abs(down - n) <= 1e-4 * n) return f / n;
  const double up = frame_time_seconds * file.frames_per_second;
  const double m = std::round(up);
  if (m >= 1.0 && std::abs(up - m) <= 1e-4 * m) return f * m;
  return f * frame_time_seconds * file.frames_per_second;
}

}  // namespace tempokey::testing
