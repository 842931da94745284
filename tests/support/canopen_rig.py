"""The CANopen rig of the protocol tests: the shipped actuation profile planned, a master and a simulated
drive pair built from it (as ``emacheck dry-run`` builds them), without the command layer."""

from __future__ import annotations

from functools import cache
from pathlib import Path

from hil.canopen.od import load_eds
from hil.master.core import MasterCore
from hil.profile.load import load_actuation
from hil.profile.rig import Rig, plan_for
from sim.drives import SimDrivePair

__all__ = ["cyclic_master", "make_master", "make_pair", "od_factory", "shipped_rig"]


@cache
def shipped_rig() -> Rig:
    """The shipped actuation profile and EDS, planned (cached: the plan is immutable)."""
    return plan_for(load_actuation())


def od_factory(rig: Rig):
    """``od_factory(name, node_id)`` of :class:`sim.drives.SimDrivePair`: a fresh OD from the rig's EDS."""
    return lambda name, node_id: load_eds(rig.eds_paths[name], node_id=node_id)


def make_pair(plant, rig: Rig | None = None, **kw) -> SimDrivePair:
    """A simulated drive pair for ``rig`` (default the shipped one) around ``plant``."""
    rig = rig or shipped_rig()
    return SimDrivePair(plant, rig.plan, od_factory(rig), **kw)


def make_master(act=None, *, profile_path: str | Path | None = None, eds=None, safety=None) -> MasterCore:
    """A master core for ``act`` (default the shipped profile), planned against its EDS; ``safety``: the
    check's safety profile (the limits the preflight writes to the drives)."""
    if act is None and profile_path is None:
        return MasterCore(load_actuation(), shipped_rig().plan, safety=safety)
    if act is None:
        act = load_actuation(profile_path)
    return MasterCore(act, plan_for(act, profile_path, eds).plan, safety=safety)


def cyclic_master(act, plant, safety=None) -> MasterCore:
    """A master for ``act`` through its preflight against a simulated pair around ``plant``, every frame
    at t = 0 (its heartbeat consumers start then), in the cyclic phase. The drill of the master's death,
    which lets time pass, is skipped (test_master.py tests it). ``safety``: as :func:`make_master`."""
    from dataclasses import replace

    from hil.master.core import Phase

    act = replace(act, canopen=replace(act.canopen, skip_master_loss_drill="tested elsewhere"))
    pair = make_pair(plant)
    m = make_master(act, safety=safety)
    to_slaves, to_master = list(m.start(0.0)), list(pair.power_on(0.0))
    while to_slaves or to_master:
        while to_slaves:
            to_master += pair.on_frame(to_slaves.pop(0), 0.0)
        while to_master:
            to_slaves += m.on_frame(to_master.pop(0), 0.0)
    assert m.preflight_done and m.fault is None and m.phase is Phase.CYCLIC
    return m
