"""Shared fixtures: one simulated default check per test session (it takes ~2 s)."""

from __future__ import annotations

import atexit
import gc
import os
import shutil
import sys
import tempfile
from pathlib import Path

# Bytecode: this machine's environment sets PYTHONDONTWRITEBYTECODE=1, so every pytest process (each
# xdist worker, every run) compiled the project's modules and rewrote the ~90 test modules' asserts
# anew: about 4 of a worker's 7.5 s of collection CPU (docs/performance.md, "Fast loop, fourth pass").
# The tests' own process writes its bytecode (git-ignored __pycache__; pytest's rewritten test modules
# under their own tag); each file's is checked against its source's mtime and size at every import, as
# Python's own cache is. The commands the tests start keep the environment's setting and read it.
sys.dont_write_bytecode = False

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


# --- pytest-xdist: the run is split over worker processes (docs/testing.md, "Parallel") ---

#: groups whose tests share something of the host and so run one at a time, on one worker: named in the
#: test modules with ``pytestmark = pytest.mark.xdist_group(...)``. Every other test's group is its module
#: (its module-scoped fixtures are built once per run, as in a serial run).
#: The groups that take longest, started first so that none of them is left to run alone at the end (the
#: vcan stage first; it runs beside the other worker since 2026-11-27, docs/testing.md, "Parallel").
FIRST_GROUPS = ("vcan", "tests/test_eds.py", "tests/test_diagnose_independent.py", "tests/test_diagnose_floors.py",
                "tests/test_diagnose_dual_reference.py", "wall_clock", "tests/test_independent_rig.py")


def pytest_addoption(parser, pluginmanager):
    """Without pytest-xdist (``-p no:xdist`` or not installed) the addopts' ``-n``/``--dist`` are accepted
    and ignored: the tests run serially in this process."""
    if pluginmanager.has_plugin("xdist"):
        return
    group = parser.getgroup("xdist", "pytest-xdist not loaded: serial run")
    group._addoption("-n", "--numprocesses", dest="ignored_numprocesses", default=None,
                     help="ignored: pytest-xdist is not loaded, the tests run in this process")
    group.addoption("--dist", dest="ignored_dist", default="no", help="ignored: pytest-xdist is not loaded")
    group.addoption("--no-loadscope-reorder", dest="ignored_loadscopereorder", action="store_false", default=True,
                    help="ignored: pytest-xdist is not loaded")


def pytest_report_header(config):
    if not config.pluginmanager.has_plugin("xdist"):
        return "pytest-xdist not loaded: the tests run serially in this process"
    return None


#: this process is a pytest-xdist worker (not: a pytest it started, which inherits PYTEST_XDIST_WORKER)
_XDIST_WORKER = False


def pytest_configure(config):
    global _XDIST_WORKER
    _XDIST_WORKER = hasattr(config, "workerinput")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Each test without an ``xdist_group`` gets its module's (before xdist reads the marks: tryfirst);
    the longest groups are moved to the front (stable: the order within a group is kept)."""
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::", 1)[0]))

    def group(item) -> str:
        return str(item.get_closest_marker("xdist_group").args[0])

    items.sort(key=lambda item: FIRST_GROUPS.index(group(item)) if group(item) in FIRST_GROUPS
               else len(FIRST_GROUPS))


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session):
    """What collection built (the imported modules, numba's and scipy's objects, the test items: ~260 000
    objects the collector tracks, ~0.1-0.2 s per full collection) lives until the run ends: moved out of
    the collector's generations, so its full collections (during the tests, and pytest's five at the end
    of the session, which look for unraisable exceptions) no longer walk it. Garbage made after this is
    collected as before."""
    gc.collect()
    gc.freeze()


def once_per_run(tmp_path_factory, name: str, make):
    """``make(folder) -> picklable`` run once per test run, however many xdist workers ask.

    Serially (no worker) it is simply called in a new temporary folder. Under xdist the first worker to
    ask builds it under the run's shared base folder, holding a lock; the others wait and read its
    pickled answer. A ``make`` that raises leaves no answer: the next worker tries again (and fails the
    same way), as each would serially."""
    from support.once import made_once

    if not _XDIST_WORKER:
        return make(tmp_path_factory.mktemp(name))
    root = tmp_path_factory.getbasetemp().parent / f"once-{name}"

    def make_afresh():
        folder = root / "made"
        if folder.exists():  # a failed attempt's leftovers
            shutil.rmtree(folder)
        folder.mkdir()
        return make(folder)

    return made_once(root, "answer", make_afresh)


@pytest.fixture(scope="session")
def run_shared(tmp_path_factory) -> Path:
    """A folder every process of this test run sees (each xdist worker and the processes they start), for
    answers made once per run and read by all (``support.independent_rig.diagnosed``). Serially: a new
    temporary folder."""
    if not _XDIST_WORKER:
        return tmp_path_factory.mktemp("shared")
    root = tmp_path_factory.getbasetemp().parent / "run-shared"
    root.mkdir(exist_ok=True)
    return root


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

    def make(where: Path) -> dict:
        out = where / "run"
        return {"out": str(out), "rc": main(["dry-run", "--out", str(out), "--quiet"])}

    made = once_per_run(tmp_path_factory, "dry", make)
    return Path(made["out"]), made["rc"]


@pytest.fixture(scope="session")
def default_run(tmp_path_factory, actuation, check_profile, simrig):
    """Run folder of one simulated check with the shipped profiles and seed.

    Its users are marked ``slow`` (a whole simulated check): the fast loop never runs it."""
    def make(where: Path) -> dict:
        out = where / "default"
        outcome, truth = simulate_run(out, actuation, check_profile, simrig, simrig.seed)
        assert outcome.status == "done", outcome.reason
        return {"out": str(out), "truth": truth}

    made = once_per_run(tmp_path_factory, "run", make)
    return Path(made["out"]), made["truth"]


@pytest.fixture(scope="session")
def stalled_dry_runs(tmp_path_factory) -> dict:
    """The shipped check's in-process dry-run (:func:`hil.cli.dry_run.dry_run`, the shipped profiles and seed, no
    fault) with the master stalling every 5 s for 45 ms (the issue's figure) and for 50 ms (the derived limit),
    each made once per test run: tests/test_master_stalls.py and tests/test_faults.py each ran both, the same
    call on the same profiles (docs/performance.md, "Test suite, sixth pass"). ``{stall_ms: run}``, each run
    what those tests read of :class:`hil.cli.dry_run.DryRun`: ``out`` (its run folder, which no test changes),
    ``exit_code`` and ``link.tr.stalls.injected`` (the stalls injected, [(t, s)])."""
    from types import SimpleNamespace

    from hil.cli.dry_run import dry_run as dry_run_in_process

    def make(where: Path) -> dict:
        act, sim = load_actuation(), load_simrig()
        chk = load_check(None, act)
        made = {}
        for ms in (45.0, 50.0):
            r = dry_run_in_process(act, chk, sim, where / f"stalled{ms:g}", stall=(ms, 5.0))
            made[ms] = {"out": str(r.out), "exit_code": r.exit_code, "injected": list(r.link.tr.stalls.injected)}
        return made

    made = once_per_run(tmp_path_factory, "stalled", make)
    return {ms: SimpleNamespace(out=Path(r["out"]), exit_code=r["exit_code"],
                                link=SimpleNamespace(tr=SimpleNamespace(stalls=SimpleNamespace(injected=r["injected"]))))
            for ms, r in made.items()}
