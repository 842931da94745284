"""Benchmark (not a test): N two-process checks at the shipped SYNC rate over udp_multicast (or SocketCAN).

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

Bystanders (``--witness``, default on): during each check one more process
per CPU, pinned to it (SCHED_FIFO 60 where permitted, above both loops), does
nothing but sleep to 2 ms deadlines and record every wake-up later than
0.3 ms with its wall-clock time. After the check the master's CAN log is read
for stalls: a SYNC or a drive's TPDO stream silent for more than 2.5 periods
(the freshness limit stops the check at 3 periods without a sample). Each
stall is printed with who went silent (SYNC: the master's loop; a TPDO while
SYNCs came: sim-serve) and how long each bystander was held in the same
interval: a stall the bystanders share is the machine's (a vCPU its host did
not run), one they do not share is the loop's own.

Kernel trace (``--kernel-trace``, root and tracefs at /sys/kernel/tracing): during each check a
tracefs instance of its own records every hard-interrupt handler's entry and exit (local timer, IPIs,
device interrupts; clock CLOCK_MONOTONIC). Each handler's duration is read back; a stall is printed with
the slowest handler inside it. A handler normally takes microseconds; in a virtual machine whose host
stops the vCPU while the guest handles a timer interrupt (its exit to the host), the handler lasts as long
as the host held it: that names the host as a stall's cause, with the CPU and the time.

``--interface socketcan --channel vcan0`` (or a real CAN interface) runs the same checks over SocketCAN,
where ``run`` sends SYNC kernel-timed (Broadcast Manager); a kernel with CAN is needed (not a kernel
without it, as this project's development machine: there ``tests/bench/bench_vcan.py`` runs in
user-mode-linux).

Usage: python tests/bench/bench_two_process.py [-n 10] [--competitor] [--rt-sim 50] [--rt-run 40] [--check CHECK.toml]
       [--profile ACTUATION.toml] [--sim SIMRIG.toml] [--json FILE] [--keep DIR] [--floor-s 20] [--no-witness]
       [--kernel-trace] [--interface {udp_multicast,socketcan}] [--channel CHANNEL]
"""

from __future__ import annotations

import argparse
import bisect
import dataclasses
import itertools
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
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


#: a bystander: pinned to one CPU, SCHED_FIFO 60 where permitted (above both loops), sleeping to 2 ms
#: deadlines as the loops wait; every wake-up later than 0.3 ms as [wall-clock time of the wake-up [s],
#: how late [s]], written as JSON to argv[2] when stopped (SIGINT/SIGTERM)
_WITNESS = """
import json, os, select, signal, socket, sys, time
cpu, out = int(sys.argv[1]), sys.argv[2]
os.sched_setaffinity(0, {cpu})
try:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(60))
    fifo = True
except OSError:
    fifo = False
stop = []
signal.signal(signal.SIGINT, lambda *_: stop.append(1))
signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
T, n, late = 0.002, 0, []
mono, wall = time.monotonic, time.time
t_next = mono() + T
print("ready", flush=True)
while not stop:
    while (now := mono()) < t_next:
        select.select([s], [], [], t_next - now)
    d = now - t_next
    if d > 3e-4:
        late.append((round(wall(), 6), round(d, 6)))
    n += 1
    t_next += T * (1 + int(d // T))  # a stall skips the deadlines it missed, as the loops do
json.dump({"cpu": cpu, "fifo": fifo, "wakeups": n, "late": late}, open(out, "w"))
"""


def start_witnesses(folder: Path, k: int) -> list[tuple[subprocess.Popen, Path]]:
    """One bystander per CPU this process may run on (see :data:`_WITNESS`), each ready when returned."""
    out = []
    for cpu in sorted(os.sched_getaffinity(0)):
        path = folder / f"witness{k}_cpu{cpu}.json"
        w = subprocess.Popen([sys.executable, "-c", _WITNESS, str(cpu), str(path)], stdout=subprocess.PIPE, text=True)
        w.stdout.readline()
        out.append((w, path))
    return out


def stop_witnesses(ws: list[tuple[subprocess.Popen, Path]]) -> list[dict]:
    for w, _ in ws:
        w.send_signal(signal.SIGINT)
    got = []
    for w, path in ws:
        w.wait(timeout=10)
        got.append(json.loads(path.read_text()))
    return got


