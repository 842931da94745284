"""Raw CAN traffic log (candump -L format) and its decoding back into signals.

The master logs every frame it sends and receives, as it happens, with
python-can's :class:`can.io.CanutilsLogWriter` (one line per frame,
``(timestamp) channel ID#DATA``; can-utils' ``canplayer`` and python-can's
``can.LogReader`` replay it, and a crash loses at most the unflushed lines).

:func:`decode_can_log` turns such a log back into the signals of the run
folder with the one codec of a SYNC cycle the master uses
(:mod:`hil.canopen.cycle`), and the RPDOs for the setpoint columns.
"""

from __future__ import annotations

import codecs
import dataclasses
import gzip
import re
import zlib
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np

from hil.canopen.cia402 import OperationMode, enables_operation
from hil.canopen.cycle import CycleDecoder, SetpointEncoder, SyncSchedule, from_image
from hil.canopen.errors import CanopenInputError
from hil.canopen.frame import SYNC_COB_ID, Frame
from hil.canopen.pdo import Direction, PdoError
from hil.canopen.signalmap import Signal, torque_scale
from hil.config import Actuation
from hil.errors import IncompleteRecordingError, RecordingError
from hil.runfolder import DiskSync, LoopFile, Signals
from hil.runrecord import RunRecord


class CanLogWriter:
    """Append frames to a candump ``.log`` file as they happen.

    Flushed every ``flush_frames`` frames and whenever the frame time moved
    ``flush_period_s`` past the last flush, so a killed master loses at most
    that much of the log (the last line may be cut short: readers drop it).
    The lines are formatted by python-can's :class:`can.io.CanutilsLogWriter`
    into a :class:`hil.runfolder.LoopFile`: with ``disk`` (a background
    :class:`~hil.runfolder.DiskSync`, ``emacheck run``) a flush hands them to its
    thread and no write to the file lands on the loop's; without, written at once.
    ``time_offset_s`` is added to every stamp: ``emacheck run`` logs wall-clock
    (UNIX) time as candump does; a dry-run logs its simulated time from 0.
    """

    def __init__(self, path: Path, channel: str = "can0", flush_frames: int = 2000,
                 flush_period_s: float = 0.5, time_offset_s: float = 0.0, disk: DiskSync | None = None) -> None:
        self.path = path
        self._w = can.io.CanutilsLogWriter(LoopFile(path, disk), channel=channel)
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
    except IsADirectoryError:
        raise RecordingError(f"{path}: a folder, not a CAN log") from None
    except (OSError, EOFError, zlib.error) as exc:
        what = "a corrupt or truncated gzip file" if path.name.lower().endswith(".gz") else "cannot read it"
        raise RecordingError(f"{path}: {what}, not a CAN log ({type(exc).__name__}: {exc})") from None
    data = data.removeprefix(codecs.BOM_UTF8)
    lines = data.split(b"\n")
    cut_short = bool(lines) and lines[-1] != b""
    body = lines[:-1]
    match = _LINE.fullmatch
    for k, line in enumerate(body, start=1):
        if line and match(line) is None:
            shown = line[:60].decode("ascii", "replace")
            raise RecordingError(f"{path}: line {k}: not a candump frame line '(time) channel ID#DATA': {shown!r}")
    return cut_short


def _codec(act: Actuation, meta, rig=None):
    """The cycle codec of a recorded check: meta.json's process image where the run folder has one,
    else the profile's plan (scalings the drives report are then not known: the rated torque is taken
    as 1 N m for the setpoint columns, a motor angle scaled by the drive refuses the log)."""
    image = meta.process_image if meta is not None else None
    notes = []
    if image:
        try:
            pdos, chans = from_image(image)
        except CanopenInputError as exc:
            raise RecordingError(f"meta.json: {exc}") from None
    else:
        if rig is None:
            from hil.rig import plan_for

            rig = plan_for(act)
        plan = rig.plan
        pdos = plan.tx_pdos + plan.rx_pdos
        chans = []
        for ch in plan.channels:
            if ch.scale is None and ch.signal in (Signal.MOTOR_ANGLE, Signal.TARGET_POSITION):
                raise RecordingError(f"{ch.key}: the motor angle's scaling is read from the drive "
                                     f"({ch.source.value}); decode the CAN log with its run folder's meta.json")
            if ch.scale is None and ch.signal is Signal.TARGET_TORQUE:
                ch = dataclasses.replace(ch, scale=torque_scale(1.0, act.mechanics.i_total_rad_per_mm))
                if not notes:
                    notes.append("no meta.json: force setpoints taken at a rated torque of 1 N m")
            chans.append(ch)
    tx = [p for p in pdos if p.direction is Direction.TX]
    rx = [p for p in pdos if p.direction is Direction.RX]
    try:
        return (CycleDecoder(tx, [c for c in chans if c.signal.direction is Direction.TX]),
                SetpointEncoder(rx, [c for c in chans if c.signal.direction is Direction.RX]), tuple(notes))
    except CanopenInputError as exc:
        raise RecordingError(f"process image: {exc}") from None


