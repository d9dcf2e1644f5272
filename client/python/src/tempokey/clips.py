"""Clips as tempokey.v1 messages: building one from plain Python values, naming its channels,
and cutting its samples into the slices a call sends.

Units: times in seconds; rotations in degrees; positions in file units.
"""

import dataclasses
import numbers
from typing import Any, Iterator, List, Optional, Sequence, Tuple, Union

from tempokey import _arguments
from tempokey.v1 import clip_pb2

__all__ = [
    "CHANNEL_KINDS", "CHANNEL_KIND_NAMES", "ChannelSpec", "DEFAULT_SLICE_BYTES", "JointSpec",
    "MarkerSpec", "channel_label", "make_clip", "sample_batches", "sample_slices",
]

# Samples per sent or received message, as the C++ client (wire::kDefaultSliceBytes).
DEFAULT_SLICE_BYTES = 1 << 20
BYTES_PER_SAMPLE = 8

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


def _sequence(values: Any, what: str) -> Sequence[Any]:
    """`values` if it is a sized iterable other than a string (whose characters would be taken
    one by one: make_clip(..., samples=["12"]) must not become [1.0, 2.0])."""
    if (isinstance(values, (str, bytes, bytearray)) or not hasattr(values, "__len__")
            or not hasattr(values, "__iter__")):
        raise TypeError("%s must be a list, got %s %s"
                        % (what, type(values).__name__, _arguments.shown(values)))
    return values


def _vec3(values: Sequence[float], what: str) -> clip_pb2.Vec3:
    _sequence(values, what)
    if len(values) != 3:
        raise ValueError("%s must have 3 numbers, got %d" % (what, len(values)))
    x, y, z = (_arguments.real(v, what) for v in values)
    return clip_pb2.Vec3(x=x, y=y, z=z)


class _NotANumber(Exception):
    pass


