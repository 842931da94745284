"""The verdict's rules pinned at their boundaries (ISO 14253-1 guard band, blf/maint/verdict.py).

Every rule is tested exactly on its limit and one float step either side (tests/support/boundary.py:
the inputs are walked by nextafter until ``B + U`` or ``B - U`` *is* the limit in floats), asserting
which side gives which status. With ``>=`` for ``>`` in the fail rule, or ``<`` for ``<=`` in the pass
rule, a test here fails. The budget functions are pinned by exact known answers and by errors that
name the argument and its unit (the house rule for errors).
"""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from blf.errors import InputError
from blf.maint.verdict import (
    COVERAGE_FACTOR,
    METHOD_BOUND_MM,
    METHOD_BOUND_REL,
    SERV_METHOD_REL,
    ChannelVerdict,
    Status,
    combine,
    decide,
    maint_uncertainty,
    overall,
    serv_uncertainty,
)
from support.boundary import around

LIMIT = 0.200  # B_spec of the shipped actuation [mm]
U = 0.006  # the expanded uncertainty of a shipped check's reading [mm]


# ---------------------------------------------------------------------------- pass: B + U <= limit


@pytest.mark.parametrize("limit, u", [(LIMIT, U), (0.15, 0.0123), (1.0, 0.25)])
def test_pass_rule_on_its_limit_and_one_step_either_side(limit, u):
    below, at, above = around(lambda b: b + u, limit, limit - u)
    assert at + u == limit  # on the limit, in floats
    for b, status in ((below, Status.PASS), (at, Status.PASS), (above, Status.INCONCLUSIVE)):
        v = decide(b, u, limit)
        assert (v.status, v.backlash_mm, v.uncertainty_mm, v.limit_mm) == (status, b, u, limit), (b, v)
        assert v.margin_mm == limit - b
    assert decide(at, u, limit).reason == f"B + U = {at + u:.4f} mm <= limit {limit:.4f} mm"


# ---------------------------------------------------------------------------- fail: B - U > limit


@pytest.mark.parametrize("limit, u", [(LIMIT, U), (0.15, 0.0123), (1.0, 0.25)])
def test_fail_rule_on_its_limit_and_one_step_either_side(limit, u):
    """B - U = 0.200 exactly is not proven above the limit (inconclusive); one step more is."""
    below, at, above = around(lambda b: b - u, limit, limit + u)
    assert at - u == limit
    for b, status in ((below, Status.INCONCLUSIVE), (at, Status.INCONCLUSIVE), (above, Status.FAIL)):
        v = decide(b, u, limit)
        assert (v.status, v.backlash_mm, v.uncertainty_mm) == (status, b, u), (b, v)
        assert v.margin_mm == limit - b
    v = decide(above, u, limit)
    assert v.reason == f"B - U = {above - u:.4f} mm > limit {limit:.4f} mm"
    v = decide(at, u, limit)
    assert v.reason == (f"the limit {limit:.4f} mm lies within B +- U = {at:.4f} +- {u:.4f} mm: "
                        "neither conformance nor non-conformance is proven")


def test_without_uncertainty_the_limit_itself_passes_and_one_step_above_fails():
    assert decide(LIMIT, 0.0, LIMIT).status == Status.PASS
    assert decide(math.nextafter(LIMIT, 1.0), 0.0, LIMIT).status == Status.FAIL
    assert decide(math.nextafter(LIMIT, 0.0), 0.0, LIMIT).status == Status.PASS


def test_a_reading_in_micrometres_on_each_side():
    """Whole micrometres, as an inspector reads them: 194 + 6 = 200 passes, 195 + 6 does not;
    206 - 6 = 200 is inconclusive, 207 - 6 fails (the float of each landing where intended)."""
    um = 1e-3
    assert decide(194 * um, 6 * um, 200 * um).status == Status.PASS
    assert decide(195 * um, 6 * um, 200 * um).status == Status.INCONCLUSIVE
    assert decide(205 * um, 6 * um, 200 * um).status == Status.INCONCLUSIVE
    assert decide(207 * um, 6 * um, 200 * um).status == Status.FAIL


# ---------------------------------------------------------------------------- not measured, not traversed


def test_a_channel_not_measured_names_why_and_the_default_says_so():
    v = decide(None, None, LIMIT)
    assert v == ChannelVerdict(Status.INCONCLUSIVE, None, None, LIMIT, None, "not measured: not measured")
    v = decide(None, None, LIMIT, missing="no contact on the tension side")
    assert v.status == Status.INCONCLUSIVE and v.reason == "not measured: no contact on the tension side"
    # a reading given with missing= is still decided on its numbers
    assert decide(0.1, 0.01, LIMIT, missing="ignored").status == Status.PASS


