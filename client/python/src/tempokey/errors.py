"""Errors of the tempokey client: a failed call is a TempokeyError carrying the gRPC status code
and the server's message unchanged (a deadline that passed on the client's side, which gRPC
reports as "Deadline Exceeded", names the timeout instead; an UNAVAILABLE from a failed TLS
set-up gets "; " and why, found by probing the server). Arguments are checked before anything is
sent: a value of the wrong type (None or a str for a clip, a str or bool for a number) is a
TypeError and what cannot be encoded at all (2.7 frames, an infinite timeout) a ValueError, both
naming the parameter. Files: tempokey.bvh.BvhError (a ValueError, "<file>:<line>:<column>: ...") and
tempokey.bvh.BvhFileError (an OSError, "<file>: ...")."""

from typing import Any, Optional

import grpc

__all__ = ["RETRY_AFTER_METADATA_KEY", "TempokeyError"]

# Trailing metadata of a RESOURCE_EXHAUSTED that may pass later (a full queue, no stream slot, the
# memory budget in use): whole milliseconds to wait. A RESOURCE_EXHAUSTED without it is a request
# over a limit, refused again however late it comes back.
RETRY_AFTER_METADATA_KEY = "retry-after-ms"


class TempokeyError(Exception):
    """A failed call: the gRPC status code and the server's message, unchanged.

    Attributes:
      code: grpc.StatusCode, e.g. grpc.StatusCode.INVALID_ARGUMENT.
      details: the server's message ("operation 1 (retime): ..."), or for the client's own
        deadline "no answer within the client's timeout of 60 s (retries included); ...", or
        for an UNAVAILABLE from TLS set-up gRPC's text and what a probe of the server found
        ("...: Socket closed; the server speaks TLS: connect with tls=True ...").
      retry_after_seconds: the server's hint of when to try again (a full queue, no stream slot,
        the memory budget in use), or None: then retrying the same request cannot help.
    """

    def __init__(self, code: grpc.StatusCode, details: str,
                 retry_after_seconds: Optional[float] = None):
        super().__init__("%s: %s" % (code.name, details))
        self.code = code
        self.details = details
        self.retry_after_seconds = retry_after_seconds


def retry_after_seconds(call: Any) -> Optional[float]:
    """The retry-after-ms trailing metadata of a finished call, in seconds, or None."""
    try:
        trailers = call.trailing_metadata() or ()
    except Exception:  # a call that never reached the server has no trailers
        return None
    for key, value in trailers:
        if key == RETRY_AFTER_METADATA_KEY and str(value).isdigit():
            return int(value) / 1000.0
    return None


# gRPC's own text when a call's deadline passed on the client's side; the server's deadline
# errors (an idle stream, a queued job) carry messages of their own.
_CLIENT_DEADLINE_TEXT = "Deadline Exceeded"


def from_rpc_error(error: grpc.RpcError, timeout: Optional[float] = None) -> TempokeyError:
    """The one place gRPC errors become TempokeyError: same code, same message; but for the
    client's own deadline (`timeout`, the seconds connect() was given), whose gRPC text names
    nothing, a message that names it."""
    code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
    details = error.details() if hasattr(error, "details") else str(error)
    if (code == grpc.StatusCode.DEADLINE_EXCEEDED and details == _CLIENT_DEADLINE_TEXT
            and timeout is not None):
        details = ("no answer within the client's timeout of %g s (retries included); "
                   "connect() with a longer timeout, or timeout=None for none" % timeout)
    return TempokeyError(code, details or "", retry_after_seconds(error))


def malformed_result(what: str) -> TempokeyError:
    """The error of a result the server sent in a shape the protocol does not allow."""
    return TempokeyError(grpc.StatusCode.INTERNAL, "malformed result from the server: " + what)

