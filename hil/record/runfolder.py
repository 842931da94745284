"""The run folder: signals CSV written as it happens, meta.json, result.json.

Format (see README, "File formats")::

    RUN/signals.csv   t,phi1,phi2,s1,s2,F1,F2,mode1,sp1,mode2,sp2,step
                      t in s, phi in rad, s in mm, F in N; mode is the CiA 402
                      mode (0 disabled, 8 CSP, 10 CST), sp the setpoint (rad or N)
    RUN/meta.json     the run record (hil.record.runrecord): profiles snapshot, software version,
                      seed, step times, ...; written by MetaWriter only
    RUN/result.json   the analysis result
    RUN/report.html   the report

The CSV is flushed at least every ``flush_rows`` rows and at every step
change, so a crash loses at most that much. A bare CSV recorded elsewhere
needs only the first seven columns.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hil.canopen.process import Sample, Setpoint
from hil.errors import IncompleteRecordingError, OutputError, RecordingError
from hil.record.runrecord import META_NAME, RunRecord
from hil.record.signals_csv import EXTRA_COLUMNS, SIGNAL_COLUMNS


def write_json_atomic(path: Path, obj: Any) -> None:
    """Write JSON via a temporary file and rename, so a crash never leaves half a file; an OSError (a full
    disk) leaves the file as it was and is raised as :class:`hil.errors.OutputError` naming ``path``."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "w") as fh:
            json.dump(obj, fh, indent=2, sort_keys=False, default=json_default)
            fh.write("\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:  # a full disk, an IO error: the file as it was, the path and the cause named
        with _suppress_os():
            os.unlink(tmp)
        raise output_error(path, exc) from None


def output_error(path: Path, exc: OSError) -> OutputError:
    """An OSError met writing an output, as one line naming the path (exit status 3)."""
    if isinstance(exc, FileExistsError):
        return OutputError(f"{path}: exists; emacheck never overwrites a record (give another --out, or omit "
                           f"--out for a new folder)")
    return OutputError(f"{path}: cannot be written ({exc.strerror or type(exc).__name__}); give --out a "
                       f"folder you can write to")


def _link_new(src: Path, dst: Path) -> None:
    """Give the complete file ``src`` the name ``dst`` only if ``dst`` does not exist (``os.link`` fails
    then, even in a race: never a replace); ``src`` is removed either way. Where the file system has no
    hard links, ``dst`` is created with ``O_EXCL`` and ``src`` copied into it."""
    import errno
    import shutil

    try:
        try:
            os.link(src, dst)
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK,
                                 errno.ENOSYS):
                raise
            with open(src, "rb") as fin, open(dst, "xb") as fout:
                shutil.copyfileobj(fin, fout)
                fout.flush()
                os.fsync(fout.fileno())
    except OSError as exc:
        raise output_error(dst, exc) from None
    finally:
        with _suppress_os():
            os.unlink(src)


def _suppress_os():
    import contextlib

    return contextlib.suppress(OSError)


def new_file_mode() -> int:
    """The mode a new file gets under this process's umask (0o644 under the usual 022), as ``open`` gives it."""
    try:
        with open("/proc/self/status") as fh:  # Linux: read without changing it (os.umask would, process-wide)
            mask = next(int(line.split()[1], 8) for line in fh if line.startswith("Umask:"))
    except (OSError, StopIteration, ValueError, IndexError):
        mask = os.umask(0o022)
        os.umask(mask)
    return 0o666 & ~mask


def create_with(path: Path, write) -> Path:
    """Create the file ``path`` by ``write(tmp)`` (any writer taking a path: a report) without ever
    replacing a file: written complete under a temporary name beside it, then linked to ``path`` only if
    ``path`` does not exist (:class:`~hil.errors.OutputError` naming it otherwise, exit status 3)."""
    import tempfile

    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
        try:
            os.fchmod(fd, new_file_mode())  # (mkstemp makes it 0600: an output is readable as the user's others)
        finally:
            os.close(fd)
    except OSError as exc:
        raise output_error(path, exc) from None
    try:
        write(Path(tmp))
    except BaseException as exc:
        with _suppress_os():
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, OutputError):  # a full disk, an IO error
            raise output_error(path, exc) from None
        raise
    _link_new(Path(tmp), path)
    return path


def create_bytes(path: Path, data: bytes) -> Path:
    """Create the file ``path`` holding ``data`` (fsynced) only if it does not exist (:func:`create_with`)."""

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())

    return create_with(path, write)


