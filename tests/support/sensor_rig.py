"""A rig with a sensor node, from the shipped files only: the shipped drives (``ema_drive.eds``) and the
LVDTs and load cells on a CiA 401 analog input module (``cia401_io.eds``, node 3).

The shipped actuation profile with the LVDT and force of both EMAs moved to the I/O module's 16-bit
analog inputs 0x6401:01..04 (EMA 1 LVDT, EMA 1 force, EMA 2 LVDT, EMA 2 force), scaled as signal
conditioners would deliver them: LVDT +-20 mm over +-32000 raw (0.000625 mm per unit), load cell
+-10 kN over +-32000 raw (0.3125 N per unit). No file of ../shared is needed.
"""

from __future__ import annotations

from pathlib import Path

from hil.profile.load import load_actuation
from hil.profile.rig import Rig, plan_for
from support.profiles import write_profile_variant

__all__ = ["FORCE_N_PER_UNIT", "IO_NODE", "LVDT_MM_PER_UNIT", "sensor_profile", "sensor_rig"]

IO_NODE = 3
LVDT_MM_PER_UNIT = 0.000625
FORCE_N_PER_UNIT = 0.3125


def sensor_profile(dest: str | Path, **io: object) -> Path:
    """Write the actuation profile of the sensor-node rig to ``dest``; ``io`` overrides keys of
    ``[nodes.io]`` (e.g. ``heartbeat_period_s``)."""
    node = {"node_id": IO_NODE, "eds": "cia401_io.eds", "vendor_id": 0x0E3A, "product_code": 0x0401,
            "revision_min": 0x00010000, "device_profile": 401, **io}
    signals = {}
    for ema, (lvdt, force) in ((1, ("0x6401:01", "0x6401:02")), (2, ("0x6401:03", "0x6401:04"))):
        signals[f"ema{ema}"] = {
            "lvdt": {"node": "io", "object": lvdt, "mm_per_unit": LVDT_MM_PER_UNIT},
            "force": {"node": "io", "object": force, "N_per_unit": FORCE_N_PER_UNIT}}
    drop = [f"signals.ema{ema}.{sig}" for ema in (1, 2) for sig in ("lvdt", "force")]
    return write_profile_variant("actuation.toml", dest, remove=drop, add={"signals": signals, "nodes": {"io": node}})


def sensor_rig(dest: str | Path, **io: object) -> tuple[object, Rig]:
    """(the actuation, the planned rig) of :func:`sensor_profile` written to ``dest``."""
    path = sensor_profile(dest, **io)
    act = load_actuation(path)
    return act, plan_for(act, path)
