"""Labelled benchmark of ``emacheck diagnose`` on concealed effects (issue 6).

Not collected by pytest (no test_ functions; the file name does not match).
Usage::

    python tests/bench/bench_diagnose.py [out.json] [--jobs N] [--only NAME,...] [--dev | --first-seed N]
                                         [--sets K] [--cache DIR]

It prints one line per case, then the summary and the figures of issue 6 as
Markdown tables, and writes everything to ``out.json`` (default
``bench_diagnose.json``). ``--cache DIR`` keeps
each generated recording (keyed by case and seed) so that a second run only
diagnoses: for development, never for the reported run. ``--dev`` runs the
same cases on development seeds (20001..), for tuning; the reported run uses
:data:`FIRST_SEED` onwards, seeds never run before the method was frozen.
``--sets K`` runs K sets of the 33 cases (seeds from the first seed, + 10000,
+ 20000, ...) and reports them together (the reported run: :data:`REPORT_SETS`
sets; with ``--dev`` or ``--first-seed`` one unless given): one set's 25
effect cases move a percentage by 4 points per case.

Every case is a full simulated maintenance check (``hil.check.runner.run_check`` on
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

The recordings (base rig, effects, concealment) are made by
``tests/support/diagnose_cases.py``, which the tests of ``emacheck diagnose``
share. The diagnosis is run blind: it gets the recorded signals and nothing else.

Scores (issue 6): named effect right (name and place) in effect cases; null
cases called ``no_mismatch``; out-of-library cases called ``unexplained``;
fitted parameters within 20 % of truth; residual RMS of the most affected
channel after the fit within 1.2x its noise floor; diagnosis time per case.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (support)

from hil.record.runfolder import read_signals  # noqa: E402
from support.diagnose_cases import (  # noqa: E402
    NOISE,
    case_list,
    diagnose_signals,
    generate,
)
from support.independent_rig import judge  # noqa: E402

#: First seed of the reported run. History (each set was run once, on a method frozen before):
#: 9001.. made the first report (31 of 33 cases, 84 % of effect cases); 50001.. the second
#: (22/25 = 88 %: Stribeck at both EMAs and direction-dependent friction at EMA 2 missed). The
#: method was changed after each, on development seeds only (20001.., 20101.., 20201..), so
#: both sets count as development seeds now. 60001.. made the third report (88 %, out of library
#: 2/4: the stiffness rise at both EMAs missed); the regime test was then added and its threshold
#: set on 36 null recordings of development seeds (20001..20804); 70001.. were never run before.
#: Issue 13 (the band, the calibrated LVDTs, the hinge as nominal, friction in drive or load path,
#: viscous friction a candidate): 80001.. was run once on that method (84 %: Coulomb friction at EMA 1
#: named viscous twice), the tie rule between forms of one physics was then added; on 90001.. it took
#: Coulomb for a direction-dependent friction (run stopped after 24 cases), so it was restricted to
#: forms with as many parameters. 80001.. and 90001.. count as development seeds. 100001.. was run
#: once (21/25 = 84 % strict, 23/25 by issue 13's rules; out of library 4/4 unexplained but 2/4
#: located first at the wrong EMA); the places were then ranked by every channel's evidence, the
#: place of a physics passing at both EMAs decided by the joint fit, and the independent rig's
#: ratio stated: 100001.. counts as development seeds. 110001.. was run once (effect cases 22/25 by
#: issue 13's rules, 19/25 strict, all cases 30/33); then both LVDT pitches alike were named once
#: (transmission_ratio), so 110001.. counts as development seeds too. 120001.. was run once (22/25 by
#: issue 13's rules, 28/33); then the replay was made 4x faster and a linearised step cut by a bound
#: refitted jointly (110001.. unchanged: 22/25, 30/33), and 130001.., 140001.., 150001.. were run once
#: (21, 21, 19 of 25); the forms of one physics within 2 BIC units were then named by parsimony across
#: parameter counts (those four sets: 86/100 from 83/100), so 120001..150001 count as development
#: seeds. 160001.., 170001.., 180001.. had never been run: the report is those three sets together.
FIRST_SEED = 160001
#: sets of 33 cases in the reported run (seeds FIRST_SEED + 10000 k)
REPORT_SETS = 3
FIRST_DEV_SEED = 20001


def score_issue13(kind: str, truths: list, verdict: str, named: list, where: list) -> bool:
    """Right by issue 13's rules (:func:`support.independent_rig.judge`): extras at ``external`` and one
    other allowed beside the expected effects; out of library located at the right EMA."""
    if kind == "out_of_library":
        expect = [["unexplained", truths[0]["where"]]]
    else:
        expect = [[t["name"], t["where"]] for t in truths]
    return judge(expect, verdict, [tuple(x) for x in named], list(where))[0]


def score(case: dict, truths: list, d) -> dict:
    named = [(e.name, e.where) for e in d.effects]
    want = [(t["name"], t["where"]) for t in truths]
    out = {"verdict": d.verdict, "named": named,
           "ok_issue13": score_issue13(case["kind"], truths, d.verdict, named, list(getattr(d, "where", ())))}
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
                        if k not in e.parameters:  # a parameter the fitted form names otherwise
                            continue
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
           "partial": [],  # issue 13: effects lists every accepted effect, whatever the verdict
           "where": list(getattr(d, "where", ())),
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
        "effect_cases_right_issue13_rules": (sum(r["ok_issue13"] for r in eff), len(eff)),
        "all_cases_right_issue13_rules": (sum(r["ok_issue13"] for r in results), len(results)),
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


EMPS = TESTS.parents[1] / "shared" / "data" / "emps" / "DATA_EMPS.mat"


def run_emps() -> dict | None:
    """The single-axis diagnosis of the EMPS recording (None when ../shared is absent)."""
    if not EMPS.exists():
        return None
    from blf.diagnose.engine import diagnose
    from hil.analysis.diagnose.load import load_model
    model, period = load_model(EMPS, "single-axis", None)
    t0 = time.perf_counter()
    d = diagnose(model, period)
    secs = time.perf_counter() - t0
    return {"verdict": d.verdict, "seconds": round(secs, 2),
            "effects": [{"name": e.name, "where": e.where, "parameters": e.parameters,
                         "uncertainty": e.uncertainty} for e in d.effects],
            "band": d.band.words,
            "rms_raw_holdout_before": d.residual_rms_raw_holdout_before["force"],
            "rms_raw_holdout_after": d.residual_rms_raw_holdout_after["force"],
            "rms_before": d.residual_rms_before["force"], "rms_after": d.residual_rms_after["force"],
            "rms_holdout_before": d.residual_rms_holdout_before["force"],
            "rms_holdout_after": d.residual_rms_holdout_after["force"],
            "noise_floor": d.noise_floor["force"], "nominal": d.nominal}


def _frac(x) -> str:
    k, n = x
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else "0/0"


def _seed_blocks(results: list) -> list:
    """(first, last) seed of each run of consecutive seeds."""
    seeds = sorted(r["seed"] for r in results)
    out = [[seeds[0], seeds[0]]]
    for x in seeds[1:]:
        if x == out[-1][1] + 1:
            out[-1][1] = x
        else:
            out.append([x, x])
    return [tuple(b) for b in out]


def tables(summ: dict, results: list, emps: dict | None, argv_line: str) -> str:
    """Markdown tables of the figures of issue 6 and of every case (printed by :func:`main`)."""
    L = [f"Made by `{argv_line}` on {time.strftime('%Y-%m-%d')}; "
         f"seeds " + ", ".join(f"{a}..{b}" for a, b in _seed_blocks(results)) + ".", "",
         "| figure | target | reached |", "|---|---|---|",
         f"| effect named right (effect cases) | >= 90 % | {_frac(summ['effect_cases_named_right'])} |",
         f"| effect cases right by issue 13's rules (extras at external and one other allowed) | >= 90 % | "
         f"{_frac(summ['effect_cases_right_issue13_rules'])} |",
         f"| all cases right by issue 13's rules (out of library located at its EMA) | | "
         f"{_frac(summ['all_cases_right_issue13_rules'])} |",
         f"| - single effects | | {_frac(summ['single_effect_named_right'])} |",
         f"| - two effects | | {_frac(summ['two_effect_named_right'])} |",
         f"| null called `no_mismatch` | >= 90 % | {_frac(summ['null_called_no_mismatch'])} |",
         f"| out of library called `unexplained` | >= 80 % | {_frac(summ['out_of_library_called_unexplained'])} |",
         f"| fitted parameters within 20 % of truth (cases named right) | all | {_frac(summ['params_within_20pct'])}"
         f" (median error {100 * (summ['param_rel_err_median'] or 0):.1f} %) |",
         f"| fitted parameters within 3 of their stated uncertainties | | "
         f"{_frac(summ['params_within_3_uncertainties'])} |",
         f"| residual RMS of the affected channel <= 1.2x noise floor | all | "
         f"{_frac(summ['rms_after_within_1p2_floor'])} |",
         f"| diagnosis time per 111 s check (one core) | < 30 s | median {summ['seconds_median']:.1f} s, "
         f"max {summ['seconds_max']:.1f} s |",
         f"| largest per-sample signature / noise of any effect | < 1 | "
         f"{np.floor(summ['max_snr_any_case'] * 1e4) / 1e4:.4f} (truncated) |"]
    if emps:
        eff = "; ".join(f"`{e['name']}` " + ", ".join(f"{k} = {v:.4g} ± {e['uncertainty'][k]:.2g}"
                                                     for k, v in e["parameters"].items()) for e in emps["effects"])
        L += [f"| EMPS: named effects (verdict `{emps['verdict']}`) | a named effect | {eff or 'none'} |",
              f"| EMPS: force residual RMS on the held-out half | improves | {emps['rms_holdout_before']:.3f} N -> "
              f"{emps['rms_holdout_after']:.3f} N in the band (noise floor {emps['noise_floor']:.2f} N; "
              f"{emps['band']}); raw band {emps['rms_raw_holdout_before']:.3f} N -> "
              f"{emps['rms_raw_holdout_after']:.3f} N |",
              f"| EMPS: diagnosis time | | {emps['seconds']:.1f} s |"]
    else:
        L += ["| EMPS | | not run: ../shared/data/emps/DATA_EMPS.mat absent |"]
    L += ["", "Per case: the largest per-sample signature over noise (any raw channel), the aggregate "
          "signature chi-square in s and F, and the part of it that a re-fit of the nominal load-path "
          "parameters cannot absorb (what is left to find; the drive-force channel adds to both), "
          "then the diagnosis.", "",
          "| case | truth | max SNR | aggregate chi2 | beyond nominal refit | verdict | named | parameter error "
          "| RMS after / floor | s |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        truth = ", ".join(f"{t['name']}@{t['where']}" for t in r["truth"]) or "none"
        named = ", ".join(f"{n}@{w}" for n, w in r["named"]) or "-"
        if r["partial"]:
            named += " (partial: " + ", ".join(f"{n}@{w}" for n, w in r["partial"]) + ")"
        errs = ", ".join(f"{100 * v:.0f} %" for v in r.get("param_rel_err", {}).values()) or "-"
        ratio = f"{r['rms_after_over_floor']:.2f}" if r.get("rms_after_over_floor") is not None else "-"
        wrong = "" if r["ok"] else " **(wrong)**"
        L.append(f"| {r['id']} ({r['seed']}) | {truth} | {max(r['snr_max'].values()):.2f} "
                 f"| {r['aggregate_chi2']:.0f} | {r['orthogonal_chi2']:.0f} | {r['verdict']}{wrong} | {named} | "
                 f"{errs} | {ratio} | {r['seconds']} |")
    L += [""]
    return "\n".join(L)


def main(argv: list[str]) -> int:
    out = Path(next((a for a in argv if a.endswith(".json")), "bench_diagnose.json"))
    jobs = int(argv[argv.index("--jobs") + 1]) if "--jobs" in argv else 1
    if "--help" in argv or "-h" in argv:
        print(__doc__)
        return 0
    if "--readme" in argv:
        raise SystemExit("--readme is gone: the benchmark prints its tables and writes its JSON, "
                         "it no longer rewrites the README")
    first = int(argv[argv.index("--first-seed") + 1]) if "--first-seed" in argv else None
    first = first or (FIRST_DEV_SEED if "--dev" in argv else FIRST_SEED)
    sets = int(argv[argv.index("--sets") + 1]) if "--sets" in argv else (1 if "--dev" in argv or "--first-seed" in argv
                                                                          else REPORT_SETS)
    cases = [c for k in range(sets) for c in case_list(first + 10000 * k)]
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
    print(tables(summ, results, emps, "python tests/bench/bench_diagnose.py " + " ".join(argv)))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
