r"""The commissioning's findings explained jointly (pure): hypotheses about the rig, each tried against every
observation, the simplest that explains them all accepted (docs/commission.md, "One cause, several symptoms").

A rig engineer who sees both LVDTs read 1.34 and 1.22 mm per mm and both load cells 0.78 of the torque does not
change four scalings: one number, the gear ratio, explains all four. This module does that reasoning on the
commissioning's measurements (:func:`observe`: typed :class:`Observation` s from
:attr:`hil.master.commission.Commission.measured`) and returns typed results (:func:`explain`).

The model of the rig
--------------------
Each measured gain is predicted from a few causes, every one a single mistake in the profile or the wiring:

.. math::

    g^{\mathrm{LVDT}}_a = \sigma_a\, m_a\, c, \qquad
    g^{\mathrm{F}}_{a,j} = w_{a,j}\, \sigma_a\, m_a / c, \qquad
    r_a = m_a\, d

with :math:`c` the profile's gear ratio over the rig's (``mechanics.i_total_rad_per_mm``: the master commands
:math:`c` times the stroke it means, and a torque :math:`1/c` times the force), :math:`\sigma_a = \pm 1` a
channel's sign, :math:`m_a` its scale (a power of ten for a unit error), :math:`w_{a,j} = +1` for the pushing
drive's own load cell and :math:`-1` for the other (on a free surface the two forces cancel; a swap of the load
cells flips both), :math:`r_a` a channel's noise at rest over the declared one and :math:`d` a wrong declared
noise. A swap of the LVDTs shows only in which LVDT follows the motor in the force steps.

The causes (:class:`CauseKind`): the gear ratio (free value), a channel's sign (no free value), a unit error
(a power of ten: no free value), a channel's scale (free), the LVDTs swapped, the load cells swapped, a
declared noise (free). A hypothesis is a set of causes; its free values are fitted to the observations, then
every observation must lie within its tolerance of the prediction (the rules' own tolerances:
``HARD_LVDT_GAIN_TOLERANCE``, ``FORCE_GAIN_TOLERANCE``, ``NOISE_FACTOR``). Hypotheses are tried simplest first:
fewer causes, then fewer free values (a value that is fitted explains anything it touches; a unit error or a
swap is a stronger statement), then the smaller normalised residual. The first that explains everything is
accepted; any other of the same simplicity that explains everything too is listed as *as good* (the rig
cannot tell them apart: the text says so).

What the commissioning does not model (a dead input, a scan or preflight problem, the drill, a load cell's
offset, a stop at a limit, a rig without CST) passes through unchanged.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

from hil.master.commission_rules import (
    FORCE_GAIN_TOLERANCE,
    MIN_STEP_MOTION_MM,
    NOISE_FACTOR,
    Finding,
    Kind,
    Stage,
)
from hil.profile.config import HARD_LVDT_GAIN_TOLERANCE

__all__ = ["MAX_CAUSES", "UNIT_NOISE_BAND", "Cause", "CauseKind", "Explanation", "Hypothesis", "Observation",
           "ObsKind", "explain", "observe"]

#: At most this many causes in one hypothesis (four would be each of four gains on its own).
MAX_CAUSES = 3
#: A noise at rest of :math:`10^k` times the declared (k >= 1) within this factor proposes a unit error: a
#: sensor as noisy as declared (the clean simulated rig: 1.04 and 0.96 of it) read in the wrong unit. A factor
#: 2 keeps the bands of 10, 100 and 1000 ([5, 20], [50, 200], [500, 2000]) apart from each other and from the
#: healthy one (at most ``NOISE_FACTOR`` = 4); a noise between them is a noisier sensor, no unit fits.
UNIT_NOISE_BAND = 2.0
#: Powers of ten tried as unit errors (mm vs um, N vs kN, ...).
UNIT_POWERS = (-3, -2, -1, 1, 2, 3)


class ObsKind(Enum):
    """What an observation is."""

    LVDT_GAIN = "LVDT gain"  #: mm of LVDT per mm of motor travel over the gear ratio, its own EMA moving
    FORCE_GAIN = "load-cell gain"  #: load-cell change per change of the pushing drive's force
    FOLLOWS = "LVDT follows"  #: in EMA j's force step the other LVDT moved more than LVDT j (1) or not (0)
    NOISE = "noise at rest"  #: noise at rest over the declared one
    LEVEL = "LVDT at rest"  #: an LVDT's mean at rest [mm]


@dataclass(frozen=True, slots=True)
class Observation:
    """One measurement the hypotheses must explain.

    ``sensor`` is ``"lvdt"`` or ``"force"``, ``ema`` the channel's EMA, ``mover`` the EMA that moved or
    pushed (0 at rest). ``measured`` in ``unit``; ``se`` its standard error (NaN: not estimated);
    ``tolerance`` the rule's: relative for the gains, a factor for the noise, a bound for a level."""

    kind: ObsKind
    sensor: str
    ema: int
    mover: int
    measured: float
    tolerance: float
    unit: str
    key: str
    se: float = math.nan

    @property
    def name(self) -> str:
        who = f"{self.sensor.replace('force', 'load cell').replace('lvdt', 'LVDT')} {self.ema}"
        if self.kind is ObsKind.FOLLOWS:
            return f"in EMA {self.mover}'s force step, the other LVDT moved more than LVDT {self.ema} (1 yes, 0 no)"
        verb = "pushing" if self.kind is ObsKind.FORCE_GAIN else "moving"
        return f"{self.kind.value} of {who}" + (f", EMA {self.mover} {verb}" if self.mover else "")

    def as_json(self) -> dict:
        return {"kind": self.kind.value, "sensor": self.sensor, "ema": self.ema, "mover": self.mover,
                "measured": self.measured, "se": None if math.isnan(self.se) else self.se,
                "tolerance": self.tolerance, "unit": self.unit, "key": self.key}


