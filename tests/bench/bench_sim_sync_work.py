"""Benchmark (not a test): the simulated pair's work per SYNC, in process, on the frames a run sent (issue 38).

Reads a run folder's ``can.log`` (``emacheck run`` in a two-process check: ``bench_two_process.py --keep DIR``,
or a dry-run's), builds the simulated pair as ``emacheck sim-serve`` does (same profiles, seed; ``gc.collect``
then ``gc.freeze`` after set-up, the collector left on, as :func:`hil.cli.realtime.prepare_realtime` with
``bounded=False``), and feeds it every frame the master sent (``T`` lines) at the log's time stamps, with
``pair.tick`` every :data:`hil.sim_server.TICK_PERIOD_S` as :func:`hil.sim_server.serve` calls it. Each SYNC's
``pair.on_frame`` is timed (``time.perf_counter_ns`` wall, ``time.thread_time_ns`` CPU) and tagged with what
happened in it: the rig's steps (``plant_steps + free_steps`` before/after), a garbage collection
(``gc.callbacks``, the generation), the TPDOs returned. Replayed as fast as it goes (no sleeping between
frames), so the figures are the work's own, without the wake-up that a served loop adds.

With ``--old DIR`` the same replay runs in that checkout too (a fresh process per tree and round, alternating)
and both are printed side by side: p50, p99, p99.9, max [ms] of wall and CPU, and what the slowest 0.1 %
SYNCs have in common.

Usage: python tests/bench/bench_sim_sync_work.py CAN.log [--old DIR] [--rounds 3] [--profile A.toml]
       [--sim S.toml] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _frames(log: Path) -> list[tuple[float, int, bytes]]:
    """The frames the master sent (``T`` lines; SYNC, sent by the transport, is logged as received, ``R``),
    their times counted from the log's first line plus 0.1 s (sim-serve is up before the master)."""
    out = []
    t0 = None
    for line in log.read_text().splitlines():
        parts = line.split()
        if len(parts) != 4:
            continue
        t = float(parts[0].strip("()"))
        t0 = t if t0 is None else t0
        cid, _, data = parts[2].partition("#")
        if parts[3] == "T" or cid == "080":
            out.append((t - t0 + 0.1, int(cid, 16), bytes.fromhex(data)))
    return out


def _pair(root: Path, profile: Path | None, simrig: Path | None):
    sys.path.insert(0, str(root))
    import numpy as np

    from hil.canopen.od import load_eds

    try:
        from hil.profile.load import load_actuation, load_simrig
        from hil.profile.rig import plan_for
    except ImportError:  # ac0fd0d's layout
        from hil.profiles import load_actuation, load_simrig
        from hil.rig import plan_for
    from sim.drives import SimDrivePair
    from sim.plant import RigPlant

    act = load_actuation(profile)
    sr = load_simrig(simrig)
    rig = plan_for(act, profile, None)
    plant = RigPlant(sr.params, np.random.default_rng(sr.seed))
    return SimDrivePair(
        plant, rig.plan, lambda name, node_id: load_eds(rig.eds_paths[name], node_id=node_id), serials=sr.serials
    )


class _ReplayBus:
    """A python-can bus for :func:`hil.sim_server.serve` that delivers the log's frames one after the other
    (as received messages) and sends what the pair answers on a real udp_multicast bus of its own group (the
    python-can work and system call of a two-process check's sim-serve); the stop flag is set at the end."""

    def __init__(self, frames, clock, stop, out_bus) -> None:
        self._frames = iter(frames)
        self._clock = clock
        self._stop = stop
        self._out = out_bus
        self.in_sync = False  #: between a SYNC's delivery and the next receive: that SYNC's cycle
        self.serving = False  #: from the first receive on (before: the set-up, power-on and on_ready)

    def recv(self, timeout=None):
        import can

        self.in_sync = False
        self.serving = True
        nxt = next(self._frames, None)
        if nxt is None:
            self._stop.set()
            return None
        t, cid, data = nxt
        self._clock.deliver(t)
        self.in_sync = cid == 0x080
        return can.Message(timestamp=t, arbitration_id=cid, data=data, is_extended_id=False, check=False)

    def send(self, msg, timeout=None) -> None:
        self._out.send(msg, timeout)

    def shutdown(self) -> None:
        self._out.shutdown()


