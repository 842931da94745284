"""Which freshness limit applies: the master's stall budget (pure; the derivation is docs/safety.md,
*A stall of the master*).

A stall of the master is no hazard while both drives hold their last setpoint and keep the hard limits
themselves: the stroke by their software position limits 0x607D, the force by their max torque 0x6072,
the speed by their max motor speed 0x6080 (:mod:`hil.canopen.drivelimits`, written and read back by the
preflight). What the stall costs is the master's picture of the rig: a ram may move at the kept speed
``v`` for the stall's length, so the position the master saw last is off by ``v t``. The stall the master
accepts is therefore the time in which a ram at the kept speed moves by the following error the check
accepts, and never so long that the drives' consumer heartbeat would stop them first:

.. math::

    t_{stale} = \\min\\Big(\\texttt{max\\_stale\\_ms},\\ \\texttt{HARD\\_MAX\\_STALE\\_MS},\\
                \\frac{e_{max}}{v_{max}},\\ C - P_{hb} - 2T\\Big)

with ``e_max`` / ``v_max`` this run's following error and speed limits (each capped), ``C`` the drives'
consumer heartbeat time on the master (0x1016), ``P_hb`` the master's heartbeat period (the consumer counts
from its last heartbeat, up to one period before the stall began) and ``2 T`` the master's own reaction.
The physics terms are computed from this run's own values: ``e / v`` bounds the motion the master cannot
see, ``v t <= e``, whatever ``e`` and ``v`` the profile sets; the consumer term keeps the stall inside the
drives' own stop. ``HARD_MAX_STALE_MS`` (100 ms) is a ceiling independent of them: the master is never blind
longer than the rig's independent stop path on the master's loss is assumed to take (docs/drives.md
section 5: a watchdog relay drops STO 100 ms after the master's last heartbeat). (It was 2 mm / 50 mm/s =
40 ms, ``e / v`` at the two hard caps: one point of the ``e / v`` term, 10 ms at e = 0.5 mm, v = 50 mm/s and
200 ms at e = 2 mm, v = 10 mm/s, not a bound of anything.) Shipped: min(50, 100, 50, 71) = 50 ms = 25 SYNC
cycles at 2 ms.
A drive that does not keep all three of 0x607D, 0x6072 and 0x6080 (a drive that keeps none of its limits
among them) keeps today's short limit, ``safety.max_stale_cycles`` SYNC cycles (hard cap 5).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass

from hil.canopen.drivelimits import LimitKind
from hil.profile.config import (
    HARD_MAX_FOLLOWING_ERROR_MM,
    HARD_MAX_STALE_CYCLES,
    HARD_MAX_STALE_MS,
    HARD_MAX_VELOCITY_MM_PER_S,
    Actuation,
    Safety,
)

__all__ = ["NEEDED", "StaleLimit", "stale_limit"]

#: The limits each drive must keep itself for the derived (longer) freshness limit to apply.
NEEDED = frozenset((LimitKind.POSITION_MIN, LimitKind.POSITION_MAX, LimitKind.MAX_TORQUE, LimitKind.MAX_MOTOR_SPEED))


@dataclass(frozen=True, slots=True)
class StaleLimit:
    """The freshness limit in force: SYNC cycles without a complete sample that are still fresh.

    Attributes
    ----------
    cycles : int
        A gap of more missed SYNC cycles than this is stale.
    ms : float
        The same as a time [ms] (``cycles`` is ``floor(ms / T)``).
    derived : bool
        True: the drives keep their limits, the stall budget applies; False: today's short limit.
    why : str
        Which term set it (for the record and the violation's text).
    """

    cycles: int
    ms: float
    derived: bool
    why: str

    @property
    def name(self) -> str:
        """The profile key of the limit in force (the supervisor's violation names it)."""
        return "max_stale_ms" if self.derived else "max_stale_cycles"


def _short(act: Actuation, safety: Safety, why: str) -> StaleLimit:
    n = min(safety.max_stale_cycles, HARD_MAX_STALE_CYCLES)
    return StaleLimit(n, n * act.timing.sync_period_s * 1000.0, False, why)


def stale_limit(act: Actuation, safety: Safety, kept: Sequence[Collection[LimitKind]] | None) -> StaleLimit:
    """The freshness limit for drives that keep ``kept`` themselves (per EMA the limits written to the drive
    and read back; None: not known, e.g. before the preflight), see the module docstring."""
    if kept is None:
        return _short(act, safety, "the limits the drives keep are not known")
    for ema, limits in enumerate(kept, start=1):
        missing = NEEDED - set(limits)
        if missing:
            names = ", ".join(sorted(k.value for k in missing))
            return _short(act, safety, f"EMA {ema} does not keep {names} itself")
    T_ms = act.timing.sync_period_s * 1000.0
    c = act.canopen
    e = min(safety.max_following_error_mm, HARD_MAX_FOLLOWING_ERROR_MM)
    v = min(safety.max_velocity_mm_per_s, HARD_MAX_VELOCITY_MM_PER_S)
    terms = {
        "safety.max_stale_ms": safety.max_stale_ms,
        "HARD_MAX_STALE_MS": HARD_MAX_STALE_MS,
        "max_following_error_mm / max_velocity_mm_per_s": 1000.0 * e / v,
        "consumer heartbeat - master heartbeat period - 2 SYNC periods":
            c.master_consumer_time_s * 1000.0 - c.master_heartbeat_period_s * 1000.0 - 2.0 * T_ms,
    }
    why = min(terms, key=terms.__getitem__)
    ms = terms[why]
    cycles = max(0, math.floor(ms / T_ms + 1e-9))
    return StaleLimit(cycles, cycles * T_ms, True, f"{why} = {ms:g} ms")
