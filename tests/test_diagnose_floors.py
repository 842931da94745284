"""The dual-EMA model's default floors (hil.analysis.diagnose_floors) against their measurement (issue 35, part 2).

Slow (about 30 s CPU): diagnoses the independent rig's effect-free recordings (../shared, skipped with the
reason where absent) and checks that each default floor covers 3 sqrt(2) times the standard deviation of
the nominal fit's identification error (the default is the larger of this and the simulated checks'
spread, docs/diagnose.md).
"""

from __future__ import annotations

import pytest

from support.ci import skip_or_fail
from support.independent_rig import DATA

pytestmark = pytest.mark.slow


def test_the_play_stiffness_and_gain_floors_cover_three_sqrt2_times_the_identification_spread():
    if not (DATA / "keys.json").exists():
        skip_or_fail(f"independent-rig recordings not present at {DATA} (../shared/data)")
    from bench.bench_diagnose_floors import independent

    from hil.analysis.diagnose_floors import DUAL_FLOORS
    ind = independent()
    for kind in ("play_um", "stiffness_pct", "sensor_gain_pct", "loadcell_gain_pct"):
        assert ind[kind]["floor_3sqrt2_sd"] <= DUAL_FLOORS[kind], kind
        assert abs(ind[kind]["mean"]) < 3 * ind[kind]["sd"]  # no bias beyond the spread: the fit is right
