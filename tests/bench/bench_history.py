"""Benchmark (not a test): the wear history's speed at fleet size and the wear statistics' coverage.

1. Speed, on SQLite and on PostgreSQL (a server started here, fsync on, as a station runs it):
   10,000 actuators (5,000 pairs) x 50 checks each = 250,000 results and 750,000 readings, then
   ``emacheck history --actuator X`` (in the process: open, query, trends, console or JSON out; and
   the whole command as a new process, interpreter start included) and one insert (on an open
   store, and the whole recording after a check: open, schema check, insert, close).
   Targets: history --actuator under 0.5 s, one insert under 50 ms.
2. The wear scenario (tests/support/wear.py: 0.025 / 0.020 / 0.010 mm per 1000 FH, scatter 2 um,
   B_spec 0.2 mm), 12 checks of one pair over 3000 FH, 20 seeds, through the plant and BLFmaint
   (the check on the simulated rig worn to each check's flight hours, analysed as `emacheck
   simulate` does, recorded, `history` trends): how often the 95 % intervals of the rate and of
   the B_spec crossing cover the simulated truth (target: at least 17 of 20). And the same
   statistics on readings drawn from the truth with the stated uncertainty, 2,000 seeds.

Usage: python tests/bench/bench_history.py [--json bench_history.json] [--pairs 5000] [--checks 50]
       [--seeds 20] [--no-e2e] [--no-postgres] [--workers 2]
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as _dt
import io
import json
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # the repository (hil, blf, sim)
sys.path.insert(1, str(ROOT / "tests"))  # support

import numpy as np  # noqa: E402 (after the repository is put on sys.path)

CHANNELS = ("int1", "int2", "ext")
VENDOR, PRODUCT = 0x0E3A, 0x0402


# ------------------------------------------------------------------------------------------- speed


def fill(url: str, pairs: int, checks: int) -> float:
    """Bulk-load ``pairs`` x ``checks`` results (explicit ids, executemany); returns seconds."""
    import sqlalchemy as sa

    from hil.history import schema as S
    from hil.history.store import HistoryStore

    t0 = time.perf_counter()
    rng = np.random.default_rng(1)
    start = _dt.datetime(2020, 1, 1)
    with HistoryStore.open(url) as store, store._tx(write=True) as conn:
        conn.execute(sa.insert(S.actuators), [{"id": i + 1, "vendor_id": VENDOR, "product_code": PRODUCT,
                                               "serial": 0x10000000 + i} for i in range(2 * pairs)])
        batch_c, batch_r = [], []
        for p in range(pairs):
            b0 = 0.08 + 0.04 * rng.random(3)
            rate = 1e-5 * (1.0 + rng.random(3))
            for k in range(checks):
                cid = p * checks + k + 1
                fh = 60.0 * k
                batch_c.append({
                    "id": cid, "result_sha256": f"{cid:064x}", "run_key": f"bench-{cid}", "run_id": f"bench-{cid}",
                    "kind": "maint", "simulated": False, "mode": "run", "time_utc": start + _dt.timedelta(days=7 * k),
                    "analysed_utc": start + _dt.timedelta(days=7 * k, minutes=3), "recorded_utc": start,
                    "aircraft": f"D-A{p:04d}", "position": "left aileron", "rig": "bench", "operator": "bench",
                    "work_order": f"WO-{cid}", "flight_hours": fh, "flight_cycles": int(fh * 0.8), "status": "pass",
                    "software_version": "0.1.0", "check_software_version": "0.1.0", "limit_int_mm": 0.2,
                    "limit_ext_mm": 0.2, "ema1_actuator_id": 2 * p + 1, "ema2_actuator_id": 2 * p + 2,
                    "ema1_revision": 0x10000, "ema2_revision": 0x10000, "ema1_node": 1, "ema2_node": 2,
                    "ema1_lvdt_pitch": 1.075, "ema2_lvdt_pitch": 0.98, "run_folder": f"/runs/{cid}"})
                y = b0 + rate * fh + rng.normal(0.0, 0.003, 3)
                batch_r += [{"check_id": cid, "channel": ch, "backlash_mm": float(y[j]), "uncertainty_mm": 0.006,
                             "limit_mm": 0.2, "margin_mm": 0.2 - float(y[j]), "verdict": "pass", "reason": "",
                             "stiffness_left_N_per_mm": 8e4, "stiffness_right_N_per_mm": 8e4}
                            for j, ch in enumerate(CHANNELS)]
            if len(batch_c) >= 5000 or p == pairs - 1:
                conn.execute(sa.insert(S.checks), batch_c)
                conn.execute(sa.insert(S.readings), batch_r)
                batch_c, batch_r = [], []
        if store.dialect == "postgresql":  # explicit ids: move the sequences past them
            for t in ("emacheck_checks", "emacheck_actuators"):
                conn.execute(sa.text(f"SELECT setval(pg_get_serial_sequence('{t}', 'id'), (SELECT max(id) FROM {t}))"))
    with HistoryStore.open(url) as store, store._tx(write=True) as conn:
        conn.exec_driver_sql("ANALYZE")
    return time.perf_counter() - t0


def speed(url: str, pairs: int, checks: int) -> dict:
    from hil.cli import main as cli
    from hil.history.record import record_from_result
    from hil.history.store import HistoryStore
    from hil.history.sync import record_after_check
    from support.wear import wear_results

    res = {"fill_s": round(fill(url, pairs, checks), 1)}
    rng = np.random.default_rng(2)
    serials = [0x10000000 + int(i) for i in rng.integers(0, 2 * pairs, 21)]
    for mode in ("console", "json"):
        times = []
        for s in serials:
            argv = ["history", "--history", url, "--actuator", str(s)] + (["--json"] if mode == "json" else [])
            t0 = time.perf_counter()
            with contextlib.redirect_stdout(io.StringIO()) as buf:
                assert cli(argv) == 0
            times.append(time.perf_counter() - t0)
            if mode == "json":
                doc = json.loads(buf.getvalue())
                assert len(doc["checks"]) == checks, len(doc["checks"])
        res[f"history_actuator_{mode}_s"] = {"first": round(times[0], 3),
                                             "median": round(statistics.median(times[1:]), 3),
                                             "max": round(max(times[1:]), 3)}
    proc = []
    for s in serials[:3]:
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "hil.cli", "history", "--history", url, "--actuator", str(s)],
                           cwd=ROOT, capture_output=True, text=True)
        proc.append(time.perf_counter() - t0)
        assert r.returncode == 0, r.stderr
    res["history_actuator_process_s"] = round(statistics.median(proc), 2)
    base = wear_results(n=1, seed=5, simulated=False)[0]
    recs = []
    for _ in range(31):
        r = json.loads(json.dumps(base))
        r["trace"]["run_id"] = uuid.uuid4().hex
        r["trace"]["identity"]["ema1"]["serial"] = serials[0]
        recs.append(record_from_result(r))
    ins = []
    with HistoryStore.open(url) as store:
        for rec in recs:
            t0 = time.perf_counter()
            assert store.add(rec)
            ins.append(time.perf_counter() - t0)
    res["insert_open_store_ms"] = {"median": round(1e3 * statistics.median(ins[1:]), 2),
                                   "max": round(1e3 * max(ins[1:]), 2)}
    full = []
    with tempfile.TemporaryDirectory() as td:
        for k in range(10):
            r = json.loads(json.dumps(base))
            r["trace"]["run_id"] = uuid.uuid4().hex
            p = Path(td) / f"r{k}.json"
            p.write_text(json.dumps(r))
            t0 = time.perf_counter()
            assert record_after_check(url, p, run_folder=None, recording=None, say=lambda m: None)
            full.append(time.perf_counter() - t0)
    res["record_after_check_ms"] = {"median": round(1e3 * statistics.median(full[1:]), 1),
                                    "max": round(1e3 * max(full[1:]), 1)}
    return res


# ------------------------------------------------------------------------------ wear coverage (e2e)


def e2e_seed(seed: int) -> dict:
    """12 checks of one pair over 3000 FH through the plant and BLFmaint, recorded; the trends' coverage."""
    from hil.analysis.maint import analyze_signals, result_dict
    from hil.check.runner import PlantLink, run_check
    from hil.cli.check import simulated_identity, truth_dict
    from hil.cli.result import trace_of
    from hil.history.record import record_from_result
    from hil.history.store import HistoryStore
    from hil.history.trends import build_series, history_document
    from hil.profile.load import load_actuation, load_check, load_simrig
    from hil.record.runfolder import MetaWriter, read_signals
    from hil.record.runrecord import Installation, RunMode, start_record
    from sim.plant import RigPlant
    from sim.truth import apply_wear, rig_truth
    from support.wear import WEAR, true_crossing_fh

    act = load_actuation()
    check = load_check(None, act)
    simrig = load_simrig()
    start = _dt.datetime(2025, 1, 6, 8, 0)
    with tempfile.TemporaryDirectory() as td:
        url = f"sqlite:///{td}/h.sqlite"
        with HistoryStore.open(url) as store:
            for k, fh in enumerate(np.linspace(0.0, 3000.0, 12)):
                params = apply_wear(simrig.params, WEAR, float(fh), np.random.default_rng([seed, k, 0x16]))
                truth = truth_dict(rig_truth(params))
                out = Path(td) / f"run{k}"
                t = start + _dt.timedelta(days=30 * k)
                meta = MetaWriter(out, start_record(
                    act, check, mode=RunMode.SIMULATE, seed=seed, truth=truth, started_utc=t.isoformat() + "+00:00",
                    identity=simulated_identity(act, simrig),
                    installation=Installation(aircraft="D-AXYZ", position="left aileron", flight_hours=float(fh))))
                plant = RigPlant(params, np.random.default_rng([seed, k]))
                outcome = run_check(PlantLink(plant), act, check, meta)
                assert outcome.status == "done", outcome.reason
                result = result_dict(analyze_signals(read_signals(out / "signals.csv"), act), act, truth)
                result["trace"] = trace_of(meta.record, out / "signals.csv")
                store.add(record_from_result(result, result_path=out / "result.json", run_folder=out))
            rows = store.checks()
    doc = history_document(rows, build_series(rows), url="bench", filters={})
    cov = {}
    for t in doc["trends"]:
        ch = t["channel"]
        rate = WEAR.rate_mm_per_1000_fh(ch)
        lo, hi = t["rate_interval_95"]
        flo, fhi = t["limit_at_fh_interval"]
        truth_x = true_crossing_fh(ch, t["limit_mm"])
        cov[ch] = {"rate": t["rate_mm_per_1000_fh"], "rate_sigma": t["rate_sigma"], "rate_covered": lo <= rate <= hi,
                   "limit_at_fh": t["limit_at_fh"], "interval": [flo, fhi], "truth_fh": truth_x,
                   "crossing_covered": (flo if flo is not None else -np.inf) <= truth_x
                   <= (fhi if fhi is not None else np.inf), "chi2_per_dof": t["chi2_per_dof"], "n": t["n"]}
    return cov


