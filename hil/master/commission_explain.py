"""The commissioning's findings explained (:mod:`hil.master.hypotheses`) with the profile at hand: the
channels' keys and scalings, the swaps the signal map can express, every patch checked by loading and
planning the patched profile (:func:`hil.profile.patch.patch_problem`: never advice the loader would refuse),
and the serial numbers a profile pins (``canopen.serial_ema1``, ``canopen.serial_ema2``) against 0x1018:04.
"""

from __future__ import annotations

from pathlib import Path

from hil.canopen.signalmap import Signal
from hil.master.commission_rules import Finding, Kind, Stage, ema_key
from hil.master.hypotheses import Explanation, explain, observe

__all__ = ["explain_commission", "serial_findings", "swap_patch"]

_SENSORS = {"lvdt": Signal.LVDT, "force": Signal.FORCE}


def swap_patch(plan, sensor: str) -> dict:
    """The patch that makes each EMA's ``sensor`` read from the other's object (and node): the signal map's
    expression of two swapped wires."""
    e = {a: plan.map.entry(a, _SENSORS[sensor]) for a in (1, 2)}
    if e[1] is None or e[2] is None:
        return {}
    out = {}
    for a in (1, 2):
        o = e[3 - a]
        out[f"{e[a].key}.object"] = f"0x{o.index:04X}:{o.subindex:02X}"
        if o.node != e[a].node:
            out[f"{e[a].key}.node"] = o.node
    return out


def explain_commission(core, act, profile_data: dict, profile_path: str | Path | None,
                       eds: str | Path | None = None) -> Explanation:
    """:func:`hil.master.hypotheses.explain` over the commissioning ``core``'s measurements and findings,
    with the actuation profile's tables ``profile_data`` (read from ``profile_path``, None: the shipped
    one) for checking each patch."""
    from hil.profile.patch import patch_problem

    plan = core.plan
    keys = {(s, a): ema_key(plan, a, sig) for s, sig in _SENSORS.items() for a in (1, 2)}
    scales = {}
    for (s, a) in keys:
        e = plan.map.entry(a, _SENSORS[s])
        scales[(s, a)] = e.scale.si_per_unit if e is not None and e.scale is not None else 1.0
    sensors = act.sensors
    obs = observe(core.measured, core.findings, keys=keys,
                  declared={"lvdt": sensors.lvdt_noise_pp_mm, "force": sensors.loadcell_noise_std_N},
                  stroke_mm=min(sensors.lvdt_full_scale_mm, act.mechanics.stroke_limit_mm))
    fname = Path(profile_path).name if profile_path is not None else "actuation.toml"
    return explain(obs, core.findings, scales=scales, i_total=act.mechanics.i_total_rad_per_mm,
                   refuses=lambda patch: patch_problem(profile_data, patch, profile_path, eds, fname),
                   swaps={s: swap_patch(plan, s) for s in _SENSORS})


def serial_findings(act, scan_nodes: dict) -> list[Finding]:
    """A serial number pinned in the profile (``canopen.serial_emaN``, 0: none) that the drive does not
    report in 0x1018:04: the actuator on the rig is another one (fits: the serial read)."""
    out = []
    c = act.canopen
    for ema, nid in ((1, c.node_id_ema1), (2, c.node_id_ema2)):
        want = getattr(c, f"serial_ema{ema}")
        got = (scan_nodes.get(nid, {}).get("identity") or {}).get("serial")
        if want and got is not None and got != want:
            out.append(Finding(Stage.SCAN, Kind.SERIAL, f"canopen.serial_ema{ema}",
                               f"EMA {ema}'s drive (node {nid}) reports serial 0x{got:08X} (0x1018:04), the profile "
                               f"pins 0x{want:08X}: another actuator is fitted, or the profile is another rig's",
                               float(got), "", f"0x{got:08X}"))
    return out
