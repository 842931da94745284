"""A check's record on a disk that can fill: how much it needs, checked before anything moves, and space kept
for its end.

How much (:func:`record_bytes`): the longest a check may run (the runner's own limit, 3 x its planned
duration + 60 s: a check that has not finished by then is aborted) at one row of signals.csv and every
frame of the cycle in can.log per SYNC period, plus the end of the record (:data:`END_BYTES`). The sizes
per row and per frame are measured on the shipped dry-run (111.5 s, 55 756 rows, 395 420 frames):
signals.csv 5.5 MB, 99 bytes a row (12 columns); can.log 17 MB, 43 bytes a frame (candump ``-L``: stamp,
channel, id, up to 8 data bytes); both rounded up by a fifth for longer numbers (a real clock's stamps,
larger values). The check's ``frames_per_cycle`` comes from its bus-load plan
(:class:`hil.canopen.busload.BusLoad`: SYNC, every PDO, the heartbeats per cycle).

Space for the end (:class:`EndReserve`): a file of :data:`END_BYTES` allocated when the check starts and
removed when it ends, or at once when a write fails for lack of space, so that the drives' safe stop can
still be recorded: meta.json ``aborted`` and why, result.json and the report (the shipped dry-run's: 24 kB,
12 kB, 848 kB; 4 MiB keeps five times that).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from pathlib import Path

from hil.errors import OutputError

#: bytes a row of signals.csv takes at most (99 measured, a fifth more)
SIGNALS_BYTES_PER_ROW = 120
#: bytes a frame of can.log takes at most (43 measured, a fifth more)
CANLOG_BYTES_PER_FRAME = 52
#: the record's end: meta.json, result.json, report.html (five times the shipped dry-run's 0.9 MB)
END_BYTES = 4 * 1024 * 1024
#: the name of the file that keeps :data:`END_BYTES` for the end
RESERVE_NAME = ".emacheck-end-reserve"


def record_bytes(duration_s: float, sync_period_s: float, frames_per_cycle: float) -> int:
    """Bytes a check's record needs at most: ``duration_s`` of signals.csv rows and can.log frames at one
    cycle per ``sync_period_s``, plus :data:`END_BYTES`."""
    cycles = duration_s / sync_period_s
    return int(cycles * (SIGNALS_BYTES_PER_ROW + frames_per_cycle * CANLOG_BYTES_PER_FRAME)) + END_BYTES


def free_bytes(folder: Path) -> int:
    """Bytes free for this user on the file system of ``folder``."""
    return shutil.disk_usage(folder).free


def check_free_space(folder: Path, needed: int, why: str) -> None:
    """Refuse (:class:`hil.errors.OutputError`, exit 3) a record that would not fit: ``needed`` bytes
    (``why`` says how that was reckoned) where fewer are free."""
    free = free_bytes(folder)
    if free < needed:
        raise OutputError(f"{folder}: {free / 1e6:.1f} MB free, the check's record needs up to {needed / 1e6:.1f} MB "
                          f"({why}); free some space or give --out a folder on another disk")


class EndReserve:
    """:data:`END_BYTES` kept in the run folder for the record's end (see the module docstring)."""

    def __init__(self, folder: Path, size: int = END_BYTES) -> None:
        self.path = Path(folder) / RESERVE_NAME
        self.kept = False
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except OSError:
            return
        try:
            try:
                os.posix_fallocate(fd, 0, size)
            except (AttributeError, OSError):  # a file system without fallocate: written out
                os.write(fd, bytes(size))
            self.kept = True
        except OSError:
            pass
        finally:
            os.close(fd)
        if not self.kept:
            self.release()

    def release(self) -> None:
        """Give the space back (idempotent; never raises)."""
        with contextlib.suppress(OSError):
            self.path.unlink()
        self.kept = False
