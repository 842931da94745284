"""Object dictionary of the EMA drives: load the EDS and check it has what the master needs.

The shipped CiA 306 EDS (``profiles/ema_drive.eds``) describes the drive; the
simulated drives (:mod:`sim.drives`) serve it, and the master refuses a
drive EDS that lacks an object the PDO layout maps or the check reads or
writes (:func:`check_drive_od`), including the drive's own reaction to the
master's death (:data:`MASTER_LOSS_OBJECTS`, configured as
:func:`master_loss_steps` says). Parsing and data-type encoding are canopen's
(``canopen.objectdictionary``); nothing here talks to a bus.
"""

from __future__ import annotations

import configparser
import struct
from dataclasses import dataclass
from enum import IntEnum
from importlib import resources
from pathlib import Path

import canopen.objectdictionary as cod
from canopen.objectdictionary import datatypes as dt

from hil.canopen.errors import EdsError
from hil.canopen.pdo import DEFAULT_LAYOUT, Direction, PdoLayout

DEFAULT_EDS = "ema_drive.eds"  #: file name of the shipped EDS in the ``profiles`` package

_TYPE_NAMES = {v: k for k, v in vars(dt).items() if k.isupper() and isinstance(v, int) and v <= 0x1B}


def _type_name(code: int | None) -> str:
    if code is None:
        return "none"
    return f"0x{code:04X} ({_TYPE_NAMES.get(code, 'unknown')})"


def default_eds_path() -> Path:
    """Path of the EDS shipped in the ``profiles`` package."""
    return Path(str(resources.files("profiles").joinpath(DEFAULT_EDS)))


