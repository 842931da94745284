"""Benchmark: how repeatable the dual-EMA model's nominal parameters are (the floors of issue 35, part 2).

A change between two checks of one rig is named only above its relevance floor; this script measures
the floors' data in each parameter's unit (play in um, stiffness and LVDT pitch in %, frictions in N):

* **independent rig** (../shared/data/independent-rig, the effect-free recordings ``null-*`` and
  ``pitch-*``, whose keys give the true internal play and contact stiffness of each EMA): the
  identification error of ``emacheck diagnose``'s nominal fit, fitted minus true, per EMA. Its
  standard deviation sigma over recordings and EMAs (the mean, a bias every check of one rig shares,
  cancels in a change) gives the floor of a change between two checks, ``3 sqrt(2) sigma`` (two
  independent errors, the same factor 3 as the statistical test);
* **own simulator**: two healthy checks of the shipped simulated rig (``emacheck simulate``) with
  different noise seeds: the change of every nominal parameter between them, which a floor must
  exceed (one pair: a lower bound of the spread, not a floor by itself).

    python tests/bench/bench_diagnose_floors.py /tmp/floors.json [--sim RUN_A RUN_B | --no-sim]

``--sim`` takes two run folders already simulated (``emacheck simulate --seed 11 --out RUN_A``, and
``--seed 12``); without it they are simulated here (about 20 s). About 1 min on one core.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from support.independent_rig import DATA, KEYS, diagnose_file  # noqa: E402

#: nominal parameter -> (kind, unit printed, how a change is expressed)
KINDS = {"backlash_int": ("play", "um"), "backlash_bearing": ("play", "um"), "stiffness_int": ("stiffness", "%"),
         "compliance_ext": ("stiffness", "%"), "lvdt_pitch": ("sensor_gain", "%"), "lvdt_offset": ("offset", "um"),
         "hinge_coulomb_N": ("friction", "N"), "drive_coulomb_N": ("friction", "N")}


def _kind(name: str):
    return next((v for k, v in KINDS.items() if name.startswith(k)), None)


def change_in_unit(name: str, new: float, ref: float) -> float:
    """A nominal parameter's change in its floor's unit: um for a play or an offset (values in mm), % of
    the reference for a stiffness, a compliance or a pitch, N for a friction."""
    kind = _kind(name)
    if kind is None:
        return float("nan")
    if kind[1] == "um":
        return 1000.0 * (new - ref)
    if kind[1] == "%":
        return 100.0 * (new / ref - 1.0)
    return new - ref


def independent() -> dict:
    """Fitted minus true internal play (um) and contact stiffness (%), per effect-free recording and EMA."""
    rows = []
    for name in sorted(n for n, k in KEYS.items() if not k["expect"]):
        d, secs = diagnose_file(DATA / f"{name}.csv.gz")
        truth = KEYS[name]["truth"]
        for e in (1, 2):
            play = d.nominal[f"backlash_int{e}_mm"]
            k = d.nominal[f"stiffness_int{e}_N_per_mm"]
            rows.append({"recording": name, "ema": e, "play_fit_um": 1000 * play,
                         "play_true_um": 1000 * truth["backlash_mm"][f"int{e}"],
                         "stiffness_fit_N_per_mm": k,
                         "stiffness_true_N_per_mm": truth["stiffness_N_per_mm"][f"int{e}"]["compression"],
                         "pitch_fit": d.nominal[f"lvdt_pitch{e}"], "pitch_true": KEYS[name]["lvdt_pitch"][e - 1],
                         "cpu_s": secs})
    for r in rows:
        r["play_error_um"] = r["play_fit_um"] - r["play_true_um"]
        r["stiffness_error_pct"] = 100 * (r["stiffness_fit_N_per_mm"] / r["stiffness_true_N_per_mm"] - 1)
        r["pitch_error_pct"] = 100 * (r["pitch_fit"] / r["pitch_true"] - 1)
    out = {"rows": rows}
    for key, kind in (("play_error_um", "play_um"), ("stiffness_error_pct", "stiffness_pct"),
                      ("pitch_error_pct", "sensor_gain_pct")):
        x = np.array([r[key] for r in rows])
        sd = float(np.std(x, ddof=1))
        out[kind] = {"mean": float(x.mean()), "sd": sd, "floor_3sqrt2_sd": 3 * math.sqrt(2) * sd, "n": int(x.size)}
    return out


def simulated(run_a: Path, run_b: Path) -> dict:
    """The change of every nominal parameter between two healthy simulated checks (b against a)."""
    from blf.diagnose import diagnose
    from hil.analysis.diagnose import load_model
    nom = []
    for run in (run_a, run_b):
        model, period = load_model(run, "dual-ema", None)
        nom.append(diagnose(model, period).nominal)
    return {n: {"a": nom[0][n], "b": nom[1][n], "change": change_in_unit(n, nom[1][n], nom[0][n]),
                "unit": (_kind(n) or ("", ""))[1]} for n in nom[0]}


def _simulate(folder: Path) -> tuple:
    runs = []
    for seed in (11, 12):
        out = folder / f"sim{seed}"
        subprocess.run([sys.executable, "-m", "hil", "simulate", "--seed", str(seed), "--out", str(out), "--quiet"],
                       check=True, cwd=TESTS.parent, capture_output=True)
        runs.append(out)
    return tuple(runs)


def main(argv: list[str]) -> int:
    out = Path(next((a for a in argv if a.endswith(".json")), "bench_diagnose_floors.json"))
    result = {}
    if (DATA / "keys.json").exists():
        ind = independent()
        result["independent"] = ind
        print("| recording | EMA | play fit um | play true um | error um | stiffness fit N/mm | true N/mm | error % "
              "| LVDT pitch error % |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in ind["rows"]:
            print(f"| {r['recording']} | {r['ema']} | {r['play_fit_um']:.2f} | {r['play_true_um']:.2f} "
                  f"| {r['play_error_um']:+.2f} | {r['stiffness_fit_N_per_mm']:.0f} "
                  f"| {r['stiffness_true_N_per_mm']:.0f} | {r['stiffness_error_pct']:+.2f} "
                  f"| {r['pitch_error_pct']:+.4f} |")
        for kind in ("play_um", "stiffness_pct", "sensor_gain_pct"):
            s = ind[kind]
            print(f"{kind}: error mean {s['mean']:+.3g}, sd {s['sd']:.3g} over {s['n']}; "
                  f"floor 3 sqrt(2) sd = {s['floor_3sqrt2_sd']:.3g}")
    else:
        print(f"independent-rig recordings not present at {DATA}")
    if "--no-sim" in argv:
        out.write_text(json.dumps(result, indent=1) + "\n")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        runs = (Path(argv[argv.index("--sim") + 1]), Path(argv[argv.index("--sim") + 2])) if "--sim" in argv \
            else _simulate(Path(tmp))
        sim = simulated(*runs)
    result["simulated"] = sim
    fr = [v["change"] for n, v in sim.items() if v["unit"] == "N"]
    result["simulated_friction_3rms_N"] = 3 * float(np.sqrt(np.mean(np.square(fr))))
    print("| nominal parameter | seed 11 | seed 12 | change | unit |")
    print("|---|---|---|---|---|")
    for n, v in sim.items():
        print(f"| {n} | {v['a']:.6g} | {v['b']:.6g} | {v['change']:+.3g} | {v['unit']} |")
    print(f"frictions (hinge, drive Coulomb): 3 x RMS of the changes = {result['simulated_friction_3rms_N']:.3g} N")
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
