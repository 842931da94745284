"""The Cranfield ball-screw actuator recordings (../shared/data/cranfield-actuator) as single-axis CSVs.

Not shipped data: the files are read where they are (``CRANFIELD``) and never copied into the
project; a test that needs them skips with the reason where the folder is absent
(:func:`require`). See the folder's README.md and data_description.pdf.

Each file holds 3 loads x 10 runs x 5 cycles of 324 samples at 25 Hz, columns ``set_point`` (mm),
``position_error`` (mm, set point minus measured position), ``current`` (A), ``profile``, ``load``
(kgf), ``run``, ``fault_type``, ``group``, ``time`` (s within the cycle). :func:`single_axis` selects
a load and runs and writes the single-axis layout of ``emacheck diagnose --model single-axis``:

* ``t`` (s): continuous, sample k at k / 25 Hz (the cycles and runs one after the other);
* ``q`` (m): (set_point - position_error) / 1000, the measured nut position;
* ``q_ref`` (m): set_point / 1000;
* ``current`` (A): the drive's current, as recorded;
* ``load`` (N): load (kgf) x 9.80665, the known external load.
"""

from __future__ import annotations

import csv
import gzip
from functools import lru_cache
from pathlib import Path

import numpy as np

CRANFIELD = Path(__file__).resolve().parents[3] / "shared" / "data" / "cranfield-actuator"
SAMPLE_RATE_HZ = 25.0
G_N_PER_KGF = 9.80665
DEVELOPMENT = ("normal", "lackLubrication1", "backlash1", "spalling1", "spalling3", "spalling5", "spalling7")
_NUMERIC = ("set_point", "position_error", "current", "load", "run", "time")


def require() -> Path:
    """The data folder, or skip (fail under CI=true) with the reason where it is absent."""
    from support.ci import skip_or_fail
    if not (CRANFIELD / "normal.csv.gz").exists():
        skip_or_fail(f"Cranfield actuator recordings not present at {CRANFIELD} (../shared/data)")
    return CRANFIELD


@lru_cache(maxsize=8)
def read_condition(name: str, folder: Path = CRANFIELD) -> dict:
    """The numeric columns of ``<name>.csv.gz`` as float arrays (cached)."""
    with gzip.open(folder / f"{name}.csv.gz", "rt", newline="") as f:
        rows = csv.reader(f)
        head = next(rows)
        at = [head.index(c) for c in _NUMERIC]
        data = np.array([[float(r[j]) for j in at] for r in rows])
    return {c: data[:, i] for i, c in enumerate(_NUMERIC)}


def single_axis(name: str, load_kgf: float, runs, folder: Path = CRANFIELD) -> dict:
    """Single-axis columns (``t,q,q_ref,current,load``, SI) of one condition, load and set of runs."""
    d = read_condition(name, folder)
    sel = (d["load"] == load_kgf) & np.isin(d["run"], list(runs))
    if not sel.any():
        raise ValueError(f"{name}: no samples at {load_kgf} kgf, runs {sorted(runs)}")
    sp = d["set_point"][sel]
    n = int(sel.sum())
    return {"t": np.arange(n) / SAMPLE_RATE_HZ, "q": (sp - d["position_error"][sel]) / 1000.0,
            "q_ref": sp / 1000.0, "current": d["current"][sel], "load": d["load"][sel] * G_N_PER_KGF}


def write_single_axis(path: Path, name: str, load_kgf: float, runs, folder: Path = CRANFIELD) -> Path:
    """Write :func:`single_axis` as a CSV (header ``t,q,q_ref,current,load``) and return its path."""
    cols = single_axis(name, load_kgf, runs, folder)
    arr = np.column_stack([cols[c] for c in ("t", "q", "q_ref", "current", "load")])
    np.savetxt(path, arr, delimiter=",", header="t,q,q_ref,current,load", comments="", fmt="%.9g")
    return Path(path)
