"""Reading a signals CSV in bounded memory (IO shell): the text streamed in chunks, parsed into float arrays.

A recording of 10 million rows is 711 MB of text; read whole and parsed into Python lists it took 8-13
times that. Here the (decompressed) text is never held whole: it is read in chunks of
:data:`CHUNK_LINES` lines, each parsed by :func:`numpy.loadtxt` (the same conversion as Python's
``float``: the arrays are identical) into float64 arrays preallocated from the text's size (a gzip
file's trailer says it) and the first chunk's line length, grown when needed, then shrunk in place.
The peak is the arrays plus one chunk (at most twice the arrays while one grows; measured on 10 million
rows: 561 MB of arrays, 708 MB peak for ``read_signals`` with its time checks). A chunk numpy refuses
(a cell that is not a number, a wrong number of fields, an empty line) is parsed again line by line to
name the first bad line.

Rules (docs/files.md, "Reading a recording"): UTF-8 with or without a byte-order mark; ``.gz`` read through
gzip; the header on line 1 must hold ``t,phi1,phi2,s1,s2,F1,F2`` in any order, each column once: columns are
read by their name, never by their position, and a column not known is not read (and said so in a note);
every line the header's number of
fields; every cell of those columns (and of ``mode1,sp1,mode2,sp2``) a finite number; the time strictly
increasing. A last line without its newline (a recording cut short by a crash) is dropped and noted.
Every refusal is a :class:`hil.errors.RecordingError` naming the file and the line (1-based, the header
is line 1).
"""

from __future__ import annotations

import csv
import gzip
import io
import math
import zlib
from pathlib import Path

import numpy as np

from hil.canopen.process import MEASURED_CHANNELS
from hil.errors import IncompleteRecordingError, RecordingError, UnusableRecordingError

#: the measured channels of signals.csv, in the order written (units: :data:`COLUMN_UNITS`)
SIGNAL_COLUMNS = tuple(name for name, _ in MEASURED_CHANNELS)
#: the columns a run's signals.csv holds after them: the drives' modes and set points, the check's step
EXTRA_COLUMNS = ("mode1", "sp1", "mode2", "sp2", "step")
#: column -> unit
COLUMN_UNITS = dict(MEASURED_CHANNELS)

#: lines parsed at a time (about 7 MB of text for the 7-column CSV)
CHUNK_LINES = 100_000
#: the numeric columns a signals CSV may carry, in the order the arrays are kept
NUMERIC_COLUMNS = ("t", "phi1", "phi2", "s1", "s2", "F1", "F2", "mode1", "sp1", "mode2", "sp2")
#: errors of reading and decoding a file that mean the file is not a (readable) text recording
READ_ERRORS = (OSError, EOFError, zlib.error, UnicodeDecodeError)


def open_text(path: Path):
    """``path`` as text (UTF-8, a byte-order mark skipped; ``.gz`` decompressed as it is read)."""
    if path.suffix.lower() == ".gz":
        return gzip.open(path, "rt", encoding="utf-8-sig")  # noqa: SIM115 - the caller's `with` closes it
    return open(path, encoding="utf-8-sig")  # noqa: SIM115 - likewise


def read_error(path: Path, exc: BaseException, what: str) -> RecordingError:
    """The RecordingError for an error met while reading ``path`` (it names the file and the cause)."""
    if isinstance(exc, FileNotFoundError):
        return IncompleteRecordingError(f"{path}: no such file")
    if isinstance(exc, IsADirectoryError):
        return RecordingError(f"{path}: a folder without signals.csv or can.log, not a recording")
    if isinstance(exc, UnicodeDecodeError):
        if path.suffix.lower() == ".mat":
            return RecordingError(f"{path}: a MATLAB file, not {what}; a single-axis recording such as EMPS's is "
                                  f"read by `emacheck diagnose {path.name} --model single-axis`")
        return RecordingError(f"{path}: not {what}: not UTF-8 text (binary data, or UTF-16) "
                              f"({type(exc).__name__})")
    if isinstance(exc, (gzip.BadGzipFile, zlib.error, EOFError)):
        return RecordingError(f"{path}: a corrupt or truncated gzip file, not {what} "
                              f"({type(exc).__name__}: {exc})")
    return RecordingError(f"{path}: cannot read it: {type(exc).__name__}: {exc}")


