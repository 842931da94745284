"""What a floor covers (issue 48, "Floors that say what they cover"; docs/diagnose.md, "What a floor covers").

A floor measured within one test session (two halves of one healthy recording, repeated fits of one rig
model) is a **repeatability**: it does not cover what moves between sessions, re-assemblies and days (the
healthy Cranfield actuator's friction moves by about 96 N RMS between sessions, against a 75 N floor
measured within one). A floor measured across healthy recordings of several sessions is a
**reproducibility**. Every floor of diagnosis.json says which it is (``floor.coverage``, :func:`coverage`).

Given several healthy references (``--reference`` more than once, single axis), the floors are measured
from their spread (:func:`floors_from_references`): every pair of references compared as a recording is
against its reference, the force parameters' changes (friction, direction-dependent force) and the
tracking error's (lag, jitter ratio) pooled per kind, each floor
:math:`3\\sqrt{\\overline{\\Delta^2}}` (:func:`blf.diagnose.witness.floor_from_spread`). The recording is
compared against the first reference; the others measure the floors.
"""

from __future__ import annotations

from itertools import combinations
from pathlib import Path

from hil.analysis.diagnose.results import rounded
from hil.errors import RecordingError

#: what a single-session default does not cover
REPEATABILITY_WORDS = ("a repeatability: measured within one test session (halves of one healthy recording); it "
                       "does not cover what changes between sessions, re-assemblies or days (the healthy Cranfield "
                       "actuator's friction moves by about 96 N RMS between sessions, more than this floor): a "
                       "change of about that size may be a session offset, not the actuator; give several "
                       "healthy references of different sessions (--reference more than once) to measure a "
                       "reproducibility")


def coverage(kind: str, words: str, **more) -> dict:
    """diagnosis.json's ``floor.coverage``: ``kind`` repeatability, reproducibility or stated, with words."""
    assert kind in ("repeatability", "reproducibility", "stated")
    return {"kind": kind, "words": words} | more


def default_coverage(stated: bool) -> dict:
    """The coverage of a single-axis comparison against one reference: the measured defaults (a repeatability)
    or a floor stated with ``--force-floor-N`` (what it covers is the user's statement)."""
    if stated:
        return coverage("stated", "the force floor was stated (--force-floor-N): it covers what its author measured "
                        "it over; the tracking error's floors are the defaults, " + REPEATABILITY_WORDS)
    return coverage("repeatability", "every floor is a default, " + REPEATABILITY_WORDS)


def dual_coverage(floors: dict) -> dict:
    """The coverage of a dual-EMA comparison's floors (``by_kind``): the measured defaults
    (:data:`hil.profile.floors.DUAL_FLOORS`) are a repeatability (rig models and repeated simulated checks: no
    session-to-session change); a kind set in the check profile's ``[diagnosis]`` is stated there."""
    from hil.profile.floors import DUAL_FLOORS
    stated = sorted(k for k, v in floors.items() if k in DUAL_FLOORS and v != DUAL_FLOORS[k])
    words = ("the defaults are a repeatability: measured on rig models and repeated simulated checks, which have "
             "no session-to-session change (temperature, re-assembly, days); a real rig's spread between checks is "
             "larger (the Cranfield actuator's friction: about 96 N RMS between sessions), so a change under it "
             "may be a session offset; state a rig's own reproducibility in the check profile's [diagnosis]")
    if stated:
        return coverage("stated", f"{', '.join(stated)} stated in the check profile's [diagnosis]: they cover what "
                        f"their author measured them over; the others: {words}", stated=stated)
    return coverage("repeatability", words)


def _pairs(refs: list, opts, witness_floors: dict) -> tuple:
    """The changes between every pair of references: ({force parameter: [N]}, [lag m], [jitter ratio])."""
    from blf.diagnose import compare_axis
    from blf.errors import AnalysisError
    from hil.analysis.diagnose import witness
    from hil.analysis.diagnose.single_axis import prepared_pair
    force, lag, jit = {}, [], []
    for a, b in combinations(refs, 2):
        pair = prepared_pair(b, a, opts)
        try:
            cmp = compare_axis(pair.prepared_new, pair.prepared_ref, opts.force_floor_N, opts.z_min, pair.gain_rel_u)
        except AnalysisError as exc:
            raise RecordingError(f"--reference {b} against --reference {a}: {exc}") from None
        for c in cmp.changes:
            if c.name in ("friction_N", "coulomb_N", "offset_N"):
                force.setdefault(c.name, []).append(c.change)
        changes, _ = witness.compare_pair(pair.new, pair.ref, witness_floors, opts.z_min)
        if changes is not None:
            lag.append(changes[0].change)
            jit.append(changes[1].change)
    return force, lag, jit


