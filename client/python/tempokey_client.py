"""A small Python client of tempokey.v1.MotionService (SPEC 6).

It needs Debian's python3-grpcio and python3-protobuf, and the tempokey.v1 stubs the build
generates (target ``tempokey_python_stubs``, written to ``<build>/python``)::

    PYTHONPATH=build/python:client/python python3 client/python/example_pipeline.py ...

The studio-pipeline call, one stateless ``Process`` call (safe through a load balancer)::

    import tempokey_client as tk

    clip = tk.make_clip("walk", 1 / 30,
                        channels=[tk.ChannelSpec("Xrotation", joint_index=0)],
                        samples=[[0.0, 1.5, 3.0, 2.0]],
                        joints=[tk.JointSpec("Hips")])
    with tk.connect("127.0.0.1:50051", timeout=60) as client:
        result = client.process(clip, [tk.retime_operation(speed="0s:1,2s:0.5,4s:0.5,4s:1"),
                                       tk.reduce_operation(tolerance=0.5)])
    result.keyed_clip        # tempokey.v1.KeyedClip: the header and one curve per channel
    result.reduction_report  # keys kept, RMS and max error, worst channel and frame

Stored jobs go through ``upload_clip``, ``submit``, ``watch`` and ``result``.

Clips are ``tempokey.v1.Clip`` messages (a header plus samples); ``make_clip`` builds one from
plain Python lists. They are sent as the C++ client sends them: the header, then slices of at
most 1 MiB of samples (less when the server's message limit is smaller), channel by channel.
Results are reassembled into one ``Clip`` (one ``ChannelSamples`` per channel covering every
frame) or one ``KeyedClip`` (one ``KeyedCurve`` per channel), with the operations' reports.

Units: times in seconds unless a name says frames; rotations in degrees; positions in file units.

Errors: a failed call raises ``TempokeyError`` carrying the gRPC status code (``.code``, a
``grpc.StatusCode``) and the server's message (``.details``) exactly as sent, e.g.
``INVALID_ARGUMENT: operation 1 (retime): speed knot 2 (2s:-1): speed must be > 0``. Values
(NaN samples, speeds out of range, ...) are the server's to check, with its one set of rules and
messages; the helpers here raise ``ValueError`` only for what cannot be encoded at all (an
unknown channel kind, ragged sample lists, a time without a unit). Only UNAVAILABLE is retried
(the server is draining or unreachable), as the C++ client does.
"""

import dataclasses
import fractions
import json
import random
import re
import time
import uuid
from typing import Callable, Iterator, List, Optional, Sequence, Tuple, Union

import grpc

try:
    from tempokey.v1 import clip_pb2
    from tempokey.v1 import motion_service_pb2
    from tempokey.v1 import motion_service_pb2_grpc
    from tempokey.v1 import operations_pb2
except ImportError as error:  # pragma: no cover - depends on the caller's PYTHONPATH
    raise ImportError(
        "cannot import the generated tempokey.v1 stubs (%s): build the tempokey_python_stubs "
        "target and put <build>/python on PYTHONPATH" % error) from error

__all__ = [
    "ChannelSpec", "Client", "JointSpec", "MarkerSpec", "PipelineResult", "TempokeyError",
    "bake_operation", "connect", "convert_operation", "make_clip", "parse_speed",
    "reduce_operation", "retime_operation", "speed_knot", "time_point",
]

MOTION_SERVICE = "tempokey.v1.MotionService"
HEALTH_CHECK_METHOD = "/grpc.health.v1.Health/Check"
# Samples per sent or received message, as the C++ client (wire::kDefaultSliceBytes).
DEFAULT_SLICE_BYTES = 1 << 20
# Largest message accepted from the server; results come in slices well below it.
DEFAULT_MAX_RECEIVE_BYTES = 64 << 20
# Trailing metadata of a RESOURCE_EXHAUSTED from a full queue: whole milliseconds to wait.
RETRY_AFTER_METADATA_KEY = "retry-after-ms"
_BYTES_PER_SAMPLE = 8
_UNARY_METHODS = ("GetServerInfo", "SubmitJob", "GetJob", "ListJobs", "CancelJob", "DeleteJob")


# ---- errors -------------------------------------------------------------------------------------

class TempokeyError(Exception):
    """A failed call: the gRPC status code and the server's message, unchanged.

    Attributes:
      code: grpc.StatusCode, e.g. grpc.StatusCode.INVALID_ARGUMENT.
      details: the server's message ("operation 1 (retime): ...").
      retry_after_seconds: the server's hint of when to try again (a full queue), or None.
    """

    def __init__(self, code: grpc.StatusCode, details: str,
                 retry_after_seconds: Optional[float] = None):
        super().__init__("%s: %s" % (code.name, details))
        self.code = code
        self.details = details
        self.retry_after_seconds = retry_after_seconds


def _retry_after_seconds(call) -> Optional[float]:
    """The retry-after-ms trailing metadata of a finished call, in seconds, or None."""
    try:
        trailers = call.trailing_metadata() or ()
    except Exception:  # a call that never reached the server has no trailers
        return None
    for key, value in trailers:
        if key == RETRY_AFTER_METADATA_KEY and str(value).isdigit():
            return int(value) / 1000.0
    return None


def _from_rpc_error(error: grpc.RpcError) -> TempokeyError:
    """The one place gRPC errors become TempokeyError: same code, same message."""
    code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
    details = error.details() if hasattr(error, "details") else str(error)
    return TempokeyError(code, details or "", _retry_after_seconds(error))