def _frames(path: Path, counts: dict):
    """The frames of a candump log (``.gz`` too) with their stamps [s], skipping lines python-can cannot
    parse (counted)."""
    opener = gzip.open if path.name.lower().endswith(".gz") else open
    try:
        # closed however the reading ends (python-can closes only at the end)
        with opener(path, "rt", encoding="utf-8-sig") as fh:
            it = iter(can.io.CanutilsLogReader(fh))
            while True:
                try:
                    msg = next(it)
                except StopIteration:
                    return
                except (ValueError, IndexError):
                    counts["bad"] += 1
                    continue
                counts["frames"] += 1
                yield Frame(msg.arbitration_id, bytes(msg.data)), msg.timestamp
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read CAN log: {exc}") from None


def decode_can_log(path: str | Path, act: Actuation, meta: RunRecord | None = None, *, rig=None) -> DecodedLog:
    """Decode a candump log of a check into run-folder signals.

    A sample is formed for every SYNC cycle in which every TPDO with an input
    arrived (:class:`hil.canopen.cycle.CycleDecoder`, as the master forms it);
    its time is its SYNC's period (:class:`hil.canopen.cycle.SyncSchedule` on the SYNCs' stamps: the
    periods since the last SYNC, the nearest whole number and at least one), as the master logs it.
    Setpoint columns come from the RPDOs sent after that sample (mode from the
    modes-of-operation RPDO, targets from the synchronous RPDOs, the mode column
    0 while the controlword does not enable operation). The layout and scalings
    are meta.json's ``process_image`` when given, else the profile's plan.
    Lines that are not frames are counted and skipped.
    """
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such CAN log")
    cut_short = _check_lines(path)
    dec, enc, notes = _codec(act, meta, rig)
    T = act.timing.sync_period_s
    rows: list[list[float]] = []
    setp: list[list[float]] = []
    mode = {1: 0, 2: 0}
    counts = {"frames": 0, "bad": 0}
    cycle = syncs = incomplete = bad = 0
    schedule = SyncSchedule(T)  # each sample's time: its SYNC's period, as the master gives it
    pending: int | None = None  # index of the last row waiting for its setpoints
    for f, stamp in _frames(path, counts):
        cid = f.arbitration_id
        try:
            if cid == SYNC_COB_ID:
                syncs += 1
                if cycle > 0 and pending is None:
                    incomplete += 1
                cycle += 1
                schedule.on_sync(stamp)
                pending = None
                dec.reset()
                continue
            if dec.feed(f) is not None:
                if pending is None and cycle > 0 and dec.complete:
                    rows.append([schedule.t_s, *dec.values])
                    setp.append([0.0, 0.0, 0.0, 0.0])
                    pending = len(rows) - 1  # the RPDOs until the next SYNC carry this sample's setpoints
                continue
            rx = enc.decode(f)
            if rx is None:
                continue
            if rx.mode is not None:
                mode[rx.ema] = rx.mode
            if pending is not None and rx.controlword is not None:
                k = 0 if rx.ema == 1 else 2
                m = mode[rx.ema]
                setp[pending][k] = m if enables_operation(rx.controlword) else 0
                value = rx.target_torque_N if m == OperationMode.CST else rx.target_position_rad
                setp[pending][k + 1] = 0.0 if value is None else value
        except PdoError:
            bad += 1
    # (the last SYNC's cycle is judged by no next SYNC: where the recording ends, it is not counted,
    # as the master counts a cycle incomplete only when the next SYNC comes)
    bad += counts["bad"]
    if not rows:
        raise IncompleteRecordingError(f"{path}: no complete SYNC cycle with the TPDOs of the rig's nodes")
    a = np.asarray(rows)
    s = np.asarray(setp)
    sig = Signals(t=a[:, 0], phi1=a[:, 1], phi2=a[:, 2], s1=a[:, 3], s2=a[:, 4], F1=a[:, 5], F2=a[:, 6],
                  mode1=s[:, 0], sp1=s[:, 1], mode2=s[:, 2], sp2=s[:, 3],
                  notes=(f"decoded from CAN log {path.name}: {incomplete} incomplete cycle(s), {bad} bad line(s)",)
                  + notes + (("last line incomplete (recording cut short), dropped",) if cut_short else ()))
    return DecodedLog(sig, counts["frames"], syncs, incomplete, bad)