def floors_from_references(refs, opts, stated: bool) -> tuple:
    """(force floor N, tracking error floors, diagnosis.json's ``floor.coverage``) measured from the spread of
    several healthy references (paths, at least two, all distinct).

    A floor stated with ``--force-floor-N`` is kept (``stated``), the spread reported beside it. Raises
    :class:`RecordingError` (exit 3) for a reference given twice, references without any spread (a floor
    of 0 would name every change) or a pair that cannot be compared."""
    from blf.diagnose.witness import floor_from_spread
    from hil.analysis.diagnose.witness import WITNESS_FLOORS
    refs = [Path(r) for r in refs]
    seen = [r.resolve() for r in refs]
    twice = sorted({str(r) for r, s in zip(refs, seen, strict=True) if seen.count(s) > 1})
    if twice:
        raise RecordingError(f"--reference {', '.join(twice)}: given more than once; each healthy reference once")
    force, lag, jit = _pairs(refs, opts, WITNESS_FLOORS)
    values = [v for vs in force.values() for v in vs]
    n_pairs = len(refs) * (len(refs) - 1) // 2
    f_force = floor_from_spread(values) if values else None
    f_w = dict(WITNESS_FLOORS)
    measured_w = []
    if lag:
        f_w = {"tracking_lag_m": floor_from_spread(lag), "tracking_jitter_ratio": floor_from_spread(jit)}
        measured_w = ["tracking_lag_m", "tracking_jitter_ratio"]
    zero = [k for k, v in ({"force_N": f_force} | f_w).items() if v is not None and not v > 0]
    if zero:
        raise RecordingError(f"--reference: the {len(refs)} references show no spread in {', '.join(zero)}: a floor "
                             "cannot be measured from them (the same recording twice?)")
    force_floor = opts.force_floor_N if stated or f_force is None else f_force
    spread = {"force_N": rounded(f_force), "tracking_lag_m": rounded(f_w["tracking_lag_m"]),
              "tracking_jitter_ratio": rounded(f_w["tracking_jitter_ratio"])}
    words = (f"a reproducibility over the {len(refs)} healthy references given ({n_pairs} pair(s), 3 x the RMS of "
             f"their changes{', with few pairs an estimate' if n_pairs < 3 else ''}): it covers what differs "
             "between them (sessions, re-assemblies, days as far as they were recorded so), not what none of them "
             "saw; the recording is compared against the first reference")
    if stated:
        words = ("the force floor was stated (--force-floor-N), the spread of the references reported beside it; "
                 "the tracking error's floors are " + words)
    cov = coverage("stated" if stated else "reproducibility", words, references=[str(r) for r in refs],
                   pairs=n_pairs, from_spread=spread,
                   changes={"force_N": [rounded(v) for v in values], "tracking_lag_m": [rounded(v) for v in lag],
                            "tracking_jitter_ratio": [rounded(v) for v in jit]},
                   measured=(["force_N"] if not stated and f_force is not None else []) + measured_w)
    return force_floor, f_w, cov


def dual_floors_from_spread(pooled: dict, folders: list, floors: dict) -> tuple:
    """(floors by kind, diagnosis.json's ``floor.coverage``) of a dual-EMA comparison whose reference is the
    wear history's, from the changes between every pair of its healthy checks of the same actuators
    (``pooled``: floor key -> changes in its unit, separable sized parameters only, of the ``folders``
    compared pairwise: :func:`hil.analysis.diagnose.dual_reference.history_floors`): each kind's floor is 3 x
    the RMS of its changes; a kind without a change, or with no spread, keeps its floor."""
    from blf.diagnose.witness import floor_from_spread
    spread = {k: floor_from_spread(v) for k, v in pooled.items() if v}
    measured = sorted(k for k, v in spread.items() if v > 0)
    n_pairs = len(folders) * (len(folders) - 1) // 2
    few = ", with few pairs an estimate" if n_pairs < 3 else ""
    words = (f"a reproducibility over the wear history's {len(folders)} latest healthy checks of these actuators "
             f"({n_pairs} pair(s), 3 x the RMS of their changes per kind{few}): {', '.join(measured) or 'no kind'} "
             "measured so; it covers what moved between those checks (sessions, days, what was done to the rig "
             "between them), not what none of them saw; the other kinds: " + dual_coverage(floors)["words"])
    cov = coverage("reproducibility", words, references=[str(f) for f in folders], pairs=n_pairs,
                   from_spread={k: rounded(v) for k, v in spread.items()},
                   changes={k: [rounded(x) for x in v] for k, v in pooled.items()}, measured=measured)
    return floors | {k: spread[k] for k in measured}, cov
