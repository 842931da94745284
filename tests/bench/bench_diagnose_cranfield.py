"""Benchmark: ``emacheck diagnose --model single-axis --reference`` on the Cranfield actuator (issue 35).

Each development condition at +20 and +40 kgf against ``normal`` at the same load (runs 1-10), and
``normal`` runs 6-10 against runs 1-5 (two test sessions of the healthy actuator); the -40 kgf rows
are printed too, marked: the README says their current was re-levelled segment by segment.

Per row: the verdict, the effects named, the load the new recording's effort sees against the known one
(``effort`` in diagnosis.json: a recording whose effort does not see its load is ``untrusted_effort``),
the change of the friction at the running speed with its uncertainty and the floor, the change of the
direction-dependent force, the largest change of the terms along the stroke (as a force at the end of
the stroke, N), and what the raw current says (:func:`raw_friction_change`: the direction-mean current
of the steady part of each stroke, samples 40-119 and 220-299 of every cycle, against the reference's,
divided by the current per newton from the reference's half-difference and its load; no mask, no fit).

    python tests/bench/bench_diagnose_cranfield.py /tmp/cranfield.json [--repeatability]

``--repeatability`` prints how the default floor (``hil.analysis.diagnose.single_axis.FORCE_FLOOR_N``) was
measured: the changes of the force parameters (friction, direction-dependent force) of ``normal``
runs 6-10 against runs 1-5 at +20 and +40 kgf, their RMS, x 3.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from support.cranfield import CRANFIELD, DEVELOPMENT, G_N_PER_KGF, read_condition, write_single_axis  # noqa: E402

ALL_RUNS = range(1, 11)


def raw_friction_change(name: str, ref_name: str, load_kgf: float, runs=ALL_RUNS, ref_runs=ALL_RUNS) -> float:
    """What the raw current says (N): the change of its direction-mean in steady motion, over k."""
    def means(n, rr):
        d = read_condition(n)
        sel = (d["load"] == load_kgf) & np.isin(d["run"], list(rr))
        cyc = d["current"][sel].reshape(-1, 324)
        return cyc[:, 40:120].mean(), cyc[:, 220:300].mean()
    ext_r, ret_r = means(ref_name, ref_runs)
    ext, ret = means(name, runs)
    k = (ret_r - ext_r) / 2 / (load_kgf * G_N_PER_KGF)  # A per N from the reference's half-difference
    return float(((ext + ret) / 2 - (ext_r + ret_r) / 2) / k)


def diagnose_pair(folder: Path, name: str, load_kgf: float, runs, ref_runs, **opts) -> dict:
    """diagnosis.json (as a dict) of one condition against normal at the same load."""
    from hil.analysis.diagnose.axis_reference import reference_diagnosis
    from hil.analysis.diagnose.single_axis import AxisOptions
    new = write_single_axis(folder / f"{name}_{load_kgf}_{min(runs)}.csv", name, load_kgf, runs)
    ref = write_single_axis(folder / f"normal_{load_kgf}_{min(ref_runs)}-{max(ref_runs)}.csv", "normal",
                            load_kgf, ref_runs)
    return reference_diagnosis(new, ref, AxisOptions(current_law="power", **opts))


def _um(x):
    return None if x is None else 1e6 * x


def _pct(x):
    return None if x is None else 100 * x


def _row(name, load, data, raw) -> dict:
    ch = {c["parameter"]: c for c in data["changes"]}
    f, o = ch.get("friction_N", {}), ch.get("offset_N", {})
    half = data["stroke"]["half_stroke_m"]
    along = [abs(c["change"]) * (half ** 2 if c["parameter"].endswith("per_m2") else half)
             for c in data["changes"] if c["parameter"].startswith("position_dependent")]
    w = {c["parameter"]: c for c in data["witness"].get("changes", [])}
    lag, jit = w.get("tracking_lag_m", {}), w.get("tracking_jitter_ratio", {})
    return {"condition": name, "load_kgf": load, "verdict": data["verdict"],
            "named": [f"{e['name']} {e['change'][next(iter(e['change']))]:+.0f} N" for e in data["effects"]
                      if e["source"] != "witness"],
            "named_witness": [f"{e['name']} {100 * e['change'][next(iter(e['change']))]:+.1f} %"
                              for e in data["effects"] if e["source"] == "witness"],
            "witness_rule": data["witness"].get("rule"), "lag_change_um": _um(lag.get("change")),
            "lag_u_um": _um(lag.get("uncertainty")), "lag_named": lag.get("named"),
            "jitter_m": jit.get("value_m"), "jitter_reference_m": jit.get("reference_m"),
            "jitter_change_pct": _pct(jit.get("change")), "jitter_u_pct": _pct(jit.get("uncertainty")),
            "jitter_named": jit.get("named"),
            "load_check_trusted": data["effort"]["recording"]["trusted"],
            "friction_change_N": f.get("change"), "friction_u_N": f.get("uncertainty"),
            "offset_change_N": o.get("change"), "offset_u_N": o.get("uncertainty"),
            "along_stroke_change_N": max(along, default=None),
            "floor_N": data["floor"]["force_N"], "raw_current_friction_change_N": raw,
            "samples_used": data["mask"]["samples_used"], "conversion": data["conversion"],
            "effort_trusted": data["effort"]["trusted"], "load_N": data["effort"]["recording"]["load_N"],
            "effort_sees_N": data["effort"]["recording"]["seen_N"],
            "effort_sees_u_N": data["effort"]["recording"]["uncertainty_N"]}


def table(folder: Path, loads=(20, 40), conditions=DEVELOPMENT, **opts) -> list:
    """Rows of the benchmark (``normal`` is runs 6-10 against 1-5; the others all runs against normal's)."""
    rows = []
    for load in loads:
        for name in conditions:
            runs, ref_runs = (range(6, 11), range(1, 6)) if name == "normal" else (ALL_RUNS, ALL_RUNS)
            data = diagnose_pair(folder, name, load, runs, ref_runs, **opts)
            rows.append(_row(name, load, data, raw_friction_change(name, "normal", load, runs, ref_runs)))
    return rows


def repeatability(folder: Path) -> dict:
    """The session-to-session changes of the healthy actuator and the floor they give (3 x RMS)."""
    diffs = {}
    for load in (20, 40):
        d = diagnose_pair(folder, "normal", load, range(6, 11), range(1, 6))
        diffs[load] = {c["parameter"]: c["change"] for c in d["changes"] if c["parameter"].endswith("_N")}
    allv = [v for d in diffs.values() for v in d.values()]
    rms = float(np.sqrt(np.mean(np.square(allv))))
    return {"changes_N": diffs, "rms_N": rms, "floor_3rms_N": 3 * rms}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json", nargs="?", default="bench_diagnose_cranfield.json",
                    help="where to write the figures (default: bench_diagnose_cranfield.json in the current folder)")
    ap.add_argument("--repeatability", action="store_true",
                    help="also print how the default floor was measured (normal runs 6-10 against 1-5)")
    args = ap.parse_args(argv)
    out = Path(args.json)
    argv = ["--repeatability"] if args.repeatability else []
    if not (CRANFIELD / "normal.csv.gz").exists():
        print(f"Cranfield recordings not present at {CRANFIELD}")
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        result = {}
        if "--repeatability" in argv:
            rep = repeatability(Path(tmp))
            result["repeatability"] = rep
            for load, d in rep["changes_N"].items():
                changes = ", ".join(f"{k} {v:+.1f} N" for k, v in d.items())
                print(f"normal runs 6-10 against 1-5 at +{load} kgf: {changes}")
            print(f"RMS {rep['rms_N']:.1f} N; 3 x RMS = {rep['floor_3rms_N']:.1f} N")
        rows = table(Path(tmp), loads=(20, 40, -40))
    result["rows"] = rows
    print("| condition | load kgf | verdict | named | friction change N (± u) | direction-dependent change N (± u) "
          "| largest change along the stroke N | floor N | raw current says N | effort sees load N (± u) of "
          "| tracking lag change um (± u) | tracking jitter mm, change % (± u) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        mark = " (current re-levelled, README)" if r["load_kgf"] < 0 else ""
        print(f"| {r['condition']}{' 6-10 vs 1-5' if r['condition'] == 'normal' else ''} | {r['load_kgf']:+d}{mark} "
              f"| {r['verdict']} | {', '.join(r['named'] + r['named_witness']) or '-'} "
              f"| {r['friction_change_N']:+.1f} ± "
              f"{r['friction_u_N']:.1f} | {r['offset_change_N']:+.1f} ± {r['offset_u_N']:.1f} "
              f"| {r['along_stroke_change_N']:.1f} | {r['floor_N']:g} "
              f"| {r['raw_current_friction_change_N']:+.1f} | {r['effort_sees_N']:+.0f} ± {r['effort_sees_u_N']:.0f} "
              f"of {r['load_N']:+.0f}{'' if r['load_check_trusted'] else ' untrusted'} "
              f"| {r['lag_change_um']:+.1f} ± {r['lag_u_um']:.1f}{' named' if r['lag_named'] else ''} "
              f"| {1e3 * r['jitter_reference_m']:.3f} -> {1e3 * r['jitter_m']:.3f}, {r['jitter_change_pct']:+.1f} ± "
              f"{r['jitter_u_pct']:.1f}{' named' if r['jitter_named'] else ''} |")
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
