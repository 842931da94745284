"""Benchmark: forces periodic in position on the Cranfield actuator (issue 48), ``emacheck diagnose NEW
--model single-axis --reference NORMAL --current-law power`` (with the screw's 5 mm lead stated).

Each development condition at +20, +40 and -40 kgf against ``normal`` at the same load (runs 1-10), and
``normal`` against ``normal`` in two splits per load (runs 6-10 against 1-5; odd against even runs). Per
row: the verdict, the effects named, and per periodic component its period in the recording and the
reference, the amplitude per direction (reference -> recording, change ± u), whether named, where along
the travel, and the held-out residual RMS without and with the periodic terms; the CPU time of the pair.

    python tests/bench/bench_diagnose_cranfield_periodic.py /tmp/periodic.json [--floor] [--scale-tolerance S]

Per row also the tracking error's witness rule and jitter change (the merged rule: docs/diagnose.md, "The
second witness") and, per component, the position's scale that makes the nearest order of the lead whole.

``--floor`` prints how the default floor (``hil.analysis.diagnose.single_axis.PERIODIC_FLOOR_N``) was
measured: the amplitude changes per direction of the two ``normal`` splits at +20 and +40 kgf, their RMS, x 3.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from bench.bench_diagnose_cranfield import ALL_RUNS, diagnose_pair  # noqa: E402
from support.cranfield import CRANFIELD, DEVELOPMENT  # noqa: E402

SPLITS = {"6-10 vs 1-5": (range(6, 11), range(1, 6)), "odd vs even": ((1, 3, 5, 7, 9), (2, 4, 6, 8, 10))}
LEAD_M = 0.005  #: the README's screw lead (RM1605: 5 mm)


def pairs(loads=(20, 40, -40), conditions=DEVELOPMENT):
    """(condition label, name, load, runs, reference runs) of the benchmark."""
    for load in loads:
        for name in conditions:
            if name == "normal":
                for split, (runs, ref) in SPLITS.items():
                    yield f"normal {split}", name, load, runs, ref
            else:
                yield name, name, load, ALL_RUNS, ALL_RUNS


def row(folder: Path, label, name, load, runs, ref_runs, scale_tolerance: float = 0.0) -> dict:
    t0 = time.process_time()
    d = diagnose_pair(folder, name, load, runs, ref_runs, screw_lead_m=LEAD_M,
                      position_scale_tolerance=scale_tolerance)
    cpu = time.process_time() - t0
    per, wit = d.get("periodic", {}), d.get("witness", {})
    jit = next((c for c in wit.get("changes", []) if c["parameter"] == "tracking_jitter_ratio"), None)
    return {"condition": label, "load_kgf": load, "verdict": d["verdict"], "cpu_s": cpu,
            "rule": wit.get("rule", "-"), "jitter_change": None if jit is None else jit["change"],
            "jitter_u": None if jit is None else jit["uncertainty"], "jitter_named": bool(jit and jit["named"]),
            "named": [e["name"] + (f" {e['period_m'] * 1e3:.4g} mm {e['change']['amplitude_N']:+.0f} N "
                                   f"({'+'.join(e['directions'])})" if "period_m" in e else
                                   f" {100 * next(iter(e['change'].values())):+.0f} %" if e.get("source") == "witness"
                                   else f" {next(iter(e['change'].values())):+.0f}") for e in d["effects"]],
            "components": per.get("components", []), "holdout_before_N": per.get("holdout_rms_before_N"),
            "holdout_after_N": per.get("holdout_rms_after_N"),
            "friction_change_N": next(c["change"] for c in d["changes"] if c["parameter"] == "friction_N")}


def floor(rows) -> dict:
    """3 x RMS of the normal splits' amplitude changes per direction at +20 and +40 kgf."""
    ch = [v["change_N"] for r in rows if r["condition"].startswith("normal") and r["load_kgf"] > 0
          for c in r["components"][:1] for v in c["directions"].values()]
    rms = float(np.sqrt(np.mean(np.square(ch)))) if ch else float("nan")
    return {"changes_N": ch, "rms_N": rms, "floor_3rms_N": 3 * rms}


def _fmt(c) -> str:
    dirs = "; ".join(f"{d[:3]} {v['reference_N']:.1f}->{v['amplitude_N']:.1f} "
                     f"({v['change_N']:+.1f}±{v['uncertainty_N']:.1f}){'*' if v['named'] else ''}"
                     for d, v in c["directions"].items())
    where = "uniform" if c["where"]["uniform"] else (f"local {c['where']['span_m'][0] * 1e3:.0f}-"
                                                     f"{c['where']['span_m'][1] * 1e3:.0f} mm")
    order = c.get("order", {})
    scale = f", scale {order['scale_difference'] * 100:+.1f} %" if "scale_difference" in order else ""
    return (f"{c['period_m'] * 1e3:.3f} ± {c['period_u_m'] * 1e3:.3f} (ref {c['period_reference_m'] * 1e3:.3f}) mm; "
            f"{dirs}; {where}; order {order.get('nearest', '-')}{scale}"
            f"{' (lead contradicted)' if order.get('contradicts_stated_lead') else ''}")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("json", nargs="?", default="bench_diagnose_cranfield_periodic.json")
    ap.add_argument("--floor", action="store_true", help="also print how the default floor was measured")
    ap.add_argument("--scale-tolerance", type=float, default=0.0, metavar="FRACTION",
                    help="the position sensor's scale tolerance stated (--position-scale-tolerance; default 0)")
    args = ap.parse_args(argv)
    if not (CRANFIELD / "normal.csv.gz").exists():
        print(f"Cranfield recordings not present at {CRANFIELD}")
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        rows = [row(Path(tmp), *p, scale_tolerance=args.scale_tolerance) for p in pairs()]
    print("| condition | load kgf | verdict | named | witness rule (jitter change %, * named) | friction change N "
          "| periodic components: period (reference) mm; amplitude per direction reference -> recording N "
          "(change ± u; * named); where; order of the 5 mm lead, the position's scale that makes it whole "
          "| held-out RMS N before -> after | CPU s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        comps = "<br>".join(_fmt(c) for c in r["components"]) or "-"
        ho = (f"{r['holdout_before_N']:.1f} -> {r['holdout_after_N']:.1f}" if r["holdout_after_N"] is not None
              else "-")
        jit = (f" ({100 * r['jitter_change']:+.1f} ± {100 * r['jitter_u']:.1f}{'*' if r['jitter_named'] else ''})"
               if r["jitter_change"] is not None else "")
        print(f"| {r['condition']} | {r['load_kgf']:+d} | {r['verdict']} | {', '.join(r['named']) or '-'} "
              f"| {r['rule']}{jit} | {r['friction_change_N']:+.1f} | {comps} | {ho} | {r['cpu_s']:.2f} |")
    result = {"rows": rows}
    if args.floor:
        result["floor"] = f = floor(rows)
        print(f"floor: changes {', '.join(f'{c:+.2f}' for c in f['changes_N'])} N; RMS {f['rms_N']:.2f} N; "
              f"3 x RMS {f['floor_3rms_N']:.2f} N")
    Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
