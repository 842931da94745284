"""BLFmaint and the verdict on recordings of a rig model written independently of sim/ (../shared).

The 19 development recordings of ``../shared/data/independent-rig`` (7-column CSVs, no step column:
the phases are found from the data; LVDT pitch errors up to 7.5 %; library and out-of-library
effects) with their keys: every channel must be measured within 5 um of the true backlash and the
check must pass (every backlash is far below B_spec). Skipped with the reason where ../shared is absent.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hil.analysis.maint import analyze_signals, result_dict
from hil.profile.load import load_actuation
from hil.record.runfolder import read_signals
from support.ci import skip_or_fail

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "independent-rig"
KEYS = json.loads((DATA / "keys.json").read_text()) if (DATA / "keys.json").exists() else {}

pytestmark = pytest.mark.slow


@pytest.fixture(autouse=True)
def _needs_the_shared_recordings():
    if not KEYS:
        skip_or_fail(f"independent-rig recordings not present at {DATA} (../shared/data)")


@pytest.mark.parametrize("name", sorted(KEYS) or ["none"])
def test_every_channel_measured_within_5_um_and_the_check_passes(name):
    act = load_actuation()
    an = analyze_signals(read_signals(DATA / f"{name}.csv.gz"), act)
    r = result_dict(an, act)
    truth = KEYS[name]["truth"]["backlash_mm"]
    assert an.segments.source == "detected"  # no step column: the phases were found from the data
    for ch, b_true in truth.items():
        b = r["backlash_mm"][ch]
        assert b is not None, (ch, r["blf_maint"][ch])
        assert abs(b - b_true) <= 0.005, (ch, b, b_true)
        v = r["verdict"][ch]
        assert v["status"] == "pass" and v["backlash_mm"] + v["uncertainty_mm"] <= v["limit_mm"]
    assert r["status"] == "pass"
    for k, pitch in zip(("ema1", "ema2"), KEYS[name]["lvdt_pitch"], strict=True):
        assert r["calibration"][k]["pitch"] == pytest.approx(pitch, rel=2e-3)