class CauseKind(Enum):
    """One mistake in the profile or the wiring."""

    GEAR = "gear ratio"
    SIGN = "sign"
    UNIT = "unit error"
    SCALE = "scale"
    LVDTS_SWAPPED = "LVDTs swapped"
    LOADCELLS_SWAPPED = "load cells swapped"
    NOISE = "declared noise"


#: free values of each kind of cause (0: the cause is a fixed statement)
_FREE = {CauseKind.GEAR: 1, CauseKind.SCALE: 1, CauseKind.NOISE: 1}


@dataclass(frozen=True, slots=True)
class Cause:
    """A cause: its kind, the channel (``sensor``, ``ema``; none for the gear ratio and the swaps) and, for a
    unit error, the power of ten :math:`k` (the reading is :math:`10^k` times the truth)."""

    kind: CauseKind
    sensor: str = ""
    ema: int = 0
    power: int = 0

    @property
    def label(self) -> str:
        if self.kind is CauseKind.UNIT:
            return f"{self.sensor} {self.ema}: unit error x10^{self.power}"
        if self.kind is CauseKind.NOISE:
            return f"{self.sensor}: {self.kind.value}"
        if self.sensor:
            return f"{self.sensor} {self.ema}: {self.kind.value}"
        return self.kind.value


@dataclass(frozen=True, slots=True)
class Hypothesis:
    """A set of causes tried: its fitted values, each observation's prediction, and the verdict.

    ``status``: ``"accepted"``, ``"as good"`` (explains everything as simply as the accepted one),
    ``"explains, less simple"`` or ``"rejected"``; ``why`` says which observation refused it, or that it
    explains every one."""

    causes: tuple[Cause, ...]
    fitted: dict
    predicted: tuple[float, ...]
    explains: bool
    score: float
    why: str
    status: str = "rejected"

    @property
    def label(self) -> str:
        return " + ".join(c.label for c in self.causes) or "the profile as it is"

    @property
    def simplicity(self) -> tuple[int, int]:
        return len(self.causes), sum(_FREE.get(c.kind, 0) for c in self.causes)

    def as_json(self) -> dict:
        return {"hypothesis": self.label, "causes": len(self.causes), "free_values": self.simplicity[1],
                "fitted": self.fitted, "explains_all": self.explains, "residual_score": self.score,
                "status": self.status, "why": self.why}


@dataclass(frozen=True)
class Explanation:
    """What :func:`explain` returns: the observations, every hypothesis tried (simplest first), the accepted
    one (None: no observation to explain, or none explains them all), and the findings with the ones it
    explains replaced by one per cause."""

    observations: tuple[Observation, ...]
    tried: tuple[Hypothesis, ...]
    accepted: Hypothesis | None
    findings: tuple[Finding, ...]
    patch: dict = field(default_factory=dict)  #: dotted profile key -> value that makes the rig ready
    wiring: tuple[str, ...] = ()  #: fixes the profile cannot express (a swap of wires)

    def as_json(self) -> dict:
        return {"observations": [o.as_json() for o in self.observations],
                "tried": [h.as_json() for h in self.tried],
                "accepted": None if self.accepted is None else self.accepted.label,
                "patch": self.patch, "wiring_fixes": list(self.wiring)}


