"""Validators of the pure analysis and the physics: one place, one message style.

Each returns the value converted or raises :class:`blf.errors.InputError`
quoting the argument's name, its shape and its unit, e.g. ``d_mm must be a
1-D array in mm; got shape (3, 2)``. Used by every module of :mod:`blf` and
by the pure physics of :mod:`sim`.
"""

from __future__ import annotations

import numpy as np

from blf.errors import InputError


def as_1d_finite(value, name: str, unit: str, *, min_len: int = 1) -> np.ndarray:
    """Return ``value`` as a float64 1-D array or raise InputError naming it."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"{name} must be a 1-D numeric array in {unit}; got {type(value).__name__} "
            f"that cannot be converted to float ({exc})"
        ) from None
    if arr.ndim != 1:
        raise InputError(
            f"{name} must be a 1-D array in {unit}; got shape {arr.shape}"
        )
    if arr.size < min_len:
        raise InputError(
            f"{name} must have at least {min_len} samples in {unit}; got shape {arr.shape}"
        )
    return _finite(arr, name, unit)


def as_finite(value, name: str, unit: str) -> np.ndarray:
    """Return ``value`` as a float64 array of any shape, all finite, or raise InputError naming it."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a numeric array in {unit}; got {type(value).__name__}") from None
    return _finite(arr, name, unit)


def _finite(arr: np.ndarray, name: str, unit: str) -> np.ndarray:
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr)))
        raise InputError(f"{name} must be finite (in {unit}); got {bad} NaN/inf value(s) in shape {arr.shape}")
    return arr


def same_shape(*items: tuple[np.ndarray, str, str]) -> None:
    """Raise InputError unless all (array, name, unit) items share one shape."""
    ref, ref_name, ref_unit = items[0]
    for arr, name, unit in items[1:]:
        if arr.shape != ref.shape:
            raise InputError(
                f"{name} (in {unit}) must have the same shape as {ref_name} (in {ref_unit}); "
                f"got {name} shape {arr.shape} and {ref_name} shape {ref.shape}"
            )


def positive_scalar(value, name: str, unit: str) -> float:
    """Return ``value`` as a finite positive float or raise InputError naming it."""
    if np.ndim(value) != 0 or isinstance(value, bool):
        raise InputError(
            f"{name} must be a finite positive scalar in {unit}; got {value!r} "
            f"(shape {np.shape(value)})"
        )
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(
            f"{name} must be a finite positive number in {unit}; got {value!r} "
            f"(shape {np.shape(value)})"
        ) from None
    if not np.isfinite(x) or x <= 0.0:
        raise InputError(
            f"{name} must be a finite positive number in {unit}; got {x!r} (shape ())"
        )
    return x


def below_nyquist(value, name: str, sample_rate_Hz: float) -> float:
    """``value`` as a finite positive angular frequency (rad/s) below the Nyquist frequency
    ``pi * sample_rate_Hz``, else InputError naming it."""
    w = positive_scalar(value, name, "rad/s")
    nyq = np.pi * sample_rate_Hz
    if w >= nyq:
        raise InputError(f"{name} must be below the Nyquist frequency pi*sample_rate_Hz = {nyq:.4g} rad/s; "
                         f"got {w:g} rad/s (shape ())")
    return w


def readonly(arr: np.ndarray) -> np.ndarray:
    """Return a read-only copy-owned array (for frozen result dataclasses)."""
    out = np.array(arr, copy=True)
    out.flags.writeable = False
    return out


def is_real(value) -> bool:
    """True for an int or float (numpy's included), not a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def scalar(value, name: str, unit: str, *, lo: float = -np.inf, lo_open: bool = False,
           hi: float = np.inf, hi_open: bool = False) -> float:
    """``value`` as a finite float in the interval ``lo..hi`` (open or closed ends), else InputError
    quoting the bound and the unit: ``name must be a finite scalar > 0.0 mm, got -1`` (one bound),
    ``... in [0.0, 0.5) (dimensionless), got 0.7`` (two bounds)."""
    ok = is_real(value) and np.isfinite(float(value))
    if ok:
        v = float(value)
        ok = (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
    if not ok:
        raise InputError(f"{name} must be a finite scalar {_bounds(lo, lo_open, hi, hi_open)}{unit}, got {value!r}")
    return float(value)


def _bounds(lo: float, lo_open: bool, hi: float, hi_open: bool) -> str:
    """The allowed range in words, ready to stand before the unit."""
    if np.isinf(lo) and np.isinf(hi):
        return "in "
    if np.isinf(hi):
        return f"{'>' if lo_open else '>='} {lo} "
    if np.isinf(lo):
        return f"{'<' if hi_open else '<='} {hi} "
    return f"in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'} "


def count(value, name: str, lo: int, hi: int | None = None) -> int:
    """``value`` as an int count in ``lo..hi`` (no upper bound when ``hi`` is None), else InputError."""
    ok = not isinstance(value, bool) and isinstance(value, (int, np.integer))
    if ok:
        ok = int(value) >= lo and (hi is None or int(value) <= hi)
    if not ok:
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise InputError(f"{name} must be an int {rng} (count), got {value!r}")
    return int(value)


def instance_of(value, cls: type, name: str, what: str | None = None):
    """``value`` if it is an instance of ``cls``, else InputError naming the argument and the type got."""
    if not isinstance(value, cls):
        raise InputError(f"{name} must be {what or 'a ' + cls.__name__}, got {type(value).__name__}")
    return value


def generator(rng, name: str = "rng") -> np.random.Generator:
    """``rng`` if it is a ``numpy.random.Generator`` (explicit randomness), else InputError."""
    if not isinstance(rng, np.random.Generator):
        raise InputError(f"{name} must be a numpy.random.Generator, got {type(rng).__name__}")
    return rng


def one_of(value, name: str, allowed: tuple, what: str = "a str, no unit"):
    """``value`` if it is one of ``allowed``, else InputError listing them."""
    if value not in allowed or isinstance(value, bool):
        raise InputError(f"{name} must be one of {allowed} ({what}), got {value!r}")
    return value
