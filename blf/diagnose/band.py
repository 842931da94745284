"""The band a model claims to explain: a zero-phase low-pass and decimation (as IDIM-LS does).

A replay model is compared with its recording in the band its physics
covers (the quasi-static load paths of the dual-EMA replay up to 10 Hz, the
inverse dynamics of a positioning axis up to 20 Hz), not at the full sample
rate: above that band lie the controller's reaction to encoder quantisation,
structural ringing and sensor noise, which the model does not claim and which
would otherwise drown a real improvement. :class:`Band` low-passes a residual
with a zero-phase Butterworth filter (forward and backward, so nothing is
delayed) and keeps every ``step``-th sample, so that the kept samples of
white noise are nearly independent; :meth:`Band.keep` says which kept
samples lie far enough from samples that are not compared (transients) for
the filter not to carry them in.

Pure: arrays and an explicit sample rate in, arrays and a frozen dataclass out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import binary_erosion
from scipy.signal import butter, sosfiltfilt, upfirdn

from blf.validate import count, positive_scalar

__all__ = ["Band", "make_band", "raw_band"]


@dataclass(frozen=True)
class Band:
    """A zero-phase low-pass at ``cutoff_hz`` followed by keeping every ``step``-th sample.

    Attributes
    ----------
    cutoff_hz : float or None
        -3 dB frequency of one pass of the Butterworth filter, Hz (the
        forward-backward filter is -6 dB there); None: no filter (raw band).
    sample_rate_hz : float
        Sample rate of the recording, Hz.
    order : int
        Order of the Butterworth filter.
    step : int
        Decimation: one kept sample per ``step`` samples.
    noise_gain : float
        RMS after the filter of white noise of unit RMS (dimensionless): the
        noise floor in the band is the white-noise floor times this.
    sum_factor : float
        Variance of a sum of n kept samples of filtered white noise over n
        times the variance of one (dimensionless, ~1): the window test divides
        by its square root.
    support : int
        Samples on either side of a kept sample that carry all but 1e-3 of
        its filter weight.
    """

    cutoff_hz: float | None
    sample_rate_hz: float
    order: int
    step: int
    noise_gain: float
    sum_factor: float
    support: int
    _sos: np.ndarray | None = field(default=None, repr=False, compare=False)
    _fir: np.ndarray | None = field(default=None, repr=False, compare=False)  #: impulse response, centred

    @property
    def words(self) -> str:
        """The band in words, for the report."""
        if self.cutoff_hz is None:
            return f"raw: every sample at {self.sample_rate_hz:.4g} Hz"
        return (f"zero-phase Butterworth low-pass of order {self.order} at {self.cutoff_hz:.4g} Hz (forward and "
                f"backward), then every {self.step}th sample ({self.sample_rate_hz / self.step:.4g} Hz)")

    def indices(self, n: int) -> np.ndarray:
        """The kept samples of a recording of ``n`` samples."""
        return np.arange(self.step // 2, n, self.step)

    def lowpass(self, x: np.ndarray) -> np.ndarray:
        """The zero-phase low-pass of ``x`` (same shape; the raw band returns ``x``)."""
        if self._sos is None:
            return np.asarray(x, dtype=float)
        return sosfiltfilt(self._sos, x, padtype="even")

    def reduce(self, x: np.ndarray) -> np.ndarray:
        """Low-pass and keep: the band-limited samples of ``x``, shape (len(indices(n)),).

        The kept samples only are computed (polyphase FIR of the forward-backward
        filter's impulse response, truncated where its tails hold < 1e-6 of its
        weight; the ends mirrored)."""
        x = np.asarray(x, dtype=float)
        if self._fir is None:
            return x[self.indices(x.size)]
        h = self._fir
        S = h.size // 2
        o = self.step // 2
        K = self.indices(x.size).size
        j0 = -(-(S + o) // self.step)
        P = j0 * self.step - S - o
        right = S + 2 * self.step
        xp = np.pad(x, (P, right), mode="reflect") if x.size > max(P, right) else np.pad(x, (P, right), mode="edge")
        return upfirdn(h, xp, 1, self.step)[j0:j0 + K]

    def keep(self, valid: np.ndarray) -> np.ndarray:
        """Kept samples whose filter support lies entirely in ``valid`` (bool, shape of indices(n))."""
        v = np.asarray(valid, dtype=bool)
        if self.support > 0 and v.size:
            v = binary_erosion(v, np.ones(2 * self.support + 1, bool), border_value=1)
        return v[self.indices(v.size)]


def raw_band(sample_rate_hz: float) -> Band:
    """The identity: every sample, no filter."""
    fs = positive_scalar(sample_rate_hz, "sample_rate_hz", "Hz")
    return Band(None, fs, 0, 1, 1.0, 1.0, 0)


def make_band(sample_rate_hz: float, cutoff_hz: float | None, order: int = 4) -> Band:
    """The band of a model: zero-phase Butterworth low-pass and decimation.

    Parameters
    ----------
    sample_rate_hz : float
        Sample rate of the recording, Hz (> 0).
    cutoff_hz : float or None
        Cut-off, Hz, below half the sample rate; None gives :func:`raw_band`.
    order : int, optional
        Butterworth order, 1..8 (default 4).

    Returns
    -------
    Band

    Notes
    -----
    Decimation :math:`k = \\max(1, \\lfloor f_s / (2 f_c) \\rfloor)` (the kept
    rate is twice the cut-off). With :math:`h` the impulse response of the
    forward-backward filter, the noise gain is :math:`\\|h\\|_2` and, for a
    window long against :math:`h`, a sum of :math:`n` kept samples of white
    noise of variance :math:`\\sigma^2` has variance
    :math:`\\sigma^2 n / k = n\\,(\\sigma\\|h\\|_2)^2 \\cdot 1/(k\\|h\\|_2^2)`,
    so ``sum_factor`` is :math:`1/(k\\|h\\|_2^2)`.
    """
    fs = positive_scalar(sample_rate_hz, "sample_rate_hz", "Hz")
    if cutoff_hz is None:
        return raw_band(fs)
    fc = positive_scalar(cutoff_hz, "cutoff_hz", "Hz")
    order = count(order, "order", 1, 8)
    if not fc < 0.45 * fs:
        return raw_band(fs)  # nothing to remove: the whole recorded band is claimed
    sos = butter(order, fc / (0.5 * fs), output="sos")
    n = int(8 * fs / fc) | 1
    imp = np.zeros(n)
    imp[n // 2] = 1.0
    h = sosfiltfilt(sos, imp)
    gain = float(np.sqrt(np.sum(h * h)))
    step = max(1, int(fs // (2.0 * fc)))
    a = np.abs(h)
    tail = np.cumsum(a[::-1])[::-1]  # weight at and beyond each lag, one side
    half = tail[n // 2:] / a.sum()
    support = int(np.argmax(half < 0.5e-3)) if np.any(half < 0.5e-3) else n // 2
    keep = int(np.argmax(half < 1e-6)) if np.any(half < 1e-6) else n // 2
    fir = h[n // 2 - keep: n // 2 + keep + 1].copy()
    return Band(fc, fs, order, step, gain, 1.0 / (step * gain * gain), support, sos, fir)