def load_drive_od(path: str | Path | None = None, *, node_id: int | None = None) -> cod.ObjectDictionary:
    """Parse a drive EDS into a ``canopen.ObjectDictionary``.

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
    if not p.is_file():
        raise EdsError(f"{p}: EDS not found")
    if p.suffix.lower() not in (".eds", ".dcf"):
        raise EdsError(f"{p}: not an EDS/DCF file (suffix {p.suffix!r})")
    try:
        return cod.import_od(str(p), node_id)
    except (configparser.Error, KeyError, ValueError, cod.ObjectDictionaryError) as exc:
        raise EdsError(f"{p}: not a valid EDS: {type(exc).__name__}: {exc}") from None


@dataclass(frozen=True, slots=True)
class RequiredObject:
    """One object the master needs in a drive's object dictionary.

    ``access`` is what the master does with it: ``"r"`` (reads it, by SDO or
    in a TPDO), ``"w"`` (writes it, in an RPDO) or ``"rw"`` (configures it by SDO).
    """

    index: int
    subindex: int
    name: str
    data_type: int
    access: str
    pdo_mappable: bool = False


class AbortConnectionOption(IntEnum):
    """CiA 402 abort connection option code 0x6007: what a drive does on a connection loss
    (here: a heartbeat event of its consumer 0x1016)."""

    NO_ACTION = 0
    FAULT = 1  #: fault signal: transition 13, FAULT_REACTION_ACTIVE then FAULT
    DISABLE_VOLTAGE = 2  #: disable voltage command: power stage off at once
    QUICK_STOP = 3  #: quick stop command: then as 0x605A says (2: switch on disabled)


#: 0x605A quick stop option code of the emacheck drives: 2 = slow down, then switch on disabled.
QUICK_STOP_OPTION = 2


@dataclass(frozen=True, slots=True)
class ConfigStep:
    """One object of the preflight: written (``write``) and/or read back, expecting ``data``."""

    index: int
    subindex: int
    data: bytes
    what: str
    write: bool


def master_loss_steps(master_node_id: int, consumer_ms: int, sync_period_us: int) -> tuple[ConfigStep, ...]:
    """The preflight's configuration of a drive's own reaction to the master's death, in order.

    0x1016:01 = ``master_node_id << 16 | consumer_ms`` (consumer heartbeat on
    the master), 0x6007 = 3 (quick stop on the loss), both written and read
    back; 0x605A (= 2: then switch on disabled) and 0x1006 (the SYNC period,
    the drive's communication cycle) read back, written before.
    """
    return (ConfigStep(0x1016, 1, struct.pack("<I", master_node_id << 16 | consumer_ms),
                       "consumer heartbeat time 1", True),
            ConfigStep(0x6007, 0, struct.pack("<h", AbortConnectionOption.QUICK_STOP),
                       "abort connection option code", True),
            ConfigStep(0x605A, 0, struct.pack("<h", QUICK_STOP_OPTION), "quick stop option code", False),
            ConfigStep(0x1006, 0, struct.pack("<I", sync_period_us), "communication cycle period", False))


#: The objects of a drive's own reaction to the master's death (the preflight writes and reads
#: them back): consumer heartbeat time 1 (the master's node id and the time) and the CiA 402
#: abort connection option code (3: quick stop, then switch on disabled through 0x605A = 2).
MASTER_LOSS_OBJECTS: tuple[RequiredObject, ...] = (
    RequiredObject(0x1016, 1, "consumer heartbeat time 1", dt.UNSIGNED32, "rw"),
    RequiredObject(0x6007, 0, "abort connection option code", dt.INTEGER16, "rw"),
)


def required_objects(layout: PdoLayout = DEFAULT_LAYOUT, *, master_loss: bool = True) -> tuple[RequiredObject, ...]:
    """The objects a drive must have for ``layout`` and the check.

    The mapped objects (RPDO ones writable, TPDO ones readable, both
    PDO-mappable), the PDO communication (sub 1 COB-ID, sub 2 transmission
    type) and mapping parameters (sub 0 and one entry per mapped object,
    writable), and the objects the master reads or sets up: device type,
    identity, producer heartbeat, error code, quick stop option code,
    software position limits, rated torque, encoder resolution, supported
    drive modes and the gear ratio 0x2102; with ``master_loss`` (the
    default) also :data:`MASTER_LOSS_OBJECTS`, the drive's own reaction to
    the master's death. Only a rig whose profile states another protection
    (``canopen.external_watchdog``) may do without them.
    """
    req: list[RequiredObject] = []
    for p in layout.pdos:
        access = "w" if p.direction is Direction.RX else "r"
        for e in p.entries:
            req.append(RequiredObject(e.index, e.subindex, e.name, e.data_type, access, True))
    for p in layout.pdos:
        req.append(RequiredObject(p.comm_index, 1, f"{p.name} COB-ID", dt.UNSIGNED32, "rw"))
        req.append(RequiredObject(p.comm_index, 2, f"{p.name} transmission type", dt.UNSIGNED8, "rw"))
        req.append(RequiredObject(p.mapping_index, 0, f"{p.name} number of mapped objects", dt.UNSIGNED8, "rw"))
        for k in range(1, len(p.entries) + 1):
            req.append(RequiredObject(p.mapping_index, k, f"{p.name} mapping entry {k}", dt.UNSIGNED32, "rw"))
    req += [
        RequiredObject(0x1000, 0, "device type", dt.UNSIGNED32, "r"),
        RequiredObject(0x1017, 0, "producer heartbeat time", dt.UNSIGNED16, "rw"),
        RequiredObject(0x1018, 1, "vendor-ID", dt.UNSIGNED32, "r"),
        RequiredObject(0x1018, 2, "product code", dt.UNSIGNED32, "r"),
        RequiredObject(0x1018, 3, "revision number", dt.UNSIGNED32, "r"),
        RequiredObject(0x603F, 0, "error code", dt.UNSIGNED16, "r"),
        RequiredObject(0x605A, 0, "quick stop option code", dt.INTEGER16, "r"),
        RequiredObject(0x607D, 1, "min position limit", dt.INTEGER32, "rw"),
        RequiredObject(0x607D, 2, "max position limit", dt.INTEGER32, "rw"),
        RequiredObject(0x6076, 0, "motor rated torque", dt.UNSIGNED32, "r"),
        RequiredObject(0x608F, 1, "encoder increments", dt.UNSIGNED32, "r"),
        RequiredObject(0x608F, 2, "motor revolutions", dt.UNSIGNED32, "r"),
        RequiredObject(0x6502, 0, "supported drive modes", dt.UNSIGNED32, "r"),
        RequiredObject(0x2102, 0, "gear ratio i_total", dt.REAL32, "r"),
    ]
    if master_loss:
        req += MASTER_LOSS_OBJECTS
    return tuple(req)


#: What the master requires of a drive with the default PDO layout.
REQUIRED_OBJECTS: tuple[RequiredObject, ...] = required_objects(DEFAULT_LAYOUT)


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


_lookup = lookup  # the former private name


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
                           f"as {_type_name(var.data_type)}: {exc}") from None


def decode_value(od: cod.ObjectDictionary, index: int, subindex: int, data: bytes) -> int | float | str | bytes:
    """Decode bytes read from ``index:subindex`` with the object's data type."""
    var = od_variable(od, index, subindex)
    try:
        return var.decode_raw(bytes(data))
    except cod.ObjectDictionaryError as exc:
        raise EdsError(f"0x{index:04X}:{subindex:02X} ({var.name}): cannot decode {bytes(data).hex()} "
                           f"as {_type_name(var.data_type)}: {exc}") from None


def check_drive_od(od: cod.ObjectDictionary, *, layout: PdoLayout = DEFAULT_LAYOUT,
                   source: str = "drive EDS", master_loss: bool = True) -> None:
    """Refuse an object dictionary that lacks what the master needs.

    Every :func:`required_objects` entry must exist (a real sub-index, not
    one canopen synthesises for arrays), have the data type, be readable
    and/or writable as the master uses it and, if mapped, be PDO-mappable.

    Parameters
    ----------
    od : canopen.ObjectDictionary
        Typically :func:`load_drive_od`'s result.
    layout : PdoLayout
        The PDO layout the master will configure.
    source : str
        Name used in the message (e.g. the EDS path).
    master_loss : bool
        Require :data:`MASTER_LOSS_OBJECTS` (default; fail closed). False only
        for a rig whose actuation profile states another protection against
        the master's death (``canopen.external_watchdog``).

    Raises
    ------
    EdsError
        Listing every problem, each naming the object, e.g.
        ``drive EDS: 0x6041:00 (statusword) is missing``.
    """
    problems: list[str] = []
    for r in required_objects(layout, master_loss=master_loss):
        where = f"0x{r.index:04X}:{r.subindex:02X} ({r.name})"
        var = lookup(od, r.index, r.subindex)
        if var is None:
            problems.append(f"{where} is missing")
            continue
        if var.data_type != r.data_type:
            problems.append(f"{where} has data type {_type_name(var.data_type)}, "
                            f"expected {_type_name(r.data_type)}")
        if "r" in r.access and not var.readable:
            problems.append(f"{where} is not readable (access {var.access_type})")
        if "w" in r.access and not var.writable:
            problems.append(f"{where} is not writable (access {var.access_type})")
        if r.pdo_mappable and not var.pdo_mappable:
            problems.append(f"{where} is not PDO-mappable")
    if problems:
        raise EdsError(f"{source}: " + "; ".join(problems))
