"""BLFserv accuracy over seeds, and its cost (not a test: ``python tests/bench/bench_serv.py``).

1. Accuracy: for every seed, the LVDTs are calibrated from simulated slow
   sweeps under an opposing force (blf.maint.calibration), then the normal-operation
   scenarios of sim.scenarios are simulated (sim.operation) (default rig: noise, 7.5 % pitch
   error on LVDT 1, ...) and BLFserv (improved and paper method) runs on
   D_int,1, D_int,2 and D_ext. Per scenario and channel: bias and standard
   deviation of the reading relative to the simulator's truth, worst seed,
   and how often a channel that was not traversed was reported as such. Also
   the full stroke on raw (uncalibrated) LVDT data.
2. Cost: one hour of 500 Hz data (1.8 M samples, three D channels): batch
   BLFserv time against one scipy.signal.lfilter pass over one channel, and
   the streaming monitor's cost per 2 ms sample for all three channels.

Prints a table and writes everything to JSON (``--out``, default
bench_serv.json in the current directory).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (support)

from blf.maint.calibration import fit_lvdt_calibration  # noqa: E402
from blf.serv.blfserv import BlfServMonitor, blf_serv  # noqa: E402
from blf.serv.filters import design_serv_filters  # noqa: E402
from hil.profile.load import load_simrig  # noqa: E402
from sim import operation as op  # noqa: E402
from sim import scenarios as sc  # noqa: E402

CHANNELS = ("int1", "int2", "ext")
FS = 500.0


def d_channels(rec, i_total, cal1, cal2):
    s1 = rec.s1_mm if cal1 is None else cal1.correct(rec.s1_mm)
    s2 = rec.s2_mm if cal2 is None else cal2.correct(rec.s2_mm)
    return {"int1": s1 - rec.phi1_rad / i_total, "int2": s2 - rec.phi2_rad / i_total, "ext": s2 - s1}


def accuracy(seeds: int) -> dict:
    params = load_simrig().params
    i_total = params.i_total_rad_per_mm
    gens = {
        "full_stroke": lambda r: sc.full_stroke_profile(params),
        "small_manoeuvres": lambda r: sc.small_manoeuvre_profile(params),
        "gusts": lambda r: sc.gust_profile(params, r),
        "ext_crossing": lambda r: sc.ext_crossing_profile(params),
        "cruise": lambda r: sc.cruise_profile(params, r),
    }
    rows: dict = {}
    raw: dict = {}
    for seed in range(seeds):
        rng = np.random.default_rng(1000 + seed)
        sw1 = op.simulate_calibration_sweep(params, rng, ema=1)
        sw2 = op.simulate_calibration_sweep(params, rng, ema=2)
        cal1 = fit_lvdt_calibration(sw1.x_mm, sw1.s_mm)
        cal2 = fit_lvdt_calibration(sw2.x_mm, sw2.s_mm)
        for name, gen in gens.items():
            rec = op.simulate_operation(params, gen(rng), rng)
            d = d_channels(rec, i_total, cal1, cal2)
            for ch in CHANNELS:
                r = blf_serv(d[ch], FS, keep_signals=False)
                key = (name, ch)
                e = rows.setdefault(key, {"truth": rec.expected_backlash_mm[ch], "improved": [], "paper": [],
                                          "n_improved": [], "n_paper": []})
                e["improved"].append(r.backlash_improved_mm)
                e["paper"].append(r.backlash_paper_mm)
                e["n_improved"].append(r.traversals_improved)
                e["n_paper"].append(r.traversals_paper)
            if name == "full_stroke":
                draw = d_channels(rec, i_total, None, None)
                for ch in CHANNELS:
                    r = blf_serv(draw[ch], FS, keep_signals=False)
                    e = raw.setdefault(ch, {"truth": rec.expected_backlash_mm[ch], "improved": [], "paper": [],
                                            "d_peak_to_peak_mm": []})
                    e["improved"].append(r.backlash_improved_mm)
                    e["paper"].append(r.backlash_paper_mm)
                    e["d_peak_to_peak_mm"].append(float(np.ptp(draw[ch])))
        print(f"  seed {seed + 1}/{seeds} done", file=sys.stderr)
    table = []
    for (name, ch), e in rows.items():
        row = {"scenario": name, "channel": ch, "truth_mm": e["truth"], "seeds": seeds,
               "traversals_improved_mean": float(np.mean(e["n_improved"])),
               "traversals_paper_mean": float(np.mean(e["n_paper"]))}
        for m in ("improved", "paper"):
            vals = e[m]
            if e["truth"] is None:
                row[f"{m}_not_traversed_rate"] = sum(v is None for v in vals) / len(vals)
            else:
                ok = np.array([v for v in vals if v is not None])
                rel = (ok / e["truth"] - 1.0) * 100.0
                row[f"{m}_found"] = int(ok.size)
                row[f"{m}_bias_pct"] = float(np.mean(rel)) if ok.size else None
                row[f"{m}_std_pct"] = float(np.std(rel, ddof=1)) if ok.size > 1 else None
                row[f"{m}_worst_pct"] = float(rel[np.argmax(np.abs(rel))]) if ok.size else None
                row[f"{m}_mean_mm"] = float(np.mean(ok)) if ok.size else None
        table.append(row)
    raw_rows = []
    for ch, e in raw.items():
        row = {"channel": ch, "truth_mm": e["truth"], "d_peak_to_peak_mm": float(np.mean(e["d_peak_to_peak_mm"]))}
        for m in ("improved", "paper"):
            vals = [v for v in e[m] if v is not None]
            row[f"{m}_reported"] = len(vals)
            row[f"{m}_mean_mm"] = float(np.mean(vals)) if vals else None
        raw_rows.append(row)
    return {"table": table, "uncalibrated_full_stroke": raw_rows}


def timing() -> dict:
    n = 1_800_000
    rng = np.random.default_rng(0)
    t = np.arange(n) / FS
    sigma = 0.025 / 6.0
    chans = []
    for c in range(3):
        d = sigma * (np.sqrt(2.0) if c == 2 else 1.0) * rng.standard_normal(n) + 0.02 * np.sin(2 * np.pi * 0.05 * t)
        flips = (np.arange(n) % 10_000) == 5_000  # a backlash traversal every 20 s
        d += 0.1 * (np.cumsum(flips) % 2)
        chans.append(d)
    f = design_serv_filters(FS)
    blf_serv(chans[0][:5000], FS)  # compile / warm caches

    def best(fn, reps=3):
        ts = []
        for _ in range(reps):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        return min(ts)

    t_lf = best(lambda: signal.lfilter(f.lowpass_b, f.lowpass_a, chans[0]))
    t_batch = best(lambda: [blf_serv(d, FS, keep_signals=False) for d in chans])
    t_batch_sig = best(lambda: [blf_serv(d, FS) for d in chans])
    noise = [sigma, sigma, sigma * np.sqrt(2.0)]
    t_batch_known = best(lambda: [blf_serv(d, FS, noise_std_mm=s, keep_signals=False)
                                  for d, s in zip(chans, noise, strict=True)])
    X = np.column_stack(chans)
    m = 30_000
    mon = BlfServMonitor(FS, noise)
    t0 = time.perf_counter()
    for k in range(m):
        mon.update(X[k])
    t_stream = (time.perf_counter() - t0) / m
    return {
        "samples": n, "channels": 3,
        "lfilter_pass_s": t_lf,
        "batch_s": t_batch, "batch_passes": t_batch / t_lf,
        "batch_with_signals_s": t_batch_sig, "batch_with_signals_passes": t_batch_sig / t_lf,
        "batch_known_noise_s": t_batch_known, "batch_known_noise_passes": t_batch_known / t_lf,
        "stream_us_per_sample_3ch": t_stream * 1e6,
        "stream_fraction_of_2ms": t_stream / 0.002,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--out", type=Path, default=Path("bench_serv.json"))
    ap.add_argument("--no-timing", action="store_true")
    ap.add_argument("--no-accuracy", action="store_true")
    args = ap.parse_args()
    res: dict = {}
    if not args.no_accuracy:
        res["accuracy"] = accuracy(args.seeds)
        print(f"\nBLFserv vs truth over {args.seeds} seeds (calibrated LVDTs; % of truth)")
        print(f"{'scenario':17s} {'ch':4s} {'truth':>6s} | {'improved bias':>13s} {'std':>5s} {'worst':>6s} "
              f"{'n':>4s} | {'paper bias':>10s} {'std':>5s} {'worst':>6s} {'n':>4s}")
        for r in res["accuracy"]["table"]:
            if r["truth_mm"] is None:
                print(f"{r['scenario']:17s} {r['channel']:4s} {'none':>6s} | not traversed reported in "
                      f"{r['improved_not_traversed_rate']:.0%} (improved), {r['paper_not_traversed_rate']:.0%} "
                      f"(paper) of the seeds")
                continue

            def f(x, w=6, p=1):
                return f"{x:+{w}.{p}f}" if x is not None else " " * (w - 1) + "-"
            print(f"{r['scenario']:17s} {r['channel']:4s} {r['truth_mm']:6.3f} | {f(r['improved_bias_pct'], 12)}% "
                  f"{f(r['improved_std_pct'], 4)} {f(r['improved_worst_pct'])} {r['traversals_improved_mean']:4.1f} | "
                  f"{f(r['paper_bias_pct'], 9)}% {f(r['paper_std_pct'], 4)} {f(r['paper_worst_pct'])} "
                  f"{r['traversals_paper_mean']:4.1f}")
        print("\nfull stroke on raw (uncalibrated) LVDT data:")
        for r in res["accuracy"]["uncalibrated_full_stroke"]:
            def mm(x):
                return "-" if x is None else f"{x:.4f} mm"
            print(f"  {r['channel']}: truth {mm(r['truth_mm'])}, D peak-to-peak {r['d_peak_to_peak_mm']:.2f} mm, "
                  f"improved {mm(r['improved_mean_mm'])} ({r['improved_reported']} seeds reported), "
                  f"paper {mm(r['paper_mean_mm'])} ({r['paper_reported']} seeds reported)")
    if not args.no_timing:
        tm = timing()
        res["timing"] = tm
        print(f"\none hour at 500 Hz, three channels ({tm['samples']} samples each):")
        print(f"  one lfilter pass over one channel: {tm['lfilter_pass_s'] * 1e3:.1f} ms")
        print(f"  batch BLFserv, noise estimated:    {tm['batch_s'] * 1e3:.0f} ms = {tm['batch_passes']:.1f} passes")
        print(f"  batch BLFserv, noise given:        {tm['batch_known_noise_s'] * 1e3:.0f} ms = "
              f"{tm['batch_known_noise_passes']:.1f} passes")
        print(f"  batch BLFserv with filter outputs: {tm['batch_with_signals_s'] * 1e3:.0f} ms = "
              f"{tm['batch_with_signals_passes']:.1f} passes")
        print(f"  streaming, per 2 ms sample, 3 ch:  {tm['stream_us_per_sample_3ch']:.1f} us "
              f"({tm['stream_fraction_of_2ms']:.1%} of the real-time budget)")
    args.out.write_text(json.dumps(res, indent=1))
    print(f"\nwritten {args.out}")


if __name__ == "__main__":
    main()
