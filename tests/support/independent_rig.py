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
import re
import tempfile
import time
from functools import cache
from pathlib import Path

from support.once import made_once

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "independent-rig"
KEYS: dict = json.loads((DATA / "keys.json").read_text()) if (DATA / "keys.json").exists() else {}
CALIBRATED = ("lvdt_pitch", "lvdt_offset")
SHIPPED_ACTUATION = Path(__file__).resolve().parents[2] / "profiles" / "actuation.toml"


def rig_i_total() -> float | None:
    """The rig's motor-to-ram ratio (rad/mm) as its README states it (``i_total = 5.0265 rad/mm``).

    Our shipped profile says 2*pi*4/5 = 5.026548 rad/mm; the recordings' rig uses the README's
    rounded 5.0265, 9.6 ppm less, which a diagnosis with the shipped profile rightly reports as an
    LVDT pitch error of about +1e-5 at both EMAs (the LVDTs are calibrated against the motor angle).
    A test engineer states the rig's ratio in the actuation profile; so do the tests."""
    readme = DATA / "README.md"
    if not readme.exists():
        return None
    m = re.search(r"i_total\s*=\s*([0-9]+(?:\.[0-9]+)?)\s*rad/mm", readme.read_text())
    return float(m.group(1)) if m else None


@cache
def rig_profile() -> Path | None:
    """The shipped actuation profile with the rig's ratio (:func:`rig_i_total`) in it, written to a
    temporary file (``--profile`` of ``emacheck diagnose``); None where the README does not state it."""
    i_total = rig_i_total()
    if i_total is None:
        return None
    text, n = re.subn(r"(?m)^i_total_rad_per_mm\s*=.*$",
                      f"i_total_rad_per_mm = {i_total!r}   # the rig's README",
                      SHIPPED_ACTUATION.read_text())
    assert n == 1, "the shipped actuation profile has no i_total_rad_per_mm line"
    path = Path(tempfile.mkdtemp(prefix="emacheck-indep-")) / "actuation.toml"
    path.write_text(text)  # its EDS, not next to it, is then the shipped one
    return path


def diagnose_file(path: Path, profile: Path | None = None):
    """(Diagnosis, seconds) of one recording, through the CLI's loader (no files written), with
    ``profile`` (default :func:`rig_profile`) as ``--profile``."""
    from blf.diagnose.engine import diagnose
    from hil.analysis.diagnose.load import load_model
    model, period = load_model(path, "dual-ema", profile or rig_profile())
    t0 = time.process_time()
    d = diagnose(model, period)
    return d, time.process_time() - t0


def diagnosed(name: str, shared: Path | None = None):
    """:func:`diagnose_file` of the set's recording ``name`` with :func:`rig_profile`: (Diagnosis, CPU seconds).

    With ``shared`` (a folder every process of one test run sees: ``conftest.run_shared``) each recording is
    diagnosed once per test run, by the first process to ask (holding a lock on it; the others wait and read
    its pickled answer, the CPU seconds its own diagnosis took). test_diagnose_independent.py diagnoses all 19
    and test_diagnose_floors.py 12 of them again, through the same ``diagnose`` of the same model (issue 13's
    dev set, the floors, the pairs): the second asker reads the first's, bit for bit the same answer
    (docs/performance.md, "Test suite, fifth pass"). Without ``shared``: diagnosed here."""
    path = DATA / f"{name}.csv.gz"
    if shared is None:
        return diagnose_file(path)
    return made_once(shared, f"indep-{name}", lambda: diagnose_file(path))


class SharedFits(dict):
    """A ``cache`` for :func:`hil.analysis.diagnose.dual_reference.dual_reference_diagnosis` whose fits of the
    set's recordings (loaded with :func:`rig_profile`) come from :func:`diagnosed` (once per test run), the
    nominal covariance computed here from it as ``_fitted`` does. The cache's keys are dual_reference's:
    ``("loaded", path, profile)`` -> recording, ``("fitted", id(recording))`` -> (diagnosis, covariance)."""

    def __init__(self, shared: Path | None):
        super().__init__()
        self.shared = shared

    def __contains__(self, key) -> bool:
        if dict.__contains__(self, key):
            return True
        if self.shared is None or not (isinstance(key, tuple) and key[:1] == ("fitted",)):
            return False
        rec = next((v for k, v in self.items() if k[0] == "loaded" and id(v) == key[1]), None)
        loaded = next(k for k, v in self.items() if v is rec) if rec is not None else None
        name = Path(rec.path).name.removesuffix(".csv.gz") if rec is not None else None
        if (name not in KEYS or Path(rec.path).resolve() != (DATA / f"{name}.csv.gz").resolve()
                or loaded[2] != str(rig_profile())):
            return False
        from blf.diagnose import nominal_covariance
        d, _ = diagnosed(name, self.shared)
        self[key] = (d, nominal_covariance(rec.model, rec.period_s, d.nominal))
        return True


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
