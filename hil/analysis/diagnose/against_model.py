"""A recording against the simulation (``emacheck diagnose RECORDING``, no reference): its diagnosis.json."""

from __future__ import annotations

import numpy as np

from hil.analysis.diagnose.results import rounded


def effect_sizes_N(model, d) -> dict:
    """Each library effect's size as a force: the largest change of the predicted force over the samples
    compared when it alone is taken out (N), at the fitted nominal parameters."""
    theta = np.array([d.nominal[n] for n in model.names])
    by_name = {c.name: c for c in model.candidates}
    active = [(by_name[e.name], np.array([e.parameters[p.name] for p in by_name[e.name].params]))
              for e in d.effects if e.name in by_name]
    ok = model.valid["force"]
    full = model.predict(theta, active)["force"]
    return {cand.name: float(np.max(np.abs(full - model.predict(theta, [a for a in active if a[0] is not cand])
                                           ["force"])[ok]))
            for cand, _ in active}


def apply_force_floor(data: dict, sizes: dict, floor_N: float) -> dict:
    """diagnosis.json of a single axis without a reference with a stated force floor: an effect whose force
    is under it is moved to ``below_floor`` (named no more); an ``explained`` verdict left without
    effects becomes ``no_mismatch``. The residual figures stay those of the fit with every effect."""
    keep, below = [], []
    for e in data["effects"]:
        size = sizes.get(e["name"])
        e["size_N"] = rounded(size)
        (below if size is not None and size <= floor_N else keep).append(e)
    data["effects"], data["below_floor"] = keep, below
    data["floor"] = {"force_N": floor_N, "words": (
        f"an effect is named only when its force (the largest change of the predicted force it makes over the "
        f"samples compared) exceeds {floor_N:g} N (stated); residual figures include every accepted effect")}
    if data["verdict"] == "explained" and not keep:
        data["verdict"] = "no_mismatch"
    return data
