"""Forces periodic in position (issue 48): the pure steps (blf.diagnose.periodic) and the single-axis
comparison against a reference (emacheck diagnose --model single-axis --reference), on synthetic
recordings whose answers are known: a trapezoidal stroke at one speed, a force recorded with noise, a
ripple of known period and amplitude, uniform or at a place."""

from __future__ import annotations

import json
from importlib import resources

import jsonschema
import numpy as np
import pytest

from blf.diagnose.periodic import find_periods, lead_order, locality, search_range
from blf.errors import AnalysisError

FS = 25.0


def _stroke(n_cycles=20, lo=0.02, hi=0.14, v=0.024, dwell_s=1.0):
    """Position (m) of a trapezoidal set point: up at v, dwell, down, dwell."""
    t_move = (hi - lo) / v
    up = lo + v * np.arange(0, t_move, 1 / FS)
    cyc = np.r_[up, np.full(int(dwell_s * FS), hi), up[::-1], np.full(int(dwell_s * FS), lo)]
    return np.tile(cyc, n_cycles)


def _ripple(q, period, amp, centre=None, width=None):
    r = amp * np.cos(2 * np.pi * q / period + 0.3)
    if centre is not None:
        r = r * (np.abs(q - centre) < width / 2)
    return r


def _direction(q):
    d = np.sign(np.gradient(q))
    return d


@pytest.mark.parametrize("period", [0.004, 0.005])
def test_a_uniform_ripple_is_found_with_its_period_and_amplitude(period):
    rng = np.random.default_rng(1)
    q = _stroke()
    d = _direction(q)
    used = d != 0
    r = _ripple(q, period, 30.0) + rng.normal(0, 90.0, q.size)  # 30 N under 90 N of noise per sample
    s = search_range(q, used, d)
    found = find_periods(q, r, d, used, s)
    assert found, "the ripple is not found"
    f = found[0]
    assert abs(f.period_m / period - 1) < 0.02  # the 2 %
    assert abs(f.amplitude_N / 30.0 - 1) < 0.2  # and 20 %
    assert 0 < f.period_u_m < 0.01 * period
    w = locality(q, r, d, used, f.period_m, s)
    assert w.uniform


def test_noise_alone_names_no_period():
    rng = np.random.default_rng(2)
    q = _stroke()
    d = _direction(q)
    used = d != 0
    hits = sum(bool(find_periods(q, rng.normal(0, 90.0, q.size), d, used, search_range(q, used, d)))
               for _ in range(10))
    assert hits == 0


def test_a_local_defect_is_placed_where_it_is():
    """A ripple over 30 mm of the 120 mm travel (6 periods: its period is known to about 1/6 of a
    Rayleigh width of those 30 mm, far coarser than a uniform one's)."""
    rng = np.random.default_rng(3)
    q = _stroke(n_cycles=30)
    d = _direction(q)
    used = d != 0
    r = _ripple(q, 0.005, 80.0, centre=0.11, width=0.03) + rng.normal(0, 60.0, q.size)
    s = search_range(q, used, d)
    f = find_periods(q, r, d, used, s)[0]
    assert abs(f.period_m / 0.005 - 1) < 0.02
    w = locality(q, r, d, used, f.period_m, s)
    assert not w.uniform
    assert w.span_m[0] - 0.01 <= 0.11 <= w.span_m[1] + 0.01  # the stretch holding the defect
    assert "local" in w.words


def test_a_travel_shorter_than_two_periods_cannot_name_one_and_says_so():
    q = _stroke(lo=0.02, hi=0.0215)  # 1.5 mm of travel at about 1 mm per sample
    d = _direction(q)
    with pytest.raises(AnalysisError, match="shorter than two"):
        search_range(q, d != 0, d)
    s = search_range(_stroke(), _direction(_stroke()) != 0, _direction(_stroke()))
    assert s.longest_m == pytest.approx(s.span_m / 2)  # a period longer than half the travel is not sought


def test_a_stated_lead_names_the_order_or_is_reported_as_contradicted():
    once = lead_order(0.005, 0.00001, 0.005)
    assert once.nearest == 1 and not once.contradicts and "once per turn" in once.words
    twice = lead_order(0.0025, 0.00001, 0.005)
    assert twice.nearest == 2 and not twice.contradicts
    motor = lead_order(0.001, 0.000002, 0.005, gear_ratio=5.0)
    assert motor.part == "motor" and motor.nearest == 1 and not motor.contradicts
    # boundary: 3 standard uncertainties from order 1 (order 1 +- 3 u_n)
    inside = lead_order(0.005 / (1 + 2.9 * 0.001), 0.005 * 0.001, 0.005)
    outside = lead_order(0.005 / (1 + 3.2 * 0.001), 0.005 * 0.001, 0.005)
    assert not inside.contradicts and outside.contradicts
    bad = lead_order(0.0041, 0.00001, 0.005)  # a 4.1 mm period against a stated 5 mm lead
    assert bad.contradicts and "contradicts" in bad.words