def synthetic_coverage(n_seeds: int) -> dict:
    """The statistics alone on readings drawn from the truth with the stated uncertainty."""
    from blf.wear import fit_wear, limit_crossing
    from support.wear import U_MM, WEAR, true_crossing_fh, wear_results

    hits = {ch: [0, 0] for ch in CHANNELS}
    for seed in range(n_seeds):
        res = wear_results(n=12, fh_max=3000.0, seed=seed)
        x = np.array([r["trace"]["flight_hours"] for r in res])
        for ch in CHANNELS:
            f = fit_wear(x, [r["backlash_mm"][ch] for r in res], np.full(12, U_MM[ch]))
            rate = WEAR.rate_mm_per_1000_fh(ch) / 1000.0
            hits[ch][0] += abs(f.rate - rate) <= f.quantile * f.rate_sigma
            c = limit_crossing(f, 0.2)
            hits[ch][1] += c.lo <= true_crossing_fh(ch, 0.2) <= c.hi
    return {ch: {"rate": round(h[0] / n_seeds, 3), "crossing": round(h[1] / n_seeds, 3)} for ch, h in hits.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", default="bench_history.json")
    ap.add_argument("--pairs", type=int, default=5000, help="actuator pairs (2 actuators each)")
    ap.add_argument("--checks", type=int, default=50, help="checks per pair")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-e2e", action="store_true", help="skip the wear scenario through the plant")
    ap.add_argument("--no-postgres", action="store_true")
    ap.add_argument("--no-speed", action="store_true")
    args = ap.parse_args()
    out: dict = {"actuators": 2 * args.pairs, "checks_per_actuator": args.checks}
    if not args.no_speed:
        with tempfile.TemporaryDirectory() as td:
            out["sqlite"] = speed(f"sqlite:///{td}/h.sqlite", args.pairs, args.checks)
            print("sqlite:", json.dumps(out["sqlite"]), flush=True)
        if not args.no_postgres:
            from support import postgres

            try:
                srv = postgres.start(durable=True)
            except postgres.Unavailable as exc:
                out["postgresql"] = {"skipped": str(exc)}
            else:
                try:
                    out["postgresql"] = speed(srv.new_database("bench"), args.pairs, args.checks)
                finally:
                    srv.stop()
            print("postgresql:", json.dumps(out["postgresql"]), flush=True)
    t0 = time.perf_counter()
    out["synthetic_coverage_2000_seeds"] = synthetic_coverage(2000)
    out["synthetic_s"] = round(time.perf_counter() - t0, 1)
    print("statistics on drawn readings, 2000 seeds:", json.dumps(out["synthetic_coverage_2000_seeds"]), flush=True)
    if not args.no_e2e:
        import multiprocessing as mp

        t0 = time.perf_counter()
        with mp.get_context("spawn").Pool(args.workers) as pool:
            per_seed = pool.map(e2e_seed, range(args.seeds))
        e2e = {"seeds": args.seeds, "wall_s": round(time.perf_counter() - t0, 1), "per_channel": {}}
        for ch in CHANNELS:
            rs = [s[ch] for s in per_seed]
            e2e["per_channel"][ch] = {
                "rate_covered": sum(r["rate_covered"] for r in rs),
                "crossing_covered": sum(r["crossing_covered"] for r in rs),
                "rate_median": statistics.median(r["rate"] for r in rs),
                "rate_sigma_median": statistics.median(r["rate_sigma"] for r in rs),
                "limit_at_fh_median": statistics.median(r["limit_at_fh"] for r in rs),
                "truth_fh": rs[0]["truth_fh"],
                "chi2_per_dof_median": statistics.median(r["chi2_per_dof"] for r in rs)}
        e2e["detail"] = per_seed
        out["e2e"] = e2e
        for ch, v in e2e["per_channel"].items():
            print(f"e2e {ch}: rate covered {v['rate_covered']}/{args.seeds}, crossing covered "
                  f"{v['crossing_covered']}/{args.seeds}; rate median {v['rate_median']:.4f} (sigma "
                  f"{v['rate_sigma_median']:.4f}) mm/1000 FH, crossing median {v['limit_at_fh_median']:.0f} FH "
                  f"(truth {v['truth_fh']:.0f}), chi2/dof median {v['chi2_per_dof_median']:.2f}", flush=True)
    Path(args.json).write_text(json.dumps(out, indent=1, default=str) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