def create_json(path: Path, obj: Any) -> Path:
    """Create the JSON file ``path`` only if it does not exist: a record written once, never replaced."""
    text = json.dumps(obj, indent=2, sort_keys=False, default=json_default) + "\n"
    return create_bytes(path, text.encode())


def open_new(path: Path):
    """``open(path, "x")``: a new text file, never one that exists (:class:`~hil.errors.OutputError`)."""
    try:
        return open(path, "x")
    except OSError as exc:
        raise output_error(Path(path), exc) from None


def _write_bytes_atomic(path: Path, data: bytes) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


#: stack of the disk-sync thread [bytes]: it writes, fsyncs and renames, nothing deep
DISK_SYNC_STACK_BYTES = 256 * 1024


class DiskSync:
    """The run folder's writes to the disk, off the cyclic loop's thread (IO shell).

    ``fsync`` takes milliseconds to tens of milliseconds (8-13 ms measured here for
    meta.json) and a pure-Python ``json.dump`` with indentation about 1 ms: done at a step
    change inside the check loop, the master missed SYNC cycles. The loop serialises the
    JSON (C encoder, ~0.15 ms for meta.json) and hands the bytes, and the files to fsync, to
    this thread, which does the writing, fsync and rename (all of which release the GIL) in
    order. A killed master still loses at most what it had not flushed to the OS (the loop's
    flushes are unchanged); a power cut, what this thread had not synced yet (milliseconds
    more). :meth:`close` waits for every job and raises the first error met.

    The thread gets a stack of :data:`DISK_SYNC_STACK_BYTES`, not the default 8 MiB: a
    real-time master locks its memory (``mlockall`` with ``MCL_FUTURE``), so every page of
    a new thread's stack is faulted in at once (2048 page faults for 8 MiB, ~0.9 ms each
    inside user-mode-linux; the vcan stage bounds the check's page faults).

    ``background=False`` (a dry-run on simulated time: nothing to keep from stalling)
    does each job at once on the caller's thread, so the folder on disk follows the loop
    exactly.
    """

    def __init__(self, background: bool = True) -> None:
        import queue
        import threading

        self.background = background
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._errors: list[BaseException] = []
        self._thread = threading.Thread(target=self._run, name="emacheck-disk-sync", daemon=True)
        if background:
            previous = threading.stack_size(DISK_SYNC_STACK_BYTES)
            try:
                self._thread.start()
            finally:
                threading.stack_size(previous)

    def _run(self) -> None:
        while True:
            job = self._q.get()
            if job is None:
                return
            try:
                _do(job)
            except OSError as exc:  # recorded (naming the file where the job does), raised by close()
                self._errors.append(_naming(exc, job[3] if len(job) > 3 else None))
            except BaseException as exc:
                self._errors.append(exc)

    def _job(self, *job) -> None:
        if self.background:
            self._q.put(job)
        else:
            _do(job)

    def write_json(self, path: Path, obj: Any) -> None:
        """Write ``obj`` as JSON to ``path`` atomically (as :func:`write_json_atomic`), in the background."""
        if not self.background:
            write_json_atomic(path, obj)
            return
        self._q.put(("json", path, (json.dumps(obj, default=json_default) + "\n").encode()))

    def fsync(self, fd: int) -> None:
        """fsync the open file ``fd`` in the background (it must stay open until :meth:`close`)."""
        self._job("fsync", fd)

    def append(self, fd: int, data: bytes, path: Path | None = None) -> None:
        """Write ``data`` at the end of the open file ``fd`` (opened with ``O_APPEND``; ``path``: its name, for
        an error) in the background, in order with this DiskSync's other jobs."""
        try:
            self._job("append", fd, data, path)
        except OSError as exc:
            raise _naming(exc, path) from None

    def close_file(self, fd: int, sync: bool) -> None:
        """Close the file ``fd`` (``sync``: fsync it first) after every job given before."""
        self._job("close_synced" if sync else "close", fd)

    @property
    def error(self) -> BaseException | None:
        """The first error the thread met so far (None: every job done or pending); :meth:`close` raises it."""
        return self._errors[0] if self._errors else None

    def close(self) -> None:
        """Wait for every job; raise the first error met. Jobs given later are done at once."""
        if self._thread.is_alive():
            self._q.put(None)
            self._thread.join()
        self.background = False
        if self._errors:
            raise self._errors[0]