@pytest.mark.parametrize("z, contradicts", [(2.9, False), (3.1, True)])
@pytest.mark.parametrize("side", ["longer", "shorter"])
def test_a_stated_position_scale_tolerance_widens_the_order_check_at_its_boundary(z, contradicts, side):
    """Tolerance s = 5 %, u_P/P = 0.1 %: order 1 is consistent while the gap |n - 1| - s n is within 3 u_n.
    Longer period: n = 1/(1 + s + z r) gives gap/u_n = z (r = u_P/P); shorter: n = 1/(1 - s - z r)."""
    s_tol, r, lead = 0.05, 0.001, 0.005
    n = 1.0 / (1.0 + s_tol + z * r) if side == "longer" else 1.0 / (1.0 - s_tol - z * r)
    # n = 1/(1 + s + z r): gap = 1 - n - s n = z r n = z u_n; n = 1/(1 - s - z r): gap = n - 1 - s n = z u_n
    P = lead / n
    got = lead_order(P, P * r, lead, scale_tolerance=s_tol)
    assert got.contradicts is contradicts and got.nearest == 1
    assert got.scale_difference == pytest.approx(1.0 / n - 1.0)
    if contradicts:
        assert "beyond the stated tolerance of the position's scale" in got.words
    else:
        assert "within the stated tolerance of the position sensor's scale" in got.words
        assert lead_order(P, P * r, lead).contradicts  # the same period with the scale taken as exact


def test_a_scale_tolerance_that_joins_two_orders_says_so_and_a_bad_one_is_refused():
    """Orders k and k + 1 meet once s >= 1/(2k + 1): 1/3 for order 1."""
    assert "cannot be told apart" in lead_order(0.005, 1e-5, 0.005, scale_tolerance=0.34).words
    assert "cannot be told apart" not in lead_order(0.005, 1e-5, 0.005, scale_tolerance=0.32).words
    for bad in (-0.01, 0.5):
        with pytest.raises(AnalysisError, match="scale_tolerance"):
            lead_order(0.005, 1e-5, 0.005, scale_tolerance=bad)


def _write(path, q, force, fs=FS):
    t = np.arange(q.size) / fs
    np.savetxt(path, np.column_stack([t, q, q, force]), delimiter=",", header="t,q,q_ref,force", comments="",
               fmt="%.9g")
    return path


def _axis_force(q, rng, ripple=None):
    v = np.gradient(q) * FS
    f = 200.0 * np.sign(v) + rng.normal(0, 20.0, q.size)
    return f + (ripple if ripple is not None else 0.0)


def test_a_ripple_grown_against_a_reference_is_named_with_period_and_amplitude(tmp_path):
    from hil.analysis.diagnose.axis_reference import reference_diagnosis
    from hil.analysis.diagnose.single_axis import PERIODIC_FLOOR_N, AxisOptions
    rng = np.random.default_rng(4)
    q = _stroke()
    ref = _write(tmp_path / "ref.csv", q, _axis_force(q, rng, _ripple(q, 0.005, 10.0)))
    new = _write(tmp_path / "new.csv", q, _axis_force(q, rng, _ripple(q, 0.005, 30.0)))
    d = reference_diagnosis(new, ref, AxisOptions(screw_lead_m=0.005))
    schema = json.loads(resources.files("hil.schemas").joinpath("diagnosis.schema.json").read_text())
    schema["required"] = [k for k in schema["required"] if k != "trace"]  # the command adds it (test_inputs_traced)
    jsonschema.validate(d, schema)
    e = [x for x in d["effects"] if x["name"] == "periodic_force_change"]
    assert len(e) == 1 and d["verdict"] == "explained"
    assert abs(e[0]["period_m"] / 0.005 - 1) < 0.02 and abs(e[0]["amplitude_N"] / 30 - 1) < 0.2
    assert abs(e[0]["change"]["amplitude_N"] / 20 - 1) < 0.2 and e[0]["floor"]["amplitude_N"] == PERIODIC_FLOOR_N
    c = d["periodic"]["components"][0]
    assert c["order"]["nearest"] == 1 and not c["order"]["contradicts_stated_lead"]
    assert d["periodic"]["holdout_rms_after_N"] < d["periodic"]["holdout_rms_before_N"]
    assert all(c["parameter"] in ("friction_N", "offset_N") or not c["named"] for c in d["changes"])
    json.dumps(d)


