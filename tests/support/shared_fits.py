"""One read and one fit per recording for a test module's ``emacheck diagnose --reference`` commands.

``emacheck diagnose NEW --reference REF`` (dual-EMA) reads and fits both recordings anew at every call
(:func:`hil.analysis.diagnose.dual_reference.load_pair` and ``_fitted``, with a cache that lives for the
call). A test module that runs the command in process a dozen times against the same healthy check
refitted it a dozen times (~2 s to read and ~3-4 s to fit, each). Within :func:`one_fit_per_recording`
the command's cache is one dict for the whole module: each recording (by its resolved path and the
actuation profile given) is read and fitted at its first use, and every later command takes that
recording and fit, the same objects (the fit is deterministic: the same recording gives the same numbers).
What each command does with them (floors, comparisons, the history's reference, its refusals, the files
it writes) runs at every call. Use it only where no recording changes at its path within the module and no
test expects a recording's own refusal (the seal of a run folder changed after its check, a reading
refused): a cached recording is not read again.

Across modules (:func:`module_fits_once` under a test run's ``run_shared`` folder): test_diagnose_dual_reference.py
and test_diagnose_history_floors.py each simulate the same checks (the shipped rig with noise seeds 11 and 14;
10 N more Coulomb friction at EMA 1 with seed 13), each in its own run folder, and fitted each. A fit is now
made once per test run for each replay model: keyed by the sha256 of everything the fit reads (every array,
number and name of the model, :func:`model_key`, and the sample period), the first process to ask fits it
holding a lock and pickles (diagnosis, covariance), the others read that, bit for bit what their own fit of
the same model gives (docs/performance.md, "Test suite, sixth pass"). A model with anything the key cannot
read is fitted where it is asked, as before.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from support.once import made_once


class _Unkeyable(Exception):
    pass


def _feed(h, obj, seen: set) -> None:
    """Feed ``obj`` into the hash ``h``: arrays by dtype, shape and bytes; numbers, strings and bytes by type
    and repr; tuples, lists and dicts (keys sorted by repr) element by element; dataclasses and plain objects by
    class and fields (a model's memo ``_cache`` left out: what it memoises follows from the rest)."""
    if isinstance(obj, np.ndarray):
        h.update(f"nd{obj.dtype.str}{obj.shape}".encode())
        h.update(np.ascontiguousarray(obj).tobytes())
    elif obj is None or isinstance(obj, (bool, int, float, complex, str, bytes, np.generic)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
    elif isinstance(obj, (tuple, list)):
        h.update(f"{type(obj).__name__}[{len(obj)}".encode())
        for x in obj:
            _feed(h, x, seen)
        h.update(b"]")
    elif isinstance(obj, dict):
        h.update(f"dict[{len(obj)}".encode())
        for k in sorted(obj, key=repr):
            _feed(h, k, seen)
            _feed(h, obj[k], seen)
        h.update(b"]")
    else:
        if id(obj) in seen:
            raise _Unkeyable(f"a cycle at {type(obj).__qualname__}")
        seen.add(id(obj))
        cls = type(obj)
        if dataclasses.is_dataclass(obj):
            fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
        elif cls.__module__.split(".")[0] in ("sim", "blf", "hil") and hasattr(obj, "__dict__"):
            fields = {k: v for k, v in vars(obj).items() if k != "_cache"}
        else:
            raise _Unkeyable(f"{cls.__module__}.{cls.__qualname__}")
        h.update(f"{cls.__module__}.{cls.__qualname__}(".encode())
        _feed(h, fields, seen)
        h.update(b")")
        seen.discard(id(obj))


def model_key(model, period_s: float) -> str | None:
    """sha256 of everything a replay model holds (see :func:`_feed`) and the sample period; None where it holds
    something that is not read into the key."""
    h = hashlib.sha256()
    try:
        _feed(h, (model, period_s), set())
    except _Unkeyable:
        return None
    return h.hexdigest()


@contextmanager
def one_fit_per_recording(run_shared: Path | None = None) -> Iterator[dict]:
    """Within it, the dual-EMA reference diagnosis reads and fits each recording once (see the module); with
    ``run_shared`` (conftest ``run_shared``) each replay model is fitted once per test run."""
    from hil.analysis.diagnose import dual_reference as dr

    shared: dict = {}
    load_pair, fitted = dr.load_pair, dr._fitted

    def load_pair_shared(new_path, ref_path, profile, cache, accept_modified=False):
        return load_pair(new_path, ref_path, profile, shared, accept_modified)

    def fitted_shared(rec, cache):
        k = ("fitted", id(rec))
        if run_shared is not None and k not in shared:
            key = model_key(rec.model, rec.period_s)
            if key is not None:
                shared[k] = made_once(run_shared / "fits", f"fit-{key}", lambda: fitted(rec, {}))
        return fitted(rec, shared)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(dr, "load_pair", load_pair_shared)
        mp.setattr(dr, "_fitted", fitted_shared)
        yield shared


@pytest.fixture(scope="module")
def module_fits_once(run_shared):
    """:func:`one_fit_per_recording` for a whole test module, each model's fit once per test run: import it into the
    module and add ``pytest.mark.usefixtures("module_fits_once")`` to its ``pytestmark`` (the module's docstring
    says why it may)."""
    with one_fit_per_recording(run_shared):
        yield
