"""From a recording to a diagnosis: load it, build the replay model, and the JSON of the result.

The dual-EMA model (:class:`sim.replay_model.DualEmaReplay`) gets the phases
from the recorded drive modes when the recording has them, otherwise from
the same segmentation the maintenance analysis uses
(:func:`hil.analysis.maint.find_segments`); the held force target from the
check profile (the run folder's snapshot, else the shipped one); and, when
the run folder records the simulated rig it was made with (meta.json
``simrig``), that rig as the nominal. The core is :func:`blf.diagnose.engine.diagnose` (pure).
"""

from __future__ import annotations

from pathlib import Path

from hil.errors import RecordingError


def check_for(meta, act):
    """The check profile a recording was made with (meta.json's snapshot), else the shipped one."""
    from hil.profile.config import Check
    from hil.profile.load import load_check
    from hil.profile.tables import build_dataclass
    snap = meta.profiles.check if meta is not None and meta.profiles is not None else None
    if snap is not None:
        try:
            return build_dataclass(Check, snap, "meta.json (check snapshot)")
        except ValueError:  # ProfileError: an old or foreign snapshot; the shipped check then
            pass
    return load_check(None, act)


def load_dual(path: Path, profile: Path | None):
    """The dual-EMA replay model of a run folder, signals CSV (``.csv``, ``.csv.gz``) or CAN log
    (``.log``, ``.log.gz``), and its sample period (s)."""
    from blf.errors import AnalysisError
    from hil.analysis.maint import check_units, find_segments
    from hil.record.canlog import decode_can_log
    from hil.record.recording import actuation_for
    from hil.record.runfolder import is_can_log, read_record, read_signals, resolve_recording
    from hil.record.signals_csv import CHECK_CHANNELS, refuse_jumps, refuse_unusable
    from sim.replay_model import DualEmaReplay

    sig_path, run_dir = resolve_recording(path)
    meta = read_record(run_dir)
    act = actuation_for(profile, meta)
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
    check = check_for(meta, act)
    try:
        seg = find_segments(sig, act)
    except AnalysisError:
        seg = None  # no check phases (e.g. normal operation): nothing held, only slack paths skipped
    period = sig.sample_period_s
    model = DualEmaReplay(sig.t, sig.phi1, sig.phi2, sig.s1, sig.s2, sig.F1, sig.F2,
                          act.mechanics.i_total_rad_per_mm, period, sig.mode1, sig.sp1, sig.mode2, sig.sp2,
                          segments=seg, opposing_force_N=check.calibration.opposing_force_N,
                          force_ramp_s=check.calibration.force_ramp_s,
                          nominal_rig=meta.simrig if meta is not None else None)
    return model, period


def load_model(path: Path, model: str, profile: Path | None, axis_options=None):
    """Replay model and sample period of a recording (run folder, CSV, CAN log, .mat); a single axis is
    read with ``axis_options`` (:class:`hil.analysis.diagnose.single_axis.AxisOptions`, how to read its effort)."""
    from hil.analysis.diagnose.single_axis import AxisOptions, read_axis, single_axis_model
    if not Path(path).exists():
        raise RecordingError(f"{path}: no such file or folder")
    if model == "single-axis":
        return single_axis_model(read_axis(Path(path)), axis_options or AxisOptions())
    return load_dual(Path(path), profile)
