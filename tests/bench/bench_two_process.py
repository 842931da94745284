"""Benchmark (not a test): N two-process checks at the shipped SYNC rate over udp_multicast.

Each check is two processes on this machine, as on a hardware-in-the-loop
bench: ``emacheck sim-serve`` (the simulated drives, ``--timing-json``) and
``emacheck run --arm`` (the master), on a multicast group of their own
(239.74.<pid-derived>.<k>), with the shipped profiles unless given. After each
check sim-serve is stopped (SIGINT) and the figures are read back: the run's
meta.json (status, reason, ``timing``: the master's reaction = SYNC in to
RPDOs out, its work per cycle, SYNC to SYNC), its result.json (the verdict)
and sim-serve's JSON (its reaction = SYNC in to TPDOs out).

``--competitor`` runs one CPU-bound process (a Python busy loop) alongside the
whole time. ``uptime``'s load average is recorded before and after. Both
processes run under SCHED_FIFO as on a rig (``--rt-priority``: sim-serve 50,
run 40, as bench_vcan.py) unless ``--rt-sim 0 --rt-run 0``.

First measures the machine's floor (``--floor-s``, default 20 s): a lone
process sleeping to 2 ms deadlines, how late it wakes, then running for half
as long, the longest it was held while it ran (a virtual machine's vCPU
descheduled by its host); no loop can be more punctual than that. Prints
one line per check, then completions, per process the reaction's p50, p99,
p99.9 and max over all checks (max of each check's percentile), the abort
causes; writes everything to JSON (``--json``, default bench_two_process.json).

Usage: python tests/bench/bench_two_process.py [-n 10] [--competitor] [--rt-sim 50] [--rt-run 40] [--check CHECK.toml]
       [--profile ACTUATION.toml] [--sim SIMRIG.toml] [--json FILE] [--keep DIR] [--floor-s 20]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]


def _load() -> str:
    return Path("/proc/loadavg").read_text().split(" ", 3)[:3].__str__()


def _cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "hil", *args]


def _profile_args(a) -> list[str]:
    out = []
    if a.profile:
        out += ["--profile", str(a.profile)]
    return out


def one_check(k: int, a, folder: Path) -> dict:
    channel = f"239.74.{(os.getpid() >> 8) % 250 + 1}.{(os.getpid() + k) % 250 + 1}"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    sim_json = folder / f"sim{k}.json"
    run_dir = folder / f"run{k}"
    rt_sim = ["--rt-priority", str(a.rt_sim)] if a.rt_sim else []
    rt_run = ["--rt-priority", str(a.rt_run)] if a.rt_run else []
    sim_cmd = _cmd("sim-serve", "--interface", "udp_multicast", "--channel", channel, *rt_sim,
                   "--timing-json", str(sim_json), *_profile_args(a), *(["--sim", str(a.sim)] if a.sim else []))
    sim = subprocess.Popen(sim_cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=ROOT)
    t_ready = time.monotonic() + 60
    ready = False
    sim_out = []
    while time.monotonic() < t_ready:
        line = sim.stdout.readline()
        if not line:
            break
        sim_out.append(line.rstrip())
        if line.rstrip().endswith("ready"):
            ready = True
            break
    if not ready:
        sim.kill()
        return {"k": k, "channel": channel, "status": "sim-serve not ready", "sim_out": sim_out}
    run_cmd = _cmd("run", "--interface", "udp_multicast", "--channel", channel, "--arm", "--quiet", "--no-history",
                   *rt_run,
                   "--out", str(run_dir), *_profile_args(a), *(["--check", str(a.check)] if a.check else []))
    t0 = time.monotonic()
    try:
        r = subprocess.run(run_cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=a.timeout)
        rc, run_out = r.returncode, r.stdout + r.stderr
    except subprocess.TimeoutExpired as exc:
        rc, run_out = None, f"timed out after {a.timeout} s: {exc.stdout}"
    wall = time.monotonic() - t0
    sim.send_signal(signal.SIGINT)
    try:
        rest, _ = sim.communicate(timeout=20)
        sim_out += rest.splitlines()
    except subprocess.TimeoutExpired:
        sim.kill()
        sim_out.append("sim-serve did not stop within 20 s of SIGINT: killed")
    meta = json.loads((run_dir / "meta.json").read_text()) if (run_dir / "meta.json").exists() else {}
    result = json.loads((run_dir / "result.json").read_text()) if (run_dir / "result.json").exists() else {}
    simj = json.loads(sim_json.read_text()) if sim_json.exists() else {}
    return {"k": k, "channel": channel, "rc": rc, "wall_s": round(wall, 2), "status": meta.get("status"),
            "verdict": result.get("status"), "reason": meta.get("reason"), "safety": meta.get("safety"),
            "can": meta.get("can"), "master_timing": meta.get("timing"), "sim": simj,
            "run_out_tail": run_out.splitlines()[-12:], "sim_out": sim_out[-8:]}


def cause(r: dict) -> str:
    """Which process was late, and how, for an aborted check."""
    mt = r.get("master_timing") or {}
    st = (r.get("sim") or {}).get("timing") or {}
    bits = []
    if mt:
        bits.append(f"master: reaction max {mt['reaction']['max_ms']:.2f} ms, {mt['late']} late, "
                    f"{mt['unanswered']} unanswered, SYNC skipped {mt.get('sync_skipped')}, "
                    f"SYNC late max {mt.get('sync_late_max_ms')} ms, "
                    f"periods without a SYNC {mt.get('sync_periods_skipped')}, "
                    f"lag max {(r.get('can') or {}).get('max_lag_ms')} ms")
    if st:
        bits.append(f"sim-serve: reaction max {st['reaction']['max_ms']:.2f} ms, {st['late']} late, "
                    f"{st['unanswered']} unanswered, SYNC gaps max {st['gap']['max_ms']:.2f} ms "
                    f"({st['syncs_missing']} periods missing), {(r.get('sim') or {}).get('rpdos_late')} late RPDOs")
    return "; ".join(bits)


#: a lone process sleeping to 2 ms deadlines (select, as the loops wait), SCHED_FIFO where permitted:
#: how late this machine wakes a sleeping process, whatever emacheck does (printed as JSON)
_FLOOR = """
import json, os, select, socket, sys, time
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(40))
except OSError:
    pass
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
T, late = 0.002, []
t_next = time.monotonic() + T
end = t_next + float(sys.argv[1])
while t_next < end:
    while (now := time.monotonic()) < t_next:
        select.select([s], [], [], t_next - now)
    late.append(now - t_next)
    t_next += T