def _malformed_result(what: str) -> TempokeyError:
    return TempokeyError(grpc.StatusCode.INTERNAL, "malformed result from the server: " + what)


# ---- clips --------------------------------------------------------------------------------------

# Channel kind names as BVH and the keyed-clip JSON spell them.
CHANNEL_KINDS = {
    "Xposition": clip_pb2.CHANNEL_KIND_X_POSITION,
    "Yposition": clip_pb2.CHANNEL_KIND_Y_POSITION,
    "Zposition": clip_pb2.CHANNEL_KIND_Z_POSITION,
    "Xrotation": clip_pb2.CHANNEL_KIND_X_ROTATION,
    "Yrotation": clip_pb2.CHANNEL_KIND_Y_ROTATION,
    "Zrotation": clip_pb2.CHANNEL_KIND_Z_ROTATION,
    "scalar": clip_pb2.CHANNEL_KIND_SCALAR,
}
CHANNEL_KIND_NAMES = {value: name for name, value in CHANNEL_KINDS.items()}


@dataclasses.dataclass(frozen=True)
class JointSpec:
    """A joint: its name, parent (index into the joint list, -1 for a root; parents first),
    offset from the parent and End Site offsets, in file units."""
    name: str
    parent_index: int = -1
    offset: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    end_sites: Tuple[Tuple[float, float, float], ...] = ()


@dataclasses.dataclass(frozen=True)
class ChannelSpec:
    """A channel: its kind ("Xposition".."Zrotation" or "scalar"), the joint it animates (index
    into the joint list; None for a plain channel) and, for plain channels, its name."""
    kind: str
    joint_index: Optional[int] = None
    name: str = ""


@dataclasses.dataclass(frozen=True)
class MarkerSpec:
    """A timed annotation (foot contact, event); 0 duration for an instant. Seconds."""
    name: str
    time_seconds: float
    duration_seconds: float = 0.0


def _vec3(values: Sequence[float], what: str) -> clip_pb2.Vec3:
    if len(values) != 3:
        raise ValueError("%s must have 3 numbers, got %d" % (what, len(values)))
    x, y, z = (float(v) for v in values)
    return clip_pb2.Vec3(x=x, y=y, z=z)


def _channel_info(index: int, spec: Union[ChannelSpec, str]) -> clip_pb2.ChannelInfo:
    if isinstance(spec, str):
        spec = ChannelSpec("scalar", name=spec)
    if spec.kind not in CHANNEL_KINDS:
        raise ValueError("channel %d: unknown kind %r, expected one of %s"
                         % (index, spec.kind, ", ".join(CHANNEL_KINDS)))
    info = clip_pb2.ChannelInfo(kind=CHANNEL_KINDS[spec.kind], name=spec.name)
    if spec.joint_index is not None:
        info.joint_index = spec.joint_index
    return info


def make_clip(name: str, frame_time_seconds: float,
              channels: Sequence[Union[ChannelSpec, str]],
              samples: Sequence[Sequence[float]],
              joints: Sequence[JointSpec] = (),
              markers: Sequence[MarkerSpec] = ()) -> clip_pb2.Clip:
    """Builds a tempokey.v1.Clip from plain Python values.

    Args:
      name: the clip's name (results carry it).
      frame_time_seconds: seconds between samples (1/30 for 30 fps), kept exactly.
      channels: one ChannelSpec per channel in column order, or a str for a plain (scalar)
        channel of that name. A joint's channels compose in the order they are listed.
      samples: channel-major, one sequence of numbers per channel, all of the same length (the
        frame count).
      joints: the skeleton, parents before children; empty for plain channels only.
      markers: timed annotations, mapped through retiming.

    Returns: the clip (header plus one whole-channel ChannelSamples per channel).

    Raises:
      ValueError: an unknown channel kind, a channel count not matching the sample lists, sample
        lists of different lengths or holding something that is not a number. Everything else
        (NaN, a frame time <= 0, joint indices out of range, ...) is checked by the server,
        which answers INVALID_ARGUMENT naming what is wrong.
    """
    if len(channels) != len(samples):
        raise ValueError("%d channels but %d sample lists; give one list per channel"
                         % (len(channels), len(samples)))
    frame_count = len(samples[0]) if samples else 0
    header = clip_pb2.ClipHeader(name=name, frame_time_seconds=float(frame_time_seconds),
                                 frame_count=frame_count)
    for joint in joints:
        header.joints.add(name=joint.name, parent_index=joint.parent_index,
                          offset=_vec3(joint.offset, "joint %s offset" % joint.name),
                          end_site_offsets=[_vec3(site, "joint %s end site" % joint.name)
                                            for site in joint.end_sites])
    for index, spec in enumerate(channels):
        header.channels.append(_channel_info(index, spec))
    for marker in markers:
        header.markers.add(name=marker.name, time_seconds=float(marker.time_seconds),
                           duration_seconds=float(marker.duration_seconds))
    clip = clip_pb2.Clip(header=header)
    for index, values in enumerate(samples):
        if len(values) != frame_count:
            raise ValueError("channel %d has %d samples, channel 0 has %d; every channel needs "
                             "one sample per frame" % (index, len(values), frame_count))
        try:
            floats = [float(v) for v in values]
        except (TypeError, ValueError) as error:
            raise ValueError("channel %d: samples must be numbers (%s)" % (index, error)) from None
        clip.samples.add(channel_index=index, first_frame=0, samples=floats)
    return clip


