"""Segments of a recording (blf.maint.segments): runs, smoothed speed, trimming, phase segmentation, sweep finder.

Known answers on synthetic recordings at 500 Hz: two calibration sweeps
(triangles at 5 mm/s over +-15 mm, one EMA at a time) and a force fight
(rams still, |F1 - F2|/2 switching between +-3 kN); a slow sweep under a
steady load among sweeps that do not qualify.
"""

from __future__ import annotations

import numpy as np
import pytest

from blf.errors import AnalysisError, InputError
from blf.maint.segments import Segments, find_segments, find_sweep, runs, smooth_speed, trim

T = 0.002  # s
LIMIT = 20.0  # mm
SPEED = 5.0  # mm/s of the sweeps


def _spread(level_mm_s: float) -> int:
    """Samples by which the 0.2 s (100-sample) centred average of a speed step from 0 to SPEED
    reaches ``level_mm_s`` ahead of the step (and stays above it after the step back to 0):
    100 * level / SPEED samples of the window must be moving."""
    return int(round(50 - 100 * level_mm_s / SPEED))


SPREAD = _spread(0.5)  # the "moving" level of find_segments: 40 samples at 5 mm/s


def _triangle(n: int, amp: float) -> np.ndarray:
    """0 -> +amp -> -amp -> 0 over n samples."""
    u = np.arange(n) / n
    return amp * (1.0 - 2.0 * np.abs(2.0 * ((u + 0.25) % 1.0) - 1.0))


def _recording(rng: np.random.Generator):
    """Rest, sweep of EMA 1, rest, sweep of EMA 2, rest, force fight, rest; and the true stretches."""
    rest = int(2.0 / T)
    nsw = int(4 * 15.0 / SPEED / T)  # 12 s
    nff = int(10.0 / T)
    parts = [("rest", rest), ("cal1", nsw), ("rest", rest), ("cal2", nsw), ("rest", rest), ("ff", nff),
             ("rest", rest)]
    n = sum(k for _, k in parts)
    x1, x2, f1, f2 = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    truth, step = {}, np.full(n, "rest", dtype=object)
    i = 0
    for name, k in parts:
        sl = slice(i, i + k)
        if name == "cal1":
            x1[sl] = _triangle(k, 15.0)
            f1[sl], f2[sl] = -2000.0, 2000.0  # EMA 2 opposes in force mode
        elif name == "cal2":
            x2[sl] = _triangle(k, 15.0)
            f1[sl], f2[sl] = 2000.0, -2000.0
        elif name == "ff":
            # force fight: +-3 kN, switching sign every 2 s within 10 samples
            t = np.arange(k) * T
            s = np.clip(np.sin(2 * np.pi * t / 4.0) * 30.0, -1.0, 1.0)
            s[:10] *= np.arange(10) / 10.0
            f1[sl], f2[sl] = 3000.0 * s, -3000.0 * s
        if name != "rest":
            truth[name] = (i, i + k)
            step[sl] = {"cal1": "cal1_sweep", "cal2": "cal2_sweep", "ff": "force_fight"}[name]
        i += k
    x1 += 1e-4 * rng.standard_normal(n)  # resolver-level noise
    x2 += 1e-4 * rng.standard_normal(n)
    f1 += 10.0 * rng.standard_normal(n)
    f2 += 10.0 * rng.standard_normal(n)
    return x1, x2, f1, f2, truth, step


def _edges(mask: np.ndarray) -> tuple[int, int]:
    (r,) = runs(mask)
    return int(r[0]), int(r[1])


# ---------------------------------------------------------------------- runs, speed, trim


@pytest.mark.parametrize("mask, expected", [
    ([], []),
    ([False, False], []),
    ([True], [(0, 1)]),
    ([True, True, False, True], [(0, 2), (3, 4)]),
    ([False, True, True, True, False, False, True, True], [(1, 4), (6, 8)]),
    (np.ones(5, bool), [(0, 5)]),
])
def test_runs_of_small_masks(mask, expected):
    assert [(int(a), int(b)) for a, b in runs(mask)] == expected


