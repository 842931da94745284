"""``emacheck analyze`` on a large signals CSV: peak memory and wall time (not a test).

Usage: python tests/bench/bench_large_csv.py [--rows 10000000] [--json bench_large_csv.json] [--keep DIR]

``--rows`` is rounded up to whole laps of the dry-run.

Makes a bare 7-column CSV (``t,phi1,phi2,s1,s2,F1,F2``, the run folder's number formats) of ``--rows``
rows in a temporary folder: a dry-run's recording (``emacheck dry-run --seed 42``) repeated, each lap
joined to the next by a one-second straight line back to its start, the time running on (a recording
joined end to start would jump in position, and ``analyze`` refuses jumps). Then runs
``emacheck analyze FILE --out DIR`` in a subprocess and reports its peak resident memory (``ru_maxrss``
of the children, resource.getrusage) and wall time, the size of the file and of the decoded arrays
(7 float64 columns), and the exit status, and whether the peak is within issue 34's target of
1.2 GB (``TARGET_MB``; stated for 10 million rows). Prints a table and writes JSON.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
FORMATS = ("%.4f", "%.7f", "%.7f", "%.6f", "%.6f", "%.3f", "%.3f")
BLOCK = 200_000
JOIN_S = 1.0  #: the straight line from one lap's end back to the next lap's start [s]
TARGET_MB = 1200.0  #: issue 34's target for the peak of analyze on 10 million rows [MB]


def _emacheck(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hil.cli", *args], cwd=cwd, capture_output=True, text=True)


def make_csv(path: Path, rows: int, work: Path) -> int:
    """At least ``rows`` rows of a dry-run recording repeated, each lap joined to the next by a one-second
    straight line from its last sample back to its first, the time running on; ends with a whole lap
    (a check cut mid-way has a force fight too short to analyse). Returns the number of rows."""
    run = work / "dry"
    done = _emacheck("dry-run", "--seed", "42", "--out", str(run), cwd=ROOT)
    if done.returncode != 0:
        raise SystemExit(f"dry-run failed ({done.returncode}): {done.stderr}")
    src = np.loadtxt(run / "signals.csv", delimiter=",", skiprows=1, usecols=range(7))
    period = float(np.median(np.diff(src[:, 0])))
    ramp_rows = int(round(JOIN_S / period))
    w = (np.arange(1, ramp_rows + 1) / (ramp_rows + 1))[:, None]
    lap = np.vstack([src, src[-1] + w * (src[0] - src[-1])])
    rows = -(-rows // lap.shape[0]) * lap.shape[0] - ramp_rows  # whole laps, the last without its ramp
    with open(path, "w") as fh:
        fh.write("t,phi1,phi2,s1,s2,F1,F2\n")
        k = 0
        while k < rows:
            idx = np.arange(k, min(k + BLOCK, rows))
            block = lap[idx % lap.shape[0]]
            block[:, 0] = src[0, 0] + idx * period
            np.savetxt(fh, block, fmt=",".join(FORMATS))
            k += BLOCK
    return rows


def measure(big: Path, out: Path) -> None:
    """Run analyze on ``big`` as this process's only child; print its peak RSS and wall time as JSON."""
    t0 = time.perf_counter()
    done = _emacheck("analyze", str(big), "--out", str(out), "--no-history", cwd=ROOT)
    wall = time.perf_counter() - t0
    print(json.dumps({"ru_maxrss_KiB": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss,
                      "wall_s": wall, "exit_status": done.returncode,
                      "stderr_tail": done.stderr.strip().splitlines()[-3:]}))


def main() -> None:
    if sys.argv[1:2] == ["--measure"]:
        measure(Path(sys.argv[2]), Path(sys.argv[3]))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=10_000_000)
    ap.add_argument("--json", default="bench_large_csv.json")
    ap.add_argument("--keep", type=Path, help="make the CSV and the outputs here (kept) instead of a temp folder")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-large-csv-") as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        big = work / "large.csv"
        t0 = time.perf_counter()
        rows = make_csv(big, args.rows, work)
        made_s = time.perf_counter() - t0
        # measured in a process of its own whose only child is analyze (RUSAGE_CHILDREN is the
        # largest peak of all the children, the dry-run above included)
        done = subprocess.run([sys.executable, __file__, "--measure", str(big), str(work / "analysis")],
                              capture_output=True, text=True)
        measured = json.loads(done.stdout.strip().splitlines()[-1])
        peak_kib, wall = measured["ru_maxrss_KiB"], measured["wall_s"]
        fig = {
            "command": f"python tests/bench/bench_large_csv.py --rows {args.rows}",
            "rows": rows,
            "file_MB": round(big.stat().st_size / 1e6, 1),
            "arrays_MB": round(rows * 7 * 8 / 1e6, 1),
            "peak_rss_MB": round(peak_kib * 1024 / 1e6, 1),
            "peak_over_arrays": round(peak_kib * 1024 / (rows * 7 * 8), 2),
            "target_MB": TARGET_MB,
            "within_target": peak_kib * 1024 / 1e6 <= TARGET_MB,
            "analyze_wall_s": round(wall, 1),
            "make_csv_s": round(made_s, 1),
            "exit_status": measured["exit_status"],
            "stderr_tail": measured["stderr_tail"],
        }
    for k, v in fig.items():
        print(f"{k:>20}: {v}")
    Path(args.json).write_text(json.dumps(fig, indent=2) + "\n")


if __name__ == "__main__":
    main()
