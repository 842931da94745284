"""``emacheck diagnose``'s one way into the analysis: a request in, an outcome out.

The command line reads its arguments into a :class:`DiagnoseRequest`; :func:`diagnose_recording` routes it
to the mode it names and returns a :class:`DiagnoseOutcome` (diagnosis.json's dict and what the report draws
from); nothing here writes. The modes:

* against the simulation (no reference): :func:`hil.analysis.diagnose.against_model.diagnose_against_model`;
* a single axis against a reference recording: :func:`hil.analysis.diagnose.axis_reference.reference_diagnosis`;
* a dual-EMA check against a reference run folder, recording or the wear history's last check of the same
  actuators: :func:`hil.analysis.diagnose.dual_reference.dual_reference`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from hil.analysis.diagnose.results import DiagnoseOutcome
from hil.analysis.diagnose.single_axis import AxisOptions
from hil.errors import RecordingError

#: the models ``--model`` names
MODELS = ("dual-ema", "single-axis")


@dataclass(frozen=True)
class DiagnoseRequest:
    """What ``emacheck diagnose`` was asked (paths as given; checked by :func:`diagnose_recording`)."""

    recording: Path
    model: str = "dual-ema"  #: one of :data:`MODELS`
    profile: Path | None = None  #: the actuation profile (dual-EMA; default: the run folder's, else the shipped)
    axis: AxisOptions = AxisOptions()  #: a single axis: how to read its effort, its force floor
    force_floor_stated: bool = False  #: ``--force-floor-N`` given (without a reference it then applies)
    reference: Path | None = None  #: the healthy recording, or None
    more_references: tuple = ()  #: further healthy recordings (``--reference`` again): the floors from their spread
    from_history: bool = False  #: ``--reference history``: the wear history's last check of the same actuators
    history_url: str | None = None  #: ... in this database (dual-EMA)
    check: Path | None = None  #: dual-EMA reference: the check profile whose ``[diagnosis]`` floors apply
    allow_other_serials: bool = False
    accept_modified: bool = False  #: a run folder's recording changed after its check: diagnosed anyway, said so


def diagnose_recording(req: DiagnoseRequest, progress: Callable[[str], None] | None = None) -> DiagnoseOutcome:
    """The diagnosis the request names; :class:`hil.errors.RecordingError` (exit 3) for a recording or
    reference that cannot be diagnosed, naming it."""
    if req.reference is None and not req.from_history:
        from hil.analysis.diagnose.against_model import diagnose_against_model
        return diagnose_against_model(req.recording, req.model, req.profile, req.axis, req.force_floor_stated,
                                      progress, accept_modified=req.accept_modified)
    if req.from_history and req.model != "dual-ema":
        raise RecordingError("--reference history: the wear history holds dual-EMA checks; a single axis needs "
                             "its reference recording")
    for ref in () if req.from_history else (req.reference, *req.more_references):
        if not Path(ref).exists():
            raise RecordingError(f"--reference {ref}: no such file")
    if req.more_references and req.model != "single-axis":
        raise RecordingError("--reference given more than once: floors measured from several references are for "
                             "a single axis; a dual-EMA check's floors are its check profile's [diagnosis]")
    t0 = time.perf_counter()
    if req.model == "single-axis":
        from hil.analysis.diagnose.axis_reference import reference_diagnosis
        out = DiagnoseOutcome("axis_reference", reference_diagnosis(
            req.recording, Path(req.reference), req.axis, tuple(Path(r) for r in req.more_references),
            req.force_floor_stated))
    else:
        from hil.analysis.diagnose.dual_reference import dual_reference
        data, fits = dual_reference(req.recording, req.reference, req.profile, req.check,
                                    req.history_url if req.from_history else None, req.allow_other_serials,
                                    accept_modified=req.accept_modified)
        out = DiagnoseOutcome("dual_reference", data, fits=fits)
    out.data["diagnosis_s"] = round(time.perf_counter() - t0, 2)
    return out