def _naming(exc: OSError, path: Path | None) -> OSError:
    """``exc`` naming ``path`` where it names no file (a write to a descriptor names none)."""
    if path is None or exc.filename:
        return exc
    return type(exc)(exc.errno, exc.strerror, str(path))


def _do(job: tuple) -> None:
    """One job of a :class:`DiskSync`, on the thread that does it."""
    kind, target = job[0], job[1]
    if kind == "json":
        _write_bytes_atomic(target, job[2])
    elif kind == "append":
        view = memoryview(job[2])
        while view:
            view = view[os.write(target, view):]
    else:
        if kind != "close":
            os.fsync(target)
        if kind != "fsync":
            os.close(target)


class LoopFile:
    """A text file the cyclic loop writes with no system call on its thread (IO shell).

    :meth:`write` keeps the text in memory; :meth:`flush` hands it, encoded as UTF-8, to the
    :class:`DiskSync` (appended by its thread, in order with the file's fsync and close); with no
    DiskSync, or one that is not in the background (a dry-run on simulated time), each flush
    writes at once. A killed process loses what was not flushed, as with a buffered file; a
    ``write()`` to the page cache no longer lands in a SYNC cycle (one took 2.4 ms on the
    master's loop thread; a write to a file the sync thread is fsyncing may wait for it).
    Enough of a text file for :class:`can.io.CanutilsLogWriter` and :class:`SignalsWriter`.
    """

    def __init__(self, path: Path, disk: DiskSync | None = None) -> None:
        self.path = Path(path)
        self.disk = disk if disk is not None else DiskSync(background=False)  # (none: each job at once)
        try:  # a new file: a run's can.log and signals.csv are written once, never over an older one
            self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
        except OSError as exc:
            raise output_error(self.path, exc) from None
        self._parts: list[str] = []
        self.closed = False

    def write(self, text: str) -> int:
        self._parts.append(text)
        return len(text)

    def flush(self) -> None:
        """Hand the text written so far to the disk (the DiskSync's thread, or at once)."""
        if self._parts:
            data = "".join(self._parts).encode()
            self._parts.clear()
            self.disk.append(self._fd, data, self.path)

    def fsync(self) -> None:
        """After what was flushed: to the disk itself (survives a power cut)."""
        self.disk.fsync(self._fd)

    def fileno(self) -> int:
        return self._fd

    def close(self, sync: bool = False) -> None:
        """Flush and close (``sync``: fsync first); the descriptor is closed after the writes given before."""
        if self.closed:
            return
        self.flush()
        self.closed = True
        self.disk.close_file(self._fd, sync)


def has_record(run_dir: Path) -> bool:
    """Whether ``run_dir`` holds a meta.json."""
    return (Path(run_dir) / META_NAME).exists()


def record_path(run_dir: Path) -> Path:
    """The path of ``run_dir``'s run record (meta.json), whether it exists or not."""
    return Path(run_dir) / META_NAME


def read_record(run_dir: Path | None) -> RunRecord | None:
    """A run folder's record (:class:`hil.record.runrecord.RunRecord`), or None (no run folder, or no meta.json
    in it); not JSON, or a malformed field: a :class:`~hil.errors.RecordingError` naming the file (and
    the field)."""
    if run_dir is None or not has_record(run_dir):
        return None
    path = Path(run_dir) / META_NAME
    return RunRecord.from_json(read_json(path), str(path))


def read_json(path: Path) -> Any:
    """A JSON file (UTF-8, a byte-order mark skipped), or a RecordingError naming it and the cause
    (missing, a folder, unreadable, not UTF-8, not JSON)."""
    try:
        return json.loads(Path(path).read_bytes())  # (bytes: json detects a BOM and UTF-16/32 itself)
    except FileNotFoundError:
        raise RecordingError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise RecordingError(f"{path}: a folder, not a JSON file") from None
    except OSError as exc:
        raise RecordingError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise RecordingError(f"{path}: not a JSON text file (byte {exc.start} is not UTF-8)") from None
    except json.JSONDecodeError as exc:
        raise RecordingError(f"{path}: not valid JSON: {exc}") from None