def stalls(can_log: Path, period_s: float = 0.002, limit_periods: float = 2.5) -> list[dict]:
    """Where the check's cyclic streams went silent, from the master's CAN log (wall-clock stamps).

    A stream is the SYNC (0x080) or a drive's TPDO (COB-IDs 0x180-0x1FF, 0x280-0x2FF, 0x380-0x3FF,
    0x480-0x4FF; udp_multicast echoes the master's own RPDOs, which are not counted) with at least half as
    many frames as SYNCs; a stall is a gap in one longer than ``limit_periods`` periods.
    Overlapping stalls are merged; each keeps its first gap (``first``: start, end [s], ms) and names who
    went silent first (the SYNC: the master; a TPDO while SYNCs kept coming: sim-serve). What follows an
    abort (the master's safe stop) is merged into the stall that caused it.
    """
    import can

    times: dict[int, list[float]] = {}
    with open(can_log) as fh:
        for msg in can.io.CanutilsLogReader(fh):
            cid = msg.arbitration_id
            if cid == 0x80 or (cid >> 7 in (3, 5, 7, 9) and msg.is_rx):
                times.setdefault(cid, []).append(msg.timestamp)
    n_sync = len(times.get(0x80, ()))
    gaps = []
    for cid, ts in times.items():
        if len(ts) < n_sync / 2:
            continue
        for a, b in itertools.pairwise(ts):
            if b - a > limit_periods * period_s:
                gaps.append((a, b, cid))
    gaps.sort()
    merged: list[dict] = []
    for a, b, cid in gaps:
        if merged and a <= merged[-1]["end"]:
            m = merged[-1]
            m["end"] = max(m["end"], b)
            m["streams"].add(cid)
        else:
            merged.append({"start": a, "end": b, "streams": {cid}, "first": (a, b, cid)})
    for m in merged:
        m["ms"] = round((m["end"] - m["start"]) * 1e3, 2)
        m["period_ms"] = period_s * 1e3
        a, b, cid = m["first"]
        m["silent"] = "master (SYNC)" if cid == 0x80 else "sim-serve (TPDO)"
        m["first"] = {"start": a, "end": b, "ms": round((b - a) * 1e3, 2)}
        m["streams"] = sorted(f"0x{c:03X}" for c in m["streams"])
    return merged


def is_shared(stall: dict) -> bool:
    """A bystander was held at least half as long as the stall's first gap was late (its length less one
    period)."""
    late_ms = stall["first"]["ms"] - stall["period_ms"]
    return max(stall.get("bystanders_held_ms", {}).values(), default=0.0) >= late_ms / 2


def shared(stall: dict, witnesses: list[dict]) -> dict[int, float]:
    """Per bystander CPU, the longest it was held (a wake-up that late [ms]) overlapping the stall's first
    gap (what the stall began with, before any abort followed it)."""
    stall = stall["first"]
    out = {}
    for w in witnesses:
        late = w["late"]
        ends = [t for t, _ in late]
        i = bisect.bisect_left(ends, stall["start"])
        held = 0.0
        while i < len(late) and late[i][0] - late[i][1] <= stall["end"]:
            held = max(held, late[i][1])
            i += 1
        out[w["cpu"]] = round(held * 1e3, 2)
    return out


TRACEFS = Path("/sys/kernel/tracing")
#: the hard-interrupt handlers timed (tracefs event groups and names, each with _entry and _exit)
IRQ_EVENTS = (("irq_vectors", "local_timer"), ("irq_vectors", "call_function_single"),
              ("irq_vectors", "call_function"), ("irq_vectors", "reschedule"), ("irq_vectors", "irq_work"),
              ("irq", "irq_handler"))
#: a handler at least this long is kept with its time (the rest only counted) [ms]
SLOW_HANDLER_MS = 0.2
#: a CPU without any interrupt for at least this long is kept as a silence [ms] (with the bystanders on,
#: each CPU takes a timer interrupt every 2 ms: longer, the CPU had interrupts off or its host did not run it)
SILENT_MS = 2.5
_TRACE_LINE = re.compile(r"\[(\d+)\]\s+\S+\s+(\d+\.\d+): (\w+)_(entry|exit):")
_LOST = re.compile(r"CPU:(\d+) \[LOST (\d+) EVENTS\]")


