"""Profile tables (TOML) into validated frozen dataclasses, and back: the field checks every profile loader uses.

Every error names the file and the dotted field, e.g. ``check.toml: field
'force_fight.amplitude_fraction_of_limit' = 0.2 is above the hard cap 0.15``;
unknown keys are refused with the closest known name, which catches wrong
units (``sweep_speed_mm_per_min`` is not ``sweep_speed_mm_per_s``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import math
import tomllib
import typing
from enum import Enum
from pathlib import Path
from typing import Any

from hil.errors import ProfileError

__all__ = ["Problems", "build_dataclass", "check_keys", "check_range", "convert_scalar", "read_toml", "snapshot"]


class Problems:
    """Every problem of a profile, collected so that one run names them all.

    Each check runs inside :meth:`collect`; a :class:`~hil.errors.ProfileError` it raises is kept (all its
    problems, if it carries several) and the loader goes on with the next field. :meth:`raise_any` raises one
    ProfileError holding every problem, in the order found, if there was any.
    """

    def __init__(self) -> None:
        self.items: list[str] = []

    @contextlib.contextmanager
    def collect(self):
        try:
            yield
        except ProfileError as exc:
            self.items.extend(exc.problems)

    def add(self, message: str) -> None:
        self.items.append(message)

    def raise_any(self) -> None:
        if self.items:
            raise ProfileError.of(self.items)


def read_toml(path: Path) -> dict:
    """A profile's TOML as a dict: UTF-8, with or without a byte-order mark (an editor's "UTF-8 with BOM").

    Raises
    ------
    ProfileError
        Naming the file and what is wrong: not found, a folder, unreadable, not UTF-8 text (binary,
        UTF-16: the byte offset of the first bad byte), or not valid TOML (line and column).
    """
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise ProfileError(f"{path}: profile not found") from None
    except IsADirectoryError:
        raise ProfileError(f"{path}: a folder, not a profile (a TOML file)") from None
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read the profile: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        kind = "UTF-16 text" if data[:2] in (b"\xff\xfe", b"\xfe\xff") else "binary or not UTF-8"
        raise ProfileError(f"{path}: not a TOML text file ({kind}: byte {exc.start} is not UTF-8); "
                           f"save it as UTF-8") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{path}: not valid TOML: {exc}") from None


def check_keys(table: dict, known: list[str], where: str, fname: str) -> None:
    """Every unknown key of ``table`` refused at once, each with the closest known name."""
    problems = Problems()
    for key in table:
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1, cutoff=0.5)
            hint = f" (did you mean '{close[0]}'? units are part of the name)" if close else ""
            problems.add(f"{fname}: unknown field '{where}{key}'{hint}")
    problems.raise_any()


def convert_scalar(value: Any, typ: Any, name: str, fname: str) -> Any:
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ProfileError(f"{fname}: field '{name}' must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ProfileError(f"{fname}: field '{name}' must be finite, got {value!r}")
        return value
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProfileError(f"{fname}: field '{name}' must be an integer, got {value!r}")
        return value
    if typ is str:
        if not isinstance(value, str):
            raise ProfileError(f"{fname}: field '{name}' must be a string, got {value!r}")
        return value
    raise ProfileError(f"{fname}: field '{name}' has an unsupported type {typ!r}")  # pragma: no cover


def check_range(value: Any, meta: typing.Mapping, name: str, fname: str) -> None:
    lo, hi, hard = meta.get("lo"), meta.get("hi"), meta.get("hard_max")
    if hard is not None and value > hard:
        raise ProfileError(f"{fname}: field '{name}' = {value} is above the hard cap {hard}")
    if lo is not None:
        if meta.get("lo_open") and not value > lo:
            raise ProfileError(f"{fname}: field '{name}' = {value} must be > {lo}")
        if not meta.get("lo_open") and not value >= lo:
            raise ProfileError(f"{fname}: field '{name}' = {value} must be >= {lo}")
    if hi is not None and value > hi:
        raise ProfileError(f"{fname}: field '{name}' = {value} must be <= {hi}")


def build_dataclass(cls: type, table: Any, fname: str, where: str = "",
                    ranges: typing.Mapping[str, tuple] | None = None) -> Any:
    """Build a (nested) frozen dataclass from a TOML table, validating everything.

    Parameters
    ----------
    cls : dataclass type
    table : dict
        The TOML table.
    fname : str
        File name quoted in errors.
    where : str
        Dotted prefix of this table quoted in errors.
    ranges : mapping, optional
        ``{"Class.field": (lo, hi)}`` for classes without range metadata.
    """
    if not isinstance(table, dict):
        raise ProfileError(f"{fname}: '{where.rstrip('.') or 'profile'}' must be a table")
    hints = typing.get_type_hints(cls)
    fields = [f for f in dataclasses.fields(cls) if f.init]
    problems = Problems()
    with problems.collect():
        check_keys(table, [f.name for f in fields], where, fname)
    kwargs = {}
    for f in fields:
        with problems.collect():
            if f.name in table:
                kwargs[f.name] = _field(cls, f, hints[f.name], table[f.name], fname, where, ranges)
            elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ProfileError(f"{fname}: missing field '{where}{f.name}'")
    problems.raise_any()
    return cls(**kwargs)


def _field(cls: type, f: dataclasses.Field, typ: Any, value: Any, fname: str, where: str,
           ranges: typing.Mapping[str, tuple] | None) -> Any:
    """One field of :func:`build_dataclass`: a nested table built, a scalar converted and range-checked."""
    name = f"{where}{f.name}"
    if dataclasses.is_dataclass(typ):
        return build_dataclass(typ, value, fname, name + ".", ranges)
    value = convert_scalar(value, typ, name, fname)
    meta = dict(f.metadata)
    if ranges and f"{cls.__name__}.{f.name}" in ranges:
        lo, hi = ranges[f"{cls.__name__}.{f.name}"]
        meta.update(lo=lo, hi=hi, lo_open=False)
    if meta:
        check_range(value, meta, name, fname)
    return value


def snapshot(obj: Any) -> Any:
    """A JSON-serialisable snapshot of a profile dataclass (for meta.json)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out = {f.name: snapshot(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
        if hasattr(obj, "name") and isinstance(getattr(type(obj), "NAME", None), str):
            out["name"] = type(obj).NAME
        return out
    if isinstance(obj, Enum):
        return obj.value
    if isinstance(obj, (tuple, list)):
        return [snapshot(x) for x in obj]
    if isinstance(obj, dict):
        return {str(k): snapshot(v) for k, v in obj.items()}
    return obj
