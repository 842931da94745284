"""A quantised LVDT or load cell against its stated noise (issue 36, part 4; hil/check/resolution.py).

Known answer: the bound on false frozen-sensor stops checked by simulation where the rates can be counted;
boundaries: ``profile check`` and ``dry-run`` on either side of the largest step that works; the
message names the key, the step and the step that works, and nothing is sent or written."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hil.check.resolution import FALSE_STOPS, largest_step, sensor_steps
from hil.cli import main
from hil.profile.load import load_actuation, load_check
from hil.profile.rig import plan_for
from support.profiles import write_profile_variant


def _false_stops(q: float, sigma: float, m: int, cycles: int, checks: int, rng) -> float:
    """Mean count of supervisor frozen stops (more than ``m`` exact repeats; the count restarts after a stop)
    per check of ``cycles`` samples at rest, the true value at a step's centre (the rule's worst case)."""
    stops = 0
    for _ in range(checks):
        x = np.round(rng.normal(0.0, sigma, cycles) / q)
        same = 0
        for eq in x[1:] == x[:-1]:
            same = same + 1 if eq else 0
            if same > m:
                stops += 1
                same = 0
    return stops / checks


def test_the_bound_holds_where_the_rate_can_be_counted():
    """With M = 4 and N = 2000 the rule's alpha = 0.2 is countable: at q_max the mean number of false stops
    per check stays below alpha, and within a factor of 4 of it (the bound is not needlessly strict: 0.095
    counted); at 2 q_max it is many times alpha (1.6 counted: the rule is not vacuous)."""
    rng = np.random.default_rng(20261126)
    sigma, m, n, alpha = 1.0, 4, 2000, 0.2
    q = largest_step(sigma, m, n, alpha)
    assert q == pytest.approx(2 * math.sqrt(2) * sigma * 0.14139, rel=1e-3)  # erfinv((0.2/2000)**0.2) = 0.14139
    at_bound = _false_stops(q, sigma, m, n, 400, rng)
    assert alpha / 4 < at_bound <= alpha
    assert _false_stops(2 * q, sigma, m, n, 100, rng) > 5 * alpha


@pytest.mark.parametrize("p", [1e-6, 4e-6, 1e-3, 0.01, 0.14139, 0.48, 0.5, 0.9, 0.999, 1 - 1e-9, 1 - 1e-12])
def test_the_inverse_error_function_is_scipys(p):
    """The standard library's quantile (hil.check.resolution._erfinv, no scipy before the loop) gives
    scipy.special.erfinv: within 6e-15 relative from 0.01 up, 6e-11 down to 1e-6 (checked on dense grids)."""
    from scipy.special import erfinv

    from hil.check.resolution import _erfinv

    assert _erfinv(p) == pytest.approx(float(erfinv(p)), rel=1e-10 if p < 0.01 else 1e-14, abs=0)


def test_the_shipped_rig_and_its_numbers():
    act = load_actuation()
    check = load_check(None, act)
    steps = {s.key: s for s in sensor_steps(plan_for(act).plan, act, check)}
    assert set(steps) == {f"signals.ema{k}.{s}" for k in (1, 2) for s in ("lvdt.mm_per_unit", "force.N_per_unit")}
    lvdt = steps["signals.ema1.lvdt.mm_per_unit"]
    assert lvdt.step == pytest.approx(0.001) and lvdt.sigma == pytest.approx(0.025 / 6)
    assert lvdt.largest == pytest.approx(0.00566, abs=5e-5) and lvdt.largest_at_cap == pytest.approx(0.01165, abs=5e-5)
    assert steps["signals.ema2.force.N_per_unit"].largest == pytest.approx(13.6, abs=0.05)
    assert all(s.ok for s in steps.values()) and FALSE_STOPS == 1e-3


@pytest.fixture(scope="module")
def q_max():
    act = load_actuation()
    s = next(s for s in sensor_steps(plan_for(act).plan, act, load_check(None, act))
             if s.key == "signals.ema2.lvdt.mm_per_unit")
    return s.largest


@pytest.mark.parametrize("factor, rc", [(0.999, 0), (1.001, 3)])
def test_profile_check_on_either_side_of_the_largest_step(tmp_path, capsys, q_max, factor, rc):
    prof = write_profile_variant("actuation.toml", tmp_path / "a.toml",
                                 {"signals": {"ema2": {"lvdt": {"mm_per_unit": q_max * factor}}}})
    assert main(["profile", "check", str(prof), "--json"]) == rc
    out = json.loads(capsys.readouterr().out)
    if rc:
        (p,) = out["problems"]
        assert p["key"] == "signals.ema2.lvdt.mm_per_unit"
        assert f"the largest step that works is {q_max:.3g} mm per raw unit" in p["message"]
        assert "raise check safety.max_frozen_cycles (hard cap 100: up to 0.0116 mm there)" in p["message"]
    else:
        s = {x["key"]: x for x in out["sensor_steps"]}["signals.ema2.lvdt.mm_per_unit"]
        assert s["ok"] is True and s["largest_step"] == pytest.approx(q_max)


def test_a_longer_frozen_limit_in_the_check_profile_admits_a_coarser_step(tmp_path, capsys, q_max):
    prof = write_profile_variant("actuation.toml", tmp_path / "a.toml",
                                 {"signals": {"ema2": {"lvdt": {"mm_per_unit": 2 * q_max}}}})
    chk = write_profile_variant("check.toml", tmp_path / "c.toml", {"safety": {"max_frozen_cycles": 100}})
    assert main(["profile", "check", str(prof), "--json"]) == 3
    capsys.readouterr()
    assert main(["profile", "check", str(prof), "--check", str(chk), "--json"]) == 0


def test_the_issues_10_bit_input_is_refused_before_anything_moves(tmp_path, capsys):
    """0.04 mm per unit for an LVDT of 0.025 mm peak-to-peak noise: the dry-run stopped 0.066 s in on
    'LVDT 2 frozen'; now refused before a run folder is made, with the key and the step that works."""
    prof = write_profile_variant("actuation.toml", tmp_path / "a.toml",
                                 {"signals": {"ema2": {"lvdt": {"mm_per_unit": 0.04}}}})
    out = tmp_path / "run"
    assert main(["dry-run", "--profile", str(prof), "--out", str(out), "--quiet"]) == 3
    err = capsys.readouterr().err
    assert "a.toml: field 'signals.ema2.lvdt.mm_per_unit' = 0.04: a step of 0.04 mm per raw unit" in err
    assert "the largest step that works is 0.00566 mm" in err
    assert "(no safety.max_frozen_cycles up to its cap 100 admits it)" in err
    assert not out.exists()


def test_a_real32_sensor_has_no_step_to_judge(tmp_path):
    act = load_actuation()
    plan = plan_for(act).plan
    import dataclasses

    chans = tuple(dataclasses.replace(c, data_type=0x0008) if c.key == "signals.ema1.lvdt" else c
                  for c in plan.channels)
    keys = {s.key for s in sensor_steps(dataclasses.replace(plan, channels=chans), act, load_check(None, act))}
    assert "signals.ema1.lvdt.mm_per_unit" not in keys and "signals.ema2.lvdt.mm_per_unit" in keys


@pytest.mark.parametrize("args", [(0.0, 25, 1000), (float("nan"), 25, 1000), (1.0, 0, 1000), (1.0, 25, 0.5)])
def test_largest_step_refuses_bad_arguments(args):
    with pytest.raises(ValueError):
        largest_step(*args)
