"""Argument validators of the CANopen vocabulary: one place, one message style.

Each returns the value converted (``int`` or ``float``) or raises
:class:`~hil.canopen.errors.InputError` (or the error class given) naming
the argument, its value and its range or unit, e.g.
``node_id = 128 is outside 1..127``. Used by the protocol modules of
:mod:`hil.canopen` and by the simulated drives (sim/drives).
"""

from __future__ import annotations

import math
import operator

from hil.canopen.errors import InputError

MAX_NODE_ID = 127  #: highest CANopen node id (CiA 301)


def integer(name: str, value: object, lo: int, hi: int, *, error: type[Exception] = InputError,
            show: str = "{}") -> int:
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
        Raised on failure (default :class:`InputError`).
    show : str
        Format of the value and the range in the message, e.g. ``"0x{:X}"``.
    """
    if isinstance(value, bool):
        raise error(f"{name} must be an int, got bool")
    try:
        v = operator.index(value)
    except TypeError:
        raise error(f"{name} must be an int, got {type(value).__name__} {value!r}") from None
    if not lo <= v <= hi:
        raise error(f"{name} = {show.format(v)} is outside {show.format(lo)}..{show.format(hi)}")
    return v


def node_id(value: object, name: str = "node_id") -> int:
    """A CANopen node id, 1..127."""
    if isinstance(value, bool):
        raise InputError(f"{name} must be an int in 1..127, got bool")
    try:
        n = operator.index(value)
    except TypeError:
        raise InputError(f"{name} must be an int in 1..127, got {value!r}") from None
    if not 1 <= n <= MAX_NODE_ID:
        raise InputError(f"{name} = {n} is outside 1..127")
    return n


def word16(name: str, value: object) -> int:
    """A 16-bit word (controlword, statusword), 0..0xFFFF."""
    if isinstance(value, bool):
        raise InputError(f"{name} must be an int in 0..0xFFFF, got bool")
    try:
        v = operator.index(value)
    except TypeError:
        raise InputError(f"{name} must be an int in 0..0xFFFF, got {value!r}") from None
    if not 0 <= v <= 0xFFFF:
        raise InputError(f"{name} = 0x{v:X} is outside 0..0xFFFF (16-bit word)")
    return v


def finite(name: str, value: object, unit: str) -> float:
    """A finite float in ``unit``."""
    if isinstance(value, bool):
        raise InputError(f"{name} must be a number [{unit}], got bool")
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number [{unit}], got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} = {v} [{unit}] must be finite")
    return v


def positive(name: str, value: object, unit: str) -> float:
    """A finite float > 0 in ``unit``."""
    v = finite(name, value, unit)
    if v <= 0.0:
        raise InputError(f"{name} = {v} [{unit}] must be > 0")
    return v


def time_s(value: object, name: str = "t") -> float:
    """A finite time in s (any monotonic origin)."""
    if isinstance(value, bool):
        raise InputError(f"{name} must be a time in s (float), got bool")
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a time in s (float), got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} = {v} [s] must be finite")
    return v


def error_code(value: object, name: str = "code", *, allow_zero: bool = False) -> int:
    """A 16-bit EMCY error code, 0x0001..0xFFFF (0x0000 "no error" only with ``allow_zero``)."""
    if isinstance(value, bool):
        raise InputError(f"{name} must be an int error code 0x0001..0xFFFF, got bool")
    try:
        c = operator.index(value)
    except TypeError:
        raise InputError(f"{name} must be an int error code 0x0001..0xFFFF, got {value!r}") from None
    lo = 0 if allow_zero else 1
    if not lo <= c <= 0xFFFF:
        raise InputError(f"{name} = 0x{c:X} is outside 0x{lo:04X}..0xFFFF (16-bit EMCY error code)")
    return c
