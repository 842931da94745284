"""Commissionings at normal priority on this PC, for docs/commission.md (not a test:
``python tests/bench/bench_commission_pc.py N OUT [BURNERS]``).

Runs N two-process commissionings of the clean simulated rig (``emacheck sim-serve`` + ``emacheck commission
--arm`` on python-can's udp_multicast in a private network namespace, :func:`support.netns.serve_and_master`),
one after the other, at the shipped 500 Hz and normal scheduling, each into ``OUT/run-NN``, and prints one JSON
line per run: the exit status, the report's status and findings (stage, kind, key), the load average at its
start and end and the wall time. The issue's target: every run completes (READY) or stops naming the PC
(a ``pc.*`` key). ``BURNERS`` (default 0): that many processes spinning on the CPU at normal priority for
the whole batch, besides whatever else runs (the other programs of a PC that is loaded: 2 on this 2-core
machine keep every core busy).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (support)

from support.netns import cannot_run, serve_and_master  # noqa: E402


def main(n: int, base: Path, burners: int = 0) -> int:
    if why := cannot_run():
        print(f"cannot run: {why}", file=sys.stderr)
        return 1
    base.mkdir(parents=True, exist_ok=True)
    burn = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(burners)]
    try:
        return _batch(n, base, burners)
    finally:
        for p in burn:
            p.kill()
            p.wait()


def _batch(n: int, base: Path, burners: int) -> int:
    for i in range(n):
        out = base / f"run-{i:02d}"
        load0, t0 = os.getloadavg()[0], time.monotonic()
        r = serve_and_master([], ["commission", "--arm", "--out", str(out)], timeout_s=240)
        wall = time.monotonic() - t0
        try:
            rep = json.loads((out / "commission.json").read_text())
            keys, status = [(f["stage"], f["kind"], f["key"]) for f in rep["findings"]], rep["status"]
        except (OSError, ValueError) as exc:
            keys, status = [repr(exc)], "no report"
        print(json.dumps({"run": i, "rc": r["master_rc"], "status": status, "findings": keys,
                          "burners": burners, "load1_start": round(load0, 2), "load1_end": round(os.getloadavg()[0], 2),
                          "wall_s": round(wall, 1)}), flush=True)
        (base / f"run-{i:02d}.out.txt").write_text(r["master_out"] + "\n----\n" + r["serve_out"])
    return 0


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    sys.exit(main(int(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3]) if len(sys.argv) == 4 else 0))