class _ReplayClock:
    """The log's time of the frame being handled plus the real time since it was delivered [s] (never
    backwards): the pair sees the run's times, the loop's timing the real work."""

    def __init__(self) -> None:
        import time

        self._pc = time.perf_counter
        self._base = 0.0
        self._at = self._pc()
        self._last = 0.0

    def deliver(self, t: float) -> None:
        self._base = t
        self._at = self._pc()

    def __call__(self) -> float:
        v = max(self._last, self._base + self._pc() - self._at)
        self._last = v
        return v


def _measure(root: Path, log: Path, profile: Path | None, simrig: Path | None, bare: bool) -> dict:
    import gc
    import threading
    import time

    pair = _pair(root, profile, simrig)
    from hil.canopen.frame import SYNC_COB_ID, Frame

    frames = _frames(log)
    gcs: list = []  # (generation, wall ns, in a SYNC's cycle)
    if bare:  # the pair alone: each SYNC's on_frame timed, with pair.tick as serve calls it
        from hil.sim_server import TICK_PERIOD_S

        rows = []
        pair.power_on(0.0)
        gc.collect()
        gc.freeze()  # sim-serve: prepare_realtime(bounded=False)
        gc.callbacks.append(lambda ph, info: gcs.append(info["generation"]) if ph == "start" else None)
        pc, tt = time.perf_counter_ns, time.thread_time_ns
        next_tick = TICK_PERIOD_S
        for t, cid, data in frames:
            f = Frame(cid, data)
            if cid == SYNC_COB_ID:
                s = pair.stats
                steps0 = s.plant_steps + s.free_steps
                del gcs[:]
                c0, w0 = tt(), pc()
                pair.on_frame(f, t)
                w1, c1 = pc(), tt()
                s = pair.stats
                rows.append((w1 - w0, c1 - c0, s.plant_steps + s.free_steps - steps0, max(gcs, default=-1), t))
            else:
                pair.on_frame(f, t)
            if t >= next_tick:
                pair.tick(t)
                next_tick = t + TICK_PERIOD_S
        return {"bare": _summary(rows)}
    import can

    from hil.cli.realtime import prepare_realtime
    from hil.sim_server import serve

    group = f"239.74.{os.getpid() % 250}.{200 + os.getpid() % 50}"
    out = can.Bus(interface="udp_multicast", channel=group)
    stop = threading.Event()
    clock = _ReplayClock()
    bus = _ReplayBus(frames, clock, stop, out)
    prepare_realtime(0)  # as sim-serve: gc.collect, gc.freeze, the collector on
    from hil.cli import realtime

    ready = getattr(realtime, "freeze_heap", None)  # sim-serve's on_ready since issue 38 (not in ac0fd0d)
    t0 = [0]

    def on_gc(phase, info):
        if phase == "start":
            t0[0] = time.perf_counter_ns()
        else:
            where = ("in SYNC cycle" if bus.in_sync else "between") if bus.serving else "set-up"
            gcs.append((info["generation"], time.perf_counter_ns() - t0[0], where))

    gc.callbacks.append(on_gc)
    stats = serve(bus, pair, stop=stop, clock=clock, period_s=0.002, on_ready=ready)
    gc.callbacks.remove(on_gc)
    tally: dict[str, list] = {}
    for g, ns, where in gcs:
        k = f"gen{g} {where}"
        tally.setdefault(k, []).append(ns / 1e6)
    tm = stats.timing.as_json()
    keep = ("n", "p50_ms", "p99_ms", "p99.9_ms", "max_ms")
    return {
        "serve": {
            "syncs": stats.syncs,
            "work": {k: tm["work"][k] for k in keep},
            "work_cpu": {k: tm["work_cpu"][k] for k in keep},
            "worst": tm["work"]["worst"],
            "gc": {
                k: {"n": len(v), "max_ms": round(max(v), 4), "sum_ms": round(sum(v), 3)}
                for k, v in sorted(tally.items())
            },
        }
    }