class MetaWriter:
    """The one writer of a run folder's meta.json (IO shell): owns its path, the record as last
    written and, while the check loop runs, the folder's :class:`DiskSync`.

    :meth:`write` writes at once on the caller's thread (atomically, fsynced; with ``new`` the first write
    creates the file and refuses one that exists, :class:`~hil.errors.OutputError`); :meth:`post` hands the
    record to the DiskSync (in the background on a real bus, so the loop never waits for the disk),
    which also writes and fsyncs signals.csv (:class:`SignalsWriter`) in order with it.
    """

    def __init__(self, run_dir: Path, record: RunRecord, disk: DiskSync | None = None, *, new: bool = False) -> None:
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / META_NAME
        self.record = record  #: the record as last written (or as given, before the first write)
        self.disk = disk
        #: the first write creates meta.json (a new run: never over another run's); later ones replace it
        self._create = new

    def write(self, record: RunRecord | None = None) -> RunRecord:
        """Write ``record`` (default: the current one) now; returns it."""
        if record is not None:
            self.record = record
        if self._create:
            create_json(self.path, self.record.as_json())
            self._create = False
        else:
            write_json_atomic(self.path, self.record.as_json())
        return self.record

    def post(self, record: RunRecord) -> RunRecord:
        """Write ``record`` through the DiskSync (at once without one, or when it creates the file); returns it."""
        if self.disk is None or self._create:
            return self.write(record)
        self.record = record
        self.disk.write_json(self.path, record.as_json())
        return record

    def open_disk(self, background: bool) -> None:
        """Make the DiskSync unless one was given (``background``: its own thread)."""
        if self.disk is None:
            self.disk = DiskSync(background=background)

    def close_disk(self) -> None:
        """Wait for the DiskSync's jobs and let it go (raises its first error); later writes are at once."""
        disk, self.disk = self.disk, None
        if disk is not None:
            disk.close()


def json_default(o: Any) -> Any:
    """JSON form of numpy scalars and arrays (``json.dump(..., default=json_default)``)."""
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


class SignalsWriter:
    """Append-only writer of ``signals.csv`` (IO shell): rows in memory until :meth:`flush`, then to the
    disk through ``disk`` (:class:`LoopFile`: on a real bus by the DiskSync's thread, never a system call
    on the loop's; with none, at once)."""

    def __init__(self, path: Path, flush_rows: int = 500, disk: DiskSync | None = None) -> None:
        self.path = path
        self._fh = LoopFile(path, disk)
        self._fh.write(",".join(SIGNAL_COLUMNS + EXTRA_COLUMNS) + "\n")
        self._fh.flush()
        self._pending = 0
        self._flush_rows = flush_rows
        self.rows = 0
        self.flushed_t_s = 0.0  #: sample time of the last flush

    #: one row: t [s] 4 decimals, angles [rad] 7, strokes [mm] 6, forces [N] 3, then each drive's mode (its
    #: integer) and setpoint (7 significant digits), the step (one %-format: about a quarter cheaper than the
    #: f-string it replaced)
    _ROW = "%.4f,%.7f,%.7f,%.6f,%.6f,%.3f,%.3f,%d,%.7g,%d,%.7g,%s\n"

    def write(self, smp: Sample, sp1: Setpoint, sp2: Setpoint, step: str) -> None:
        self._fh.write(self._ROW % (smp.t_s, smp.phi1_rad, smp.phi2_rad, smp.s1_mm, smp.s2_mm, smp.F1_N, smp.F2_N,
                                    sp1.mode, sp1.value, sp2.mode, sp2.value, step))
        self.rows += 1
        self._pending += 1
        if self._pending >= self._flush_rows:
            self.flush(smp.t_s)

    def flush(self, t_s: float | None = None, sync: bool = False) -> None:
        """Hand the rows written so far to the OS (they survive a killed process); ``sync``: also to
        the disk (they survive a power cut)."""
        self._fh.flush()
        if sync:
            self._fh.fsync()
        self._pending = 0
        if t_s is not None:
            self.flushed_t_s = t_s

    def fileno(self) -> int:
        return self._fh.fileno()

    def close(self) -> None:
        """Flush, fsync and close."""
        self._fh.close(sync=True)


