"""The rig of the tests that build the plant by hand (the brief's dual-EMA rig, profiles aside)."""

from __future__ import annotations

import math
from dataclasses import replace

from sim.params import DriveParams, EmaMechanics, RigParams, SensorParams, SurfaceParams

I_TOTAL = 2.0 * math.pi * 4.0 / 5.0  #: gear ratio [rad/mm]: gearbox 4:1, lead 5 mm
T_S = 0.002  #: sample period [s]


def brief_rig(**overrides) -> RigParams:
    """The default rig: 0.10/0.12 mm internal play, 80 kN/mm, LVDT pitch errors of 7.5 % and -2 %;
    keyword overrides replace RigParams fields."""
    base = dict(
        i_total_rad_per_mm=I_TOTAL,
        stroke_limit_mm=20.0,
        sample_period_s=T_S,
        substeps=8,
        ema1=EmaMechanics(0.10, 80e3, 80e3, 0.05, 200e3, 20e3),
        ema2=EmaMechanics(0.12, 80e3, 80e3, 0.05, 200e3, 20e3),
        drive=DriveParams(1.0e-4, 1e-4, 10.0, 150.0, 0.8, 0.05),
        surface=SurfaceParams(300.0, 0.5, 0.0),
        sensors1=SensorParams(1.075, 0.3, 0.02, 20.0, 0.025, 1.0, 10.0, 12),
        sensors2=SensorParams(0.98, -0.2, 0.02, 20.0, 0.025, 1.0, 10.0, 12),
        effects=(),
    )
    base.update(overrides)
    return RigParams(**base)


def quiet(params: RigParams) -> RigParams:
    """The same rig with noise-free LVDTs and load cells."""
    return replace(
        params,
        sensors1=replace(params.sensors1, lvdt_noise_pp_mm=0.0, loadcell_noise_std_N=0.0),
        sensors2=replace(params.sensors2, lvdt_noise_pp_mm=0.0, loadcell_noise_std_N=0.0),
    )
