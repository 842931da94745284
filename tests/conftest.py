"""Shared fixtures: one simulated default check per test session (it takes ~2 s)."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from pathlib import Path

# One OpenBLAS thread for the tests and every command they start (subprocesses inherit it); set
# before numpy is first imported, which loads OpenBLAS. The tests' matrices are small, and on a
# shared machine OpenBLAS's second thread waits for a busy core: test_blf_maint.py took 15-31 s with
# the default threads and 4-5 s with one, back to back at load average 3.5-3.9 (docs/performance.md,
# "Test suite cost"). An explicit setting wins. The product is unchanged (results agree within an ulp).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from hil.profile.load import load_actuation, load_check, load_simrig  # noqa: E402

SHARED = Path(__file__).resolve().parents[2] / "shared"

# `run`, `analyze` and `serv` record every real result in the wear history, by default an SQLite
# file in the user's data directory (platformdirs: $XDG_DATA_HOME, else ~/.local/share). The tests
# and every command they start (subprocesses inherit it) write to a temporary one instead.
os.environ["XDG_DATA_HOME"] = tempfile.mkdtemp(prefix="emacheck-test-data-")
atexit.register(shutil.rmtree, os.environ["XDG_DATA_HOME"], ignore_errors=True)


@pytest.fixture(scope="session")
def actuation():
    return load_actuation()


@pytest.fixture(scope="session")
def check_profile(actuation):
    return load_check(None, actuation)


@pytest.fixture(scope="session")
def simrig():
    return load_simrig()


def simulate_run(out: Path, act, check, simrig_profile, seed: int):
    """The check on the plant, as `emacheck simulate` runs it, without the terminal."""
    from hil.check.runner import PlantLink, run_check
    from hil.cli.check import truth_dict
    from hil.record.runfolder import MetaWriter
    from hil.record.runrecord import RunMode, start_record
    from sim.plant import RigPlant
    from sim.truth import rig_truth

    plant = RigPlant(simrig_profile.params, np.random.default_rng(seed))
    truth = truth_dict(rig_truth(simrig_profile.params))
    meta = MetaWriter(out, start_record(act, check, mode=RunMode.SIMULATE, seed=seed, truth=truth))
    outcome = run_check(PlantLink(plant), act, check, meta)
    return outcome, truth


@pytest.fixture(scope="session")
def dry_run(tmp_path_factory):
    """``emacheck dry-run`` with the shipped profiles and seed (over the in-process CANopen bus):
    its run folder and exit status. Users are marked ``slow``; none may change the folder's files."""
    from hil.cli import main

    out = tmp_path_factory.mktemp("dry") / "run"
    rc = main(["dry-run", "--out", str(out), "--quiet"])
    return out, rc


@pytest.fixture(scope="session")
def default_run(tmp_path_factory, actuation, check_profile, simrig):
    """Run folder of one simulated check with the shipped profiles and seed.

    Its users are marked ``slow`` (a whole simulated check): the fast loop never runs it."""
    out = tmp_path_factory.mktemp("run") / "default"
    outcome, truth = simulate_run(out, actuation, check_profile, simrig, simrig.seed)
    assert outcome.status == "done", outcome.reason
    return out, truth
