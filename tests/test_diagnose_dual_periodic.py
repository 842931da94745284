"""A force periodic in position through the dual-EMA path (issue 48 part 2): the simulator's effect
(``sim.effects.PeriodicForce``) and its diagnosis against truth.

The fast tests pin the effect's table and validation and the replay's candidate on synthetic arrays; the
slow one simulates checks with the effect at two periods and as a local defect and diagnoses them against
a healthy check (tests/bench/bench_diagnose_dual_periodic.py prints the table; about 3 min on one core).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from blf.errors import InputError
from sim.effects import COLUMNS, PeriodicForce, compile_effects
from sim.replay_periodic import periodic_candidate, periodic_force, periodic_start
from support.shared_fits import module_fits_once  # noqa: F401 (a fixture, used below)


def test_the_effect_compiles_to_its_columns_in_si():
    t = compile_effects((PeriodicForce("ema2", 20.0, 4.0, 1.0, 3.0, 12.0),), 0.002, 4)
    row = t[1]
    assert row[COLUMNS.index("periodic_amp_N")] == 20.0
    assert row[COLUMNS.index("periodic_period_m")] == pytest.approx(0.004)
    assert row[COLUMNS.index("periodic_phase_rad")] == 1.0
    assert row[COLUMNS.index("periodic_center_m")] == pytest.approx(0.003)
    assert row[COLUMNS.index("periodic_halfwidth_m")] == pytest.approx(0.006)
    assert not t[0].any() and not t[2].any()


@pytest.mark.parametrize("kw", [{"amplitude_N": -1.0}, {"period_mm": 0.0}, {"width_mm": -1.0}])
def test_a_bad_effect_is_refused_naming_the_field(kw):
    args = {"where": "ema1", "amplitude_N": 10.0} | kw
    with pytest.raises(InputError, match=next(iter(kw))):
        PeriodicForce(**args)
    with pytest.raises(InputError, match="where"):
        PeriodicForce("external", 10.0)


def _sweeps(period_mm=5.0, amp=20.0, local=None, seed=0):
    """Motor-side position sweeping +-17 mm at 2 mm/s for 8 sweeps at 500 Hz; the load cell reads the
    target less the periodic force, with 10 N of noise."""
    rng = np.random.default_rng(seed)
    fs = 500.0
    one = np.r_[np.arange(-17, 17, 2 / fs), np.arange(17, -17, -2 / fs)]
    x = np.tile(one, 4)
    v = np.gradient(x) * fs
    target = np.full(x.size, -2000.0)
    fp = periodic_force(x, (amp, 0.4, period_mm) + (() if local is None else local))
    f = target - 5.0 * np.sign(v) - fp + rng.normal(0, 10.0, x.size)
    return x, v, f, target


@pytest.mark.parametrize("period", [4.0, 5.0])
def test_the_replay_finds_the_period_and_starts_the_candidate_there(period):
    x, v, f, target = _sweeps(period)
    p, a, ph, span = periodic_start(x, v, f, target, np.ones(x.size, bool), 10.0)
    assert abs(p / period - 1) < 0.02 and abs(a / 20 - 1) < 0.2 and span is None
    c = periodic_candidate("ema1", "1", (p, a, ph, span))
    assert c.name == "periodic_force" and c.shape == ("phase_rad", "period_mm")
    assert np.allclose(periodic_force(x, [q.x0 for q in c.params]), periodic_force(x, (a, ph, p)))


def test_a_local_defect_starts_a_local_candidate_where_it_is():
    x, v, f, target = _sweeps(5.0, 40.0, local=(3.0, 6.0, 0.01))
    p, a, ph, span = periodic_start(x, v, f, target, np.ones(x.size, bool), 10.0)
    assert abs(p / 5 - 1) < 0.02 and span is not None and abs(span[0] - 3.0) < 2.0
    c = periodic_candidate("ema1", "1", (p, a, ph, span))
    assert [q.name for q in c.params][-3:] == ["center_mm", "half_width_mm", "edge_mm"] and "local" in c.words


def test_noise_alone_starts_no_candidate():
    x, v, f, target = _sweeps(amp=0.0)
    assert periodic_start(x, v, f, target, np.ones(x.size, bool), 10.0) is None


@pytest.mark.slow
# the table's diagnoses fit each replay model once per test run (support.shared_fits): its six checks stay at their
# paths, none is refused for itself; the healthy seed-11 check and one more are fitted by
# test_diagnose_dual_reference.py as well (docs/performance.md, "Test suite, sixth pass")
@pytest.mark.usefixtures("module_fits_once")
def test_the_dual_ema_path_names_the_periodic_force_at_the_right_ema_with_its_period_and_amplitude(tmp_path):
    import sys
    sys.path.insert(0, str(Path(__file__).parent))
    from bench.bench_diagnose_dual_periodic import table

    from support.figures import figures_unrendered
    # the six checks simulated in this process, their reports' figures built but not drawn: the diagnosis reads
    # the recordings only (each simulate 5.8 -> ~2 s: no interpreter start, no figures drawn; docs/performance.md)
    with figures_unrendered():
        rows = {r["pair"]: r for r in table(tmp_path, here=True)}
    for pair in ("lead5-ema1 vs healthy11", "lead4-ema2 vs healthy11", "local-ema1 vs healthy11"):
        r = rows[pair]
        assert r["right"], r  # period within 2 %, amplitude change within 20 %, at the right EMA only
        assert r["verdict"] == "explained", r  # the local one too: its window's edges are fitted
    for pair in ("healthy12 vs healthy11", "healthy13 vs healthy11"):
        assert rows[pair]["verdict"] == "no_mismatch" and rows[pair]["named"] == []


@pytest.mark.parametrize("edge_mm", [0.01, 1.5])
def test_a_local_defect_is_fitted_with_its_ends_sharp_or_gradual(edge_mm):
    """A defect over 3 +- 6 mm, 40 N every 5 mm, with sharp ends (edge 0.01 mm: the simulator's box) or
    gradual ones (1.5 mm): the candidate's window, fitted from its start by least squares within its
    bounds, recovers the centre and half width within 0.3 mm, the amplitude within 5 %, the edge width
    within 0.5 mm, and leaves the noise (10 N) alone in the residual (within 3 %)."""
    from scipy.optimize import least_squares
    x, v, f, target = _sweeps(5.0, 40.0, local=(3.0, 6.0, edge_mm), seed=2)
    c = periodic_candidate("ema1", "1", periodic_start(x, v, f, target, np.ones(x.size, bool), 10.0))
    d = np.sign(v)

    def resid(p):
        y = target - f - periodic_force(x, p[:6])  # the friction 5 N per direction as two offsets
        return y + p[6] * (d > 0) + p[7] * (d < 0)

    fit = least_squares(resid, [q.x0 for q in c.params] + [0.0, 0.0],
                        bounds=([q.lo for q in c.params] + [-50, -50], [q.hi for q in c.params] + [50, 50]),
                        x_scale=[q.scale for q in c.params] + [1.0, 1.0])
    a, _, p, ctr, w, s = fit.x[:6]
    assert abs(ctr - 3.0) < 0.3 and abs(w - 6.0) < 0.3 and abs(a / 40 - 1) < 0.05 and abs(p / 5 - 1) < 0.005
    assert abs(s - edge_mm) < 0.5
    assert np.sqrt(np.mean(fit.fun ** 2)) == pytest.approx(10.0, rel=0.03)