# ------------------------------------------------------------------ observations


def observe(measured: dict, findings, *, keys: dict, declared: dict, stroke_mm: float) -> tuple[Observation, ...]:
    """The observations in the commissioning's ``measured`` (see :class:`~hil.master.commission.Commission`).

    ``keys``: ``(sensor, ema) -> profile key`` of the channel (``signals.ema1.lvdt``); ``declared``: the
    declared noise per sensor (``{"lvdt": pp [mm], "force": std [N]}``); ``stroke_mm``: the LVDT's range at
    rest [mm]. At rest only the channels with a noise or range finding are observed there (a stop at rest
    leaves nothing else); in motion every gain is."""
    obs = []
    se = measured.get("gain_se", {})
    for name, gains in (measured.get("lvdt_gain") or {}).items():
        a = int(name[3])
        if f"ema{a}" in gains:  # each LVDT judged while its own motor moved
            obs.append(Observation(ObsKind.LVDT_GAIN, "lvdt", a, a, gains[f"ema{a}"], HARD_LVDT_GAIN_TOLERANCE,
                                   "mm/mm", keys[("lvdt", a)], se.get(f"lvdt{a}_ema{a}_moving", math.nan)))
    for name, gains in (measured.get("loadcell_gain") or {}).items():
        j = int(name[3])
        for e, g in sorted(gains.items()):
            a = int(e[3])
            obs.append(Observation(ObsKind.FORCE_GAIN, "force", a, j, g, FORCE_GAIN_TOLERANCE, "N/N",
                                   keys[("force", a)], se.get(f"force{a}_ema{j}_pushing", math.nan)))
    for name, f in (measured.get("lvdt_follows") or {}).items():
        j = int(name[3])
        if abs(f["motor_mm"]) < MIN_STEP_MOTION_MM:
            continue
        g = {a: abs((measured["lvdt_gain"].get(f"ema{a}_moving") or {}).get(f"ema{a}") or 1.0) for a in (1, 2)}
        other = abs(f[f"lvdt{3 - j}_mm"]) / g[3 - j] > abs(f[f"lvdt{j}_mm"]) / g[j]
        obs.append(Observation(ObsKind.FOLLOWS, "lvdt", j, j, float(other), 0.0, "", keys[("lvdt", j)]))
    flagged = {(f.key, f.kind) for f in findings}
    rest = measured.get("at_rest") or {}
    for sensor, sym, stat in (("lvdt", "s", "ptp"), ("force", "F", "std")):
        for a in (1, 2):
            x = rest.get(f"{sym}{a}")
            if x is None:
                continue
            decl_key = "sensors.lvdt_noise_pp_mm" if sensor == "lvdt" else "sensors.loadcell_noise_std_N"
            r = x[stat] / declared[sensor]
            if r > NOISE_FACTOR and (decl_key, Kind.NOISE) in flagged:
                obs.append(Observation(ObsKind.NOISE, sensor, a, 0, r, NOISE_FACTOR, "x declared",
                                       keys[(sensor, a)]))
            if sensor == "lvdt" and (keys[(sensor, a)], Kind.RANGE) in flagged:
                obs.append(Observation(ObsKind.LEVEL, sensor, a, 0, x["mean"], stroke_mm, "mm", keys[(sensor, a)]))
    return tuple(obs)


# ------------------------------------------------------------------ candidates and predictions


