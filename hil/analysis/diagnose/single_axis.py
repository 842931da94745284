"""A single-axis recording as real drives record it, and its diagnosis against a reference recording.

The CSV layout (``emacheck diagnose FILE.csv --model single-axis``): ``t,q,q_ref`` (s, m, m), one
effort column, ``force`` (N), ``torque`` (N m, with ``--screw-lead-m``) or ``current`` (A, with
``--current-law`` and ``--current-per-force`` or a reference with a known load), and optionally
``load`` (N, a known external force on the axis, positive along +q). A ``.mat`` file holds the EMPS
keys ``t, qm, qg, vir, gtau`` (force ``gtau * vir``).

Here: the recording read and validated (:func:`read_axis`), how its effort becomes a force
(:func:`conversion`, :func:`axis_force`), the recording prepared for a fit (:func:`prepare`), its replay
model without a reference (:func:`single_axis_model`) and its effort against its known load
(:func:`model_effort_check`). Against a reference recording: :mod:`hil.analysis.diagnose.axis_reference`.
"""

from __future__ import annotations

import dataclasses
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hil.analysis.diagnose.results import rounded
from hil.errors import RecordingError

#: default relevance floor of a force parameter (friction, offset), N: 3 x the RMS of the
#: session-to-session changes of the healthy Cranfield actuator (``normal`` runs 1-5 against 6-10 at
#: +20 and +40 kgf: friction +15.8 and -43.2 N, offset -8.7 and +8.4 N; RMS 23.8 N, x 3 = 71.3 N),
#: rounded up to 75 N (docs/diagnose.md, "Floors"; tests/bench/bench_diagnose_cranfield.py --repeatability)
FORCE_FLOOR_N = 75.0
#: default relevance floor of a periodic force's amplitude change, N: 3 x the RMS of the changes per
#: direction of the healthy Cranfield actuator's ripple (``normal`` runs 6-10 against 1-5 and odd against
#: even runs at +20 and +40 kgf: 8 changes, RMS 2.62 N, x 3 = 7.85 N), rounded up to 8 N: a repeatability
#: (docs/diagnose.md, "Forces periodic in position"; tests/bench/bench_diagnose_cranfield_periodic.py)
PERIODIC_FLOOR_N = 8.0
EFFORTS = ("force", "torque", "current")


@dataclass(frozen=True)
class AxisRecording:
    """One single-axis recording: columns in SI, the effort's kind, the sample rate."""

    path: Path
    t: np.ndarray
    q: np.ndarray
    q_ref: np.ndarray
    effort: np.ndarray
    kind: str  #: force, torque or current
    load: np.ndarray | None
    sample_rate_hz: float
    notes: tuple = ()  #: what was noted while reading it (columns not read)


@dataclass(frozen=True)
class AxisOptions:
    """How to read the effort and when a change is named."""

    current_law: str | None = None
    current_a_per_N: float | None = None
    screw_lead_m: float | None = None
    force_floor_N: float = FORCE_FLOOR_N
    z_min: float = 3.0
    periodic_floor_N: float | None = PERIODIC_FLOOR_N  #: None: forces periodic in position not sought
    gear_ratio: float | None = None  #: motor turns per screw turn (with screw_lead_m: the part's order)
    #: the stated tolerance of the position sensor's scale (fraction) in the order's check; 0: exact
    position_scale_tolerance: float = 0.0


