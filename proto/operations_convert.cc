// Pipeline operations and their reports as tempokey.v1 messages (operations.proto).
#include "proto/operations_convert.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/status.h"

namespace tempokey::wire {
namespace {

template <class... Ts>
struct Overloaded : Ts... {
  using Ts::operator()...;
};
template <class... Ts>
Overloaded(Ts...) -> Overloaded<Ts...>;

absl::Status Invalid(std::string message) { return absl::InvalidArgumentError(message); }

// ---- operations ----------------------------------------------------------------------------------

// Error prefix for operation `index` (0-based): "operation 2: ".
std::string OpPrefix(int index) { return absl::StrCat("operation ", index + 1, ": "); }

absl::Status UnknownEnum(int op, const std::string& field, int value) {
  return Invalid(absl::StrCat(OpPrefix(op), field, " has unknown value ", value));
}

absl::StatusOr<core::TimePoint> TimePointFromProto(int op, const std::string& field,
                                                   const v1::TimePoint& tp) {
  switch (tp.unit_case()) {
    case v1::TimePoint::kSeconds:
      return core::TimePoint{.value = tp.seconds(), .in_frames = false};
    case v1::TimePoint::kFrames:
      return core::TimePoint{.value = tp.frames(), .in_frames = true};
    case v1::TimePoint::UNIT_NOT_SET:
      break;
  }
  return Invalid(absl::StrCat(OpPrefix(op), field, " has no unit: set seconds or frames"));
}

v1::TimePoint TimePointToProto(const core::TimePoint& tp) {
  v1::TimePoint out;
  if (tp.in_frames) {
    out.set_frames(tp.value);
  } else {
    out.set_seconds(tp.value);
  }
  return out;
}

// A rate given as numerator/denominator where 0/0 means "keep the source's"; any other pair is
// the caller's rate, which core validates ("output rate 30/0 must have a positive numerator and
// denominator").
std::optional<core::FrameRate> RateFromProto(std::int64_t numerator, std::int64_t denominator) {
  if (numerator == 0 && denominator == 0) return std::nullopt;
  return core::FrameRate{.numerator = numerator, .denominator = denominator};
}

absl::StatusOr<std::vector<core::SpeedKnot>> KnotsFromProto(
    int op, const std::string& field,
    const google::protobuf::RepeatedPtrField<v1::SpeedKnot>& knots) {
  std::vector<core::SpeedKnot> out;
  out.reserve(knots.size());
  for (int k = 0; k < knots.size(); ++k) {
    const std::string name = absl::StrCat(field, "[", k, "]");
    TEMPOKEY_ASSIGN_OR_RETURN(core::TimePoint time,
                              TimePointFromProto(op, name + ".time", knots[k].time()));
    out.push_back(core::SpeedKnot{.time = time, .speed = knots[k].speed()});
  }
  return out;
}

absl::StatusOr<core::RetimeStep> RetimeFromProto(int op, const v1::RetimeOperation& r) {
  core::RetimeStep step;
  std::vector<std::string> domains;
  if (r.speed_over_source_size() > 0) domains.push_back("speed_over_source");
  if (r.speed_over_output_size() > 0) domains.push_back("speed_over_output");
  if (r.time_map_size() > 0) domains.push_back("time_map");
  if (domains.size() > 1) {
    return Invalid(absl::StrCat(OpPrefix(op),
                                "retime takes at most one of speed_over_source, speed_over_output "
                                "and time_map, got ",
                                domains[0], " and ", domains[1]));
  }
  if (r.speed_over_source_size() > 0) {
    step.warp.domain = core::WarpDomain::kSpeedOverSource;
    TEMPOKEY_ASSIGN_OR_RETURN(step.warp.speed,
                              KnotsFromProto(op, "retime.speed_over_source", r.speed_over_source()));
  } else if (r.speed_over_output_size() > 0) {
    step.warp.domain = core::WarpDomain::kSpeedOverOutput;
    TEMPOKEY_ASSIGN_OR_RETURN(step.warp.speed,
                              KnotsFromProto(op, "retime.speed_over_output", r.speed_over_output()));
  } else if (r.time_map_size() > 0) {
    step.warp.domain = core::WarpDomain::kTimeMapKeys;
    for (int k = 0; k < r.time_map_size(); ++k) {
      const std::string name = absl::StrCat("retime.time_map[", k, "]");
      TEMPOKEY_ASSIGN_OR_RETURN(core::TimePoint output,
                                TimePointFromProto(op, name + ".output", r.time_map(k).output()));
      TEMPOKEY_ASSIGN_OR_RETURN(core::TimePoint source,
                                TimePointFromProto(op, name + ".source", r.time_map(k).source()));
      step.warp.keys.push_back(core::TimeMapKey{.output = output, .source = source});
    }
  }
  for (int h = 0; h < r.holds_size(); ++h) {
    const std::string name = absl::StrCat("retime.holds[", h, "]");
    TEMPOKEY_ASSIGN_OR_RETURN(core::TimePoint at, TimePointFromProto(op, name + ".at", r.holds(h).at()));
    step.warp.holds.push_back(core::Hold{.at = at, .duration_seconds = r.holds(h).duration_seconds()});
  }
  step.warp.reverse = r.reverse();

  switch (r.fit_case()) {
    case v1::RetimeOperation::kFitSeconds:
      step.options.fit_seconds = r.fit_seconds();
      break;
    case v1::RetimeOperation::kFitFrames:
      step.options.fit_frames = r.fit_frames();
      break;
    case v1::RetimeOperation::FIT_NOT_SET:
      break;
  }
  step.options.fit_to_grid = !r.disable_fit_to_grid();
  step.options.output_rate = RateFromProto(r.output_rate_numerator(), r.output_rate_denominator());
  switch (r.filter()) {
    case v1::RESAMPLE_FILTER_UNSPECIFIED:
    case v1::RESAMPLE_FILTER_TENT:
      step.options.filter = core::ResampleFilter::kTent;
      break;
    case v1::RESAMPLE_FILTER_LINEAR:
      step.options.filter = core::ResampleFilter::kLinear;
      break;
    case v1::RESAMPLE_FILTER_BOX:
      step.options.filter = core::ResampleFilter::kBox;
      break;
    case v1::RESAMPLE_FILTER_CUBIC:
      step.options.filter = core::ResampleFilter::kCubic;
      break;
    case v1::RESAMPLE_FILTER_LANCZOS3:
      step.options.filter = core::ResampleFilter::kLanczos3;
      break;
    default:
      return UnknownEnum(op, "retime.filter", r.filter());
  }
  switch (r.method()) {
    case v1::RETIME_METHOD_UNSPECIFIED:
    case v1::RETIME_METHOD_EXACT:
      step.options.method = core::RetimeMethod::kExact;
      break;
    case v1::RETIME_METHOD_PAPER:
      step.options.method = core::RetimeMethod::kPaper;
      break;
    default:
      return UnknownEnum(op, "retime.method", r.method());
  }
  switch (r.rotation_mode()) {
    case v1::ROTATION_MODE_UNSPECIFIED:
    case v1::ROTATION_MODE_QUATERNION:
      step.options.rotation_mode = core::RotationMode::kQuaternion;
      break;
    case v1::ROTATION_MODE_EULER:
      step.options.rotation_mode = core::RotationMode::kEuler;
      break;
    default:
      return UnknownEnum(op, "retime.rotation_mode", r.rotation_mode());
  }
  for (int p = 0; p < r.pins_size(); ++p) {
    const std::string name = absl::StrCat("retime.pins[", p, "]");
    TEMPOKEY_ASSIGN_OR_RETURN(core::TimePoint source,
                              TimePointFromProto(op, name + ".source", r.pins(p).source()));
    step.options.pins.push_back(
        core::Pin{.source = source, .output_frame = r.pins(p).output_frame()});
  }
  // 0 selects the default range; anything else is the caller's and core checks it.
  if (r.min_speed() != 0.0) step.options.min_speed = r.min_speed();
  if (r.max_speed() != 0.0) step.options.max_speed = r.max_speed();
  step.euler_filter = r.euler_filter();
  return step;
}

absl::StatusOr<core::ReduceStep> ReduceFromProto(int op, const v1::ReduceOperation& r) {
  core::ReduceStep step;
  core::ReduceOptions& o = step.options;
  switch (r.method()) {
    case v1::REDUCE_METHOD_UNSPECIFIED:
    case v1::REDUCE_METHOD_TOLERANCE:
      o.method = core::ReduceMethod::kTolerance;
      break;
    case v1::REDUCE_METHOD_PAPER:
      o.method = core::ReduceMethod::kPaper;
      break;
    case v1::REDUCE_METHOD_NOISE:
      o.method = core::ReduceMethod::kNoise;
      break;
    default:
      return UnknownEnum(op, "reduce.method", r.method());
  }
  if (r.has_euler_filter()) o.euler_filter = r.euler_filter();
  const v1::NoiseParams& n = r.noise();
  if (n.has_rotation_sigma_degrees()) o.noise.rotation_sigma_degrees = n.rotation_sigma_degrees();
  if (n.has_position_sigma()) o.noise.position_sigma = n.position_sigma();
  if (n.has_min_sigma()) o.noise.min_sigma = n.min_sigma();
  if (n.has_guard_sigmas()) o.noise.guard_sigmas = n.guard_sigmas();
  if (n.has_key_sigmas()) o.noise.key_sigmas = n.key_sigmas();

  // Set fields replace the defaults; ValidateReduceOptions() (run on the whole pipeline before
  // anything is queued) checks every value and names it.
  const v1::PaperParams& p = r.paper();
  if (p.has_step_x_frames()) o.paper.step_x_frames = p.step_x_frames();
  if (p.has_step_y()) o.paper.step_y = p.step_y();
  if (p.has_step_tangent_x()) o.paper.step_tangent_x = p.step_tangent_x();
  if (p.has_step_tangent_y()) o.paper.step_tangent_y = p.step_tangent_y();
  if (p.has_accuracy()) o.paper.accuracy = p.accuracy();
  if (p.has_max_iterations()) o.paper.max_iterations = p.max_iterations();
  if (p.has_smoothing_sigma_frames()) o.paper.smoothing_sigma_frames = p.smoothing_sigma_frames();
  if (p.has_min_key_spacing_frames()) o.paper.min_key_spacing_frames = p.min_key_spacing_frames();

  const v1::ToleranceParams& t = r.tolerance();
  if (t.has_max_rotation_error_degrees()) {
    o.tolerance.max_rotation_error_degrees = t.max_rotation_error_degrees();
  }
  if (t.has_max_position_error()) o.tolerance.max_position_error = t.max_position_error();
  if (t.has_max_scalar_error()) o.tolerance.max_scalar_error = t.max_scalar_error();
  if (t.has_key_budget()) o.tolerance.key_budget = t.key_budget();
  o.tolerance.fewest_keys = t.fewest_keys();
  switch (t.joint_tolerance_case()) {
    case v1::ToleranceParams::kMaxJointError:
      o.tolerance.joint_tolerance = core::JointTolerance{.value = t.max_joint_error()};
      break;
    case v1::ToleranceParams::kMaxJointErrorPercentOfHeight:
      o.tolerance.joint_tolerance = core::JointTolerance{
          .value = t.max_joint_error_percent_of_height(), .percent_of_height = true};
      break;
    case v1::ToleranceParams::JOINT_TOLERANCE_NOT_SET:
      break;
  }
  switch (t.pose_alignment()) {
    case v1::POSE_ALIGNMENT_UNSPECIFIED:
    case v1::POSE_ALIGNMENT_NONE:
      o.tolerance.pose_alignment = core::PoseAlignment::kNone;
      break;
    case v1::POSE_ALIGNMENT_JOINT:
      o.tolerance.pose_alignment = core::PoseAlignment::kJoint;
      break;
    case v1::POSE_ALIGNMENT_CLIP:
      o.tolerance.pose_alignment = core::PoseAlignment::kClip;
      break;
    default:
      return UnknownEnum(op, "reduce.tolerance.pose_alignment", t.pose_alignment());
  }
  return step;
}

v1::RetimeOperation RetimeToProto(const core::RetimeStep& step) {
  v1::RetimeOperation r;
  auto add_knots = [](const std::vector<core::SpeedKnot>& knots,
                      google::protobuf::RepeatedPtrField<v1::SpeedKnot>* out) {
    for (const core::SpeedKnot& k : knots) {
      v1::SpeedKnot* knot = out->Add();
      *knot->mutable_time() = TimePointToProto(k.time);
      knot->set_speed(k.speed);
    }
  };
  switch (step.warp.domain) {
    case core::WarpDomain::kIdentity:
      break;
    case core::WarpDomain::kSpeedOverSource:
      add_knots(step.warp.speed, r.mutable_speed_over_source());
      break;
    case core::WarpDomain::kSpeedOverOutput:
      add_knots(step.warp.speed, r.mutable_speed_over_output());
      break;
    case core::WarpDomain::kTimeMapKeys:
      for (const core::TimeMapKey& k : step.warp.keys) {
        v1::TimeMapKey* key = r.add_time_map();
        *key->mutable_output() = TimePointToProto(k.output);
        *key->mutable_source() = TimePointToProto(k.source);
      }
      break;
  }
  for (const core::Hold& h : step.warp.holds) {
    v1::Hold* hold = r.add_holds();
    *hold->mutable_at() = TimePointToProto(h.at);
    hold->set_duration_seconds(h.duration_seconds);
  }
  r.set_reverse(step.warp.reverse);
  const core::RetimeOptions& o = step.options;
  if (o.fit_seconds) r.set_fit_seconds(*o.fit_seconds);
  if (o.fit_frames) r.set_fit_frames(*o.fit_frames);
  r.set_disable_fit_to_grid(!o.fit_to_grid);
  if (o.output_rate) {
    r.set_output_rate_numerator(o.output_rate->numerator);
    r.set_output_rate_denominator(o.output_rate->denominator);
  }
  switch (o.filter) {
    case core::ResampleFilter::kTent:
      r.set_filter(v1::RESAMPLE_FILTER_TENT);
      break;
    case core::ResampleFilter::kLinear:
      r.set_filter(v1::RESAMPLE_FILTER_LINEAR);
      break;
    case core::ResampleFilter::kBox:
      r.set_filter(v1::RESAMPLE_FILTER_BOX);
      break;
    case core::ResampleFilter::kCubic:
      r.set_filter(v1::RESAMPLE_FILTER_CUBIC);
      break;
    case core::ResampleFilter::kLanczos3:
      r.set_filter(v1::RESAMPLE_FILTER_LANCZOS3);
      break;
  }
  r.set_method(o.method == core::RetimeMethod::kPaper ? v1::RETIME_METHOD_PAPER
                                                      : v1::RETIME_METHOD_EXACT);
  r.set_rotation_mode(o.rotation_mode == core::RotationMode::kEuler ? v1::ROTATION_MODE_EULER
                                                                    : v1::ROTATION_MODE_QUATERNION);
  for (const core::Pin& p : o.pins) {
    v1::Pin* pin = r.add_pins();
    *pin->mutable_source() = TimePointToProto(p.source);
    pin->set_output_frame(p.output_frame);
  }
  r.set_min_speed(o.min_speed);
  r.set_max_speed(o.max_speed);
  r.set_euler_filter(step.euler_filter);
  return r;
}

v1::ReduceOperation ReduceToProto(const core::ReduceStep& step) {
  v1::ReduceOperation r;
  const core::ReduceOptions& o = step.options;
  if (o.euler_filter) r.set_euler_filter(*o.euler_filter);
  if (o.method == core::ReduceMethod::kNoise) {
    r.set_method(v1::REDUCE_METHOD_NOISE);
    v1::NoiseParams* n = r.mutable_noise();
    if (o.noise.rotation_sigma_degrees) {
      n->set_rotation_sigma_degrees(*o.noise.rotation_sigma_degrees);
    }
    if (o.noise.position_sigma) n->set_position_sigma(*o.noise.position_sigma);
    n->set_min_sigma(o.noise.min_sigma);
    n->set_guard_sigmas(o.noise.guard_sigmas);
    n->set_key_sigmas(o.noise.key_sigmas);
  } else if (o.method == core::ReduceMethod::kPaper) {
    r.set_method(v1::REDUCE_METHOD_PAPER);
    v1::PaperParams* p = r.mutable_paper();
    p->set_step_x_frames(o.paper.step_x_frames);
    p->set_step_y(o.paper.step_y);
    p->set_step_tangent_x(o.paper.step_tangent_x);
    p->set_step_tangent_y(o.paper.step_tangent_y);
    p->set_accuracy(o.paper.accuracy);
    p->set_max_iterations(o.paper.max_iterations);
    p->set_smoothing_sigma_frames(o.paper.smoothing_sigma_frames);
    p->set_min_key_spacing_frames(o.paper.min_key_spacing_frames);
  } else {
    r.set_method(v1::REDUCE_METHOD_TOLERANCE);
    v1::ToleranceParams* t = r.mutable_tolerance();
    // Unset bounds stay unset: the server resolves the scale-aware defaults against the clip.
    if (o.tolerance.max_rotation_error_degrees) {
      t->set_max_rotation_error_degrees(*o.tolerance.max_rotation_error_degrees);
    }
    if (o.tolerance.max_position_error) {
      t->set_max_position_error(*o.tolerance.max_position_error);
    }
    t->set_max_scalar_error(o.tolerance.max_scalar_error);
    if (const std::optional<core::JointTolerance>& joint = o.tolerance.joint_tolerance) {
      if (joint->percent_of_height) {
        t->set_max_joint_error_percent_of_height(joint->value);
      } else {
        t->set_max_joint_error(joint->value);
      }
    }
    t->set_fewest_keys(o.tolerance.fewest_keys);
    if (o.tolerance.key_budget) {
      t->set_key_budget(static_cast<std::int32_t>(std::min<std::int64_t>(
          *o.tolerance.key_budget, std::numeric_limits<std::int32_t>::max())));
    }
    switch (o.tolerance.pose_alignment) {
      case core::PoseAlignment::kNone:
        t->set_pose_alignment(v1::POSE_ALIGNMENT_NONE);
        break;
      case core::PoseAlignment::kJoint:
        t->set_pose_alignment(v1::POSE_ALIGNMENT_JOINT);
        break;
      case core::PoseAlignment::kClip:
        t->set_pose_alignment(v1::POSE_ALIGNMENT_CLIP);
        break;
    }
  }
  return r;
}

v1::WorldErrorReport WorldErrorToProto(const core::WorldErrorReport& w) {
  v1::WorldErrorReport out;
  out.set_figure_height_units(w.figure_height);
  out.set_max_error_units(w.max_error);
  out.set_rms_error_units(w.rms_error);
  out.set_worst_point(w.worst_point_name);
  out.set_worst_joint_index(w.worst_point.joint);
  out.set_worst_end_site_index(w.worst_point.end_site);
  out.set_worst_frame(w.worst_frame);
  out.set_joint_tolerance_units(w.joint_tolerance);
  return out;
}

core::WorldErrorReport WorldErrorFromProto(const v1::WorldErrorReport& w) {
  return core::WorldErrorReport{
      .figure_height = w.figure_height_units(),
      .max_error = w.max_error_units(),
      .worst_point = {.joint = w.worst_joint_index(), .end_site = w.worst_end_site_index()},
      .worst_point_name = w.worst_point(),
      .worst_frame = w.worst_frame(),
      .rms_error = w.rms_error_units(),
      .joint_tolerance = w.joint_tolerance_units()};
}

}  // namespace

// ---- operations ----------------------------------------------------------------------------------

absl::StatusOr<std::vector<core::PipelineStep>> PipelineFromProto(
    const google::protobuf::RepeatedPtrField<v1::Operation>& operations) {
  std::vector<core::PipelineStep> steps;
  steps.reserve(static_cast<std::size_t>(operations.size()));
  for (int i = 0; i < operations.size(); ++i) {
    const v1::Operation& op = operations[i];
    switch (op.kind_case()) {
      case v1::Operation::kRetime: {
        TEMPOKEY_ASSIGN_OR_RETURN(core::RetimeStep step, RetimeFromProto(i, op.retime()));
        steps.emplace_back(std::move(step));
        break;
      }
      case v1::Operation::kReduce: {
        TEMPOKEY_ASSIGN_OR_RETURN(core::ReduceStep step, ReduceFromProto(i, op.reduce()));
        steps.emplace_back(std::move(step));
        break;
      }
      case v1::Operation::kBake:
        steps.emplace_back(core::BakeStep{
            .rate = RateFromProto(op.bake().rate_numerator(), op.bake().rate_denominator())});
        break;
      case v1::Operation::kConvert:
        steps.emplace_back(core::ConvertStep{.wrap_rotations = op.convert().wrap_rotations(),
                                             .euler_filter = op.convert().euler_filter()});
        break;
      case v1::Operation::KIND_NOT_SET:
        return Invalid(absl::StrCat(OpPrefix(i),
                                    "no operation set (one of retime, reduce, bake, convert)"));
    }
  }
  return steps;
}

v1::Operation PipelineStepToProto(const core::PipelineStep& step) {
  v1::Operation op;
  std::visit(Overloaded{
                 [&](const core::RetimeStep& s) { *op.mutable_retime() = RetimeToProto(s); },
                 [&](const core::ReduceStep& s) { *op.mutable_reduce() = ReduceToProto(s); },
                 [&](const core::BakeStep& s) {
                   v1::BakeOperation* bake = op.mutable_bake();
                   if (s.rate) {
                     bake->set_rate_numerator(s.rate->numerator);
                     bake->set_rate_denominator(s.rate->denominator);
                   }
                 },
                 [&](const core::ConvertStep& s) {
                   op.mutable_convert()->set_wrap_rotations(s.wrap_rotations);
                   op.mutable_convert()->set_euler_filter(s.euler_filter);
                 },
             },
             step);
  return op;
}

v1::OperationReport StepReportToProto(const core::StepReport& report) {
  v1::OperationReport out;
  std::visit(Overloaded{
                 [&](const core::RetimeReport& r) {
                   v1::RetimeReport* o = out.mutable_retime();
                   o->set_output_duration_seconds(r.output_duration_seconds);
                   o->set_output_frame_count(r.output_frame_count);
                   o->set_fit_factor(r.fit_factor);
                   o->set_max_decimation_ratio(r.max_decimation_ratio);
                   o->set_filtered_sample_count(r.filtered_sample_count);
                 },
                 [&](const core::ReductionReport& r) {
                   v1::ReductionReport* o = out.mutable_reduction();
                   o->mutable_channels()->Reserve(static_cast<int>(r.channels.size()));
                   for (const core::ChannelReduction& ch : r.channels) {
                     v1::ChannelReduction* c = o->add_channels();
                     c->set_channel_index(ch.channel_index);
                     c->set_key_count(ch.key_count);
                     c->set_sample_count(ch.sample_count);
                     c->set_rms_error(ch.rms_error);
                     c->set_max_error(ch.max_error);
                     c->set_max_error_frame(ch.max_error_frame);
                     c->set_noise_sigma(ch.noise_sigma);
                     c->set_noise_sigma_estimated(ch.noise_sigma_estimated);
                   }
                   o->set_key_count(r.key_count);
                   o->set_sample_count(r.sample_count);
                   o->set_rms_error(r.rms_error);
                   o->set_max_error(r.max_error);
                   o->set_worst_channel_index(r.worst_channel_index);
                   o->set_worst_frame(r.worst_frame);
                   o->set_iterations(r.iterations);
                   if (r.world) *o->mutable_world_error() = WorldErrorToProto(*r.world);
                   o->set_euler_filtered_frames(r.euler_filtered_frames);
                 },
             },
             report);
  return out;
}

core::StepReport StepReportFromProto(const v1::OperationReport& report) {
  if (report.has_reduction()) {
    const v1::ReductionReport& r = report.reduction();
    core::ReductionReport out;
    out.channels.reserve(static_cast<std::size_t>(r.channels_size()));
    for (const v1::ChannelReduction& c : r.channels()) {
      out.channels.push_back(core::ChannelReduction{.channel_index = c.channel_index(),
                                                    .key_count = c.key_count(),
                                                    .sample_count = c.sample_count(),
                                                    .rms_error = c.rms_error(),
                                                    .max_error = c.max_error(),
                                                    .max_error_frame = c.max_error_frame(),
                                                    .noise_sigma = c.noise_sigma(),
                                                    .noise_sigma_estimated =
                                                        c.noise_sigma_estimated()});
    }
    out.key_count = r.key_count();
    out.sample_count = r.sample_count();
    out.rms_error = r.rms_error();
    out.max_error = r.max_error();
    out.worst_channel_index = r.worst_channel_index();
    out.worst_frame = r.worst_frame();
    out.iterations = r.iterations();
    if (r.has_world_error()) out.world = WorldErrorFromProto(r.world_error());
    out.euler_filtered_frames = r.euler_filtered_frames();
    return out;
  }
  const v1::RetimeReport& r = report.retime();
  return core::RetimeReport{.output_duration_seconds = r.output_duration_seconds(),
                            .output_frame_count = r.output_frame_count(),
                            .fit_factor = r.fit_factor(),
                            .max_decimation_ratio = r.max_decimation_ratio(),
                            .filtered_sample_count = r.filtered_sample_count()};
}

}  // namespace tempokey::wire
