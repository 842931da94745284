"""Benchmark: how repeatable the dual-EMA model's nominal parameters are (the floors of issue 35, part 2).

A change between two checks of one rig is named only above its relevance floor; this script measures
the floors' data in each parameter's unit (play in um, stiffness and LVDT pitch in %, frictions in N):

* **independent rig** (../shared/data/independent-rig, the effect-free recordings ``null-*`` and
  ``pitch-*``, whose keys give the true internal play and contact stiffness of each EMA): the
  identification error of ``emacheck diagnose``'s nominal fit, fitted minus true, per EMA. Its
  standard deviation sigma over recordings and EMAs (the mean, a bias every check of one rig shares,
  cancels in a change) gives the floor of a change between two checks, ``3 sqrt(2) sigma`` (two
  independent errors, the same factor 3 as the statistical test);
* **own simulator**: three healthy checks of the shipped simulated rig (``emacheck simulate``) with
  noise seeds 11, 12, 13: the change of every nominal parameter between each pair, and per kind
  3 x their RMS (the pairs share checks: three checks, not three independent pairs).

The default floor of a kind is the larger of the two, rounded up.

    python tests/bench/bench_diagnose_floors.py /tmp/floors.json [--library] [--bare] [--no-ind]
        [--sim RUN_A RUN_B RUN_C | --no-sim]

``--library``: every candidate of the library (else the drives' Coulomb friction and the load cells' gain);
``--bare``: the simulated checks in the independent rig's layout (t,phi1,phi2,s1,s2,F1,F2 only);
``--no-ind``: without the independent rig's part.

``--sim`` takes three run folders already simulated (``emacheck simulate --seed 11 --out RUN_A``, and
``--seed 12``, ``--seed 13``); without it they are simulated here (about 30 s). About 2 min on one core.
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

from support.independent_rig import DATA, KEYS  # noqa: E402

SEEDS = (11, 12, 13)
#: library candidates (name, variant) fitted on every healthy recording for the floors of their changes
CANDIDATES = (("coulomb_friction", "drive"), ("loadcell_gain", ""))  # the quick set (the slow test's)


def compared(runs_or_models) -> list:
    """Per recording (its Diagnosis, its NominalCovariance, its check speed mm/s), for the product's own comparison
    (:func:`hil.analysis.diagnose.floors.nominal_changes`: the parameters, sums and frictions it compares)."""
    from blf.diagnose.covariance import nominal_covariance
    from blf.diagnose.engine import diagnose
    from hil.analysis.diagnose.floors import check_speed
    out = []
    for model, period in runs_or_models:
        d = diagnose(model, period)
        out.append((d, nominal_covariance(model, period, d.nominal), check_speed(model)))
    return out


def changes(new, ref) -> dict:
    """{parameter: (floor key, change in the floor's unit)} of every comparison the product makes and could
    name (a parameter it does not separate is left out: it is never named)."""
    from hil.analysis.diagnose.floors import nominal_changes
    from hil.profile.floors import DUAL_FLOORS
    return {c["parameter"]: (c["floor_key"], c["change"])
            for c in nominal_changes(new[0].nominal, ref[0].nominal, new[1], ref[1], DUAL_FLOORS, ref[2])
            if c["separable"]}


def candidate_values(model, period: float, d, everything: bool = False) -> dict:
    """Each candidate of :data:`CANDIDATES` (``everything``: of the whole library) at each EMA fitted on a
    healthy recording (whose diagnosis is ``d``), each size parameter in its floor's unit
    (:data:`hil.analysis.diagnose.floors.LIBRARY_FLOORS`; a viscous coefficient as its force at the
    check's speed): {"name.param@where/variant": (floor key, value)}."""
    from blf.diagnose.engine import fit_effect
    from hil.analysis.diagnose.floors import LIBRARY_FLOORS, check_speed
    out = {}
    v = check_speed(model)
    for c in model.candidates:
        if everything or (c.name, c.variant) in CANDIDATES:
            e = fit_effect(model, period, d.nominal, c, ())
            for k, x in e.parameters.items():
                if k in c.shape:
                    continue
                key, _, scale, _ = LIBRARY_FLOORS[(c.name, k)]
                out[f"{c.name}.{k}@{c.where}" + (f"/{c.variant}" if c.variant else "")] = \
                    (key, (v if scale == "speed" else scale) * x)
    return out


def _pooled(series: dict) -> dict:
    """Per floor key, from {series: (key, [values, one per recording])} whose truth is the same in every
    recording (0: no such effect): the pooled standard deviation about each series' mean and 3 sqrt(2) of it."""
    by: dict = {}
    for key, vals in series.values():
        by.setdefault(key, []).append(np.asarray(vals, dtype=float))
    out = {}
    for key, ss in by.items():
        dev = sum(float(((x - x.mean()) ** 2).sum()) for x in ss)
        dof = sum(x.size - 1 for x in ss)
        sd = math.sqrt(dev / dof)
        allx = np.concatenate(ss)
        out[key] = {"mean": float(allx.mean()), "sd": sd, "floor_3sqrt2_sd": 3 * math.sqrt(2) * sd, "n": int(allx.size),
                    "series": len(ss)}
    return out


def independent(everything: bool = False, shared: Path | None = None) -> dict:
    """Fitted minus true internal play (um) and contact stiffness (%), per effect-free recording and EMA.
    ``shared``: each recording's diagnosis once per test run (:func:`support.independent_rig.diagnosed`)."""
    from hil.analysis.diagnose.load import load_model
    from support.independent_rig import diagnosed, rig_profile
    rows, gains, ext = [], [], []
    for name in sorted(n for n, k in KEYS.items() if not k["expect"]):
        d, secs = diagnosed(name, shared)
        model, period = load_model(DATA / f"{name}.csv.gz", "dual-ema", rig_profile())
        ext.append({"recording": name, "play_fit_um": 1000 * (d.nominal["backlash_bearing1_mm"]
                                                              + d.nominal["backlash_bearing2_mm"]),
                    "play_true_um": 1000 * KEYS[name]["truth"]["backlash_mm"]["ext"],
                    "compliance_mm_per_N": [d.nominal[f"compliance_ext{e}_mm_per_N"] for e in (1, 2)],
                    "stiffness_true_N_per_mm": KEYS[name]["truth"]["stiffness_N_per_mm"]["ext"]["approx"]})
        gains += [{"recording": name, "candidate": k, "kind": kind, "value": v}
                  for k, (kind, v) in candidate_values(model, period, d, everything).items()]
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
    out = {"rows": rows, "loadcell_gain_rows": gains, "external_rows": ext}
    # external play: the two bearings' sum against the key's one external play (the split is not in the data)
    x = np.array([r["play_fit_um"] - r["play_true_um"] for r in ext])
    sd = float(np.std(x, ddof=1))
    out["external_play_um"] = {"mean": float(x.mean()), "sd": sd, "floor_3sqrt2_sd": 3 * math.sqrt(2) * sd,
                               "n": int(x.size)}
    # compliance per EMA: the keys give one external stiffness, the same in every recording, and no split: the
    # scatter of each EMA's fitted compliance about its mean over the recordings (% of it) is its error's
    c = np.array([r["compliance_mm_per_N"] for r in ext])
    dev = 100 * (c / c.mean(axis=0) - 1)
    sd = float(np.sqrt(np.sum(dev ** 2) / (dev.size - 2)))
    out["compliance_pct"] = {"mean": 0.0, "sd": sd, "floor_3sqrt2_sd": 3 * math.sqrt(2) * sd, "n": int(dev.size),
                             "true_same_in_all": len({r["stiffness_true_N_per_mm"] for r in ext}) == 1}
    # the library's candidates, fitted at each EMA where none is (true 0), pooled per floor key
    series: dict = {}
    for g in gains:
        series.setdefault(g["candidate"], (g["kind"], []))[1].append(g["value"])
    out["library"] = _pooled(series)
    out["loadcell_gain_pct"] = out["library"]["loadcell_gain_pct"]
    for key, kind in (("play_error_um", "play_um"), ("stiffness_error_pct", "stiffness_pct"),
                      ("pitch_error_pct", "sensor_gain_pct")):
        x = np.array([r[key] for r in rows])
        sd = float(np.std(x, ddof=1))
        out[kind] = {"mean": float(x.mean()), "sd": sd, "floor_3sqrt2_sd": 3 * math.sqrt(2) * sd, "n": int(x.size)}
    return out


def simulated(runs, everything: bool = False) -> dict:
    """The change of every comparison the product makes (:func:`changes`) between each pair of healthy
    simulated checks, and per floor kind 3 x the RMS of those changes."""
    from itertools import combinations

    from hil.analysis.diagnose.load import load_model
    models = [load_model(run, "dual-ema", None) for run in runs]
    fits = compared(models)
    cand = [candidate_values(m, T, f[0], everything) for (m, T), f in zip(models, fits, strict=True)]
    pairs, kind_of = {}, {}
    for i, j in combinations(range(len(runs)), 2):
        ch = changes(fits[j], fits[i])
        kind_of |= {n: k for n, (k, _) in ch.items()} | {k: f"{v[0]} (library)" for k, v in cand[0].items()}
        pairs[f"{SEEDS[j]} vs {SEEDS[i]}"] = {n: v for n, (_, v) in ch.items()} \
            | {k: cand[j][k][1] - cand[i][k][1] for k in cand[0]}
    kinds = {}
    for ch in pairs.values():
        for n, v in ch.items():
            kinds.setdefault(kind_of[n], []).append(v)
    return {"pairs": pairs, "kind_of": kind_of,
            "floor_3rms": {k: 3 * float(np.sqrt(np.mean(np.square(v)))) for k, v in kinds.items()},
            "n": {k: len(v) for k, v in kinds.items()}}


def _simulate(folder: Path) -> tuple:
    runs = []
    for seed in SEEDS:
        out = folder / f"sim{seed}"
        subprocess.run([sys.executable, "-m", "hil", "simulate", "--seed", str(seed), "--out", str(out), "--quiet"],
                       check=True, cwd=TESTS.parent, capture_output=True)
        runs.append(out)
    return tuple(runs)


def main(argv: list[str]) -> int:
    out = Path(next((a for a in argv if a.endswith(".json")), "bench_diagnose_floors.json"))
    result = {}
    if "--no-ind" in argv:
        pass
    elif (DATA / "keys.json").exists():
        ind = independent("--library" in argv)
        result["independent"] = ind
        print("| recording | EMA | play fit um | play true um | error um | stiffness fit N/mm | true N/mm | error % "
              "| LVDT pitch error % |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in ind["rows"]:
            print(f"| {r['recording']} | {r['ema']} | {r['play_fit_um']:.2f} | {r['play_true_um']:.2f} "
                  f"| {r['play_error_um']:+.2f} | {r['stiffness_fit_N_per_mm']:.0f} "
                  f"| {r['stiffness_true_N_per_mm']:.0f} | {r['stiffness_error_pct']:+.2f} "
                  f"| {r['pitch_error_pct']:+.4f} |")
        print("| recording | external play fit um (bearing 1 + 2) | true um | error um | compliance 1, 2 mm/N |")
        print("|---|---|---|---|---|")
        for r in ind["external_rows"]:
            print(f"| {r['recording']} | {r['play_fit_um']:.2f} | {r['play_true_um']:.2f} "
                  f"| {r['play_fit_um'] - r['play_true_um']:+.2f} "
                  f"| {r['compliance_mm_per_N'][0]:.4g}, {r['compliance_mm_per_N'][1]:.4g} |")
        for kind in ("play_um", "external_play_um", "stiffness_pct", "compliance_pct", "sensor_gain_pct",
                     "loadcell_gain_pct"):
            s = ind[kind]
            print(f"{kind}: error mean {s['mean']:+.3g}, sd {s['sd']:.3g} over {s['n']}; "
                  f"floor 3 sqrt(2) sd = {s['floor_3sqrt2_sd']:.3g}")
        for kind, s in ind["library"].items():
            print(f"{kind} (library, true 0): mean {s['mean']:+.3g}, pooled sd {s['sd']:.3g} over {s['n']} values in "
                  f"{s['series']} series; floor 3 sqrt(2) sd = {s['floor_3sqrt2_sd']:.3g}")
    else:
        print(f"independent-rig recordings not present at {DATA}")
    if "--no-sim" in argv:
        out.write_text(json.dumps(result, indent=1) + "\n")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        runs = tuple(Path(a) for a in argv[argv.index("--sim") + 1:argv.index("--sim") + 1 + len(SEEDS)]) \
            if "--sim" in argv else _simulate(Path(tmp))
        if "--bare" in argv:  # each check as the independent rig's recordings are: t,phi1,phi2,s1,s2,F1,F2 only
            from bench.bench_diagnose_reference_pairs import bare
            runs = tuple(bare(run, Path(tmp) / f"bare{i}.csv") for i, run in enumerate(runs))
        sim = simulated(runs, "--library" in argv)
    result["simulated"] = sim
    from hil.analysis.diagnose.floors import LIBRARY_FLOORS
    units = {"play_um": "um", "external_play_um": "um", "stiffness_pct": "%", "compliance_pct": "%",
             "sensor_gain_pct": "%", "friction_N": "N"} | {v[0]: v[1] for v in LIBRARY_FLOORS.values()}
    names = list(next(iter(sim["pairs"].values())))
    print("| nominal parameter | unit | " + " | ".join(sim["pairs"]) + " |")
    print("|---|---|" + "---|" * len(sim["pairs"]))
    for n in names:
        unit = units[sim["kind_of"][n].split(" ")[0]]
        print(f"| {n} | {unit} | " + " | ".join(f"{ch[n]:+.3g}" for ch in sim["pairs"].values()) + " |")
    for k, v in sim["floor_3rms"].items():
        src = result.get("independent", {})
        lib = src.get("library", {}) if k.endswith(" (library)") else src
        ind = lib.get(k.split(" ")[0], {}).get("floor_3sqrt2_sd")
        print(f"{k}: simulated pairs 3 x RMS = {v:.3g} over {sim['n'][k]}"
              + (f"; independent rig 3 sqrt(2) sd = {ind:.3g}" if ind is not None else ""))
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"written {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
