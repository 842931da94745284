"""Issue 13's development benchmark: ``emacheck diagnose`` on the 19 independent-rig recordings.

Not collected by pytest. Usage::

    python tests/bench/bench_diagnose_dev.py [out.json] [--only NAME,...] [--shipped-profile]

One line per recording (verdict, effects, where, judgement, CPU seconds), then
the score by issue 13's rules (:func:`support.independent_rig.judge`). The
actuation profile is the shipped one with the rig's ratio from its README
(:func:`support.independent_rig.rig_profile`); ``--shipped-profile`` uses the
shipped ratio instead (9.6 ppm more than the rig's). Needs
../shared/data/independent-rig. One process, one core.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from support.independent_rig import DATA, KEYS, SHIPPED_ACTUATION, diagnose_file, judge  # noqa: E402


def main(argv: list[str]) -> int:
    out = Path(next((a for a in argv if not a.startswith("--") and a.endswith(".json")), "bench_diagnose_dev.json"))
    only = None
    if "--only" in argv:
        only = set(argv[argv.index("--only") + 1].split(","))
    profile = SHIPPED_ACTUATION if "--shipped-profile" in argv else None
    if not KEYS:
        print(f"independent-rig recordings not present at {DATA}")
        return 2
    rows = []
    for name, key in KEYS.items():
        if only and name not in only:
            continue
        try:
            d, secs = diagnose_file(DATA / f"{name}.csv.gz", profile)
            effects = [(e.name, e.where) for e in d.effects]
            where = list(getattr(d, "where", ()) or ())
            if not hasattr(d, "where") and d.locations:  # an older Diagnosis: the strongest location's EMA
                ch = max(d.locations, key=lambda loc: loc.score).channel
                where = ["ema1" if ch.endswith("1") else "ema2" if ch.endswith("2") else "external"]
            ok, why = judge(key["expect"], d.verdict, effects, where)
            row = {"name": name, "expect": key["expect"], "verdict": d.verdict, "effects": effects, "where": where,
                   "ok": ok, "why": why, "cpu_s": round(secs, 1),
                   "parameters": [[e.name, e.where, e.parameters, e.uncertainty] for e in d.effects],
                   "band_holdout_rms": [d.residual_rms_holdout_before, d.residual_rms_holdout_after]
                   if hasattr(d, "residual_rms_raw_before") else None}
        except Exception as exc:  # noqa: BLE001 - a crash is a wrong answer, reported
            row = {"name": name, "expect": key["expect"], "verdict": "crash", "effects": [], "where": [],
                   "ok": False, "why": f"{type(exc).__name__}: {exc}"[:200], "cpu_s": None}
        rows.append(row)
        print(f"{name:18s} {'RIGHT' if row['ok'] else 'wrong'} {row['verdict']:12s} "
              f"effects={row['effects']} where={row['where']} ({row['why']}) {row['cpu_s']} s", flush=True)
    n_ok = sum(r["ok"] for r in rows)
    print(f"\ndev set: {n_ok}/{len(rows)} right ({100.0 * n_ok / max(len(rows), 1):.0f} %, target >= 90 %)")
    secs = [r["cpu_s"] for r in rows if r["cpu_s"] is not None]
    if secs:
        print(f"CPU time per recording: median {sorted(secs)[len(secs) // 2]:.1f} s, max {max(secs):.1f} s")
    out.write_text(json.dumps({"rows": rows, "right": n_ok, "total": len(rows)}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