late.sort()
n = len(late)
# then running, not sleeping, for half as long: the longest time the process was held while it ran
# (at normal priority: a SCHED_FIFO process that never sleeps is stopped by Linux's real-time
# throttling, 50 ms in every second)
os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
held, t_prev = [], time.monotonic()
end = t_prev + float(sys.argv[1]) / 2
while (now := time.monotonic()) < end:
    if now - t_prev > 1e-4:
        held.append(now - t_prev)
    t_prev = now
print(json.dumps({"seconds": float(sys.argv[1]), "n": n, "p50_ms": late[n // 2] * 1e3,
                  "p99.9_ms": late[int(n * 0.999)] * 1e3, "max_ms": late[-1] * 1e3,
                  "over_1ms": sum(x > 1e-3 for x in late), "over_3ms": sum(x > 3e-3 for x in late),
                  "held_max_ms": max(held, default=0.0) * 1e3, "held_over_1ms": sum(x > 1e-3 for x in held)}))
"""


def wake_floor(seconds: float) -> dict:
    """How late a lone process sleeping to 2 ms deadlines wakes on this machine (p50, p99.9, max [ms])."""
    r = subprocess.run([sys.executable, "-c", _FLOOR, str(seconds)], capture_output=True, text=True, check=True)
    return json.loads(r.stdout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=10, help="checks (default 10)")
    ap.add_argument("--competitor", action="store_true", help="one CPU-bound process alongside")
    ap.add_argument("--check", type=Path)
    ap.add_argument("--profile", type=Path)
    ap.add_argument("--sim", type=Path)
    ap.add_argument("--rt-sim", type=int, default=50, help="sim-serve's --rt-priority (default 50; 0: normal)")
    ap.add_argument("--rt-run", type=int, default=40, help="run's --rt-priority (default 40; 0: normal)")
    ap.add_argument("--timeout", type=float, default=600.0, help="per check [s]")
    ap.add_argument("--json", type=Path, default=Path("bench_two_process.json"))
    ap.add_argument("--keep", type=Path, help="keep the run folders here")
    ap.add_argument("--floor-s", type=float, default=20.0,
                    help="first measure this machine's wake-up floor for this long [s] (0: not)")
    a = ap.parse_args(argv)
    floor = wake_floor(a.floor_s) if a.floor_s > 0 else None
    if floor is not None:
        print(f"wake-up floor (a lone process sleeping to 2 ms deadlines, {a.floor_s:.0f} s): p50 "
              f"{floor['p50_ms']:.3f}  p99.9 {floor['p99.9_ms']:.3f}  max {floor['max_ms']:.3f} ms late; "
              f"{floor['over_1ms']} over 1 ms, {floor['over_3ms']} over 3 ms; running for {a.floor_s / 2:.0f} s, "
              f"held at most {floor['held_max_ms']:.3f} ms, {floor['held_over_1ms']} times over 1 ms", flush=True)
    comp = None
    if a.competitor:
        comp = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    load0 = _load()
    rows = []
    try:
        with tempfile.TemporaryDirectory(prefix="emacheck-2p-") as tmp:
            folder = a.keep or Path(tmp)
            folder.mkdir(parents=True, exist_ok=True)
            for k in range(a.n):
                r = one_check(k, a, folder)
                rows.append(r)
                mt, st = r.get("master_timing") or {}, (r.get("sim") or {}).get("timing") or {}
                fm = lambda t: (f"{t['reaction']['p50_ms']:.3f}/{t['reaction']['p99_ms']:.3f}/"  # noqa: E731
                                f"{t['reaction']['p99.9_ms']:.3f}/{t['reaction']['max_ms']:.2f}") if t else "-"
                print(f"check {k + 1}/{a.n}: {r['status']} {r.get('verdict')} ({r.get('wall_s')} s); reaction "
                      f"p50/p99/p99.9/max ms: master {fm(mt)}, sim-serve {fm(st)}"
                      + (f"; ABORT: {r['reason']} [{cause(r)}]" if r["status"] != "done" else ""), flush=True)
    finally:
        if comp is not None:
            comp.kill()
            comp.wait()
    load1 = _load()
    done = [r for r in rows if r["status"] == "done"]
    passed = [r for r in done if r.get("verdict") == "pass"]
    agg = {}
    for who, get in (("master", lambda r: r.get("master_timing")),
                     ("sim-serve", lambda r: (r.get("sim") or {}).get("timing"))):
        ts = [get(r) for r in rows if get(r)]
        if not ts:
            continue
        agg[who] = {m: {q: max(t[m][q] for t in ts) for q in ("p50_ms", "p99_ms", "p99.9_ms", "max_ms")}
                    for m in ("reaction", "work", "gap")}
        agg[who]["late"] = sum(t["late"] for t in ts)
        agg[who]["unanswered"] = sum(t["unanswered"] for t in ts)
    summary = {"n": a.n, "completed": len(done), "passed": len(passed), "competitor": a.competitor,
               "rt_priority": {"sim-serve": a.rt_sim, "run": a.rt_run},
               "load_before": load0, "load_after": load1, "wake_floor": floor, "cores": os.cpu_count(),
               "per_process": agg,
               "aborts": [{"k": r["k"], "reason": r["reason"], "cause": cause(r)}
                          for r in rows if r["status"] != "done"]}
    print(f"\n{len(done)} of {a.n} checks completed, {len(passed)} passed; competitor: {a.competitor}; "
          f"load average before {load0}, after {load1}")
    for who, g in agg.items():
        for m in ("reaction", "work", "gap"):
            q = g[m]
            print(f"{who:9s} {m:8s} worst over checks: p50 {q['p50_ms']:.3f}  p99 {q['p99_ms']:.3f}  "
                  f"p99.9 {q['p99.9_ms']:.3f}  max {q['max_ms']:.3f} ms")
        print(f"{who:9s} late answers {g['late']}, unanswered cycles {g['unanswered']}")
    for ab in summary["aborts"]:
        print(f"abort {ab['k'] + 1}: {ab['reason']}\n    {ab['cause']}")
    a.json.write_text(json.dumps({"summary": summary, "checks": rows}, indent=1))
    print(f"written to {a.json}")
    return 0 if len(passed) == a.n else 1


if __name__ == "__main__":
    sys.exit(main())
