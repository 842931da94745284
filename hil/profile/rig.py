"""The rig a profile describes, planned: every node's EDS loaded and checked against the signal map.

:func:`plan_for` is the one place that turns an actuation profile (and an
``--eds`` given on the command line) into the :class:`~hil.canopen.plan.RigPlan`
the master runs, the simulated nodes serve and ``emacheck profile check``
prints. It reads the EDS files; nothing is sent on a bus.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import canopen.objectdictionary as cod

from hil.canopen.errors import EdsError
from hil.canopen.od import load_eds
from hil.canopen.plan import PlanError, Problem, RigPlan, plan_rig
from hil.canopen.signalmap import NodeRole
from hil.profile.config import Actuation
from hil.profile.load import resolve_eds
from hil.profile.signals import gear_ratio_object

__all__ = ["Rig", "plan_for"]


@dataclass(frozen=True)
class Rig:
    """A planned rig: the plan, each node's EDS path and object dictionary (node name -> ...)."""

    plan: RigPlan
    eds_paths: dict[str, Path]
    ods: dict[str, cod.ObjectDictionary]


def plan_for(act: Actuation, profile_path: str | Path | None = None, eds: str | Path | None = None,
             *, max_bus_load: float = 0.5) -> Rig:
    """Load every node's EDS and plan the rig.

    Parameters
    ----------
    act : Actuation
        A loaded actuation profile (with its signal map).
    profile_path : path, optional
        The profile's file: EDS names are looked up next to it first.
    eds : path, optional
        ``--eds``: the drives' EDS, overriding ``canopen.eds``.

    Raises
    ------
    hil.errors.ProfileError
        An EDS that cannot be found (naming the profile key).
    hil.canopen.plan.PlanError
        Every problem of the profile, its map and the EDS files, each with its profile key and object.
    """
    paths: dict[str, Path] = {}
    ods: dict[str, cod.ObjectDictionary] = {}
    problems = []
    for n in act.signals.nodes:
        drive = n.role is NodeRole.DRIVE
        key = "canopen.eds" if drive else f"{n.key}.eds"
        p = resolve_eds(n.eds, profile_path, key, override=eds if drive else None)
        paths[n.name] = p
        try:
            ods[n.name] = load_eds(p, node_id=n.node_id)
        except EdsError as exc:
            problems.append(Problem(key, None, str(exc)))
    if problems:
        raise PlanError(problems)
    c = act.canopen
    plan = plan_rig(act.signals, ods, eds_names={k: v.name for k, v in paths.items()}, bitrate_bps=c.bitrate_bps,
                    sync_period_s=act.timing.sync_period_s, master_node_id=c.master_node_id,
                    master_heartbeat_period_s=c.master_heartbeat_period_s,
                    external_watchdog=bool(c.external_watchdog), gear_ratio_object=gear_ratio_object(act),
                    i_total_rad_per_mm=act.mechanics.i_total_rad_per_mm, max_bus_load=max_bus_load)
    return Rig(plan, paths, ods)
