"""The independent-rig development recordings (../shared/data/independent-rig) and the issue-13 rules.

What tests/test_diagnose_independent.py and tests/bench/bench_diagnose_dev.py share:
where the recordings are (:data:`DATA`), their keys (:data:`KEYS`), the
diagnosis of one recording as ``emacheck diagnose`` makes it (:func:`diagnose_file`)
and the judgement of issue 13 (:func:`judge`):

* effect recordings: ``explained``, every expected ``[name, where]`` among the
  effects, extras only at ``external`` plus at most one other;
* effect-free and pitch-error recordings: ``no_mismatch``, or effects only at
  ``external`` or the LVDT pitch/offset it calibrated;
* out-of-library (``["unexplained", "emaN"]``): ``unexplained`` with the rest
  located first at emaN.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "independent-rig"
KEYS: dict = json.loads((DATA / "keys.json").read_text()) if (DATA / "keys.json").exists() else {}
CALIBRATED = ("lvdt_pitch", "lvdt_offset")


def diagnose_file(path: Path):
    """(Diagnosis, seconds) of one recording, through the CLI's loader (no files written)."""
    from blf.diagnose import diagnose
    from hil.analysis.diagnose import load_model
    model, period = load_model(path, "dual-ema", None)
    t0 = time.process_time()
    d = diagnose(model, period)
    return d, time.process_time() - t0


def judge(expect: list, verdict: str, effects: list, where: list) -> tuple[bool, str]:
    """Right by issue 13's rules? ``effects`` as [(name, where)]; returns (ok, why)."""
    exp = [tuple(e) for e in expect]
    if exp and exp[0][0] == "unexplained":
        ema = exp[0][1]
        if verdict != "unexplained":
            return False, f"verdict {verdict}, expected unexplained at {ema}"
        if not where or where[0] != ema:
            return False, f"unexplained, but located at {where or 'nowhere'}, expected {ema}"
        return True, f"unexplained at {ema}"
    if not exp:
        bad = [e for e in effects if e[1] != "external" and e[0] not in CALIBRATED]
        if verdict == "unexplained":
            return False, "unexplained, expected no_mismatch"
        if bad:
            return False, f"named {bad}, expected none"
        return True, verdict
    missing = [e for e in exp if e not in effects]
    extra = [e for e in effects if e not in exp and e[1] != "external"]
    if verdict != "explained":
        return False, f"verdict {verdict}" + (f", missing {missing}" if missing else "")
    if missing:
        return False, f"missing {missing}"
    if len(extra) > 1:
        return False, f"extras {extra}"
    return True, "explained"
