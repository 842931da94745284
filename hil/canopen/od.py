"""Object dictionaries: load a node's EDS, look objects up, encode and decode their values.

Any node's CiA 306 EDS (the drives' ``profiles/ema_drive.eds`` shipped, a
vendor's file, an I/O module's) is parsed by canopen
(``canopen.objectdictionary``); what the check needs of each node is decided
by :mod:`hil.canopen.plan`. This module also holds the configuration of a
drive's own reaction to the master's death (:func:`master_loss_steps`).
Nothing here talks to a bus.
"""

from __future__ import annotations

import configparser
import functools
import io
import pickle
import struct
from dataclasses import dataclass
from enum import IntEnum
from importlib import resources
from pathlib import Path

import canopen.objectdictionary as cod
from canopen.objectdictionary import datatypes as dt

from hil.canopen.errors import EdsError
from hil.canopen.validate import integer
from hil.canopen.validate import node_id as _node_id

DEFAULT_EDS = "ema_drive.eds"  #: file name of the shipped EDS in the ``profiles`` package

_TYPE_NAMES = {v: k for k, v in vars(dt).items() if k.isupper() and isinstance(v, int) and v <= 0x1B}


def type_name(code: int | None) -> str:
    """``0x0007 (UNSIGNED32)``: a CiA 301 data type code with its name."""
    if code is None:
        return "none"
    return f"0x{code:04X} ({_TYPE_NAMES.get(code, 'unknown')})"


def default_eds_path() -> Path:
    """Path of the EDS shipped in the ``profiles`` package."""
    return Path(str(resources.files("profiles").joinpath(DEFAULT_EDS)))


