"""Raw CAN traffic log (candump -L format) and its decoding back into signals.

The master logs every frame it sends and receives, as it happens, with
python-can's :class:`can.io.CanutilsLogWriter` (one line per frame,
``(timestamp) channel ID#DATA``; can-utils' ``canplayer`` and python-can's
``can.LogReader`` replay it, and a crash loses at most the unflushed lines).

:func:`decode_can_log` turns such a log back into the signals of the run
folder: it follows the SYNC frames and the drives' TPDOs exactly as the
master does, and the RPDOs for the setpoint columns.
"""

from __future__ import annotations

import gzip

import re
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from hil.canopen.cia402 import OperationMode
from hil.canopen.frame import SYNC_COB_ID, Frame, split_cob_id
from hil.canopen.pdo import (
    RPDO1,
    RPDO2,
    TPDO1,
    TPDO2,
    PdoError,
    decode_rpdo1,
    decode_rpdo2,
    decode_tpdo1,
    decode_tpdo2,
)
from hil.canopen.units import force_dN_to_newton, increments_to_rad, lvdt_um_to_mm, permille_to_force_N
from hil.config import Actuation
from hil.errors import IncompleteRecordingError, RecordingError
from hil.runfolder import Signals


class CanLogWriter:
    """Append frames to a candump ``.log`` file as they happen.

    Flushed to the OS every ``flush_frames`` frames and whenever the frame time
    moved ``flush_period_s`` past the last flush, so a killed master loses at
    most that much of the log (the last line may be cut short: readers drop it).
    ``time_offset_s`` is added to every stamp: ``emacheck run`` logs wall-clock
    (UNIX) time as candump does; a dry-run logs its simulated time from 0.
    """

    def __init__(self, path: Path, channel: str = "can0", flush_frames: int = 2000,
                 flush_period_s: float = 0.5, time_offset_s: float = 0.0) -> None:
        self.path = path
        self._w = can.io.CanutilsLogWriter(str(path), channel=channel)
        self._n = 0
        self._flush_frames = flush_frames
        self._flush_period_s = flush_period_s
        self._flushed_t = 0.0
        self.frames = 0
        self.time_offset_s = float(time_offset_s)

    def write(self, frame: Frame, t: float, rx: bool) -> None:
        msg = can.Message(timestamp=t, arbitration_id=frame.arbitration_id, data=frame.data,
                          is_extended_id=False, is_rx=rx)
        self.write_msg(msg)

    def write_msg(self, msg: can.Message) -> None:
        """Log a python-can message (its timestamp in the transport's time, direction flag ``is_rx``)."""
        t = msg.timestamp
        if self.time_offset_s:
            msg = can.Message(timestamp=t + self.time_offset_s, arbitration_id=msg.arbitration_id, data=msg.data,
                              is_extended_id=False, is_rx=msg.is_rx, check=False)
        self._w.on_message_received(msg)
        self.frames += 1
        self._n += 1
        if self._n >= self._flush_frames or t - self._flushed_t >= self._flush_period_s:
            self.flush()
            self._flushed_t = t

    def flush(self) -> None:
        self._w.file.flush()
        self._n = 0

    def close(self) -> None:
        self._w.stop()


@dataclass(frozen=True)
class DecodedLog:
    signals: Signals
    frames: int
    syncs: int
    incomplete_cycles: int
    bad_lines: int


_LINE = re.compile(rb"\(\d+(?:\.\d+)?\) \S+ [0-9A-Fa-f]{3}(?:[0-9A-Fa-f]{5})?#(?:[0-9A-Fa-f]{2}){0,8}(?: [RT])?")


def _check_lines(path: Path) -> bool:
    """Refuse a CAN log with lines that are not candump frames, naming the first one.

    A last line without its newline (the writer was killed mid-line) is tolerated:
    returns True when there is one (the reader drops it as a bad line).
    """
    try:
        data = gzip.decompress(path.read_bytes()) if path.name.lower().endswith(".gz") else path.read_bytes()
    except (OSError, EOFError) as exc:
        raise RecordingError(f"{path}: cannot read CAN log: {exc}") from None
    lines = data.split(b"\n")
    cut_short = bool(lines) and lines[-1] != b""
    body = lines[:-1]
    match = _LINE.fullmatch
    for k, line in enumerate(body, start=1):
        if line and match(line) is None:
            shown = line[:60].decode("ascii", "replace")
            raise RecordingError(f"{path}: line {k}: not a candump frame line '(time) channel ID#DATA': {shown!r}")
    return cut_short


