"""What the diagnosis (:func:`blf.diagnose.engine.diagnose`) is given and what it gives.

Given: a replay model (:class:`ReplayModel`: the recording, its channels and
their validity, the nominal parameters (:class:`Param`, read by name through
:class:`ParamVector`), the candidate physics terms (:class:`Candidate`) and
the nominal parameters compared with a reference (:class:`Reference`)) and
the tuning (:class:`DiagnoseConfig`). Given back: a :class:`Diagnosis`, its
effects (:class:`FittedEffect`) and locations (:class:`Location`).

Pure: frozen dataclasses, no IO.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from functools import lru_cache
from typing import Protocol

import numpy as np

from blf.diagnose.band import Band
from blf.diagnose.mismatch import RegimeScore
from blf.errors import InputError

__all__ = ["Param", "ParamVector", "Candidate", "Reference", "ReplayModel", "DiagnoseConfig", "Location",
           "FittedEffect", "Diagnosis", "DiagnosisVerdict", "RegimeScore", "NominalCovariance", "EIGEN_FLOOR",
           "place_of"]


class DiagnosisVerdict(StrEnum):
    """What the diagnosis concludes; a ``str`` whose value the diagnosis JSON holds."""

    NO_MISMATCH = "no_mismatch"  #: no significant mismatch between simulation and recording
    EXPLAINED = "explained"  #: the mismatch is explained by the named effects
    UNEXPLAINED = "unexplained"  #: a mismatch the candidate library does not explain


@dataclass(frozen=True)
class Param:
    """One fitted parameter: name (with unit), start value, scale, bounds."""

    name: str
    x0: float
    scale: float
    lo: float = -np.inf
    hi: float = np.inf


@lru_cache(maxsize=64)
def _positions(names: tuple) -> dict:
    return {n: j for j, n in enumerate(names)}


class ParamVector:
    """A parameter vector read by name.

    The diagnosis moves a model's nominal parameters as a plain vector in the order of its
    :class:`Param` tuple; the model reads them by their names (with units), never by position:
    ``ParamVector(names, theta)["lvdt_pitch1"]``.

    Parameters
    ----------
    names : tuple of str
        The parameters' names, in the order of the vector (``tuple(q.name for q in params)``).
    values : array_like, shape (len(names),)
        The values, in each parameter's unit.
    """

    __slots__ = ("_at", "values")

    def __init__(self, names: tuple, values) -> None:
        self._at = _positions(tuple(names))
        self.values = np.asarray(values, dtype=float)
        if self.values.shape != (len(self._at),):
            raise InputError(f"a parameter vector of {len(self._at)} named parameters needs shape "
                             f"({len(self._at)},); got shape {self.values.shape}")

    def __getitem__(self, name: str) -> float:
        """The value of parameter ``name`` as a float (KeyError names an unknown parameter)."""
        return float(self.values[self._at[name]])

    def __contains__(self, name: object) -> bool:
        return name in self._at

    @staticmethod
    def position(names: tuple, name: str) -> int:
        """Where parameter ``name`` sits in the vector of ``names``."""
        return _positions(tuple(names))[name]


@dataclass(frozen=True)
class Candidate:
    """A candidate physics term: machine name, place, engineer's words, parameters; ``variant`` tells
    apart two forms of the same physics at the same place (e.g. friction in the drive or in the load
    path): at most one of them is accepted. ``shape``: the names of parameters that set the term's form,
    not its size (a Stribeck velocity, a time constant): meaningless where the size is 0, so a comparison
    of two recordings holds them at the value of the recording that has the term and compares the size."""

    name: str
    where: str
    words: str
    params: tuple
    variant: str = ""
    shape: tuple = ()


@dataclass(frozen=True)
class Reference:
    """A nominal parameter compared with a reference value; named as effect ``name`` at ``where``
    when it differs significantly. Reported as ``param`` = value - ``offset``."""

    index: int
    value: float
    name: str
    where: str
    words: str
    param: str
    offset: float = 0.0
    #: references with the same ``common`` = (name, where, words, param) that are all named and agree,
    #: relative to their reference values, within 3 combined standard uncertainties are one physics
    #: shared by their places (e.g. both LVDT pitches: the motor-to-ram ratio), named once
    common: tuple = ()


class ReplayModel(Protocol):
    """What :func:`blf.diagnose.engine.diagnose` needs from a model of the recording."""

    t_s: np.ndarray
    channels: tuple
    measured: dict  #: channel -> ndarray (n,)
    valid: dict  #: channel -> bool ndarray (n,), samples where the channel is modelled
    nominal: tuple  #: of Param
    candidates: tuple  #: of Candidate
    regimes: dict  #: regime variable name -> ndarray (n,)

    def predict(self, theta: np.ndarray, active: list) -> dict:
        """Predicted channels for the nominal vector ``theta`` (in the order of ``nominal``; read it by
        name with :class:`ParamVector`) and the active effects [(Candidate, parameters)]."""

    # Optional: ``places`` ({channel: place} where :func:`place_of` would not do), ``band_hz`` (the band
    # the model claims, Hz; None: raw), ``references`` (tuple of
    # Reference), ``derived(channels) -> {name: ndarray}`` and ``derived_valid`` ({name: bool
    # ndarray}): signals computed from the channels (e.g. the paper's D signals), reported
    # (excess, locations, RMS) but not fitted, so nothing is counted twice.


@dataclass(frozen=True)
class DiagnoseConfig:
    """Tuning of :func:`blf.diagnose.engine.diagnose` (seconds, chi-square units)."""

    block_s: float = 2.0
    window_s: float = 1.0
    noise_window_s: float = 0.2
    excess_threshold: float = 3.0
    bic_margin: float = 10.0
    holdout_margin: float = 10.0
    max_effects: int = 3
    refit_top: int = 5
    min_explained_fraction: float = 0.5  #: of each flagged channel's excess above 1, for "explained"
    regime_bins: int = 10  #: position bins of the regime test (x 2 velocity signs x 2 force signs)
    regime_threshold: float = 5.0  #: regime score S above which a channel differs (S ~ N(0, 1) under noise)
    #: forms of one physics at one place whose BIC lies within this of the best are indistinguishable
    #: (Kass and Raftery 1995: a BIC difference below 2 is "not worth more than a bare mention"):
    #: the one with the fewest parameters, then the first in the library, is named
    form_margin: float = 2.0


@dataclass(frozen=True)
class Location:
    channel: str
    t_start_s: float
    t_end_s: float
    regime: str
    score: float
    test: str = "window"  #: "window" (a time window) or "regime" (a regime cell, first to last visit)
    where: str = ""  #: the place the channel belongs to (ema1, ema2, external)


@dataclass(frozen=True)
class FittedEffect:
    name: str
    where: str
    words: str
    parameters: dict
    uncertainty: dict
    delta_bic: float
    delta_chi2_holdout: float
    evidence: str
    source: str = "library"  #: "library" (a candidate term) or "nominal" (a nominal parameter off its reference)
    variant: str = ""  #: the candidate's variant (:class:`Candidate`), e.g. friction in the drive or the load path


@dataclass(frozen=True)
class NominalCovariance:
    """The shape of the nominal parameters' covariance at a fit (:func:`blf.diagnose.covariance.nominal_covariance`).

    ``covariance`` (physical units, in the order of ``names``) is the white-noise one,
    :math:`(J^T J)^{-1}` of the weighted residual: its scale is far below the spread between checks,
    so only its shape is used: ``vif`` (each parameter's variance inflation factor,
    :math:`\\mathrm{VIF}_j = (F_n^{-1})_{jj}` of the information matrix normalised to a unit
    diagonal; :math:`\\sqrt{\\mathrm{VIF}_j}` is how many times the parameter's standard uncertainty
    exceeds what it would be were the others known) and ratios of its entries. A direction the
    recording does not determine at all (eigenvalue of :math:`F_n` below :data:`EIGEN_FLOOR` times the
    largest) is given that floor: its VIF is then about :math:`10^{12}`, not infinite."""

    names: tuple
    covariance: np.ndarray
    vif: np.ndarray

    def index(self, name: str) -> int:
        return self.names.index(name)

    def correlation(self, a: str, b: str) -> float:
        i, j = self.index(a), self.index(b)
        c = self.covariance
        return float(c[i, j] / np.sqrt(c[i, i] * c[j, j]))


#: eigenvalues of the normalised information matrix below this times the largest are taken as this
EIGEN_FLOOR = 1e-12


@dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`blf.diagnose.engine.diagnose` (plain dicts inside: JSON-ready, treat as read-only).

    RMS figures without ``raw`` are in the band (:attr:`band`); ``holdout`` ones
    over the held-out half only (never fitted)."""

    verdict: DiagnosisVerdict
    effects: tuple
    locations: tuple
    where: tuple  #: places of the mismatch left after the effects (unexplained), best first
    band: Band
    residual_rms_before: dict
    residual_rms_after: dict
    residual_rms_holdout_before: dict
    residual_rms_holdout_after: dict
    residual_rms_raw_before: dict
    residual_rms_raw_after: dict
    residual_rms_raw_holdout_before: dict
    residual_rms_raw_holdout_after: dict
    noise_floor: dict  #: in the band
    noise_floor_raw: dict
    excess_before: dict
    excess_after: dict
    ic_before: float
    ic_after: float
    nominal: dict
    screening: tuple
    predicted_before: dict = field(repr=False)
    predicted_after: dict = field(repr=False)
    measured: dict = field(repr=False, default_factory=dict)  #: all reported channels, derived included
    valid: dict = field(repr=False, default_factory=dict)  #: raw samples compared, per channel
    held_out: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, bool))  #: raw samples never fitted
    kept: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, np.int64))  #: kept samples of the band
    kept_valid: dict = field(repr=False, default_factory=dict)  #: per channel, over the kept samples
    regime_cells_before: dict = field(repr=False, default_factory=dict)  #: channel -> RegimeScore (step 3)
    regime_cells_after: dict = field(repr=False, default_factory=dict)
    regime_labels: tuple = ()  #: description of each cell

    @property
    def regime_before(self) -> dict:
        """Regime-test score S per channel after the nominal fit."""
        return {c: r.score for c, r in self.regime_cells_before.items()}

    @property
    def regime_after(self) -> dict:
        """Regime-test score S per channel with the accepted effects."""
        return {c: r.score for c, r in self.regime_cells_after.items()}


def place_of(channel: str) -> str:
    """The place a channel belongs to: ``ema1``/``ema2`` by its number, ``external`` otherwise."""
    if channel.endswith("1"):
        return "ema1"
    if channel.endswith("2"):
        return "ema2"
    return "external"
