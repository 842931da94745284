"""The records the steps of the diagnosis (:func:`blf.diagnose.engine.diagnose`) hand on: one frozen
dataclass per step result (the module docstring of :mod:`blf.diagnose.engine` lists them by step).

Pure: frozen dataclasses, no IO.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from blf.diagnose.band import Band
from blf.diagnose.fit import CandidateFit, JointFit, Problem, Projector
from blf.diagnose.model import Candidate, DiagnoseConfig, DiagnosisVerdict, Reference, ReplayModel, place_of

__all__ = ["Comparison", "NominalFit", "NoiseFloor", "TestFrame", "ChannelTests", "Standing", "Screened",
           "Screening", "Refit", "Accepted", "Selection", "NamedReference", "ResidualRms", "Verdict"]


@dataclass(frozen=True)
class Comparison:
    """Step 0, the band: the recording as the diagnosis compares it.

    ``problem`` (:class:`blf.diagnose.fit.Problem`) holds the kept samples of the band, the fit and
    held-out halves, the validity per channel and the noise floors (set by steps 1 and 2);
    ``places`` the model's own channel -> place map (:func:`place_of` where it has none)."""

    model: ReplayModel = field(repr=False)
    cfg: DiagnoseConfig
    band: Band
    problem: Problem = field(repr=False)
    places: dict

    def place(self, channel: str) -> str:
        """The place a channel belongs to (the model's map, else :func:`place_of`)."""
        return self.places.get(channel) or place_of(channel)

    def full(self, channels: dict) -> dict:
        """The model's channels and the signals it derives from them (reported, not fitted)."""
        derive = getattr(self.model, "derived", None)
        return {**channels, **derive(channels)} if derive else dict(channels)


@dataclass(frozen=True)
class NominalFit:
    """Step 1: the nominal parameters fitted on the fit half (model units, the order of
    ``model.nominal``) and the model's channels at them."""

    theta: np.ndarray
    predicted: dict = field(repr=False)


@dataclass(frozen=True)
class NoiseFloor:
    """Step 2: the reported channels (the model's, then the derived ones), the recording and the
    nominal model over them, and the RMS noise floor per channel in the band and raw (None where no
    sample is compared)."""

    channels: tuple
    measured: dict = field(repr=False)
    predicted: dict = field(repr=False)
    in_band: dict = field(default_factory=dict)
    raw: dict = field(default_factory=dict)


@dataclass(frozen=True)
class TestFrame:
    """Step 3's frame over the kept samples: ``n_window`` samples per window of the window test,
    ``rho`` the square root of the band's ``sum_factor``, the regime cells (index per sample, a
    label per cell), the regime variables (for the words of a location) and the times (s)."""

    n_window: int
    rho: float
    cells: np.ndarray = field(repr=False)
    labels: tuple = field(repr=False)
    regimes: dict = field(repr=False)
    t_s: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class ChannelTests:
    """Step 3 for one prediction (channels, derived included): per reported channel the band
    residual in noise sigmas scaled for the window sums (``weighted``), the window excess E and the
    regime test (:class:`blf.diagnose.mismatch.RegimeScore`)."""

    predicted: dict = field(repr=False)
    weighted: dict = field(repr=False)
    excess: dict = field(default_factory=dict)
    regime: dict = field(default_factory=dict)

    @property
    def regime_score(self) -> dict:
        """Regime-test score S per channel."""
        return {c: r.score for c, r in self.regime.items()}


@dataclass(frozen=True)
class Standing:
    """The model at the start of a round of forward selection: nominal parameters, accepted terms
    [(Candidate, parameters)], chi-square on each half, the linear re-adjustment of the nominal about
    them (``projector``) and the fit half's weighted residual before (``weighted_fit``) and after
    (``residual_fit``) that re-adjustment."""

    theta: np.ndarray
    active: tuple
    chi2_fit: float
    chi2_holdout: float
    projector: Projector = field(repr=False)
    residual_fit: np.ndarray = field(repr=False)
    weighted_fit: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class Screened:
    """Step 4, one candidate: the chi-square it removes on the fit half (linearised, the nominal
    re-adjusted) and that less its BIC penalty (``gain``; refitted while above ``bic_margin``)."""

    candidate: Candidate
    delta_chi2: float
    gain: float


@dataclass(frozen=True)
class Screening:
    """Step 4, one round: the candidates best first, the BIC penalty of each (:math:`k \\ln N_j`)
    and the round's entry of :attr:`blf.diagnose.model.Diagnosis.screening`."""

    ranked: tuple
    penalty: dict
    log: list


@dataclass(frozen=True)
class Refit:
    """Step 5, one candidate refitted (:class:`blf.diagnose.fit.CandidateFit`), judged on the
    linearisation: BIC change on the fit half and chi-square change on the held-out half."""

    delta_bic: float
    delta_chi2_holdout: float
    candidate: Candidate
    fit: CandidateFit


@dataclass(frozen=True)
class Accepted:
    """Steps 5 and 6 (the place), one round: the candidate taken, its BIC change on the fit half and
    chi-square change on the held-out half, and the exact fit (nominal and candidate) they are of."""

    candidate: Candidate
    delta_bic: float
    delta_chi2_holdout: float
    fit: JointFit


@dataclass(frozen=True)
class Selection:
    """Steps 4-6 over every round: the nominal parameters and accepted terms at the end, the library
    effects named, the screening of each round (:attr:`blf.diagnose.model.Diagnosis.screening`), and the BIC of the
    nominal fit and of the final model."""

    theta: np.ndarray
    active: tuple
    effects: tuple
    screening: tuple
    ic_before: float
    ic_after: float


@dataclass(frozen=True)
class NamedReference:
    """A nominal parameter named because it is off its reference: its value and standard
    uncertainty, and what holding it at the reference costs in chi-square on each half."""

    reference: Reference
    value: float
    uncertainty: float
    delta_chi2_fit: float
    delta_chi2_holdout: float


@dataclass(frozen=True)
class ResidualRms:
    """RMS residual per reported channel of one prediction: in the band over the kept samples (whole,
    held-out half) and in the raw band (whole, held-out half); None where no sample is compared."""

    in_band: dict
    in_band_holdout: dict
    raw: dict
    raw_holdout: dict


@dataclass(frozen=True)
class Verdict:
    """Step 7: the verdict, and where it is ``unexplained`` the locations and the places where the
    rest lies (best first)."""

    verdict: DiagnosisVerdict
    locations: tuple = ()
    where: tuple = ()
