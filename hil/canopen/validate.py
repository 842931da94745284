"""Argument validators of the CANopen vocabulary: one place, one message style.

Each returns the value converted (``int`` or ``float``) or raises
:class:`~hil.canopen.errors.CanopenInputError` (or the error class given) naming
the argument, its value and its range or unit, e.g.
``node_id = 128 is outside 1..127``. Used by the protocol modules of
:mod:`hil.canopen` and by the simulated drives (sim/drives).
"""

from __future__ import annotations

import math
import operator

from hil.canopen.errors import CanopenInputError

MAX_NODE_ID = 127  #: highest CANopen node id (CiA 301)


def integer(name: str, value: object, lo: int, hi: int, *, error: type[Exception] = CanopenInputError,
            show: str = "{}", what: str = "") -> int:
    """``value`` as an int in ``lo..hi`` (bool refused).

    Parameters
    ----------
    name : str
        Name quoted in the message.
    value : object
        Anything with ``__index__``.
    lo, hi : int
        Inclusive range.
    error : exception type
        Raised on failure (default :class:`CanopenInputError`).
    show : str
        Format of the value and the range in the message, e.g. ``"0x{:X}"``.
    what : str
        What the number is, appended to the range, e.g. ``" (16-bit word)"``.
    """
    if value.__class__ is int and lo <= value <= hi:  # the common case, first (hot path of the master)
        return value
    span = f"{show.format(lo)}..{show.format(hi)}"
    if isinstance(value, bool):
        raise error(f"{name} must be an int in {span}{what}, got bool")
    try:
        v = operator.index(value)
    except TypeError:
        raise error(f"{name} must be an int in {span}{what}, got {type(value).__name__} {value!r}") from None
    if not lo <= v <= hi:
        shown = show.format(v) if v >= 0 else "-" + show.format(-v)  # -0x1, not 0x-1
        raise error(f"{name} = {shown} is outside {span}{what}")
    return v


def node_id(value: object, name: str = "node_id") -> int:
    """A CANopen node id, 1..127."""
    return integer(name, value, 1, MAX_NODE_ID)


def word16(name: str, value: object) -> int:
    """A 16-bit word (controlword, statusword), 0..0xFFFF."""
    if value.__class__ is int and 0 <= value <= 0xFFFF:  # the common case, first
        return value
    return integer(name, value, 0, 0xFFFF, show="0x{:X}", what=" (16-bit word)")


def finite(name: str, value: object, unit: str) -> float:
    """A finite float in ``unit``."""
    if value.__class__ is float:  # the common case, first (hot path of the master)
        if value - value == 0.0:  # not NaN or inf
            return value
    elif value.__class__ is int:
        return float(value)
    if isinstance(value, bool):
        raise CanopenInputError(f"{name} must be a number [{unit}], got bool")
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise CanopenInputError(f"{name} must be a number [{unit}], got {value!r}") from None
    if not math.isfinite(v):
        raise CanopenInputError(f"{name} = {v} [{unit}] must be finite")
    return v


def positive(name: str, value: object, unit: str) -> float:
    """A finite float > 0 in ``unit``."""
    v = finite(name, value, unit)
    if v <= 0.0:
        raise CanopenInputError(f"{name} = {v} [{unit}] must be > 0")
    return v


def time_s(value: object, name: str = "t") -> float:
    """A finite time in s (any monotonic origin)."""
    return finite(name, value, "s")


def error_code(value: object, name: str = "code", *, allow_zero: bool = False) -> int:
    """A 16-bit EMCY error code, 0x0001..0xFFFF (0x0000 "no error" only with ``allow_zero``)."""
    return integer(name, value, 0 if allow_zero else 1, 0xFFFF, show="0x{:04X}", what=" (16-bit EMCY error code)")
