"""Labelled benchmark of ``emacheck diagnose`` on concealed effects (issue 6).

Not collected by pytest (no test_ functions; the file name does not match).
Usage::

    python tests/bench_diagnose.py [out.json] [--jobs N] [--only NAME,...] [--dev | --first-seed N]
                                   [--cache DIR] [--readme README.md]

``--readme`` rewrites the table between the ``bench_diagnose`` markers of the
README (the figures there come from this one command). ``--cache DIR`` keeps
each generated recording (keyed by case and seed) so that a second run only
diagnoses: for development, never for the reported run. ``--dev`` runs the
same cases on development seeds (20001..), for tuning; the reported run uses
:data:`FIRST_SEED` onwards, seeds never run before the method was frozen.

Every case is a full simulated maintenance check (``hil.runner.run_check`` on
``sim.plant.RigPlant``, ~111 s, 55 758 samples) of a base rig with ideal
sensors (LVDT pitch 1, no offset or non-linearity) and one, two or no
switchable physics terms on. Magnitudes are drawn from the case's own
generator and then *concealed*: the recording's drive setpoints are replayed
open loop through the rig with and without the effect (same noise seed, so
the noise cancels) and the per-sample signature ``|with - without|`` must
stay below the noise in every raw channel (s1, s2: LVDT noise sigma; F1, F2:
load-cell noise sigma; phi1, phi2: the motor angle before quantisation must
move by less than one resolver quantum, the resolution of that channel),
outside the first 1 s after a drive-mode change: there a drive entering FORCE
mode flies freely across its backlash and hits the far flank, and any
friction shifts that impact by a sample or two (a signature of tens of
noise sigmas in those few samples that no physical magnitude avoids). The SNR
including those samples is reported too (``snr_max_incl_mode_transients``).
A magnitude that breaks this is scaled by 0.7 until it holds, then bisected
back up to within ~5 % of the largest concealed size (each effect of a
two-effect case on its own first, then both together), and the final SNR is
asserted. The binding channel is nearly always the motor angle: its quantum
is 0.3 um of ram travel, so friction effects end at about 1 N against a
load-cell noise of 10 N.

The diagnosis is run blind: it gets the recorded signals and nothing else.

Scores (issue 6): named effect right (name and place) in effect cases; null
cases called ``no_mismatch``; out-of-library cases called ``unexplained``;
fitted parameters within 20 % of truth; residual RMS of the most affected
channel after the fit within 1.2x its noise floor; diagnosis time per case.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hil.profiles import load_actuation, load_check, load_simrig  # noqa: E402
from hil.runfolder import read_signals  # noqa: E402
from hil.runner import PlantLink, run_check, start_meta  # noqa: E402
from sim import effects as fx  # noqa: E402
from sim.plant import RigPlant  # noqa: E402

I_TOTAL = 5.026548245743669


def base_params():
    """Default simulated rig with ideal LVDTs and a drive loss that damps the torque-mode ringing.

    The default rig's EMA in FORCE mode rings at 7.9 Hz with 2 % damping
    (+-500 N after each force ramp); any friction damps that ringing and is
    then far from concealed in those samples. The base rig of the benchmark
    therefore has a motor viscous loss of 3e-3 N m s/rad (damping ratio ~0.3).
    """
    sr = load_simrig(None).params
    ideal = dict(lvdt_gain=1.0, lvdt_offset_mm=0.0, lvdt_nonlinearity_mm=0.0)
    return dataclasses.replace(sr, sensors1=dataclasses.replace(sr.sensors1, **ideal),
                               sensors2=dataclasses.replace(sr.sensors2, **ideal),
                               drive=dataclasses.replace(sr.drive, motor_viscous_Nm_s_per_rad=3e-3))


def short_check():
    """A shorter check (~40 s: 8 mm sweeps at 4 mm/s, one force-fight cycle) for the default tests."""
    act = load_actuation(None)
    c = load_check(None, act)
    return dataclasses.replace(
        c, calibration=dataclasses.replace(c.calibration, sweep_amplitude_mm=8.0, sweep_speed_mm_per_s=4.0),
        force_fight=dataclasses.replace(c.force_fight, cycles=1))


def record(params, seed: int, out: Path, check=None):
    act = load_actuation(None)
    check = check or load_check(None, act)
    run_check(PlantLink(RigPlant(params, np.random.default_rng(seed))), act, check, out,
              start_meta(act, check, {"seed": seed}))
    return read_signals(out / "signals.csv")


# ---------------------------------------------------------------- effects: (apply to params, truth dict)

def _sensor(p, where, **kw):
    name = "sensors1" if where == "ema1" else "sensors2"
    return dataclasses.replace(p, **{name: dataclasses.replace(getattr(p, name), **kw)})


def _mech(p, where, **kw):
    return dataclasses.replace(p, **{where: dataclasses.replace(getattr(p, where), **kw)})


def make_effect(kind: str, where: str, scale: float, rng: np.random.Generator):
    """(function params -> params, truth {param: value}) for an effect of size ``scale`` x the draw."""
    u = lambda a, b: float(rng.uniform(a, b)) * scale  # noqa: E731
    if kind == "coulomb_friction":
        f = u(5.0, 9.0)
        return (lambda p: _add(p, fx.CoulombFriction(where, f))), {"force_N": f}
    if kind == "viscous_friction":
        c = u(2.0, 4.0)
        return (lambda p: _add(p, fx.ViscousFriction(where, c))), {"coeff_N_s_per_mm": c}
    if kind == "stribeck_friction":
        f, vs = u(6.0, 9.0), float(rng.uniform(2.0, 4.0))
        return (lambda p: _add(p, fx.StribeckFriction(where, f, vs))), {"extra_force_N": f,
                                                                         "stribeck_velocity_mm_per_s": vs}
    if kind == "asymmetric_friction":
        fp, fm = u(6.0, 9.0), u(2.0, 3.0)
        return (lambda p: _add(p, fx.AsymmetricFriction(where, fp, fm))), {"force_extend_N": fp,
                                                                           "force_retract_N": fm}
    if kind == "viscoelastic":
        kv, tau = u(3000.0, 6000.0), float(rng.uniform(0.5, 2.0))
        return (lambda p: _add(p, fx.Viscoelastic(where, kv, tau))), {"stiffness_N_per_mm": kv,
                                                                      "time_constant_s": tau}
    if kind == "stiffness_asymmetry":
        d = u(0.03, 0.06)
        return (lambda p: _mech(p, where, stiffness_tension_N_per_mm=getattr(p, where).stiffness_compression_N_per_mm
                                * (1.0 + d))), {"tension_over_compression_minus_1": d}
    if kind == "lvdt_pitch":
        g = u(1.2e-4, 2.0e-4) * float(rng.choice([-1, 1]))
        return (lambda p: _sensor(p, where, lvdt_gain=1.0 + g)), {"gain_error": g}
    if kind == "lvdt_offset":
        o = u(2.0e-3, 3.5e-3) * float(rng.choice([-1, 1]))
        return (lambda p: _sensor(p, where, lvdt_offset_mm=o)), {"offset_mm": o}
    if kind == "lvdt_nonlinearity":
        n3 = u(4e-3, 6e-3) * float(rng.choice([-1, 1]))
        return (lambda p: _sensor(p, where, lvdt_nonlinearity_mm=n3)), {"nonlinearity_mm": n3}
    if kind == "lvdt_drift":
        d = u(1.0e-6, 1.8e-6) * float(rng.choice([-1, 1]))
        return (lambda p: _add(p, fx.LvdtDrift(where, d))), {"gain_drift_per_s": d}
    if kind == "time_skew":
        d = u(0.6e-3, 1.0e-3)
        return (lambda p: _add(p, fx.TimeSkew(where, d))), {"delay_s": d}
    if kind == "loadcell_gain":
        g = u(8e-4, 1.4e-3) * float(rng.choice([-1, 1]))
        return (lambda p: _sensor(p, where, loadcell_gain=1.0 + g)), {"gain_error": g}
    # out of library
    if kind == "lead_error":
        a = u(2.0e-3, 3.0e-3)
        return (lambda p: _add(p, fx.LeadError(where, a, 5.0))), {"amplitude_mm": a}
    if kind == "stiffness_bump":
        r, c, w = u(0.4, 0.8), float(rng.uniform(-8.0, 8.0)), float(rng.uniform(4.0, 10.0))
        return (lambda p: _add(p, fx.StiffnessBump(where, r, c, w))), {"relative_increase": r, "center_mm": c,
                                                                          "width_mm": w}
    raise ValueError(kind)


def _add(p, eff):
    return dataclasses.replace(p, effects=p.effects + (eff,))


#: viscous_friction is not a separate candidate of the dual-EMA replay (the drive's own viscous
#: loss is a nominal parameter and the two are indistinguishable), so it has no case here.
LIBRARY = ("coulomb_friction", "stribeck_friction", "asymmetric_friction", "viscoelastic",
           "stiffness_asymmetry", "lvdt_pitch", "lvdt_offset", "lvdt_nonlinearity", "lvdt_drift",
           "time_skew", "loadcell_gain")
OUT_OF_LIBRARY = ("lead_error", "stiffness_bump")


#: First seed of the reported run. History (each set was run once, on a method frozen before):
#: 9001.. made the first report (31 of 33 cases, 84 % of effect cases); 50001.. the second
#: (22/25 = 88 %: Stribeck at both EMAs and direction-dependent friction at EMA 2 missed). The
#: method was changed after each, on development seeds only (20001.., 20101.., 20201..), so
#: both sets count as development seeds now. 60001.. made the third report (88 %, out of library
#: 2/4: the stiffness rise at both EMAs missed); the regime test was then added and its threshold
#: set on 36 null recordings of development seeds (20001..20804); 70001.. were never run before.
FIRST_SEED = 70001
FIRST_DEV_SEED = 20001


def case_list(first_seed: int = FIRST_SEED) -> list[dict]:
    """The >= 30 labelled cases on consecutive seeds from ``first_seed``."""
    cases = []
    seed = first_seed
    for k in range(4):
        cases.append({"id": f"null-{k}", "kind": "null", "effects": [], "seed": seed}); seed += 1
    for kind in LIBRARY:
        for where in ("ema1", "ema2"):
            cases.append({"id": f"{kind}-{where}", "kind": "single", "effects": [(kind, where)], "seed": seed})
            seed += 1
    for pair in ((("coulomb_friction", "ema1"), ("lvdt_pitch", "ema2")),
                 (("loadcell_gain", "ema1"), ("lvdt_offset", "ema2")),
                 (("stiffness_asymmetry", "ema2"), ("lvdt_nonlinearity", "ema1"))):
        cases.append({"id": "+".join(f"{k}-{w}" for k, w in pair), "kind": "two", "effects": list(pair),
                      "seed": seed}); seed += 1
    for kind in OUT_OF_LIBRARY:
        for where in ("ema1", "ema2"):
            cases.append({"id": f"{kind}-{where}", "kind": "out_of_library", "effects": [(kind, where)],
                          "seed": seed}); seed += 1
    return cases


NOISE = {"s1": 0.025 / 6, "s2": 0.025 / 6, "F1": 10.0, "F2": 10.0,
         "phi1": 2 * np.pi / 4096, "phi2": 2 * np.pi / 4096}


def twin(params, seed: int, sig):
    """The recording's drive setpoints replayed open loop through ``params`` with the same noise seed.

    Row 0 of a run folder is the plant's first step with both drives disabled;
    row k (k >= 1) is the step with the setpoints computed from row k - 1.
    Returns the measured channels and, as ``phi1_true``/``phi2_true``, the
    motor angles before the resolver's quantisation.
    """
    def prev(x):
        return np.r_[0.0, np.asarray(x, dtype=float)[:-1]]
    tr = RigPlant(params, np.random.default_rng(seed)).run(
        prev(sig.mode1).astype(int), prev(sig.sp1), prev(sig.mode2).astype(int), prev(sig.sp2))
    return {"s1": tr.s1_mm, "s2": tr.s2_mm, "F1": tr.F1_N, "F2": tr.F2_N, "phi1": tr.phi1_rad, "phi2": tr.phi2_rad,
            "phi1_true": tr.true_phi_rad[:, 0], "phi2_true": tr.true_phi_rad[:, 1]}


def transient_mask(sig, after_s: float = 1.0) -> np.ndarray:
    """True within ``after_s`` after a drive-mode change (the free flight of a drive entering
    FORCE mode across its backlash and the impact that ends it)."""
    ch = np.zeros(sig.n, bool)
    ch[1:] = (np.diff(sig.mode1) != 0) | (np.diff(sig.mode2) != 0)
    k = int(round(after_s / 0.002))
    return np.convolve(ch, np.ones(k), mode="full")[: sig.n] > 0


def snr(with_effect: dict, without: dict, mask: np.ndarray | None = None) -> dict:
    """Max per-sample |signature| / noise per raw channel, outside ``mask``.

    The signature is the difference between the two open-loop twins (same
    setpoints, same noise seed, so the noise cancels): s and F as measured,
    over their noise sigma; the motor angles before quantisation, over one
    resolver quantum (the resolution of a quantised channel: a change below
    it shows at most as single-quantum flips of the recorded angle, which
    the recording without the effect shows too).
    """
    n = without["s1"].size
    keep = np.ones(n, bool) if mask is None else ~mask
    out = {c: float(np.max(np.abs(with_effect[c] - without[c])[keep])) / NOISE[c] for c in ("s1", "s2", "F1", "F2")}
    for c in ("phi1", "phi2"):
        out[c] = float(np.max(np.abs(with_effect[c + "_true"] - without[c + "_true"])[keep])) / NOISE[c]
    return out


def aggregate_chi2(with_effect: dict, without: dict, mask: np.ndarray) -> float:
    """Sum over the recording (outside ``mask``) of (signature / noise)^2 in s and F: what a
    perfect model could gain by aggregating; below ~30 no method can find the effect."""
    return float(sum(np.sum(((with_effect[c] - without[c])[~mask] / NOISE[c]) ** 2)
                     for c in ("s1", "s2", "F1", "F2")))


def orthogonal_chi2(with_effect: dict, without: dict, sig, mask: np.ndarray) -> float:
    """The part of :func:`aggregate_chi2` that no re-fit of the replay's nominal parameters can
    absorb: the weighted signature in s and F with its projection on the nominal Jacobian (at the
    base rig, by finite differences of the replay of ``sig``'s motor angles) removed."""
    from sim.replay import DualEmaReplay
    base = base_params()
    m = DualEmaReplay(sig.t, sig.phi1, sig.phi2, sig.s1, sig.s2, sig.F1, sig.F2, I_TOTAL, 0.002,
                      sig.mode1, sig.sp1, sig.mode2, sig.sp2)
    th = []
    for e in (base.ema1, base.ema2):
        th += [e.backlash_int_mm, e.stiffness_compression_N_per_mm, e.bearing_backlash_mm,
               1.0 / e.bearing_stiffness_N_per_mm + 1.0 / e.housing_stiffness_N_per_mm]
    th = np.array(th + [q.x0 for q in m.nominal[8:]])
    chans = ("s1", "s2", "F1", "F2")
    keep = ~mask

    def vec(pred):
        return np.concatenate([pred[c][keep] / NOISE[c] for c in chans])
    p0 = vec(m.predict(th, []))
    cols = []
    for j in range(8):  # the chain parameters (M and c act on Fd only)
        t2 = th.copy()
        t2[j] *= 1.0 + 1e-3
        cols.append((vec(m.predict(t2, [])) - p0) / (t2[j] - th[j]))
    J = np.stack(cols, axis=1)
    d = np.concatenate([(with_effect[c] - without[c])[keep] / NOISE[c] for c in chans])
    coef, *_ = np.linalg.lstsq(J, d, rcond=None)
    r = d - J @ coef
    return float(r @ r)


def concealed(s: dict) -> bool:
    """Below the noise sigma in s and F, below one quantum in the motor angles."""
    return all(v < 1.0 for v in s.values())


def generate(case: dict, work: Path, check=None):
    """Recording of a case with concealed magnitudes; returns (signals, truths, snr, snr incl. transients).

    The drawn magnitudes are scaled by 0.7 until the signature is concealed
    (at most 25 times), then the scale is bisected (geometrically, 3 times)
    between the last scale that showed and the first that was concealed, so
    the effect ends within ~5 % of the largest concealed size: the hardest
    honest case, not an arbitrarily small one. The search runs on the open-
    loop twins of a recording without the effect (cheap); the case is then
    recorded closed loop at the scale found and checked again on the twins
    of its own setpoints (scaled by 0.9 and recorded again until it holds).
    """
    base = base_params()

    def params(scales):
        rng = np.random.default_rng(case["seed"])
        p, truths = base, []
        for (kind, where), sc in zip(case["effects"], scales):
            apply, truth = make_effect(kind, where, sc, rng)  # draws even when off: same draws
            if sc > 0:
                p = apply(p)
            truths.append({"name": kind, "where": where, "parameters": truth})
        return p, truths

    def signature(scales, sig):
        tw = (twin(params(scales)[0], case["seed"], sig), twin(base, case["seed"], sig))
        return tw, snr(*tw, transient_mask(sig))

    if not case["effects"]:
        sig = record(base, case["seed"], work / "rec", check)
        s = {c: 0.0 for c in NOISE}
        return sig, [], s, dict(s, aggregate_chi2=0.0, orthogonal_chi2=0.0)

    probe = record(base, case["seed"], work / "probe", check)

    def conceal(scales, k):
        """Largest scale of effect k (others fixed) whose signature stays concealed."""
        def ok(x):
            return concealed(signature(scales[:k] + [x] + scales[k + 1:], probe)[1])
        x, shown = scales[k], None
        for _ in range(25):
            if ok(x):
                break
            shown, x = x, x * 0.7
        assert ok(x), (case["id"], x)
        if shown is not None:
            lo, hi = x, shown
            for _ in range(3):
                mid = float(np.sqrt(lo * hi))
                lo, hi = (mid, hi) if ok(mid) else (lo, mid)
            x = lo
        return x

    # each effect on its own first (so one cannot shrink the other), then together
    scales = []
    for k in range(len(case["effects"])):
        single = [0.0] * len(case["effects"])
        single[k] = 1.0
        scales.append(conceal(single, k))
    while not concealed(signature(scales, probe)[1]):
        scales = [x * 0.85 for x in scales]
    for _ in range(20):
        p, truths = params(scales)
        sig = record(p, case["seed"], work / "rec", check)
        tw, s = signature(scales, sig)
        if concealed(s):
            break
        scales = [x * 0.9 for x in scales]
    assert concealed(s), (case["id"], s)
    s_all = snr(*tw)
    s_all["aggregate_chi2"] = aggregate_chi2(*tw, transient_mask(sig))
    s_all["orthogonal_chi2"] = orthogonal_chi2(*tw, sig, transient_mask(sig))
    return sig, truths, s, s_all


def diagnose_signals(sig):
    from blf.diagnose import diagnose
    from sim.replay import DualEmaReplay
    m = DualEmaReplay(sig.t, sig.phi1, sig.phi2, sig.s1, sig.s2, sig.F1, sig.F2, I_TOTAL, 0.002,
                      sig.mode1, sig.sp1, sig.mode2, sig.sp2)
    return diagnose(m, 0.002)


def score(case: dict, truths: list, d) -> dict:
    named = [(e.name, e.where) for e in d.effects]
    want = [(t["name"], t["where"]) for t in truths]
    out = {"verdict": d.verdict, "named": named}
    if case["kind"] == "null":
        out["ok"] = d.verdict == "no_mismatch"
    elif case["kind"] == "out_of_library":
        out["ok"] = d.verdict == "unexplained"
        out["located"] = bool(d.locations)
    else:
        out["ok"] = d.verdict == "explained" and sorted(named) == sorted(want)
        errs, zs = {}, {}
        for t in truths:
            for e in d.effects:
                if (e.name, e.where) == (t["name"], t["where"]):
                    for k, v in t["parameters"].items():
                        errs[f"{t['name']}.{k}"] = abs(e.parameters[k] - v) / abs(v)
                        zs[f"{t['name']}.{k}"] = abs(e.parameters[k] - v) / max(e.uncertainty[k], 1e-300)
        out["param_rel_err"] = errs
        out["param_err_over_uncertainty"] = zs
        ch = max(d.excess_before, key=lambda c: d.excess_before[c])
        out["affected_channel"] = ch
        out["rms_after_over_floor"] = d.residual_rms_after[ch] / d.noise_floor[ch]
    return out


def _generate_cached(case: dict, cache: Path | None):
    """:func:`generate`, or its earlier result from ``cache`` (signals CSV + JSON, keyed by id and seed)."""
    if cache is not None:
        stem = cache / f"{case['seed']}-{case['id']}"
        if stem.with_suffix(".json").exists():
            meta = json.loads(stem.with_suffix(".json").read_text())
            return read_signals(stem.with_suffix(".csv")), meta["truths"], meta["snr"], meta["snr_all"]
    with tempfile.TemporaryDirectory() as tmp:
        sig, truths, s, s_all = generate(case, Path(tmp))
        if cache is not None:
            cache.mkdir(parents=True, exist_ok=True)
            shutil.copy(Path(tmp) / "rec" / "signals.csv", stem.with_suffix(".csv"))
            stem.with_suffix(".json").write_text(json.dumps({"truths": truths, "snr": s, "snr_all": s_all}))
    return sig, truths, s, s_all


def run_case(case: dict, cache: Path | None = None) -> dict:
    sig, truths, s, s_all = _generate_cached(case, cache)
    t0 = time.perf_counter()
    d = diagnose_signals(sig)
    secs = time.perf_counter() - t0
    res = {"id": case["id"], "kind": case["kind"], "seed": case["seed"], "truth": truths,
           "snr_max": dict(s),  # full precision: the figure is compared with 1
           "snr_max_incl_mode_transients": {k: round(v, 3) for k, v in s_all.items() if k in NOISE},
           "aggregate_chi2": round(s_all["aggregate_chi2"], 1),
           "orthogonal_chi2": round(s_all["orthogonal_chi2"], 1),
           "seconds": round(secs, 1),
           "effects": [{"name": e.name, "where": e.where, "parameters": e.parameters,
                        "uncertainty": e.uncertainty} for e in d.effects],
           "partial": [(e.name, e.where) for e in d.partial_effects],
           "excess_before": {k: round(v, 2) for k, v in d.excess_before.items()},
           "excess_after": {k: round(v, 2) for k, v in d.excess_after.items()},
           "regime_before": {k: round(v, 2) for k, v in d.regime_before.items()},
           "regime_after": {k: round(v, 2) for k, v in d.regime_after.items()}}
    res.update(score(case, truths, d))
    print(f"{case['id']:<48} {res['verdict']:<12} {'ok' if res['ok'] else 'WRONG':<6} {secs:5.1f} s "
          f"named {res['named']} partial {res['partial']}", flush=True)
    return res


def summary(results: list) -> dict:
    def frac(rs):
        return (sum(r["ok"] for r in rs), len(rs))
    eff = [r for r in results if r["kind"] in ("single", "two")]
    errs = [v for r in eff if r["ok"] for v in r["param_rel_err"].values()]
    rms = [r["rms_after_over_floor"] for r in eff if r["ok"]]
    return {
        "effect_cases_named_right": frac(eff),
        "single_effect_named_right": frac([r for r in results if r["kind"] == "single"]),
        "two_effect_named_right": frac([r for r in results if r["kind"] == "two"]),
        "null_called_no_mismatch": frac([r for r in results if r["kind"] == "null"]),
        "out_of_library_called_unexplained": frac([r for r in results if r["kind"] == "out_of_library"]),
        "params_within_20pct": (sum(e <= 0.2 for e in errs), len(errs)),
        "params_within_3_uncertainties": (sum(z <= 3.0 for r in eff if r["ok"]
                                               for z in r["param_err_over_uncertainty"].values()), len(errs)),
        "param_rel_err_median": float(np.median(errs)) if errs else None,
        "rms_after_within_1p2_floor": (sum(x <= 1.2 for x in rms), len(rms)),
        "seconds_median": float(np.median([r["seconds"] for r in results])),
        "seconds_max": float(np.max([r["seconds"] for r in results])),
        "max_snr_any_case": max((max(r["snr_max"].values()) for r in results if r["truth"]), default=0.0),
    }


EMPS = Path(__file__).resolve().parents[2] / "shared" / "data" / "emps" / "DATA_EMPS.mat"


def run_emps() -> dict | None:
    """The single-axis diagnosis of the EMPS recording (None when ../shared is absent)."""
    if not EMPS.exists():
        return None
    from blf.diagnose import diagnose
    from hil.analysis.diagnose import load_model
    model, period = load_model(EMPS, "single-axis", None)
    t0 = time.perf_counter()
    d = diagnose(model, period)
    secs = time.perf_counter() - t0
    return {"verdict": d.verdict, "seconds": round(secs, 2),
            "effects": [{"name": e.name, "where": e.where, "parameters": e.parameters,
                         "uncertainty": e.uncertainty} for e in d.effects + d.partial_effects],
            "rms_before": d.residual_rms_before["force"], "rms_after": d.residual_rms_after["force"],
            "rms_holdout_before": d.residual_rms_holdout_before["force"],
            "rms_holdout_after": d.residual_rms_holdout_after["force"],
            "noise_floor": d.noise_floor["force"], "nominal": d.nominal}


BEGIN, END = "<!-- bench_diagnose:begin -->", "<!-- bench_diagnose:end -->"


def _frac(x) -> str:
    k, n = x
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else "0/0"


def readme_block(summ: dict, results: list, emps: dict | None, argv_line: str) -> str:
    """Markdown of the figures of issue 6 (the README's table, between the markers)."""
    L = [BEGIN, "", f"Made by `{argv_line}` on {time.strftime('%Y-%m-%d')}; "
         f"seeds {min(r['seed'] for r in results)}..{max(r['seed'] for r in results)}.", "",
         "| figure | target | reached |", "|---|---|---|",
         f"| effect named right (effect cases) | >= 90 % | {_frac(summ['effect_cases_named_right'])} |",
         f"| - single effects | | {_frac(summ['single_effect_named_right'])} |",
         f"| - two effects | | {_frac(summ['two_effect_named_right'])} |",
         f"| null called `no_mismatch` | >= 90 % | {_frac(summ['null_called_no_mismatch'])} |",
         f"| out of library called `unexplained` | >= 80 % | {_frac(summ['out_of_library_called_unexplained'])} |",
         f"| fitted parameters within 20 % of truth (cases named right) | all | {_frac(summ['params_within_20pct'])}"
         f" (median error {100 * (summ['param_rel_err_median'] or 0):.1f} %) |",
         f"| fitted parameters within 3 of their stated uncertainties | | {_frac(summ['params_within_3_uncertainties'])} |",
         f"| residual RMS of the affected channel <= 1.2x noise floor | all | {_frac(summ['rms_after_within_1p2_floor'])} |",
         f"| diagnosis time per 111 s check (one core) | < 30 s | median {summ['seconds_median']:.1f} s, "
         f"max {summ['seconds_max']:.1f} s |",
         f"| largest per-sample signature / noise of any effect | < 1 | {np.floor(summ['max_snr_any_case'] * 1e4) / 1e4:.4f} (truncated) |"]
    if emps:
        eff = "; ".join(f"`{e['name']}` " + ", ".join(f"{k} = {v:.4g} ± {e['uncertainty'][k]:.2g}"
                                                     for k, v in e["parameters"].items()) for e in emps["effects"])
        L += [f"| EMPS: named effects (verdict `{emps['verdict']}`) | a named effect | {eff or 'none'} |",
              f"| EMPS: force residual RMS on the held-out half | improves | {emps['rms_holdout_before']:.3f} N -> "
              f"{emps['rms_holdout_after']:.3f} N (noise floor {emps['noise_floor']:.2f} N) |",
              f"| EMPS: diagnosis time | | {emps['seconds']:.1f} s |"]
    else:
        L += ["| EMPS | | not run: ../shared/data/emps/DATA_EMPS.mat absent |"]
    L += ["", "Per case: the largest per-sample signature over noise (any raw channel), the aggregate "
          "signature chi-square in s and F, and the part of it that a re-fit of the nominal load-path "
          "parameters cannot absorb (what is left to find; the drive-force channel adds to both), "
          "then the diagnosis.", "",
          "| case | truth | max SNR | aggregate chi2 | beyond nominal refit | verdict | named | parameter error | RMS after / floor | s |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        truth = ", ".join(f"{t['name']}@{t['where']}" for t in r["truth"]) or "none"
        named = ", ".join(f"{n}@{w}" for n, w in r["named"]) or "-"
        if r["partial"]:
            named += " (partial: " + ", ".join(f"{n}@{w}" for n, w in r["partial"]) + ")"
        errs = ", ".join(f"{100 * v:.0f} %" for v in r.get("param_rel_err", {}).values()) or "-"
        ratio = f"{r['rms_after_over_floor']:.2f}" if r.get("rms_after_over_floor") is not None else "-"
        L.append(f"| {r['id']} | {truth} | {max(r['snr_max'].values()):.2f} | {r['aggregate_chi2']:.0f} | {r['orthogonal_chi2']:.0f} | {r['verdict']}{'' if r['ok'] else ' **(wrong)**'} | {named} | "
                 f"{errs} | {ratio} | {r['seconds']} |")
    L += ["", END]
    return "\n".join(L)


def write_readme(path: Path, block: str) -> None:
    text = path.read_text()
    if BEGIN not in text or END not in text:
        raise SystemExit(f"{path}: markers {BEGIN} / {END} not found")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    path.write_text(head + block + tail)


def main(argv: list[str]) -> int:
    out = Path(next((a for a in argv if a.endswith(".json")), "bench_diagnose.json"))
    jobs = int(argv[argv.index("--jobs") + 1]) if "--jobs" in argv else 1
    first = int(argv[argv.index("--first-seed") + 1]) if "--first-seed" in argv else None
    cases = case_list(first or (FIRST_DEV_SEED if "--dev" in argv else FIRST_SEED))
    cache = Path(argv[argv.index("--cache") + 1]) if "--cache" in argv else None
    if "--only" in argv:
        keep = argv[argv.index("--only") + 1].split(",")
        cases = [c for c in cases if any(k in c["id"] for k in keep)]
    print(f"{len(cases)} cases, {jobs} job(s)", flush=True)
    if jobs > 1:
        from multiprocessing import Pool
        with Pool(jobs) as pool:
            results = pool.starmap(run_case, [(c, cache) for c in cases], chunksize=1)
    else:
        results = [run_case(c, cache) for c in cases]
    summ = summary(results)
    emps = run_emps()
    print(json.dumps(summ, indent=1))
    out.write_text(json.dumps({"summary": summ, "cases": results, "emps": emps}, indent=1, default=str))
    print(f"wrote {out}")
    if "--readme" in argv:
        readme = Path(argv[argv.index("--readme") + 1])
        write_readme(readme, readme_block(summ, results, emps, "python tests/bench_diagnose.py " + " ".join(argv)))
        print(f"updated the table in {readme}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
