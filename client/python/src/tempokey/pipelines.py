"""Pipelines: the operations a call runs on a clip, as tempokey.v1 messages built from Python
values, and what a pipeline gives back.

    import tempokey as tk

    operations = [tk.retime_operation(speed="0s:1,2s:0.5,4s:0.5,4s:1", fps=30),
                  tk.reduce_operation(tolerance=0.5)]

Values (speeds, tolerances, rates) are the server's to check, with its one set of rules and
messages; the builders raise ValueError only for what cannot be encoded at all (an unknown name,
a time without a unit, both fits at once, a whole number given as 2.7), and TypeError for an
unknown keyword or a value of the wrong type (a str or bool where a number is expected, a str
where True or False is), naming the parameter.

Units: times in seconds unless a name says frames; rotations in degrees; positions in file units.
"""

import dataclasses
import fractions
import re
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from tempokey import _arguments
from tempokey.v1 import clip_pb2
from tempokey.v1 import operations_pb2

__all__ = [
    "PipelineResult", "REDUCE_OPTIONS", "RateLike", "ReduceOption", "SpeedLike", "TimeLike",
    "bake_operation", "convert_operation", "frame_rate", "parse_joint_tolerance", "parse_speed",
    "reduce_operation", "retime_operation", "speed_knot", "time_point", "world_error_lines",
]

TimeLike = Union[float, int, str]
# A speed curve: the CLI's --speed text, or (time, speed) pairs, or SpeedKnot messages.
SpeedLike = Union[str, Sequence[Union[operations_pb2.SpeedKnot, Tuple[TimeLike, float]]]]
# A frame rate: 30, "29.97", Fraction(30000, 1001) or (30000, 1001).
RateLike = Union[int, float, str, fractions.Fraction, Tuple[int, int]]

_TIME_PATTERN = re.compile(r"^\s*([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)\s*([sf])\s*$")
_NTSC_RATES = {"23.976": 24000, "29.97": 30000, "47.952": 48000, "59.94": 60000,
               "119.88": 120000}
_FILTERS = {"tent": operations_pb2.RESAMPLE_FILTER_TENT,
            "linear": operations_pb2.RESAMPLE_FILTER_LINEAR,
            "box": operations_pb2.RESAMPLE_FILTER_BOX,
            "cubic": operations_pb2.RESAMPLE_FILTER_CUBIC,
            "lanczos3": operations_pb2.RESAMPLE_FILTER_LANCZOS3}
_RETIME_METHODS = {"exact": operations_pb2.RETIME_METHOD_EXACT,
                   "paper": operations_pb2.RETIME_METHOD_PAPER}
_ROTATION_MODES = {"quaternion": operations_pb2.ROTATION_MODE_QUATERNION,
                   "euler": operations_pb2.ROTATION_MODE_EULER}
_REDUCE_METHODS = {"tolerance": operations_pb2.REDUCE_METHOD_TOLERANCE,
                   "paper": operations_pb2.REDUCE_METHOD_PAPER,
                   "noise": operations_pb2.REDUCE_METHOD_NOISE}
_POSE_ALIGNMENTS = {"none": operations_pb2.POSE_ALIGNMENT_NONE,
                    "joint": operations_pb2.POSE_ALIGNMENT_JOINT,
                    "clip": operations_pb2.POSE_ALIGNMENT_CLIP}


def _choice(table: Mapping[str, int], value: Optional[str], what: str) -> int:
    """The enum value named `value` in `table` (0, the server's default, for None)."""
    if value is None:
        return 0
    if value not in table:
        raise ValueError("%s %r is not one of %s" % (what, value, ", ".join(table)))
    return table[value]


