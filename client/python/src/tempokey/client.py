"""The client of tempokey.v1.MotionService (SPEC 6): connect with a deadline, a token and TLS;
health; upload; the stateless `process` call with progress; stored jobs (submit, watch, result).

    import tempokey as tk

    with tk.connect("127.0.0.1:50051", timeout=60) as client:
        result = client.process(clip, [tk.retime_operation(speed="0s:1,2s:0.5,4s:0.5,4s:1"),
                                       tk.reduce_operation(tolerance=0.5)])
    result.keyed_clip        # tempokey.v1.KeyedClip: the header and one curve per channel
    result.reduction_report  # keys kept, RMS and max error, worst channel and frame

Clips are sent as the C++ client sends them: the header, then slices of at most 1 MiB of samples
(less when the server's message limit is smaller), packed several to a message for servers with
the "sample_slices" feature. Results are reassembled into one Clip (one ChannelSamples per
channel covering every frame) or one KeyedClip (one KeyedCurve per channel), with the reports.

Errors: a failed call raises TempokeyError with the gRPC status code and the server's message
exactly as sent, e.g. ``INVALID_ARGUMENT: operation 1 (retime): speed knot 2 (2s:-1): speed must
be > 0``; when gRPC's UNAVAILABLE text only says "Socket closed" or "certificate verify failed",
the client probes the server's TLS and appends why, e.g. ``...; the server does not speak TLS:
connect without tls=True, ...`` (TCP connections and TLS handshakes, never a request or the
token, within the timeout and 10 s). Only UNAVAILABLE is retried (the server is draining or
unreachable), as the C++ client does. Thread-safety: a Client may be shared by threads (gRPC
channels are thread-safe); the server info it caches is read-only once fetched.
"""

import ipaddress
import json
import random
import time
import uuid
from typing import Any, Callable, Iterator, List, Mapping, Optional, Sequence, Tuple, TypeVar

import grpc

from tempokey import _arguments, _pem, _tls_diagnosis
from tempokey.clips import (BYTES_PER_SAMPLE, DEFAULT_SLICE_BYTES, channel_label, sample_batches,
                            sample_slices)
from tempokey.errors import TempokeyError, from_rpc_error, malformed_result
from tempokey.pipelines import PipelineResult
from tempokey.v1 import clip_pb2
from tempokey.v1 import motion_service_pb2
from tempokey.v1 import motion_service_pb2_grpc
from tempokey.v1 import operations_pb2

__all__ = ["Client", "DEFAULT_MAX_RECEIVE_BYTES", "HEALTH_STATES", "MOTION_SERVICE", "connect",
           "is_loopback_target"]

MOTION_SERVICE = "tempokey.v1.MotionService"
HEALTH_CHECK_METHOD = "/grpc.health.v1.Health/Check"
# Largest message accepted from the server; results come in slices well below it.
DEFAULT_MAX_RECEIVE_BYTES = 64 << 20
_UNARY_METHODS = ("GetServerInfo", "SubmitJob", "GetJob", "ListJobs", "CancelJob", "DeleteJob")

_T = TypeVar("_T")
# One attempt of a streaming call: (timeout in seconds or None, list filled once a response
# arrived) -> its result.
_Attempt = Callable[[Optional[float], List[bool]], _T]


# ---- results ------------------------------------------------------------------------------------

