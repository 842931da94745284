"""Tests of ``emacheck diagnose`` (blf.diagnose.engine, sim.replay, sim.single_axis, hil.cli.diagnose).

Recordings are short simulated checks (~40 s, see ``support.diagnose_cases.short_check``)
with concealed effects generated as in the benchmark (``support.diagnose_cases``), with
their own seeds (31001..), never the benchmark's. The full >= 30-case benchmark is
``python tests/bench/bench_diagnose.py``. The tests that simulate a recording (or read
the EMPS one through the command line) are ``slow``; the statistics of the method on
synthetic residuals stay in the fast loop.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_verdict import validate

from blf.diagnose.engine import diagnose
from blf.errors import InputError
from hil.cli import main
from sim.replay import ChainParams, replay_chains
from sim.replay_model import DualEmaReplay
from support import diagnose_cases as dc
from support.ci import skip_or_fail

EMPS = Path(__file__).resolve().parents[2] / "shared" / "data" / "emps" / "DATA_EMPS.mat"


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    return dc.short_check()


def _case(kind_effects, seed, tmp, check, size=1.0):
    case = {"id": "t", "kind": "single", "effects": kind_effects, "seed": seed}
    sig, truths, s, _ = dc.generate(case, tmp, check, size=size)
    return sig, truths, s


def _diag(sig):
    m = DualEmaReplay(sig.t, sig.phi1, sig.phi2, sig.s1, sig.s2, sig.F1, sig.F2, dc.I_TOTAL, 0.002,
                      sig.mode1, sig.sp1, sig.mode2, sig.sp2)
    return diagnose(m, 0.002)


@pytest.mark.slow
def test_replay_reproduces_plant_within_noise(tmp_path, short):
    """Driven by the measured motor angles with the true parameters, the replay leaves only noise in s."""
    sig = dc.record(dc.base_params(), 31001, tmp_path, short)
    ks = 1 / 200000 + 1 / 20000
    tr = replay_chains(sig.phi1 / dc.I_TOTAL, sig.phi2 / dc.I_TOTAL, ChainParams(0.10, 8e4, 8e4, 0.05, ks),
                       ChainParams(0.12, 8e4, 8e4, 0.05, ks), 0.002, 0.0, 300.0, 0.5)
    sigma = 0.025 / 6
    for j, s in enumerate((sig.s1, sig.s2)):
        rms = float(np.sqrt(np.mean((s - tr.s_mm[:, j]) ** 2)))
        assert rms < 1.1 * sigma, (j, rms)


def test_replay_refuses_bad_input():
    c = ChainParams(0.1, 8e4, 8e4, 0.05, 5e-5)
    with pytest.raises(InputError, match="same shape|one shape"):
        replay_chains(np.zeros(5), np.zeros(4), c, c, 0.002)
    with pytest.raises(InputError, match="> 0"):
        replay_chains(np.zeros(5), np.zeros(5), ChainParams(0.1, -1.0, 8e4, 0.05, 5e-5), c, 0.002)


@pytest.mark.parametrize("progressive_per_mm", [0.0, 0.4])
@pytest.mark.parametrize("hinge_coulomb_N", [0.0, 40.0])
def test_replay_surface_balances_its_forces_at_every_sample(progressive_per_mm, hinge_coulomb_N):
    """Known answer of the surface equation, sample by sample: with backward differences
    g = F1 + F2 - k y - m (y - 2y' + y'')/T^2 - c (y - y')/T is the hinge friction F_c sign(dy)
    while the surface moves and within +-F_c while it sticks (to the solver's 1e-13 m), over
    motor paths that cross both chains' backlash many times, force fight and slack alike."""
    T, n = 0.002, 6000
    t = np.arange(n) * T
    rng = np.random.default_rng(7)
    x1 = 0.8 * np.sin(2 * np.pi * 0.7 * t) + 0.01 * rng.standard_normal(n).cumsum() / 30
    x2 = 0.8 * np.sin(2 * np.pi * 0.7 * t + 0.4) + 0.15 * np.sin(2 * np.pi * 3.1 * t)
    c1 = ChainParams(0.10, 8e4, 6e4, 0.05, 5e-5, 2e4, 0.3, progressive_per_mm)
    c2 = ChainParams(0.14, 9e4, 9e4, 0.03, 6e-5)
    k_load, mass, damping = 300.0, 25.0, 0.5  # N/mm, kg, N s/mm
    tr = replay_chains(x1, x2, c1, c2, T, k_load, mass, damping, hinge_coulomb_N)
    y = tr.y_mm * 1e-3
    g = (tr.F_N[:, 0] + tr.F_N[:, 1] - k_load * 1e3 * y)[2:] \
        - mass * (y[2:] - 2 * y[1:-1] + y[:-2]) / T ** 2 - damping * 1e3 * (y[2:] - y[1:-1]) / T
    moving = y[2:] != y[1:-1]
    # 1e-13 m of the stiffest flank pair plus the surface terms, in N
    tol = 1e-13 * (2 * 9e4 * 1e3 + mass / T ** 2 + damping * 1e3 / T + k_load * 1e3) + 1e-9 * np.abs(tr.F_N).max()
    fric = hinge_coulomb_N * np.sign(y[2:] - y[1:-1])
    assert moving.sum() > n // 2
    assert np.max(np.abs(g - fric)[moving]) < tol
    if hinge_coulomb_N > 0.0:
        assert (~moving).sum() > 10
        assert np.max(np.abs(g[~moving])) <= hinge_coulomb_N + tol
    assert np.ptp(tr.F_N[:, 0]) > 1e3 and np.any(tr.F_N[:, 0] == 0.0)  # contact and slack both visited

@pytest.mark.slow
def test_null_is_no_mismatch(tmp_path, short):
    sig, _, _ = _case([], 31002, tmp_path, short)
    d = _diag(sig)
    assert d.verdict == "no_mismatch", (d.excess_before, [e.name for e in d.effects])
    assert d.effects == ()


@pytest.mark.slow
def test_concealed_coulomb_friction_found(tmp_path):
    """A full-length check: the concealed friction needs the whole recording to stand out."""
    sig, truths, s = _case([("coulomb_friction", "ema1")], 31003, tmp_path, None)
    assert max(v for c, v in s.items() if not c.startswith("phi")) < 1.0
    d = _diag(sig)
    assert d.verdict == "explained"
    assert [(e.name, e.where) for e in d.effects] == [("coulomb_friction", "ema1")]
    true_f = truths[0]["parameters"]["force_N"]
    fit = d.effects[0].parameters["force_N"]
    unc = d.effects[0].uncertainty["force_N"]
    # concealed means ~1 N against 10 N of load-cell noise: the estimate is good to its
    # stated uncertainty (which must itself be small enough to mean something)
    assert abs(fit - true_f) < 3.0 * unc, (fit, unc, true_f)
    assert unc < 0.3 * true_f, (unc, true_f)
    assert d.ic_after < d.ic_before
    assert d.residual_rms_after["Fd1"] < d.residual_rms_before["Fd1"]


@pytest.mark.slow
def test_out_of_library_is_unexplained(tmp_path, short):
    """A screw lead error (periodic along the stroke: no effect of the library has that shape) is
    found, called unexplained with its locations at EMA 1, and no library effect is named for it there
    (``effects`` lists whatever the fit accepted, whatever the verdict: an effect elsewhere may be).

    At its largest concealed size the short recording carries it only at the detection threshold
    (window excess 3.5 against 3.0 at this seed; 1 of 4 seeds tried gave no_mismatch): it is
    recorded at twice that size (the magnitude drawn from this test's own seed, the per-sample
    signature about 2 noise sigmas), so that a detector that never detects fails here."""
    sig, _, s = _case([("lead_error", "ema1")], 31004, tmp_path, short, size=2.0)
    assert 1.0 < max(s.values()) < 2.5, s  # above the noise per sample, but not by much
    d = _diag(sig)
    assert d.verdict == "unexplained", (d.verdict, d.excess_before, [e.name for e in d.effects])
    assert not [e for e in d.effects if e.where == "ema1"], d.effects
    assert d.where and d.where[0] == "ema1", d.where
    assert d.locations, (d.excess_before, d.regime_before)


@pytest.mark.slow
def test_emps_cli(tmp_path):
    if not EMPS.exists():
        skip_or_fail(f"EMPS recording not present at {EMPS} (../shared/data)")
    rc = main(["diagnose", str(EMPS), "--model", "single-axis", "--out", str(tmp_path), "--quiet"])
    assert rc == 0
    data = validate(tmp_path / "diagnosis.json", "diagnosis")
    assert set(data) >= {"verdict", "effects", "locations", "residual_rms_before", "residual_rms_after",
                         "ic_before", "ic_after"}
    named = data["effects"]
    assert named, data["verdict"]
    assert all(e["delta_chi2_holdout"] < -10 for e in named)
    # the dominant missing physics: viscous friction that differs with the direction of motion
    assert (named[0]["name"], named[0]["where"]) == ("asymmetric_friction", "axis")
    asym = named[0]["parameters"]["viscous_asymmetry_N_s_per_m"]
    assert abs(asym) > 10 * named[0]["uncertainty"]["viscous_asymmetry_N_s_per_m"]
    # compared in the band the rigid-body model claims (IDIM-LS's 20 Hz), and the fit improves there by
    # >= 15 % on the half it was never fitted on (issue 13's figure); the raw band beside it improves too
    assert data["band"]["cutoff_hz"] == 20.0
    hb, ha = data["residual_rms_holdout_before"]["force"], data["residual_rms_holdout_after"]["force"]
    assert ha < 0.85 * hb, (hb, ha)
    rb, ra = data["residual_rms_raw_holdout_before"]["force"], data["residual_rms_raw_holdout_after"]["force"]
    assert ra < rb and hb < rb, (rb, ra, hb)
    # what is left in the band is far above its noise floor: not explained, and said where
    assert data["verdict"] == "unexplained" and data["where"] == ["axis"], (data["verdict"], data["where"])
    assert data["ic_after"] < data["ic_before"]
    assert data["residual_rms_after"]["force"] < data["residual_rms_before"]["force"]
    assert data["locations"]
    assert (tmp_path / "diagnosis_report.html").stat().st_size > 10_000


def test_cli_bad_recording(tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("t,phi1\n0,0\n")
    assert main(["diagnose", str(bad), "--out", str(tmp_path)]) == 3


def test_noise_floor_on_a_sparse_grid():
    """A channel valid every 50th sample (block means) gets its white-noise sigma from its own grid."""
    from blf.diagnose.mismatch import noise_floor
    rng = np.random.default_rng(7)
    n = 50_000
    valid = np.zeros(n, bool)
    valid[25::50] = True
    r = np.where(valid, 1.5 * rng.standard_normal(n) + 0.2 * np.sin(np.arange(n) / 4000.0), 0.0)
    sig = noise_floor(r, valid, 100)
    assert abs(np.median(sig[valid]) - 1.5) < 0.1, np.median(sig[valid])
    dense = noise_floor(1.5 * rng.standard_normal(n), np.ones(n, bool), 100)
    assert abs(np.median(dense) - 1.5) < 0.05


def test_drive_force_blocks_balance_momentum():
    """Known answer: a motion whose drive target is exactly the chain force plus M a + c v
    (continuous time) gives block means of the replayed drive force equal to those of the
    chain force, without differentiating the angle twice."""
    T, n, i_tot = 0.002, 20_000, dc.I_TOTAL
    t = np.arange(n) * T
    M, c = 2500.0, 75.0  # kg, N s/mm
    w = 2 * np.pi * 0.7
    x = 3.0 * np.sin(w * t)  # mm
    F_chain = 2000.0 + 500.0 * np.sin(0.9 * t)
    # the setpoint of sample k acts over (t_k, t_k+1]: its mean target over that period
    tm = t + 0.5 * T
    tgt_mid = 2000.0 + 500.0 * np.sin(0.9 * tm) + M * 1e-3 * (-3.0 * w * w * np.sin(w * tm)) \
        + c * 3.0 * w * np.cos(w * tm)
    mode = np.full(n, 10.0)
    mode[:10] = 8.0
    m = DualEmaReplay(t, x * i_tot, x * i_tot, x, x, F_chain, F_chain, i_tot, T, mode, tgt_mid, mode, tgt_mid)
    th = np.array([q.x0 for q in m.nominal])
    names = [q.name for q in m.nominal]
    th[names.index("reflected_mass_kg")], th[names.index("drive_viscous_N_s_per_mm")] = M, c
    th[names.index("drive_coulomb_N")] = 0.0
    pred = m.predict(th, [])
    ok = m.valid["Fd1"]
    assert ok.sum() > 300
    err = pred["Fd1"][ok] - m.measured["Fd1"][ok]
    assert np.sqrt(np.mean(err ** 2)) < 0.05, (np.sqrt(np.mean(err ** 2)), np.abs(err).max())  # N; M a swings +-145 N


@pytest.mark.slow
def test_cli_on_a_run_folder(tmp_path, short):
    """End to end on a run folder the tool made (no effect): JSON of issue 6's shape, the D
    signals reported beside the fitted channels, the HTML report written."""
    run = tmp_path / "run"
    dc.record(dc.base_params(), 31005, run, short)
    out = tmp_path / "diag"
    assert main(["diagnose", str(run), "--out", str(out), "--quiet"]) == 0
    data = validate(out / "diagnosis.json", "diagnosis")
    assert data["verdict"] == "no_mismatch", data["excess_before"]
    assert set(data["residual_rms_before"]) == {"s1", "s2", "F1", "F2", "Fd1", "Fd2", "Dint1", "Dint2", "Dext"}
    # D_int,1 = s1 - phi1/i_total with phi1 an input of the replay: same residual as s1
    assert data["residual_rms_before"]["Dint1"] == pytest.approx(data["residual_rms_before"]["s1"], rel=1e-6)
    assert 0.8 < data["residual_rms_after"]["s1"] / data["noise_floor"]["s1"] < 1.2
    html = (out / "diagnosis_report.html").read_text()
    assert "Dext" in html and html.count("data:image/png;base64,") == 9


def test_block_means_is_the_trapezoid_over_the_block():
    from sim.replay import block_means
    x = np.arange(100, dtype=float) ** 2  # x_k = k^2
    k0 = np.array([1, 11, 50])
    got = block_means(x, k0, 10)
    # exact time mean of the piecewise-linear interpolant of k^2 over [k0 - 1, k0 + 9]
    want = [np.mean([0.5 * (k * k + (k + 1) ** 2) for k in range(a - 1, a + 9)]) for a in k0]
    assert np.allclose(got, want, rtol=0, atol=1e-9), (got, want)


def _regime_setup(n=60000, force=None):
    """Cells of triangle sweeps (mm, not in step with the 2 s blocks) x velocity sign x the sign of
    ``force`` (default a slow sine), the blocks and the fit half."""
    from blf.diagnose.mismatch import regime_cells
    t = np.arange(n) * 0.002
    pos = 10.0 * np.abs(((t / 4.3) % 2.0) - 1.0) - 5.0
    regimes = {"position along the stroke": pos, "velocity": np.gradient(pos, t),
               "force F1": np.sin(2 * np.pi * t / 11.0) if force is None else force}
    cells, labels = regime_cells(regimes, 10)
    block = np.arange(n) // 1000
    return cells, labels, block, block % 2 == 0


def test_regime_score_is_standard_under_white_and_correlated_noise():
    """Under noise only the regime score has mean 0 and unit spread, also when the noise is
    correlated (AR(1), a = 0.8: sums 9x wider than white) -- the over-dispersion is estimated."""
    from scipy.signal import lfilter

    from blf.diagnose.mismatch import regime_score
    cells, labels, block, fit = _regime_setup()
    rng = np.random.default_rng(5)
    valid = np.ones(cells.size, bool)
    for a in (0.0, 0.8):
        S = []
        for _ in range(150):
            e = lfilter([np.sqrt(1 - a * a)], [1.0, -a], rng.normal(size=cells.size))
            S.append(regime_score(e, valid, fit, block, cells, len(labels)).score)
        S = np.array(S)
        assert abs(S.mean()) < 0.25, (a, S.mean())
        assert 0.8 < S.std() < 1.3, (a, S.std())
        assert S.max() < 4.5, (a, S.max())


def test_regime_score_sees_a_mismatch_repeated_in_a_cell_and_not_one_that_flips():
    """An offset of 0.15 sigma in the samples of a few cells (invisible per sample; a 1 s
    window holds at most 0.43 s of it: below 1.5 sigma) is found when it repeats in both halves; one whose sign flips
    between the halves (not a property of the regime) scores negative."""
    from blf.diagnose.mismatch import regime_score
    cells, labels, block, fit = _regime_setup()
    rng = np.random.default_rng(6)
    e = rng.normal(size=cells.size)
    valid = np.ones(cells.size, bool)
    hit = np.isin(cells, [3, 4, 5, 6])
    rep = regime_score(e + 0.15 * hit, valid, fit, block, cells, len(labels))
    S_rep, prod = rep.score, rep.products
    S_flip = regime_score(e + 0.15 * hit * np.where(fit, 1.0, -1.0), valid, fit, block, cells, len(labels)).score
    S_none = regime_score(e, valid, fit, block, cells, len(labels)).score
    assert S_rep > 5.0 and S_rep > S_none + 4.0, (S_rep, S_none)
    assert S_flip < S_none - 2.0, (S_flip, S_none)
    assert set(np.argsort(-np.nan_to_num(prod, nan=-1e9))[:2]) <= {3, 4, 5, 6}


def test_regime_cells_chosen_by_the_measured_force_would_bias_its_residual():
    """Why diagnose forms the force cells from the model's force: a cell chosen by the sign
    of a noisy measurement selects that measurement's noise, and pure noise then scores as a
    repeated mismatch; cells from the noise-free force do not."""
    from blf.diagnose.mismatch import regime_score
    n = 60000
    t = np.arange(n) * 0.002
    rng = np.random.default_rng(7)
    noise = rng.normal(0.0, 10.0, n)  # N
    f_true = 8.0 * np.sin(2 * np.pi * t / 11.0)  # N, often below the noise
    valid = np.ones(n, bool)
    out = {}
    for name, f in (("measured", f_true + noise), ("model", f_true)):
        cells, labels, block, fit = _regime_setup(n, force=f)
        out[name] = regime_score(noise / 10.0, valid, fit, block, cells, len(labels)).score
    assert out["measured"] > 10.0, out
    assert abs(out["model"]) < 4.0, out


class _BandModel:
    """A minimal replay model: one force channel F = gain x reference + white noise (sigma 1),
    plus ``offset`` wherever the stroke position is inside +-1 (a regime-tied mismatch that
    no candidate explains: the library is empty)."""

    def __init__(self, offset: float, seed: int = 11):
        from blf.diagnose import Param
        n = 60000
        self.t_s = np.arange(n) * 0.002
        pos = 10.0 * np.abs(((self.t_s / 4.3) % 2.0) - 1.0) - 5.0
        self.ref = 100.0 * np.sin(2 * np.pi * self.t_s / 11.0)
        rng = np.random.default_rng(seed)
        self.channels = ("F",)
        self.measured = {"F": 1.02 * self.ref + rng.normal(size=n) + offset * (np.abs(pos) < 1.0)}
        self.valid = {"F": np.ones(n, bool)}
        self.nominal = (Param("gain", 1.0, 0.1, 0.5, 2.0),)
        self.candidates = ()
        self.regimes = {"position along the stroke": pos, "velocity": np.gradient(pos, self.t_s),
                        "force F": self.measured["F"]}

    def predict(self, theta, active):
        return {"F": theta[0] * self.ref}


def test_regime_test_localises_a_mismatch_the_window_test_misses():
    """A 0.12-sigma offset over a fifth of the stroke: the window test stays under its threshold,
    the regime test flags it, the verdict is unexplained (empty library) with regime locations
    inside the band; without the offset the same model is no_mismatch."""
    d = diagnose(_BandModel(0.12), 0.002)
    assert d.excess_before["F"] < 3.0, d.excess_before
    assert d.regime_before["F"] > 8.0, d.regime_before
    assert d.verdict == "unexplained" and d.effects == ()
    reg = [loc for loc in d.locations if loc.test == "regime"]
    assert reg and all("position along the stroke -1" in loc.regime or "position along the stroke +0" in loc.regime
                       or "position along the stroke -0" in loc.regime for loc in reg), [loc.regime for loc in reg]
    assert abs(d.nominal["gain"] - 1.02) < 1e-3
    d0 = diagnose(_BandModel(0.0), 0.002)
    assert d0.verdict == "no_mismatch", (d0.excess_before, d0.regime_before)
    assert abs(d0.regime_before["F"]) < 4.0


def test_both_lvdt_pitches_alike_are_one_ratio_named_once():
    # two references of one common physics: folded when both are named and agree (relative to their
    # references) within 3 combined standard uncertainties, else named each at its place
    from blf.diagnose import Param, Reference
    from blf.diagnose.records import NamedReference
    from blf.diagnose.selection import _reference_effects
    from sim.replay_model import RATIO

    nominal = tuple(Param(f"gain{k}", 1.0, 1.0, 0.5, 1.5) for k in range(2))
    r1 = Reference(0, 1.075, "lvdt_pitch", "ema1", "LVDT 1 pitch", "gain_error", 1.0, RATIO)
    r2 = Reference(1, 0.98, "lvdt_pitch", "ema2", "LVDT 2 pitch", "gain_error", 1.0, RATIO)
    u = 3e-6
    alike = [NamedReference(r1, 1.075 * (1 + 12e-6), 1.075 * u, 40.0, 30.0),
             NamedReference(r2, 0.98 * (1 + 16e-6), 0.98 * u, 50.0, 35.0)]
    (e,) = _reference_effects(alike, (r1, r2), nominal, 10.0)
    assert (e.name, e.where, e.source) == ("transmission_ratio", "external", "nominal")
    assert e.parameters["gain_error"] == pytest.approx(14e-6, abs=1e-9)  # equal weights: the mean
    assert e.uncertainty["gain_error"] == pytest.approx(u / np.sqrt(2), rel=1e-9)
    assert e.delta_bic == pytest.approx(-(30.0 + 40.0)) and e.delta_chi2_holdout == pytest.approx(-65.0)
    apart = [alike[0], NamedReference(r2, 0.98 * (1 + 40e-6), 0.98 * u, 50.0, 35.0)]  # 28e-6 apart > 3 x 4.2e-6
    assert [(x.name, x.where) for x in _reference_effects(apart, (r1, r2), nominal, 10.0)] == [
        ("lvdt_pitch", "ema1"), ("lvdt_pitch", "ema2")]
    (one,) = _reference_effects(alike[:1], (r1, r2), nominal, 10.0)  # the other not named: no fold
    assert (one.name, one.where) == ("lvdt_pitch", "ema1")
    assert one.parameters["gain_error"] == pytest.approx(1.075 * (1 + 12e-6) - 1.0)


class _SharedFrictionModel:
    """Two force channels sharing a nominal friction c >= 0 (a bound), EMA 1 with a candidate
    extra friction x: F1 = ref1 + (c + x) sign(v1), F2 = ref2 + c sign(v2), noise sigma 1 N.
    The recording has 20 N in F1 and -10 N in F2: the unbounded optimum (c = -10, x = 30) lies
    beyond c's bound, the bounded one is c = 0, x = 20 with F2's 10 N left unexplained."""

    def __init__(self, seed: int = 5):
        from blf.diagnose import Candidate, Param
        n = 60000
        self.t_s = np.arange(n) * 0.002
        self.sg = (np.sign(np.sin(2 * np.pi * self.t_s / 7.0)), np.sign(np.sin(2 * np.pi * self.t_s / 5.0 + 1.0)))
        self.ref = (300.0 * np.sin(2 * np.pi * self.t_s / 11.0), 250.0 * np.sin(2 * np.pi * self.t_s / 13.0))
        rng = np.random.default_rng(seed)
        self.channels = ("F1", "F2")
        self.measured = {"F1": self.ref[0] + 20.0 * self.sg[0] + rng.normal(size=n),
                         "F2": self.ref[1] - 10.0 * self.sg[1] + rng.normal(size=n)}
        self.valid = {c: np.ones(n, bool) for c in self.channels}
        self.nominal = (Param("coulomb_N", 5.0, 5.0, 0.0, 100.0),)
        self.candidates = (Candidate("coulomb_friction", "ema1", "extra friction of EMA 1",
                                     (Param("force_N", 5.0, 5.0, 0.0, 100.0),), "drive"),)
        self.regimes = {"velocity 1": self.sg[0], "velocity 2": self.sg[1]}

    def predict(self, theta, active):
        x = sum(float(p[0]) for _, p in active)
        return {"F1": self.ref[0] + (theta[0] + x) * self.sg[0], "F2": self.ref[1] + theta[0] * self.sg[1]}


def test_an_effect_is_fitted_to_the_bounded_optimum_when_a_bound_cuts_the_linear_step():
    """The linearised re-adjustment wants the shared nominal friction at -10 N; cut at its bound 0,
    that step would leave 10 N in F1 with x = 30 N. The accepted effect is the bounded optimum
    (nominal and candidate refitted together): x = 20 N, c = 0, the rest (F2) unexplained at EMA 2."""
    d = diagnose(_SharedFrictionModel(), 0.002)
    (e,) = [e for e in d.effects if e.source == "library"]
    assert (e.name, e.where) == ("coulomb_friction", "ema1")
    assert e.parameters["force_N"] == pytest.approx(20.0, abs=0.2), e.parameters
    assert d.nominal["coulomb_N"] == pytest.approx(0.0, abs=0.1)
    assert d.residual_rms_after["F1"] < 0.5 * d.residual_rms_before["F1"]
    assert d.verdict == "unexplained" and d.where[0] == "ema2"


def test_forms_of_one_physics_within_two_bic_units_name_the_simpler():
    """Parsimony among the friction laws of one drive: within form_margin (2) of the best BIC the
    form with the fewest parameters is named, then the library's first; beyond it the better BIC
    decides. A simpler form not yet refitted is refitted for the comparison; another place or
    variant never takes part."""
    from blf.diagnose import Candidate, DiagnoseConfig, Param
    from blf.diagnose.fit import CandidateFit
    from blf.diagnose.records import Refit
    from blf.diagnose.selection import _prefer_simpler_law

    def cand(name, n, where="ema1", variant="drive"):
        return Candidate(name, where, name, tuple(Param(f"p{k}", 1.0, 1.0) for k in range(n)), variant)

    cou, vis, stri, asym = cand("coulomb_friction", 1), cand("viscous_friction", 1), \
        cand("stribeck_friction", 2), cand("asymmetric_friction", 2)
    other = cand("coulomb_friction", 1, where="ema2")
    lib = (cou, vis, stri, asym, other)
    pen = {c: 8.0 * len(c.params) for c in lib}
    margin = DiagnoseConfig().form_margin
    assert margin == 2.0

    def row(bic, c):
        return Refit(bic, -20.0, c, CandidateFit(np.ones(len(c.params)), np.ones(len(c.params)), np.zeros(3), 0.0, 0.0))

    def first(refits, refit=lambda c: None):
        return _prefer_simpler_law(list(refits), lib, pen, set(), margin, refit, 100.0, 100.0,
                                   lambda s: None)[0].candidate

    # a direction-dependent fit 1.3 better than Coulomb: indistinguishable, Coulomb named
    assert first([row(-45.4, asym), row(-44.1, cou), row(-40.0, stri)]) is cou
    # 3.5 better: evidence, the direction-dependent law named (not Stribeck by library order)
    assert first([row(-27.4, asym), row(-23.9, vis), row(-17.8, stri)]) is asym
    assert first([row(-27.4, asym), row(-26.0, stri)]) is stri  # same count, within 2: the library's first
    assert first([row(-30.0, asym), row(-29.5, other)]) is asym  # another place is another question
    # the simpler forms not among the refits are refitted here (Coulomb: chi2 on the fit half
    # 46 - 100 + pen 8 = -46, within 1 of the best)
    calls = []

    def refit(c):
        calls.append(c.name)
        return CandidateFit(np.ones(1), np.ones(1), np.zeros(3), 46.0, 80.0) if c is cou else None
    assert first([row(-47.0, asym)], refit) is cou
    assert calls == ["coulomb_friction", "viscous_friction", "stribeck_friction"]


class _TwoLawsModel:
    """One force channel with a friction of 20 N at a constant speed of 1 mm/s: Coulomb (force_N)
    and viscous (N s/mm) friction have the same signature there; the nominal is the gain."""

    def __init__(self, seed: int = 9):
        from blf.diagnose import Candidate, Param
        n = 40000
        self.t_s = np.arange(n) * 0.002
        self.v = np.sign(np.sin(2 * np.pi * self.t_s / 6.0))  # mm/s
        self.ref = 200.0 * np.sin(2 * np.pi * self.t_s / 9.0)
        self.channels = ("F1",)
        self.measured = {"F1": 1.01 * self.ref + 20.0 * self.v + np.random.default_rng(seed).normal(size=n)}
        self.valid = {"F1": np.ones(n, bool)}
        self.nominal = (Param("gain", 1.0, 0.1, 0.5, 2.0),)
        self.candidates = tuple(Candidate(name, "ema1", name, (Param(pn, 5.0, 5.0, 0.0, 100.0),), "drive")
                                for name, pn in (("coulomb_friction", "force_N"),
                                                 ("viscous_friction", "coeff_N_s_per_mm")))
        self.regimes = {"velocity": self.v}

    def predict(self, theta, active):
        return {"F1": theta[0] * self.ref + sum(float(p[0]) for _, p in active) * self.v}


def test_a_form_the_recording_cannot_tell_apart_is_named_beside_the_one_taken():
    """At one speed Coulomb and viscous friction fit alike: Coulomb (the library's first) is named,
    20 N, and its evidence says viscous friction fitted as well, with its BIC."""
    d = diagnose(_TwoLawsModel(), 0.002)
    (e,) = d.effects
    assert (e.name, e.where) == ("coulomb_friction", "ema1") and d.verdict == "explained"
    assert e.parameters["force_N"] == pytest.approx(20.0, abs=0.1)
    assert "as good within 2 BIC units" in e.evidence and "viscous_friction (BIC -" in e.evidence, e.evidence


def test_the_friction_law_with_a_held_tanh_is_the_law_and_another_band_is_computed_afresh():
    """sim.replay.friction_force takes tanh(v / v_eps) from a model that holds it (the dual-EMA replay):
    bit for bit the law computed afresh, Stribeck term or not; a friction law of another band never gets
    the held one (DualEmaReplay._tanh_of)."""
    import numpy as np

    from sim.replay import FRICTION_BAND_MM_S, friction_force
    from sim.replay_model import DualEmaReplay

    v = np.random.default_rng(3).normal(0.0, 2.0, 500)
    held = np.tanh(v / FRICTION_BAND_MM_S)
    for kw in ({"coulomb_N": 12.0, "viscous_N_s_per_mm": 0.4}, {"coulomb_N": -0.0, "stribeck_N": 5.0},
               {"asym_N": 3.0, "stribeck_N": -0.0}):
        assert friction_force(v, **kw, tanh_v=held).tobytes() == friction_force(v, **kw).tobytes(), kw
    model = DualEmaReplay.__new__(DualEmaReplay)  # only the held tanh is needed here
    model._tanh_v = (held, held)
    assert model._tanh_of({"coulomb_N": 1.0}, 0) is held
    assert model._tanh_of({"coulomb_N": 1.0, "band_mm_s": FRICTION_BAND_MM_S}, 1) is held
    assert model._tanh_of({"coulomb_N": 1.0, "band_mm_s": 0.2}, 0) is None