def _candidates(obs: tuple[Observation, ...]) -> list[Cause]:
    """The causes worth trying: each suggested by at least one observation outside its tolerance."""
    out: list[Cause] = []
    gains = [o for o in obs if o.kind in (ObsKind.LVDT_GAIN, ObsKind.FORCE_GAIN)]
    off = [o for o in gains if abs(o.measured / _want(o) - 1.0) > o.tolerance]
    if off and any(o.kind is ObsKind.LVDT_GAIN for o in gains):
        out.append(Cause(CauseKind.GEAR))
    for o in off:
        rel = o.measured / _want(o)
        if rel < 0:
            out.append(Cause(CauseKind.SIGN, o.sensor, o.ema))
        k = round(math.log10(abs(rel))) if rel else 0
        if k and k in UNIT_POWERS:
            out.append(Cause(CauseKind.UNIT, o.sensor, o.ema, k))
        out.append(Cause(CauseKind.SCALE, o.sensor, o.ema))
    for o in obs:
        if o.kind is ObsKind.NOISE:
            out += [Cause(CauseKind.UNIT, o.sensor, o.ema, k) for k in UNIT_POWERS
                    if k > 0 and 1.0 / UNIT_NOISE_BAND <= o.measured / 10.0 ** k <= UNIT_NOISE_BAND]
            out.append(Cause(CauseKind.NOISE, o.sensor))
    if any(o.kind is ObsKind.FOLLOWS and o.measured for o in obs):
        out.append(Cause(CauseKind.LVDTS_SWAPPED))
    if sum(1 for o in off if o.kind is ObsKind.FORCE_GAIN and o.measured / _want(o) < 0) >= 2:
        out.append(Cause(CauseKind.LOADCELLS_SWAPPED))
    return list(dict.fromkeys(out))


def _want(o: Observation) -> float:
    """The expected gain: +1, or -1 for the load cell of the EMA that did not push."""
    return -1.0 if o.kind is ObsKind.FORCE_GAIN and o.ema != o.mover else 1.0


def _consistent(causes: tuple[Cause, ...]) -> bool:
    """At most one scale (a unit error or a scale) and one sign per channel, one declared noise per sensor."""
    seen = set()
    for c in causes:
        slot = ("scale" if c.kind in (CauseKind.UNIT, CauseKind.SCALE) else c.kind.value, c.sensor, c.ema)
        if slot in seen:
            return False
        seen.add(slot)
    return True


def _fixed(causes, o: Observation) -> float:
    """The prediction of ``o`` by the hypothesis' causes without free values (the gain's sign and powers of ten,
    a swap)."""
    p = _want(o)
    for c in causes:
        mine = c.sensor == o.sensor and c.ema == o.ema
        if c.kind is CauseKind.SIGN and mine and o.kind in (ObsKind.LVDT_GAIN, ObsKind.FORCE_GAIN):
            p = -p
        elif c.kind is CauseKind.UNIT and mine:
            p *= 10.0 ** c.power
        elif c.kind is CauseKind.LOADCELLS_SWAPPED and o.kind is ObsKind.FORCE_GAIN:
            p = -p
    return p


def _fit(causes: tuple[Cause, ...], obs: tuple[Observation, ...]) -> tuple[dict, list[float]]:
    """The free values fitted (in log space: the mean log ratio of the observations each one alone scales) and
    every observation's prediction."""
    fitted: dict = {}
    pred = [_fixed(causes, o) for o in obs]
    gains = [i for i, o in enumerate(obs) if o.kind in (ObsKind.LVDT_GAIN, ObsKind.FORCE_GAIN)]
    scaled = {(c.sensor, c.ema) for c in causes if c.kind is CauseKind.SCALE}
    if any(c.kind is CauseKind.GEAR for c in causes):
        logs = [(1 if obs[i].kind is ObsKind.LVDT_GAIN else -1) * math.log(abs(obs[i].measured / pred[i]))
                for i in gains if (obs[i].sensor, obs[i].ema) not in scaled and obs[i].measured * pred[i] > 0]
        c = math.exp(sum(logs) / len(logs)) if logs else 1.0
        fitted["gear_factor"] = c
        if math.isfinite(se := _log_mean_se(logs)):  # (JSON has no NaN: absent where not estimated)
            fitted["gear_factor_se"] = c * se
        for i in gains:
            pred[i] *= c if obs[i].kind is ObsKind.LVDT_GAIN else 1.0 / c
    for s, a in sorted(scaled):
        mine = [i for i in gains if (obs[i].sensor, obs[i].ema) == (s, a) and obs[i].measured * pred[i] > 0]
        m = math.exp(sum(math.log(obs[i].measured / pred[i]) for i in mine) / len(mine)) if mine else 1.0
        fitted[f"{s}{a}_scale"] = m
        for i, o in enumerate(obs):
            if (o.sensor, o.ema) == (s, a) and o.kind in (ObsKind.LVDT_GAIN, ObsKind.FORCE_GAIN, ObsKind.NOISE):
                pred[i] *= m
    for c in causes:
        if c.kind is CauseKind.NOISE:
            mine = [i for i, o in enumerate(obs) if o.kind is ObsKind.NOISE and o.sensor == c.sensor]
            d = max((obs[i].measured / (abs(pred[i]) * NOISE_FACTOR) for i in mine), default=1.0)
            d = max(1.0, d) * (1.0 + 1e-9)  # (the noisiest then exactly at NOISE_FACTOR, not above by rounding)
            fitted[f"{c.sensor}_noise_factor"] = d
            for i in mine:
                pred[i] *= d
    for i, o in enumerate(obs):
        if o.kind is ObsKind.FOLLOWS:
            pred[i] = float(any(c.kind is CauseKind.LVDTS_SWAPPED for c in causes))
        elif o.kind is ObsKind.NOISE:
            pred[i] = abs(pred[i])
        elif o.kind is ObsKind.LEVEL:
            pred[i] = abs(_fixed(causes, o)) * fitted.get(f"{o.sensor}{o.ema}_scale", 1.0)
    return fitted, pred


