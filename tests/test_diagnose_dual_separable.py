"""What a dual-EMA check can separate (hil.analysis.diagnose.floors.nominal_changes,
blf.diagnose.covariance.nominal_covariance).

Pinned at their boundaries: a nominal parameter is compared alone only while its variance inflation is below
VIF_MAX on both recordings; the two bearing plays are compared as their sum (external play); the drives' and
the hinge's friction as Coulomb + viscous x the check's speed; each with its own floor. Known answers on a
synthetic covariance and a linear model whose Jacobian is known.
"""

from __future__ import annotations

import numpy as np
import pytest

from blf.diagnose import EIGEN_FLOOR, NominalCovariance
from hil.analysis.diagnose.floors import VIF_MAX, check_speed, nominal_changes
from hil.profile.floors import DUAL_FLOORS

NAMES = ("backlash_int1_mm", "backlash_bearing1_mm", "backlash_bearing2_mm", "compliance_ext1_mm_per_N",
         "drive_coulomb_N", "drive_viscous_N_s_per_mm", "hinge_coulomb_N", "hinge_viscous_N_s_per_mm")
REF = {"backlash_int1_mm": 0.100, "backlash_bearing1_mm": 0.050, "backlash_bearing2_mm": 0.050,
       "compliance_ext1_mm_per_N": 5.0e-5, "drive_coulomb_N": 8.0, "drive_viscous_N_s_per_mm": 96.0,
       "hinge_coulomb_N": 6.0, "hinge_viscous_N_s_per_mm": 17.0}


def _cov(vif_bearing: float = 1.0) -> NominalCovariance:
    vif = np.ones(len(NAMES))
    vif[1] = vif[2] = vif_bearing
    return NominalCovariance(NAMES, np.diag(vif), vif)


def _by(changes: list) -> dict:
    return {c["parameter"]: c for c in changes}


@pytest.mark.parametrize("vif, separable", [(VIF_MAX * (1 - 1e-9), True), (VIF_MAX, False)])
def test_a_parameter_is_compared_alone_only_below_the_vif_limit(vif, separable):
    new = REF | {"backlash_bearing1_mm": 0.060, "backlash_bearing2_mm": 0.040}  # the split moves, the sum not
    c = _by(nominal_changes(new, REF, _cov(1.0), _cov(vif), DUAL_FLOORS, 2.0))
    b1 = c["backlash_bearing1_mm"]
    assert b1["change"] == pytest.approx(10.0) and b1["separable"] is separable and b1["named"] is separable
    if not separable:
        assert b1["vif"] == vif and "not separable" in b1["words"] and "external_play_mm" in b1["words"]
    ext = c["external_play_mm"]  # compared either way, at external, with its own floor
    assert ext["change"] == pytest.approx(0.0, abs=1e-9) and not ext["named"] and ext["where"] == "external"
    assert ext["of"] == ["backlash_bearing1_mm", "backlash_bearing2_mm"] and ext["floor_key"] == "external_play_um"


@pytest.mark.parametrize("extra_um, named", [(1.3001, True), (1.2999, False)])
def test_the_external_play_is_named_above_its_own_floor(extra_um, named):
    assert DUAL_FLOORS["external_play_um"] == 1.3
    new = REF | {"backlash_bearing2_mm": 0.050 + extra_um / 1000}
    ext = _by(nominal_changes(new, REF, _cov(1e10), _cov(1e10), DUAL_FLOORS, 2.0))["external_play_mm"]
    assert ext["change"] == pytest.approx(extra_um) and ext["unit"] == "um" and ext["named"] is named


@pytest.mark.parametrize("dc, named", [(1.1001, True), (1.0999, False)])
def test_friction_is_compared_at_the_check_speed_not_coulomb_alone(dc, named):
    """Coulomb -16 N and viscous +8 N s/mm: at 2 mm/s that is 0 (the fits' usual trade at one speed), then
    dc more: named only above the friction floor (1.1 N). Coulomb alone is not a comparison any more."""
    new = REF | {"drive_coulomb_N": 8.0 - 16.0 + dc, "drive_viscous_N_s_per_mm": 96.0 + 8.0}
    c = _by(nominal_changes(new, REF, _cov(), _cov(), DUAL_FLOORS, 2.0))
    f = c["drive_friction_N"]
    assert f["value"] == pytest.approx(new["drive_coulomb_N"] + 2.0 * 104.0)
    assert f["reference"] == pytest.approx(8.0 + 2.0 * 96.0)
    assert f["change"] == pytest.approx(dc) and f["named"] is named and f["speed_mm_per_s"] == 2.0
    assert f["of"] == ["drive_coulomb_N", "drive_viscous_N_s_per_mm"] and "2 mm/s" in f["words"]
    assert "drive_coulomb_N" not in c and "hinge_coulomb_N" not in c
    assert not c["hinge_friction_N"]["named"]


