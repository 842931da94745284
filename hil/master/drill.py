"""What the master-loss drill records of each drive: the reaction as written and read back, and what the
drill observed (meta.json ``master_loss``). Plain frozen data (sans-IO); the drill itself is the
preflight's (:mod:`hil.master.preflight`)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

__all__ = ["DrillOutcome", "DrillResult", "MasterLossRecord", "ReactionConfig"]


class DrillOutcome(Enum):
    REACTED = "reacted"  #: the drive left OPERATION_ENABLED after the master fell silent
    NO_REACTION = "no reaction"  #: still OPERATION_ENABLED at the drill's deadline
    SKIPPED = "skipped"  #: the profile says why (canopen.skip_master_loss_drill)
    NOT_CONFIGURED = "not configured"  #: the drive has no reaction to drill (external watchdog stated)
    #: configured, but the drill did not get to the master's silence (the preflight stopped first; ``note``: why)
    NOT_RUN = "not run"


@dataclass(frozen=True, slots=True)
class DrillResult:
    """What the drill observed of one drive.

    Attributes
    ----------
    outcome : DrillOutcome
    reaction_ms : float or None
        From the master's last heartbeat to the first statusword outside OPERATION_ENABLED [ms].
    waited_ms : float or None
        How long the master stayed silent [ms].
    state_after : str or None
        The state the drive reacted into (e.g. ``QUICK_STOP_ACTIVE``).
    emcy : tuple of int
        EMCY error codes the drive sent while the master was silent.
    note : str
        Why it was skipped, or what else the engineer should know.
    """

    outcome: DrillOutcome
    reaction_ms: float | None = None
    waited_ms: float | None = None
    state_after: str | None = None
    emcy: tuple[int, ...] = ()
    note: str = ""


@dataclass(frozen=True, slots=True)
class ReactionConfig:
    """The reaction to the master's death as written and read back (what the drive was told).

    ``consumer_heartbeat_ms``, ``master_node_id`` and ``abort_connection_option`` are what was written;
    None (absent from the JSON) when nothing was written (the drive's EDS lacks the objects: ``problems``
    names which)."""

    consumer_heartbeat_ms: int | None
    master_node_id: int | None
    abort_connection_option: int | None
    configured: bool  #: every object written and read back as intended
    problems: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class MasterLossRecord:
    """How one drive is protected against the master's death: configured, and observed by the drill."""

    reaction: ReactionConfig
    drill: DrillResult
    external_watchdog: str = ""

    @property
    def armed(self) -> bool:
        """The drive may be enabled for the check: it reacted in the drill, the drill was skipped with a
        reason, or the rig states another protection."""
        return bool(self.external_watchdog) or self.drill.outcome in (DrillOutcome.REACTED, DrillOutcome.SKIPPED)

    def as_json(self) -> dict:
        d, r = self.drill, self.reaction
        written = {k: v for k, v in (("consumer_heartbeat_ms", r.consumer_heartbeat_ms),
                                     ("master_node_id", r.master_node_id),
                                     ("abort_connection_option", r.abort_connection_option)) if v is not None}
        return {**written, "configured": r.configured, "problems": list(r.problems),
                "drill": {"outcome": d.outcome.value, "reaction_ms": d.reaction_ms, "waited_ms": d.waited_ms,
                          "state_after": d.state_after, "emcy": [f"0x{c:04X}" for c in d.emcy], "note": d.note},
                "external_watchdog": self.external_watchdog}
