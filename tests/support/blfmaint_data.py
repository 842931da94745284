"""Synthetic force-fight F-D records for BLFmaint (tests/test_blf_maint.py, tests/bench/bench_envelope.py).

Model (quasi-static force fight, sampled at 500 Hz), in the sign-normalised
force G (increasing with D; the recorded force is ``F = slope_sign * G``):

* a slow triangular force demand: per cycle the gap is traversed to the right
  at ``gap_speed_mm_per_s`` (G = +gap friction), the right contact is loaded
  G: 0 -> f_max -> 0 in ``2 * ramp_s``, the gap is traversed to the left
  (G = -gap friction), the left contact is loaded G: 0 -> -f_max -> 0;
* piecewise linear contact with backlash B (truth = the asymptotes; B is the
  distance between them at G = 0) and tension/compression stiffnesses that
  may differ::

      right:  D =  B/2 + G/k_right - r * exp(-|G|/G_r)
      left:   D = -B/2 + G/k_left  + r * exp(-|G|/G_r)

  (r = ``rounding_mm`` softens the first ~r of each contact, a visco-elastic
  like rounding; 0 = piecewise linear);
* the shipped noise model: LVDT noise 0.025 mm peak-to-peak = Gaussian with
  std 0.025/6 mm on each stroke (``sim/params.py``), load cells 10 N std. The
  internal difference D_int = s - phi/i carries one LVDT's noise with the
  EMA's force F_i; the external pair D_ext = s2 - s1, F2 - F1 carries two,
  so both stds are sqrt(2) larger (``channel="ext"``). D noise may be AR(1)
  coloured (``d_noise_ar1``), F noise is white.

For ``slope_sign = -1`` (internal) this is D = -(F/k_c + B/2) for F > 0 and
D = -(F/k_t - B/2) for F < 0 with k_c = k_left, k_t = k_right.

:func:`make_force_fight` is the generator; :func:`envelope_case` draws one
record of a cell of the benchmark's envelope grid (backlash, ratio of backlash
to the D range of the force fight, contact stiffness, noise factor) with the
nuisance parameters (slope sign, stiffness asymmetry, offset, gap speed, gap
friction, internal/external noise) drawn from the seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

__all__ = [
    "FS_HZ",
    "F_RANGE_N",
    "SIGMA_D_MM",
    "SIGMA_F_N",
    "EnvelopeCase",
    "envelope_case",
    "f_max_for_ratio",
    "make_force_fight",
]

FS_HZ = 500.0
SIGMA_D_MM = 0.025 / 6.0  # LVDT noise 0.025 mm pp (sim/params.py: std = pp / 6)
SIGMA_F_N = 10.0  # load cell noise std
#: force-fight amplitudes a check can produce: from a small fight to the external pair F2 - F1 at
#: twice the per-EMA cap (profiles/check.toml: 15 % of the 40 kN limit load, capped at 7 kN)
F_RANGE_N = (500.0, 15_000.0)


def make_force_fight(
    rng: np.random.Generator,
    *,
    stiffness_left_N_per_mm: float = 80_000.0,
    stiffness_right_N_per_mm: float = 80_000.0,
    backlash_mm: float = 0.10,
    slope_sign: int = -1,
    f_max_N: float = 6_000.0,
    n_cycles: int = 3,
    ramp_s: float = 1.9,
    gap_speed_mm_per_s: float = 0.25,
    rounding_mm: float = 0.0,
    rounding_force_N: float = 400.0,
    gap_friction_N: float = 0.0,
    d_offset_mm: float = 0.0,
    sigma_d_mm: float = 0.0042,
    sigma_f_N: float = SIGMA_F_N,
    d_noise_ar1: float = 0.0,
):
    """Quasi-static force fight through +-f_max_N, sampled at 500 Hz (model: module docstring).

    Per cycle (4*ramp_s + 2*gap time, ~8.4 s with the defaults): traverse the
    gap to the right at gap_speed (G = +friction), right contact G: 0 -> f_max
    -> 0, traverse the gap to the left (G = -friction), left contact
    G: 0 -> -f_max -> 0. D noise is Gaussian with std sigma_d_mm (mm), white
    or, with d_noise_ar1 = a, AR(1) coloured (e[k] = a e[k-1] + w[k], same
    stationary std); F noise std sigma_f_N (N).

    Returns (d_mm, f_N) with noise, and the noise-free (d_true, f_true).
    """
    n_ramp = int(round(ramp_s * FS_HZ))
    up = np.arange(n_ramp) / n_ramp
    tri = np.concatenate((up, 1.0 - up)) * f_max_N
    edge = backlash_mm / 2.0 - rounding_mm
    n_gap = max(1, int(round(2.0 * edge / gap_speed_mm_per_s * FS_HZ)))
    gap = np.linspace(-edge, edge, n_gap, endpoint=False)

    def right(gv):
        soft = rounding_mm * np.exp(-np.abs(gv) / rounding_force_N)
        return backlash_mm / 2 + gv / stiffness_right_N_per_mm - soft

    def left(gv):
        soft = rounding_mm * np.exp(-np.abs(gv) / rounding_force_N)
        return -backlash_mm / 2 + gv / stiffness_left_N_per_mm + soft

    ds, gs = [], []
    for _ in range(n_cycles):
        ds += [gap, right(tri), -gap, left(-tri)]
        gs += [np.full(n_gap, gap_friction_N), tri, np.full(n_gap, -gap_friction_N), -tri]
    d_true = np.concatenate(ds) + d_offset_mm
    f_true = slope_sign * np.concatenate(gs)
    w = rng.normal(0.0, sigma_d_mm * np.sqrt(1.0 - d_noise_ar1**2), d_true.size)
    d = d_true + lfilter([1.0], [1.0, -d_noise_ar1], w)
    f = f_true + rng.normal(0.0, sigma_f_N, f_true.size)
    return d, f, d_true, f_true


def f_max_for_ratio(backlash_mm: float, ratio: float, k_left_N_per_mm: float, k_right_N_per_mm: float) -> float:
    """Force amplitude (N) at which backlash / (D range of the force fight) = ``ratio``.

    D range = B + f_max/k_left + f_max/k_right (noise-free), so
    f_max = B (1/ratio - 1) / (1/k_left + 1/k_right).
    """
    return backlash_mm * (1.0 / ratio - 1.0) / (1.0 / k_left_N_per_mm + 1.0 / k_right_N_per_mm)


@dataclass(frozen=True)
class EnvelopeCase:
    """One synthetic record of an envelope cell and its truth (units in the names)."""

    d_mm: np.ndarray
    f_N: np.ndarray
    backlash_mm: float
    stiffness_left_N_per_mm: float
    stiffness_right_N_per_mm: float
    f_max_N: float
    d_range_mm: float
    channel: str  #: "int" (one LVDT, one load cell) or "ext" (two of each: sqrt(2) larger noise)
    params: dict  #: every generator argument, for the benchmark's JSON


def envelope_case(rng: np.random.Generator, backlash_mm: float, ratio: float, stiffness_N_per_mm: float,
                  noise_factor: float) -> EnvelopeCase:
    """One record of the envelope cell (backlash, ratio, stiffness, noise factor); nuisances from ``rng``.

    ``stiffness_N_per_mm`` is the geometric mean of the two contact
    stiffnesses; their ratio k_right/k_left is drawn log-uniform in
    [1/1.4, 1.4] (tension and compression may differ). The force amplitude
    follows from ``ratio`` (:func:`f_max_for_ratio`). Drawn as well: slope
    sign (internal -1 / external +1), channel (internal: one LVDT and one load
    cell; external: sqrt(2) x both noises), D offset U(-0.5, 0.5) mm, gap
    speed log-uniform 0.1-1 mm/s, gap friction U(0, 100) N (20 % of the
    smallest force amplitude), ramp time U(1.5, 3) s, 3 cycles. Noise: ``noise_factor`` x the shipped
    model (0.025/6 mm, 10 N).
    """
    asym = float(np.exp(rng.uniform(-np.log(1.4), np.log(1.4))))
    k_l = stiffness_N_per_mm / np.sqrt(asym)
    k_r = stiffness_N_per_mm * np.sqrt(asym)
    f_max = f_max_for_ratio(backlash_mm, ratio, k_l, k_r)
    channel = "ext" if rng.random() < 0.5 else "int"
    scale = noise_factor * (np.sqrt(2.0) if channel == "ext" else 1.0)
    params = dict(
        stiffness_left_N_per_mm=float(k_l),
        stiffness_right_N_per_mm=float(k_r),
        backlash_mm=float(backlash_mm),
        slope_sign=-1 if channel == "int" else 1,
        f_max_N=float(f_max),
        n_cycles=3,
        ramp_s=float(rng.uniform(1.5, 3.0)),
        gap_speed_mm_per_s=float(np.exp(rng.uniform(np.log(0.1), np.log(1.0)))),
        gap_friction_N=float(rng.uniform(0.0, 100.0)),
        d_offset_mm=float(rng.uniform(-0.5, 0.5)),
        sigma_d_mm=float(SIGMA_D_MM * scale),
        sigma_f_N=float(SIGMA_F_N * scale),
    )
    d, f, _, _ = make_force_fight(rng, **params)
    return EnvelopeCase(d_mm=d, f_N=f, backlash_mm=float(backlash_mm), stiffness_left_N_per_mm=float(k_l),
                        stiffness_right_N_per_mm=float(k_r), f_max_N=float(f_max),
                        d_range_mm=float(backlash_mm + f_max / k_l + f_max / k_r), channel=channel,
                        params=params)