@dataclass(frozen=True)
class Handler:
    """One hard-interrupt handler that took at least :data:`SLOW_HANDLER_MS`."""

    cpu: int
    start_s: float  #: when it began [s, the clock the trace was converted to]
    ms: float  #: how long it ran [ms]
    name: str  #: e.g. local_timer, call_function_single, irq_handler


@dataclass(frozen=True)
class Silence:
    """A CPU that took no interrupt (no handler began or ended) for at least :data:`SILENT_MS`."""

    cpu: int
    start_s: float  #: its last interrupt event before [s]
    ms: float  #: until its next [ms]


def parse_irq_trace(lines, offset_s: float = 0.0, slow_ms: float = SLOW_HANDLER_MS,
                    silent_ms: float = SILENT_MS) -> dict:
    """Hard-interrupt handler durations from tracefs text (``trace`` of an instance with the
    :data:`IRQ_EVENTS` enabled).

    Each ``<name>_entry`` is paired with the next ``<name>_exit`` on the same CPU; the duration is exit
    minus entry [ms]. An exit without its entry (the trace began inside the handler) is not counted.
    ``offset_s`` is added to the trace's stamps (CLOCK_MONOTONIC to wall clock: ``time.time() -
    time.monotonic()``). Returns ``n``, ``p50_us``, ``p99_us``, ``p99.9_us``, ``max_ms``, ``over_1ms``,
    ``lost_events`` (the ring buffer overflowed: some handlers are missing), ``slow``: a
    :class:`Handler` for each handler of at least ``slow_ms``, and ``silent``: a :class:`Silence` for each
    interval of at least ``silent_ms`` in which a CPU logged no interrupt event (both in time order).
    """
    import numpy as np

    open_: dict[tuple[int, str], float] = {}
    durations: list[float] = []
    slow: list[Handler] = []
    silent: list[Silence] = []
    last: dict[int, float] = {}
    lost = 0
    for line in lines:
        m = _TRACE_LINE.search(line)
        if m is None:
            if (lm := _LOST.search(line)) is not None:
                lost += int(lm.group(2))
            continue
        cpu, t, name, edge = int(m.group(1)), float(m.group(2)), m.group(3), m.group(4)
        gap_ms = round((t - last.get(cpu, t)) * 1e3, 3)
        if gap_ms >= silent_ms:
            silent.append(Silence(cpu, last[cpu] + offset_s, gap_ms))
        last[cpu] = t
        if edge == "entry":
            open_[(cpu, name)] = t
        elif (t0 := open_.pop((cpu, name), None)) is not None:
            ms = round((t - t0) * 1e3, 3)  # the trace's stamps are whole microseconds
            durations.append(ms)
            if ms >= slow_ms:
                slow.append(Handler(cpu, t0 + offset_s, ms, name))
    d = np.asarray(durations)
    q = (lambda p: round(float(np.percentile(d, p)) * 1e3, 1)) if d.size else (lambda p: None)  # noqa: E731
    return {"n": int(d.size), "p50_us": q(50), "p99_us": q(99), "p99.9_us": q(99.9),
            "max_ms": round(float(d.max()), 3) if d.size else None, "over_1ms": int((d > 1.0).sum()),
            "lost_events": lost, "slow": sorted(slow, key=lambda h: h.start_s),
            "silent": sorted(silent, key=lambda x: x.start_s)}


def slowest_inside(stall: dict, slow: list[Handler] | list[Silence]) -> Handler | Silence | None:
    """The longest slow handler (or CPU silence) overlapping the stall's first gap, if any."""
    a, b = stall["first"]["start"], stall["first"]["end"]
    inside = [h for h in slow if h.start_s < b and h.start_s + h.ms / 1e3 > a]
    return max(inside, key=lambda h: h.ms, default=None)


