"""File formats: a BVH capture read into a tempokey.v1 Clip, and keyed results written as the
"tempokey.keyed_clip" JSON document the C++ tools read and write (README, File formats).

    clip = tk.read_bvh_clip("walk.bvh")           # BvhError names line and column
    ...
    tk.write_keyed_clip_json("walk.json", result.keyed_clip)

The BVH reader itself is tempokey.bvh.
"""

import json
import os
import tempfile
from typing import Any, Dict, Union

from tempokey import bvh
from tempokey.clips import CHANNEL_KIND_NAMES, ChannelSpec, JointSpec, make_clip
from tempokey.v1 import clip_pb2

__all__ = ["clip_from_bvh", "keyed_clip_to_dict", "read_bvh_clip", "write_json_atomically",
           "write_keyed_clip_json"]


def clip_from_bvh(parsed: bvh.BvhClip) -> clip_pb2.Clip:
    """The tempokey.v1.Clip of a parsed BVH file: skeleton, channels in column order, samples
    and frame time exactly as read."""
    joints = [JointSpec(j.name, j.parent_index, j.offset, tuple(j.end_sites))
              for j in parsed.joints]
    channels = [ChannelSpec(kind, joint_index=joint) for joint, kind in parsed.channels]
    return make_clip(parsed.name, parsed.frame_time_seconds, channels, parsed.samples, joints)


def read_bvh_clip(path: Union[str, "os.PathLike[str]"], *, max_bytes: int = bvh.MAX_FILE_BYTES,
                  idle_seconds: float = bvh.STREAM_IDLE_SECONDS) -> clip_pb2.Clip:
    """Reads the BVH file at `path` as a tempokey.v1.Clip named after the file's stem, with the
    CLI's caps (see bvh.read_bvh: at most `max_bytes`, a FIFO silent at most `idle_seconds`).

    Raises: bvh.BvhFileError (an OSError) for a file refused before parsing (a device, over the
    cap, a silent FIFO), other OSErrors when the file cannot be read; bvh.BvhError (a
    ValueError) naming the line and column of what is malformed."""
    return clip_from_bvh(bvh.read_bvh(path, max_bytes=max_bytes, idle_seconds=idle_seconds))


def keyed_clip_to_dict(keyed: clip_pb2.KeyedClip) -> Dict[str, Any]:
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


def write_json_atomically(path: str, document: Any) -> None:
    """Writes `document` as JSON to a temporary file beside `path`, then renames it into place,
    so a failed run never leaves a half-written file. NaN and infinities are refused.

    Raises: OSError; ValueError for a value JSON cannot hold."""
    directory = os.path.dirname(os.path.abspath(path))
    handle, temporary = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=directory)
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            json.dump(document, stream, allow_nan=False)
            stream.write("\n")
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def write_keyed_clip_json(path: str, keyed: clip_pb2.KeyedClip) -> None:
    """Writes `keyed` to `path` as a "tempokey.keyed_clip" document, atomically.

    Raises: OSError."""
    write_json_atomically(path, keyed_clip_to_dict(keyed))
