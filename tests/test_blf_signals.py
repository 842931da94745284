"""Tests of blf.signals.position_differences (paper eq. 1)."""

from __future__ import annotations

import numpy as np
import pytest

from blf.errors import InputError
from blf.signals import PositionDifferences, position_differences

I_TOTAL = 2 * np.pi * 4 / 5  # 5.0265 rad/mm


def test_known_values():
    phi1 = np.array([0.0, I_TOTAL, -2 * I_TOTAL, 10.0])
    phi2 = np.array([0.0, 0.0, I_TOTAL, -10.0])
    s1 = np.array([0.0, 1.05, -2.0, 3.0])
    s2 = np.array([0.5, -0.02, 1.0, -3.0])
    pd = position_differences(phi1, phi2, s1, s2, I_TOTAL)
    assert isinstance(pd, PositionDifferences)
    np.testing.assert_allclose(pd.d_int1_mm, [0.0, 0.05, 0.0, 3.0 - 10.0 / I_TOTAL], atol=1e-15)
    np.testing.assert_allclose(pd.d_int2_mm, [0.5, -0.02, 0.0, -3.0 + 10.0 / I_TOTAL], atol=1e-15)
    np.testing.assert_allclose(pd.d_ext_mm, [0.5, -1.07, 3.0, -6.0], atol=1e-15)
    assert I_TOTAL == pytest.approx(5.0265, abs=1e-4)


def test_compression_gives_negative_internal_difference():
    """F > 0: the motor leads, the ram lags by F/k + B/2 -> D_int < 0 (paper Fig. 4)."""
    k, b, f = 80_000.0, 0.1, 6_000.0
    x_motor = np.linspace(-5.0, 5.0, 11)
    s = x_motor - (f / k + b / 2)
    pd = position_differences(x_motor * I_TOTAL, x_motor * I_TOTAL, s, s, I_TOTAL)
    np.testing.assert_allclose(pd.d_int1_mm, -0.125, atol=1e-12)
    np.testing.assert_allclose(pd.d_ext_mm, 0.0, atol=0)


def test_lists_are_accepted_and_results_read_only():
    pd = position_differences([0.0, 1.0], [0.0, 0.0], [0.0, 1.0], [1.0, 1.0], 2.0)
    np.testing.assert_allclose(pd.d_int1_mm, [0.0, 0.5])
    with pytest.raises(ValueError):
        pd.d_ext_mm[0] = 1.0
    with pytest.raises(AttributeError):
        pd.d_ext_mm = np.zeros(2)  # type: ignore[misc]


def test_input_errors_name_argument_shape_and_unit():
    z = np.zeros(10)
    msg = r"s2_mm \(in mm\) must have the same shape as phi1_rad.*\(9,\).*\(10,\)"
    with pytest.raises(InputError, match=msg):
        position_differences(z, z, z, z[:9], I_TOTAL)
    with pytest.raises(InputError, match=r"phi1_rad must be a 1-D array in rad; got shape \(2, 5\)"):
        position_differences(z.reshape(2, 5), z, z, z, I_TOTAL)
    bad = z.copy()
    bad[4] = np.nan
    msg = r"s1_mm must be finite \(in mm\); got 1 NaN/inf value\(s\) in shape \(10,\)"
    with pytest.raises(InputError, match=msg):
        position_differences(z, z, bad, z, I_TOTAL)
    with pytest.raises(InputError, match=r"phi2_rad.*at least 1 samples.*\(0,\)"):
        position_differences(z, np.zeros(0), z, z, I_TOTAL)
    for bad_i in (0.0, -5.0, np.nan, np.inf, np.array([5.0])):
        with pytest.raises(InputError, match="i_total_rad_per_mm.*rad/mm"):
            position_differences(z, z, z, z, bad_i)
    with pytest.raises(InputError, match="phi1_rad"):
        position_differences(["a"] * 10, z, z, z, I_TOTAL)