def read_axis(path: Path) -> AxisRecording:
    """A single-axis recording (CSV or EMPS ``.mat``), validated; :class:`RecordingError` names what is wrong."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    if path.suffix.lower() == ".mat":
        return _read_mat(path)
    from hil.record.runfolder import read_text
    text = read_text(path, "a text CSV file (columns t,q,q_ref and force, torque or current)")
    if not text.strip():
        raise RecordingError(f"{path}: empty file; need columns t,q,q_ref (s, m, m) and force, torque or current")
    header = [h.strip() for h in text.lstrip("\ufeff").splitlines()[0].split(",")]
    twice = sorted({h for h in header if h and header.count(h) > 1})
    if twice:
        raise RecordingError(f"{path}: line 1: column(s) {', '.join(twice)} named more than once; each column "
                             f"once, read by its name")
    try:
        arr = np.genfromtxt(io.StringIO(text), delimiter=",", names=True)
    except (ValueError, IndexError, TypeError) as exc:
        raise RecordingError(f"{path}: not a readable CSV ({type(exc).__name__}: {exc})") from None
    names = arr.dtype.names or ()
    efforts = [c for c in EFFORTS if c in names]
    unread = [h for h in header if h not in ("t", "q", "q_ref", "load", *EFFORTS)]
    if any(c not in names for c in ("t", "q", "q_ref")) or len(efforts) != 1:
        raise RecordingError(f"{path}: line 1: need columns t,q,q_ref (s, m, m) and exactly one of force (N), "
                             f"torque (N m), current (A), optionally load (N); got {','.join(names) or 'none'}")
    cols = {c: np.atleast_1d(np.asarray(arr[c], dtype=float)) for c in ("t", "q", "q_ref", efforts[0])
            + (("load",) if "load" in names else ())}
    if not all(np.all(np.isfinite(x)) for x in cols.values()) or np.any(np.diff(cols["t"]) <= 0):
        raise RecordingError(f"{path}: NaN, empty cells or non-increasing time")
    rec = _recording(path, cols["t"], cols["q"], cols["q_ref"], cols[efforts[0]], efforts[0], cols.get("load"))
    if unread:
        rec = dataclasses.replace(rec, notes=(f"{path.name}: column(s) {', '.join(repr(h) for h in unread)} not "
                                              f"read (columns are read by name)",))
    return rec


def _read_mat(path: Path) -> AxisRecording:
    import struct
    import zlib

    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError
    try:
        d = loadmat(path)
    except (OSError, ValueError, EOFError, zlib.error, struct.error, TypeError, IndexError, KeyError,
            NotImplementedError, MatReadError) as exc:  # a corrupt or truncated file, whatever scipy met
        raise RecordingError(f"{path}: not a readable .mat file ({type(exc).__name__}: {exc})") from None
    missing = [k for k in ("t", "qm", "qg", "vir", "gtau") if k not in d]
    if missing:
        raise RecordingError(f"{path}: missing key(s) {', '.join(missing)}; expected t, qm, qg, vir, gtau")
    try:
        t = np.asarray(d["t"], dtype=float).ravel()
        force = float(np.ravel(d["gtau"])[0]) * np.asarray(d["vir"], dtype=float).ravel()
        q, qref = np.asarray(d["qm"], dtype=float).ravel(), np.asarray(d["qg"], dtype=float).ravel()
    except (TypeError, ValueError, IndexError) as exc:
        raise RecordingError(f"{path}: t, qm, qg, vir, gtau must be numeric arrays ({exc})") from None
    if not t.size == q.size == qref.size == force.size:
        raise RecordingError(f"{path}: t, qm, qg and vir must be equally long arrays "
                             f"(got {t.size}, {q.size}, {qref.size}, {force.size})")
    if not all(np.all(np.isfinite(x)) for x in (t, q, qref, force)) or np.any(np.diff(t) <= 0):
        raise RecordingError(f"{path}: NaN or non-increasing time in t, qm, qg, vir")
    return _recording(path, t, q, qref, force, "force", None)


def _recording(path, t, q, q_ref, effort, kind, load) -> AxisRecording:
    if t.size < 200:
        raise RecordingError(f"{path}: {t.size} samples: too short (need >= 200)")
    dt = np.diff(t)
    period = float(np.median(dt))
    if np.max(np.abs(dt - period)) > 0.01 * period:
        raise RecordingError(f"{path}: the sample period varies by more than 1 % (median {period:.6g} s)")
    return AxisRecording(path, t, q, q_ref, effort, kind, load, 1.0 / period)


def _direction(rec: AxisRecording, moving: np.ndarray) -> np.ndarray:
    vr = np.gradient(rec.q_ref, rec.t)
    return np.where(moving, np.sign(vr), 0.0)


def _mask(rec: AxisRecording, opts: AxisOptions, *, reference_mode: bool = False):
    """Dwells masked with a supply current (the holding current), and in the reference mode with any effort
    (standing still, the friction force is anywhere in its static band: the linear model's sign(v) is not
    defined there); catch-ups masked with a current."""
    from blf.diagnose import effort_mask
    power = rec.kind == "current" and opts.current_law == "power"
    return effort_mask(rec.t, rec.q, rec.q_ref, rec.sample_rate_hz, dwell_says_nothing=power or reference_mode,
                       mask_transients=rec.kind == "current")


def conversion(rec: AxisRecording, opts: AxisOptions, reference: AxisRecording | None = None) -> tuple:
    """(A per N or None, words, relative standard uncertainty of the gain): how the effort becomes a force;
    :class:`RecordingError` where it cannot (a stated gain or a force, torque: uncertainty 0)."""
    from blf.diagnose import identify_current_per_force
    from blf.errors import AnalysisError
    if rec.kind == "force":
        return None, "force column (N) as recorded", 0.0
    if rec.kind == "torque":
        if opts.screw_lead_m is None:
            raise RecordingError(f"{rec.path}: a torque (N m) needs the screw lead (--screw-lead-m) to become a force")
        return None, f"torque x 2 pi / lead ({opts.screw_lead_m:g} m per revolution)", 0.0
    if opts.current_law is None:
        raise RecordingError(f"{rec.path}: a current (A) with no way to convert it: state --current-law (torque: "
                             "a phase current that follows the torque; power: a supply current that follows "
                             "mechanical power)")
    if opts.current_a_per_N is not None:
        return opts.current_a_per_N, f"{opts.current_law} law, k = {opts.current_a_per_N:g} A/N (stated)", 0.0
    src = reference
    if src is None or src.load is None:
        raise RecordingError(f"{rec.path}: a current (A) with no way to convert it: state --current-per-force, or "
                             "give a --reference with a known load (a load column in N)")
    m = _mask(src, opts, reference_mode=True)
    try:
        gain = identify_current_per_force(src.effort, src.load, _direction(src, m.moving), m.used, opts.current_law)
    except AnalysisError as exc:
        raise RecordingError(f"{src.path}: {exc}") from None
    return (gain.a_per_N, gain.words + f" (identified on the reference {src.path.name})",
            gain.uncertainty_a_per_N / gain.a_per_N)


def axis_force(rec: AxisRecording, opts: AxisOptions, k: float | None, moving: np.ndarray) -> np.ndarray:
    """The drive's force along +q (N) from the recorded effort."""
    from blf.diagnose import effort_to_force
    return effort_to_force(rec.effort, rec.kind, v_dir=_direction(rec, moving), lead_m=opts.screw_lead_m,
                           current_law=opts.current_law, current_a_per_N=k)


