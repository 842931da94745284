"""Work made once per test run however many pytest-xdist workers ask for it (lock and pickle in a folder they all
see): conftest ``once_per_run``, the independent rig's diagnoses (``support.independent_rig.diagnosed``) and the
dual-EMA fits (``support.shared_fits``) share it."""

from __future__ import annotations

import fcntl
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

T = TypeVar("T")


def made_once(folder: Path, name: str, make: Callable[[], T]) -> T:
    """``make()`` once for ``name`` in ``folder``: the first process to ask makes it holding a lock
    (``NAME.lock``) and pickles the answer (``NAME.pickle``, written whole and then renamed); the others wait
    and read that. A ``make`` that raises leaves no answer: the next asker makes it again (and fails the same
    way)."""
    folder.mkdir(parents=True, exist_ok=True)
    answer = folder / f"{name}.pickle"
    with open(folder / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if answer.exists():
                return pickle.loads(answer.read_bytes())
            made = make()
            part = answer.with_suffix(".part")
            part.write_bytes(pickle.dumps(made, protocol=pickle.HIGHEST_PROTOCOL))
            part.replace(answer)
            return made
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
