"""The wear scenario's checks without the plant: result.json documents of one actuator pair over flight hours.

Each check's true backlash is the simulated rig's wear line plus its per-check
scatter (:func:`sim.truth.apply_wear`, the same draw the simulated rig makes),
and the reading is the truth plus a measurement error of the standard
uncertainty the check states (U / 2, U as BLFmaint reports it on the default
rig). The statistics see what a series of simulated checks would give them,
in milliseconds instead of seconds per check; ``tests/bench/bench_history.py``
runs the same scenario through the plant and BLFmaint.
"""

from __future__ import annotations

import datetime as _dt
import uuid

import numpy as np

from blf.maint.verdict import decide, overall
from hil.profile.load import load_actuation, load_simrig
from sim.params import WearParams
from sim.truth import apply_wear, rig_truth, wear_line_mm

#: the scenario: rates [mm per 1000 FH] and per-check scatter [mm] of the wear test and benchmark
WEAR = WearParams(backlash_int1_mm_per_1000_fh=0.025, backlash_int2_mm_per_1000_fh=0.020,
                  backlash_ext_mm_per_1000_fh=0.010, scatter_mm=0.002)
#: U (k = 2) of BLFmaint on the default simulated rig, per channel [mm] (result.json of a simulated check)
U_MM = {"int1": 0.0058, "int2": 0.0069, "ext": 0.0058}
SERIALS = (0x5E000101, 0x5E000102)
CHANNELS = ("int1", "int2", "ext")


def true_crossing_fh(channel: str, limit_mm: float, wear: WearParams = WEAR) -> float:
    """Flight hours at which the scenario's wear line reaches ``limit_mm``."""
    base = rig_truth(load_simrig().params).backlash_mm[channel]
    return wear.reference_flight_hours + (limit_mm - base) / wear.rate_mm_per_1000_fh(channel) * 1000.0


def wear_results(n: int = 12, fh_max: float = 3000.0, seed: int = 0, *, wear: WearParams = WEAR,
                 serials: tuple[int, int] = SERIALS, start: _dt.datetime = _dt.datetime(2025, 1, 6, 8, 0),
                 days_between: float = 30.0, aircraft: str = "D-AXYZ", position: str = "left aileron",
                 simulated: bool = True, fh0: float = 0.0) -> list[dict]:
    """``n`` results of one pair, checks evenly from ``fh0`` to ``fh_max`` flight hours, ``days_between`` apart."""
    act = load_actuation()
    params = load_simrig().params
    rng = np.random.default_rng([seed, 1016])
    spec = {"int1": act.mechanics.backlash_spec_int_mm, "int2": act.mechanics.backlash_spec_int_mm,
            "ext": act.mechanics.backlash_spec_ext_mm}
    out = []
    for k, fh in enumerate(np.linspace(fh0, fh_max, n)):
        truth = rig_truth(apply_wear(params, wear, float(fh), rng)).backlash_mm
        read = {ch: float(truth[ch] + rng.normal(0.0, U_MM[ch] / 2.0)) for ch in CHANNELS}
        verdicts = {ch: decide(read[ch], U_MM[ch], spec[ch]) for ch in CHANNELS}
        t = start + _dt.timedelta(days=days_between * k)
        out.append({
            "status": overall(verdicts),
            "verdict": {ch: {"status": v.status, "backlash_mm": v.backlash_mm, "uncertainty_mm": v.uncertainty_mm,
                             "limit_mm": v.limit_mm, "margin_mm": v.margin_mm, "reason": v.reason}
                        for ch, v in verdicts.items()},
            "backlash_mm": read, "backlash_sigma_mm": {ch: 0.0003 for ch in CHANNELS},
            "stiffness_N_per_mm": {ch: {"left": 8.0e4, "right": 8.0e4} for ch in CHANNELS},
            "stiffness_sigma_N_per_mm": {ch: {"left": 50.0, "right": 50.0} for ch in CHANNELS},
            "calibration": {e: {"pitch": p, "offset_mm": 0.0, "nonlinearity_mm": 0.0, "rmse_mm": 0.004}
                            for e, p in (("ema1", 1.075), ("ema2", 0.98))},
            "spec": {"backlash_int_mm": spec["int1"], "backlash_ext_mm": spec["ext"]},
            "truth": {"backlash_mm": dict(truth), "line_mm": wear_line_mm(params, wear, float(fh))}
            if simulated else None,
            "trace": {
                "run_id": uuid.UUID(bytes=rng.bytes(16)).hex, "started_utc": t.isoformat() + "+00:00",
                "analysed_utc": (t + _dt.timedelta(minutes=3)).isoformat() + "+00:00",
                "software": {"name": "emacheck", "version": "0.1.0", "check_run_with": "0.1.0"},
                "operator": "A. Inspector", "work_order": f"WO-{4700 + k}",
                "identity": {f"ema{j}": {"node": j, "vendor_id": act.canopen.vendor_id,
                                         "product_code": act.canopen.product_code,
                                         "revision": act.canopen.revision_min, "serial": s}
                             for j, s in enumerate(serials, start=1)},
                "files_sha256": {}, "recording": "signals.csv", "mode": "simulate" if simulated else "run",
                "aircraft": aircraft, "position": position, "rig": "rig-1", "flight_hours": float(fh),
                "flight_cycles": int(round(fh * 0.8)),
            },
        })
        if not simulated:
            out[-1].pop("truth")
    return out
