"""Benchmark: SIGKILL of `emacheck run` at random instants of the check; the drives stop by themselves.

    python tests/bench/bench_master_loss.py [--kills 20] [--seed N] [--check CHECK.toml]
        [--profile ACTUATION.toml] [--sim SIMRIG.toml] [--json bench_master_loss.json]

``emacheck sim-serve`` and ``emacheck run --arm`` run as two processes on
python-can's ``udp_multicast`` interface (the ``virtual`` one does not reach
across processes), so no SocketCAN is needed. Multicast must not leave the
machine: the benchmark runs itself in a private network namespace
(``unshare -n``: only a loopback interface, which carries the multicast
group) and refuses to run outside one. Per kill, with a fresh ``sim-serve``:

1. ``run`` starts; once the first sample is in its signals.csv (the cyclic
   phase began) a delay drawn uniformly from [0, 0.95 x the check's duration)
   passes (the duration of the same check on the plant alone, simulated
   first; seeded rng; a draw that lands after ``run`` ended is drawn again, at
   most as many times as there are kills);
2. ``run`` is SIGKILLed (its SYNC task, the master's heartbeat and every other
   frame of it stop with it);
3. a separate SDO client on the same bus (python-can +
   :class:`hil.canopen.sdo.SdoClient`) reads each drive's statusword 0x6041
   every ``POLL_S`` until both are in Switch on disabled (or a deadline);
4. from a recording of every frame (kernel receive stamps) it takes the
   master's last frame, each drive's EMCY 0x8130 (the moment its consumer
   fired and it left Operation enabled) and the first SDO answer that says
   Switch on disabled.

A kill passes when both drives sent EMCY 0x8130 within the consumer time
(``canopen.master_consumer_time_s``) + 2 SYNC periods of the master's last
frame, and both answered Switch on disabled within that + the drives' quick
stop hold (:data:`sim.drives.QUICK_STOP_HOLD_S`) + one poll period, and stay
there. Exit status 0: every kill passed; 1: one did not; 77: cannot run here
(the reason is printed: no ``unshare``, no msgpack for udp_multicast).

The defaults are the vcan stage's profiles (tests/vcan: 100 Hz SYNC, the
master's heartbeat every 0.5 s, consumer time 1.25 s; their headers say why):
the host's two shared cores, like user-mode-linux, hold a process now and
then, and a 500 Hz Python master on udp_multicast would be judged on that.
Printed as a table and written to JSON (``--json``).
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent  # tests/bench
ROOT = HERE.parents[1]
sys.path[:0] = [str(ROOT), str(HERE.parent)]

from hil.canopen.cia402 import State, decode_state  # noqa: E402
from hil.canopen.frame import Frame  # noqa: E402
from hil.canopen.sdo import SdoAbortError, SdoClient, SdoEvent  # noqa: E402
from hil.profile.load import load_actuation, load_check, load_simrig  # noqa: E402
from sim.drives import QUICK_STOP_HOLD_S  # noqa: E402

SEED = 20261123
GROUP = "239.74.163.2"  #: python-can's default IPv4 multicast group, on the namespace's loopback only
NETNS_ENV = "EMACHECK_PRIVATE_NETNS"
SKIP = 77
POLL_S = 0.01  #: statusword poll period of the SDO client [s]
READY_TIMEOUT_S = 60.0
START_TIMEOUT_S = 60.0  #: from starting run to its first sample
VCAN = HERE.parent / "vcan"
DEFAULT_PROFILE, DEFAULT_SIM, DEFAULT_CHECK = VCAN / "actuation.toml", VCAN / "simrig.toml", VCAN / "check.toml"


def cannot_run() -> str | None:
    """Why the benchmark cannot run on this machine, or None."""
    try:
        from can.interfaces.udp_multicast.utils import is_msgpack_installed
        if not is_msgpack_installed(raise_exception=False):
            return "python-can's udp_multicast needs msgpack (pip install msgpack)"
    except ImportError as exc:  # pragma: no cover
        return f"python-can has no udp_multicast interface: {exc}"
    if os.environ.get(NETNS_ENV) != "1":
        for tool in ("unshare", "ip"):
            if shutil.which(tool) is None and not Path(f"/usr/sbin/{tool}").exists():
                return f"`{tool}` not found (util-linux, iproute2): no private network namespace for multicast"
    return None


def reexec_in_private_netns(argv: list[str]) -> int:
    """Run this script again in a new network namespace whose loopback carries the multicast group."""
    ip = shutil.which("ip") or "/usr/sbin/ip"
    setup = (f"{ip} link set lo up && {ip} link set lo multicast on && "
             f"{ip} route add 224.0.0.0/4 dev lo")
    cmd = " ".join(_q(a) for a in [sys.executable, str(Path(__file__).resolve()), *argv])
    unshare = ["unshare", "-n"] if os.geteuid() == 0 else ["unshare", "-r", "-n"]
    probe = subprocess.run([*unshare, "sh", "-c", setup], capture_output=True, text=True, check=False)
    if probe.returncode != 0:
        print(f"SKIP: no private network namespace here (`{' '.join(unshare)}` + loopback multicast): "
              f"{probe.stderr.strip() or probe.returncode}", flush=True)
        return SKIP
    env = dict(os.environ, **{NETNS_ENV: "1"})
    return subprocess.run([*unshare, "sh", "-c", f"{setup} && exec {cmd}"], env=env, check=False).returncode


def _q(s: str) -> str:
    import shlex
    return shlex.quote(s)


class Recorder:
    """Every frame on the bus with its kernel receive stamp (CLOCK_REALTIME [s]); SDO responses
    are also queued for the client. One thread owns ``recv``; ``send`` is called from the main one."""

    def __init__(self) -> None:
        import can
        self.bus = can.Bus(interface="udp_multicast", channel=GROUP)
        self.frames: list[tuple[float, int, bytes]] = []
        self.sdo: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.05)
            if msg is None or msg.is_extended_id or msg.is_error_frame:
                continue
            rec = (float(msg.timestamp), msg.arbitration_id, bytes(msg.data))
            self.frames.append(rec)
            if 0x581 <= msg.arbitration_id <= 0x5FF:
                self.sdo.put(rec)

    def send(self, f: Frame) -> None:
        import can
        self.bus.send(can.Message(arbitration_id=f.arbitration_id, data=f.data, is_extended_id=False))

    def close(self) -> None:
        self._stop.set()
        self._t.join(2.0)
        self.bus.shutdown()


def read_statusword(rec: Recorder, node: int, timeout_s: float = 0.2) -> tuple[float, int] | None:
    """One SDO upload of 0x6041 from ``node``: (receive stamp of the answer, statusword) or None."""
    while not rec.sdo.empty():  # drop late answers of an earlier read
        rec.sdo.get_nowait()
    client = SdoClient(node, timeout_s=timeout_s)
    rec.send(client.start_upload(0x6041, 0, time.monotonic()))
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            t, cid, data = rec.sdo.get(timeout=max(0.0, deadline - time.monotonic()))
        except queue.Empty:
            break
        try:
            res = client.on_frame(Frame(cid, data), time.monotonic())
        except SdoAbortError:
            return None
        if isinstance(res, SdoEvent):
            return t, struct.unpack("<H", res.data[:2])[0]
    return None


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "hil.cli", *args]


def _csv_rows(path: Path) -> int:
    try:
        return max(0, path.read_text().count("\n") - 1)
    except OSError:
        return 0


def one_kill(k: int, delay_s: float, args, act, work: Path) -> dict:
    """Start sim-serve and run, SIGKILL run ``delay_s`` after its first sample; measure."""
    c = act.canopen
    T = act.timing.sync_period_s
    nodes = c.node_ids
    master_ids = {0x000, 0x080, 0x700 + c.master_node_id} | {b + n for b in (0x200, 0x300) for n in nodes}
    out = work / f"kill{k:02d}"
    prof = ["--profile", str(args.profile)]
    row: dict = {"kill": k, "delay_s": round(delay_s, 3)}
    rec = Recorder()
    procs: list[subprocess.Popen] = []
    try:
        serve = subprocess.Popen(_cli("sim-serve", "--interface", "udp_multicast", "--channel", GROUP, *prof,
                                      "--sim", str(args.sim)), cwd=ROOT, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True)
        procs.append(serve)
        t0 = time.monotonic()
        line = ""
        while "ready" not in line and time.monotonic() - t0 < READY_TIMEOUT_S:
            line = serve.stdout.readline()
            if not line and serve.poll() is not None:
                break
        if "ready" not in line:
            raise RuntimeError(f"sim-serve not ready: {line!r}")
        threading.Thread(target=serve.stdout.read, daemon=True).start()  # keep its pipe drained
        with open(work / f"run{k:02d}.out", "w") as run_log:  # (the child has its own copy of the fd)
            run = subprocess.Popen(_cli("run", "--interface", "udp_multicast", "--channel", GROUP, "--arm",
                                        "--quiet", "--no-history", *prof, "--check", str(args.check),
                                        "--out", str(out)),
                                   cwd=ROOT, stdout=run_log, stderr=subprocess.STDOUT)
        procs.append(run)
        t0 = time.monotonic()
        while _csv_rows(out / "signals.csv") < 1 and run.poll() is None and time.monotonic() - t0 < START_TIMEOUT_S:
            time.sleep(0.005)
        if run.poll() is not None or _csv_rows(out / "signals.csv") < 1:
            raise RuntimeError(f"run ended or did not start its cyclic phase (exit {run.poll()})")
        t_cyclic = time.monotonic()
        while time.monotonic() - t_cyclic < delay_s and run.poll() is None:
            time.sleep(min(0.005, max(0.0, delay_s - (time.monotonic() - t_cyclic))))
        if run.poll() is not None:
            row["after_loop"] = True
            return row
        t_kill = time.time()
        run.send_signal(signal.SIGKILL)
        run.wait(10)
        row["killed_after_s"] = round(time.monotonic() - t_cyclic, 3)
        # the drives on their own: poll their statuswords until both are switch on disabled
        bound_sod = c.master_consumer_time_s + QUICK_STOP_HOLD_S + 2 * T + POLL_S
        deadline = time.time() + bound_sod + 2.0
        first_sod: dict[int, float] = {}
        last_state: dict[int, str] = {}
        while time.time() < deadline and len(first_sod) < len(nodes):
            for n in nodes:
                got = read_statusword(rec, n)
                if got is not None:
                    state = decode_state(got[1])
                    last_state[n] = state.name
                    if state is State.SWITCH_ON_DISABLED:
                        first_sod.setdefault(n, got[0])
            time.sleep(POLL_S)
        time.sleep(0.05)
        final = {n: (s := read_statusword(rec, n)) and decode_state(s[1]).name for n in nodes}
    finally:
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM if p is procs[0] else signal.SIGKILL)
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        rec.close()
    frames = rec.frames
    t_last = max(t for t, cid, _ in frames if cid in master_ids and t <= t_kill + 0.005)
    last_hb = max(t for t, cid, _ in frames if cid == 0x700 + c.master_node_id and t <= t_kill + 0.005)
    emcy = {n: min((t for t, cid, d in frames if cid == 0x80 + n and t > t_last and d[:2] == b"\x30\x81"),
                   default=None) for n in nodes}
    row.update(
        t_last_hb_s=round(last_hb - t_last, 4),
        emcy_after_last_s={n: None if v is None else round(v - t_last, 4) for n, v in emcy.items()},
        sod_after_last_s={n: round(first_sod[n] - t_last, 4) if n in first_sod else None for n in nodes},
        final={n: final[n] for n in nodes}, polled={n: last_state.get(n) for n in nodes},
        csv_rows=_csv_rows(out / "signals.csv"),
    )
    try:
        tail = (out / "signals.csv").read_text().rstrip("\n").rsplit("\n", 1)[-1].split(",")
        row["last_step"], row["last_F_N"] = tail[-1], [float(tail[5]), float(tail[6])]
    except (OSError, IndexError, ValueError):
        pass
    bound_oe = c.master_consumer_time_s + 2 * T
    row["ok"] = (all(v is not None and v <= bound_oe + 1e-9 for v in row["emcy_after_last_s"].values())
                 and all(v is not None and v <= bound_sod + 1e-9 for v in row["sod_after_last_s"].values())
                 and all(v == State.SWITCH_ON_DISABLED.name for v in row["final"].values()))
    return row


def check_duration_s(act, chk, sim_path: Path, work: Path) -> float:
    """The check's duration on the plant alone (no CAN, as `emacheck simulate` runs it) [s]."""
    from hil.check.runner import PlantLink, run_check
    from hil.record.runfolder import MetaWriter
    from hil.record.runrecord import RunMode, start_record
    from sim.plant import RigPlant

    sim = load_simrig(sim_path)
    plant = RigPlant(sim.params, np.random.default_rng(sim.seed))
    meta = MetaWriter(work / "duration", start_record(act, chk, mode=RunMode.SIMULATE))
    out = run_check(PlantLink(plant), act, chk, meta)
    return out.duration_s


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--profile", type=Path, default=DEFAULT_PROFILE)
    ap.add_argument("--sim", type=Path, default=DEFAULT_SIM)
    ap.add_argument("--check", type=Path, default=DEFAULT_CHECK)
    ap.add_argument("--json", type=Path, default=Path("bench_master_loss.json"))
    ap.add_argument("--keep", type=Path, help="keep the run folders here (default: a temporary directory)")
    args = ap.parse_args(argv)
    why = cannot_run()
    if why:
        print(f"SKIP: {why}", flush=True)
        return SKIP
    if os.environ.get(NETNS_ENV) != "1":
        return reexec_in_private_netns(argv)
    act = load_actuation(args.profile)
    chk = load_check(args.check, act)
    c, T = act.canopen, act.timing.sync_period_s
    with tempfile.TemporaryDirectory() as d:
        duration = check_duration_s(act, chk, args.sim, Path(d))
    print(f"bench_master_loss: seed {args.seed}, {args.kills} kills of `emacheck run` in [0, {0.95 * duration:.1f}) s "
          f"of its cyclic phase; consumer time {c.master_consumer_time_s * 1e3:.0f} ms (master heartbeat every "
          f"{c.master_heartbeat_period_s * 1e3:.0f} ms), SYNC {T * 1e3:.0f} ms, quick stop hold "
          f"{QUICK_STOP_HOLD_S * 1e3:.0f} ms", flush=True)
    rng = np.random.default_rng(args.seed)
    rows: list[dict] = []
    after_loop = 0
    t_start = time.monotonic()
    with tempfile.TemporaryDirectory() as d:
        work = args.keep or Path(d)
        work.mkdir(parents=True, exist_ok=True)
        k = 0
        while len(rows) < args.kills and after_loop <= args.kills:
            delay = float(rng.uniform(0.0, 0.95 * duration))
            row = one_kill(k, delay, args, act, work)
            k += 1
            if row.get("after_loop"):
                after_loop += 1
                continue
            rows.append(row)
            e, s = row["emcy_after_last_s"], row["sod_after_last_s"]
            print(f"kill {len(rows):2d} at {row['killed_after_s']:6.2f} s ({row.get('last_step', '?'):<11}) "
                  f"EMCY 0x8130 after the master's last frame {e} s, switch on disabled read {s} s, "
                  f"final {row['final']}: {'ok' if row['ok'] else 'NOT SAFE'}", flush=True)
    wall = time.monotonic() - t_start
    oe = [v for r in rows for v in r["emcy_after_last_s"].values() if v is not None]
    sod = [v for r in rows for v in r["sod_after_last_s"].values() if v is not None]
    bad = [r["kill"] for r in rows if not r["ok"]]
    summary = {
        "seed": args.seed, "kills": len(rows), "after_loop_redrawn": after_loop, "not_safe": len(bad),
        "consumer_time_s": c.master_consumer_time_s, "sync_period_s": T, "quick_stop_hold_s": QUICK_STOP_HOLD_S,
        "bound_out_of_operation_enabled_s": c.master_consumer_time_s + 2 * T,
        "bound_switch_on_disabled_s": c.master_consumer_time_s + QUICK_STOP_HOLD_S + 2 * T + POLL_S,
        "out_of_operation_enabled_s": {"min": min(oe, default=None), "max": max(oe, default=None),
                                       "median": float(np.median(oe)) if oe else None},
        "switch_on_disabled_read_s": {"min": min(sod, default=None), "max": max(sod, default=None)},
        "wall_s": round(wall, 1), "profile": str(args.profile), "check": str(args.check), "rows": rows,
    }
    print(f"{len(rows) - len(bad)} of {len(rows)} kills: both drives out of Operation enabled (EMCY 0x8130) "
          f"{summary['out_of_operation_enabled_s']['min']}..{summary['out_of_operation_enabled_s']['max']} s after "
          f"the master's last frame (bound {summary['bound_out_of_operation_enabled_s']:.3f} s), switch on disabled "
          f"read {summary['switch_on_disabled_read_s']['min']}..{summary['switch_on_disabled_read_s']['max']} s "
          f"(bound {summary['bound_switch_on_disabled_s']:.3f} s); {len(bad)} left a drive enabled or late "
          f"{bad}; seed {args.seed}; {after_loop} draw(s) after the check were drawn again; {wall:.0f} s wall")
    args.json.write_text(json.dumps(summary, indent=2, default=str))
    print(f"wrote {args.json}")
    return 0 if not bad and len(rows) == args.kills else 1


if __name__ == "__main__":
    sys.exit(main())
