"""Benchmark: forces periodic in position through the dual-EMA path against truth (issue 48 part 2).

Simulated checks of the shipped rig (``emacheck simulate``) with the simulator's ``[[effects]]
periodic_force`` (a force periodic in the ram's position in one drive, behind its load cell): 20 N at a
5 mm period at EMA 1, 20 N at a 4 mm period at EMA 2 (phase 1 rad), and a local defect, 40 N at a 5 mm
period over 12 mm of the stroke around +3 mm at EMA 1; each (seed 13) against the healthy seed-11 check,
and healthy checks against each other. Rule (the issue's): the period within 2 %, the amplitude change
within 20 %, at the right EMA; healthy pairs name nothing.

    python tests/bench/bench_diagnose_dual_periodic.py /tmp/dual-periodic.json

About 2 min on one core (six simulations, each diagnosis, five comparisons).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
ROOT = TESTS.parent

#: name -> (effects, seed, where, period mm, amplitude N, truth in words)
CHECKS = {
    "healthy11": ([], 11, None, None, None, "healthy"),
    "healthy12": ([], 12, None, None, None, "healthy"),
    "healthy13": ([], 13, None, None, None, "healthy"),
    "lead5-ema1": ([{"name": "periodic_force", "where": "ema1", "amplitude_N": 20.0, "period_mm": 5.0}], 13,
                   "ema1", 5.0, 20.0, "EMA 1: 20 N every 5 mm, uniform"),
    "lead4-ema2": ([{"name": "periodic_force", "where": "ema2", "amplitude_N": 20.0, "period_mm": 4.0,
                     "phase_rad": 1.0}], 13, "ema2", 4.0, 20.0, "EMA 2: 20 N every 4 mm, uniform"),
    "local-ema1": ([{"name": "periodic_force", "where": "ema1", "amplitude_N": 40.0, "period_mm": 5.0,
                     "center_mm": 3.0, "width_mm": 12.0}], 13, "ema1", 5.0, 40.0,
                   "EMA 1: 40 N every 5 mm over 12 mm of the stroke around +3 mm"),
}
PAIRS = (("lead5-ema1", "healthy11"), ("lead4-ema2", "healthy11"), ("local-ema1", "healthy11"),
         ("healthy12", "healthy11"), ("healthy13", "healthy11"))


def simulate(folder: Path, name: str, here: bool = False) -> Path:
    """``emacheck simulate`` of the check ``name`` into ``folder``: a process of its own, or ``here`` (in this
    process, through :func:`hil.cli.main`: the same command without a new interpreter's start)."""
    from support.profiles import write_profile_variant
    effects, seed, *_ = CHECKS[name]
    out = folder / name
    argv = ["simulate", "--seed", str(seed), "--out", str(out), "--quiet"]
    if effects:
        argv += ["--sim", str(write_profile_variant("simrig.toml", folder / f"{name}.toml", add={"effects": effects}))]
    if here:
        from hil.cli import main
        if main(argv) != 0:
            raise RuntimeError(f"emacheck {' '.join(argv)} failed")
    else:
        subprocess.run([sys.executable, "-m", "hil", *argv], check=True, cwd=ROOT, capture_output=True)
    return out


def row(new: str, ref: str, data: dict) -> dict:
    _, _, where, period, amp, truth = CHECKS[new]
    per = [e for e in data["effects"] if e["name"].startswith("periodic")]
    out = {"pair": f"{new} vs {ref}", "truth": truth, "verdict": data["verdict"],
           "named": [f"{e['name']} at {e['where']}" + (f" {e['period_m'] * 1e3:.4g} mm, {e['amplitude_N']:.3g} N"
                                                      if "period_m" in e else "") for e in data["effects"]],
           "periodic": per}
    if where is None:
        out["right"] = not data["effects"]
        return out
    ok = [e for e in per if e["where"] == where]
    if ok:
        e = ok[0]
        ch = next(iter(e["change"].values()))
        out |= {"period_err": e["period_m"] * 1e3 / period - 1, "amplitude_err": ch / amp - 1}
    out["right"] = bool(ok and abs(out["period_err"]) <= 0.02 and abs(out["amplitude_err"]) <= 0.2
                        and all(e["where"] == where for e in per))
    return out


def table(folder: Path, here: bool = False) -> list:
    """The pairs' rows; ``here``: the checks simulated in this process (:func:`simulate`)."""
    from hil.analysis.diagnose.dual_reference import dual_reference_diagnosis
    runs = {name: simulate(folder, name, here) for name in CHECKS}
    cache: dict = {}
    return [row(n, r, dual_reference_diagnosis(runs[n], runs[r], None, cache=cache)[0]) for n, r in PAIRS]


def main(argv: list[str]) -> int:
    out = Path(next((a for a in argv if a.endswith(".json")), "bench_diagnose_dual_periodic.json"))
    with tempfile.TemporaryDirectory() as tmp:
        rows = table(Path(tmp))
    print("| pair | truth | verdict | named | period error | amplitude change error | right |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        pe = f"{r['period_err'] * 100:+.2f} %" if "period_err" in r else "-"
        ae = f"{r['amplitude_err'] * 100:+.1f} %" if "amplitude_err" in r else "-"
        print(f"| {r['pair']} | {r['truth']} | {r['verdict']} | {', '.join(r['named']) or '-'} | {pe} | {ae} "
              f"| {'yes' if r['right'] else 'no'} |")
    out.write_text(json.dumps({"rows": rows}, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.path[:0] = [str(ROOT), str(TESTS)]
    sys.exit(main(sys.argv[1:]))