def time_point(value: TimeLike) -> operations_pb2.TimePoint:
    """A point in time: a number is seconds; a string carries its unit, "2.5s" or "75f" (frames
    of the timeline it refers to).

    Raises: ValueError for a string without a unit or not a number; TypeError for anything but
    a number or a string (a bool, None).
    """
    if isinstance(value, str):
        match = _TIME_PATTERN.match(value)
        if not match:
            raise ValueError("time %r needs a unit, such as 2.5s or 75f" % value)
        number = float(match.group(1))
        if match.group(2) == "s":
            return operations_pb2.TimePoint(seconds=number)
        return operations_pb2.TimePoint(frames=number)
    return operations_pb2.TimePoint(seconds=_arguments.real(value, "time"))


def speed_knot(time_value: TimeLike, speed: float) -> operations_pb2.SpeedKnot:
    """One knot of a speed curve: at `time_value` (see time_point) play at `speed` (1 normal,
    0.5 half speed, 2 double speed). Speeds are checked by the server (> 0, within its range)."""
    return operations_pb2.SpeedKnot(time=time_point(time_value),
                                    speed=_arguments.real(speed, "speed"))


def parse_speed(text: str) -> List[operations_pb2.SpeedKnot]:
    """Knots written as the CLI's --speed: "0s:1,2s:0.5,4s:0.5,4s:1" (times in s or f).

    Raises: ValueError naming the knot (counted from 1) that is not "time:speed".
    """
    _arguments.text(text, "speed")
    knots = []
    for number, item in enumerate(text.split(","), start=1):
        time_text, sep, speed_text = item.strip().partition(":")
        if not sep:
            raise ValueError("speed knot %d (%r) is not time:speed, e.g. 2s:0.5" % (number, item))
        try:
            knots.append(speed_knot(time_text, float(speed_text)))
        except ValueError as error:
            raise ValueError("speed knot %d (%r): %s" % (number, item, error)) from None
    return knots


def _speed_knots(speed: SpeedLike) -> List[operations_pb2.SpeedKnot]:
    if isinstance(speed, str):
        return parse_speed(speed)
    if not hasattr(speed, "__iter__"):
        raise TypeError("speed must be a str such as \"0s:1,2s:0.5\" or a list of (time, speed) "
                        "pairs, got %s %s" % (type(speed).__name__, _arguments.shown(speed)))
    knots = []
    for number, item in enumerate(speed, start=1):
        if isinstance(item, operations_pb2.SpeedKnot):
            knots.append(item)
            continue
        if isinstance(item, (str, bytes)) or not hasattr(item, "__len__") or len(item) != 2:
            raise TypeError("speed knot %d must be a (time, speed) pair or a SpeedKnot, got %s"
                            % (number, _arguments.shown(item)))
        time_value, value = item
        knots.append(speed_knot(time_value, value))
    return knots


def frame_rate(fps: RateLike) -> Tuple[int, int]:
    """(numerator, denominator) of a frame rate in Hz: an int, a Fraction, a (num, den) pair, or
    a decimal number or string ("29.97", "23.976" and the other NTSC rates mean N*1000/1001).

    Raises: ValueError for a rate that is not a positive number.
    """
    if isinstance(fps, tuple):
        if len(fps) != 2:
            raise ValueError("frame rate %r must be a (numerator, denominator) pair" % (fps,))
        numerator = _arguments.integer(fps[0], "frame rate numerator")
        denominator = _arguments.integer(fps[1], "frame rate denominator")
    elif isinstance(fps, fractions.Fraction):
        numerator, denominator = fps.numerator, fps.denominator
    else:
        text = str(fps).strip()
        if text in _NTSC_RATES:
            return _NTSC_RATES[text], 1001
        try:
            rate = fractions.Fraction(text)
        except (ValueError, ZeroDivisionError):
            raise ValueError("frame rate %r is not a number such as 30, 29.97 or 30000/1001"
                             % (fps,)) from None
        numerator, denominator = rate.numerator, rate.denominator
    if numerator <= 0 or denominator <= 0:
        raise ValueError("frame rate %r must be > 0" % (fps,))
    if max(numerator, denominator) > _arguments.INT64[1]:
        raise ValueError("frame rate %r is out of range: %d/%d does not fit in 64-bit integers"
                         % (fps, numerator, denominator))
    return numerator, denominator


