"""A run's recording sealed when its check ends, and a re-analysis that finds it changed.

When the check loop ends (done or aborted, its files closed), meta.json gets ``recording_sha256``: the
SHA-256 of signals.csv and can.log as the check left them (:func:`seal_of`). A later analysis of the run
folder (``analyze``, ``serv``, ``diagnose``) hashes the file it reads again and compares
(:func:`check_seal`): a recording changed after the check is refused (exit 3) naming the file and both
hashes, unless the user accepts it (``--accept-modified``), and then the result says so
(``trace.modified``) and its report shows it. A run folder of an older emacheck (no seal) is read as it is.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from hil.errors import RecordingError

#: the files of a run folder its seal covers
SEALED = ("signals.csv", "can.log")


#: bytes read at a time: one small buffer, reused (a real-time master has locked its memory, MCL_FUTURE: every
#: new page is faulted in at once, ~0.9 ms each inside user-mode-linux; 16 pages, once)
_CHUNK = 1 << 16


def sha256_file(path: Path) -> str | None:
    """SHA-256 of a file's bytes (hex), None if it cannot be read."""
    h = hashlib.sha256()
    buf = bytearray(_CHUNK)
    view = memoryview(buf)
    try:
        with open(path, "rb", buffering=0) as fh:
            while n := fh.readinto(buf):
                h.update(view[:n])
    except OSError:
        return None
    return h.hexdigest()


def seal_of(run_dir: Path) -> dict[str, str]:
    """{file name: SHA-256} of the run folder's recording files that exist (:data:`SEALED`)."""
    out = {}
    for name in SEALED:
        h = sha256_file(Path(run_dir) / name)
        if h is not None:
            out[name] = h
    return out


def check_seal(sig_path: Path, meta, accept_modified: bool = False) -> dict | None:
    """The recording ``sig_path`` of a run folder against the seal in its record ``meta`` (a
    :class:`hil.record.runrecord.RunRecord`, or None: a bare file, nothing to check).

    Returns None where it matches (or there is no seal), else, with ``accept_modified``, the result's
    ``trace.modified`` entry; without, a :class:`hil.errors.RecordingError` (exit 3) naming the file and both
    hashes."""
    seal = getattr(meta, "recording_sha256", None) or {}
    name = Path(sig_path).name
    if name not in seal:
        return None
    now = sha256_file(sig_path)
    if now == seal[name]:
        return None
    words = (f"{sig_path}: changed after the check (SHA-256 {seal[name][:16]}... when the check ended, now "
             f"{(now or 'unreadable')[:16]}...)")
    if not accept_modified:
        raise RecordingError(words + "; a result is made only from the recording the check left: restore it, or "
                                     "--accept-modified to analyse it anyway (the result then says so)")
    return {"file": str(sig_path), "sha256_sealed": seal[name], "sha256_now": now,
            "words": words + "; analysed as it is now, at the user's request (--accept-modified)"}