def test_smooth_speed_of_a_ramp_is_exact_up_to_the_edges():
    t = np.arange(1000) * T
    v = smooth_speed(3.0 + 5.0 * t, T)
    np.testing.assert_allclose(v, 5.0, rtol=1e-9)  # edges padded with the end values, not zeros
    # a step of the speed: the 0.2 s centred average spreads it over 100 samples
    x = np.where(t > 1.0, 5.0 * (t - 1.0), 0.0)
    v = smooth_speed(x, T)
    k = int(np.argmax(t > 1.0))
    assert v[k - 51] == 0.0 and v[k + 50] == pytest.approx(5.0)
    assert v[k] == pytest.approx(2.5, abs=0.1)
    with pytest.raises(InputError, match="sample_period_s"):
        smooth_speed(x, 0.0)
    with pytest.raises(InputError, match=r"x_mm must be a 1-D array in mm"):
        smooth_speed(np.zeros((3, 3)), T)


def test_trim_drops_two_percent_of_each_run():
    m = np.zeros(400, bool)
    m[10:110] = True  # 100 samples: 2 dropped at each end
    m[200:250] = True  # 50 samples: 1 dropped at each end
    out = trim(m)
    assert [(int(a), int(b)) for a, b in runs(out)] == [(12, 108), (201, 249)]
    assert [(int(a), int(b)) for a, b in runs(trim(m, 0.1))] == [(20, 100), (205, 245)]
    with pytest.raises(InputError, match="frac"):
        trim(m, 0.5)


# ---------------------------------------------------------------------- phase segmentation


def test_detected_phases_lie_where_the_truth_puts_them():
    x1, x2, f1, f2, truth, _ = _recording(np.random.default_rng(1))
    seg = find_segments(x1, x2, f1, f2, T, LIMIT)
    assert isinstance(seg, Segments) and seg.source == "detected"
    for name, mask in (("cal1", seg.cal1), ("cal2", seg.cal2)):
        a, b = _edges(mask)
        ta, tb = truth[name]
        # the moving mask extends by the averaging spread on either side
        assert abs(a - (ta - SPREAD)) <= 2 and abs(b - (tb + SPREAD)) <= 2, (name, a, b, ta, tb)
    a, b = _edges(seg.force_fight)
    ta, tb = truth["ff"]
    # the force fight: from the first to the last sample above 20 % of its maximum (rams still)
    assert 0 <= a - ta <= 5 and 0 <= tb - b <= 5, (a, b, ta, tb)
    assert not (seg.force_fight & (seg.cal1 | seg.cal2)).any()


def test_one_detected_sweep_calibrates_both_emas():
    x1, x2, f1, f2, truth, _ = _recording(np.random.default_rng(2))
    a2, b2 = truth["cal2"]
    x2[a2:b2] = 0.0  # EMA 2 never swept
    seg = find_segments(x1, x2, f1, f2, T, LIMIT)
    assert seg.cal2 is seg.cal1
    assert abs(_edges(seg.cal1)[0] - (truth["cal1"][0] - SPREAD)) <= 2


def test_phases_from_the_step_column():
    x1, x2, f1, f2, truth, step = _recording(np.random.default_rng(3))
    seg = find_segments(x1, x2, f1, f2, T, LIMIT, step=step)
    assert seg.source == "step column"
    for name, mask in (("cal1", seg.cal1), ("cal2", seg.cal2), ("ff", seg.force_fight)):
        assert _edges(mask) == truth[name]
    step2 = np.where(step == "cal2_sweep", "rest", step)
    assert find_segments(x1, x2, f1, f2, T, LIMIT, step=step2).cal2 is None
    with pytest.raises(AnalysisError, match="no 'force_fight' samples"):
        find_segments(x1, x2, f1, f2, T, LIMIT, step=np.where(step == "force_fight", "rest", step))
    with pytest.raises(InputError, match=r"step .* same shape as x1_mm"):
        find_segments(x1, x2, f1, f2, T, LIMIT, step=step[:-1])


