"""Variants of an EDS file for the tests: a default changed, an object removed (text in, text out)."""

from __future__ import annotations

import configparser
from collections.abc import Iterable, Mapping
from pathlib import Path

from hil.canopen.od import default_eds_path

__all__ = ["write_eds_variant"]


def write_eds_variant(path: Path, *, source: Path | None = None,
                      defaults: Mapping[tuple[int, int], str] | None = None,
                      access: Mapping[tuple[int, int], str] | None = None,
                      remove: Iterable[int] = (), remove_subs: Iterable[tuple[int, int]] = ()) -> Path:
    """Write ``source`` (default the shipped drive EDS) to ``path`` with ``DefaultValue``s set
    (``{(0x6502, 0): "0x00000080"}``), ``AccessType``s set, whole objects and single sub-indices
    (``[(0x1018, 2)]``) removed; KeyError naming an object that is not in the file (a variant that would
    silently change nothing is a test bug)."""
    ini = configparser.ConfigParser(interpolation=None, strict=False)
    ini.optionxform = str  # keys as written
    ini.read(source or default_eds_path(), encoding="utf-8")

    def section(index: int, sub: int) -> str:
        name = f"{index:04X}" if f"{index:04X}" in ini and sub == 0 and f"{index:04X}sub0" not in ini \
            else f"{index:04X}sub{sub:X}"
        if name not in ini:
            raise KeyError(f"{source or 'the shipped EDS'}: no object 0x{index:04X}:{sub:02X}")
        return name

    for (index, sub), value in (defaults or {}).items():
        ini[section(index, sub)]["DefaultValue"] = value
    for (index, sub), value in (access or {}).items():
        ini[section(index, sub)]["AccessType"] = value
    for index, sub in remove_subs:
        ini.remove_section(section(index, sub))
    for index in remove:
        names = [s for s in ini.sections() if s.upper() == f"{index:04X}" or s.upper().startswith(f"{index:04X}SUB")]
        if not names:
            raise KeyError(f"{source or 'the shipped EDS'}: no object 0x{index:04X}")
        for s in names:
            ini.remove_section(s)
        for listing in ("MandatoryObjects", "OptionalObjects", "ManufacturerObjects"):
            if listing in ini:
                kept = [v for k, v in ini[listing].items() if k != "SupportedObjects" and int(v, 16) != index]
                ini.remove_section(listing)
                ini.add_section(listing)
                ini[listing]["SupportedObjects"] = str(len(kept))
                for k, v in enumerate(kept, start=1):
                    ini[listing][str(k)] = v
    with open(path, "w", encoding="utf-8") as fh:
        ini.write(fh, space_around_delimiters=False)
    return path