def load_eds(path: str | Path | None = None, *, node_id: int | None = None) -> cod.ObjectDictionary:
    """Parse a node's EDS into a ``canopen.ObjectDictionary``.

    Parameters
    ----------
    path : str or Path, optional
        The EDS (or DCF); default the shipped ``profiles/ema_drive.eds``.
    node_id : int, optional
        Node id to resolve ``$NODEID`` defaults (PDO and EMCY COB-IDs). Without
        it those defaults stay None (their raw text is in ``default_raw``).

    Raises
    ------
    EdsError
        The file is missing or is not a readable EDS; the message names it.
    """
    p = default_eds_path() if path is None else Path(path)
    if p.is_dir():
        raise EdsError(f"{p}: a folder, not an EDS file")
    if not p.is_file():
        raise EdsError(f"{p}: EDS not found")
    if p.suffix.lower() not in (".eds", ".dcf"):
        raise EdsError(f"{p}: not an EDS/DCF file (suffix {p.suffix!r})")
    try:
        text = p.read_bytes().decode("utf-8-sig")  # a byte-order mark is read, not taken as a key
    except OSError as exc:
        raise EdsError(f"{p}: cannot read the EDS: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise EdsError(f"{p}: not a valid EDS: not UTF-8 text (byte {exc.start}); save it as UTF-8") from None
    try:
        parsed = _parsed_eds(text, str(p), node_id)
    except (configparser.Error, KeyError, ValueError, TypeError, IndexError, UnicodeDecodeError,
            cod.ObjectDictionaryError) as exc:
        raise EdsError(f"{p}: not a valid EDS: {type(exc).__name__}: {exc}") from None
    return pickle.loads(parsed)  # a fresh object dictionary per call: the caller may change its own


@functools.lru_cache(maxsize=16)
def _parsed_eds(text: str, name: str, node_id: int | None) -> bytes:
    """The object dictionary of an EDS text, parsed once per (text, file name, node id) and kept pickled.

    canopen's parser takes 5-9 ms an EDS (configparser); the same EDS is loaded for each drive by the
    plan and again by each simulated drive, and a test session loaded the shipped one 1 152 times. The
    pickle round trip gives an equal, independent copy in 0.4 ms (every attribute of every object compared
    on the shipped and vendor EDS files, docs/performance.md). A text that does not parse is not kept."""
    fh = io.StringIO(text)
    fh.name = name  # canopen picks the format by the name's suffix
    return pickle.dumps(cod.import_od(fh, node_id), pickle.HIGHEST_PROTOCOL)


class AbortConnectionOption(IntEnum):
    """CiA 402 abort connection option code 0x6007: what a drive does on a connection loss
    (here: a heartbeat event of its consumer 0x1016)."""

    NO_ACTION = 0
    FAULT = 1  #: fault signal: transition 13, FAULT_REACTION_ACTIVE then FAULT
    DISABLE_VOLTAGE = 2  #: disable voltage command: power stage off at once
    QUICK_STOP = 3  #: quick stop command: then as 0x605A says (2: switch on disabled)


#: 0x605A quick stop option code the preflight writes where the drive lets it: 2 = slow down on the
#: quick stop ramp, then switch on disabled. The master does not rely on it: from QUICK STOP ACTIVE it
#: commands disable voltage itself once the drive has stopped (:mod:`hil.canopen.cia402`).
QUICK_STOP_OPTION = 2


@dataclass(frozen=True, slots=True)
class ConfigStep:
    """One object of the preflight: written (``write``) and/or read back, expecting ``data``."""

    index: int
    subindex: int
    data: bytes
    what: str
    write: bool


def master_loss_steps(master_node_id: int, consumer_ms: int) -> tuple[ConfigStep, ...]:
    """The preflight's configuration of a drive's own reaction to the master's death, in order.

    0x1016:01 = ``master_node_id << 16 | consumer_ms`` (consumer heartbeat on
    the master) and 0x6007 = 3 (quick stop on the loss), each written and read
    back. That is what the drive was *told*; whether it reacts is what the
    master's drill observes (:mod:`hil.master.core`).

    Raises
    ------
    CanopenInputError
        ``master_node_id`` outside 1..127 or ``consumer_ms`` outside 1..65535 (an entry of 0x1016
        holds the node id in bits 16..23 and the time in bits 0..15; 0 in either is unused).
    """
    node = _node_id(master_node_id, "master_node_id")
    ms = integer("consumer_ms", consumer_ms, 1, 0xFFFF, what=" ms (0x1016 bits 0..15)")
    return (ConfigStep(0x1016, 1, struct.pack("<I", node << 16 | ms),
                       "consumer heartbeat time 1", True),
            ConfigStep(0x6007, 0, struct.pack("<h", AbortConnectionOption.QUICK_STOP),
                       "abort connection option code", True))


def lookup(od: cod.ObjectDictionary, index: int, subindex: int) -> cod.ODVariable | None:
    """The variable at ``index:subindex``, None if absent.

    Parameters
    ----------
    od : canopen.ObjectDictionary
        The object dictionary to search.
    index, subindex : int
        The object; sub-index 0 for a plain variable.

    Returns
    -------
    canopen.objectdictionary.ODVariable or None
        The real variable: no array member that canopen would synthesise from
        the array's first entry, no sub-index other than 0 of a plain variable.
    """
    if index not in od:
        return None
    obj = od[index]
    if isinstance(obj, cod.ODVariable):
        return obj if subindex == 0 else None
    return obj.subindices.get(subindex)


def od_variable(od: cod.ObjectDictionary, index: int, subindex: int) -> cod.ODVariable:
    """The ``ODVariable`` at ``index:subindex``; EdsError naming it if it does not exist."""
    var = lookup(od, index, subindex)
    if var is None:
        raise EdsError(f"object 0x{index:04X}:{subindex:02X} is not in the object dictionary")
    return var


def encode_value(od: cod.ObjectDictionary, index: int, subindex: int, value: int | float | str) -> bytes:
    """Encode ``value`` with the object's data type (little endian, canopen's codec)."""
    var = od_variable(od, index, subindex)
    try:
        return var.encode_raw(value)
    except (ValueError, TypeError, cod.ObjectDictionaryError) as exc:
        raise EdsError(f"0x{index:04X}:{subindex:02X} ({var.name}): cannot encode {value!r} "
                           f"as {type_name(var.data_type)}: {exc}") from None


def decode_value(od: cod.ObjectDictionary, index: int, subindex: int, data: bytes) -> int | float | str | bytes:
    """Decode bytes read from ``index:subindex`` with the object's data type."""
    var = od_variable(od, index, subindex)
    try:
        return var.decode_raw(bytes(data))
    except cod.ObjectDictionaryError as exc:
        raise EdsError(f"0x{index:04X}:{subindex:02X} ({var.name}): cannot decode {bytes(data).hex()} "
                           f"as {type_name(var.data_type)}: {exc}") from None
