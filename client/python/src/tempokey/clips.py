"""Clips as tempokey.v1 messages: building one from plain Python values, naming its channels,
and cutting its samples into the slices a call sends.

Units: times in seconds; rotations in degrees; positions in file units.
"""

import dataclasses
from typing import Iterator, Optional, Sequence, Tuple, Union

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

