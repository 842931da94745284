"""A recording against the simulation (``emacheck diagnose RECORDING``, no reference): its diagnosis.

The dual-EMA model replays the recording (:mod:`hil.analysis.diagnose.load`); a single axis is read and,
with a known load, its effort checked against it first (:mod:`hil.analysis.diagnose.single_axis`): an
effort that does not see its load is not diagnosed. The core is :func:`blf.diagnose.diagnose`; with a
stated force floor a single axis's effects under it are named no more (:func:`apply_force_floor`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hil.analysis.diagnose.load import load_dual
from hil.analysis.diagnose.results import (
    DiagnoseOutcome,
    diagnosis_dict,
    identifiability_dict,
    rounded,
    untrusted_dict,
    with_notes,
)
from hil.analysis.diagnose.single_axis import AxisOptions, axis_model
from hil.errors import RecordingError


def diagnose_against_model(path: Path, model_name: str, profile: Path | None, opts: AxisOptions,
                           force_floor_stated: bool = False,
                           progress: Callable[[str], None] | None = None, *,
                           accept_modified: bool = False) -> DiagnoseOutcome:
    """diagnosis.json of a recording against the simulation, with the replay model and the diagnosis its
    report draws; a single axis whose effort does not see its known load: the reason, nothing diagnosed
    (verdict ``untrusted_effort``). ``force_floor_stated``: a single axis's ``opts.force_floor_N`` was
    stated (``--force-floor-N``) and applies to its effects too."""
    from blf.diagnose import diagnose
    from blf.errors import AnalysisError, InputError
    t0 = time.perf_counter()
    effort = None
    try:
        if model_name == "single-axis":
            rec, effort, model, period = axis_model(path, opts)  # read once: the effort check and the model
            if model is None:
                return DiagnoseOutcome("model", with_notes(untrusted_dict(effort), rec.notes))
        else:
            if not Path(path).exists():
                raise RecordingError(f"{path}: no such file or folder")
            rec = load_dual(Path(path), profile, accept_modified)
            model, period = rec.model, rec.period_s
        d = diagnose(model, period, progress=progress)
    except (InputError, AnalysisError) as exc:  # the recording does not support a diagnosis: bad input
        raise RecordingError(f"{path}: cannot be diagnosed: {exc}") from None
    data = diagnosis_dict(d, model_name, time.perf_counter() - t0)
    ident = identifiability_dict(model)
    if model_name == "single-axis" and force_floor_stated:
        data = apply_force_floor(data, effect_sizes_N(model, d), opts.force_floor_N)
    if ident is not None:
        mask = ident.pop("mask", None)
        data["identifiability"] = ident
        if mask is not None:
            data["mask"] = mask
    if effort is not None:
        data["effort"] = effort
    return DiagnoseOutcome("model", with_notes(data, rec.notes), model=model, diagnosis=d)


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