def _summary(rows: list) -> dict:
    import numpy as np

    wall = np.array([r[0] for r in rows]) / 1e6
    cpu = np.array([r[1] for r in rows]) / 1e6
    n = len(rows)
    k = max(1, n // 1000)
    worst = sorted(range(n), key=lambda i: -rows[i][0])[:k]

    def q(a):
        return {p: round(float(np.percentile(a, float(p[1:]))), 4) for p in ("p50", "p99", "p99.9")} | {
            "max": round(float(a.max()), 4)
        }

    def tally(idx):
        steps: dict[int, int] = {}
        gen: dict[int, int] = {}
        for i in idx:
            steps[rows[i][2]] = steps.get(rows[i][2], 0) + 1
            gen[rows[i][3]] = gen.get(rows[i][3], 0) + 1
        return {"steps": dict(sorted(steps.items())), "gc_generation": dict(sorted(gen.items()))}

    return {
        "syncs": n,
        "wall_ms": q(wall),
        "cpu_ms": q(cpu),
        "all": tally(range(n)),
        "slowest_0.1%": tally(worst),
        "slowest": [
            {
                "ms": round(float(wall[i]), 4),
                "cpu_ms": round(float(cpu[i]), 4),
                "steps": rows[i][2],
                "gc": rows[i][3],
                "t_s": round(rows[i][4], 4),
            }
            for i in worst[:8]
        ],
    }


def _print(r: int, name: str, s: dict) -> None:
    if "bare" in s:
        b = s["bare"]
        print(f"round {r} {name:5s} pair only, {b['syncs']} SYNCs: wall {b['wall_ms']}  cpu {b['cpu_ms']}")
        print(f"      slowest 0.1 %: {b['slowest_0.1%']}  (all SYNCs: {b['all']})")
    else:
        v = s["serve"]
        print(f"round {r} {name:5s} serve, {v['syncs']} SYNCs: work {v['work']}  cpu {v['work_cpu']}")
        print(f"      gc: {v['gc']}")
        print(f"      worst: {v['worst']}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", type=Path, help="the run's can.log")
    ap.add_argument(
        "--old",
        type=Path,
        action="append",
        default=[],
        help="another checkout to replay in too (e.g. ac0fd0d's); repeatable",
    )
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--bare", action="store_true", help="time the pair's on_frame(SYNC) alone (no serve loop)")
    ap.add_argument("--profile", type=Path)
    ap.add_argument("--sim", type=Path)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child is not None:
        print(json.dumps(_measure(a.child, a.log.resolve(), a.profile, a.sim, a.bare)))
        return 0
    trees = [("this", ROOT)] + [(str(d), d.resolve()) for d in a.old]
    res: dict[str, list] = {name: [] for name, _ in trees}
    for r in range(a.rounds):
        for name, tree in trees:
            cmd = [sys.executable, str(Path(__file__).resolve()), str(a.log.resolve()), "--child", str(tree)]
            cmd += ["--bare"] if a.bare else []
            for opt, v in (("--profile", a.profile), ("--sim", a.sim)):
                if v is not None:
                    cmd += [opt, str(v.resolve())]
            env = dict(os.environ, PYTHONPATH=str(tree))
            s = json.loads(subprocess.run(cmd, env=env, cwd=tree, check=True, capture_output=True, text=True).stdout)
            res[name].append(s)
            _print(r + 1, name, s)
    if a.json is not None:
        a.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
