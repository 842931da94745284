"""A profile patch: the keys and values that make a rig ready, as ``emacheck commission`` writes them
(``profile.patch.toml``) and ``emacheck profile apply-patch`` applies them (docs/commission.md).

A patch is a TOML file of the actuation profile's own tables holding only the keys to change::

    [mechanics]
    i_total_rad_per_mm = 4.0213

    [signals.ema2.force]
    N_per_unit = 0.01

Applied, every key of the patch must already exist in the profile (a patch never adds a field the profile
does not have, except a signal's ``node``), and the patched profile must load and plan (its EDS files
looked up next to the original profile): :func:`patch_problem` says why not, naming the key.
"""

from __future__ import annotations

import copy
import json
import math
import tomllib
from pathlib import Path

from hil.errors import EmacheckError, ProfileError

__all__ = ["apply_patch", "dotted", "nested", "patch_problem", "patch_text", "read_patch", "toml_text"]

#: Keys a patch may add to a signal's table (a signal moved to another node of the map).
ADDABLE = frozenset({"node"})


def nested(patch: dict) -> dict:
    """``{"a.b.c": v}`` -> ``{"a": {"b": {"c": v}}}``."""
    out: dict = {}
    for key, v in patch.items():
        *path, last = key.split(".")
        t = out
        for p in path:
            t = t.setdefault(p, {})
        t[last] = v
    return out


def dotted(tables: dict, prefix: str = "") -> dict:
    """The inverse of :func:`nested`: every leaf as ``"a.b.c": v``."""
    out: dict = {}
    for k, v in tables.items():
        if isinstance(v, dict):
            out |= dotted(v, f"{prefix}{k}.")
        else:
            out[f"{prefix}{k}"] = v
    return out


def apply_patch(data: dict, patch: dict, fname: str = "profile") -> dict:
    """The profile tables ``data`` with the dotted keys of ``patch`` set (a copy).

    Raises
    ------
    hil.errors.ProfileError
        A key the profile does not have (naming it), or one whose parent is not a table.
    """
    out = copy.deepcopy(data)
    for key, v in patch.items():
        *path, last = key.split(".")
        t = out
        for depth, p in enumerate(path):
            if not isinstance(t.get(p), dict):
                raise ProfileError(f"{fname}: the patch's key '{key}': the profile has no table "
                                   f"'{'.'.join(path[:depth + 1])}'")
            t = t[p]
        if last not in t and last not in ADDABLE:
            raise ProfileError(f"{fname}: the patch's key '{key}': the profile has no such field")
        t[last] = v
    return out


def patch_problem(data: dict, patch: dict, profile_path: str | Path | None, eds: str | Path | None = None,
                  fname: str = "profile") -> str | None:
    """Why the profile loader refuses ``data`` patched with ``patch`` (loaded, then planned with every node's
    EDS as ``emacheck profile check`` does), or None if it accepts it."""
    from hil.canopen.errors import CanopenError
    from hil.profile.load import actuation_from_tables
    from hil.profile.rig import plan_for

    try:
        act = actuation_from_tables(apply_patch(data, patch, fname), fname)
        plan_for(act, profile_path, eds)
    except (EmacheckError, CanopenError) as exc:
        return str(exc).replace("\n", "; ")
    return None


def read_patch(path: str | Path) -> dict:
    """A patch file -> its dotted keys and values (:class:`hil.errors.ProfileError` naming the file)."""
    try:
        with open(path, "rb") as fh:
            return dotted(tomllib.load(fh))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ProfileError(f"{path}: not a readable profile patch: {exc}") from None


def patch_text(patch: dict, header: list[str]) -> str:
    """The patch as TOML, ``header`` as comment lines above it."""
    lines = [f"# {h}" for h in header]
    return "\n".join(lines) + "\n\n" + (toml_text(nested(patch)) if patch else "# (nothing to change)\n")


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if isinstance(v, float) and not math.isfinite(v):
            raise ProfileError(f"not a TOML number: {v!r}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)) and not any(isinstance(x, dict) for x in v):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise ProfileError(f"a value a profile cannot hold: {v!r}")


def toml_text(tables: dict, path: str = "") -> str:
    """Tables (dicts of numbers, strings, booleans, lists of them, lists of tables) as TOML text; the
    scalars of a table first, then its sub-tables (``[a.b]``) and arrays of tables (``[[a.c]]``)."""
    scal = [(k, v) for k, v in tables.items() if not isinstance(v, dict) and not _tables(v)]
    out = [f"{_key(k)} = {_value(v)}" for k, v in scal]
    text = ("\n".join(out) + "\n") if out else ""
    for k, v in tables.items():
        sub = f"{path}.{_key(k)}" if path else _key(k)
        if isinstance(v, dict):
            inner = toml_text(v, sub)
            text += f"\n[{sub}]\n{inner}" if any(not isinstance(x, dict) for x in v.values()) or not v else inner
        elif _tables(v):
            for t in v:
                text += f"\n[[{sub}]]\n{toml_text(t, sub)}"
    return text


def _tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and k.isascii() else json.dumps(k)
