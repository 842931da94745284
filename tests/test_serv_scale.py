"""BLFserv's jumps held to the LVDT's scale (blf.serv.scale): a jump counts only where it clears what an LVDT
of unknown pitch can make of the ram's travel through it. Known answer against the simulator's truth of which
play each scenario crosses, and the rule pinned at its boundary."""

from __future__ import annotations

import numpy as np
import pytest

from blf.errors import InputError
from blf.serv import blf_serv, motion_through_jumps, with_known_scale
from sim import operation as op
from sim import scenarios as sc

FS = 500.0
CHANNELS = ("int1", "int2", "ext")
P_MAX = 0.10  # no calibration: the largest LVDT pitch error the house admits (HARD_LVDT_GAIN_TOLERANCE)


def _uncalibrated(params, rec):
    i = params.i_total_rad_per_mm
    d = {"int1": rec.s1_mm - rec.phi1_rad / i, "int2": rec.s2_mm - rec.phi2_rad / i, "ext": rec.s2_mm - rec.s1_mm}
    x = {"int1": rec.phi1_rad / i, "int2": rec.phi2_rad / i, "ext": 0.5 * (rec.phi1_rad + rec.phi2_rad) / i}
    out = {}
    for ch in CHANNELS:
        raw = blf_serv(d[ch], FS, keep_signals=False, t0_s=float(rec.t_s[0]))
        dx = motion_through_jumps(x[ch], FS, raw.jumps, t0_s=float(rec.t_s[0]))
        out[ch] = (raw, with_known_scale(raw, dx, P_MAX, lvdts=2 if ch == "ext" else 1))
    return out


@pytest.mark.parametrize("seed", range(3))
def test_without_calibration_a_channel_is_measured_exactly_where_the_simulator_crossed_its_play(simrig, seed):
    """Five normal-operation scenarios, raw LVDT data (pitch errors +7.5 % and -2 %): each channel has a reading
    if and only if the simulation crossed that play (its truth), within 20 % of the true backlash (the 7.5 %
    scale error of the uncorrected height itself plus the spread of 1 to 13 jumps; worst seen 16 %)."""
    params = simrig.params
    rng = np.random.default_rng(500 + seed)
    profiles = {"full_stroke": sc.full_stroke_profile(params), "small_manoeuvres": sc.small_manoeuvre_profile(params),
                "gusts": sc.gust_profile(params, rng), "ext_crossing": sc.ext_crossing_profile(params),
                "cruise": sc.cruise_profile(params, rng)}
    artefacts = 0
    for name, prof in profiles.items():
        rec = op.simulate_operation(params, prof, rng)
        for ch, (raw, held) in _uncalibrated(params, rec).items():
            assert (held.traversals > 0) == rec.traversed[ch], (name, ch, held.traversals)
            if held.traversals:
                assert abs(held.backlash_mm / rec.truth.backlash_mm[ch] - 1.0) < 0.20, (name, ch)
            artefacts += raw.traversals - held.traversals
            if not rec.traversed[ch]:
                assert held.backlash_mm is None and held.backlash_paper_mm is None
    # the raw detector counted the stroke's acceleration phases (the ext 0.077 mm from 4 "traversals")
    assert artefacts >= 10


def _one_jump(h_mm: float = 0.1, dx_mm: float = 0.0, seed: int = 1):
    """4 s at 500 Hz, one jump of D by ``h_mm`` at 2 s while x steps by ``dx_mm`` (over 20 ms, inside the event)."""
    rng = np.random.default_rng(seed)
    t = np.arange(2000) / FS
    d = rng.normal(0.0, 0.003, t.size) + h_mm * (t >= 2.0)
    x = dx_mm * np.clip((t - 1.99) / 0.02, 0.0, 1.0)
    return d, x


def test_the_rule_at_its_boundary():
    """|h| - c p_max |dx| >= min_jump: a travel 0.1 % short of the boundary keeps the jump, 0.1 % over drops it;
    two LVDTs (D_ext) halve the travel allowed."""
    d, _ = _one_jump()
    r = blf_serv(d, FS, min_jump_mm=0.02, keep_signals=False)
    [j] = r.jumps
    assert j.accepted and abs(j.height_mm - 0.1) < 0.005
    for lvdts in (1, 2):
        edge = (abs(j.height_mm) - 0.02) / (lvdts * P_MAX)
        for factor, kept in ((0.999, True), (1.001, False)):
            _, x = _one_jump(dx_mm=edge * factor)
            dx = motion_through_jumps(x, FS, r.jumps)
            assert dx[0] == pytest.approx(edge * factor, rel=1e-9)
            held = with_known_scale(r, dx, P_MAX, lvdts=lvdts)
            assert held.traversals == int(kept) and held.jumps[0].accepted is kept, (lvdts, factor)
            assert (held.backlash_mm == r.backlash_mm) if kept else held.backlash_mm is None
            if not kept:
                assert held.jumps[0].reason.startswith("within the LVDT scale's reach")
                assert not held.jumps[0].paper_accepted and held.backlash_paper_mm is None


def test_a_travel_at_constant_speed_through_the_jump_is_no_travel():
    """The lines either side carry a constant speed: only a change of the ram's motion inside the event counts."""
    d, _ = _one_jump()
    r = blf_serv(d, FS, keep_signals=False)
    x = 25.0 * np.arange(d.size) / FS  # 25 mm/s throughout
    assert abs(motion_through_jumps(x, FS, r.jumps)[0]) < 1e-9
    assert with_known_scale(r, motion_through_jumps(x, FS, r.jumps), P_MAX).traversals == 1


def test_inputs_are_checked():
    d, x = _one_jump()
    r = blf_serv(d, FS, keep_signals=False)
    with pytest.raises(InputError, match="one travel per jump"):
        with_known_scale(r, [0.0, 0.0], P_MAX)
    with pytest.raises(InputError, match="pitch_bound"):
        with_known_scale(r, [0.0], -0.1)
    with pytest.raises(InputError, match="lvdts"):
        with_known_scale(r, [0.0], P_MAX, lvdts=3)
    with pytest.raises(InputError, match="outside"):
        motion_through_jumps(x[:500], FS, r.jumps)
