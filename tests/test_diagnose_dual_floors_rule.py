"""The naming rule of a library effect's change against a reference (hil.analysis.diagnose_dual_ref.library_change),
at its boundaries: named only when |z| > 3 and |change| > its floor; a parameter with no floor is never named."""

from __future__ import annotations

import pytest

from blf.diagnose import FittedEffect
from hil.analysis.diagnose_dual_ref import library_change
from hil.analysis.diagnose_floors import DUAL_FLOORS


def _eff(name: str, param: str, value: float, u: float) -> FittedEffect:
    return FittedEffect(name, "ema1", "", {param: value}, {param: u}, 0.0, 0.0, "", variant="drive")


@pytest.mark.parametrize("floor, named", [(9.99, True), (10.0, False)])
def test_a_friction_change_is_named_only_above_its_floor(floor, named):
    (c,) = library_change(_eff("coulomb_friction", "force_N", 10.0, 0.3), _eff("coulomb_friction", "force_N", 0.0, 0.4),
                          DUAL_FLOORS | {"friction_N": floor})
    assert c["change"] == 10.0 and c["uncertainty"] == pytest.approx(0.5) and c["z"] == pytest.approx(20.0)
    assert c["supported"] and c["above_floor"] is named and c["named"] is named and c["unit"] == "N"


@pytest.mark.parametrize("u_new, named", [(0.9999, True), (1.0, False)])
def test_a_change_above_its_floor_is_named_only_when_z_is_above_3(u_new, named):
    """u = hypot(u_new, 0) and change 3 N: z = 3 / u_new; the floor (0.9 N) is not what decides."""
    (c,) = library_change(_eff("coulomb_friction", "force_N", 3.0, u_new),
                          _eff("coulomb_friction", "force_N", 0.0, 0.0), DUAL_FLOORS)
    assert c["above_floor"] and c["supported"] is named and c["named"] is named


def test_a_load_cell_gain_change_is_in_percent_and_a_parameter_without_floor_is_never_named():
    (c,) = library_change(_eff("loadcell_gain", "gain_error", 0.02, 1e-5),
                          _eff("loadcell_gain", "gain_error", 0.0, 1e-5), DUAL_FLOORS)
    assert c["change"] == pytest.approx(2.0) and c["unit"] == "%" and c["floor"] == DUAL_FLOORS["loadcell_gain_pct"]
    assert c["named"]
    (v,) = library_change(_eff("viscous_friction", "coeff_N_s_per_mm", 50.0, 0.1),
                          _eff("viscous_friction", "coeff_N_s_per_mm", 0.0, 0.1), DUAL_FLOORS)
    assert v["floor"] is None and v["supported"] and not v["named"] and "no floor" in v["words"]
