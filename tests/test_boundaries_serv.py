"""BLFserv's refusals pinned at their boundaries (blf/serv/blfserv.py, the detector of blf/serv/detect.py).

A traversal counts when both plateaus are long enough (``min_plateau_s``), quiet (fit residual at
most ``max_residual_factor`` x the noise level), the event not too long (``max_event_s``) and the
jump at least ``min_jump_mm`` (the paper's Delta D likewise for the paper method). Each rule is fed
exactly its limit, taken from the jump itself (the measured height, residual, plateau length, event
length), and one step either side: a float step for the real-valued rules, one sample for the
counted ones; the noise level is a power of two so that ``factor x noise`` is exact. The input
refusals are pinned the same way (10 samples, ``min_plateau_s <= plateau_s``, ``min_jump_mm >= 0``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from blf.errors import AnalysisError, InputError
from blf.serv.blfserv import BlfServMonitor, blf_serv

FS = 500.0
SIGMA = 2.0 ** -8  # noise level passed to BLFserv [mm] (~ the shipped LVDT's 0.025/6 mm), a power of two


def _record(seed: int, jump_at_s: float = 1.0, n: int = 1500, height_mm: float = 0.1) -> np.ndarray:
    """D at rest with white noise (std 0.004 mm) and one backlash jump of ``height_mm``."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    return height_mm * (t >= jump_at_s) + rng.normal(0.0, 0.004, n)


def _one_jump(d: np.ndarray, **kw):
    r = blf_serv(d, FS, noise_std_mm=SIGMA, keep_signals=False, **kw)
    assert len(r.jumps) == 1, r.jumps
    return r, r.jumps[0]


# ---------------------------------------------------------------------------- the height: min_jump_mm


def test_min_jump_on_the_jumps_own_height_and_one_step_above():
    _, j = _one_jump(_record(5), min_jump_mm=0.0)
    h = abs(j.height_mm)
    assert 0.08 < h < 0.12 and j.accepted
    for mj, accepted in ((math.nextafter(h, 0.0), True), (h, True), (math.nextafter(h, 1.0), False)):
        r, jj = _one_jump(_record(5), min_jump_mm=mj)
        assert jj.height_mm == j.height_mm  # the detection does not depend on min_jump_mm
        assert jj.accepted is accepted and jj.reason == ("ok" if accepted else "below min jump"), mj
        assert (r.traversals, r.backlash_mm) == ((1, h) if accepted else (0, None))


def test_paper_delta_on_its_own_size_and_one_step_above():
    _, j = _one_jump(_record(5), min_jump_mm=0.0, method="paper")
    p = abs(j.paper_delta_mm)
    assert 0.03 < p < 0.09  # the paper's Delta D reads low
    for mj, accepted in ((p, True), (math.nextafter(p, 1.0), False)):
        r, jj = _one_jump(_record(5), min_jump_mm=mj, method="paper")
        assert jj.paper_accepted is accepted
        assert (r.traversals, r.backlash_mm) == ((1, p) if accepted else (0, None))


# ---------------------------------------------------------------------------- quiet plateaus


def _seed_where(before_noisier: bool) -> int:
    for seed in range(50):
        _, j = _one_jump(_record(seed))
        if (j.residual_before_mm > j.residual_after_mm) == before_noisier:
            return seed
    raise AssertionError("no seed found")


@pytest.mark.parametrize("side", ["before", "after"])
def test_plateau_residual_on_its_limit_and_one_step_above(side):
    seed = _seed_where(before_noisier=side == "before")
    _, j = _one_jump(_record(seed))
    res = getattr(j, f"residual_{side}_mm")
    factor = res / SIGMA  # exact: SIGMA is a power of two
    assert factor * SIGMA == res and 0.5 < factor < 1.5
    for f, reason in ((math.nextafter(factor, 9.0), "ok"), (factor, "ok"),
                      (math.nextafter(factor, 0.0), f"plateau {side} not quiet")):
        _, jj = _one_jump(_record(seed), max_residual_factor=f)
        assert jj.reason == reason and jj.accepted is (reason == "ok"), (f, jj)


# ---------------------------------------------------------------------------- plateau lengths


@pytest.mark.parametrize("side, jump_at_s, n", [("before", 0.18, 1500), ("after", 1.0, 590)])
def test_plateau_length_on_its_limit_and_one_sample_more(side, jump_at_s, n):
    """A jump near the start (end) of the record has a shorter plateau before (after) it: that length
    is accepted as min_plateau_s, one sample more is not."""
    d = _record(11, jump_at_s=jump_at_s, n=n)
    _, j = _one_jump(d)
    m = getattr(j, f"n_{side}")
    other = j.n_after if side == "before" else j.n_before
    assert 10 < m < 75 and other == 75  # (75: the full plateau_s of 0.15 s)
    for samples, reason in ((m - 1, "ok"), (m, "ok"), (m + 1, f"plateau {side} too short")):
        _, jj = _one_jump(d, min_plateau_s=samples / FS)
        assert jj.reason == reason, (samples, jj)


