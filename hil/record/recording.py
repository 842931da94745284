"""A recording loaded for an analysis: where it is and what it was made with (:func:`recording_source`: its
run folder, run record and profiles), its signals (a signals CSV, or a CAN log decoded with the run's step
times), refused when unusable, and the actuation profile it is analysed with.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hil.profile.config import Actuation, Check
from hil.profile.load import actuation_of_recording, profiles_from
from hil.record.runfolder import is_can_log, read_record, read_signals, resolve_recording
from hil.record.runrecord import RunRecord


@dataclass(frozen=True)
class RecordingSource:
    """Where a recording is and what it was made with (:func:`recording_source`)."""

    signals_path: Path  #: signals.csv, a bare signals CSV or a CAN log
    run_dir: Path | None  #: its run folder (None for a bare file)
    meta: RunRecord | None  #: the run folder's record (None without one)
    act: Actuation  #: ``--profile``, else the run's snapshot, else the shipped one
    check: Check  #: the run's snapshot, else the shipped one


def recording_source(path: Path, profile: Path | None) -> RecordingSource:
    """A run folder, signals CSV or CAN log argument resolved (:func:`hil.record.runfolder.resolve_recording`),
    its run record read and the profiles it is analysed with loaded, in one step."""
    sig_path, run_dir = resolve_recording(path)
    meta = read_record(run_dir)
    snaps = meta.profiles if meta is not None else None
    act, check = profiles_from(profile, snaps.actuation if snaps is not None else None,
                               snaps.check if snaps is not None else None)
    return RecordingSource(sig_path, run_dir, meta, act, check)


def load_recording(sig_path: Path, act: Actuation, meta: RunRecord | None, *,
                   channels: tuple[str, ...] = (), min_rows: int = 2, what: str = "the analysis",
                   jumps: bool = True):
    """Signals from a CSV, or decoded from a raw CAN log (``*.log``, ``*.log.gz``), step labels from
    the run record's step times. Refused with a jump in time or position (a RecordingError naming the
    file and the line or sample), with fewer than ``min_rows`` rows or a constant signal among
    ``channels`` (an IncompleteRecordingError naming the signal; :mod:`hil.record.signals_csv`). ``jumps``
    False: not checked for jumps (a run that aborted: the sensor fault that stopped it may be one)."""
    from hil.record.signals_csv import refuse_jumps, refuse_unusable

    sig = read_signals(sig_path) if not is_can_log(sig_path) else _decoded(sig_path, act, meta)
    refuse_unusable(sig, channels=channels, min_rows=min_rows, what=what)
    if jumps:
        refuse_jumps(sig, sig_path, act.mechanics.i_total_rad_per_mm, lines=not is_can_log(sig_path), meta=meta,
                     sync_period_s=act.timing.sync_period_s)
    return sig


def _decoded(sig_path: Path, act: Actuation, meta: RunRecord | None):
    import dataclasses

    import numpy as np

    from hil.record.canlog import decode_can_log

    dec = decode_can_log(sig_path, act, meta)
    sig = dec.signals
    steps = meta.steps if meta is not None else None
    if steps:
        label = np.full(sig.n, "", dtype=object)
        for s in steps:
            t1 = s.t_end_s if s.t_end_s is not None else np.inf
            label[(sig.t >= s.t_start_s - 1e-9) & (sig.t < t1 - 1e-9)] = s.name
        sig = dataclasses.replace(sig, step=label.astype(str),
                                  notes=sig.notes + ("step labels from meta.json step times",))
    return sig


def actuation_for(profile: Path | None, meta: RunRecord | None) -> Actuation:
    """The actuation to analyse a recording with: ``--profile`` if given, else the run folder's
    snapshot (what the run used), else the shipped profile."""
    return actuation_of_recording(profile, meta.profiles.actuation if meta is not None and meta.profiles is not None
                                  else None)