@pytest.mark.parametrize("grown, named", [(7.0, False), (9.0, True)])
def test_the_floor_of_a_periodic_change_holds_at_its_boundary(tmp_path, grown, named):
    """A 5 mm ripple of 10 N grown by 7 N (just under the 8 N floor) is not named, by 9 N (just over) it is
    (noise kept low so that both are statistically supported)."""
    from hil.analysis.diagnose.axis_reference import reference_diagnosis
    from hil.analysis.diagnose.single_axis import AxisOptions
    rng = np.random.default_rng(5)
    q = _stroke()
    ref = _write(tmp_path / "ref.csv", q, 200.0 * np.sign(np.gradient(q)) + rng.normal(0, 5, q.size)
                 + _ripple(q, 0.005, 10.0))
    new = _write(tmp_path / "new.csv", q, 200.0 * np.sign(np.gradient(q)) + rng.normal(0, 5, q.size)
                 + _ripple(q, 0.005, 10.0 + grown))
    d = reference_diagnosis(new, ref, AxisOptions())
    c = d["periodic"]["components"][0]
    assert all(abs(v["z"]) > 3 for v in c["directions"].values())
    assert c["named"] is named
    assert any(e["name"] == "periodic_force_change" for e in d["effects"]) is named


def test_healthy_pairs_name_no_periodic_force(tmp_path):
    from hil.analysis.diagnose.axis_reference import reference_diagnosis
    from hil.analysis.diagnose.single_axis import AxisOptions
    for seed in (6, 7, 8):
        rng = np.random.default_rng(seed)
        q = _stroke()
        ref = _write(tmp_path / f"ref{seed}.csv", q, _axis_force(q, rng, _ripple(q, 0.005, 20.0)))
        new = _write(tmp_path / f"new{seed}.csv", q, _axis_force(q, rng, _ripple(q, 0.005, 20.0)))
        d = reference_diagnosis(new, ref, AxisOptions())
        assert d["verdict"] == "no_mismatch" and d["effects"] == []


@pytest.mark.parametrize("hi, lead, says", [
    (0.0215, None, "shorter than two of the shortest periods"),  # 1.5 mm of travel: no period at all
    (0.035, 0.010, "cannot be named from this recording"),  # 15 mm of travel: a 10 mm lead needs 20 mm
])
def test_a_recording_too_short_for_a_period_says_so_in_diagnosis_json(tmp_path, hi, lead, says):
    from hil.analysis.diagnose.axis_reference import reference_diagnosis
    from hil.analysis.diagnose.single_axis import AxisOptions
    rng = np.random.default_rng(9)
    q = _stroke(n_cycles=20, hi=hi)
    ref = _write(tmp_path / "ref.csv", q, _axis_force(q, rng))
    new = _write(tmp_path / "new.csv", q, _axis_force(q, rng, _ripple(q, 0.010, 40.0)))
    d = reference_diagnosis(new, ref, AxisOptions(screw_lead_m=lead))
    assert says in d["periodic"]["words"]
    assert not any(e["name"] == "periodic_force_change" and e["period_m"] > (hi - 0.02) / 2 for e in d["effects"])


@pytest.mark.parametrize("tol, code", [("0.05", 0), ("0.5", 3), ("-0.01", 3)])
def test_the_command_takes_a_position_scale_tolerance_in_0_to_half(tmp_path, tol, code, capsys):
    from hil.cli import main
    rng = np.random.default_rng(5)
    q = _stroke()
    ref = _write(tmp_path / "ref.csv", q, _axis_force(q, rng, _ripple(q, 0.005, 10.0)))
    new = _write(tmp_path / "new.csv", q, _axis_force(q, rng, _ripple(q, 0.0052, 30.0)))  # +4 % scale
    out = tmp_path / "out"
    got = main(["diagnose", str(new), "--model", "single-axis", "--reference", str(ref), "--out", str(out),
                "--quiet", "--screw-lead-m", "0.005", "--position-scale-tolerance", tol])
    assert got == code
    if code:
        assert "--position-scale-tolerance" in capsys.readouterr().err and not (out / "diagnosis.json").exists()
    else:
        comp = json.loads((out / "diagnosis.json").read_text())["periodic"]["components"][0]
        assert not comp["order"]["contradicts_stated_lead"] and comp["order"]["nearest"] == 1
        assert comp["order"]["scale_difference"] == pytest.approx(0.04, abs=0.004)