def _float(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise _NotANumber()
    return float(value)


def _floats(values: Any, index: int) -> List[float]:
    """Channel `index`'s samples as floats; anything but a number (a str, a bool, None) is
    refused, naming the channel and frame. The common types take the fast path."""
    _sequence(values, "samples[%d]" % index)
    try:
        return [v if type(v) is float else float(v) if type(v) is int else _float(v)
                for v in values]
    except _NotANumber:
        pass
    for frame, value in enumerate(values):
        _arguments.real(value, "samples[%d][%d] (channel %d, frame %d)"
                        % (index, frame, index, frame))
    raise AssertionError("unreachable")


def _channel_info(index: int, spec: Union[ChannelSpec, str]) -> clip_pb2.ChannelInfo:
    if isinstance(spec, str):
        spec = ChannelSpec("scalar", name=spec)
    if not isinstance(spec, ChannelSpec):
        raise TypeError("channels[%d] must be a ChannelSpec or a str, got %s %s"
                        % (index, type(spec).__name__, _arguments.shown(spec)))
    if spec.kind not in CHANNEL_KINDS:
        raise ValueError("channel %d: unknown kind %r, expected one of %s"
                         % (index, spec.kind, ", ".join(CHANNEL_KINDS)))
    info = clip_pb2.ChannelInfo(kind=CHANNEL_KINDS[spec.kind],
                                name=_arguments.text(spec.name, "channels[%d].name" % index))
    if spec.joint_index is not None:
        info.joint_index = _arguments.integer(spec.joint_index, "channels[%d].joint_index"
                                              % index, _arguments.INT32)
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
      TypeError: an argument of the wrong type, naming it: a string where a list is expected
        (samples=["12"]), a sample, offset or time that is not a number (a str, a bool, None),
        a joint or channel index that is not a whole number.
      ValueError: an unknown channel kind, a channel count not matching the sample lists, sample
        lists of different lengths, a non-integral index (2.7). Everything else (NaN, a frame
        time <= 0, joint indices out of range, ...) is checked by the server, which answers
        INVALID_ARGUMENT naming what is wrong.
    """
    _arguments.text(name, "name")
    frame_time_seconds = _arguments.real(frame_time_seconds, "frame_time_seconds")
    _sequence(channels, "channels")
    _sequence(samples, "samples")
    _sequence(joints, "joints")
    _sequence(markers, "markers")
    if len(channels) != len(samples):
        raise ValueError("%d channels but %d sample lists; give one list per channel"
                         % (len(channels), len(samples)))
    frame_count = len(_sequence(samples[0], "samples[0]")) if len(samples) else 0
    header = clip_pb2.ClipHeader(name=name, frame_time_seconds=frame_time_seconds,
                                 frame_count=frame_count)
    for index, joint in enumerate(joints):
        if not isinstance(joint, JointSpec):
            raise TypeError("joints[%d] must be a JointSpec, got %s %s"
                            % (index, type(joint).__name__, _arguments.shown(joint)))
        _arguments.text(joint.name, "joints[%d].name" % index)
        parent_index = _arguments.integer(joint.parent_index, "joints[%d].parent_index" % index,
                                          _arguments.INT32)
        header.joints.add(name=joint.name, parent_index=parent_index,
                          offset=_vec3(joint.offset, "joint %s offset" % joint.name),
                          end_site_offsets=[_vec3(site, "joint %s end site" % joint.name)
                                            for site in _sequence(
                                                joint.end_sites, "joint %s end_sites"
                                                % joint.name)])
    for index, spec in enumerate(channels):
        header.channels.append(_channel_info(index, spec))
    for index, marker in enumerate(markers):
        if not isinstance(marker, MarkerSpec):
            raise TypeError("markers[%d] must be a MarkerSpec, got %s %s"
                            % (index, type(marker).__name__, _arguments.shown(marker)))
        header.markers.add(
            name=_arguments.text(marker.name, "markers[%d].name" % index),
            time_seconds=_arguments.real(marker.time_seconds, "markers[%d].time_seconds" % index),
            duration_seconds=_arguments.real(marker.duration_seconds,
                                             "markers[%d].duration_seconds" % index))
    clip = clip_pb2.Clip(header=header)
    for index, values in enumerate(samples):
        if len(_sequence(values, "samples[%d]" % index)) != frame_count:
            raise ValueError("channel %d has %d samples, channel 0 has %d; every channel needs "
                             "one sample per frame" % (index, len(values), frame_count))
        clip.samples.add(channel_index=index, first_frame=0, samples=_floats(values, index))
    return clip


def channel_label(header: clip_pb2.ClipHeader, index: int) -> str:
    """"Hips.Xrotation" for a joint channel, the name for a plain one (as the server says)."""
    info = header.channels[index]
    kind = CHANNEL_KIND_NAMES.get(info.kind, "channel")
    if info.HasField("joint_index") and 0 <= info.joint_index < len(header.joints):
        return "%s.%s" % (header.joints[info.joint_index].name, kind)
    return info.name or "channel %d" % index


def _samples_per_slice(slice_bytes: int) -> int:
    return max(1, slice_bytes // BYTES_PER_SAMPLE)


def sample_slices(clip: clip_pb2.Clip, slice_bytes: int) -> Iterator[clip_pb2.ChannelSamples]:
    """Consecutive slices of `clip`'s samples, each at most `slice_bytes` of samples (at least one
    sample), in the order they are stored (channel by channel for make_clip's clips)."""
    per_slice = _samples_per_slice(slice_bytes)
    for run in clip.samples:
        values = run.samples
        for start in range(0, len(values), per_slice):
            yield clip_pb2.ChannelSamples(channel_index=run.channel_index,
                                          first_frame=run.first_frame + start,
                                          samples=values[start:start + per_slice])


def sample_batches(clip: clip_pb2.Clip, slice_bytes: int) -> Iterator[clip_pb2.SampleSlices]:
    """The slices of sample_slices() packed into SampleSlices messages of at most `slice_bytes`
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