@pytest.mark.parametrize("pct, named", [(12.001, True), (11.999, False)])
def test_a_compliance_change_has_its_own_floor(pct, named):
    assert DUAL_FLOORS["compliance_pct"] == 12.0
    new = REF | {"compliance_ext1_mm_per_N": 5.0e-5 * (1 + pct / 100)}
    c = _by(nominal_changes(new, REF, _cov(), _cov(), DUAL_FLOORS, 2.0))["compliance_ext1_mm_per_N"]
    assert c["change"] == pytest.approx(pct) and c["named"] is named and c["floor_key"] == "compliance_pct"


def test_check_speed_is_the_median_of_the_moving_samples():
    class M:
        regimes = {"velocity": np.r_[np.zeros(500), np.full(300, 2.0), np.full(200, -2.1), np.full(50, 0.09)]}
    # 0.09 mm/s is under 5 % of the 99th percentile (2.1): not moving; median of 2.0 x300, 2.1 x200 is 2.0
    assert check_speed(M) == 2.0
    M.regimes = {"velocity": np.zeros(10)}
    assert check_speed(M) == 0.0


class _Linear:
    """A replay whose prediction is linear in its parameters: y = A theta (one channel), noise floor 1."""

    channels = ("F1",)
    candidates = ()

    def __init__(self, A: np.ndarray) -> None:
        from blf.diagnose import Param
        n = A.shape[0]
        self.A = A
        self.t_s = np.arange(n) * 0.002
        self.nominal = tuple(Param(f"p{j}", 1.0, 1.0, -10.0, 10.0) for j in range(A.shape[1]))
        rng = np.random.default_rng(3)
        self.measured = {"F1": A @ np.ones(A.shape[1]) + rng.normal(0.0, 1.0, n)}
        self.valid = {"F1": np.ones(n, bool)}
        self.regimes = {"velocity": np.ones(n)}

    def predict(self, theta, active):
        return {"F1": self.A @ np.asarray(theta)}


def test_nominal_covariance_finds_a_direction_the_data_does_not_hold():
    """Columns 1 and 2 equal (only their sum acts): both get a VIF at the eigenvalue floor (~1e12), the others
    their known VIF: column 3 = column 0 + small independent part gives VIF = 1/(1 - r^2)."""
    from blf.diagnose.covariance import nominal_covariance
    rng = np.random.default_rng(7)
    n = 4000
    a, b, e = rng.normal(size=n), rng.normal(size=n), rng.normal(size=n)
    A = np.column_stack([a, b, b, a + 0.1 * e])
    cov = nominal_covariance(_Linear(A), 0.002, {f"p{j}": 1.0 for j in range(4)})
    assert cov.vif[1] > 0.1 / EIGEN_FLOOR and cov.vif[2] > 0.1 / EIGEN_FLOOR
    assert cov.vif[1] >= VIF_MAX and cov.vif[0] < VIF_MAX
    r2 = np.corrcoef(A[:, 0], A[:, 3])[0, 1] ** 2
    assert cov.vif[0] == pytest.approx(1 / (1 - r2), rel=0.05) and cov.vif[3] == pytest.approx(1 / (1 - r2), rel=0.05)
    assert cov.correlation("p1", "p2") == pytest.approx(-1.0, abs=1e-6)


def test_the_report_says_why_each_comparison_is_or_is_not_named():
    from hil.report.diagnose_ref import _status
    base = {"named": False, "floor": 1.0, "supported": True}
    assert _status(base | {"named": True}) == "<b>named</b>"
    assert _status(base | {"separable": False}) == "not separable by this check: not named"
    assert _status(base | {"shape": True, "floor": None}) == "shape parameter (form, not size): not named"
    assert _status(base | {"floor": None}) == "no floor measured: not named"
    assert _status(base) == "supported, under its floor"
    assert _status(base | {"supported": False}) == "not supported (|z| ≤ 3)"


@pytest.mark.parametrize("new, ref, where, words", [
    ("unexplained", "explained", ["ema2", "ema1"], "physics outside the library appeared"),
    ("unexplained", "unexplained", ["ema2", "ema1"], "between two imperfect fits"),
    ("explained", "unexplained", [], "against an imperfect fit of the reference"),
    ("no_mismatch", "explained", [], "neither recording"),
])
def test_which_recording_leaves_a_mismatch_outside_the_library(new, ref, where, words):
    from types import SimpleNamespace

    from hil.analysis.diagnose.dual_reference import _unexplained
    u = _unexplained(SimpleNamespace(verdict=new, where=("ema2", "ema1")), SimpleNamespace(verdict=ref, where=()))
    assert u["recording"] is (new == "unexplained") and u["reference"] is (ref == "unexplained")
    assert u["where"] == where and words in u["words"]
