"""Benchmark: can the re-levelled -40 kgf Cranfield current be told from an honest one? (issue 35, target 5)

The README of ../shared/data/cranfield-actuator says the -40 kgf current was re-levelled segment by
segment in preprocessing (extension, retraction and dwell means equal across all conditions), so its
force content cannot be trusted. This script prints the figures of the candidate rules tried for
flagging such a recording (the rows at +20 and +40 kgf must stay trusted, every -40 kgf row flagged),
on the steady part of each segment: extension and retraction from 40 samples (1.6 s) after the
set-point step to 4 samples before the next one, the dwell likewise (samples 40-119, 164-194 and
239-319 of every 324-sample cycle, found from the set point, not hard-coded).

a) **Pair rule** (a recording against its reference at the same load): for each segment kind the
   difference of the two recordings' mean currents ``d`` and its statistical uncertainty
   ``u = sqrt(s_1^2/n_1 + s_2^2/n_2)`` (s the standard deviation of the per-cycle segment means, n
   the number of cycles), ``z = d/u``. Independent recordings of one actuator differ by at least
   their uncertainty; levels imposed by re-levelling agree far better. Flag when all three |z| < c,
   c from ``P(|z| < c)^3 = alpha`` for independent recordings (z standard normal): alpha = 0.01
   gives c = 0.274.
b) **Under-dispersion within one recording**: per run and segment kind, the block means (10 samples,
   0.4 s, longer than the noise's correlation) of each cycle form a cycles x blocks table; a two-way
   analysis of variance gives ``F = MS_cycle / MS_residual`` with (C-1, (C-1)(J-1)) degrees of
   freedom, pooled over the runs (sums of squares added). An honest current's segment levels scatter
   from cycle to cycle at least as much as its noise predicts (F >= 1 in expectation, more with
   drift); a level imposed on every segment scatters less. One-sided p = P(F' <= F); flag when
   p < 0.001 in a segment kind.
c) **Under-dispersion between runs** (the earlier try of docs/diagnose.md, as a test): per segment
   kind, the run means of the per-cycle segment means against their scatter within the runs, a
   one-way analysis of variance, F = MS_run / MS_cycle-within-run, the two moving kinds pooled; runs
   are sessions, which drift, so an honest current has F >= 1; flag at p < 0.001.
e) **Offset steps at a fixed cycle phase, away from the motion** (the README's first tell, tried
   2026-11-27): a physical effort changes level where the motion does (a set-point step and the
   catch-up transient after it); an offset added segment by segment in processing is a step where the
   motion has no event, at the same sample of every cycle. Motion zones, from the recording itself: each
   set-point velocity change (and the cycle's start and end, where the file cuts the bottom dwell) until
   the mean position error, past its peak, is back within one sample's noise (sigma_e, the median over
   samples of the cycle-to-cycle standard deviation of the position error). At every sample k whose two
   windows [k - W, k + W) stay out of every zone, the two-sample mean shift of each cycle
   ``D = mean(x[k:k+W]) - mean(x[k-W:k])`` (W = 8 samples, 0.32 s), and ``z = mean(D) / (sd(D)/sqrt(C))``
   over the C cycles (the cycle-to-cycle scatter is the noise: it holds the sample noise, its correlation
   and the drift). Flag when max |z| > c, c the two-sided Bonferroni quantile for p = 0.001 over the
   positions tested (about 4.6).
f) **Offset steps at a fixed phase whose size varies from cycle to cycle** (per-segment offsets of
   either sign average out of e): the same D on the current minus its run's mean cycle (what recurs
   removed), ``S_k = mean(D^2)`` over the cycles against the median of S over the tested positions (the
   noise's own level); with C cycles, C S_k / median ~ chi2(C) where nothing steps; flag when the
   largest exceeds its Bonferroni quantile for p = 0.001.

    python tests/bench/bench_diagnose_cranfield_relevel.py [/tmp/relevel.json]

About 4 s on one core. Exits 2 where ../shared is absent.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from scipy import stats

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from support.cranfield import CRANFIELD, DEVELOPMENT, read_condition  # noqa: E402

CYCLE = 324  #: samples per cycle (README)
SETTLE = 40  #: samples skipped after a set-point step (1.6 s; the lag settles within about 1 s)
BEFORE = 4  #: samples left out before the next step
BLOCK = 10  #: samples per block mean in rule b
ALPHA = 0.01  #: rule a: chance that three independent |z| all fall under c
P_UNDER = 1e-3  #: rule b: one-sided p of under-dispersion that flags
KINDS = ("extension", "dwell", "retraction")
C_PAIR = float(stats.norm.ppf((1.0 + ALPHA ** (1.0 / 3.0)) / 2.0))
STEP_W = 8  #: rules e and f: samples on each side of the mean shift (0.32 s)
P_STEP = 1e-3  #: rules e and f: family-wise p over the positions tested (Bonferroni)
LATE = 25  #: rule e, printed only: flagged positions also 1 s clear of every motion zone


def windows(set_point_mm: np.ndarray) -> dict:
    """Steady sample windows of each segment kind, from the set point of one cycle."""
    v = np.diff(set_point_mm)
    steps = np.nonzero(np.abs(np.diff(v)) > 1e-6)[0] + 1  # the stop and the start of the return
    stop, start = int(steps[0]), int(steps[-1])
    return {"extension": (SETTLE, stop - BEFORE), "dwell": (stop + SETTLE, start - BEFORE),
            "retraction": (start + SETTLE, CYCLE - BEFORE)}


def runs_of(name: str, load_kgf: float, runs=range(1, 11), column: str = "current") -> tuple:
    """Per run, ``column`` (the current) as a cycles x samples array; and the windows."""
    d = read_condition(name)
    sel = (d["load"] == load_kgf) & np.isin(d["run"], list(runs))
    win = windows(d["set_point"][sel][:CYCLE])
    out = [d[column][sel & (d["run"] == r)].reshape(-1, CYCLE) for r in runs
           if (sel & (d["run"] == r)).any()]
    return out, win


def motion_zones(set_point_mm: np.ndarray, position_error_mm: np.ndarray) -> list:
    """Rules e, f: the samples [start, end) of each motion event of a cycle and its catch-up transient.

    ``set_point_mm`` and ``position_error_mm`` are cycles x samples. An event is a change of the set
    point's velocity (and the cycle's first and last sample: the file cuts the bottom dwell there); its
    zone runs until the mean position error, past its largest magnitude before the next event, is within
    sigma_e (the median over samples of the cycle-to-cycle standard deviation of the error, mm).
    """
    v = np.diff(set_point_mm[0])
    events = [0, *(int(k) for k in np.nonzero(np.abs(np.diff(v)) > 1e-6)[0] + 1)]
    e = position_error_mm.mean(0)
    sigma_e = float(np.median(position_error_mm.std(0, ddof=1)))
    zones = []
    for i, k in enumerate(events):
        nxt = events[i + 1] if i + 1 < len(events) else e.size
        peak = k + int(np.argmax(np.abs(e[k:nxt])))
        back = np.nonzero(np.abs(e[peak:nxt]) <= sigma_e)[0]
        zones.append((k, peak + int(back[0]) if back.size else nxt))
    zones.append((e.size - 1, e.size))
    return zones


def _shifts(x: np.ndarray, zones: list, w: int = STEP_W) -> tuple:
    """Rules e, f: the positions k clear of every zone and the mean shift D (cycles x positions)."""
    ks = [k for k in range(w, x.shape[1] - w + 1) if all(k + w <= a or k - w >= b for a, b in zones)]
    cs = np.concatenate([np.zeros((x.shape[0], 1)), np.cumsum(x, 1)], 1)
    return np.array(ks), np.stack([(cs[:, k + w] - 2 * cs[:, k] + cs[:, k - w]) / w for k in ks], 1)


def recurring_steps(cycles: np.ndarray, zones: list, w: int = STEP_W) -> dict:
    """Rule e: the level steps recurring at one cycle phase away from the motion (A, z, where)."""
    ks, d = _shifts(cycles, zones, w)
    m = d.mean(0)
    z = m / (d.std(0, ddof=1) / np.sqrt(d.shape[0]))
    c = float(stats.norm.ppf(1.0 - P_STEP / (2 * ks.size)))
    i = int(np.argmax(np.abs(z)))
    flagged = [int(k) for k in ks[np.abs(z) > c]]
    late = [k for k in flagged if all(k - w >= b + LATE or k + w <= a for a, b in zones)]
    return {"c": c, "positions": int(ks.size), "z_max": float(z[i]), "at": int(ks[i]), "step_A": float(m[i]),
            "largest_step_A": float(np.abs(m).max()), "flagged": flagged, "flagged_late": late}


def varying_steps(runs: list, zones: list, w: int = STEP_W) -> dict:
    """Rule f: steps at one cycle phase whose size varies between cycles (each run's mean cycle removed)."""
    resid = np.concatenate([r - r.mean(0) for r in runs])
    ks, d = _shifts(resid, zones, w)
    s = (d ** 2).mean(0)
    ratio = s / np.median(s)
    c = float(stats.chi2.ppf(1.0 - P_STEP / ks.size, d.shape[0]) / d.shape[0])
    i = int(np.argmax(ratio))
    return {"c": c, "positions": int(ks.size), "ratio_max": float(ratio[i]), "at": int(ks[i]),
            "flagged": [int(k) for k in ks[ratio > c]]}


def pair_z(new: tuple, ref: tuple) -> dict:
    """Rule a: per kind, d (A), u (A) and z of the new recording's mean segment current minus the reference's."""
    out = {}
    for k in KINDS:
        (a, b) = new[1][k]
        m1 = np.concatenate(new[0])[:, a:b].mean(1)
        m2 = np.concatenate(ref[0])[:, a:b].mean(1)
        d = m1.mean() - m2.mean()
        u = float(np.hypot(m1.std(ddof=1) / np.sqrt(m1.size), m2.std(ddof=1) / np.sqrt(m2.size)))
        out[k] = {"d_A": float(d), "u_A": u, "z": float(d / u)}
    return out


def under_dispersion(rec: tuple) -> dict:
    """Rule b: per kind, the pooled F of cycle levels against the cycle x block residual, and its lower p."""
    out = {}
    for k in KINDS:
        a, b = rec[1][k]
        j = (b - a) // BLOCK
        ss_c = ss_r = df_c = df_r = 0.0
        for cyc in rec[0]:
            x = cyc[:, a:a + j * BLOCK].reshape(cyc.shape[0], j, BLOCK).mean(2)  # cycles x blocks
            c = x.shape[0]
            if c < 2:
                continue
            row = x.mean(1, keepdims=True)
            col = x.mean(0, keepdims=True)
            ss_c += j * float(((row - x.mean()) ** 2).sum())
            ss_r += float(((x - row - col + x.mean()) ** 2).sum())
            df_c += c - 1
            df_r += (c - 1) * (j - 1)
        f = (ss_c / df_c) / (ss_r / df_r)
        out[k] = {"F": f, "df": [df_c, df_r], "p_under": float(stats.f.cdf(f, df_c, df_r))}
    return out


def run_dispersion(rec: tuple) -> dict:
    """Rule c: F of the run levels against the cycles within the runs, the moving kinds pooled, and its lower p."""
    ssb = ssw = dfb = dfw = 0.0
    for k in ("extension", "retraction"):
        a, b = rec[1][k]
        m = [c[:, a:b].mean(1) for c in rec[0]]
        g = np.concatenate(m).mean()
        ssb += sum(x.size * (x.mean() - g) ** 2 for x in m)
        ssw += sum(((x - x.mean()) ** 2).sum() for x in m)
        dfb += len(m) - 1
        dfw += sum(x.size for x in m) - len(m)
    f = (ssb / dfb) / (ssw / dfw)
    return {"F": float(f), "df": [dfb, dfw], "p_under": float(stats.f.cdf(f, dfb, dfw))}


def table() -> list:
    """One row per condition and load: rule a on the pair, rules b and c on the condition's whole file."""
    rows = []
    for load in (20.0, 40.0, -40.0):
        ref = runs_of("normal", load)
        for name in DEVELOPMENT:
            new = runs_of(name, load)
            if name == "normal":
                new, ref_row = runs_of(name, load, range(6, 11)), runs_of(name, load, range(1, 6))
                label = "normal 6-10 vs 1-5"
            else:
                ref_row, label = ref, name
            z = pair_z(new, ref_row)
            whole = runs_of(name, load)
            u = under_dispersion(whole)
            rr = run_dispersion(whole)
            zones = motion_zones(np.concatenate(runs_of(name, load, column="set_point")[0]),
                                 np.concatenate(runs_of(name, load, column="position_error")[0]))
            e = recurring_steps(np.concatenate(whole[0]), zones)
            f = varying_steps(whole[0], zones)
            rows.append({"condition": label, "load_kgf": load, "pair": z, "under": u, "runs": rr,
                         "zones": zones, "steps": e, "varying": f,
                         "flag_a": all(abs(z[k]["z"]) < C_PAIR for k in KINDS),
                         "flag_b": any(u[k]["p_under"] < P_UNDER for k in KINDS),
                         "flag_c": rr["p_under"] < P_UNDER, "flag_e": bool(e["flagged"]),
                         "flag_f": bool(f["flagged"])})
    return rows


def halves() -> dict:
    """Rules e and f on runs 1-5 and on runs 6-10 alone (the files the reference comparison diagnoses)."""
    out = {}
    for runs in (range(1, 6), range(6, 11)):
        for load in (20.0, 40.0, -40.0):
            side = out.setdefault(f"runs {runs[0]}-{runs[-1]}, {'-40' if load < 0 else '+20/+40'} kgf",
                                  {"rows": 0, "e": 0, "f": 0})
            for name in DEVELOPMENT:
                cur = runs_of(name, load, runs)[0]
                zones = motion_zones(np.concatenate(runs_of(name, load, runs, "set_point")[0]),
                                     np.concatenate(runs_of(name, load, runs, "position_error")[0]))
                side["rows"] += 1
                side["e"] += bool(recurring_steps(np.concatenate(cur), zones)["flagged"])
                side["f"] += bool(varying_steps(cur, zones)["flagged"])
    return out


def main(argv: list) -> int:
    if not (CRANFIELD / "normal.csv.gz").exists():
        print(f"Cranfield recordings not present at {CRANFIELD}", file=sys.stderr)
        return 2
    rows = table()
    print(f"rule a: flag when |z| < c = {C_PAIR:.3f} in all three kinds (alpha {ALPHA}); "
          f"rule b: flag when p_under < {P_UNDER:g} in a kind; "
          f"rule c: flag when p_under < {P_UNDER:g}\n")
    print("| condition | load kgf | z extension | z dwell | z retraction | a | F extension (p) | F dwell (p) "
          "| F retraction (p) | b | F runs (p) | c |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        zs = " | ".join(f"{r['pair'][k]['z']:+.2f}" for k in KINDS)
        fs = " | ".join(f"{r['under'][k]['F']:.2f} ({r['under'][k]['p_under']:.1g})" for k in KINDS)
        print(f"| {r['condition']} | {r['load_kgf']:+.0f} | {zs} | {'flag' if r['flag_a'] else '-'} | {fs} "
              f"| {'flag' if r['flag_b'] else '-'} | {r['runs']['F']:.2f} ({r['runs']['p_under']:.1g}) "
              f"| {'flag' if r['flag_c'] else '-'} |")
    print(f"\nrules e and f (W = {STEP_W} samples; motion zones from the set point and the position error)\n")
    print("| condition | load kgf | motion zones (samples) | positions | e: max z (at, step mA) | c | "
          "e: largest step mA | e flags at | of which 1 s clear | f: max ratio (at) | c | f |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        e, f = r["steps"], r["varying"]
        at = e["flagged"]
        where = f"{len(at)}: {at[0]}-{at[-1]}" if at else "-"
        print(f"| {r['condition']} | {r['load_kgf']:+.0f} | {' '.join(f'{a}-{b}' for a, b in r['zones'])} "
              f"| {e['positions']} | {e['z_max']:+.1f} ({e['at']}, {1000 * e['step_A']:+.0f}) | {e['c']:.2f} "
              f"| {1000 * e['largest_step_A']:.0f} | {where} | {len(e['flagged_late'])} "
              f"| {f['ratio_max']:.2f} ({f['at']}) | {f['c']:.2f} "
              f"| {'flag' if r['flag_f'] else '-'} |")
    for rule in ("a", "b", "c", "e", "f"):
        bad = sum(r[f"flag_{rule}"] for r in rows if r["load_kgf"] < 0)
        false = sum(r[f"flag_{rule}"] for r in rows if r["load_kgf"] > 0)
        print(f"\nrule {rule}: flags {bad} of 7 rows at -40 kgf, {false} of 14 at +20/+40 kgf")
    half = halves()
    print()
    for k, v in half.items():
        print(f"{k}: rule e flags {v['e']} of {v['rows']}, rule f {v['f']} of {v['rows']}")
    if len(argv) > 1:
        Path(argv[1]).write_text(json.dumps({"c_pair": C_PAIR, "alpha": ALPHA, "p_under": P_UNDER, "rows": rows,
                                             "halves": half}, indent=1))
        print(f"written {argv[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
