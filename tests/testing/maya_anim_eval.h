// An independent reader and evaluator of Maya .anim files, written from the published semantics
// and sharing no code with core's writer (core/src/io/maya_anim.cc):
//   - Autodesk "ANIM file format" v1.1: header, `anim` / `animData` blocks, the key line
//     `time value inType outType tanLock weightLock breakdown [inAngle inWeight] [outAngle
//     outWeight]` (a pair only after a `fixed` tangent); `//` and `#` comments.
//   - The devkit's animImportExport reader: angles and weights are in UI space, x in frames of
//     the file's timeUnit, y in the file's value units (it sets the UI units to the file's
//     before MFnAnimCurve::setTangent).
//   - Autodesk AnimX: a weighted curve's segment is the 2D Bezier through the keys and their
//     handles (solve x(s) = frame); a non-weighted curve's segment is the cubic Hermite in frames
//     whose end slopes are tan(angle), handle lengths playing no part; both tangents `linear`
//     make the segment a straight line; a `step` out tangent holds the value.
//   - SideFX "Converting animation key values between Houdini and Maya": tan(angle) = DV / DF,
//     weight^2 = DF^2 + DV^2: a weighted out handle sits at (F + w cos a, V + w sin a), an in
//     handle at (F - w cos a, V - w sin a).
// Tangent types read: fixed, linear, flat, step, stepnext, spline; others are refused.
#ifndef TEMPOKEY_TESTS_TESTING_MAYA_ANIM_EVAL_H_
#define TEMPOKEY_TESTS_TESTING_MAYA_ANIM_EVAL_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"

namespace tempokey::testing {

struct MayaKeyLine {
  double frame = 0.0;
  double value = 0.0;
  std::string in_type;
  std::string out_type;
  double in_angle_degrees = 0.0;  // fixed only
  double in_weight = 0.0;
  double out_angle_degrees = 0.0;
  double out_weight = 0.0;
};

struct MayaCurveBlock {
  std::string attribute;  // the full attribute name, "rotate.rotateX"
  std::string node;
  std::string output;     // angular, linear, unitless
  bool weighted = false;
  std::vector<MayaKeyLine> keys;
};

struct MayaAnimFile {
  std::string time_unit;
  double frames_per_second = 0.0;  // of time_unit
  std::string linear_unit;
  std::string angular_unit;
  double end_time = 0.0;
  std::vector<MayaCurveBlock> curves;
};

// Parses .anim text. Errors: kInvalidArgument naming the line for anything unexpected.
absl::StatusOr<MayaAnimFile> ParseMayaAnimText(std::string_view text);

// The curve's value at `frame` (frames of the file's timeUnit), Maya's semantics above.
// Errors: kInvalidArgument for an unsupported tangent type or an empty curve.
absl::StatusOr<double> EvaluateMayaCurve(const MayaCurveBlock& curve, double frame);

// Where animators see source frame `frame` of a clip at `frame_time_seconds` in `file`: when the
// clip's rate is n times the file's unit (within 1e-4; n = 1: the frame numbers themselves), the
// file frame frame / n; when the unit's is m times the clip's, frame x m; else the frame's exact
// time in the unit's frames.
double FileFrameOfSourceFrame(const MayaAnimFile& file, double frame_time_seconds,
                              std::int64_t frame);

}  // namespace tempokey::testing

#endif  // TEMPOKEY_TESTS_TESTING_MAYA_ANIM_EVAL_H_