class KernelTrace:
    """Hard-interrupt handler durations during a check, from a tracefs instance of its own.

    :meth:`problem` says why it cannot run here (None: it can). :meth:`start` clears and starts the
    instance; :meth:`stop` stops it and returns :func:`parse_irq_trace` of what it holds (wall-clock
    times); :meth:`close` removes the instance.
    """

    def __init__(self, root: Path = TRACEFS, name: str = "emacheck-bench", buffer_kb: int = 49152) -> None:
        self.root = root
        self.dir = root / "instances" / name
        self.buffer_kb = buffer_kb

    @staticmethod
    def problem(root: Path = TRACEFS) -> str | None:
        if not (root / "available_events").exists():
            return (f"tracefs is not mounted at {root} (as root: mount -t tracefs nodev {root})")
        if not os.access(root / "instances", os.W_OK):
            return f"{root}/instances is not writable (run as root)"
        have = set((root / "available_events").read_text().split())
        missing = [f"{g}:{e}_{x}" for g, e in IRQ_EVENTS for x in ("entry", "exit")
                   if f"{g}:{e}_{x}" not in have and e in ("local_timer", "irq_handler")]
        return f"this kernel has no trace event {', '.join(missing)}" if missing else None

    def _w(self, rel: str, value: str) -> None:
        (self.dir / rel).write_text(value)

    def start(self) -> None:
        if not self.dir.exists():
            self.dir.mkdir()
        self._w("tracing_on", "0")
        self._w("trace_clock", "mono")
        self._w("buffer_size_kb", str(self.buffer_kb))
        for g, e in IRQ_EVENTS:
            for x in ("entry", "exit"):
                ev = self.dir / "events" / g / f"{e}_{x}" / "enable"
                if ev.exists():
                    ev.write_text("1")
        self._w("trace", "")
        self.offset_s = time.time() - time.monotonic()
        self._w("tracing_on", "1")

    def stop(self) -> dict:
        self._w("tracing_on", "0")
        with open(self.dir / "trace") as fh:
            got = parse_irq_trace(fh, self.offset_s)
        self._w("trace", "")
        return got

    def close(self) -> None:
        try:
            self._w("tracing_on", "0")
            self.dir.rmdir()
        except OSError:
            pass


def one_check(k: int, a, folder: Path, ktrace: KernelTrace | None = None) -> dict:
    # udp_multicast: a group of this check's own; SocketCAN: the interface given
    channel = a.channel or f"239.74.{(os.getpid() >> 8) % 250 + 1}.{(os.getpid() + k) % 250 + 1}"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    sim_json = folder / f"sim{k}.json"
    run_dir = folder / f"run{k}"
    rt_sim = ["--rt-priority", str(a.rt_sim)] if a.rt_sim else []
    rt_run = ["--rt-priority", str(a.rt_run)] if a.rt_run else []
    sim_cmd = _cmd("sim-serve", "--interface", a.interface, "--channel", channel, *rt_sim,
                   "--timing-json", str(sim_json), *_profile_args(a), *(["--sim", str(a.sim)] if a.sim else []))
    ws = start_witnesses(folder, k) if a.witness else []
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
        stop_witnesses(ws)
        return {"k": k, "channel": channel, "status": "sim-serve not ready", "sim_out": sim_out}
    run_cmd = _cmd("run", "--interface", a.interface, "--channel", channel, "--arm", "--quiet", "--no-history",
                   *rt_run,
                   "--out", str(run_dir), *_profile_args(a), *(["--check", str(a.check)] if a.check else []))
    if ktrace is not None:
        ktrace.start()
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
    witnesses = stop_witnesses(ws)
    irq = ktrace.stop() if ktrace is not None else None
    meta = json.loads((run_dir / "meta.json").read_text()) if (run_dir / "meta.json").exists() else {}
    # the check's SYNC period (the master's timing record; the shipped profile's 2 ms where there is none)
    period_s = ((meta.get("timing") or {}).get("period_ms") or 2.0) / 1e3
    found = stalls(run_dir / "can.log", period_s) if (run_dir / "can.log").exists() else []
    for st in found:
        st["bystanders_held_ms"] = shared(st, witnesses)
        if irq is not None:
            st["slowest_irq"] = _as_json(slowest_inside(st, irq["slow"]))
            st["cpu_silent"] = _as_json(slowest_inside(st, irq["silent"]))
    result = json.loads((run_dir / "result.json").read_text()) if (run_dir / "result.json").exists() else {}
    simj = json.loads(sim_json.read_text()) if sim_json.exists() else {}
    return {"k": k, "channel": channel, "rc": rc, "wall_s": round(wall, 2), "status": meta.get("status"),
            "verdict": result.get("status"), "reason": meta.get("reason"), "safety": meta.get("safety"),
            "can": meta.get("can"), "master_timing": meta.get("timing"), "sim": simj,
            "master_stalls": meta.get("stalls"),  # the master's own record (meta.json stalls)
            "run_out_tail": run_out.splitlines()[-12:], "sim_out": sim_out[-8:], "stalls": found,
            "witnesses": [{"cpu": w["cpu"], "fifo": w["fifo"], "wakeups": w["wakeups"],
                           "late_over_1ms": sum(d > 1e-3 for _, d in w["late"]),
                           "late_over_3ms": sum(d > 3e-3 for _, d in w["late"]),
                           "late_max_ms": round(max((d for _, d in w["late"]), default=0.0) * 1e3, 2)}
                          for w in witnesses],
            "irq": None if irq is None else {k_: [_as_json(x) for x in v] if k_ in ("slow", "silent") else v
                                             for k_, v in irq.items()}}


