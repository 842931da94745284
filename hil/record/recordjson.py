"""The run record's JSON read field by field: each problem a :class:`hil.errors.RunRecordError` naming the
dotted field (``drives_final.ema2.safe``), and the parts of fixed shape built on it.

A part (:class:`Part`) is a frozen dataclass whose fields are declared with :func:`req` or :func:`opt` (their
JSON kind, a key of :data:`KINDS`); it has ``as_json`` and ``read`` (from :class:`Fields`). The run record
(:mod:`hil.record.runrecord`) and the drives' parts (:mod:`hil.record.driveparts`) are made of them. This
module does no IO.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from enum import StrEnum
from typing import Any

from hil.errors import RunRecordError

#: where a part read on its own (``Part.from_json`` without a source) says it came from
RECORD = "the run record"


def show(v: Any) -> str:
    """A JSON value as an error message quotes it (at most 60 characters)."""
    text = json.dumps(v, default=str) if not isinstance(v, str) else repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


KINDS = {
    "text": (lambda v: isinstance(v, str), "a string"),
    "int": (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer"),
    "number": (lambda v: isinstance(v, int | float) and not isinstance(v, bool), "a number"),
    "bool": (lambda v: isinstance(v, bool), "true or false"),
    "object": (lambda v: isinstance(v, dict), "a JSON object"),
    "list": (lambda v: isinstance(v, list), "a list"),
    "texts": (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a list of strings"),
    "text map": (lambda v: isinstance(v, dict) and all(isinstance(x, str) for x in v.values()),
                 "an object of strings"),
}


class Fields:
    """A JSON object read field by field; each problem a :class:`RunRecordError` naming the dotted field."""

    def __init__(self, obj: Any, where: str, source: str) -> None:
        if not isinstance(obj, dict):
            raise RunRecordError(where or "(top level)", f"expected a JSON object, got {show(obj)}", source)
        self.obj, self.where, self.source = obj, where, source

    def name(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def error(self, key: str, problem: str) -> RunRecordError:
        return RunRecordError(self.name(key), problem, self.source)

    def has(self, *keys: str) -> bool:
        return any(k in self.obj for k in keys)

    def get(self, key: str, kind: str, *, required: bool = False) -> Any:
        """The field's value checked against ``kind``; None when absent or null (an error if ``required``)."""
        v = self.obj.get(key)
        if v is None:
            if required:
                raise self.error(key, "missing" if key not in self.obj else "null, expected a value")
            return None
        ok, what = KINDS[kind]
        if not ok(v):
            raise self.error(key, f"expected {what}, got {show(v)}")
        return v

    def sub(self, key: str) -> Fields:
        return Fields(self.obj[key], self.name(key), self.source)

    def enum(self, key: str, cls: type[StrEnum]) -> Any:
        v = self.get(key, "text")
        return None if v is None else member(cls, v, self.name(key), self.source)


def only(obj: Mapping, known, where: str, source: str) -> None:
    """At a seam where the record is built from another module's JSON (the link's preflight record,
    the master's final states, a drive's identity): a key the record has no field for is refused, not
    dropped (a field added there must be added here)."""
    extra = [k for k in obj if k not in known]
    if extra:
        name = f"{where}.{extra[0]}" if where else extra[0]
        raise RunRecordError(name, "no field of the run record holds it (hil/record/runrecord.py)", source)


def member(cls: type[StrEnum], v: Any, field: str, source: str) -> Any:
    try:
        return cls(v)
    except ValueError:
        allowed = ", ".join(m.value for m in cls)
        raise RunRecordError(field, f"{show(v)} is not one of {allowed}", source) from None


# ------------------------------------------------------------------ the parts with a fixed shape

def req(kind: str) -> Any:
    """A part's field that its JSON must hold, of JSON ``kind`` (a key of ``KINDS``)."""
    return dataclasses.field(metadata={"kind": kind, "required": True})


def opt(kind: str) -> Any:
    """A part's field its JSON may leave out or null (None), of JSON ``kind``."""
    return dataclasses.field(default=None, metadata={"kind": kind, "required": False})


class Part:
    """A part of the record: ``as_json`` and ``read`` (from a :class:`Fields`) each part has;
    :meth:`from_json` reads one from its JSON.

    The defaults serve a part whose JSON keys are its fields, in order, each declared with
    :func:`req` or :func:`opt` (its JSON kind); a part of another shape overrides both."""

    def as_json(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def read(cls, f: Fields):
        return cls(**{d.name: f.get(d.name, d.metadata["kind"], required=d.metadata["required"])
                      for d in dataclasses.fields(cls)})

    @classmethod
    def from_json(cls, obj: Any, where: str = "", source: str = RECORD):
        """The part from its JSON ``obj`` (a malformed field: :class:`RunRecordError` naming ``where.field``)."""
        return cls.read(Fields(obj, where or cls.__name__, source))


def part_keys(part: type) -> tuple[str, ...]:
    """The JSON keys of a part whose fields are its keys (:class:`hil.record.runrecord.Bus`, ...)."""
    return tuple(f.name for f in dataclasses.fields(part))