def test_not_traversed_only_with_its_flag_and_only_without_a_reading():
    v = decide(None, None, LIMIT, not_traversed=True)
    assert v == ChannelVerdict(Status.NOT_TRAVERSED, None, None, LIMIT, None, "no backlash traversal in the recording")
    v = decide(None, None, LIMIT, missing="symmetric operation", not_traversed=True)
    assert v.status == Status.NOT_TRAVERSED and v.reason == "symmetric operation"
    assert decide(0.1, 0.01, LIMIT, not_traversed=True).status == Status.PASS  # a reading is decided


# ---------------------------------------------------------------------------- overall


def _v(status: str) -> ChannelVerdict:
    return ChannelVerdict(status, None, None, LIMIT, None, "")


@pytest.mark.parametrize("statuses, expected", [
    ((Status.PASS,), Status.PASS),
    ((Status.PASS, Status.PASS, Status.PASS), Status.PASS),
    ((Status.PASS, Status.INCONCLUSIVE), Status.INCONCLUSIVE),
    ((Status.INCONCLUSIVE, Status.PASS), Status.INCONCLUSIVE),
    ((Status.PASS, Status.FAIL), Status.FAIL),
    # a proven failure wins over an inconclusive channel
    ((Status.INCONCLUSIVE, Status.FAIL, Status.PASS), Status.FAIL),
    ((Status.FAIL, Status.FAIL), Status.FAIL),
    ((Status.INCONCLUSIVE,), Status.INCONCLUSIVE),
    ((Status.PASS, Status.NOT_TRAVERSED), Status.PASS),  # not traversed does not count
    ((Status.FAIL, Status.NOT_TRAVERSED), Status.FAIL),
    ((Status.INCONCLUSIVE, Status.NOT_TRAVERSED), Status.INCONCLUSIVE),
    ((Status.NOT_TRAVERSED,), Status.INCONCLUSIVE),  # nothing traversed proves nothing
    ((Status.NOT_TRAVERSED, Status.NOT_TRAVERSED), Status.INCONCLUSIVE),
    ((), Status.INCONCLUSIVE),
])
def test_overall_decision_of_the_channels(statuses, expected):
    assert overall({f"ch{k}": _v(s) for k, s in enumerate(statuses)}) == expected


# ---------------------------------------------------------------------------- the budget


def test_combine_root_sum_of_squares_and_k2_exactly():
    u = combine(2.0, 3.0, 6.0, 0.0)  # sqrt(4 + 9 + 36) = 7
    assert (u.statistical_mm, u.pitch_mm, u.temperature_mm, u.method_mm) == (2.0, 3.0, 6.0, 0.0)
    assert (u.combined_mm, u.expanded_mm, u.coverage_factor) == (7.0, 14.0, COVERAGE_FACTOR)
    u = combine(0.0, 0.0, 0.0, 12.0)
    assert (u.combined_mm, u.expanded_mm) == (12.0, 24.0)
    assert combine(1.0, 2.0, 2.0, 4.0).combined_mm == 5.0  # each term enters squared


@pytest.mark.parametrize("k, name", [(0, "statistical_mm"), (1, "pitch_mm"), (2, "temperature_mm"), (3, "method_mm")])
def test_combine_refuses_a_negative_term_naming_it_and_its_unit(k, name):
    args = [0.001] * 4
    args[k] = -1e-9
    with pytest.raises(InputError, match=rf"^{name} must be a finite scalar >= 0.0 mm, got -1e-09$"):
        combine(*args)
    args[k] = 0.0  # zero is allowed
    assert combine(*args).combined_mm == pytest.approx(math.sqrt(3) * 0.001, rel=1e-15)


def test_maint_budget_terms_each_known():
    b, sigma, pr, tau = 0.4, 0.0003, 2e-3, 5e-3
    u = maint_uncertainty(b, sigma, pr, temperature_error=tau)
    assert u.statistical_mm == sigma and u.pitch_mm == b * pr and u.temperature_mm == b * tau
    assert u.method_mm == METHOD_BOUND_REL * b / math.sqrt(3.0)  # 5 % of 0.4 mm > 5 um
    expected = math.sqrt(sigma**2 + (b * pr) ** 2 + (b * tau) ** 2 + (0.02 / math.sqrt(3.0)) ** 2)
    assert u.combined_mm == pytest.approx(expected, rel=1e-15)
    assert u.expanded_mm == 2.0 * u.combined_mm


def test_maint_method_bound_switches_from_absolute_to_relative_at_0p1_mm():
    """max(5 um, 5 % of B): the absolute part below B = 0.1 mm, the relative above."""
    assert (METHOD_BOUND_MM, METHOD_BOUND_REL) == (0.005, 0.05)
    for b, bound in ((0.0, 0.005), (0.05, 0.005), (0.099, 0.005), (0.101, 0.05 * 0.101), (0.3, 0.05 * 0.3)):
        assert maint_uncertainty(b, 0.0, 0.0).method_mm == bound / math.sqrt(3.0), b
    assert maint_uncertainty(0.1, 0.0, 0.0).method_mm == pytest.approx(0.005 / math.sqrt(3.0), rel=1e-15)