def _as_json(x: Handler | Silence | None) -> dict | None:
    return None if x is None else dataclasses.asdict(x)


def _irq_text(st: dict) -> str:
    if "slowest_irq" not in st:
        return ""
    h, q = st["slowest_irq"], st.get("cpu_silent")
    return ((f"; no interrupt handler over {SLOW_HANDLER_MS} ms inside" if h is None
             else f"; slowest interrupt handler inside: {h['name']} on CPU{h['cpu']}, {h['ms']:.2f} ms")
            + (f"; no CPU without interrupts for {SILENT_MS} ms" if q is None
               else f"; CPU{q['cpu']} took no interrupt for {q['ms']:.2f} ms"))


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
    ap.add_argument("--no-witness", dest="witness", action="store_false",
                    help="no bystander process per CPU during the checks (see the module's docstring)")
    ap.add_argument("--floor-s", type=float, default=20.0,
                    help="first measure this machine's wake-up floor for this long [s] (0: not)")
    ap.add_argument("--kernel-trace", action="store_true",
                    help="time every hard-interrupt handler during each check (tracefs, root) and name the "
                         "slowest inside each stall")
    ap.add_argument("--interface", choices=("udp_multicast", "socketcan"), default="udp_multicast",
                    help="the bus of both processes (default udp_multicast; socketcan: a kernel with CAN)")
    ap.add_argument("--channel", help="socketcan: the interface (vcan0, can0); udp_multicast: one group for "
                                      "every check (default: a group of each check's own)")
    a = ap.parse_args(argv)
    if a.interface == "socketcan" and not a.channel:
        ap.error("--interface socketcan needs --channel (e.g. vcan0)")
    ktrace = None
    if a.kernel_trace:
        why = KernelTrace.problem()
        if why is not None:
            ap.error(f"--kernel-trace: {why}")
        ktrace = KernelTrace()
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
                r = one_check(k, a, folder, ktrace)
                rows.append(r)
                mt, st = r.get("master_timing") or {}, (r.get("sim") or {}).get("timing") or {}
                fm = lambda t: (f"{t['reaction']['p50_ms']:.3f}/{t['reaction']['p99_ms']:.3f}/"  # noqa: E731
                                f"{t['reaction']['p99.9_ms']:.3f}/{t['reaction']['max_ms']:.2f}") if t else "-"
                print(f"check {k + 1}/{a.n}: {r['status']} {r.get('verdict')} ({r.get('wall_s')} s); reaction "
                      f"p50/p99/p99.9/max ms: master {fm(mt)}, sim-serve {fm(st)}"
                      + (f"; master's stalls: {ms['count']}, longest {ms['longest_ms']:g} ms (limit {ms['limit_ms']:g}"
                         f" ms, {ms['limit']})" if (ms := r.get("master_stalls")) else "")
                      + (f"; ABORT: {r['reason']} [{cause(r)}]" if r["status"] != "done" else ""), flush=True)
                for st in r.get("stalls", ()):
                    print(f"    stall {st['ms']:.1f} ms at {st['start']:.3f} (first gap {st['first']['ms']:.1f} ms): "
                          f"{st['silent']} silent ({', '.join(st['streams'])})"
                          + ("; bystanders held " + ", ".join(f"CPU{c} {v:.1f} ms" for c, v in held.items())
                             if (held := st.get("bystanders_held_ms")) else "")
                          + _irq_text(st), flush=True)
                if r.get("irq") is not None:
                    q = r["irq"]
                    print(f"    interrupt handlers: {q['n']}, p50 {q['p50_us']} us, p99.9 {q['p99.9_us']} us, "
                          f"max {q['max_ms']} ms, {q['over_1ms']} over 1 ms"
                          + (f"; {q['lost_events']} trace events LOST" if q["lost_events"] else ""), flush=True)
                for w in r.get("witnesses", ()):
                    print(f"    bystander CPU{w['cpu']}: {w['wakeups']} wake-ups, {w['late_over_1ms']} over 1 ms, "
                          f"{w['late_over_3ms']} over 3 ms late, max {w['late_max_ms']:.2f} ms", flush=True)
    finally:
        if comp is not None:
            comp.kill()
            comp.wait()
        if ktrace is not None:
            ktrace.close()
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
    all_stalls = [st for r in rows for st in r.get("stalls", ())]
    summary["stalls"] = {"n": len(all_stalls), "shared": sum(is_shared(st) for st in all_stalls),
                         "by_master": sum(st["silent"].startswith("master") for st in all_stalls),
                         "max_ms": max((st["ms"] for st in all_stalls), default=0.0)}
    if ktrace is not None:
        summary["stalls"]["with_irq_over_1ms"] = sum((st.get("slowest_irq") or {}).get("ms", 0.0) > 1.0
                                                     for st in all_stalls)
        summary["stalls"]["with_cpu_silent"] = sum(st.get("cpu_silent") is not None for st in all_stalls)
        irqs = [r["irq"] for r in rows if r.get("irq")]
        summary["irq"] = {"n": sum(q["n"] for q in irqs), "over_1ms": sum(q["over_1ms"] for q in irqs),
                          "max_ms": max((q["max_ms"] or 0.0 for q in irqs), default=None),
                          "p99.9_us_worst": max((q["p99.9_us"] or 0.0 for q in irqs), default=None),
                          "lost_events": sum(q["lost_events"] for q in irqs)}
    summary["interface"] = a.interface
    print(f"\n{len(done)} of {a.n} checks completed, {len(passed)} passed; competitor: {a.competitor}; "
          f"load average before {load0}, after {load1}")
    for who, g in agg.items():
        for m in ("reaction", "work", "gap"):
            q = g[m]
            print(f"{who:9s} {m:8s} worst over checks: p50 {q['p50_ms']:.3f}  p99 {q['p99_ms']:.3f}  "
                  f"p99.9 {q['p99.9_ms']:.3f}  max {q['max_ms']:.3f} ms")
        print(f"{who:9s} late answers {g['late']}, unanswered cycles {g['unanswered']}")
    if a.witness:
        g = summary["stalls"]
        print(f"stalls (a stream silent over 2.5 periods): {g['n']}, {g['by_master']} of them the SYNC, longest "
              f"{g['max_ms']:.1f} ms; shared with a bystander (held at least half as long as the stall was "
              f"late): {g['shared']} of {g['n']}")
    if ktrace is not None:
        q, g = summary["irq"], summary["stalls"]
        print(f"interrupt handlers (kernel trace): {q['n']}, worst p99.9 {q['p99.9_us_worst']} us, max "
              f"{q['max_ms']} ms, {q['over_1ms']} over 1 ms; stalls with a handler over 1 ms inside: "
              f"{g['with_irq_over_1ms']} of {g['n']}; with a CPU that took no interrupt for {SILENT_MS} ms or "
              f"more: {g['with_cpu_silent']} of {g['n']}" + (f"; {q['lost_events']} trace events LOST"
                                                         if q["lost_events"] else ""))
    for ab in summary["aborts"]:
        print(f"abort {ab['k'] + 1}: {ab['reason']}\n    {ab['cause']}")
    a.json.write_text(json.dumps({"summary": summary, "checks": rows}, indent=1))
    print(f"written to {a.json}")
    return 0 if len(passed) == a.n else 1


if __name__ == "__main__":
    sys.exit(main())