def channel_label(header: clip_pb2.ClipHeader, index: int) -> str:
    """"Hips.Xrotation" for a joint channel, the name for a plain one (as the server says)."""
    info = header.channels[index]
    kind = CHANNEL_KIND_NAMES.get(info.kind, "channel")
    if info.HasField("joint_index") and 0 <= info.joint_index < len(header.joints):
        return "%s.%s" % (header.joints[info.joint_index].name, kind)
    return info.name or "channel %d" % index


def _samples_per_slice(slice_bytes: int) -> int:
    return max(1, slice_bytes // _BYTES_PER_SAMPLE)


def _sample_slices(clip: clip_pb2.Clip, slice_bytes: int) -> Iterator[clip_pb2.ChannelSamples]:
    """Consecutive slices of `clip`'s samples, each at most `slice_bytes` of samples (at least one
    sample), in the order they are stored (channel by channel for make_clip's clips)."""
    per_slice = _samples_per_slice(slice_bytes)
    for run in clip.samples:
        values = run.samples
        for start in range(0, len(values), per_slice):
            yield clip_pb2.ChannelSamples(channel_index=run.channel_index,
                                          first_frame=run.first_frame + start,
                                          samples=values[start:start + per_slice])


def _sample_batches(clip: clip_pb2.Clip, slice_bytes: int) -> Iterator[clip_pb2.SampleSlices]:
    """The slices of _sample_slices() packed into SampleSlices messages of at most `slice_bytes`
    of samples in all, for servers that list the "sample_slices" feature: a clip of many short
    channels then takes a few messages instead of one per channel."""
    budget = _samples_per_slice(slice_bytes)
    batch = clip_pb2.SampleSlices()
    used = 0
    for run in clip.samples:
        values = run.samples
        start = 0
        while start < len(values):
            count = min(budget - used, len(values) - start)
            batch.slices.add(channel_index=run.channel_index, first_frame=run.first_frame + start,
                             samples=values[start:start + count])
            start += count
            used += count
            if used == budget:
                yield batch
                batch = clip_pb2.SampleSlices()
                used = 0
    if batch.slices:
        yield batch


# ---- operations ---------------------------------------------------------------------------------

TimeLike = Union[float, int, str]

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


def _choice(table: dict, value: Optional[str], what: str) -> int:
    """The enum value named `value` in `table` (0, the server's default, for None)."""
    if value is None:
        return 0
    if value not in table:
        raise ValueError("%s %r is not one of %s" % (what, value, ", ".join(table)))
    return table[value]


def time_point(value: TimeLike) -> operations_pb2.TimePoint:
    """A point in time: a number is seconds; a string carries its unit, "2.5s" or "75f" (frames
    of the timeline it refers to).

    Raises: ValueError for a string without a unit or not a number.
    """
    if isinstance(value, str):
        match = _TIME_PATTERN.match(value)
        if not match:
            raise ValueError("time %r needs a unit, such as 2.5s or 75f" % value)
        number = float(match.group(1))
        if match.group(2) == "s":
            return operations_pb2.TimePoint(seconds=number)
        return operations_pb2.TimePoint(frames=number)
    return operations_pb2.TimePoint(seconds=float(value))


def speed_knot(time_value: TimeLike, speed: float) -> operations_pb2.SpeedKnot:
    """One knot of a speed curve: at `time_value` (see time_point) play at `speed` (1 normal,
    0.5 half speed, 2 double speed). Speeds are checked by the server (> 0, within its range)."""
    return operations_pb2.SpeedKnot(time=time_point(time_value), speed=float(speed))


def parse_speed(text: str) -> List[operations_pb2.SpeedKnot]:
    """Knots written as the CLI's --speed: "0s:1,2s:0.5,4s:0.5,4s:1" (times in s or f).

    Raises: ValueError naming the knot (counted from 1) that is not "time:speed".
    """
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


def _speed_knots(speed) -> List[operations_pb2.SpeedKnot]:
    if isinstance(speed, str):
        return parse_speed(speed)
    knots = []
    for item in speed:
        if isinstance(item, operations_pb2.SpeedKnot):
            knots.append(item)
        else:
            time_value, value = item
            knots.append(speed_knot(time_value, value))
    return knots


def frame_rate(fps) -> Tuple[int, int]:
    """(numerator, denominator) of a frame rate in Hz: an int, a Fraction, a (num, den) pair, or
    a decimal number or string ("29.97", "23.976" and the other NTSC rates mean N*1000/1001).

    Raises: ValueError for a rate that is not a positive number.
    """
    if isinstance(fps, tuple):
        numerator, denominator = (int(v) for v in fps)
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
    return numerator, denominator


def retime_operation(speed=None, *, speed_over: str = "source", holds=(),
                     reverse: bool = False, fit_seconds: Optional[float] = None,
                     fit_frames: Optional[int] = None, fit_to_grid: bool = True, fps=None,
                     filter: Optional[str] = None, method: Optional[str] = None,
                     rotation: Optional[str] = None, pins=(),
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
    unit); values are checked by the server (INVALID_ARGUMENT naming the knot).
    """
    retime = operations_pb2.RetimeOperation(
        reverse=reverse, disable_fit_to_grid=not fit_to_grid,
        filter=_choice(_FILTERS, filter, "filter"),
        method=_choice(_RETIME_METHODS, method, "retime method"),
        rotation_mode=_choice(_ROTATION_MODES, rotation, "rotation mode"),
        min_speed=float(min_speed), max_speed=float(max_speed), euler_filter=bool(euler_filter))
    if speed is not None:
        if speed_over == "source":
            retime.speed_over_source.extend(_speed_knots(speed))
        elif speed_over == "output":
            retime.speed_over_output.extend(_speed_knots(speed))
        else:
            raise ValueError("speed_over %r is not 'source' or 'output'" % speed_over)
    for at, duration_seconds in holds:
        retime.holds.add(at=time_point(at), duration_seconds=float(duration_seconds))
    for source, output_frame in pins:
        retime.pins.add(source=time_point(source), output_frame=int(output_frame))
    if fit_seconds is not None and fit_frames is not None:
        raise ValueError("give fit_seconds or fit_frames, not both")
    if fit_seconds is not None:
        retime.fit_seconds = float(fit_seconds)
    if fit_frames is not None:
        retime.fit_frames = int(fit_frames)
    if fps is not None:
        retime.output_rate_numerator, retime.output_rate_denominator = frame_rate(fps)
    return operations_pb2.Operation(retime=retime)


def reduce_operation(*, method: str = "tolerance", tolerance: Optional[float] = None,
                     position_tolerance: Optional[float] = None,
                     scalar_tolerance: Optional[float] = None,
                     key_budget: Optional[int] = None,
                     pose_alignment: Optional[str] = None,
                     paper: Optional[dict] = None,
                     noise="auto", position_noise="auto",
                     euler_filter: Optional[bool] = None) -> operations_pb2.Operation:
    """A key-reduction step (SPEC 4): the sampled clip becomes key-frame curves.

    Args:
      method: "tolerance" (fewest keys keeping every channel within its bound at every source
        frame) or "paper" (the published Hermite DP fit; bounds nothing).
      tolerance: rotation bound in degrees (server default 0.5).
      position_tolerance: position bound in file units (default 0.5).
      scalar_tolerance: plain-channel bound (default 0.5).
      key_budget: at most this many keys in all (replaces the bounds by one scale of them).
      pose_alignment: "none" (default), "joint" or "clip": channels share key times.
      paper: fields of tempokey.v1.PaperParams for method "paper", e.g. {"step_y": 0.25}.
      noise: method "noise": the noise level of rotation channels in degrees, or "auto"
        (default: estimated per channel from the data).
      position_noise: method "noise": the same for position and scalar channels (file units).
      euler_filter: the Euler filter on the input (True/False); None takes the method's
        default (on for "noise", off for the others).

    Raises: ValueError for an unknown method, alignment or paper field, or settings of another
    method; values are checked by the server.
    """
    reduce = operations_pb2.ReduceOperation(method=_choice(_REDUCE_METHODS, method, "method"))
    bounds = {"max_rotation_error_degrees": tolerance, "max_position_error": position_tolerance,
              "max_scalar_error": scalar_tolerance, "key_budget": key_budget}
    given = {field: value for field, value in bounds.items() if value is not None}
    if method == "paper" and (given or pose_alignment is not None):
        raise ValueError("tolerances, key_budget and pose_alignment belong to method 'tolerance'")
    if method != "tolerance" and (given or pose_alignment is not None):
        raise ValueError("tolerances, key_budget and pose_alignment belong to method 'tolerance'")
    if method != "paper" and paper:
        raise ValueError("paper parameters belong to method 'paper'")
    levels = {"rotation_sigma_degrees": noise, "position_sigma": position_noise}
    for field, value in levels.items():
        if value == "auto":
            continue
        if method != "noise":
            raise ValueError("noise levels belong to method 'noise'")
        setattr(reduce.noise, field, float(value))
    if euler_filter is not None:
        reduce.euler_filter = bool(euler_filter)
    for field, value in given.items():
        setattr(reduce.tolerance, field, int(value) if field == "key_budget" else float(value))
    if pose_alignment is not None:
        reduce.tolerance.pose_alignment = _choice(_POSE_ALIGNMENTS, pose_alignment,
                                                  "pose alignment")
    for field, value in (paper or {}).items():
        try:
            setattr(reduce.paper, field, value)
        except (AttributeError, TypeError) as error:
            raise ValueError("paper parameter %r: %s" % (field, error)) from None
    return operations_pb2.Operation(reduce=reduce)


def bake_operation(fps=None) -> operations_pb2.Operation:
    """Evaluates key-frame curves back to samples at `fps` (see frame_rate; None keeps the rate
    of the clip the curves came from)."""
    bake = operations_pb2.BakeOperation()
    if fps is not None:
        bake.rate_numerator, bake.rate_denominator = frame_rate(fps)
    return operations_pb2.Operation(bake=bake)


def convert_operation(wrap_rotations: bool = False) -> operations_pb2.Operation:
    """Format-level conversion of a sampled clip: re-wrap rotations into (-180, 180]."""
    return operations_pb2.Operation(
        convert=operations_pb2.ConvertOperation(wrap_rotations=wrap_rotations))


# ---- results ------------------------------------------------------------------------------------

@dataclasses.dataclass
class PipelineResult:
    """What a pipeline produced: exactly one of `clip` (sampled) and `keyed_clip` (curves), and
    one tempokey.v1.OperationReport per operation, in pipeline order."""
    reports: List[operations_pb2.OperationReport]
    clip: Optional[clip_pb2.Clip] = None
    keyed_clip: Optional[clip_pb2.KeyedClip] = None

    def _last_report(self, kind: str):
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


class _ResultAssembler:
    """Rebuilds a PipelineResult from the ResultPart messages of Process or GetJobResult: a
    header (reports, then a clip or keyed-clip header), then sample slices or curve pieces.
    Slices of a channel must tile its frames exactly; curve pieces of a channel are joined in
    arrival order. Raises TempokeyError (INTERNAL) for anything else."""

    def __init__(self):
        self._header = None
        self._slices = {}  # channel index -> [(first_frame, samples)]
        self._curves = {}  # channel index -> KeyedCurve joined so far

    def add(self, part: motion_service_pb2.ResultPart) -> None:
        kind = part.WhichOneof("part")
        if kind == "header":
            if self._header is not None:
                raise _malformed_result("a second result header")
            if part.header.WhichOneof("kind") is None:
                raise _malformed_result("the header names neither a clip nor a keyed clip")
            self._header = part.header
            return
        if self._header is None:
            raise _malformed_result("%s before the header" % (kind or "an empty part"))
        keyed = self._header.WhichOneof("kind") == "keyed_clip"
        if kind == "samples" and not keyed:
            self._add_samples(part.samples)
        elif kind == "sample_slices" and not keyed:
            for samples in part.sample_slices.slices:
                self._add_samples(samples)
        elif kind == "curve" and keyed:
            self._add_curve(part.curve)
        elif kind == "curves" and keyed:
            for piece in part.curves.curves:
                self._add_curve(piece)
        else:
            raise _malformed_result("a %s part in a %s result"
                                    % (kind, "keyed" if keyed else "sampled"))

    def _layout(self) -> clip_pb2.ClipHeader:
        return getattr(self._header, self._header.WhichOneof("kind"))

    def _check_channel(self, index: int) -> None:
        if not 0 <= index < len(self._layout().channels):
            raise _malformed_result("channel index %d out of range" % index)

    def _add_samples(self, samples: clip_pb2.ChannelSamples) -> None:
        self._check_channel(samples.channel_index)
        self._slices.setdefault(samples.channel_index, []).append(
            (samples.first_frame, samples.samples))

    def _add_curve(self, piece: clip_pb2.KeyedCurve) -> None:
        self._check_channel(piece.channel_index)
        curve = self._curves.setdefault(piece.channel_index,
                                        clip_pb2.KeyedCurve(channel_index=piece.channel_index))
        curve.MergeFrom(piece)  # repeated columns append: consecutive runs of keys

    def _channel_samples(self, layout: clip_pb2.ClipHeader, index: int) -> List[float]:
        values: List[float] = []
        for first_frame, run in sorted(self._slices.get(index, []), key=lambda s: s[0]):
            if first_frame != len(values):
                raise _malformed_result("%s: frames %d..%d %s" % (
                    channel_label(layout, index), min(first_frame, len(values)),
                    max(first_frame, len(values)) - 1,
                    "missing" if first_frame > len(values) else "sent twice"))
            values.extend(run)
        if len(values) != layout.frame_count:
            raise _malformed_result("%s: %d samples for %d frames" % (
                channel_label(layout, index), len(values), layout.frame_count))
        return values

    def finish(self) -> PipelineResult:
        if self._header is None:
            raise _malformed_result("the result has no header")
        layout = self._layout()
        result = PipelineResult(reports=list(self._header.reports))
        if self._header.WhichOneof("kind") == "clip":
            clip = clip_pb2.Clip(header=layout)
            for index in range(len(layout.channels)):
                clip.samples.add(channel_index=index, first_frame=0,
                                 samples=self._channel_samples(layout, index))
            result.clip = clip
        else:
            keyed = clip_pb2.KeyedClip(header=layout)
            for index in range(len(layout.channels)):
                if index not in self._curves:
                    raise _malformed_result("%s: no curve arrived" % channel_label(layout, index))
                keyed.curves.append(self._curves[index])
            result.keyed_clip = keyed
        return result


def keyed_clip_to_dict(keyed: clip_pb2.KeyedClip) -> dict:
    """A keyed clip as the "tempokey.keyed_clip" version 1 JSON document (README, File formats),
    the schema the C++ tools write: json.dump() it and `tempokey` reads the same curves back.

    Keys are [time_seconds, value, in_tangent, out_tangent], plus [in_weight, out_weight] for a
    curve that carries weights; slopes are value units per second, weights fractions of the
    segment. Python writes floats in their shortest round-trip form, so no digit is lost.
    """
    header = keyed.header
    curves = {curve.channel_index: curve for curve in keyed.curves}
    joints = []
    for index, joint in enumerate(header.joints):
        joints.append({
            "name": joint.name, "parent": joint.parent_index,
            "offset": [joint.offset.x, joint.offset.y, joint.offset.z],
            "end_sites": [[s.x, s.y, s.z] for s in joint.end_site_offsets],
            "channels": [c for c, info in enumerate(header.channels)
                         if info.HasField("joint_index") and info.joint_index == index]})
    channels = []
    for index, info in enumerate(header.channels):
        curve = curves.get(index, clip_pb2.KeyedCurve())
        weighted = len(curve.in_weight) > 0 or len(curve.out_weight) > 0
        keys = []
        for k in range(len(curve.time_seconds)):
            key = [curve.time_seconds[k], curve.value[k], curve.in_tangent[k],
                   curve.out_tangent[k]]
            if weighted:
                key += [curve.in_weight[k] if curve.in_weight else None,
                        curve.out_weight[k] if curve.out_weight else None]
            keys.append(key)
        channels.append({"joint": info.joint_index if info.HasField("joint_index") else -1,
                         "kind": CHANNEL_KIND_NAMES.get(info.kind, "scalar"),
                         "name": info.name, "keys": keys})
    return {
        "format": "tempokey.keyed_clip", "version": 1, "name": header.name,
        "frame_time_seconds": header.frame_time_seconds, "frame_count": header.frame_count,
        "joints": joints, "channels": channels,
        "markers": [{"name": m.name, "time_seconds": m.time_seconds,
                     "duration_seconds": m.duration_seconds} for m in header.markers],
    }


# ---- health codec -------------------------------------------------------------------------------
# grpc.health.v1 by hand, as the C++ client does: Debian ships no Python health stubs and the
# messages are tiny: HealthCheckRequest { string service = 1; } and
# HealthCheckResponse { ServingStatus status = 1; } (an enum, a varint on the wire).

HEALTH_STATES = ("UNKNOWN", "SERVING", "NOT_SERVING", "SERVICE_UNKNOWN")


def _encode_varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _decode_varint(data: bytes, pos: int) -> Tuple[int, int]:
    value, shift = 0, 0
    while True:
        if pos >= len(data) or shift > 63:
            raise ValueError("health response: truncated varint")
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, pos


def _encode_health_request(service: str) -> bytes:
    name = service.encode("utf-8")
    return (b"\x0a" + _encode_varint(len(name)) + name) if name else b""


def _decode_health_response(data: bytes) -> str:
    """The status name of HealthCheckResponse wire bytes; unknown fields are skipped."""
    status, pos = 0, 0
    while pos < len(data):
        tag, pos = _decode_varint(data, pos)
        field, wire_type = tag >> 3, tag & 7
        if wire_type == 0:
            value, pos = _decode_varint(data, pos)
            if field == 1:
                status = value
        elif wire_type == 2:
            length, pos = _decode_varint(data, pos)
            pos += length
        elif wire_type in (1, 5):
            pos += 8 if wire_type == 1 else 4
        else:
            raise ValueError("health response: wire type %d not expected" % wire_type)
    if pos > len(data) or status >= len(HEALTH_STATES):
        raise ValueError("health response: malformed (status %d)" % status)
    return HEALTH_STATES[status]


# ---- the client ---------------------------------------------------------------------------------

def _service_config(max_attempts: int) -> str:
    """Round-robin over every address of the target, and retries on UNAVAILABLE for unary
    methods (the streaming ones are retried by the Client, before anything was received)."""
    config = {"loadBalancingConfig": [{"round_robin": {}}]}
    if max_attempts > 1:
        names = [{"service": MOTION_SERVICE, "method": m} for m in _UNARY_METHODS]
        names.append({"service": "grpc.health.v1.Health", "method": "Check"})
        config["methodConfig"] = [{"name": names, "retryPolicy": {
            "maxAttempts": max_attempts, "initialBackoff": "0.1s", "maxBackoff": "1s",
            "backoffMultiplier": 2, "retryableStatusCodes": ["UNAVAILABLE"]}}]
    return json.dumps(config)


class Client:
    """A client of one target. Use connect() to make one; close() (or a `with` block) releases
    the channel. Every method raises TempokeyError for a failed call. Each method call has one
    deadline of `timeout` seconds covering all its attempts (None: no deadline)."""

    def __init__(self, channel: grpc.Channel, *, timeout: Optional[float] = 60.0,
                 token: Optional[str] = None, max_attempts: int = 4,
                 slice_bytes: int = DEFAULT_SLICE_BYTES):
        if max_attempts < 1:
            raise ValueError("max_attempts must be >= 1, got %d" % max_attempts)
        if slice_bytes < _BYTES_PER_SAMPLE:
            raise ValueError("slice_bytes must be >= 8, got %d" % slice_bytes)
        self._channel = channel
        self._stub = motion_service_pb2_grpc.MotionServiceStub(channel)
        self._health_check = channel.unary_unary(
            HEALTH_CHECK_METHOD, request_serializer=_encode_health_request,
            response_deserializer=_decode_health_response)
        self._timeout = timeout
        self._metadata = (("authorization", "Bearer " + token),) if token else ()
        self._max_attempts = max_attempts
        self._slice_bytes = slice_bytes
        self._server_info = None

    def close(self) -> None:
        """Closes the channel; calls in flight are cancelled."""
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- plumbing --

    def _deadline(self) -> Optional[float]:
        return None if self._timeout is None else time.monotonic() + self._timeout

    @staticmethod
    def _remaining(deadline: Optional[float]) -> Optional[float]:
        return None if deadline is None else max(0.0, deadline - time.monotonic())

    def _unary(self, method, request):
        try:
            return method(request, timeout=self._timeout, metadata=self._metadata)
        except grpc.RpcError as error:
            raise _from_rpc_error(error) from None

    def _with_retries(self, attempt: Callable[[Optional[float], list], object]):
        """Runs attempt(timeout, received) until it succeeds or fails with another code than
        UNAVAILABLE, after a response arrived (`received` non-empty), after max_attempts, or when
        the next backoff would pass the deadline. Backoff: full jitter from 0.1 s, doubling up
        to 1 s."""
        deadline = self._deadline()
        backoff = 0.1
        for number in range(1, self._max_attempts + 1):
            received: list = []
            try:
                return attempt(self._remaining(deadline), received)
            except grpc.RpcError as error:
                failure = _from_rpc_error(error)
            if (failure.code != grpc.StatusCode.UNAVAILABLE or received
                    or number == self._max_attempts):
                raise failure
            pause = random.uniform(0.0, backoff)
            if deadline is not None and time.monotonic() + pause >= deadline:
                raise failure
            time.sleep(pause)
            backoff = min(backoff * 2.0, 1.0)
        raise AssertionError("unreachable")

    def _sends_batches(self) -> bool:
        """Whether the server takes SampleSlices (its "sample_slices" feature); servers of the
        first v1 get one slice per message."""
        if self._server_info is None:
            self._server_info = self.server_info()
        return "sample_slices" in self._server_info.features

    def _sample_requests(self, clip: clip_pb2.Clip, slice_bytes: int, request_type):
        """The sample messages of `clip` as `request_type` (UploadClipRequest, ProcessRequest)."""
        if self._sends_batches():
            for batch in _sample_batches(clip, slice_bytes):
                yield request_type(sample_slices=batch)
        else:
            for samples in _sample_slices(clip, slice_bytes):
                yield request_type(samples=samples)

    def _effective_slice_bytes(self) -> int:
        """Bytes of samples per sent message: slice_bytes, held to half the server's message
        limit so a slice and its framing always fit (asked once, then remembered)."""
        if self._server_info is None:
            self._server_info = self.server_info()
        limit = self._server_info.max_message_bytes
        if limit > 0:
            return max(_BYTES_PER_SAMPLE, min(self._slice_bytes, limit // 2))
        return self._slice_bytes

    # -- service --

    def health(self, service: str = "") -> str:
        """grpc.health.v1 state of `service`: "" the server overall (live), MOTION_SERVICE ready
        for jobs (NOT_SERVING while draining). Returns "SERVING", "NOT_SERVING" or "UNKNOWN".
        Raises: TempokeyError NOT_FOUND for a service the server does not know; call errors."""
        return self._unary(self._health_check, service)

    def server_info(self) -> motion_service_pb2.ServerInfo:
        """Version, limits (max_message_bytes, max_clip_samples), queue capacity, workers and the
        operations the server implements ("retime", "reduce/paper", ...)."""
        return self._unary(self._stub.GetServerInfo, motion_service_pb2.GetServerInfoRequest())

    def upload_clip(self, clip: clip_pb2.Clip) -> motion_service_pb2.UploadClipResponse:
        """Streams `clip` (header, then sample slices) and returns the server's answer: clip_id
        ("sha256:<hex>" of the content, so uploading the same clip again gives the same id and
        costs nothing), counts and already_stored. Retried whole on UNAVAILABLE.
        Raises: TempokeyError INVALID_ARGUMENT (the message names channel, frame and value),
        RESOURCE_EXHAUSTED over the server's limits; call errors."""
        slice_bytes = self._effective_slice_bytes()

        def requests():
            yield motion_service_pb2.UploadClipRequest(header=clip.header)
            yield from self._sample_requests(clip, slice_bytes,
                                             motion_service_pb2.UploadClipRequest)

        return self._with_retries(lambda timeout, received: self._stub.UploadClip(
            requests(), timeout=timeout, metadata=self._metadata))

    def process(self, clip: clip_pb2.Clip, operations: Sequence[operations_pb2.Operation],
                on_progress: Optional[Callable[[float, str], None]] = None) -> PipelineResult:
        """Runs `operations` on `clip` in one stateless call: the clip streams in, progress and
        the result stream out, nothing is kept on the server. `on_progress(fraction 0..1, stage)`
        is called on this thread for each progress update (an exception from it cancels the call
        and propagates). Retried whole on UNAVAILABLE while nothing has been received.
        Raises: TempokeyError as upload_clip, plus the pipeline's own errors
        ("operation 1 (retime): ..."), and INTERNAL for a malformed result."""
        slice_bytes = self._effective_slice_bytes()
        # Batched result parts; servers without the feature ignore the field.
        start = motion_service_pb2.ProcessStart(operations=operations, batch_parts=True)

        def requests():
            yield motion_service_pb2.ProcessRequest(header=clip.header)
            yield from self._sample_requests(clip, slice_bytes, motion_service_pb2.ProcessRequest)
            yield motion_service_pb2.ProcessRequest(start=start)

        def attempt(timeout, received):
            assembler = _ResultAssembler()
            responses = self._stub.Process(requests(), timeout=timeout, metadata=self._metadata)
            try:
                for response in responses:
                    received.append(True)
                    if response.WhichOneof("part") == "progress":
                        if on_progress is not None:
                            on_progress(response.progress.progress, response.progress.stage)
                    elif response.WhichOneof("part") == "result":
                        assembler.add(response.result)
            except grpc.RpcError:
                raise
            except BaseException:
                responses.cancel()
                raise
            return assembler.finish()

        return self._with_retries(attempt)

    # -- stored jobs --

    def submit(self, operations: Sequence[operations_pb2.Operation], *,
               clip_id: Optional[str] = None, clip: Optional[clip_pb2.Clip] = None,
               labels: Optional[dict] = None,
               request_id: Optional[str] = None) -> motion_service_pb2.Job:
        """Queues `operations` on an uploaded clip (`clip_id`) or on `clip` sent inline (small
        clips: one message). `request_id` makes a retried submit return the first job; a fresh
        one is generated when None, so the library's own retries never create two jobs.
        Returns the job (job_id, state QUEUED...).
        Raises: ValueError unless exactly one of clip_id and clip is given; TempokeyError
        NOT_FOUND unknown clip, INVALID_ARGUMENT bad pipeline, RESOURCE_EXHAUSTED queue full
        (see retry_after_seconds), UNIMPLEMENTED an operation the server lacks."""
        if (clip_id is None) == (clip is None):
            raise ValueError("give exactly one of clip_id and clip")
        request = motion_service_pb2.SubmitJobRequest(
            operations=operations, labels=labels or {},
            request_id=request_id or _new_request_id())
        if clip_id is not None:
            request.clip_id = clip_id
        else:
            request.inline_clip.CopyFrom(clip)
        return self._unary(self._stub.SubmitJob, request)

    def get_job(self, job_id: str) -> motion_service_pb2.Job:
        """The job's current snapshot. Raises: TempokeyError NOT_FOUND for an unknown job."""
        return self._unary(self._stub.GetJob, motion_service_pb2.GetJobRequest(job_id=job_id))

    def cancel_job(self, job_id: str) -> motion_service_pb2.Job:
        """Cancels a job (idempotent). Raises: TempokeyError NOT_FOUND for an unknown job."""
        return self._unary(self._stub.CancelJob,
                           motion_service_pb2.CancelJobRequest(job_id=job_id))

    def delete_job(self, job_id: str) -> None:
        """Deletes a job and its result. Raises: TempokeyError NOT_FOUND for an unknown job."""
        self._unary(self._stub.DeleteJob, motion_service_pb2.DeleteJobRequest(job_id=job_id))

    def watch(self, job_id: str,
              on_update: Optional[Callable[[motion_service_pb2.Job], None]] = None
              ) -> motion_service_pb2.Job:
        """Follows a job until it ends: calls `on_update` with each snapshot (strictly increasing
        version) and returns the last, terminal one (SUCCEEDED, FAILED with error_code and
        error_message, or CANCELLED).
        Raises: TempokeyError NOT_FOUND unknown job, UNAVAILABLE the server is draining,
        DEADLINE_EXCEEDED after `timeout`; INTERNAL if the watch ended without a snapshot."""
        request = motion_service_pb2.WatchJobRequest(job_id=job_id)

        def attempt(timeout, received):
            last = None
            for job in self._stub.WatchJob(request, timeout=timeout, metadata=self._metadata):
                received.append(True)
                if on_update is not None:
                    on_update(job)
                last = job
            if last is None:
                raise TempokeyError(grpc.StatusCode.INTERNAL,
                                    "the watch ended without sending the job")
            return last

        return self._with_retries(attempt)

    def result(self, job_id: str, slice_bytes: int = 0) -> PipelineResult:
        """The result of a succeeded job, reassembled (see PipelineResult), reports first.
        `slice_bytes` bounds the samples per message (0: the server's 1 MiB).
        Raises: TempokeyError FAILED_PRECONDITION the job has not succeeded, NOT_FOUND."""
        request = motion_service_pb2.GetJobResultRequest(job_id=job_id, slice_bytes=slice_bytes,
                                                          batch_parts=True)

        def attempt(timeout, received):
            assembler = _ResultAssembler()
            parts = self._stub.GetJobResult(request, timeout=timeout, metadata=self._metadata)
            try:
                for part in parts:
                    received.append(True)
                    assembler.add(part)
            except grpc.RpcError:
                raise
            except BaseException:
                parts.cancel()
                raise
            return assembler.finish()

        return self._with_retries(attempt)


def _new_request_id() -> str:
    """A fresh random idempotency key (UUID v4 text)."""
    return str(uuid.uuid4())


def connect(target: str, timeout: Optional[float] = 60.0, token: Optional[str] = None, *,
            tls: bool = False, root_certificates: Optional[bytes] = None,
            certificate_chain: Optional[bytes] = None, private_key: Optional[bytes] = None,
            target_name_override: Optional[str] = None, max_attempts: int = 4,
            max_receive_message_bytes: int = DEFAULT_MAX_RECEIVE_BYTES,
            slice_bytes: int = DEFAULT_SLICE_BYTES) -> Client:
    """Creates a client of `target` (no connection is made until the first call).

    Args:
      target: any gRPC target: "host:port", "dns:///host:port", "ipv4:127.0.0.1:1,127.0.0.1:2"
        (calls are spread round-robin over the addresses).
      timeout: deadline of each method call in seconds, covering its retries; None for none.
      token: sent as "authorization: Bearer <token>" on every call.
      tls: use TLS; root_certificates (PEM bytes, None: system roots), certificate_chain and
        private_key (PEM bytes, both or neither) for mutual TLS, target_name_override to accept
        a certificate issued for another name (test certificates).
      max_attempts: attempts per call on UNAVAILABLE (1 disables retries).
      max_receive_message_bytes: largest message accepted from the server.
      slice_bytes: bytes of samples per sent message (further held to half the server's limit).

    Raises: ValueError for an empty target, TLS settings without tls, a certificate without its
    key, or a non-positive size.
    """
    if not target:
        raise ValueError("the server target is empty")
    if (certificate_chain is None) != (private_key is None):
        raise ValueError("a client certificate needs its private key and a key its certificate")
    if not tls and (root_certificates or certificate_chain or target_name_override):
        raise ValueError("TLS settings were given but tls is False")
    if max_receive_message_bytes <= 0:
        raise ValueError("max_receive_message_bytes must be > 0")
    options = [("grpc.max_receive_message_length", max_receive_message_bytes),
               ("grpc.service_config", _service_config(max_attempts)),
               ("grpc.enable_retries", 1 if max_attempts > 1 else 0),
               ("grpc.primary_user_agent", "tempokey-client-python")]
    if tls:
        if target_name_override:
            options.append(("grpc.ssl_target_name_override", target_name_override))
        credentials = grpc.ssl_channel_credentials(root_certificates=root_certificates,
                                                   private_key=private_key,
                                                   certificate_chain=certificate_chain)
        channel = grpc.secure_channel(target, credentials, options=options)
    else:
        channel = grpc.insecure_channel(target, options=options)
    return Client(channel, timeout=timeout, token=token, max_attempts=max_attempts,
                  slice_bytes=slice_bytes)
