"""Benchmark of the simulated rig: 60,000 samples (2 min at 2 ms, 8 substeps).

Not collected by pytest (no test_ functions; the file name does not match).
Usage::

    python tests/bench/bench_plant.py [out.json]

Times (after a warm-up that triggers / loads the numba compilation):

* ``step``: one :meth:`RigPlant.step` per sample with fresh ``Setpoint``
  objects and the returned ``Sample`` (what the sequence core does);
* ``step_raw``: the plain-number fast path;
* ``run``: the compiled batch loop.

Prints seconds and samples/s per variant and writes them as JSON to the path
given on argv (default ``bench_plant.json`` in the current directory).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))  # the repository
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # tests/ (support)

from hil.canopen.process import DriveMode, Setpoint  # noqa: E402
from sim.params import RigParams  # noqa: E402
from sim.plant import RigPlant  # noqa: E402
from support.rigs import I_TOTAL, brief_rig  # noqa: E402

N_SAMPLES = 60_000


def default_params() -> RigParams:
    return brief_rig()


def trajectory(n: int) -> tuple[np.ndarray, np.ndarray]:
    """BLFmaint-like: force fight +-0.4 mm at 0.1 Hz over a slow common motion (rad)."""
    t = np.arange(n) * 0.002
    d = 0.4 * np.sin(2 * np.pi * 0.1 * t)
    c = 2.0 * np.sin(2 * np.pi * 0.02 * t)
    return (c + d) * I_TOTAL, (c - d) * I_TOTAL


def main(argv: list[str]) -> int:
    out_path = argv[1] if len(argv) > 1 else "bench_plant.json"
    params = default_params()
    x1, x2 = trajectory(N_SAMPLES)
    pos = DriveMode.POSITION

    t0 = time.perf_counter()
    warm = RigPlant(params, np.random.default_rng(0))
    warm.step(Setpoint(pos, 0.0), Setpoint(pos, 0.0))
    warm.run(int(pos), np.zeros(10), int(pos), np.zeros(10))
    compile_s = time.perf_counter() - t0

    results = {}
    plant = RigPlant(params, np.random.default_rng(1))
    l1, l2 = x1.tolist(), x2.tolist()
    t0 = time.perf_counter()
    for k in range(N_SAMPLES):
        plant.step(Setpoint(pos, l1[k]), Setpoint(pos, l2[k]))
    results["step"] = time.perf_counter() - t0

    plant = RigPlant(params, np.random.default_rng(1))
    p8 = int(pos)
    t0 = time.perf_counter()
    for k in range(N_SAMPLES):
        plant.step_raw(p8, l1[k], p8, l2[k], 0.0)
    results["step_raw"] = time.perf_counter() - t0

    plant = RigPlant(params, np.random.default_rng(1))
    t0 = time.perf_counter()
    plant.run(p8, x1, p8, x2)
    results["run"] = time.perf_counter() - t0

    report = {
        "samples": N_SAMPLES,
        "sample_period_s": params.sample_period_s,
        "substeps": params.substeps,
        "warmup_compile_or_cache_load_s": compile_s,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    for name, sec in results.items():
        report[f"{name}_s"] = sec
        report[f"{name}_samples_per_s"] = N_SAMPLES / sec
        print(f"{name:9s} {sec:7.3f} s   {N_SAMPLES / sec:12,.0f} samples/s")
    print(f"warm-up (compile or cache load) {compile_s:.2f} s")
    with open(out_path, "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=2)
    print(f"wrote {out_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv))
