r"""A motion profile's own time (pure): the samples' clock less the periods that brought no sample.

A profile (the check's steps, the commissioning's stages, the force-free jog) is a function of the time since
its step began. After periods without a sample (the master's PC held its loop, or the drives' answers were
lost), the samples' clock jumps by the periods missed; a profile read on that clock would jump too: its next
setpoint a step of :math:`v L` from the last at speed :math:`v` after a hold of :math:`L`, a motion the stall
did not make (0.04 mm at 0.5 mm/s after 80 ms; in a loaded two-process commissioning such a leap in the
force-free jog was followed by +214 N on one load cell of a clean rig). The drives held the last setpoint, so
the profile resumes where it was: a sample more than 1.5 periods after the last (a gap of two periods or
more, rounded to the nearest period) adds the time beyond one period to the time held,

.. math::

    \tau = t - t_0 - \sum_{t_k - t_{k-1} > 1.5 T} (t_k - t_{k-1} - T)

with :math:`t_0` the step's start. A sample within 1.5 periods of the last (a SYNC's jitter) holds nothing.
"""

from __future__ import annotations

import math

__all__ = ["ProfileClock"]


class ProfileClock:
    """The profile time of one step at a time (module docstring).

    Parameters
    ----------
    period_s : float
        The SYNC period :math:`T` [s], finite and > 0.
    """

    def __init__(self, period_s: float) -> None:
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"period_s must be finite and > 0 [s], got {period_s!r}")
        self.T = period_s
        self.t0_s = 0.0  #: the step's start, on the samples' clock [s]
        self.held_s = 0.0  #: the time held since the step's start [s]
        self._last: float | None = None

    def restart(self, t_s: float) -> None:
        """A new step begins at ``t_s`` [s] (on the samples' clock): its profile time starts at 0."""
        self.t0_s = t_s
        self.held_s = 0.0

    def elapsed(self, t_s: float) -> float:
        """The sample at ``t_s`` [s] in, the step's profile time :math:`\\tau` out [s] (call once per sample)."""
        last = self._last
        if last is not None and t_s - last > 1.5 * self.T:
            self.held_s += t_s - last - self.T
        self._last = t_s
        return t_s - self.t0_s - self.held_s
