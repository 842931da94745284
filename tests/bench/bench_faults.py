"""Benchmark (not a test): every injected fault in a dry-run; reaction time, peak true force, data kept.

    python tests/bench/bench_faults.py [--json bench_faults.json] [--stalls] [--only NAME ...]

For each fault of :mod:`sim.faults` (the cases of tests/test_faults.py plus the
force- and stroke-limit runaways) it prints: what detected it, the reaction
time from the onset (the fault's start; for the limit cases from the first
sample beyond the limit), when the quick stop / disable reached the drives,
the peak true force and stroke after the onset (plant truth, no sensor
errors), the drives' final states and the data kept in the run folder
(signals rows, the last sample time, CAN frames logged).

The master's stalls (``dry-run --master-stall-ms``, the rows of tests/test_faults.py ``STALL_CASES``; only
these with ``--stalls``): reaction from the stall's begin (over the limit) or the runaway's onset (an
overspeed inside a stall) to the stall's end, when the master takes the backlog and reacts; stop from there.

``master_silent`` (the master's death, at the force fight's 6 kN) is detected
by the drives, not the master: its reaction is from the master's last frame to
the later of the two drives' heartbeat events (EMCY 0x8130, quick stop), its
stop from there to both out of Operation enabled in the plant truth, and the
row adds when both were in Switch on disabled (``sod_ms``, from the last frame).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (conftest, support)

from test_faults import CASES, STALL_CASES, T, _first_stall_s, _t_detect, _t_safe_command  # noqa: E402
from test_master_loss import silent_figures  # noqa: E402

from hil.cli.dry_run import dry_run  # noqa: E402
from hil.profile.load import load_actuation, load_check, load_simrig  # noqa: E402
from hil.record.runfolder import (  # noqa: E402
    read_record,
    read_signals,  # noqa: E402
)
from sim.faults import Fault  # noqa: E402
from support.profiles import write_profile_variant  # noqa: E402


def _limit_checks(act, tmp: Path):
    """The check profiles of the force- and stroke-limit runaways (as in tests/test_faults.py)."""
    f = write_profile_variant("check.toml", tmp / "force.toml", {"safety": {
        "max_following_error_mm": 2.0, "max_force_fight_N": 7900.0, "max_force_imbalance_N": 4000.0}})
    s = write_profile_variant("check.toml", tmp / "stroke.toml", {
        "calibration": {"sweep_amplitude_mm": 2.5},
        "safety": {"max_stroke_mm": 3.0, "max_following_error_mm": 2.0}})
    return load_check(f, act), load_check(s, act)


def _stall_rows(act, chk, sim, tmp: Path) -> list[dict]:
    """The rows of the master's stalls (tests/test_faults.py ``STALL_CASES``)."""
    rows = []
    for k, (stall_ms, every_s, runaway, _words) in enumerate(STALL_CASES):
        t_stall = _first_stall_s(sim.seed, every_s)
        end = t_stall + stall_ms / 1000.0
        faults = [Fault("runaway", 1, t_stall + 2 * T, value=15.0)] if runaway else []
        r = dry_run(act, chk, sim, tmp / f"stall{k}", faults=faults, stall=(stall_ms, every_s))
        meta = json.loads((r.out / "meta.json").read_text())
        st, tr, sig = meta["stalls"], r.injector.truth, read_signals(r.out / "signals.csv")
        name = f"master stalls {stall_ms:g} ms / {every_s:g} s" + (", runaway 15 mm/s in one" if runaway else "")
        row = {"fault": name, "ema": 1 if runaway else None, "status": meta["status"],
               "stalls": st["count"], "longest_ms": st["longest_ms"], "rows": int(sig.n),
               "frames_logged": meta["can"]["frames_logged"], "last_t_s": float(sig.t[-1])}
        if meta["status"] == "done":
            row.update(detected_by=f"— (passes; {st['count']} stalls recorded)", reaction_ms=None, stop_ms=None,
                       peak_F_N=round(float(np.abs(tr.F_N).max()), 0), peak_s_mm=round(float(np.abs(tr.s_mm).max()), 3))
        else:
            onset = t_stall + 2 * T if runaway else t_stall
            m = tr.t_s >= onset
            row.update(detected_by=meta.get("safety", {}).get("limit") or "StaleData: safety.max_stale_ms",
                       reaction_ms=round((end - onset) * 1e3, 1),
                       stop_ms=round((_t_safe_command(tr, end) - end) * 1e3, 1),
                       peak_F_N=round(float(np.abs(tr.F_N[m]).max()), 0),
                       peak_s_mm=round(float(np.abs(tr.s_mm[m]).max()), 3))
        row["final"] = " / ".join(s.name for s in r.injector.final_states())
        rows.append(row)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default="bench_faults.json")
    ap.add_argument("--stalls", action="store_true", help="only the rows of the master's stalls")
    ap.add_argument("--only", nargs="+", metavar="NAME", default=None,
                    help="only the fault rows of these names (e.g. tpdo_missing tpdo_late bus_errors node_silent; "
                         "with --stalls also the stall rows, else none)")
    args = ap.parse_args()
    act = load_actuation()
    chk = load_check(None, act)
    sim = load_simrig()
    rows = []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        f_chk, s_chk = _limit_checks(act, tmp)
        cases = [(c[0], chk, c[0].kind) for c in CASES] + [
            (Fault("node_silent", 2, 2.0), chk, "node_silent"),
            (Fault("sdo_abort", 2, value=float(0x1017)), chk, "sdo_abort"),
            (Fault("runaway", 1, 0.6, value=5.0), f_chk, "runaway -> force limit"),
            (Fault("runaway", 1, 2.7, value=5.0), s_chk, "runaway -> stroke limit"),
            (Fault("master_silent", 1, 78.0), chk, "master_silent"),
        ]
        if args.only is not None:
            unknown = sorted(set(args.only) - {c[2] for c in cases})
            if unknown:
                ap.error(f"--only: no fault row named {', '.join(unknown)} (rows: {', '.join(c[2] for c in cases)})")
            cases = [c for c in cases if c[2] in args.only]
        for k, (fault, check, name) in enumerate([] if args.stalls and args.only is None else cases):
            r = dry_run(act, check, sim, tmp / f"run{k}", faults=[fault])
            meta = json.loads((r.out / "meta.json").read_text())
            tr = r.injector.truth
            row = {"fault": name, "ema": fault.ema, "status": meta["status"],
                   "detected_by": meta.get("safety", {}).get("limit") or meta["reason"].split(":")[1].strip(),
                   "frames_logged": meta["can"]["frames_logged"]}
            if fault.kind == "master_silent":
                fig = silent_figures(r, act)
                det = max(fig["event_s"].values())
                sig = read_signals(r.out / "signals.csv")
                row.update(detected_by="drives' consumer (EMCY 0x8130)", reaction_ms=round(det * 1e3, 1),
                           stop_ms=round((fig["out_of_oe_s"] - det) * 1e3, 1), sod_ms=round(fig["sod_s"] * 1e3, 1),
                           peak_F_N=round(fig["peak_F_N"], 0), peak_s_mm=round(fig["peak_s_mm"], 3), rows=int(sig.n),
                           last_t_s=float(sig.t[-1]), t_detect_s=round(fig["t_last_s"] + det, 4))
            elif r.injector.syncs == 0:
                row.update(reaction_ms=None, stop_ms=None, peak_F_N=0.0, peak_s_mm=float("nan"), rows=0)
            else:
                onset = r.injector.onset_s.get(fault.kind, fault.start_s)
                t_det = _t_detect(r, read_record(r.out))
                sig = read_signals(r.out / "signals.csv")
                if "limit" in name:
                    lim = meta["safety"]["threshold"]
                    q = {"max_force_N": np.maximum(np.abs(sig.F1), np.abs(sig.F2)),
                         "max_force_fight_N": np.abs(sig.F1 - sig.F2) / 2,
                         "max_stroke_mm": np.maximum(np.abs(sig.s1), np.abs(sig.s2))}[meta["safety"]["limit"]]
                    onset = float(sig.t[np.flatnonzero(q > lim)[0]])
                reach = (0,) if fault.kind == "node_silent" else ((2 - fault.ema,) if fault.kind == "rpdo_lost"
                                                                  else (0, 1))
                m = tr.t_s >= onset
                row.update(reaction_ms=round((t_det - onset) * 1e3, 1),
                           stop_ms=round((_t_safe_command(tr, t_det, reach) - t_det) * 1e3, 1),
                           peak_F_N=round(float(np.abs(tr.F_N[m]).max()), 0),
                           peak_s_mm=round(float(np.abs(tr.s_mm[m]).max()), 3),
                           rows=int(sig.n), last_t_s=float(sig.t[-1]), t_detect_s=round(t_det, 4))
            row["final"] = " / ".join(s.name for s in r.injector.final_states())
            rows.append(row)
        if args.only is None or args.stalls:
            rows += _stall_rows(act, chk, sim, tmp)
    hdr = (f"{'fault':<26}{'detected by':<26}{'reaction ms':>12}{'stop ms':>9}{'peak |F| N':>11}"
           f"{'peak |s| mm':>12}{'rows':>7}{'frames':>8}  final states")
    print(hdr)
    for r in rows:
        print(f"{r['fault']:<26}{r['detected_by'][:25]:<26}{str(r['reaction_ms']):>12}{str(r['stop_ms']):>9}"
              f"{r['peak_F_N']:>11.0f}{r['peak_s_mm']:>12.3f}{r['rows']:>7}{r['frames_logged']:>8}  {r['final']}")
    Path(args.json).write_text(json.dumps({"sync_period_ms": T * 1e3, "faults": rows}, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
