"""Raw CAN traffic log (candump -L format) and its decoding back into signals.

The master logs every frame it sends and receives, as it happens, in the
lines of python-can's :class:`can.io.CanutilsLogWriter` (one line per frame,
``(timestamp) channel ID#DATA``; can-utils' ``canplayer`` and python-can's
``can.LogReader`` replay it, and a crash loses at most the unflushed lines),
formatted in batches at each flush (:func:`candump_lines`).

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
from hil.errors import IncompleteRecordingError, RecordingError
from hil.profile.config import Actuation
from hil.record.runfolder import DiskSync, LoopFile, Signals
from hil.record.runrecord import RunRecord

#: CAN_ERR_FLAG | CAN_ERR_BUSERROR (linux/can/error.h): the identifier candump writes for an error frame
_ERROR_FRAME_ID = 0x20000000 | 0x00000080


@dataclass(frozen=True)
class FrameKind:
    """What a logged frame is when it is not a classic data frame with an 11-bit identifier on the
    log's own channel (the messages of a real bus: :meth:`CanLogWriter.write_received`)."""

    extended: bool = False
    remote: bool = False
    error: bool = False
    fd: bool = False
    bitrate_switch: bool = False
    error_state_indicator: bool = False
    channel: str | int | None = None  #: None: the log's channel

    @classmethod
    def of(cls, msg: can.Message) -> FrameKind | None:
        """A python-can message's kind, None for a classic 11-bit data frame without a channel."""
        if not (msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.is_fd
                or msg.channel is not None):
            return None
        return cls(msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame, msg.is_fd, msg.bitrate_switch,
                   msg.error_state_indicator, msg.channel)


def _channel_name(channel) -> str:
    if isinstance(channel, int) or (isinstance(channel, str) and channel.isdigit()):
        return f"can{channel}"
    return channel


def _other_line(t: float, cid: int, data: bytes, rx: bool, kind: FrameKind, channel: str) -> str:
    ch = _channel_name(kind.channel) if kind.channel is not None else channel
    if kind.error:
        head, eol = f"({t:f}) {ch} {_ERROR_FRAME_ID:08X}#", "\n"
    else:
        head, eol = f"({t:f}) {ch} {cid:08X}#" if kind.extended else f"({t:f}) {ch} {cid:03X}#", \
            " R\n" if rx else " T\n"
    if kind.remote:
        return f"{head}R{eol}"
    flags = ""
    if kind.fd:
        flags = f"#{(0x01 if kind.bitrate_switch else 0) | (0x02 if kind.error_state_indicator else 0):X}"
    return f"{head}{flags}{data.hex().upper()}{eol}"


#: one frame of the CAN log: (time [s] or None, identifier, data, received, kind: None for a classic
#: data frame with an 11-bit identifier on the log's channel)
LogRecord = tuple[float | None, int, bytes, bool, FrameKind | None]


def candump_lines(records: list[LogRecord], channel: str | int, first_t: float | None = None
                  ) -> tuple[str, float | None]:
    """The candump ``-L`` lines of ``records``, exactly as python-can's :class:`can.io.CanutilsLogWriter`
    writes them (``(time) channel ID#DATA R|T``, the time with 6 decimals, the identifier in 3 hex
    digits or 8 for an extended one, ``R`` for a remote frame, an error frame as ``20000080#``, a CAN FD
    frame's flags after ``##``), formatted in one batch.

    As python-can's writer, a time before the first frame's (or None) is written as the first frame's:
    ``first_t`` is that time from the batches before (None before the first); returns the text and it.
    """
    if not records:
        return "", first_t
    if first_t is None:
        first_t = records[0][0] or 0.0
    channel = _channel_name(channel)
    head_fmt = "(%f) " + channel.replace("%", "%%") + " "
    eols = (" T\n", " R\n")
    lines = []
    append = lines.append
    last_t = head = None  # (the frames of a SYNC cycle share their time: formatted once; a zero each time, -0.0)
    for t, cid, data, rx, kind in records:
        if t is None or t < first_t:
            t = first_t
        if kind is None:
            if t != last_t or not t:
                head = head_fmt % t
                last_t = t
            append(f"{head}{cid:03X}#{data.hex().upper()}{eols[rx]}")
        else:
            append(_other_line(t, cid, data, rx, kind, channel))
    return "".join(lines), first_t