def retime_operation(speed: Optional[SpeedLike] = None, *, speed_over: str = "source",
                     holds: Sequence[Tuple[TimeLike, float]] = (), reverse: bool = False,
                     fit_seconds: Optional[float] = None, fit_frames: Optional[int] = None,
                     fit_to_grid: bool = True, fps: Optional[RateLike] = None,
                     filter: Optional[str] = None, method: Optional[str] = None,
                     rotation: Optional[str] = None,
                     pins: Sequence[Tuple[TimeLike, int]] = (),
                     min_speed: float = 0.0, max_speed: float = 0.0,
                     euler_filter: bool = False) -> operations_pb2.Operation:
    """A retime step (SPEC 3).

    Args:
      speed: the speed curve: a string like the CLI's --speed ("0s:1,2s:0.5"), or a sequence of
        (time, speed) pairs or SpeedKnot messages. None (and no other warp) is the identity.
      speed_over: "source" (times on the source timeline, as in the paper) or "output" (times
        on the output timeline, as NLE speed ramps).
      holds: (at, duration_seconds) pairs: freeze the pose at source time `at` (see
        time_point) for that many output seconds.
      reverse: play backwards.
      fit_seconds / fit_frames: make the output last exactly this long (at most one).
      fit_to_grid: scale speeds by c ~ 1 so the last output frame is the last source pose.
      fps: output frame rate (see frame_rate); None keeps the source rate.
      filter: "tent" (default), "linear", "box", "cubic" or "lanczos3".
      method: "exact" (default) or "paper" (the published procedure).
      rotation: "quaternion" (default) or "euler".
      pins: (source_time, output_frame) pairs: source time lands exactly on that output frame.
      min_speed / max_speed: allowed speed range; 0 keeps the server's (0.01 and 100).
      euler_filter: rewrite Euler flips of the output as the nearest equivalent angles.

    Raises: ValueError for what cannot be encoded (unknown names, both fits, a time without a
    unit, fit_frames or a pin's frame not a whole number); TypeError for a value of the wrong
    type (a str or bool for a number, anything but True or False for reverse, fit_to_grid and
    euler_filter); values are checked by the server (INVALID_ARGUMENT naming the knot).
    """
    retime = operations_pb2.RetimeOperation(
        reverse=_arguments.boolean(reverse, "reverse"),
        disable_fit_to_grid=not _arguments.boolean(fit_to_grid, "fit_to_grid"),
        filter=_choice(_FILTERS, filter, "filter"),
        method=_choice(_RETIME_METHODS, method, "retime method"),
        rotation_mode=_choice(_ROTATION_MODES, rotation, "rotation mode"),
        min_speed=_arguments.real(min_speed, "min_speed"),
        max_speed=_arguments.real(max_speed, "max_speed"),
        euler_filter=_arguments.boolean(euler_filter, "euler_filter"))
    if speed is not None:
        if speed_over == "source":
            retime.speed_over_source.extend(_speed_knots(speed))
        elif speed_over == "output":
            retime.speed_over_output.extend(_speed_knots(speed))
        else:
            raise ValueError("speed_over %r is not 'source' or 'output'" % speed_over)
    for number, (at, duration_seconds) in enumerate(_pairs(holds, "holds"), start=1):
        retime.holds.add(at=time_point(at), duration_seconds=_arguments.real(
            duration_seconds, "hold %d duration_seconds" % number))
    for number, (source, output_frame) in enumerate(_pairs(pins, "pins"), start=1):
        retime.pins.add(source=time_point(source), output_frame=_arguments.integer(
            output_frame, "pin %d output_frame" % number))
    if fit_seconds is not None and fit_frames is not None:
        raise ValueError("give fit_seconds or fit_frames, not both")
    if fit_seconds is not None:
        retime.fit_seconds = _arguments.real(fit_seconds, "fit_seconds")
    if fit_frames is not None:
        retime.fit_frames = _arguments.integer(fit_frames, "fit_frames")
    if fps is not None:
        retime.output_rate_numerator, retime.output_rate_denominator = frame_rate(fps)
    return operations_pb2.Operation(retime=retime)


