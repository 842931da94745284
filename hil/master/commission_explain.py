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

__all__ = ["explain_commission", "jog_patched", "serial_findings", "swap_patch"]

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

    def refuses(patch):
        return patch_problem(profile_data, patch, profile_path, eds, fname)

    ex = explain(obs, core.findings, scales=scales, i_total=act.mechanics.i_total_rad_per_mm, refuses=refuses,
                 swaps={s: swap_patch(plan, s) for s in _SENSORS})
    return jog_patched(ex, refuses)


def jog_patched(ex: Explanation, refuses) -> Explanation:
    """``ex`` with the values of the jog's findings in its patch: a jog that stopped on a scale (the gear ratio
    in degrees for radians) is not explained again by the hypotheses (nothing was loaded: no gains of a move),
    but its finding names one key and the value that fits; that goes into the patch, as every accepted cause's
    does, where the profile loader takes it. A finding naming several keys that fit equally (an LVDT scale or
    its encoder resolution) names no single fix: it stays out (the finding says which to check)."""
    import dataclasses

    items = {f.key: f.fits for f in ex.findings
             if f.stage is Stage.JOG and f.fits is not None and f.key and "," not in f.key and f.key not in ex.patch}
    if not items or refuses(ex.patch | items) is not None:
        return ex
    return dataclasses.replace(ex, patch=ex.patch | items)


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