class CanLogWriter:
    """Append frames to a candump ``.log`` file as they happen.

    Flushed every ``flush_frames`` frames and whenever the frame time moved
    ``flush_period_s`` past the last flush, so a killed master loses at most
    that much of the log (the last line may be cut short: readers drop it).
    Frames are kept as records and formatted in batches of ``format_frames``
    (:func:`candump_lines`: python-can's :class:`can.io.CanutilsLogWriter` lines;
    a small batch, so that no SYNC cycle of ``emacheck run`` formats a whole
    flush's worth, about 1 750 lines in 0.5 s) into a :class:`hil.record.runfolder.LoopFile`:
    with ``disk`` (a background :class:`~hil.record.runfolder.DiskSync`, ``emacheck run``)
    a flush hands them to its thread and no write to the file lands on the loop's;
    without, written at once. ``time_offset_s`` is added to every stamp:
    ``emacheck run`` logs wall-clock (UNIX) time as candump does; a dry-run logs
    its simulated time from 0.
    """

    def __init__(self, path: Path, channel: str = "can0", flush_frames: int = 2000,
                 flush_period_s: float = 0.5, time_offset_s: float = 0.0, disk: DiskSync | None = None,
                 format_frames: int = 64) -> None:
        self.path = path
        self._file = LoopFile(path, disk)
        self.channel = channel
        self._records: list[LogRecord] = []
        self._first_t: float | None = None
        self._format_frames = format_frames
        self._flush_frames = flush_frames
        self._flush_period_s = flush_period_s
        self._flushed_t = 0.0
        self._flushed_frames = 0  #: :attr:`frames` at the last flush
        self.frames = 0
        self.time_offset_s = float(time_offset_s)

    def write(self, frame: Frame, t: float, rx: bool) -> None:
        """Log a frame seen (``rx``) or sent at ``t`` [s, the transport's time]."""
        records = self._records
        records.append((t + self.time_offset_s if self.time_offset_s else t, frame.arbitration_id,
                        frame.data, rx, None))
        self.frames += 1
        if len(records) >= self._format_frames:
            self._format()
        if self.frames - self._flushed_frames >= self._flush_frames or t - self._flushed_t >= self._flush_period_s:
            self.flush()
            self._flushed_t = t

    def write_received(self, got: list[tuple[Frame, float, can.Message | None]]) -> None:
        """Log frames received, in order: ``(frame, time [s], python-can message or None)`` as a
        transport delivers them (with a message, its channel and direction flag, at that time)."""
        records = self._records
        off = self.time_offset_s
        t = self._flushed_t
        for f, t, msg in got:
            if msg is None:
                records.append((t + off if off else t, f.arbitration_id, f.data, True, None))
            else:
                records.append((t + off if off else t, msg.arbitration_id, bytes(msg.data), msg.is_rx,
                                FrameKind.of(msg)))
        self.frames += len(got)
        if len(records) >= self._format_frames:
            self._format()
        if self.frames - self._flushed_frames >= self._flush_frames or t - self._flushed_t >= self._flush_period_s:
            self.flush()
            self._flushed_t = t

    def _format(self) -> None:
        """The records so far as lines into the file (in memory until the next flush)."""
        if self._records:
            text, self._first_t = candump_lines(self._records, self.channel, self._first_t)
            self._records.clear()
            self._file.write(text)

    def flush(self) -> None:
        """Format the frames logged since the last batch and hand everything to the file."""
        self._format()
        self._file.flush()
        self._flushed_frames = self.frames

    def close(self) -> None:
        self.flush()
        self._file.close()


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
            from hil.profile.rig import plan_for

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
