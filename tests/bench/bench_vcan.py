"""Benchmark (not a test): `emacheck sim-serve` and `emacheck run` in real time on vcan0.

Runs the check over SocketCAN for at least ``--minutes`` (default 10) of
real time: one ``sim-serve`` (SCHED_FIFO 50) for the whole time and ``run``
repeated (each a complete check with ``--check``, default the shipped profile,
115.5 s; ``--rt-priority 40``: memory locked, SCHED_FIFO 40), with can-utils' ``candump -L vcan0``
recording everything. Repeating whole checks rather than one long check keeps every run a real check and
includes the start-up of each (preflight, enabling), where timing is worst. Where the host kernel
has no vcan, the benchmark runs inside user-mode-linux (see
``tests/vcan/vcan_stage.py``), whose kernel clock runs a few per cent slow:
judge timing there by jitter and ratios.

From the capture, over the cyclic phase of each run (first to last SYNC):

* SYNC period: p50, p99, max [ms]; jitter = |period - nominal| p50/p99/max [ms]
* TPDOs lost: TPDO frames that never came (4 expected per SYNC), and cycles
  whose TPDOs were not all in before the next SYNC (late)
* late RPDOs: cycles (after the drives are enabled) in which a drive's RPDO1
  did not arrive before the next SYNC
* bus load: bits of all frames (hil.canopen.busload.frame_bits, nominal and with worst-case
  stuffing) per second over the configured bit rate [%]
* CPU: master (each ``run`` process) and ``sim-serve``, from /proc/PID/stat
  and the children's rusage, as % of one CPU over the wall time

Printed and written to JSON (``--json``, default bench_vcan.json).

Usage: python tests/bench/bench_vcan.py [--minutes 10] [--check CHECK.toml] [--profile ACTUATION.toml]
       [--sim SIMRIG.toml] [--json FILE]
(tests/vcan/actuation.toml + tests/vcan/simrig.toml: the vcan stage's 250 Hz)
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent  # tests/bench
ROOT = HERE.parents[1]  # the repository: the working directory of the commands it starts
sys.path[:0] = [str(ROOT), str(HERE.parent / "vcan")]

import vcan_stage  # noqa: E402

CHANNEL = vcan_stage.CHANNEL
TPDO_BASES = (0x180, 0x280)


def _proc_cpu_s(pid: int) -> float | None:
    try:
        f = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")


def _children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _read_capture(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t [s], COB-ID, DLC, first data byte) of every frame in a candump -L file."""
    t, cid, dlc, b0 = [], [], [], []
    with open(path) as fh:
        for line in fh:
            p = line.split()
            if len(p) != 3 or "#" not in p[2]:
                continue
            i, d = p[2].split("#", 1)
            t.append(float(p[0][1:-1]))
            cid.append(int(i, 16))
            dlc.append(len(d) // 2)
            b0.append(int(d[:2], 16) if d else -1)
    return np.array(t), np.array(cid), np.array(dlc), np.array(b0)


def analyse_capture(path: Path, act) -> dict:
    """The bus figures of a capture, over the SYNC trains of the runs in it."""
    from hil.canopen.busload import frame_bits

    t, cid, dlc, b0 = _read_capture(path)
    T = act.timing.sync_period_s
    nodes = act.canopen.node_ids
    periods, jit = [], []
    cycles = tp_expected = tp_seen = tp_late_cycles = rp_late = rp_cycles = 0
    bits_nom = bits_worst = 0
    busy_s = 0.0
    sync_idx = np.flatnonzero(cid == 0x080)
    # split the SYNC train into runs: a gap of more than 50 periods ends a run
    if len(sync_idx) < 2:
        raise RuntimeError(f"{path}: fewer than 2 SYNC frames")
    gaps = np.flatnonzero(np.diff(t[sync_idx]) > 50 * T)
    starts = np.r_[0, gaps + 1]
    ends = np.r_[gaps, len(sync_idx) - 1]
    runs = 0
    for a, b in zip(starts, ends, strict=True):
        if b - a < 100:
            continue
        runs += 1
        s = sync_idx[a:b + 1]
        ts = t[s]
        d = np.diff(ts)
        periods.append(d)
        jit.append(np.abs(d - T))
        lo, hi = s[0], s[-1]
        busy_s += ts[-1] - ts[0]
        for k in range(lo, hi):
            n = dlc[k]
            bits_nom += frame_bits(int(n), worst_case=False)
            bits_worst += frame_bits(int(n), worst_case=True)
        # per cycle: TPDOs in [SYNC_k, SYNC_k+1), RPDO1 per node
        enabled = False
        for k0, k1 in zip(s[:-1], s[1:], strict=True):
            c = cid[k0 + 1:k1]
            cycles += 1
            want = [base + n for base in TPDO_BASES for n in nodes]
            got = sum(1 for w in want if np.any(c == w))
            tp_expected += len(want)
            if got < len(want):
                tp_late_cycles += 1
            rp = [np.any(c == 0x200 + n) for n in nodes]
            if all(rp):
                enabled = True
            if enabled:
                rp_cycles += 1
                rp_late += sum(1 for x in rp if not x)
        in_run = (cid != 0x080) & (np.arange(len(cid)) > lo) & (np.arange(len(cid)) < hi)
        tp_seen += int(np.sum(in_run & np.isin(cid, [base + n for base in TPDO_BASES for n in nodes])))
    p = np.concatenate(periods) * 1e3
    j = np.concatenate(jit) * 1e3
    bitrate = act.canopen.bitrate_bps
    return {
        "runs_in_capture": runs,
        "sync_cycles": cycles,
        "sync_period_ms": {"nominal": T * 1e3, "p50": float(np.median(p)), "p99": float(np.percentile(p, 99)),
                           "max": float(p.max()), "min": float(p.min())},
        "sync_jitter_ms": {"p50": float(np.median(j)), "p99": float(np.percentile(j, 99)), "max": float(j.max())},
        "tpdos_expected": tp_expected,
        "tpdos_lost": tp_expected - tp_seen,
        "cycles_tpdos_late": tp_late_cycles,
        "rpdo_cycles": rp_cycles,
        "rpdos_late": rp_late,
        "bus_load_percent": {"nominal": 100.0 * bits_nom / busy_s / bitrate,
                             "worst_case_stuffing": 100.0 * bits_worst / busy_s / bitrate,
                             "bitrate_bps": bitrate},
    }


def _wait_line(proc: subprocess.Popen, text: str, timeout: float) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if text in line:
            return line.strip()
        if not line and proc.poll() is not None:
            break
    raise RuntimeError(f"sim-serve: no {text!r} within {timeout} s")


def bench(minutes: float, check: Path | None, workdir: Path, profile: Path | None = None,
          sim: Path | None = None) -> dict:
    from hil.profile.load import load_actuation

    act = load_actuation(profile)
    prof = ["--profile", str(profile)] if profile else []
    workdir.mkdir(parents=True, exist_ok=True)
    capture = workdir / "candump.log"
    procs: list[subprocess.Popen] = []
    cli = [sys.executable, "-m", "hil.cli"]
    runs = []
    try:
        with open(capture, "w") as fh:
            dump = subprocess.Popen(["candump", "-L", "-r", str(8 << 20), CHANNEL], stdout=fh, stderr=subprocess.STDOUT)
        procs.append(dump)
        serve = subprocess.Popen(cli + ["sim-serve", "--interface", "socketcan", "--channel", CHANNEL,
                                        "--rt-priority", "50", *prof] + (["--sim", str(sim)] if sim else []),
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
        procs.append(serve)
        ready = _wait_line(serve, "ready", 120)
        t0 = time.monotonic()
        serve_cpu0 = _proc_cpu_s(serve.pid) or 0.0
        k = 0
        while k == 0 or time.monotonic() - t0 < minutes * 60:
            out = workdir / f"run{k}"
            argv = cli + ["run", "--interface", "socketcan", "--channel", CHANNEL, "--arm", "--quiet",
                          "--rt-priority", "40", "--out", str(out), *prof] + (
                        ["--check", str(check)] if check else [])
            c0, w0 = _children_cpu_s(), time.monotonic()
            with open(workdir / f"run{k}.out", "w") as fh:
                p = subprocess.Popen(argv, stdout=fh, stderr=subprocess.STDOUT, cwd=ROOT)
                procs.append(p)
                rc = p.wait(timeout=3 * 3600)
            wall = time.monotonic() - w0
            meta = json.loads((out / "meta.json").read_text()) if (out / "meta.json").exists() else {}
            runs.append({"rc": rc, "wall_s": round(wall, 2), "master_cpu_s": round(_children_cpu_s() - c0, 2),
                         "status": meta.get("status"), "reason": meta.get("reason", ""),
                         "duration_s": meta.get("duration_s"),
                         "missing_cycles": meta.get("can", {}).get("missing_cycles"),
                         "max_lag_ms": meta.get("can", {}).get("max_lag_ms")})
            print(f"run {k}: exit {rc}, {runs[-1]['status']}, {wall:.1f} s wall, master CPU "
                  f"{runs[-1]['master_cpu_s']:.1f} s", flush=True)
            k += 1
        total = time.monotonic() - t0
        serve_cpu = (_proc_cpu_s(serve.pid) or 0.0) - serve_cpu0
        serve.send_signal(signal.SIGTERM)
        tail = serve.communicate(timeout=30)[0].strip().splitlines()
        time.sleep(0.2)
        dump.send_signal(signal.SIGINT)
        dump.wait(timeout=10)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=10)
    master_cpu = sum(r["master_cpu_s"] for r in runs)
    master_wall = sum(r["wall_s"] for r in runs)
    res = {
        "where": "user-mode-linux" if vcan_stage.inside_uml() else "host kernel",
        "minutes": round(total / 60, 2),
        "check_profile": str(check) if check else "shipped check.toml",
        "actuation_profile": str(profile) if profile else "shipped actuation.toml",
        "runs": runs,
        "sim_serve": {"ready": ready, "stats": tail[-1] if tail else "",
                      "cpu_percent": round(100 * serve_cpu / total, 1)},
        "master_cpu_percent": round(100 * master_cpu / master_wall, 1),
        **analyse_capture(capture, act),
    }
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=10.0, help="real time to run at least (default 10)")
    ap.add_argument("--check", type=Path, help="check profile of each run (default: the shipped one)")
    ap.add_argument("--profile", type=Path, help="actuation profile (default: the shipped one, 500 Hz)")
    ap.add_argument("--sim", type=Path, help="simulated-rig profile (its sample period must be the SYNC period)")
    ap.add_argument("--json", type=Path, default=Path("bench_vcan.json"))
    ap.add_argument("--workdir", type=Path, help="where captures and run folders go (default: a temp dir)")
    args = ap.parse_args()
    workdir = (args.workdir or Path(tempfile.mkdtemp(prefix="bench-vcan-"))).resolve()
    mode, why = vcan_stage.stage_mode()
    if mode == "host":
        res = bench(args.minutes, args.check.resolve() if args.check else None, workdir,
                    args.profile.resolve() if args.profile else None, args.sim.resolve() if args.sim else None)
    elif mode == "uml":
        inner_json = workdir / "inner.json"
        # run folders and the capture on the guest's tmpfs: on hostfs every write (and the run
        # folder's fsync at each step change) holds UML's only CPU; copied out afterwards
        shm = "/dev/shm/bench-vcan"
        argv = [sys.executable, str(HERE / "bench_vcan.py"), "--minutes", str(args.minutes),
                "--json", str(inner_json), "--workdir", shm]
        for opt in ("check", "profile", "sim"):
            if getattr(args, opt):
                argv += [f"--{opt}", str(getattr(args, opt).resolve())]
        inner = " ".join(shlex.quote(a) for a in argv)
        cmd = ["sh", "-c", f"{inner}; rc=$?; cp -a {shm} {shlex.quote(str(workdir / 'inner'))}; exit $rc"]
        print(f"no vcan on this kernel ({why}): running inside user-mode-linux", flush=True)
        r = vcan_stage.run_in_uml(cmd, workdir / "uml", timeout_s=args.minutes * 60 * 1.5 + 600)
        print(r.output)
        if r.status != 0 or not inner_json.exists():
            print(f"benchmark inside UML failed (status {r.status}, timed out {r.timed_out})\n{r.console_tail}")
            return 1
        res = json.loads(inner_json.read_text())
        res["uml_boot_s"] = r.boot_s
    else:
        print(f"cannot benchmark: {why}")
        return 1
    args.json.write_text(json.dumps(res, indent=2))
    print(json.dumps({k: v for k, v in res.items() if k != "runs"}, indent=2))
    print(f"written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