def _accel_noise(q: np.ndarray, fs: float) -> float:
    from scipy.signal import savgol_coeffs
    sq = float(np.sqrt(np.mean(np.diff(q, 2) ** 2) / 6))
    w = max(7, int(round(0.4 * fs)) | 1)
    return sq * float(np.linalg.norm(savgol_coeffs(w, 3, deriv=2, delta=1 / fs)))


def prepare(rec: AxisRecording, opts: AxisOptions, k: float | None):
    """The recording ready for a fit (:class:`blf.diagnose.axis_compare.AxisSamples`): its force (N),
    Savitzky-Golay speed and acceleration, the effort mask and what the samples kept can separate."""
    from blf.diagnose import AxisSamples, axis_kinematics, identifiability
    m = _mask(rec, opts, reference_mode=True)
    v, a = axis_kinematics(rec.q, rec.sample_rate_hz)
    vr = np.gradient(rec.q_ref, rec.t)
    ident = identifiability(v, a, vr, m.used, _accel_noise(rec.q, rec.sample_rate_hz))
    return AxisSamples(str(rec.path), rec.q, axis_force(rec, opts, k, m.moving), v, a, m, ident, rec.load)


def model_effort_check(rec: AxisRecording, opts: AxisOptions) -> dict | None:
    """Without a reference: diagnosis.json's ``effort`` of a single-axis recording (:func:`read_axis`) with a
    known load (the nominal model fitted on it alone, :func:`blf.diagnose.axis_effort.effort_load_check`); None
    without a load."""
    from blf.diagnose import effort_load_check, fit_axis
    from blf.errors import AnalysisError
    if rec.load is None:
        return None
    k, _, rel = conversion(rec, opts)
    p = prepare(rec, opts, k)
    try:
        fit = fit_axis(p.force_N, p.v_m_per_s, p.a_m_per_s2, p.mask.used, p.ident, rec.load)
    except AnalysisError as exc:
        return {"trusted": True, "words": f"the effort could not be checked against the load ({exc})"}
    c = effort_load_check(fit, rec.load, p.mask.used, opts.force_floor_N, opts.z_min, rel)
    entry = {"path": str(rec.path), "checked": c.made, "trusted": c.trusted, "load_N": rounded(c.load_N),
             "seen_N": rounded(c.seen_N), "uncertainty_N": rounded(c.uncertainty_N), "words": c.words}
    return {"trusted": not (c.made and not c.trusted), "words": c.words, "recording": entry}


