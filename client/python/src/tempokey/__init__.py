"""tempokey: the Python client of tempokey-server (tempokey.v1.MotionService).

The studio-pipeline call, one stateless ``Process`` call (safe through a load balancer)::

    import tempokey as tk

    clip = tk.read_bvh_clip("walk.bvh")
    with tk.connect("127.0.0.1:50051", timeout=60) as client:
        result = client.process(clip, [tk.retime_operation(speed="0s:1,2s:0.5,4s:0.5,4s:1"),
                                       tk.reduce_operation(tolerance=0.5)])
    tk.write_keyed_clip_json("walk.json", result.keyed_clip)

Modules, by purpose:
  tempokey.client     connect(), Client: health, upload, process, stored jobs
  tempokey.pipelines  the operations (retime, reduce, bake, convert) and PipelineResult
  tempokey.clips      clips from plain Python values (make_clip), channel names, slicing
  tempokey.formats    BVH files to clips, keyed results to the keyed-clip JSON
  tempokey.bvh        the strict BVH reader (BvhError, BvhFileError)
  tempokey.errors     TempokeyError
  tempokey.v1         the message and service stubs, generated from the protos at build time

Everything public is also importable from ``tempokey`` itself, under the names the former
``tempokey_client`` module used. Requires Debian's python3-grpcio and python3-protobuf.
"""

try:
    from tempokey.v1 import clip_pb2, motion_service_pb2, motion_service_pb2_grpc, operations_pb2
except ImportError as error:  # pragma: no cover - an uninstalled source tree
    raise ImportError(
        "tempokey.v1 stubs are missing (%s): install the package (pip install client/python), "
        "which generates them from the protos" % error) from error

from tempokey.bvh import BvhClip, BvhError, BvhFileError, BvhJoint, parse_bvh, read_bvh
from tempokey.client import (DEFAULT_MAX_RECEIVE_BYTES, HEALTH_STATES, MOTION_SERVICE, Client,
                             connect, is_loopback_target)
from tempokey.clips import (CHANNEL_KIND_NAMES, CHANNEL_KINDS, DEFAULT_SLICE_BYTES, ChannelSpec,
                            JointSpec, MarkerSpec, channel_label, make_clip, sample_batches,
                            sample_slices)
from tempokey.errors import RETRY_AFTER_METADATA_KEY, TempokeyError
from tempokey.formats import (clip_from_bvh, keyed_clip_to_dict, read_bvh_clip,
                              write_json_atomically, write_keyed_clip_json)
from tempokey.pipelines import (REDUCE_OPTIONS, PipelineResult, RateLike, ReduceOption,
                                SpeedLike, TimeLike, bake_operation, convert_operation,
                                frame_rate, parse_joint_tolerance, parse_speed,
                                reduce_operation, retime_operation, speed_knot, time_point,
                                world_error_lines)

try:
    from importlib.metadata import PackageNotFoundError, version as _version
    __version__ = _version("tempokey")
except PackageNotFoundError:  # pragma: no cover - imported from a source tree
    __version__ = "0+unknown"

__all__ = [
    "BvhClip", "BvhError", "BvhFileError", "BvhJoint", "CHANNEL_KINDS", "CHANNEL_KIND_NAMES",
    "ChannelSpec",
    "Client", "DEFAULT_MAX_RECEIVE_BYTES", "DEFAULT_SLICE_BYTES", "HEALTH_STATES", "JointSpec",
    "MOTION_SERVICE", "MarkerSpec", "PipelineResult", "REDUCE_OPTIONS", "RETRY_AFTER_METADATA_KEY",
    "RateLike", "ReduceOption", "SpeedLike", "TempokeyError", "TimeLike", "bake_operation",
    "channel_label", "clip_from_bvh", "clip_pb2", "connect", "convert_operation", "frame_rate",
    "is_loopback_target",
    "keyed_clip_to_dict", "make_clip", "motion_service_pb2", "motion_service_pb2_grpc",
    "operations_pb2", "parse_bvh", "parse_joint_tolerance", "parse_speed", "read_bvh", "read_bvh_clip", "reduce_operation",
    "retime_operation", "sample_batches", "sample_slices", "speed_knot", "time_point",
    "world_error_lines",
    "write_json_atomically", "write_keyed_clip_json",
]