def _log_mean_se(logs: list[float]) -> float:
    r"""The standard error of the mean of ``logs`` (the gains' log ratios a gear factor :math:`c` is fitted to):
    :math:`s / \sqrt{n}` with :math:`s` their sample standard deviation, so :math:`\mathrm{SE}(c) \approx c\,
    s/\sqrt{n}` (delta method). The gains' spread (each LVDT's pitch error, the load cells' torque constant) is
    what one factor cannot explain: it, not each regression's own tiny standard error, bounds the fit. NaN for
    fewer than two."""
    n = len(logs)
    if n < 2:
        return math.nan
    m = sum(logs) / n
    return math.sqrt(sum((x - m) ** 2 for x in logs) / (n - 1) / n)


def _judge(o: Observation, p: float) -> tuple[bool, float]:
    """Whether prediction ``p`` explains ``o``, and its residual in units of the tolerance."""
    if o.kind is ObsKind.FOLLOWS:
        return o.measured == p, abs(o.measured - p)
    if o.kind is ObsKind.NOISE:  # the noise over the predicted factor must be within NOISE_FACTOR
        r = o.measured / p
        return r <= o.tolerance, max(0.0, math.log(r)) / math.log(o.tolerance)
    if o.kind is ObsKind.LEVEL:  # the mean at rest, read back through the predicted scale, within the range
        r = abs(o.measured) / p / o.tolerance
        return r <= 1.0, r
    r = (o.measured / p - 1.0) / o.tolerance
    return abs(r) <= 1.0, abs(r)


def _try(causes: tuple[Cause, ...], obs: tuple[Observation, ...]) -> Hypothesis:
    fitted, pred = _fit(causes, obs)
    why, score, ok = "explains every observation within its tolerance", 0.0, True
    for o, p in zip(obs, pred, strict=True):
        good, r = _judge(o, p)
        score += r * r
        if not good and ok:
            ok = False
            why = f"{o.name}: measured {o.measured:.4g} {o.unit}, predicted {p:.4g} (tolerance {o.tolerance:g})"
    return Hypothesis(causes, {k: round(v, 6) for k, v in fitted.items()}, tuple(pred), ok, round(score, 4), why)


# ------------------------------------------------------------------ the search


def explain(obs: tuple[Observation, ...], findings, *, scales: dict, i_total: float,
            refuses: Callable[[dict], str | None] | None = None, swaps: dict | None = None) -> Explanation:
    """Every hypothesis tried against ``obs``, the simplest that explains them all accepted, and the findings
    it explains replaced by one per cause (the rest of ``findings`` unchanged).

    Parameters
    ----------
    obs : the observations (:func:`observe`)
    findings : the commissioning's findings
    scales : ``(sensor, ema) -> the profile's scale per raw unit`` (mm or N)
    i_total : the profile's gear ratio [rad/mm]
    refuses : a patch (dotted key -> value) -> why the profile loader refuses it, or None; a cause whose
        patch is refused is named as a wiring fix (never advice the loader would refuse)
    swaps : ``"lvdt"``/``"force"`` -> the patch that swaps the two channels in the signal map
    """
    findings = tuple(findings)
    if not obs or any(f.kind is Kind.SWAPPED and f.key.startswith("canopen.node_id") for f in findings):
        return Explanation(obs, (), None, findings)
    cands = _candidates(obs)
    tried = [_try((), obs)]
    for n in range(1, min(MAX_CAUSES, len(cands)) + 1):
        tried += [_try(c, obs) for c in itertools.combinations(cands, n) if _consistent(c)]
    tried.sort(key=lambda h: (not h.explains, h.simplicity, h.score))
    best = next((h for h in tried if h.explains), None)
    if best is None or not best.causes:
        return Explanation(obs, tuple(_shown(tried, best)), best, findings)
    marked = [_mark(h, best) for h in tried]
    out, patch, wiring = _findings(best, obs, findings, scales, i_total, refuses, swaps or {}, marked)
    return Explanation(obs, tuple(_shown(marked, best)), next(h for h in marked if h.status == "accepted"),
                       out, patch, wiring)