def _pairs(items: Any, name: str) -> List[Tuple[Any, Any]]:
    """`items` as a list of pairs; anything else is a TypeError naming `name` and the item."""
    if isinstance(items, (str, bytes)) or not hasattr(items, "__iter__"):
        raise TypeError("%s must be a list of pairs, got %s %s"
                        % (name, type(items).__name__, _arguments.shown(items)))
    pairs = []
    for number, item in enumerate(items, start=1):
        if isinstance(item, (str, bytes)) or not hasattr(item, "__len__") or len(item) != 2:
            raise TypeError("%s item %d must be a pair, got %s"
                            % (name, number, _arguments.shown(item)))
        pairs.append((item[0], item[1]))
    return pairs


@dataclasses.dataclass(frozen=True)
class ReduceOption:
    """One keyword of reduce_operation(): where its value goes in tempokey.v1.ReduceOperation
    (a dotted path, e.g. "tolerance.key_budget"), how it is converted, which methods take it,
    and its one-line description."""
    field: str
    convert: Callable[[Any], Any]
    methods: Tuple[str, ...]
    doc: str
    # For an option that chooses its field from its value: sets it on the ReduceOperation
    # (then `field` only documents where it goes and `convert` is not used).
    apply: Optional[Callable[[operations_pb2.ReduceOperation, Any], None]] = None


def _pose_alignment(value: str) -> int:
    return _choice(_POSE_ALIGNMENTS, value, "pose alignment")


