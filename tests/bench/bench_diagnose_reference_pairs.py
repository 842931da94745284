"""Benchmark: ``emacheck diagnose NEW --reference HEALTHY`` on pairs of dual-EMA checks of one rig (issue 35).

Simulated checks (``emacheck simulate``) of the shipped rig, healthy with noise seeds 11 to 15, and
changed rigs with seed 13 (a copy of profiles/simrig.toml with one key changed): the contact stiffness of
EMA 1 down 20 %, the internal play of EMA 2 up 30 um, a Coulomb friction of 10 N in the drive of EMA 1 (the
simulator's ``[[effects]] coulomb_friction``), the load cell gain of EMA 2 up 2 % (``sensors2.loadcell_gain``).
Each changed check against the seed-11 one, and the healthy checks against each other (seeds 14 and 15 were
not among the floors' measurements, tests/bench/bench_diagnose_floors.py).
Prints a table (verdict, what is named, the target parameter's change
and whether it is within 30 % of the truth; for healthy pairs whether nothing is named) and writes JSON.

    python tests/bench/bench_diagnose_reference_pairs.py /tmp/pairs.json [--bare]

About 2 min on one core (nine simulations, then each check's fit once and the nine comparisons). ``--bare``:
each check as the independent rig's recordings are (../shared/data/independent-rig/README.md): a CSV of
``t,phi1,phi2,s1,s2,F1,F2`` only, no run folder, no step or mode columns, the phases found from the data.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
ROOT = TESTS.parent

#: name -> (simrig section, {key: value}, seed, truth in words, target parameter, true change in its unit)
CHECKS = {
    "healthy11": (None, {}, 11, "healthy", None, None),
    "healthy12": (None, {}, 12, "healthy", None, None),
    "healthy13": (None, {}, 13, "healthy", None, None),
    "healthy14": (None, {}, 14, "healthy", None, None),
    "healthy15": (None, {}, 15, "healthy", None, None),
    "stiffness1": ("ema1", {"stiffness_compression_N_per_mm": 64000.0, "stiffness_tension_N_per_mm": 64000.0}, 13,
                   "EMA 1 contact stiffness 80000 -> 64000 N/mm (-20 %)", "stiffness_int1_N_per_mm", -20.0),
    "play2": ("ema2", {"backlash_int_mm": 0.15}, 13, "EMA 2 internal play 0.12 -> 0.15 mm (+30 um)",
              "backlash_int2_mm", 30.0),
    "friction1": ("effects", [{"name": "coulomb_friction", "where": "ema1", "force_N": 10.0}], 13,
                  "EMA 1 drive Coulomb friction 0 -> 10 N", "coulomb_friction.force_N", 10.0),
    "loadcell2": ("sensors2", {"loadcell_gain": 1.02}, 13, "EMA 2 load cell gain 1.00 -> 1.02 (+2 %)",
                  "loadcell_gain.gain_error", 2.0),
}
PAIRS = (("stiffness1", "healthy11"), ("play2", "healthy11"), ("friction1", "healthy11"), ("loadcell2", "healthy11"),
         ("healthy12", "healthy11"), ("healthy13", "healthy11"), ("healthy13", "healthy12"), ("healthy14", "healthy11"),
         ("healthy15", "healthy14"))


def rig(path: Path, section: str, values: dict) -> Path:
    """A copy of the shipped simulated rig with ``values`` set in ``[section]`` (``effects``: added)."""
    from support.profiles import write_profile_variant

    if section == "effects":
        return write_profile_variant("simrig.toml", path, add={section: values})
    return write_profile_variant("simrig.toml", path, {section: values})


def simulate(folder: Path, name: str) -> Path:
    section, values, seed, *_ = CHECKS[name]
    out = folder / name
    cmd = [sys.executable, "-m", "hil", "simulate", "--seed", str(seed), "--out", str(out), "--quiet"]
    if section is not None:
        cmd += ["--sim", str(rig(folder / f"{name}.toml", section, values))]
    subprocess.run(cmd, check=True, cwd=ROOT, capture_output=True)
    return out


def row(new: str, ref: str, data: dict) -> dict:
    truth, param, true = CHECKS[new][3], CHECKS[new][4], CHECKS[new][5]
    unit = {c["parameter"]: c["unit"] for c in data["changes"]}
    named = [f"{e['name']} at {e['where']} {v:+.3g} {unit[p]}" for e in data["effects"] for p, v in e["change"].items()]
    out = {"pair": f"{new} vs {ref}", "truth": truth, "verdict": data["verdict"], "named": named,
           "fits": data.get("fits")}
    if param is None:
        out["right"] = not data["effects"]
        out["target"] = "-"
    else:
        c = next((c for c in data["changes"] if c["parameter"] == param), None)
        if c is None:
            out.update(right=False, target=f"{param}: not compared (no library effect accepted on either check)")
            return out
        e = [e for e in data["effects"] if param in e["change"]]
        out["right"] = bool(e and e[0]["where"] == c["where"] and abs(c["change"] / true - 1) <= 0.3)
        out["target"] = (f"{param} {c['change']:+.3g} ± {2 * c['uncertainty']:.2g} (U, k=2) {c['unit']} "
                         f"(true {true:+g}, floor {c['floor']:g})")
    return out


BARE_COLUMNS = 7  #: t,phi1,phi2,s1,s2,F1,F2: the independent rig's layout


def bare(run: Path, out: Path) -> Path:
    """The run folder's signals in the independent rig's layout (its first seven columns, nothing else)."""
    with (run / "signals.csv").open() as src, out.open("w") as dst:
        for line in src:
            dst.write(",".join(line.rstrip("\n").split(",")[:BARE_COLUMNS]) + "\n")
    return out


def main(argv: list[str]) -> int:
    from hil.analysis.diagnose.dual_reference import dual_reference_diagnosis
    out = Path(next((a for a in argv if a.endswith(".json")), "bench_diagnose_reference_pairs.json"))
    rows, cache = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        runs = {name: simulate(Path(tmp), name) for name in CHECKS}
        if "--bare" in argv:
            runs = {name: bare(run, Path(tmp) / f"{name}.csv") for name, run in runs.items()}
        for new, ref in PAIRS:
            rows.append(row(new, ref, dual_reference_diagnosis(runs[new], runs[ref], None, cache=cache)[0]))
    print("| pair | truth | verdict | named (change) | target parameter: change | right | residual RMS before -> "
          "after (the channel improved most) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        f = r["fits"]
        best = max(f["before"], key=lambda k: f["before"][k] / f["after"][k]) if f else None
        fit = f"{best} {f['before'][best]:.3g} -> {f['after'][best]:.3g}" if best else "-"
        print(f"| {r['pair']} | {r['truth']} | {r['verdict']} | {', '.join(r['named']) or '-'} | {r['target']} "
              f"| {'yes' if r['right'] else 'no'} | {fit} |")
    out.write_text(json.dumps({"rows": rows}, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.path[:0] = [str(ROOT), str(TESTS)]
    sys.exit(main(sys.argv[1:]))
