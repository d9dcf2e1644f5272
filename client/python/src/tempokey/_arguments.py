"""Checks of the arguments of the public functions, before anything is encoded or sent (private).

A wrong type (a string, None or a bool where a number is expected, a string where a clip is
expected) is a TypeError; a value that cannot be encoded (a non-integral or out-of-range
integer, a timeout that is not a finite positive number) is a ValueError. Messages name the
parameter: "fit_frames must be a whole number, got 2.7". Ranges that mean something (a speed
> 0, a key budget >= 2) stay the server's to check, with its one set of messages.
"""

import math
import numbers
from typing import Any, Optional

# Longest deadline accepted, in seconds (a year): gRPC turns much larger ones (about 1e10 s)
# into a deadline that has already passed.
MAX_TIMEOUT_SECONDS = 365 * 24 * 3600.0

INT32 = (-(1 << 31), (1 << 31) - 1)
INT64 = (-(1 << 63), (1 << 63) - 1)


def shown(value: Any) -> str:
    """`value` for a message: its repr on one line, at most 60 characters."""
    if hasattr(value, "DESCRIPTOR") and hasattr(value, "ListFields"):  # a protobuf message
        return "<%s>" % value.DESCRIPTOR.full_name
    text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."


def _type_name(value: Any) -> str:
    return type(value).__name__


def _is_number(value: Any) -> bool:
    """A number a float can be made of: any numbers.Real (int, float, Fraction, numpy scalars),
    decimal.Decimal or another type with __float__; not a bool, a string or bytes (a string of
    digits is a mistake the caller should see, and a list of them was read digit by digit)."""
    if isinstance(value, (bool, str, bytes, bytearray)) or _is_numpy_bool(value):
        return False
    return isinstance(value, numbers.Real) or hasattr(value, "__float__")


def _is_numpy_bool(value: Any) -> bool:
    """A numpy boolean scalar (numpy.bool_, named "bool" from numpy 2), by its dtype's kind."""
    dtype = getattr(value, "dtype", None)
    return getattr(dtype, "kind", None) == "b" and getattr(value, "ndim", None) == 0


def real(value: Any, name: str) -> float:
    """`value` as a float: any number (_is_number()), not a bool or a string.
    NaN and infinities pass (the server names them where they matter)."""
    if not _is_number(value):
        raise TypeError("%s must be a number, got %s %s" % (name, _type_name(value), shown(value)))
    return float(value)


def integer(value: Any, name: str, bounds: tuple = INT64) -> int:
    """`value` as an int: an int (any numbers.Integral) or an integral float such as 2.0, within
    `bounds` (the range of the field it is sent in); not a bool, a string or 2.7."""
    if not _is_number(value):
        raise TypeError("%s must be a whole number, got %s %s"
                        % (name, _type_name(value), shown(value)))
    if isinstance(value, numbers.Integral):
        whole = int(value)
    else:
        # Exactly (a Decimal or Fraction above 2**53 is not rounded through a float).
        try:
            whole = int(value)
        except (OverflowError, ValueError):  # infinities, NaN
            raise ValueError("%s must be a whole number, got %s" % (name, shown(value))) from None
        if whole != value:
            raise ValueError("%s must be a whole number, got %s" % (name, shown(value)))
    if not bounds[0] <= whole <= bounds[1]:
        raise ValueError("%s %d is out of range [%d, %d]" % (name, whole, bounds[0], bounds[1]))
    return whole


def boolean(value: Any, name: str) -> bool:
    """`value` as a bool: True or False, numpy's booleans, or the integers 0 and 1; not a string
    (a string such as "false" would otherwise be true) nor another number."""
    if isinstance(value, bool):
        return value
    if _is_numpy_bool(value):
        return bool(value)
    if isinstance(value, numbers.Integral) and int(value) in (0, 1):
        return bool(int(value))
    raise TypeError("%s must be True or False, got %s %s"
                    % (name, _type_name(value), shown(value)))


def text(value: Any, name: str) -> str:
    """`value` if it is a str."""
    if not isinstance(value, str):
        raise TypeError("%s must be a str, got %s %s" % (name, _type_name(value), shown(value)))
    return value


def pem_bytes(value: Any, name: str) -> Optional[bytes]:
    """`value` if it is None or bytes: PEM text as read from a file opened with "rb" (grpcio
    takes bytes only, and a str is not encoded on the caller's behalf)."""
    if value is not None and not isinstance(value, bytes):
        raise TypeError("%s must be bytes (PEM, as read with open(path, \"rb\")), got %s %s"
                        % (name, _type_name(value), shown(value)))
    return value


def timeout(value: Any, name: str = "timeout") -> Optional[float]:
    """A deadline in seconds: None (no deadline) or a finite number in (0, MAX_TIMEOUT_SECONDS]."""
    if value is None:
        return None
    seconds = real(value, name)
    if not (math.isfinite(seconds) and 0.0 < seconds <= MAX_TIMEOUT_SECONDS):
        raise ValueError("%s must be a number of seconds > 0 and at most %d (a year), or None for "
                         "no deadline; got %s" % (name, MAX_TIMEOUT_SECONDS, shown(value)))
    return seconds


def message(value: Any, message_type: type, name: str, hint: str = "") -> Any:
    """`value` if it is a `message_type` protobuf message."""
    if not isinstance(value, message_type):
        raise TypeError("%s must be a %s%s, got %s %s"
                        % (name, message_type.DESCRIPTOR.full_name, hint, _type_name(value),
                           shown(value)))
    return value


def messages(values: Any, message_type: type, name: str, hint: str = "") -> list:
    """`values` as a list of `message_type` messages: any sequence or iterable of them, but not a
    single message or a string (which would be taken item by item)."""
    if isinstance(values, message_type):
        raise TypeError("%s must be a list of %s, got one %s: pass [it]"
                        % (name, message_type.DESCRIPTOR.full_name, type(values).__name__))
    if isinstance(values, (str, bytes, bytearray)) or not hasattr(values, "__iter__"):
        raise TypeError("%s must be a list of %s%s, got %s %s"
                        % (name, message_type.DESCRIPTOR.full_name, hint, _type_name(values),
                           shown(values)))
    items = list(values)
    for index, item in enumerate(items):
        if not isinstance(item, message_type):
            raise TypeError("%s[%d] must be a %s%s, got %s %s"
                            % (name, index, message_type.DESCRIPTOR.full_name, hint,
                               _type_name(item), shown(item)))
    return items