def single_axis_model(rec: AxisRecording, opts: AxisOptions):
    """The replay model of :func:`blf.diagnose.engine.diagnose` (no reference) and its sample period (s), of a
    single-axis recording (:func:`read_axis`).

    A current needs its conversion stated (law and gain); the masked samples are not compared."""
    from sim.single_axis import SingleAxisReplay
    k, _, _ = conversion(rec, opts)
    m = _mask(rec, opts)
    force = axis_force(rec, opts, k, m.moving)
    if rec.load is not None:
        force = force + rec.load
    model = SingleAxisReplay(rec.t, rec.q, rec.q_ref, force, 1.0 / rec.sample_rate_hz, valid=m.used)
    model.effort_mask = m
    return model, 1.0 / rec.sample_rate_hz




def axis_model(path: Path, opts: AxisOptions) -> tuple:
    """A single-axis recording read once and made ready for the diagnosis against the simulation: (the
    recording; its effort against its known load, :func:`model_effort_check`, or None; the replay model and its
    sample period, :func:`single_axis_model`, or None, None where the effort does not see its load)."""
    rec = read_axis(path)
    effort = model_effort_check(rec, opts)
    if effort is not None and not effort["trusted"]:
        return rec, effort, None, None
    model, period = single_axis_model(rec, opts)
    return rec, effort, model, period


def _check_pair(new: AxisRecording, ref: AxisRecording) -> None:
    if new.kind != ref.kind or (new.load is None) != (ref.load is None):
        what = lambda r: r.kind + (",load" if r.load is not None else "")  # noqa: E731
        raise RecordingError(f"{ref.path}: reference with other columns ({what(ref)}) than {new.path} ({what(new)})")
    if abs(new.sample_rate_hz / ref.sample_rate_hz - 1) > 0.01:
        raise RecordingError(f"{ref.path}: reference sampled at {ref.sample_rate_hz:.6g} Hz, {new.path} at "
                             f"{new.sample_rate_hz:.6g} Hz: not comparable")


@dataclass(frozen=True)
class AxisPair:
    """A single-axis recording and its reference, read, checked alike (columns, sample rate) and prepared with
    one effort conversion (:func:`prepared_pair`)."""

    new: AxisRecording
    ref: AxisRecording
    current_a_per_N: float | None  #: the conversion's gain (None: a force or torque)
    conversion_words: str
    gain_rel_u: float  #: relative standard uncertainty of the gain
    prepared_new: object  #: :class:`blf.diagnose.axis_compare.AxisSamples`
    prepared_ref: object


def prepared_pair(new_path: Path, ref_path: Path, opts: AxisOptions) -> AxisPair:
    """Both recordings of ``emacheck diagnose NEW --model single-axis --reference HEALTHY`` read, checked alike
    and prepared for their fits; :class:`RecordingError` (exit 3) names what does not fit."""
    new = read_axis(new_path)
    try:
        ref = read_axis(ref_path)
    except RecordingError as exc:
        raise RecordingError(f"--reference: {exc} (a single-axis recording is needed)") from None
    _check_pair(new, ref)
    k, words, rel_u = conversion(new, opts, ref)
    return AxisPair(new, ref, k, words, rel_u, prepare(new, opts, k), prepare(ref, opts, k))
