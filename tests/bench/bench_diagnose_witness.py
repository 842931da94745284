"""Benchmark: the tracking error as a second witness, and floors that say what they cover (issue 48, parts 3-4).

On the Cranfield actuator's development set (../shared/data/cranfield-actuator, never copied):

* ``--floors``: how the tracking error's default floors
  (``hil.analysis.diagnose.witness.WITNESS_FLOORS``) were measured: the steady lag and jitter of
  ``normal`` compared between halves of its runs (6-10 against 1-5, even against odd) at +20, +40 and
  -40 kgf (the position is not re-levelled at -40 kgf), 3 x the RMS of the six changes;
* the table: each condition against ``normal`` at the same load, and ``normal`` against itself in two
  splits per load, through ``emacheck diagnose --model single-axis --reference`` (verdict, what the effort
  names, the tracking error's lag and jitter changes, the rule that applied);
* several references: ``lackLubrication1`` and ``spalling3`` at every load against three healthy references
  (``normal`` runs 1-3, 4-7, 8-10): the floors measured from their spread, labelled a reproducibility
  (on this data set the three come from one session: the figures show the mechanism, not a
  reproducibility of the rig).

    python tests/bench/bench_diagnose_witness.py /tmp/witness.json [--floors]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from support.cranfield import CRANFIELD, DEVELOPMENT, SAMPLE_RATE_HZ, single_axis, write_single_axis  # noqa: E402

LOADS = (20, 40, -40)
ALL = range(1, 11)
#: two different splits of the healthy runs: (runs of the recording, runs of the reference)
SPLITS = {"6-10 vs 1-5": (range(6, 11), range(1, 6)), "even vs odd": (range(2, 11, 2), range(1, 11, 2))}
#: three healthy references for the floors from their spread
THREE_REFS = (range(1, 4), range(4, 8), range(8, 11))


def _witness(name: str, load: int, runs):
    from blf.diagnose.witness import tracking_witness
    c = single_axis(name, load, runs)
    return tracking_witness(c["t"], c["q"], c["q_ref"], SAMPLE_RATE_HZ)


def floors() -> dict:
    """The healthy changes of the lag (m) and the jitter ratio between halves of ``normal``, and 3 x their RMS."""
    from blf.diagnose.witness import floor_from_spread
    lag, jit, rows = [], [], []
    for load in LOADS:
        for split, (runs, ref_runs) in SPLITS.items():
            wn, wr = _witness("normal", load, runs), _witness("normal", load, ref_runs)
            lag.append(wn.lag_m - wr.lag_m)
            jit.append(wn.jitter_m / wr.jitter_m - 1)
            rows.append({"load_kgf": load, "split": split, "lag_change_m": lag[-1], "jitter_change": jit[-1],
                         "jitter_m": wn.jitter_m, "jitter_reference_m": wr.jitter_m})
    return {"rows": rows, "lag_3rms_m": floor_from_spread(lag), "jitter_3rms": floor_from_spread(jit)}


def _csv(folder: Path, name: str, load: int, runs) -> Path:
    return write_single_axis(folder / f"{name}_{load}_{min(runs)}-{max(runs)}_{len(runs)}.csv", name, load, runs)


def diagnose(folder: Path, name: str, load: int, runs, ref_runs_list) -> dict:
    """diagnosis.json of ``name`` (runs) against ``normal`` (the first of ``ref_runs_list``; the others measure
    the floors)."""
    from hil.analysis.diagnose.axis_reference import reference_diagnosis
    from hil.analysis.diagnose.single_axis import AxisOptions
    refs = [_csv(folder, "normal", load, rr) for rr in ref_runs_list]
    return reference_diagnosis(_csv(folder, name, load, runs), refs[0], AxisOptions(current_law="power"),
                               tuple(refs[1:]))


def row(name: str, load: int, label: str, data: dict) -> dict:
    """The figures of one diagnosis."""
    w = {c["parameter"]: c for c in data["witness"].get("changes", [])}
    ch = {c["parameter"]: c for c in data["changes"]}
    lag, jit = w["tracking_lag_m"], w["tracking_jitter_ratio"]
    return {"condition": name, "load_kgf": load, "against": label, "verdict": data["verdict"],
            "named": [e["name"] for e in data["effects"]], "rule": data["witness"]["rule"],
            "friction_change_N": ch["friction_N"]["change"], "friction_u_N": ch["friction_N"]["uncertainty"],
            "lag_change_m": lag["change"], "lag_u_m": lag["uncertainty"], "lag_named": lag["named"],
            "jitter_m": jit["value_m"], "jitter_reference_m": jit["reference_m"], "jitter_change": jit["change"],
            "jitter_u": jit["uncertainty"], "jitter_named": jit["named"], "floor": data["floor"],
            "untrusted_words": data["effort"]["words"] if data["verdict"] == "untrusted_effort" else None}


def table(folder: Path, loads=LOADS, conditions=DEVELOPMENT) -> list:
    """Each condition against normal (all runs) at its load; normal against normal in :data:`SPLITS`."""
    out = []
    for load in loads:
        for name in conditions:
            if name == "normal":
                for label, (runs, ref_runs) in SPLITS.items():
                    out.append(row(name, load, label, diagnose(folder, name, load, runs, [ref_runs])))
            else:
                out.append(row(name, load, "normal 1-10", diagnose(folder, name, load, ALL, [ALL])))
    return out


def several(folder: Path, names=("lackLubrication1", "spalling3"), loads=LOADS) -> list:
    """Conditions against three healthy references (:data:`THREE_REFS`): floors from their spread."""
    return [row(n, load, "normal 1-3 (+ 4-7, 8-10)", diagnose(folder, n, load, ALL, THREE_REFS))
            for load in loads for n in names]


def _print_rows(rows: list) -> None:
    print("| condition | load kgf | against | verdict | named | rule | friction change N (± u) | lag change um (± u) "
          "| jitter mm ref -> now | jitter change % (± u) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['condition']} | {r['load_kgf']:+d} | {r['against']} | {r['verdict']} | "
              f"{', '.join(r['named']) or '-'} | {r['rule']} | {r['friction_change_N']:+.1f} ± {r['friction_u_N']:.1f} "
              f"| {1e6 * r['lag_change_m']:+.1f} ± {1e6 * r['lag_u_m']:.1f}{' named' if r['lag_named'] else ''} "
              f"| {1e3 * r['jitter_reference_m']:.3f} -> {1e3 * r['jitter_m']:.3f} "
              f"| {100 * r['jitter_change']:+.1f} ± {100 * r['jitter_u']:.1f}{' named' if r['jitter_named'] else ''} |")


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json", nargs="?", default="bench_diagnose_witness.json",
                    help="where to write the figures (default: bench_diagnose_witness.json in the current folder)")
    ap.add_argument("--floors", action="store_true", help="also print how the default floors were measured")
    args = ap.parse_args(argv)
    if not (CRANFIELD / "normal.csv.gz").exists():
        print(f"Cranfield recordings not present at {CRANFIELD}")
        return 2
    result = {}
    if args.floors:
        fl = floors()
        result["floors"] = fl
        for r in fl["rows"]:
            print(f"normal {r['split']} at {r['load_kgf']:+d} kgf: lag {1e6 * r['lag_change_m']:+.1f} um, jitter "
                  f"{1e3 * r['jitter_reference_m']:.4f} -> {1e3 * r['jitter_m']:.4f} mm "
                  f"({100 * r['jitter_change']:+.2f} %)")
        print(f"3 x RMS: lag {1e6 * fl['lag_3rms_m']:.3f} um, jitter {100 * fl['jitter_3rms']:.2f} %")
    with tempfile.TemporaryDirectory() as tmp:
        result["rows"] = table(Path(tmp))
        _print_rows(result["rows"])
        result["several"] = several(Path(tmp))
        print("\nAgainst three healthy references (floors from their spread):")
        _print_rows(result["several"])
        for r in result["several"][:1]:
            cov = r["floor"]["coverage"]
            print(f"floors: force {r['floor']['force_N']:.1f} N, lag {1e6 * r['floor']['tracking_lag_m']:.1f} um, "
                  f"jitter {100 * r['floor']['tracking_jitter_ratio']:.1f} % ({cov['kind']}): {cov['words']}")
    for r in result["rows"]:
        if r["untrusted_words"]:
            print(f"{r['condition']} {r['load_kgf']:+d}: {r['untrusted_words']}")
    Path(args.json).write_text(json.dumps(result, indent=1, default=float) + "\n")
    print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