# ---------------------------------------------------------------------------- event length


def test_event_length_on_its_limit_and_one_sample_less():
    """An event stays open while the second derivative leaves its zone again within the merge gap;
    it is too long when that reaches max_event_s: (last - start) + merge samples is one too few."""
    d = _record(5)
    _, j = _one_jump(d)
    merge = round(0.1 * FS)  # merge_gap_s default
    span = round((j.t_end_s - j.t_start_s) * FS) + merge
    assert 50 < span < 200
    for samples, reason in ((span + 2, "ok"), (span + 1, "ok"), (span, "event too long")):
        r = blf_serv(d, FS, noise_std_mm=SIGMA, keep_signals=False, max_event_s=samples / FS)
        assert r.jumps[0].reason == reason, (samples, r.jumps)
        assert r.jumps[0].t_start_s == j.t_start_s


# ---------------------------------------------------------------------------- input refusals


def test_ten_samples_are_the_fewest():
    d = _record(1, n=10)
    r = blf_serv(d, FS, noise_std_mm=SIGMA)
    assert r.n_samples == 10 and r.traversals == 0 and r.backlash_mm is None
    with pytest.raises(InputError, match=r"^d_mm must have at least 10 samples in mm; got shape \(9,\)$"):
        blf_serv(d[:9], FS, noise_std_mm=SIGMA)


def test_min_plateau_may_equal_plateau_not_exceed_it():
    d = _record(1)
    blf_serv(d, FS, noise_std_mm=SIGMA, plateau_s=0.15, min_plateau_s=0.15)
    above = math.nextafter(0.15, 1.0)
    with pytest.raises(InputError, match=rf"^min_plateau_s \({above} s\) must not exceed plateau_s \(0.15 s\)$"):
        blf_serv(d, FS, noise_std_mm=SIGMA, plateau_s=0.15, min_plateau_s=above)


@pytest.mark.parametrize("kw, ok", [
    (dict(min_jump_mm=0.0), True), (dict(min_jump_mm=-1e-12), False), (dict(min_jump_mm=math.inf), False),
    (dict(noise_std_mm=1e-300), True), (dict(noise_std_mm=0.0), False), (dict(noise_std_mm=-SIGMA), False),
    (dict(noise_std_mm=math.nan), False),
    (dict(threshold_factor=1e-9), True), (dict(threshold_factor=0.0), False),
    (dict(max_residual_factor=1e-9), True), (dict(max_residual_factor=0.0), False),
    (dict(plateau_s=1e-9, min_plateau_s=1e-9), True), (dict(plateau_s=0.0, min_plateau_s=0.0), False),
    (dict(min_plateau_s=1e-9), True), (dict(min_plateau_s=0.0), False),
    (dict(guard_before_s=0.0, guard_after_s=0.0, merge_gap_s=0.0), True),
    (dict(guard_before_s=-1e-9), False), (dict(guard_after_s=-1e-9), False), (dict(merge_gap_s=-1e-9), False),
    (dict(max_event_s=1e-9), True), (dict(max_event_s=0.0), False),
    (dict(method="improved"), True), (dict(method="paper"), True), (dict(method="best"), False),
])
def test_option_limits(kw, ok):
    name = next(k for k in kw if k not in ("min_plateau_s",) or len(kw) == 1)
    args = dict(noise_std_mm=SIGMA) | kw
    if ok:
        blf_serv(_record(1, n=200), FS, keep_signals=False, **args)
    else:
        with pytest.raises(InputError, match=rf"^{name} must"):
            blf_serv(_record(1, n=200), FS, keep_signals=False, **args)


def test_monitor_refuses_unknown_options_naming_the_known():
    with pytest.raises(InputError, match=r"^unknown option\(s\) \['plateau_ms'\]; known: \['discretisation', "):
        BlfServMonitor(FS, SIGMA, plateau_ms=150)
    with pytest.raises(InputError, match=r"^noise_std_mm must be a positive finite scalar or 1-D sequence in mm"):
        BlfServMonitor(FS, [SIGMA, 0.0])
    with pytest.raises(InputError, match=r"^min_jump_mm must be None or a finite scalar/sequence >= 0 in mm, one per "
                                         r"channel; got \[0.01, 0.02, 0.03\]$"):
        BlfServMonitor(FS, [SIGMA, SIGMA], min_jump_mm=[0.01, 0.02, 0.03])
    assert list(BlfServMonitor(FS, [SIGMA, SIGMA], min_jump_mm=[0.0, 0.02]).min_jump_mm) == [0.0, 0.02]
    assert list(BlfServMonitor(FS, [SIGMA, 2 * SIGMA]).min_jump_mm) == [6 * SIGMA, 12 * SIGMA]  # default 6 sigma


def test_a_noise_free_record_needs_its_noise_level():
    d = np.where(np.arange(600) >= 300, 0.1, 0.0)
    with pytest.raises(AnalysisError, match="noise-free"):
        blf_serv(d, FS)
    assert blf_serv(d, FS, noise_std_mm=1e-4).traversals == 1