class _ResultAssembler:
    """Rebuilds a PipelineResult from the ResultPart messages of Process or GetJobResult: a
    header (reports, then a clip or keyed-clip header), then sample slices or curve pieces.
    Slices of a channel must tile its frames exactly; curve pieces of a channel are joined in
    arrival order. Raises TempokeyError (INTERNAL) for anything else."""

    def __init__(self) -> None:
        self._header: Optional[motion_service_pb2.ResultHeader] = None
        self._slices: dict = {}  # channel index -> [(first_frame, samples)]
        self._curves: dict = {}  # channel index -> KeyedCurve joined so far

    def add(self, part: motion_service_pb2.ResultPart) -> None:
        kind = part.WhichOneof("part")
        if kind == "header":
            if self._header is not None:
                raise malformed_result("a second result header")
            if part.header.WhichOneof("kind") is None:
                raise malformed_result("the header names neither a clip nor a keyed clip")
            self._header = part.header
            return
        if self._header is None:
            raise malformed_result("%s before the header" % (kind or "an empty part"))
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
            raise malformed_result("a %s part in a %s result"
                                    % (kind, "keyed" if keyed else "sampled"))

    def _layout(self) -> clip_pb2.ClipHeader:
        return getattr(self._header, self._header.WhichOneof("kind"))

    def _check_channel(self, index: int) -> None:
        if not 0 <= index < len(self._layout().channels):
            raise malformed_result("channel index %d out of range" % index)

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
                raise malformed_result("%s: frames %d..%d %s" % (
                    channel_label(layout, index), min(first_frame, len(values)),
                    max(first_frame, len(values)) - 1,
                    "missing" if first_frame > len(values) else "sent twice"))
            values.extend(run)
        if len(values) != layout.frame_count:
            raise malformed_result("%s: %d samples for %d frames" % (
                channel_label(layout, index), len(values), layout.frame_count))
        return values

    def finish(self) -> PipelineResult:
        if self._header is None:
            raise malformed_result("the result has no header")
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
                    raise malformed_result("%s: no curve arrived" % channel_label(layout, index))
                keyed.curves.append(self._curves[index])
            result.keyed_clip = keyed
        return result


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
        timeout = _arguments.timeout(timeout)
        if token is not None:
            _check_token(token)
        if _arguments.integer(max_attempts, "max_attempts") < 1:
            raise ValueError("max_attempts must be >= 1, got %d" % max_attempts)
        if _arguments.integer(slice_bytes, "slice_bytes") < BYTES_PER_SAMPLE:
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
        # How connect() made the channel, for explaining a failed connection; None for a Client
        # made from a channel directly.
        self._channel_settings: Optional[_tls_diagnosis.ChannelSettings] = None

    def close(self) -> None:
        """Closes the channel; calls in flight are cancelled."""
        self._channel.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- plumbing --

    def _deadline(self) -> Optional[float]:
        return None if self._timeout is None else time.monotonic() + self._timeout

    @staticmethod
    def _remaining(deadline: Optional[float]) -> Optional[float]:
        return None if deadline is None else max(0.0, deadline - time.monotonic())

    def _explained(self, failure: TempokeyError) -> TempokeyError:
        """`failure` as raised: an UNAVAILABLE whose gRPC text may come from TLS set-up gets what
        a probe of the server found appended after "; " (_tls_diagnosis), as the CLI does."""
        if failure.code != grpc.StatusCode.UNAVAILABLE or self._channel_settings is None:
            return failure
        explanation = _tls_diagnosis.diagnose(self._channel_settings, failure.details,
                                              self._timeout)
        if not explanation:
            return failure
        return TempokeyError(failure.code, "%s; %s" % (failure.details, explanation),
                             failure.retry_after_seconds)

    def _unary(self, method: Callable[..., _T], request: Any) -> _T:
        try:
            return method(request, timeout=self._timeout, metadata=self._metadata)
        except grpc.RpcError as error:
            raise self._explained(from_rpc_error(error, self._timeout)) from None

    def _with_retries(self, attempt: "_Attempt[_T]") -> _T:
        """Runs attempt(timeout, received) until it succeeds or fails with another code than
        UNAVAILABLE, after a response arrived (`received` non-empty), after max_attempts, or when
        the next backoff would pass the deadline. Backoff: full jitter from 0.1 s, doubling up
        to 1 s."""
        deadline = self._deadline()
        backoff = 0.1
        for number in range(1, self._max_attempts + 1):
            received: List[bool] = []
            try:
                return attempt(self._remaining(deadline), received)
            except grpc.RpcError as error:
                failure = from_rpc_error(error, self._timeout)
            if (failure.code != grpc.StatusCode.UNAVAILABLE or received
                    or number == self._max_attempts):
                raise self._explained(failure)
            pause = random.uniform(0.0, backoff)
            if deadline is not None and time.monotonic() + pause >= deadline:
                raise self._explained(failure)
            time.sleep(pause)
            backoff = min(backoff * 2.0, 1.0)
        raise AssertionError("unreachable")

    def _sends_batches(self) -> bool:
        """Whether the server takes SampleSlices (its "sample_slices" feature); servers of the
        first v1 get one slice per message."""
        if self._server_info is None:
            self._server_info = self.server_info()
        return "sample_slices" in self._server_info.features

    def _sample_requests(self, clip: clip_pb2.Clip, slice_bytes: int,
                         request_type: Callable[..., _T]) -> Iterator[_T]:
        """The sample messages of `clip` as `request_type` (UploadClipRequest, ProcessRequest)."""
        if self._sends_batches():
            for batch in sample_batches(clip, slice_bytes):
                yield request_type(sample_slices=batch)
        else:
            for samples in sample_slices(clip, slice_bytes):
                yield request_type(samples=samples)

    def _effective_slice_bytes(self) -> int:
        """Bytes of samples per sent message: slice_bytes, held to half the server's message
        limit so a slice and its framing always fit (asked once, then remembered)."""
        if self._server_info is None:
            self._server_info = self.server_info()
        limit = self._server_info.max_message_bytes
        if limit > 0:
            return max(BYTES_PER_SAMPLE, min(self._slice_bytes, limit // 2))
        return self._slice_bytes

    # -- service --

    def health(self, service: str = "") -> str:
        """grpc.health.v1 state of `service`: "" the server overall (live), MOTION_SERVICE ready
        for jobs (NOT_SERVING while draining). Returns "SERVING", "NOT_SERVING" or "UNKNOWN".
        Raises: TypeError unless `service` is a str; TempokeyError NOT_FOUND for a service the
        server does not know; call errors."""
        _arguments.text(service, "service")
        return self._unary(self._health_check, service)

    def server_info(self) -> motion_service_pb2.ServerInfo:
        """Version, limits (max_message_bytes, max_clip_samples), queue capacity, workers and the
        operations the server implements ("retime", "reduce/paper", ...)."""
        return self._unary(self._stub.GetServerInfo, motion_service_pb2.GetServerInfoRequest())

    def upload_clip(self, clip: clip_pb2.Clip) -> motion_service_pb2.UploadClipResponse:
        """Streams `clip` (header, then sample slices) and returns the server's answer: clip_id
        ("sha256:<hex>" of the content, so uploading the same clip again gives the same id and
        costs nothing), counts and already_stored. Retried whole on UNAVAILABLE.
        Raises: TypeError unless `clip` is a tempokey.v1.Clip; TempokeyError INVALID_ARGUMENT
        (the message names channel, frame and value), RESOURCE_EXHAUSTED over the server's
        limits, or refused for the moment (no stream slot, the memory budget in use) with
        retry_after_seconds; call errors."""
        _check_clip(clip)
        slice_bytes = self._effective_slice_bytes()

        def requests() -> Iterator[motion_service_pb2.UploadClipRequest]:
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
        Raises: TypeError unless `clip` is a tempokey.v1.Clip, `operations` a list of
        tempokey.v1.Operation and `on_progress` None or callable; TempokeyError as upload_clip,
        plus the pipeline's own errors ("operation 1 (retime): ..."), and INTERNAL for a
        malformed result."""
        _check_clip(clip)
        operations = _check_operations(operations)
        _check_callback(on_progress, "on_progress")
        slice_bytes = self._effective_slice_bytes()
        # Batched result parts; servers without the feature ignore the field.
        start = motion_service_pb2.ProcessStart(operations=operations, batch_parts=True)

        def requests() -> Iterator[motion_service_pb2.ProcessRequest]:
            yield motion_service_pb2.ProcessRequest(header=clip.header)
            yield from self._sample_requests(clip, slice_bytes, motion_service_pb2.ProcessRequest)
            yield motion_service_pb2.ProcessRequest(start=start)

        def attempt(timeout: Optional[float], received: List[bool]) -> PipelineResult:
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
               labels: Optional[Mapping[str, str]] = None,
               request_id: Optional[str] = None) -> motion_service_pb2.Job:
        """Queues `operations` on an uploaded clip (`clip_id`) or on `clip` sent inline (small
        clips: one message). `request_id` makes a retried submit return the first job; a fresh
        one is generated when None, so the library's own retries never create two jobs.
        Returns the job (job_id, state QUEUED...).
        Raises: ValueError unless exactly one of clip_id and clip is given; TypeError for an
        argument of the wrong type (see process); TempokeyError NOT_FOUND unknown clip,
        INVALID_ARGUMENT bad pipeline, RESOURCE_EXHAUSTED a full queue or another refusal for
        the moment (with retry_after_seconds) or a request over a limit (without),
        UNIMPLEMENTED an operation the server lacks."""
        operations = _check_operations(operations)
        if (clip_id is None) == (clip is None):
            raise ValueError("give exactly one of clip_id and clip")
        if clip_id is not None:
            _arguments.text(clip_id, "clip_id")
        else:
            _check_clip(clip)
        if request_id is not None:
            _arguments.text(request_id, "request_id")
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
        _arguments.text(job_id, "job_id")
        return self._unary(self._stub.GetJob, motion_service_pb2.GetJobRequest(job_id=job_id))

    def cancel_job(self, job_id: str) -> motion_service_pb2.Job:
        """Cancels a job (idempotent). Raises: TempokeyError NOT_FOUND for an unknown job."""
        _arguments.text(job_id, "job_id")
        return self._unary(self._stub.CancelJob,
                           motion_service_pb2.CancelJobRequest(job_id=job_id))

    def delete_job(self, job_id: str) -> None:
        """Deletes a job and its result. Raises: TempokeyError NOT_FOUND for an unknown job."""
        _arguments.text(job_id, "job_id")
        self._unary(self._stub.DeleteJob, motion_service_pb2.DeleteJobRequest(job_id=job_id))

    def watch(self, job_id: str,
              on_update: Optional[Callable[[motion_service_pb2.Job], None]] = None
              ) -> motion_service_pb2.Job:
        """Follows a job until it ends: calls `on_update` with each snapshot (strictly increasing
        version) and returns the last, terminal one (SUCCEEDED, FAILED with error_code and
        error_message, or CANCELLED).
        Raises: TempokeyError NOT_FOUND unknown job, UNAVAILABLE the server is draining,
        DEADLINE_EXCEEDED after `timeout`; INTERNAL if the watch ended without a snapshot."""
        _arguments.text(job_id, "job_id")
        _check_callback(on_update, "on_update")
        request = motion_service_pb2.WatchJobRequest(job_id=job_id)

        def attempt(timeout: Optional[float], received: List[bool]) -> motion_service_pb2.Job:
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
        _arguments.text(job_id, "job_id")
        slice_bytes = _arguments.integer(slice_bytes, "slice_bytes", _arguments.INT32)
        request = motion_service_pb2.GetJobResultRequest(job_id=job_id, slice_bytes=slice_bytes,
                                                          batch_parts=True)

        def attempt(timeout: Optional[float], received: List[bool]) -> PipelineResult:
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


def _check_clip(clip: Any) -> None:
    _arguments.message(clip, clip_pb2.Clip, "clip", " (see make_clip and read_bvh_clip)")


def _check_operations(operations: Any) -> List[operations_pb2.Operation]:
    return _arguments.messages(operations, operations_pb2.Operation, "operations",
                               " (see retime_operation and reduce_operation)")


def _check_callback(callback: Any, name: str) -> None:
    if callback is not None and not callable(callback):
        raise TypeError("%s must be None or callable, got %s" % (name, type(callback).__name__))


def _check_token(token: Any) -> None:
    """A bearer token travels in an HTTP/2 header: printable ASCII, spaces inside it allowed as
    the server's token file allows them, none at either end ("" sends none)."""
    _arguments.text(token, "token")
    for index, character in enumerate(token):
        if not " " <= character <= "~":
            raise ValueError("token: character %d (%r) is not allowed; a bearer token is "
                             "printable ASCII (it travels in an HTTP header)"
                             % (index + 1, character))
    if token != token.strip(" "):
        raise ValueError("token: a space at either end is not allowed (the server trims its "
                         "tokens, so this one could never match)")


def _is_loopback_host(host: str) -> bool:
    """Whether `host` (no port; brackets allowed) is itself a loopback name, without asking a
    resolver: "localhost", or an address in 127.0.0.0/8, ::1 or ::ffff:127.0.0.0/104."""
    if len(host) >= 2 and host[0] == "[" and host[-1] == "]":
        host = host[1:-1]
    if host.lower() == "localhost":
        return True
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return False
    mapped = getattr(address, "ipv4_mapped", None)
    return (mapped or address).is_loopback


def _host_of(address: str) -> str:
    """The host of "host:port", "[v6]:port" or a bare host (a bare IPv6 address is its own)."""
    if address.startswith("["):
        return address[1:address.find("]")] if "]" in address else address[1:]
    return address.rsplit(":", 1)[0] if address.count(":") == 1 else address


def is_loopback_target(target: str) -> bool:
    """Whether every address of a gRPC target stays on this machine: a unix-domain socket, or
    hosts that are all loopback literals, in the forms of gRPC's name syntax (doc/naming.md:
    "dns:[//authority/]host[:port]", "ipv4:"/"ipv6:" lists, a bare "host[:port]"); as the C++
    client's wire::IsLoopbackTarget()."""
    lower = target.lower()
    if lower.startswith(("unix:", "unix-abstract:")):
        return True
    for scheme in ("ipv4:", "ipv6:"):
        if lower.startswith(scheme):
            addresses = target[len(scheme):]
            return bool(addresses) and all(_is_loopback_host(_host_of(a))
                                           for a in addresses.split(","))
    if lower.startswith("dns:"):
        target = target[4:]
        if target.startswith("//"):
            slash = target.find("/", 2)
            if slash < 0:
                return False
            target = target[slash + 1:]
    elif target[max(target.find(":"), 0):].startswith("://"):
        return False  # another scheme with an authority: xds:///name, ...
    host = _host_of(target)
    return bool(host) and _is_loopback_host(host)


def _port_of(address: str) -> str:
    """The port of "host:port" or "[v6]:port"; "" when the address names none."""
    if address.startswith("["):
        close = address.find("]")
        rest = address[close + 1:] if close >= 0 else ""
        return rest[1:] if rest.startswith(":") else ""
    return address.rsplit(":", 1)[1] if address.count(":") == 1 else ""


def _check_target_ports(target: str) -> None:
    """Refuses a target whose port of digits is no TCP port, as the C++ client's
    wire::CheckTargetPorts(): gRPC takes a port modulo 65536, so 127.0.0.1:99999 reached
    127.0.0.1:34463. Other schemes' targets are their resolvers' to read."""
    lower = target.lower()
    if lower.startswith(("unix:", "unix-abstract:")):
        return
    addresses = [target]
    if lower.startswith(("ipv4:", "ipv6:")):
        addresses = target[5:].split(",")
    elif lower.startswith("dns:"):
        rest = target[4:]
        if rest.startswith("//"):
            slash = rest.find("/", 2)
            if slash < 0:
                return
            rest = rest[slash + 1:]
        addresses = [rest]
    elif target[max(target.find(":"), 0):].startswith("://"):
        return
    for address in addresses:
        port = _port_of(address)
        if port.isascii() and port.isdigit() and int(port) > 65535:
            raise ValueError("target %s: port %s is not a TCP port (0 to 65535)"
                             % (target, port))


def _new_request_id() -> str:
    """A fresh random idempotency key (UUID v4 text)."""
    return str(uuid.uuid4())


def connect(target: str, timeout: Optional[float] = 60.0, token: Optional[str] = None, *,
            tls: bool = False, root_certificates: Optional[bytes] = None,
            certificate_chain: Optional[bytes] = None, private_key: Optional[bytes] = None,
            target_name_override: Optional[str] = None, max_attempts: int = 4,
            max_receive_message_bytes: int = DEFAULT_MAX_RECEIVE_BYTES,
            slice_bytes: int = DEFAULT_SLICE_BYTES,
            allow_plaintext_token: bool = False) -> Client:
    """Creates a client of `target` (no connection is made until the first call).

    Args:
      target: any gRPC target: "host:port", "dns:///host:port", "ipv4:127.0.0.1:1,127.0.0.1:2"
        (calls are spread round-robin over the addresses).
      timeout: deadline of each method call in seconds (> 0, at most a year), covering its
        retries; None for none.
      token: sent as "authorization: Bearer <token>" on every call: over TLS, or to a target on
        this machine (is_loopback_target()), unless allow_plaintext_token says the network
        itself is trusted (a service mesh whose sidecars encrypt it); RFC 6750 5.3 allows bearer
        tokens over TLS only.
      tls: use TLS; root_certificates (PEM bytes, None: system roots), certificate_chain and
        private_key (PEM bytes, both or neither) for mutual TLS, target_name_override to accept
        a certificate issued for another name (test certificates).
      max_attempts: attempts per call on UNAVAILABLE (1 disables retries).
      max_receive_message_bytes: largest message accepted from the server.
      slice_bytes: bytes of samples per sent message (further held to half the server's limit).

    Raises: TypeError for an argument of the wrong type (a str timeout, a float size, PEM that
    is not bytes); ValueError for an empty target, a timeout that is not a finite number of
    seconds in (0, a year], a token that is not visible ASCII, a token without tls to a target
    off this machine (unless allow_plaintext_token), TLS settings without tls, a certificate
    without its key, a non-positive size, or TLS PEM that cannot work, checked before any
    channel is made and named: "root_certificates: holds no PEM certificate", "private_key: the
    key is encrypted, ...", "private_key: holds no PEM private key", "private_key is not the
    private key of the certificate in certificate_chain".
    """
    if not _arguments.text(target, "target"):
        raise ValueError("the server target is empty")
    _check_target_ports(target)
    timeout = _arguments.timeout(timeout)
    if token is not None:
        _check_token(token)
    _arguments.boolean(tls, "tls")
    _arguments.boolean(allow_plaintext_token, "allow_plaintext_token")
    if token and not tls and not allow_plaintext_token and not is_loopback_target(target):
        raise ValueError("refusing to send the token in cleartext to %s, which is not on this "
                         "machine: connect with tls=True, or pass allow_plaintext_token=True "
                         "only where the network itself is trusted, as in a service mesh that "
                         "encrypts it" % target)
    if _arguments.integer(max_attempts, "max_attempts") < 1:
        raise ValueError("max_attempts must be >= 1, got %d" % max_attempts)
    _arguments.integer(max_receive_message_bytes, "max_receive_message_bytes", _arguments.INT32)
    _arguments.integer(slice_bytes, "slice_bytes")
    for name, pem in (("root_certificates", root_certificates),
                      ("certificate_chain", certificate_chain), ("private_key", private_key)):
        _arguments.pem_bytes(pem, name)
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
        if root_certificates is not None:
            _pem.check_certificates("root_certificates", root_certificates)
        if certificate_chain is not None:
            _pem.check_key_pair("certificate_chain", certificate_chain, "private_key", private_key)
        if target_name_override:
            options.append(("grpc.ssl_target_name_override", target_name_override))
        credentials = grpc.ssl_channel_credentials(root_certificates=root_certificates,
                                                   private_key=private_key,
                                                   certificate_chain=certificate_chain)
        channel = grpc.secure_channel(target, credentials, options=options)
    else:
        channel = grpc.insecure_channel(target, options=options)
    client = Client(channel, timeout=timeout, token=token, max_attempts=max_attempts,
                    slice_bytes=slice_bytes)
    client._channel_settings = _tls_diagnosis.ChannelSettings(
        target, tls, root_certificates, certificate_chain, private_key, target_name_override)
    return client
