"""Benchmark (not a test): BLFmaint (blf.maint.blfmaint.blf_maint) across its envelope.

Part 1, synthetic F-D records (tests/support/blfmaint_data.py: piecewise
linear contact with backlash, tension/compression stiffnesses that may
differ, slow triangular force demand, the shipped noise model). A grid over

* backlash B: 0.02, 0.05, 0.1, 0.2, 0.5 mm
* ratio of B to the D range of the force fight: 0.005 ... 0.9
* contact stiffness (geometric mean of the two sides): 5, 20, 80, 200 kN/mm
* noise factor on the shipped noise (LVDT 0.025 mm pp, load cell 10 N std):
  0.5, 1, 2, 3

The force amplitude follows from B, the ratio and the stiffness; cells whose
amplitude is outside 0.5-15 kN (what a force fight of the check produces,
per EMA or as F2 - F1) or whose D range exceeds 4 mm (+-2 mm) are not
physical and are listed as such. Each cell runs ``--seeds`` records, each
with its nuisances drawn from the seed (slope sign and internal/external
noise, stiffness asymmetry up to 1.4, D offset, gap speed 0.1-1 mm/s, gap
friction 0-100 N, ramp time).

Part 2, the simulator (sim.plant.RigPlant through hil.check.runner.run_check, as
``emacheck simulate``): simulated-rig variants of profiles/simrig.toml
(small external backlash, large and small internal backlash, soft and stiff
contacts, 0.5x and 3x sensor noise), ``--sim-seeds`` seeds each, all three
channels analysed by hil.analysis.maint.analyze_signals.

Target: every channel measured in every cell, worst |B - truth| <=
max(5 um, 5 % of B). Prints the tables and writes JSON.

Usage: python tests/bench/bench_envelope.py [--seeds 5] [--sim-seeds 2] [--no-sim] [--jobs 1]
       [--json bench_envelope.json] [--impl FILE] [--centre-slope]

``--centre-slope`` fits the paper's sloped line in the backlash instead of
the level (``blf_maint(..., centre_slope=True)``).

``--impl FILE`` runs another implementation of ``blf_maint`` (a copy of
blf/maint/blfmaint.py, e.g. ``git show <commit>:blf/maint/blfmaint.py > /tmp/maint_old.py``)
through the same grid and simulator variants, for a before/after comparison.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (conftest, support)

BACKLASH_MM = (0.02, 0.05, 0.1, 0.2, 0.5)
RATIO = (0.005, 0.01, 0.03, 0.1, 0.3, 0.6, 0.9)
STIFFNESS_N_PER_MM = (5e3, 20e3, 80e3, 200e3)
NOISE = (0.5, 1.0, 2.0, 3.0)
MAX_D_RANGE_MM = 4.0

#: simulated-rig variants: name -> overrides of profiles/simrig.toml (nested like the profile)
SIM_VARIANTS = {
    "default": {},
    "ext 0.02 (bearing 0.01)": {"ema1": {"bearing_backlash_mm": 0.01}, "ema2": {"bearing_backlash_mm": 0.01}},
    "ext 0.03 (bearing 0.015)": {"ema1": {"bearing_backlash_mm": 0.015}, "ema2": {"bearing_backlash_mm": 0.015}},
    "ext 0.02, soft housing 8 kN/mm": {
        "ema1": {"bearing_backlash_mm": 0.01, "housing_stiffness_N_per_mm": 8000.0},
        "ema2": {"bearing_backlash_mm": 0.01, "housing_stiffness_N_per_mm": 8000.0}},
    "ext 0.15, stiff housing 100 kN/mm": {
        "ema1": {"bearing_backlash_mm": 0.075, "housing_stiffness_N_per_mm": 100000.0},
        "ema2": {"bearing_backlash_mm": 0.075, "housing_stiffness_N_per_mm": 100000.0}},
    "int 0.02 / 0.4": {"ema1": {"backlash_int_mm": 0.02}, "ema2": {"backlash_int_mm": 0.4}},
    "int 0.02 stiff 200 kN/mm": {
        "ema1": {"backlash_int_mm": 0.02, "stiffness_compression_N_per_mm": 200000.0,
                 "stiffness_tension_N_per_mm": 200000.0},
        "ema2": {"backlash_int_mm": 0.05, "stiffness_compression_N_per_mm": 200000.0,
                 "stiffness_tension_N_per_mm": 150000.0}},
    "int soft 30/20 kN/mm": {
        "ema1": {"stiffness_compression_N_per_mm": 30000.0, "stiffness_tension_N_per_mm": 20000.0},
        "ema2": {"backlash_int_mm": 0.03, "stiffness_compression_N_per_mm": 20000.0,
                 "stiffness_tension_N_per_mm": 30000.0}},
    "noise 3x, ext 0.02": {
        "ema1": {"bearing_backlash_mm": 0.01}, "ema2": {"bearing_backlash_mm": 0.01},
        "sensors1": {"lvdt_noise_pp_mm": 0.075, "loadcell_noise_std_N": 30.0},
        "sensors2": {"lvdt_noise_pp_mm": 0.075, "loadcell_noise_std_N": 30.0}},
    "noise 0.5x, ext 0.02": {
        "ema1": {"bearing_backlash_mm": 0.01}, "ema2": {"bearing_backlash_mm": 0.01},
        "sensors1": {"lvdt_noise_pp_mm": 0.0125, "loadcell_noise_std_N": 5.0},
        "sensors2": {"lvdt_noise_pp_mm": 0.0125, "loadcell_noise_std_N": 5.0}},
}


def tolerance_mm(backlash_mm: float) -> float:
    """The target: max(5 um, 5 % of B), mm."""
    return max(0.005, 0.05 * backlash_mm)


def _impl(path: str | None):
    """The module holding blf_maint and BlfMaintResult: blf.maint.blfmaint, or the module file ``path``."""
    if path is None:
        import blf.maint.blfmaint
        return blf.maint.blfmaint
    name = "blf_maint_impl"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod  # dataclasses look their module up
        spec.loader.exec_module(mod)
    return sys.modules[name]


def grid_cells() -> tuple[list[dict], list[dict]]:
    """(physical cells, cells outside the force fight's range), each a dict of its axes and figures."""
    from support.blfmaint_data import F_RANGE_N
    ok, out = [], []
    for ib, b in enumerate(BACKLASH_MM):
        for ir, r in enumerate(RATIO):
            for ik, k in enumerate(STIFFNESS_N_PER_MM):
                f_max = b * (1.0 / r - 1.0) * k / 2.0
                cell = dict(backlash_mm=b, ratio=r, stiffness_N_per_mm=k, f_max_N=f_max, d_range_mm=b / r,
                            index=(ib, ir, ik))
                if F_RANGE_N[0] <= f_max <= F_RANGE_N[1] and b / r <= MAX_D_RANGE_MM:
                    ok.append(cell)
                else:
                    out.append(cell)
    return ok, out


def run_cell(job: tuple) -> dict:
    """One (cell, noise factor): ``seeds`` records through blf_maint; the cell's figures."""
    cell, i_noise, seeds, impl_path, kwargs = job
    from blf.errors import AnalysisError
    from support.blfmaint_data import FS_HZ, envelope_case
    blf_maint = _impl(impl_path).blf_maint
    noise = NOISE[i_noise]
    b_true = cell["backlash_mm"]
    errs, kerrs, sigmas, failures = [], [], [], []
    for seed in range(seeds):
        rng = np.random.default_rng([seed, *cell["index"], i_noise])
        case = envelope_case(rng, b_true, cell["ratio"], cell["stiffness_N_per_mm"], noise)
        try:
            r = blf_maint(case.d_mm, case.f_N, FS_HZ, **kwargs)
        except AnalysisError as exc:
            failures.append(str(exc))
            continue
        errs.append(r.backlash_mm - b_true)
        sigmas.append(r.backlash_sigma_mm)
        kerrs += [r.stiffness_left_N_per_mm / case.stiffness_left_N_per_mm - 1.0,
                  r.stiffness_right_N_per_mm / case.stiffness_right_N_per_mm - 1.0]
    worst = float(np.max(np.abs(errs))) if errs else None
    return dict(
        backlash_mm=b_true, ratio=cell["ratio"], stiffness_N_per_mm=cell["stiffness_N_per_mm"], noise=noise,
        f_max_N=cell["f_max_N"], d_range_mm=cell["d_range_mm"], records=seeds, measured=len(errs),
        worst_abs_err_mm=worst, mean_err_mm=float(np.mean(errs)) if errs else None,
        mean_sigma_mm=float(np.mean(sigmas)) if sigmas else None,
        worst_stiffness_rel=float(np.max(np.abs(kerrs))) if kerrs else None,
        tolerance_mm=tolerance_mm(b_true),
        ok=bool(not failures and worst is not None and worst <= tolerance_mm(b_true)),
        failures=sorted(set(failures)),
    )


def run_sim(job: tuple) -> dict:
    """One simulated-rig variant and seed: the whole check, all three channels against the truth."""
    name, overrides, seed, impl_path, kwargs = job
    from conftest import simulate_run

    import hil.analysis.maint as hmaint
    from hil.profile.load import load_actuation, load_check, load_simrig
    from hil.record.runfolder import read_signals
    from support.profiles import write_profile_variant

    if impl_path is not None or kwargs:
        impl = _impl(impl_path)
        hmaint.blf_maint = lambda d, f, rate: impl.blf_maint(d, f, rate, **kwargs)
        hmaint.BlfMaintResult = impl.BlfMaintResult
    act = load_actuation()
    chk = load_check(None, act)
    with tempfile.TemporaryDirectory() as td:
        sim = load_simrig(write_profile_variant("simrig.toml", Path(td) / "simrig.toml", overrides))
        outcome, truth = simulate_run(Path(td) / "run", act, chk, sim, seed)
        if outcome.status != "done":
            return dict(variant=name, seed=seed, status=outcome.status, expected_status=None,
                        reason=str(outcome.reason), channels={})
        sig = read_signals(Path(td) / "run" / "signals.csv")
    an = hmaint.analyze_signals(sig, act)
    spec = {"int1": act.mechanics.backlash_spec_int_mm, "int2": act.mechanics.backlash_spec_int_mm,
            "ext": act.mechanics.backlash_spec_ext_mm}
    expected = "pass" if all(truth["backlash_mm"][ch] <= spec[ch] for ch in spec) else "fail"
    ff = an.segments.force_fight
    d_of = {"int1": an.d_int1, "int2": an.d_int2, "ext": an.d_ext}
    chans = {}
    for ch in ("int1", "int2", "ext"):
        r = an.maint[ch]
        b_true = truth["backlash_mm"][ch]
        lo, hi = np.quantile(d_of[ch][ff], [0.005, 0.995])
        row = dict(truth_mm=b_true, d_range_mm=float(hi - lo), ratio=b_true / float(hi - lo),
                   tolerance_mm=tolerance_mm(b_true))
        if isinstance(r, str):
            row.update(measured=False, error=r, ok=False)
        else:
            kt = truth["stiffness_N_per_mm"][ch]
            err = r.backlash_mm - b_true
            row.update(measured=True, backlash_mm=r.backlash_mm, err_mm=err, sigma_mm=r.backlash_sigma_mm,
                       stiffness_rel=[r.stiffness_left_N_per_mm / kt["left"] - 1.0,
                                      r.stiffness_right_N_per_mm / kt["right"] - 1.0],
                       ok=bool(abs(err) <= tolerance_mm(b_true)))
        chans[ch] = row
    return dict(variant=name, seed=seed, status=an.status, expected_status=expected, channels=chans)


def _map(fn, jobs: list, n_jobs: int) -> list:
    if n_jobs <= 1:
        return [fn(j) for j in jobs]
    with ProcessPoolExecutor(n_jobs) as ex:
        return list(ex.map(fn, jobs))


def _fmt_um(mm: float | None) -> str:
    return "   -  " if mm is None else f"{mm * 1e3:6.2f}"


def print_grid(rows: list[dict], outside: list[dict]) -> None:
    """One line per (B, ratio, stiffness): worst |B - truth| in um per noise factor (! over the target)."""
    print("\nsynthetic envelope: worst |B - truth| in um over the seeds, per noise factor "
          "(! = over the target, n/m = channels measured)")
    head = (f"{'B mm':>5} {'B/Drange':>8} {'k kN/mm':>7} {'Fmax kN':>7} {'Drange mm':>9} "
            + " ".join(f"{'noise ' + format(n, 'g'):>9}" for n in NOISE) + f" {'target um':>9} {'k err %':>7}")
    print(head)
    print("-" * len(head))
    by_cell: dict[tuple, list[dict]] = {}
    for r in rows:
        by_cell.setdefault((r["backlash_mm"], r["ratio"], r["stiffness_N_per_mm"]), []).append(r)
    for (b, ratio, k), cell in by_cell.items():
        cell.sort(key=lambda r: r["noise"])
        cols = []
        for r in cell:
            mark = "" if r["ok"] else "!"
            if r["measured"] < r["records"]:
                mark += f"{r['measured']}/{r['records']}"
            cols.append(f"{_fmt_um(r['worst_abs_err_mm']).strip() + mark:>9}")
        kerr = max((r["worst_stiffness_rel"] or 0.0) for r in cell) * 100
        print(f"{b:5g} {ratio:8g} {k / 1e3:7g} {cell[0]['f_max_N'] / 1e3:7.2f} {cell[0]['d_range_mm']:9.3f} "
              + " ".join(cols) + f" {tolerance_mm(b) * 1e3:9.1f} {kerr:7.2f}")
    print(f"\n{len(outside)} (B, ratio, stiffness) cells outside the force fight's range (force amplitude outside "
          "0.5-15 kN or D range over 4 mm) were not run.")


def print_sim(rows: list[dict]) -> None:
    print("\nsimulator (RigPlant + run_check): B - truth in um per channel and seed "
          "(ratio = truth / D range of the force fight; status: the check's, and from truth vs B_spec)")
    head = f"{'variant':<34} {'seed':>4} {'status/expected':>15}  " + "  ".join(
        f"{ch + ' truth/ratio/err':>26}" for ch in ("int1", "int2", "ext"))
    print(head)
    print("-" * len(head))
    for r in rows:
        if not r["channels"]:
            print(f"{r['variant']:<34} {r['seed']:>4} {r['status']:>15}  check not done: {r.get('reason')}")
            continue
        cols = []
        for ch in ("int1", "int2", "ext"):
            c = r["channels"][ch]
            err = f"{c['err_mm'] * 1e3:+.2f}" if c["measured"] else "NOT MEASURED"
            cols.append(f"{c['truth_mm']:>6.3f} {c['ratio']:>6.3f} {err + ('' if c['ok'] else '!'):>12}")
        st = f"{r['status']}/{r['expected_status']}" + ("" if r["status"] == r["expected_status"] else "!")
        print(f"{r['variant']:<34} {r['seed']:>4} {st:>15}  " + "  ".join(f"{c:>26}" for c in cols))
    for r in rows:
        for ch, c in r["channels"].items():
            if not c["measured"]:
                print(f"  {r['variant']} seed {r['seed']} {ch}: {c['error']}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=5, help="records per synthetic cell (default 5)")
    ap.add_argument("--sim-seeds", type=int, default=2, help="seeds per simulator variant (default 2)")
    ap.add_argument("--no-sim", action="store_true", help="synthetic grid only")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    ap.add_argument("--json", default="bench_envelope.json")
    ap.add_argument("--impl", default=None, help="module file with another blf_maint to run instead")
    ap.add_argument("--centre-slope", action="store_true", help="the paper's sloped line in the backlash")
    args = ap.parse_args()
    kwargs = {"centre_slope": True} if args.centre_slope else {}

    t0 = time.perf_counter()
    cells, outside = grid_cells()
    grid = _map(run_cell, [(c, i, args.seeds, args.impl, kwargs) for c in cells for i in range(len(NOISE))],
                args.jobs)
    t_grid = time.perf_counter() - t0
    print_grid(grid, outside)
    n_ok = sum(r["ok"] for r in grid)
    measured = sum(r["measured"] for r in grid)
    records = sum(r["records"] for r in grid)
    ratios = [r["worst_abs_err_mm"] / r["tolerance_mm"] for r in grid if r["worst_abs_err_mm"] is not None]
    summary = dict(
        cells=len(grid), cells_within_target=n_ok, records=records, records_measured=measured,
        worst_err_over_target=float(max(ratios)) if ratios else None,
        worst_abs_err_mm=float(max(r["worst_abs_err_mm"] or 0.0 for r in grid)),
        worst_stiffness_rel=float(max(r["worst_stiffness_rel"] or 0.0 for r in grid)),
        grid_s=round(t_grid, 1), seeds=args.seeds, impl=args.impl or "blf.maint.blfmaint", options=kwargs,
    )
    print(f"\n{n_ok}/{len(grid)} cells within target; {measured}/{records} records measured; worst error "
          f"{summary['worst_err_over_target']:.2f} x the target; worst stiffness error "
          f"{100 * summary['worst_stiffness_rel']:.2f} % ({t_grid:.0f} s)")
    failures = sorted({m for r in grid for m in r["failures"]})
    for m in failures[:10]:
        print(f"  not measured: {m}")

    sim_rows: list[dict] = []
    if not args.no_sim:
        t1 = time.perf_counter()
        sim_rows = _map(run_sim, [(n, o, s, args.impl, kwargs) for n, o in SIM_VARIANTS.items()
                                  for s in range(1, args.sim_seeds + 1)], args.jobs)
        print_sim(sim_rows)
        sim_ch = [c for r in sim_rows for c in r["channels"].values()]
        summary.update(
            sim_runs=len(sim_rows), sim_checks_done=sum(bool(r["channels"]) for r in sim_rows),
            sim_status_as_expected=sum(r["status"] == r["expected_status"] for r in sim_rows if r["channels"]),
            sim_channels=len(sim_ch),
            sim_channels_within_target=sum(c["ok"] for c in sim_ch),
            sim_worst_abs_err_mm=float(max((abs(c["err_mm"]) for c in sim_ch if c["measured"]), default=0.0)),
            sim_s=round(time.perf_counter() - t1, 1))
        print(f"\nsimulator: {summary['sim_checks_done']}/{len(sim_rows)} checks done, "
              f"{summary['sim_status_as_expected']} with the status the truth gives; "
              f"{summary['sim_channels_within_target']}/{len(sim_ch)} channels within target; worst |B - truth| "
              f"{summary['sim_worst_abs_err_mm'] * 1e3:.2f} um ({summary['sim_s']:.0f} s)")
    Path(args.json).write_text(json.dumps(dict(summary=summary, grid=grid, outside=[
        {k: v for k, v in c.items() if k != "index"} for c in outside], sim=sim_rows), indent=1) + "\n")
    sim_ok = all(r["channels"] and r["status"] == r["expected_status"] and all(c["ok"] for c in r["channels"].values())
                 for r in sim_rows)
    return 0 if n_ok == len(grid) and sim_ok else 1


if __name__ == "__main__":
    sys.exit(main())