def parse_joint_tolerance(value: Union[float, int, str]) -> Tuple[float, bool]:
    """(value, in percent of the figure's height) of a joint tolerance: 1, "1" (file units) or
    "0.5%", as the CLI's --joint-tolerance reads it. Range checks are the server's.

    Raises: ValueError for anything else ("1cm")."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value), False
    text = str(value).strip()
    percent = text.endswith("%")
    try:
        return float(text[:-1] if percent else text), percent
    except ValueError:
        raise ValueError("joint tolerance: expected a distance in file units or a percentage of "
                         "the figure's height (1, \"0.5%%\"), got %r" % (value,)) from None


def _set_joint_tolerance(reduce: operations_pb2.ReduceOperation,
                         value: Union[float, int, str]) -> None:
    distance, percent = parse_joint_tolerance(value)
    if percent:
        reduce.tolerance.max_joint_error_percent_of_height = distance
    else:
        reduce.tolerance.max_joint_error = distance


def _noise_level(keyword: str,
                 field: str) -> Callable[[operations_pb2.ReduceOperation, Any], None]:
    """Sets noise.<field> to a level; "auto" leaves it unset (estimated per channel)."""
    def apply(reduce: operations_pb2.ReduceOperation, value: Any) -> None:
        if isinstance(value, str) and value != "auto":
            # A level spelled as text ("0.1", as the CLI's --noise takes it) is read as a number.
            try:
                value = float(value)
            except ValueError:
                raise ValueError("%s must be a number or \"auto\", got %r"
                                 % (keyword, value)) from None
        if value != "auto":
            setattr(reduce.noise, field, _arguments.real(value, keyword))
    return apply


def _real(keyword: str) -> Callable[[Any], float]:
    """The converter of a number option: refuses a str or a bool, naming the keyword."""
    return lambda value: _arguments.real(value, keyword)


# The keywords of reduce_operation(), in the order its documentation lists them. A new option of
# the reduce step is one entry here (its field, converter, methods and description).
REDUCE_OPTIONS: Dict[str, ReduceOption] = {
    "tolerance": ReduceOption("tolerance.max_rotation_error_degrees", _real("tolerance"),
                              ("tolerance",),
                              "rotation bound in degrees (server default 0.5)"),
    "position_tolerance": ReduceOption("tolerance.max_position_error",
                                       _real("position_tolerance"), ("tolerance",),
                                       "position bound in file units (default 0.3 % of the "
                                       "figure's height: the vertical extent of every joint and "
                                       "end site at the first frame)"),
    "scalar_tolerance": ReduceOption("tolerance.max_scalar_error", _real("scalar_tolerance"),
                                     ("tolerance",),
                                     "plain-channel bound (default 0.5)"),
    "key_budget": ReduceOption("tolerance.key_budget",
                               lambda value: _arguments.integer(value, "key_budget",
                                                                _arguments.INT32),
                               ("tolerance",),
                               "at most this many keys in all (replaces the bounds by one scale "
                               "of them)"),
    "fewest_keys": ReduceOption("tolerance.fewest_keys",
                                lambda value: _arguments.boolean(value, "fewest_keys"),
                                ("tolerance",),
                                "search harder for fewer keys: the same bounds, about 15 % fewer "
                                "keys, hundreds of times the time"),
    "pose_alignment": ReduceOption("tolerance.pose_alignment", _pose_alignment, ("tolerance",),
                                   '"none" (default), "joint" or "clip": channels share key '
                                   "times"),
    "joint_tolerance": ReduceOption("tolerance.max_joint_error[_percent_of_height]", float,
                                    ("tolerance",),
                                    "a world-space bound: every joint and end site within it of "
                                    'its source position at every frame, in file units (1) or '
                                    'percent of the figure\'s height ("0.5%"); unset rotation and '
                                    "position bounds then leave each channel's bound to it",
                                    apply=_set_joint_tolerance),
    "noise": ReduceOption("noise.rotation_sigma_degrees", _real("noise"), ("noise",),
                          'rotation channels\' noise level in degrees, or "auto" (default: '
                          "estimated per channel from the data)",
                          apply=_noise_level("noise", "rotation_sigma_degrees")),
    "position_noise": ReduceOption("noise.position_sigma", _real("position_noise"), ("noise",),
                                   'the same for position and plain channels (file units), or '
                                   '"auto"', apply=_noise_level("position_noise",
                                                                "position_sigma")),
    "euler_filter": ReduceOption("euler_filter",
                                 lambda value: _arguments.boolean(value, "euler_filter"),
                                 ("tolerance", "paper", "noise"),
                                 "the Euler filter on the input (True/False); unset takes the "
                                 'method\'s default (on for "noise", off for the others)'),
}


def _set_field(message: Any, path: str, value: Any) -> None:
    """Sets the field at dotted `path` of `message` (sub-messages are created as needed)."""
    *parents, name = path.split(".")
    for parent in parents:
        message = getattr(message, parent)
    setattr(message, name, value)


def reduce_operation(*, method: str = "tolerance", paper: Optional[Mapping[str, Any]] = None,
                     **options: Any) -> operations_pb2.Operation:
    """A key-reduction step (SPEC 4): the sampled clip becomes key-frame curves.

    Args:
      method: "tolerance" (fewest keys keeping every channel within its bound at every source
        frame), "noise" (noise-aware: a fit whose residual matches each channel's noise level)
        or "paper" (the published Hermite DP fit; bounds nothing).
      paper: fields of tempokey.v1.PaperParams for method "paper", e.g. {"step_y": 0.25}.
      **options: the keywords of REDUCE_OPTIONS, listed below; None leaves one unset (the
        server's default).

    Raises:
      TypeError: a keyword that is not an option, a value of the wrong type (tolerance="0.5",
        euler_filter="yes").
      ValueError: an unknown method or alignment, a paper field that does not exist, an option
        of another method, key_budget not a whole number. Values are checked by the server.
    """
    reduce = operations_pb2.ReduceOperation(method=_choice(_REDUCE_METHODS, method, "method"))
    for keyword, value in options.items():
        option = REDUCE_OPTIONS.get(keyword)
        if option is None:
            raise TypeError("reduce_operation() got an unexpected keyword argument %r "
                            "(options: %s)" % (keyword, ", ".join(REDUCE_OPTIONS)))
        if value is None:
            continue
        if method not in option.methods:
            raise ValueError("%s belongs to method %s, not %r"
                             % (keyword, " or ".join(repr(m) for m in option.methods), method))
        if option.apply is not None:
            option.apply(reduce, value)
        else:
            _set_field(reduce, option.field, option.convert(value))
    if method != "paper" and paper:
        raise ValueError("paper parameters belong to method 'paper'")
    for field, value in (paper or {}).items():
        try:
            setattr(reduce.paper, field, value)
        except (AttributeError, TypeError) as error:
            raise ValueError("paper parameter %r: %s" % (field, error)) from None
    return operations_pb2.Operation(reduce=reduce)


if reduce_operation.__doc__:  # None under python -OO
    reduce_operation.__doc__ = reduce_operation.__doc__.rstrip() + "\n\n    Options:\n" + "".join(
        "      %s: %s (method %s).\n" % (keyword, option.doc, " or ".join(option.methods))
        for keyword, option in REDUCE_OPTIONS.items())


def bake_operation(fps: Optional[RateLike] = None) -> operations_pb2.Operation:
    """Evaluates key-frame curves back to samples at `fps` (see frame_rate; None keeps the rate
    of the clip the curves came from)."""
    bake = operations_pb2.BakeOperation()
    if fps is not None:
        bake.rate_numerator, bake.rate_denominator = frame_rate(fps)
    return operations_pb2.Operation(bake=bake)


def convert_operation(wrap_rotations: bool = False) -> operations_pb2.Operation:
    """Format-level conversion of a sampled clip: re-wrap rotations into (-180, 180]."""
    return operations_pb2.Operation(convert=operations_pb2.ConvertOperation(
        wrap_rotations=_arguments.boolean(wrap_rotations, "wrap_rotations")))


# ---- results ------------------------------------------------------------------------------------

@dataclasses.dataclass
class PipelineResult:
    """What a pipeline produced: exactly one of `clip` (sampled) and `keyed_clip` (curves), and
    one tempokey.v1.OperationReport per operation, in pipeline order."""
    reports: List[operations_pb2.OperationReport]
    clip: Optional[clip_pb2.Clip] = None
    keyed_clip: Optional[clip_pb2.KeyedClip] = None

    def _last_report(self, kind: str) -> Any:
        found = [r for r in self.reports if r.WhichOneof("kind") == kind]
        return getattr(found[-1], kind) if found else None

    @property
    def retime_report(self) -> Optional[operations_pb2.RetimeReport]:
        """The last retime's report (output frames and duration, fit factor), or None."""
        return self._last_report("retime")

    @property
    def reduction_report(self) -> Optional[operations_pb2.ReductionReport]:
        """The last reduction's report (keys, samples, RMS and max error), or None."""
        return self._last_report("reduction")

    @property
    def world_error(self) -> Optional[operations_pb2.WorldErrorReport]:
        """The last reduction's joint world-position error (file units; percentages of
        figure_height_units), or None without a reduction or a skeleton."""
        report = self.reduction_report
        if report is None or not report.HasField("world_error"):
            return None
        return report.world_error


def world_error_lines(world: operations_pb2.WorldErrorReport) -> List[str]:
    """The CLI's lines for a world error report ("joint max error: 0.9850 (0.707% of height) at
    Toes_R, frame 94", ...)."""
    height = world.figure_height_units

    def percent(distance: float) -> float:
        return 100.0 * distance / height if height > 0 else 0.0

    lines = ["figure height:   %.4g (first frame)" % height,
             "joint max error: %.4f (%.3f%% of height) at %s, frame %d"
             % (world.max_error_units, percent(world.max_error_units), world.worst_point,
                world.worst_frame),
             "joint rms error: %.4f (%.3f%% of height)"
             % (world.rms_error_units, percent(world.rms_error_units))]
    if world.joint_tolerance_units > 0:
        lines.append("joint bound:     %.4g (%.3f%% of height)"
                     % (world.joint_tolerance_units, percent(world.joint_tolerance_units)))
    return lines
