"""The naming rule of a library effect's change against a reference (hil.analysis.diagnose.floors.library_change),
at its boundaries: named only when |z| > 3 and |change| > its floor; a parameter with no floor is never named."""

from __future__ import annotations

import pytest

from blf.diagnose.model import FittedEffect
from hil.analysis.diagnose.floors import LIBRARY_FLOORS, library_change
from hil.profile.floors import DUAL_FLOORS


def _eff(name: str, param: str, value: float, u: float) -> FittedEffect:
    return FittedEffect(name, "ema1", "", {param: value}, {param: u}, 0.0, 0.0, "", variant="drive")


@pytest.mark.parametrize("floor, named", [(9.99, True), (10.0, False)])
def test_a_friction_change_is_named_only_above_its_floor(floor, named):
    (c,) = library_change(_eff("coulomb_friction", "force_N", 10.0, 0.3), _eff("coulomb_friction", "force_N", 0.0, 0.4),
                          DUAL_FLOORS | {"ema_friction_N": floor})
    assert c["change"] == 10.0 and c["uncertainty"] == pytest.approx(0.5) and c["z"] == pytest.approx(20.0)
    assert c["supported"] and c["above_floor"] is named and c["named"] is named and c["unit"] == "N"


@pytest.mark.parametrize("u_new, named", [(0.9999, True), (1.0, False)])
def test_a_change_above_its_floor_is_named_only_when_z_is_above_3(u_new, named):
    """u = hypot(u_new, 0) and change 6 N: z = 6 / (2 u_new); the floor (3.7 N) is not what decides."""
    (c,) = library_change(_eff("coulomb_friction", "force_N", 6.0, 2.0 * u_new),
                          _eff("coulomb_friction", "force_N", 0.0, 0.0), DUAL_FLOORS)
    assert c["above_floor"] and c["supported"] is named and c["named"] is named


def test_a_load_cell_gain_change_is_in_percent():
    (c,) = library_change(_eff("loadcell_gain", "gain_error", 0.02, 1e-5),
                          _eff("loadcell_gain", "gain_error", 0.0, 1e-5), DUAL_FLOORS)
    assert c["change"] == pytest.approx(2.0) and c["unit"] == "%" and c["floor"] == DUAL_FLOORS["loadcell_gain_pct"]
    assert c["named"]


@pytest.mark.parametrize("coeff, named", [(3.7001 / 2.0, True), (3.6999 / 2.0, False)])
def test_a_viscous_friction_change_is_compared_as_its_force_at_the_check_speed(coeff, named):
    """b N s/mm at 2 mm/s is 2 b N, against the EMA friction floor (3.7 N)."""
    assert DUAL_FLOORS["ema_friction_N"] == 3.7
    (c,) = library_change(_eff("viscous_friction", "coeff_N_s_per_mm", coeff, 1e-3),
                          _eff("viscous_friction", "coeff_N_s_per_mm", 0.0, 1e-3), DUAL_FLOORS, 2.0)
    assert c["change"] == pytest.approx(2.0 * coeff) and c["unit"] == "N" and c["named"] is named


def test_a_shape_parameter_is_listed_never_named_and_every_size_parameter_has_a_floor():
    new = FittedEffect("stribeck_friction", "ema1", "", {"extra_force_N": 900.0, "stribeck_velocity_mm_per_s": 3.0},
                       {"extra_force_N": 1.0, "stribeck_velocity_mm_per_s": 0.01}, 0.0, 0.0, "", variant="drive")
    ref = FittedEffect("stribeck_friction", "ema1", "", {"extra_force_N": 0.0, "stribeck_velocity_mm_per_s": 3.0},
                       {"extra_force_N": 1.0, "stribeck_velocity_mm_per_s": 0.0}, 0.0, 0.0, "", variant="drive")
    size, vs = library_change(new, ref, DUAL_FLOORS, 2.0, ("stribeck_velocity_mm_per_s",), "new recording")
    assert size["named"] and size["floor"] == DUAL_FLOORS["stribeck_N"] == 860.0 and size["change"] == 900.0
    assert vs["shape"] and vs["floor"] is None and not vs["named"]
    assert "held at the value of the new recording" in vs["words"]
    from sim.replay_model import dual_ema_candidates
    for c in dual_ema_candidates():
        for q in c.params:
            assert (q.name in c.shape) != ((c.name, q.name) in LIBRARY_FLOORS), (c.name, q.name)
            if q.name not in c.shape:
                assert LIBRARY_FLOORS[(c.name, q.name)][0] in DUAL_FLOORS