def test_no_force_fight_is_an_analysis_error():
    x1, x2, f1, f2, truth, _ = _recording(np.random.default_rng(4))
    end = truth["cal2"][1]
    f1[end:], f2[end:] = 0.0, 0.0  # no force at all after the sweeps
    with pytest.raises(AnalysisError, match="no force-fight segment"):
        find_segments(x1, x2, f1, f2, T, LIMIT)


def test_segmentation_refuses_bad_input():
    x = np.zeros(1000)
    with pytest.raises(InputError, match=r"f2_N \(in N\) must have the same shape as x1_mm"):
        find_segments(x, x, x, x[:-1], T, LIMIT)
    with pytest.raises(InputError, match="x2_mm must be finite"):
        find_segments(x, np.r_[x[:-1], np.nan], x, x, T, LIMIT)
    with pytest.raises(InputError, match="stroke_limit_mm"):
        find_segments(x, x, x, x, T, -1.0)


# ---------------------------------------------------------------------- slow sweep under load


def _sweep_recording(force_N: float, speed: float, travel_mm: float, rng: np.random.Generator):
    """1 s rest, a sweep of ``travel_mm`` at ``speed`` under ``force_N`` (+ ripple), 1 s rest."""
    rest = int(1.0 / T)
    k = int(travel_mm / speed / T)
    x = np.concatenate([np.full(rest, -travel_mm / 2), -travel_mm / 2 + speed * T * np.arange(k),
                        np.full(rest, travel_mm / 2)])
    f = force_N + 100.0 * np.sin(2 * np.pi * 4.0 * np.arange(x.size) * T) + 5.0 * rng.standard_normal(x.size)
    return x, f, (rest, rest + k)


def test_the_slow_sweep_under_load_is_found_and_trimmed():
    x, f, (ta, tb) = _sweep_recording(2000.0, SPEED, 24.0, np.random.default_rng(5))
    sl = find_sweep(x, f, T, LIMIT)
    # slow: the average above 0.3 mm/s, from 44 samples before the step to 44 after; 2 % trimmed
    a, b = ta - _spread(0.3), tb + _spread(0.3)
    k = int(0.02 * (b - a))
    assert abs(sl.start - (a + k)) <= 2 and abs(sl.stop - (b - k)) <= 2, (sl, a + k, b - k)


@pytest.mark.parametrize("force_N, speed, travel_mm, why", [
    (2000.0, 20.0, 24.0, "too fast"),
    (2000.0, SPEED, 8.0, "shorter than half the stroke limit"),
    (150.0, SPEED, 24.0, "load below 200 N"),
    (0.0, SPEED, 24.0, "load of both signs"),
])
def test_sweeps_that_do_not_qualify_are_not_found(force_N, speed, travel_mm, why):
    x, f, _ = _sweep_recording(force_N, speed, travel_mm, np.random.default_rng(6))
    assert find_sweep(x, f, T, LIMIT) is None, why


def test_the_longest_qualifying_sweep_wins():
    rng = np.random.default_rng(7)
    x1, f1, _ = _sweep_recording(-1500.0, SPEED, 12.0, rng)
    x2, f2, (ta, tb) = _sweep_recording(-1500.0, SPEED, 30.0, rng)
    x, f = np.concatenate([x1, x2 + 30.0]), np.concatenate([f1, f2])
    sl = find_sweep(x, f, T, LIMIT)
    assert x1.size + ta - 60 < sl.start < x1.size + ta + 60
    with pytest.raises(InputError, match="f_N"):
        find_sweep(x, f[:-1], T, LIMIT)
