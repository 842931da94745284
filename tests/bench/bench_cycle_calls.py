"""Benchmark (not a test): the per-cycle calls of the PDO codec's users, one at a time, on the dry-run's own objects.

Runs ``emacheck dry-run --quiet`` once in this process, keeps the master's SetpointEncoder and CycleDecoder
and drive 1 of the simulated pair, puts the drive in OPERATIONAL / OPERATION ENABLED in CSP (as in the check's
cyclic phase), and times each call with ``timeit`` (best of ``--repeat`` runs of ``--number`` calls: the least
disturbed run on a shared machine):

* ``SetpointEncoder.frames``: one drive's synchronous RPDO (controlword, target position and torque);
* ``CycleDecoder.feed x2``: the drive's two TPDOs (after a ``reset``);
* ``send_sync_tpdos``: the drive's two TPDOs assembled and queued, the inputs computed afresh (``measure``);
* ``on_rpdo + apply``: the drive's RPDO latched and applied (the controlword repeated);
* ``drive_cycle``: one CSP cycle of the drive;
* ``decode_state``: one statusword.

With ``--old DIR`` the same script runs in that checkout too (``python -m`` in a fresh process each,
alternating, ``--rounds`` times) and the best figure of each tree is printed side by side.

Usage: python tests/bench/bench_cycle_calls.py [--old DIR] [--rounds 2] [--number 5000] [--repeat 25]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import subprocess
import sys
import tempfile
import timeit
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _measure(root: Path, number: int, repeat: int) -> dict[str, float]:
    sys.path.insert(0, str(root))  # the tree measured (this one, or the --old one for a child)
    import hil.canopen.cycle as cycle
    import sim.drives.pair as pair_mod
    from hil.canopen.cia402 import State, decode_state
    from hil.canopen.nmt import NmtState
    from hil.cli import main as cli

    kept: dict[str, object] = {}
    for cls in (pair_mod.SimDrivePair, cycle.SetpointEncoder, cycle.CycleDecoder):
        init = cls.__init__

        def keep(self, *a, _init=init, _name=cls.__name__, **k):
            _init(self, *a, **k)
            kept[_name] = self

        cls.__init__ = keep
    with tempfile.TemporaryDirectory() as td, contextlib.redirect_stdout(io.StringIO()):
        assert cli(["dry-run", "--out", f"{td}/run", "--quiet"]) == 0
    pair, enc, dec = kept["SimDrivePair"], kept["SetpointEncoder"], kept["CycleDecoder"]
    drive = pair.nodes[0]
    drive.nmt_state = NmtState.OPERATIONAL
    drive.state_machine.state = State.OPERATION_ENABLED
    drive.int_cache[(0x6060, 0)] = 8  # CSP
    drive.store.put(0x6065, 0, (0xFFFF_FFFF).to_bytes(4, "little"))  # no following error monitoring
    rpdo = enc.frames(1, 0x000F, 0.5, 0.0)[0]
    rx = drive.rpdos_by_cob_id[rpdo.arbitration_id]
    drive.send_sync_tpdos(1.0)
    tpdos = list(drive.outbox)
    drive.outbox.clear()
    raw = pair._raw_sample

    def sync_tpdos():
        drive.measure(raw)
        drive.send_sync_tpdos(1.0)
        drive.outbox.clear()

    def feed():
        dec.reset()
        for f in tpdos:
            dec.feed(f)

    def rpdo_in():
        drive.on_rpdo(rx, rpdo, 1.0)
        drive.apply_latched_rpdos()

    calls = {"SetpointEncoder.frames": lambda: enc.frames(1, 0x000F, 0.5, 0.0), "CycleDecoder.feed x2": feed,
             "send_sync_tpdos": sync_tpdos, "on_rpdo + apply": rpdo_in, "drive_cycle": drive.drive_cycle,
             "decode_state": lambda: decode_state(0x1237)}
    return {name: min(timeit.repeat(f, number=number, repeat=repeat)) / number * 1e9 for name, f in calls.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", type=Path, help="another checkout to run the same calls in, alternating")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--number", type=int, default=5000)
    ap.add_argument("--repeat", type=int, default=25)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child or a.old is None:
        got = _measure(Path.cwd() if a.child else ROOT, a.number, a.repeat)
        if a.child:
            print(json.dumps(got))
        else:
            for name, ns in got.items():
                print(f"{name:24s} {ns:8.0f} ns")
        return 0
    trees = {"old": a.old.resolve(), "new": ROOT}
    best: dict[str, dict[str, float]] = {"old": {}, "new": {}}
    for _ in range(a.rounds):
        for label, tree in trees.items():
            env = dict(os.environ, PYTHONPATH=str(tree))
            out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", "--number",
                                  str(a.number), "--repeat", str(a.repeat)], cwd=tree, env=env, check=True,
                                 capture_output=True, text=True).stdout
            for name, ns in json.loads(out.splitlines()[-1]).items():
                best[label][name] = min(ns, best[label].get(name, ns))
    print(f"{'call':24s} {'old ns':>8s} {'new ns':>8s}")
    for name in best["new"]:
        print(f"{name:24s} {best['old'][name]:8.0f} {best['new'][name]:8.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