@dataclass(frozen=True)
class Signals:
    """A recording as arrays (units as in :data:`COLUMN_UNITS`).

    ``step`` is an array of step names, or None for a bare recording;
    ``mode1/sp1/mode2/sp2`` likewise.
    """

    t: np.ndarray
    phi1: np.ndarray
    phi2: np.ndarray
    s1: np.ndarray
    s2: np.ndarray
    F1: np.ndarray
    F2: np.ndarray
    step: np.ndarray | None = None
    mode1: np.ndarray | None = None
    sp1: np.ndarray | None = None
    mode2: np.ndarray | None = None
    sp2: np.ndarray | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def n(self) -> int:
        return int(self.t.size)

    @property
    def sample_period_s(self) -> float:
        return float(np.median(np.diff(self.t)))

    def select(self, mask: np.ndarray) -> Signals:
        kw = {}
        for name in SIGNAL_COLUMNS + EXTRA_COLUMNS:
            v = getattr(self, name)
            kw[name] = None if v is None else v[mask]
        return Signals(notes=self.notes, **kw)


def read_text(path: Path, what: str) -> str:
    """A recording's text (gzip'd when the name ends in ``.gz``; UTF-8, a byte-order mark skipped), or a
    RecordingError naming the file and saying what it is instead of ``what`` (a MATLAB file, binary
    data, a corrupt gzip file, a folder, nothing)."""
    from hil.record.signals_csv import READ_ERRORS, open_text, read_error

    try:
        with open_text(path) as fh:
            return fh.read()
    except READ_ERRORS as exc:
        raise read_error(path, exc, what) from None


def read_signals(path: str | Path, *, allow_truncated_last_line: bool = True) -> Signals:
    """Read a signals CSV (a run folder's or one recorded elsewhere), in bounded memory
    (:mod:`hil.record.signals_csv`, which has the rules).

    Requires the columns ``t,phi1,phi2,s1,s2,F1,F2``; uses ``mode1,sp1,mode2,sp2,step``
    when present. Refuses NaN, non-numeric cells and non-increasing time with
    the line number. A last line cut short by a crash is dropped and noted. A ``.gz`` file is read
    through gzip.
    """
    from hil.record.signals_csv import read_columns

    path = Path(path)
    arrays, steps, notes = read_columns(path, "a text CSV file (columns t,phi1,phi2,s1,s2,F1,F2)",
                                        allow_truncated_last_line=allow_truncated_last_line)
    t = arrays["t"]
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0])
        raise RecordingError(
            f"{path}: line {k + 3}: time not increasing (t = {t[k + 1]} s after {t[k]} s)")
    if t.size >= 3:
        dt = np.diff(t)
        med = float(np.median(dt))
        gaps = np.flatnonzero(dt > 1.5 * med)
        del dt
        if gaps.size:
            notes.append(f"{gaps.size} gap(s) in time, first at t = {t[gaps[0]]:.4f} s")
    return Signals(
        t=t, phi1=arrays["phi1"], phi2=arrays["phi2"], s1=arrays["s1"], s2=arrays["s2"],
        F1=arrays["F1"], F2=arrays["F2"], step=steps,
        mode1=arrays.get("mode1"), sp1=arrays.get("sp1"), mode2=arrays.get("mode2"), sp2=arrays.get("sp2"),
        notes=tuple(notes))


def _data_rows_absent(path: Path) -> bool:
    """True if a signals CSV holds no complete data row (a run killed before its first flush)."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    return head.count(b"\n") < 2


def is_can_log(path: Path) -> bool:
    """A raw CAN log by its name: ``*.log`` (candump -L) or ``*.log.gz``; anything else is a signals file."""
    name = Path(path).name.lower()
    return name.endswith(".log") or name.endswith(".log.gz")



def resolve_run(arg: str | Path) -> tuple[Path, Path | None]:
    """:func:`resolve_recording`, and a run folder killed before its first data (a record, no signals yet) as
    ``(folder / "signals.csv", folder)``: its record says what happened."""
    arg = Path(arg)
    try:
        return resolve_recording(arg)
    except IncompleteRecordingError:
        if not (arg.is_dir() and has_record(arg)):
            raise
        return arg / "signals.csv", arg


def resolve_recording(arg: str | Path) -> tuple[Path, Path | None]:
    """Map a RUN_FOLDER or SIGNALS.csv argument to (signals path, run folder or None)."""
    p = Path(arg)
    if p.is_dir():
        sig = p / "signals.csv"
        log = p / "can.log"
        if not sig.exists() or (_data_rows_absent(sig) and log.exists() and log.stat().st_size > 0):
            if log.exists():
                return log, p  # the raw CAN traffic alone
            raise IncompleteRecordingError(f"{p}: run folder without signals.csv or can.log")
        return sig, p
    if not p.exists():
        raise RecordingError(f"{p}: no such file or folder")
    return p, None
