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
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest


@contextmanager
def one_fit_per_recording() -> Iterator[dict]:
    """Within it, the dual-EMA reference diagnosis reads and fits each recording once (see the module)."""
    from hil.analysis.diagnose import dual_reference as dr

    shared: dict = {}
    load_pair, fitted = dr.load_pair, dr._fitted

    def load_pair_shared(new_path, ref_path, profile, cache, accept_modified=False):
        return load_pair(new_path, ref_path, profile, shared, accept_modified)

    def fitted_shared(rec, cache):
        return fitted(rec, shared)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(dr, "load_pair", load_pair_shared)
        mp.setattr(dr, "_fitted", fitted_shared)
        yield shared


@pytest.fixture(scope="module")
def module_fits_once():
    """:func:`one_fit_per_recording` for a whole test module: import it into the module and add
    ``pytest.mark.usefixtures("module_fits_once")`` to its ``pytestmark`` (the module's docstring says why it may)."""
    with one_fit_per_recording():
        yield
