"""A dual-EMA recording loaded for the diagnosis: read once, with the profiles it was made with, into its
replay model (:class:`DualRecording`).

The dual-EMA model (:class:`sim.replay_model.DualEmaReplay`) gets the phases
from the recorded drive modes when the recording has them, otherwise from
the same segmentation the maintenance analysis uses
(:func:`hil.analysis.maint.find_segments`); the held force target from the
check profile (the run folder's snapshot, else the shipped one); and, when
the run folder records the simulated rig it was made with (meta.json
``simrig``), that rig as the nominal. The core is :func:`blf.diagnose.engine.diagnose` (pure).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from hil.errors import RecordingError
from hil.profile.config import Actuation, Check
from hil.record.runrecord import RunRecord


@dataclass(frozen=True)
class DualRecording:
    """A dual-EMA recording read for the diagnosis (:func:`load_dual`): its replay model and sample period, and
    what it was read with: the actuation profile (``--profile``, else the run folder's snapshot, else the
    shipped one), the check profile (the snapshot, else the shipped one), its run record and run folder (None
    for a bare file)."""

    path: Path  #: as given
    model: object  #: :class:`sim.replay_model.DualEmaReplay`
    period_s: float
    act: Actuation
    check: Check
    meta: RunRecord | None
    run_dir: Path | None
    notes: tuple = ()  #: what was noted while reading it (columns not read, a last line dropped ...)
    modified: dict | None = None  #: changed after its check, read at the user's request (hil.record.seal)


def load_dual(path: Path, profile: Path | None, accept_modified: bool = False) -> DualRecording:
    """A run folder, signals CSV (``.csv``, ``.csv.gz``) or CAN log (``.log``, ``.log.gz``) read into its
    dual-EMA replay model; refused (:class:`hil.errors.RecordingError`) when it cannot be diagnosed, or when
    a run folder's recording changed after its check unless ``accept_modified`` (:mod:`hil.record.seal`)."""
    from blf.errors import AnalysisError
    from hil.analysis.maint import check_units, find_segments, refuse_implausible
    from hil.record.canlog import decode_can_log
    from hil.record.recording import recording_source
    from hil.record.runfolder import is_can_log, read_signals
    from hil.record.seal import check_seal
    from hil.record.signals_csv import CHECK_CHANNELS, refuse_jumps, refuse_unusable
    from sim.replay_model import DualEmaReplay

    src = recording_source(path, profile)
    sig_path, run_dir, meta, act, check = src.signals_path, src.run_dir, src.meta, src.act, src.check
    modified = check_seal(sig_path, meta, accept_modified)
    sig = decode_can_log(sig_path, act).signals if is_can_log(sig_path) else read_signals(sig_path)
    if sig.n < 1000:
        raise RecordingError(f"{sig_path}: recording too short to diagnose: {sig.n} samples (need >= 1000)")
    try:
        refuse_unusable(sig, channels=CHECK_CHANNELS, min_rows=1000, what="the diagnosis")
    except RecordingError as exc:
        raise RecordingError(f"{sig_path}: {exc}") from None
    refuse_jumps(sig, sig_path, act.mechanics.i_total_rad_per_mm, lines=not is_can_log(sig_path), meta=meta,
                 sync_period_s=act.timing.sync_period_s)
    check_units(sig, act)
    try:
        seg = find_segments(sig, act)
    except AnalysisError:
        seg = None  # no check phases (e.g. normal operation): nothing held, only slack paths skipped
    try:
        refuse_implausible(sig, act, seg, check.force_fight.amplitude_fraction_of_limit if meta is not None
                           else None)
    except RecordingError as exc:
        raise RecordingError(f"{sig_path}: {exc}") from None
    period = sig.sample_period_s
    model = DualEmaReplay(sig.t, sig.phi1, sig.phi2, sig.s1, sig.s2, sig.F1, sig.F2,
                          act.mechanics.i_total_rad_per_mm, period, sig.mode1, sig.sp1, sig.mode2, sig.sp2,
                          segments=seg, opposing_force_N=check.calibration.opposing_force_N,
                          force_ramp_s=check.calibration.force_ramp_s,
                          nominal_rig=meta.simrig if meta is not None else None)
    return DualRecording(Path(path), model, period, act, check, meta, run_dir,
                         ((modified["words"],) if modified else ()) + tuple(f"{Path(sig_path).name}: {n}"
                                                                             for n in sig.notes), modified)


def load_model(path: Path, model: str, profile: Path | None, axis_options=None):
    """Replay model and sample period of a recording (run folder, CSV, CAN log, .mat); a single axis is
    read with ``axis_options`` (:class:`hil.analysis.diagnose.single_axis.AxisOptions`, how to read its effort)."""
    from hil.analysis.diagnose.single_axis import AxisOptions, read_axis, single_axis_model
    if not Path(path).exists():
        raise RecordingError(f"{path}: no such file or folder")
    if model == "single-axis":
        return single_axis_model(read_axis(Path(path)), axis_options or AxisOptions())
    rec = load_dual(Path(path), profile)
    return rec.model, rec.period_s