def _mark(h: Hypothesis, best: Hypothesis) -> Hypothesis:
    from dataclasses import replace

    if h is best:
        return replace(h, status="accepted")
    if h.explains:
        return replace(h, status="as good" if h.simplicity == best.simplicity else "explains, less simple")
    return h


def _shown(tried: list[Hypothesis], best: Hypothesis | None) -> list[Hypothesis]:
    """What the report lists: the profile as it is, every single cause, and every hypothesis that explains
    (the accepted, the as good, the less simple up to three), simplest first."""
    out, less = [], 0
    for h in tried:
        if len(h.causes) <= 1 or h.status in ("accepted", "as good"):
            out.append(h)
        elif h.explains and less < 3:
            out.append(h)
            less += 1
    return sorted(out, key=lambda h: (h.simplicity, h.score))


# ------------------------------------------------------------------ the findings of the accepted hypothesis

_UNITS = {"lvdt": {1: "mm vs cm", 2: "a factor 100", 3: "mm vs um"}, "force": {1: "N vs daN", 2: "a factor 100",
                                                                              3: "N vs kN"}}
_EXPLAINED = (Kind.SIGN, Kind.SCALE, Kind.SWAPPED, Kind.NOISE, Kind.RANGE)


def _explained(f: Finding, obs: tuple[Observation, ...]) -> bool:
    """Whether finding ``f`` is one of the symptoms the observations stand for."""
    if f.kind not in _EXPLAINED or f.key.startswith("canopen."):
        return False
    if f.kind is Kind.NOISE:
        return any(o.kind is ObsKind.NOISE for o in obs)
    return any(f.key.startswith(o.key) for o in obs)


def _findings(best, obs, findings, scales, i_total, refuses, swaps, marked):
    """One finding per cause of ``best`` (the original finding kept where it names that cause already), the
    profile patch and the wiring fixes. The patch holds each cause's own value: a sign flipped or a power of
    ten exactly (a pitch error within the tolerance, which the check's calibration corrects, stays out of it;
    a finding's ``fits`` makes the measurement agree exactly), a fitted value where the cause has one."""
    keep = [f for f in findings if not _explained(f, obs)]
    old = {(f.kind, f.key): f for f in findings}
    out, patch, wiring = [], {}, []
    for c in best.causes:
        f, items = _cause_finding(c, best, obs, scales, i_total, swaps, marked)
        f = old.get((f.kind, f.key), f)
        if items:
            why = refuses(patch | items) if refuses is not None else None
            if why is not None:
                why = why.split("(1 problem):;", 1)[-1].strip()
                wiring.append(f"{c.label}: the profile loader refuses the swapped map ({why})")
                f = Finding(f.stage, Kind.WIRING, f.key, f"{f.text}; the signal map cannot express it (the profile "
                            f"loader refuses: {why}): fix the wiring", f.measured, f.unit, None)
                items = {}
        patch |= items
        out.append(f)
    stop = [f for f in keep if f.kind is Kind.STOP]
    return [f for f in keep if f.kind is not Kind.STOP] + out + stop, patch, tuple(wiring)


def _others(c: Cause, marked) -> str:
    """The hypotheses as good as the accepted one (the rig cannot tell them apart)."""
    alts = [h.label for h in marked if h.status == "as good"]
    return f" (as good: {'; '.join(alts)}: these observations cannot tell them apart)" if alts else ""


