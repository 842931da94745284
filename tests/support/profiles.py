"""Variants of the shipped profiles, built from the parsed TOML rather than from its text.

A text replacement (``text.replace("cycles = 3", "cycles = 0")``) silently does
nothing once the shipped text changes (a comment, a new default, an aligned
``=``); the test then checks the shipped profile instead of the variant. Here
the shipped profile is parsed with :mod:`tomllib`, the overrides are applied to
the parsed tables (every key path must already exist in the profile, else
:class:`KeyError` naming it) and the variant is written with ``tomli_w``::

    p = write_profile_variant("check.toml", tmp_path / "check.toml",
                              {"safety": {"max_stroke_mm": 3.0}})

``remove`` (dotted paths that must exist), ``rename`` (dotted path -> new
name, the value and its place kept) and ``add`` (nested keys that must not
exist yet) make the variants that are not value changes: a missing field, an
unknown or misspelt field, an extra ``[[faults]]`` table.
"""

from __future__ import annotations

import copy
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import tomli_w

from hil.profile.load import default_profile_path

__all__ = ["apply_overrides", "load_profile_data", "profile_variant", "write_profile_variant"]


def load_profile_data(name: str) -> dict:
    """The parsed tables of a shipped profile (``"check.toml"``, ``"actuation.toml"``, ``"simrig.toml"``)."""
    with open(default_profile_path(name), "rb") as fh:
        return tomllib.load(fh)


def apply_overrides(data: dict, overrides: Mapping[str, Any], *, profile: str = "profile",
                    _where: str = "") -> dict:
    """Set the values of ``overrides`` (nested like the profile) in ``data``, in place; returns ``data``.

    A key path that does not exist in ``data`` raises :class:`KeyError` naming the
    dotted path and the profile: an override that would be silently ignored by the
    loader (or refused as an unknown field) is a mistake in the test, not a variant.
    A mapping is merged into the table of the same name; any other value (also a
    mapping where the profile holds a scalar) replaces the value.
    """
    for key, value in overrides.items():
        path = f"{_where}{key}"
        if not isinstance(data, dict) or key not in data:
            raise KeyError(f"{profile}: override of '{path}': no such key in the profile")
        if isinstance(value, Mapping) and isinstance(data[key], dict):
            apply_overrides(data[key], value, profile=profile, _where=f"{path}.")
        else:
            data[key] = copy.deepcopy(value)
    return data


def _table_of(data: dict, dotted: str, profile: str, what: str) -> tuple[dict, str]:
    """(the table holding the dotted path's last key, that key); KeyError when the path does not exist."""
    *tables, leaf = dotted.split(".")
    node = data
    for t in tables:
        if not isinstance(node, dict) or t not in node:
            raise KeyError(f"{profile}: {what} of '{dotted}': no such key in the profile")
        node = node[t]
    if not isinstance(node, dict) or leaf not in node:
        raise KeyError(f"{profile}: {what} of '{dotted}': no such key in the profile")
    return node, leaf


def _remove(data: dict, dotted: str, profile: str) -> None:
    node, leaf = _table_of(data, dotted, profile, "removal")
    del node[leaf]


def _rename(data: dict, dotted: str, new: str, profile: str) -> None:
    node, leaf = _table_of(data, dotted, profile, "renaming")
    if new in node:
        raise KeyError(f"{profile}: renaming of '{dotted}' to '{new}': that key exists already")
    items = list(node.items())
    node.clear()
    node.update((new if k == leaf else k, v) for k, v in items)


def _add(data: dict, extra: Mapping[str, Any], profile: str, where: str = "") -> None:
    for key, value in extra.items():
        path = f"{where}{key}"
        if key in data:
            if isinstance(value, Mapping) and isinstance(data[key], dict):
                _add(data[key], value, profile, f"{path}.")
                continue
            raise KeyError(f"{profile}: addition of '{path}': the key exists already (use an override)")
        data[key] = copy.deepcopy(dict(value) if isinstance(value, Mapping) else value)


def profile_variant(name: str, overrides: Mapping[str, Any] | None = None, *, remove: Iterable[str] = (),
                    rename: Mapping[str, str] | None = None, add: Mapping[str, Any] | None = None) -> dict:
    """The parsed shipped profile ``name`` with ``remove``, ``rename``, ``overrides``, then ``add`` applied.

    ``remove``: dotted paths (``"mechanics.limit_load_N"``); ``rename``: dotted path -> new last
    name (``{"surface": "surfaces"}``); ``overrides``: nested values of existing keys; ``add``:
    nested keys that do not exist yet (``{"faults": [{"kind": "drive_fault"}]}``). A path that
    does not exist (or, for ``add``, one that does) raises :class:`KeyError` naming it.
    """
    data = load_profile_data(name)
    for dotted in remove:
        _remove(data, dotted, name)
    for dotted, new in (rename or {}).items():
        _rename(data, dotted, new, name)
    apply_overrides(data, overrides or {}, profile=name)
    _add(data, add or {}, name)
    return data


def write_profile_variant(name: str, dest: str | Path, overrides: Mapping[str, Any] | None = None, *,
                          remove: Iterable[str] = (), rename: Mapping[str, str] | None = None,
                          add: Mapping[str, Any] | None = None) -> Path:
    """Write :func:`profile_variant` to ``dest`` (a file path) as TOML; returns ``dest``."""
    dest = Path(dest)
    dest.write_text(tomli_w.dumps(profile_variant(name, overrides, remove=remove, rename=rename, add=add)))
    return dest