class _Columns:
    """Float64 columns preallocated for ``capacity`` rows and grown by half when full."""

    def __init__(self, names: list[str], capacity: int) -> None:
        self.names = names
        self.n = 0
        self.data = {c: np.empty(capacity) for c in names}

    def append(self, block: np.ndarray) -> None:
        m = block.shape[0]
        cap = next(iter(self.data.values())).size
        if self.n + m > cap:
            new = max(self.n + m, cap + cap // 2)
            for c in self.names:
                grown = np.empty(new)
                grown[: self.n] = self.data[c][: self.n]
                self.data[c] = grown
        for j, c in enumerate(self.names):
            self.data[c][self.n: self.n + m] = block[:, j]
        self.n += m

    def trimmed(self) -> dict[str, np.ndarray]:
        """The columns at their length (shrunk in place: nothing else refers to them)."""
        for c in self.names:
            if self.data[c].size != self.n:
                self.data[c].resize(self.n, refcheck=False)
        return self.data


def _line_errors(path: Path, lines: list[str], first_line: int, ncol: int, cols: dict[str, int]) -> None:
    """Parse ``lines`` one by one as the numbers of ``cols``; raise naming the first bad line."""

    for ln, line in enumerate(lines, start=first_line):
        cells = line.rstrip("\n").split(",")
        if len(cells) != ncol:
            raise RecordingError(f"{path}: line {ln}: {len(cells)} fields, header has {ncol}")
        for c, k in cols.items():
            cell = cells[k]
            try:
                v = float(cell)
            except ValueError:
                raise RecordingError(f"{path}: line {ln}: column '{c}': not a number: {cell!r}") from None
            if not math.isfinite(v):
                raise RecordingError(f"{path}: line {ln}: column '{c}' [{COLUMN_UNITS.get(c, '-')}] is {cell}")


def _parse_chunk(path: Path, lines: list[str], first_line: int, ncol: int, cols: dict[str, int],
                 step_col: int | None) -> tuple[np.ndarray, list[str]]:
    """One chunk of lines: the numeric columns as a (rows, len(cols)) array and the step cells."""
    steps: list[str] = []
    if step_col is not None:
        for ln, line in enumerate(lines, start=first_line):
            cells = line.rstrip("\n").split(",")
            if len(cells) != ncol:
                raise RecordingError(f"{path}: line {ln}: {len(cells)} fields, header has {ncol}")
            steps.append(cells[step_col].strip())
    # columns by their header name, in any order: usecols in the order of ``cols`` (all columns in the file's
    # own order where that is already ``cols``'s: loadtxt's faster path)
    use = None if step_col is None and list(cols.values()) == list(range(ncol)) else tuple(cols.values())
    if use is not None and step_col is None and any(ln.count(",") != ncol - 1 for ln in lines):
        _line_errors(path, lines, first_line, ncol, cols)
    try:
        with np.errstate(all="ignore"):
            block = np.loadtxt(lines, delimiter=",", comments=None, dtype=np.float64, ndmin=2, usecols=use)
    except ValueError:
        block = None
    if block is None or block.shape[0] != len(lines) or not np.isfinite(block).all():
        _line_errors(path, lines, first_line, ncol, cols)
        raise RecordingError(f"{path}: lines {first_line}-{first_line + len(lines) - 1}: "  # pragma: no cover
                             f"not readable as numbers")
    if block.shape[1] != len(cols):  # a file of fewer fields than the header (loadtxt took them as given)
        _line_errors(path, lines, first_line, ncol, cols)
    return block, steps


def _header(path: Path, first: str):
    """The header's column names; refused (exit 3) when it does not name every channel of
    :data:`SIGNAL_COLUMNS` or names one column twice."""
    header = [h.strip() for h in next(csv.reader(io.StringIO(first)))] if first.strip() else []
    missing = [c for c in SIGNAL_COLUMNS if c not in header]
    if missing:
        raise RecordingError(
            f"{path}: line 1: missing column(s) {', '.join(missing)}; expected at least "
            + ",".join(f"{c} [{COLUMN_UNITS[c]}]" for c in SIGNAL_COLUMNS) + " (in any order)")
    twice = sorted({h for h in header if h and header.count(h) > 1})
    if twice:
        raise RecordingError(f"{path}: line 1: column(s) {', '.join(twice)} named more than once; each column "
                             f"once, read by its name")
    return header


def ignored_columns(header: list[str]) -> list[str]:
    """The columns of a signals CSV's header that are not read (neither a numeric column nor ``step``)."""
    known = set(NUMERIC_COLUMNS) | {"step"}
    return [h for h in header if h not in known]


#: a gzip'd CSV's text is taken as at most this many times the file (numbers compress 3-5 times): a
#: corrupt trailer cannot make the reader allocate for gigabytes
GZIP_RATIO_MAX = 20


def _text_size(path: Path) -> int:
    """The size of ``path``'s text [bytes]: a gzip file's from its trailer (ISIZE: exact below 4 GiB, a
    lower bound above, where the arrays then grow; at most :data:`GZIP_RATIO_MAX` times the file), else
    the file's; 0 when unknown."""
    try:
        size = path.stat().st_size
        if path.suffix.lower() != ".gz":
            return size
        with open(path, "rb") as fh:
            fh.seek(max(size - 4, 0))
            return min(int.from_bytes(fh.read(4), "little"), GZIP_RATIO_MAX * size)
    except OSError:
        return 0


def _capacity(path: Path, header: str, chunk: list[str]) -> int:
    """Rows to preallocate: the text's size over the mean length of the first chunk's lines, 2 % over."""
    if not chunk:
        return 1
    per_line = sum(len(ln) for ln in chunk) / len(chunk)
    rows = (_text_size(path) - len(header)) / max(per_line, 1.0)
    return max(int(rows * 1.02) + 16, len(chunk))


def read_columns(path: Path, what: str, *, allow_truncated_last_line: bool = True):
    """The numeric columns, the step cells (or None) and the notes of the signals CSV ``path``.

    Returns ``(arrays, steps, notes)``: ``arrays`` maps each column of :data:`NUMERIC_COLUMNS` the
    header holds to its float64 array.
    """
    path = Path(path)
    try:
        with open_text(path) as fh:
            return _read(fh, path, allow_truncated_last_line)
    except READ_ERRORS as exc:
        raise read_error(path, exc, what) from None


def _read(fh, path: Path, allow_truncated_last_line: bool):
    first = fh.readline()
    if not first:
        raise IncompleteRecordingError(f"{path}: empty file")
    header = _header(path, first)
    ncol = len(header)
    cols = {c: header.index(c) for c in NUMERIC_COLUMNS if c in header}
    step_col = header.index("step") if "step" in header else None
    store: _Columns | None = None
    steps: list[str] = []
    notes: list[str] = []
    extra = ignored_columns(header)
    if extra:
        notes.append(f"column(s) {', '.join(repr(h) for h in extra)} not read (columns are read by name)")
    line_no = 2
    while True:
        chunk = [ln for _, ln in zip(range(CHUNK_LINES), fh, strict=False)]
        if not chunk:
            break
        if store is None:  # sized from the first chunk's lines
            store = _Columns(list(cols), _capacity(path, first, chunk))
        if not chunk[-1].endswith("\n"):  # the file's last line, without its newline
            if allow_truncated_last_line:
                chunk.pop()
                notes.append("last line incomplete (recording cut short), dropped")
            else:
                chunk[-1] += "\n"
        if chunk:
            block, st = _parse_chunk(path, chunk, line_no, ncol, cols, step_col)
            store.append(block)
            steps.extend(st)
            line_no += len(chunk)
    if store is None or store.n == 0:
        raise IncompleteRecordingError(f"{path}: no data rows")
    arrays = store.trimmed()
    return arrays, (np.asarray(steps) if step_col is not None else None), notes


#: the position channels of a recording and their units (the jump rule's channels)
POSITION_UNITS = {"phi1": "rad", "phi2": "rad", "s1": "mm", "s2": "mm"}
#: every measured channel a recording must not hold constant for the check (BLFmaint and diagnose)
CHECK_CHANNELS = ("phi1", "phi2", "s1", "s2", "F1", "F2")
#: ... and for BLFserv (no force sensors needed: constant forces are fine)
SERV_CHANNELS = ("phi1", "phi2", "s1", "s2")
#: the largest plausible ram speed over the hard cap no check may exceed (hil.profile.config
#: HARD_MAX_VELOCITY_MM_PER_S): a recording from elsewhere (a flight) may move faster than a check
PLAUSIBLE_SPEED_FACTOR = 2.0


def where(path: Path, index: int, t_s: float, lines: bool) -> str:
    """``path: line N`` for sample ``index`` of a CSV (the header is line 1), else its sample and time."""
    return f"{path}: line {index + 2}" if lines else f"{path}: sample {index + 1} (t = {t_s:.4f} s)"


def refuse_unusable(sig, *, channels: tuple[str, ...], min_rows: int, what: str) -> None:
    """Refuse a recording with fewer than ``min_rows`` rows (:class:`hil.errors.IncompleteRecordingError`)
    or with one of ``channels`` constant (:class:`hil.errors.UnusableRecordingError`); the message names
    the signal, the caller the file."""
    if sig.n < min_rows:
        raise IncompleteRecordingError(f"recording too short for {what}: {sig.n} samples (need >= {min_rows})")

    flat = [c for c in channels if np.ptp(getattr(sig, c)) == 0.0]
    if flat:
        c = flat[0]
        raise UnusableRecordingError(
            f"constant signal {', '.join(flat)} (all {sig.n} samples of {c} are {float(getattr(sig, c)[0]):g} "
            f"{COLUMN_UNITS[c]}): nothing moved, or the sensor is not connected; {what} needs it to change")


def part_starts(sig) -> np.ndarray:
    """The samples where a recording's step label changes (the first sample of each step after the first)."""
    if sig.step is None or sig.n < 2:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(sig.step[1:] != sig.step[:-1]) + 1


def _parts_made_apart(meta) -> bool:
    from hil.record.runrecord import RunMode

    return meta is not None and meta.mode == RunMode.SIMULATE_SCENARIO


def gap_periods_for(meta, sync_period_s: float | None) -> float:
    """The time-gap limit of :func:`blf.continuity.find_jumps` for a recording [sample periods]:
    :data:`blf.continuity.GAP_PERIODS`, or where its run record holds the stall limit the master held the
    check to (meta.json ``stalls.limit_ms``, at the SYNC period ``sync_period_s``) the gap that limit lets a
    run hold, ``limit / T + 1`` periods, if longer (50 ms at 2 ms: 26): a run the master accepted is one
    the analysis reads (docs/safety.md, *A stall of the master*)."""
    from blf.continuity import GAP_PERIODS

    st = getattr(meta, "stalls", None)
    if st is None or not sync_period_s or sync_period_s <= 0:
        return GAP_PERIODS
    return max(GAP_PERIODS, st.limit_ms / 1000.0 / sync_period_s + 1.0)


def refuse_jumps(sig, path: Path, i_total_rad_per_mm: float, *, lines: bool, meta=None,
                 sync_period_s: float | None = None) -> None:
    """Refuse a recording with a jump in time or position (:func:`blf.continuity.find_jumps`), naming
    its line (a CSV: ``lines``) or sample and time; the largest plausible speed is
    :data:`PLAUSIBLE_SPEED_FACTOR` times the ram-speed hard cap, in rad/s for the motor angles.

    ``meta``: the recording's run record (:class:`hil.record.runrecord.RunRecord`), if any. Where it declares the
    steps simulated one after the other, each from its own start (mode ``simulate-scenario``), a position
    step into the first sample of a step is not judged (:func:`part_starts`); time is judged everywhere, a gap
    against :func:`gap_periods_for` (``sync_period_s``: the actuation's SYNC period)."""
    if sig.n < 2:
        return
    from blf.continuity import NOISE_K, find_jumps
    from hil.profile.config import HARD_MAX_VELOCITY_MM_PER_S

    v_mm = PLAUSIBLE_SPEED_FACTOR * HARD_MAX_VELOCITY_MM_PER_S
    speed = {c: v_mm * (i_total_rad_per_mm if u == "rad" else 1.0) for c, u in POSITION_UNITS.items()}
    gap_periods = gap_periods_for(meta, sync_period_s)
    found = find_jumps(sig.t, {c: getattr(sig, c) for c in POSITION_UNITS}, speed, gap_periods=gap_periods,
                       part_starts=part_starts(sig) if _parts_made_apart(meta) else ())
    j = found.first
    if j is None:
        return
    at = where(path, j.index, float(sig.t[j.index]), lines)
    more = f" ({found.count} such steps in all)" if found.count > 1 else ""
    if j.kind == "time_backwards":
        raise RecordingError(f"{at}: time not increasing (t = {j.after} s after {j.before} s){more}")
    if j.kind == "time_gap":
        raise RecordingError(
            f"{at}: a jump in time: {j.after - j.before:.6g} s since the last sample (t = {j.before} s), more than "
            f"{gap_periods:g} sample periods ({j.limit:.6g} s){more}: samples missing or recordings joined; "
            f"analyse each continuous part on its own")
    unit = POSITION_UNITS[j.channel]
    raise RecordingError(
        f"{at}: a jump in position: column '{j.channel}' [{unit}] steps {j.after - j.before:+.6g} {unit} in one "
        f"sample ({j.before:.6g} -> {j.after:.6g}), more than the {j.limit:.6g} {unit} possible (twice the ram-speed "
        f"cap {HARD_MAX_VELOCITY_MM_PER_S:g} mm/s plus {NOISE_K:g} noise sigmas){more}: recordings joined, or "
        f"a sensor fault; analyse each continuous part on its own")