@pytest.mark.parametrize("kwargs, message", [
    (dict(backlash_mm=-1e-6), r"^backlash_mm must be a finite scalar >= 0.0 mm, got -1e-06$"),
    (dict(sigma_mm=-1e-6), r"^sigma_mm must be a finite scalar >= 0.0 mm, got -1e-06$"),
    (dict(pitch_rel_uncertainty=-1e-6), r"^pitch_rel_uncertainty must be a finite scalar >= 0.0 \(relative\), got"),
    (dict(temperature_error=-1e-6), r"^temperature_error must be a finite scalar >= 0.0 \(relative\), got"),
    (dict(backlash_mm=math.nan), r"^backlash_mm must be a finite scalar >= 0.0 mm, got nan$"),
])
def test_maint_budget_refuses_bad_input_naming_it(kwargs, message):
    args = dict(backlash_mm=0.1, sigma_mm=0.001, pitch_rel_uncertainty=1e-3) | kwargs
    with pytest.raises(InputError, match=message):
        maint_uncertainty(**args)


def test_maint_budget_zero_inputs_are_allowed():
    u = maint_uncertainty(0.0, 0.0, 0.0, temperature_error=0.0)
    assert (u.statistical_mm, u.pitch_mm, u.temperature_mm) == (0.0, 0.0, 0.0)
    assert u.method_mm == 0.005 / math.sqrt(3.0)


@pytest.mark.parametrize("method", ["improved", "paper"])
def test_serv_budget_terms_each_known(method):
    b, sigma, pitch, temp = 0.12, 0.003, 0.002, 0.02
    u = serv_uncertainty(b, sigma, pitch, temp, method)
    rel = SERV_METHOD_REL[method]
    assert rel == {"improved": 0.10, "paper": 0.40}[method]
    assert (u.statistical_mm, u.pitch_mm) == (sigma, pitch)
    assert u.temperature_mm == temp / math.sqrt(3.0) and u.method_mm == rel * b / math.sqrt(3.0)
    expected = math.sqrt(sigma**2 + pitch**2 + u.temperature_mm**2 + u.method_mm**2)
    assert u.combined_mm == pytest.approx(expected, rel=1e-15)
    assert serv_uncertainty(b, sigma, pitch, temp).method_mm == 0.10 * b / math.sqrt(3.0)  # improved by default


@pytest.mark.parametrize("args, message", [
    ((-1e-6, 0.0, 0.0, 0.0), r"^backlash_mm must be a finite scalar >= 0.0 mm, got -1e-06$"),
    ((0.1, 0.0, 0.0, -1e-6), r"^temperature_bound_mm must be a finite scalar >= 0.0 mm, got -1e-06$"),
    ((0.1, -1e-6, 0.0, 0.0), r"^statistical_mm must be a finite scalar >= 0.0 mm"),
    ((0.1, 0.0, -1e-6, 0.0), r"^pitch_mm must be a finite scalar >= 0.0 mm"),
    ((0.1, 0.0, 0.0, 0.0, "best"), r"^method must be one of \('improved', 'paper'\), got 'best'$"),
])
def test_serv_budget_refuses_bad_input_naming_it(args, message):
    with pytest.raises(InputError, match=message):
        serv_uncertainty(*args)


@pytest.mark.parametrize("args, message", [
    ((0.1, 0.01, 0.0), r"^limit_mm must be a finite positive number in mm; got 0.0"),
    ((0.1, 0.01, -0.2), r"^limit_mm must be a finite positive number in mm; got -0.2"),
    ((math.inf, 0.01, 0.2), r"^backlash_mm must be a finite scalar in mm, got inf$"),
    ((0.1, -1e-9, 0.2), r"^uncertainty_mm must be a finite scalar >= 0.0 mm, got -1e-09$"),
    ((0.1, None, 0.2), r"^uncertainty_mm must be a finite scalar >= 0.0 mm, got None$"),
])
def test_decide_refuses_bad_input_naming_it(args, message):
    with pytest.raises(InputError, match=message):
        decide(*args)


def test_a_status_is_its_string_in_json():
    """Status is a StrEnum: equal to its value, and result.json and the history hold the same strings."""
    assert [str(s) for s in Status] == ["pass", "fail", "inconclusive", "not_traversed"]
    assert Status.PASS == "pass" and f"{Status.NOT_TRAVERSED}" == "not_traversed"
    v = decide(0.1, 0.01, LIMIT)
    text = json.dumps(dataclasses.asdict(v))
    assert text.startswith('{"status": "pass", ') and text == json.dumps({**dataclasses.asdict(v), "status": "pass"})
    assert json.dumps({"status": overall({"int1": v})}) == '{"status": "pass"}'