def decode_can_log(path: str | Path, act: Actuation, rated_torque_Nm: float = 1.0) -> DecodedLog:
    """Decode a candump log of a check into run-folder signals.

    A sample is formed for every SYNC cycle in which both drives' TPDO1 and
    TPDO2 arrived; its time is the cycle number times the SYNC period, as the
    master logs it. Setpoint columns come from the RPDOs sent after that
    sample (mode from RPDO2, target from RPDO1). Lines that are not frames are
    counted and skipped.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such CAN log")
    cut_short = _check_lines(path)
    n1, n2 = act.canopen.node_ids
    counts = act.sensors.resolver_counts_per_rev
    i_total = act.mechanics.i_total_rad_per_mm
    T = act.timing.sync_period_s
    rows: list[list[float]] = []
    setp: list[list[float]] = []
    tp1: dict[int, object] = {}
    tp2: dict[int, object] = {}
    mode = {n1: 0, n2: 0}
    cycle = 0
    syncs = frames = incomplete = bad = 0
    pending: int | None = None  # index of the last row waiting for its setpoints

    formed = False  # the current cycle's sample exists (all four TPDOs arrived)

    def form_row() -> None:
        nonlocal pending, formed
        if formed or cycle == 0 or not all(n in tp1 and n in tp2 for n in (n1, n2)):
            return
        rows.append([cycle * T,
                     increments_to_rad(tp1[n1].position_inc, counts), increments_to_rad(tp1[n2].position_inc, counts),
                     lvdt_um_to_mm(tp2[n1].lvdt_um), lvdt_um_to_mm(tp2[n2].lvdt_um),
                     force_dN_to_newton(tp2[n1].force_dN), force_dN_to_newton(tp2[n2].force_dN)])
        setp.append([0.0, 0.0, 0.0, 0.0])
        pending = len(rows) - 1  # the RPDOs until the next SYNC carry this sample's setpoints
        formed = True

    def end_cycle() -> None:
        nonlocal pending, incomplete, formed
        if cycle > 0 and not formed:
            incomplete += 1
        pending = None
        formed = False

    try:
        # a gzip'd log (can.log.gz) is read as it is
        reader = can.io.CanutilsLogReader(gzip.open(path, "rt") if path.name.lower().endswith(".gz") else str(path))
        it = iter(reader)
        while True:
            try:
                msg = next(it)
            except StopIteration:
                break
            except (ValueError, IndexError):
                bad += 1
                continue
            frames += 1
            cid = msg.arbitration_id
            try:
                f = Frame(cid, bytes(msg.data))
                if cid == SYNC_COB_ID:
                    syncs += 1
                    end_cycle()
                    cycle += 1
                    tp1.clear()
                    tp2.clear()
                    continue
                base, node = split_cob_id(cid)
                if node not in (n1, n2):
                    continue
                if base == TPDO1.cob_id_base:
                    tp1[node] = decode_tpdo1(f)
                    form_row()
                elif base == TPDO2.cob_id_base:
                    tp2[node] = decode_tpdo2(f)
                    form_row()
                elif base == RPDO2.cob_id_base:
                    mode[node] = decode_rpdo2(f).mode
                elif base == RPDO1.cob_id_base and pending is not None:
                    r = decode_rpdo1(f)
                    k = 0 if node == n1 else 2
                    m = mode[node]
                    cw_enabled = (r.controlword & 0x0F) == 0x0F
                    mm = m if cw_enabled else 0
                    setp[pending][k] = mm
                    setp[pending][k + 1] = (permille_to_force_N(r.target_torque_permille, i_total, rated_torque_Nm)
                                            if m == OperationMode.CST else increments_to_rad(r.target_position_inc, counts))
            except PdoError:
                bad += 1
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read CAN log: {exc}") from None
    if not rows:
        raise IncompleteRecordingError(f"{path}: no complete SYNC cycle with TPDOs of nodes {n1} and {n2}")
    a = np.asarray(rows)
    s = np.asarray(setp)
    sig = Signals(t=a[:, 0], phi1=a[:, 1], phi2=a[:, 2], s1=a[:, 3], s2=a[:, 4], F1=a[:, 5], F2=a[:, 6],
                  mode1=s[:, 0], sp1=s[:, 1], mode2=s[:, 2], sp2=s[:, 3],
                  notes=(f"decoded from CAN log {path.name}: {incomplete} incomplete cycle(s), {bad} bad line(s)",)
                  + (("last line incomplete (recording cut short), dropped",) if cut_short else ()))
    return DecodedLog(sig, frames, syncs, incomplete, bad)