def _cause_finding(c: Cause, best: Hypothesis, obs, scales, i_total, swaps, marked) -> tuple[Finding, dict]:
    key = next((o.key for o in obs if (o.sensor, o.ema) == (c.sensor, c.ema)), "")
    unit_key = f"{key}.mm_per_unit" if c.sensor == "lvdt" else f"{key}.N_per_unit"
    per = scales.get((c.sensor, c.ema))
    mine = [o for o in obs if (o.sensor, o.ema) == (c.sensor, c.ema)]
    stage = Stage.STEP if any(o.kind is ObsKind.FORCE_GAIN for o in mine) else (
        Stage.MOVE if any(o.kind is ObsKind.LVDT_GAIN for o in mine or obs) else Stage.AT_REST)
    seen = ", ".join(f"{o.name} {o.measured:.4g} {o.unit}" for o in mine)
    alt = _others(c, marked)
    if c.kind is CauseKind.GEAR:
        k = best.fitted["gear_factor"]
        fits = float(f"{i_total / k:.5g}")
        se = fits * best.fitted.get("gear_factor_se", math.nan) / k  # (delta method: SE(i/c) = (i/c) SE(c)/c)
        n = sum(1 for o in obs if o.kind in (ObsKind.LVDT_GAIN, ObsKind.FORCE_GAIN))
        err = f" (standard error {se:.2g} rad/mm, from the {n} gains' spread)" if math.isfinite(se) else ""
        return Finding(stage, Kind.GEAR, "mechanics.i_total_rad_per_mm",
                       f"mechanics.i_total_rad_per_mm: one cause explains all {n} gains: the profile's gear ratio "
                       f"is {k:.3f} times the rig's (both LVDTs read {k:.3f} times the motor travel, both load "
                       f"cells 1/{k:.3f} of the force); fits {fits:.5g} rad/mm{err}{alt}", k, "x", fits), \
            {"mechanics.i_total_rad_per_mm": fits}
    if c.kind is CauseKind.UNIT:
        f10 = 10.0 ** c.power
        fits = float(f"{per / f10:.6g}")
        word = _UNITS[c.sensor][abs(c.power)]
        return Finding(stage, Kind.UNIT, unit_key, f"{key}: reads {f10:g} times the truth: a unit error ({word}); "
                       f"{seen}{alt}", f10, "x", fits), {unit_key: fits}
    if c.kind is CauseKind.SIGN:
        return Finding(stage, Kind.SIGN, unit_key, f"{key}: wrong sign ({seen}){alt}", -1.0, "x", -per), \
            {unit_key: -per}
    if c.kind is CauseKind.SCALE:
        m = best.fitted[f"{c.sensor}{c.ema}_scale"]
        fits = float(f"{per / m:.4g}")
        return Finding(stage, Kind.SCALE, unit_key, f"{key}: reads {m:.3f} times the truth ({seen}){alt}", m, "x",
                       fits), {unit_key: fits}
    if c.kind is CauseKind.NOISE:
        decl = "sensors.lvdt_noise_pp_mm" if c.sensor == "lvdt" else "sensors.loadcell_noise_std_N"
        m = best.fitted[f"{c.sensor}_noise_factor"] * NOISE_FACTOR
        noisy = [o for o in obs if o.kind is ObsKind.NOISE and o.sensor == c.sensor]
        return Finding(Stage.AT_REST, Kind.NOISE, decl, f"{decl}: the sensors are noisier than declared ("
                       + ", ".join(f"{o.name} {o.measured:.3g} x declared" for o in noisy)
                       + f"; no unit error fits: not a power of ten within a factor {UNIT_NOISE_BAND:g}){alt}",
                       m, "x declared"), {}
    sensor = "lvdt" if c.kind is CauseKind.LVDTS_SWAPPED else "force"
    k1, k2 = (next((o.key for o in obs if (o.sensor, o.ema) == (sensor, a)), f"signals.ema{a}.{sensor}")
              for a in (1, 2))
    if c.kind is CauseKind.LVDTS_SWAPPED:
        text = f"{k1} follows EMA 2's motor and {k2} EMA 1's in the force steps: the LVDTs are swapped{alt}"
    else:
        text = (f"{k1} and {k2} each read the other EMA's force: the load cells are swapped{alt}. On this rig the "
                f"surface is free (F1 = -F2 in every step), so both signs wrong read alike; what tells them apart is "
                f"a load on the surface (F1 + F2 not 0), which these moves do not make")
    return Finding(Stage.STEP, Kind.SWAPPED, f"{k1}, {k2}", text, None, "", None), dict(swaps.get(sensor, {}))
