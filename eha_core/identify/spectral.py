"""The data's frequency response: ETFE for periodic records, spectral analysis otherwise.

Fig. 12 of the paper draws, next to H_hat (eq. 25) and the linearised H(s)
(eq. 24), the frequency response read off the data themselves. Two classical
non-parametric estimators give it, each valid in its own case
(Ljung, *System Identification: Theory for the User*, 2nd ed., 1999, ch. 6):

* :func:`etfe`, the **empirical transfer function estimate** ``Y(k) / U(k)``
  at the frequencies a *periodic* excitation excites (Ljung sec. 6.3). Over a
  whole number of periods the input has lines at those frequencies only and
  the estimate needs no smoothing.
* :func:`spa`, **spectral analysis** (Blackman & Tukey, *The Measurement of
  Power Spectra*, Dover 1958; Ljung sec. 6.4; MATLAB ``spa``):
  ``G = Phi_yu / Phi_u`` from covariance functions smoothed by a Hann lag
  window, with the asymptotic variance of sec. 6.4 for a confidence band.
  It needs no periodicity, but the window trades resolution for variance.

:func:`data_frequency_response` picks the one the data allow: ETFE when the
record is a whole number (>= 1) of periods of the excitation (the caller
states the period, or a repetition is found in the input), spectral analysis
otherwise. It returns a :class:`DataFrequencyResponse` that says which it did
and why, in one sentence a student can read.

Why the output is prewhitened
-----------------------------
The closed loop of the paper (eq. 24: poles at -385, -44.5 and -0.142 rad/s)
has a time constant of 7 s, longer than most of the 10 s record, and a
magnitude falling by 86 dB from DC to the Nyquist frequency (314 rad/s at
Ts = 0.01 s). A record that does not start and end in the same state adds a
*transient term* to the DFT (``Y(k) = G U(k) + T(k)``, ``T`` a rational
function with G's poles; Ljung sec. 6.3; Pintelon & Schoukens,
*System Identification: A Frequency Domain Approach*, 2nd ed., 2012), and the
slow mode makes ``T`` large exactly where ``G`` is small. Measured on the
linearised plant (noise-free, 1000 samples), the plain ETFE of the paper's
one-period multisine lies 13-20 dB off at high frequency (3 seeds), and a
plain Hann-window spectral estimate (100 lags) of a prbs, rbs or rgs input
10-15 dB off.

Both estimators here therefore work on ``u -> y_F`` with
``y_F(t) = y(t) - a y(t-1)``, ``a`` the output's lag-one autocorrelation
(its first-order autoregression): Blackman & Tukey's prewhitening, applied to
the output only, and the estimate divided by the known
``1 - a exp(-j w Ts)`` afterwards, which gives back G exactly. For the
paper's loop ``a`` lies between 0.991 and 0.9996 (the slow pole is
``exp(-0.142 Ts) = 0.9986``), so in ``G(q) (1 - a q^-1)`` the slow mode is
scaled by less than 0.01: its transient and its long memory all but cancel,
and the response is flat where G falls as 1/w; for a fast plant
``a`` is smaller and the filter gentler (for a first-order lag driven by white
noise it whitens the output exactly). The input is left as it is: filtered
too, it would have little power at low frequency, where the estimate would
then suffer from the input's own leakage. The sample before the record is
taken equal to the first (the system at rest before it starts); a wrong
guess adds a one-sample term, flat in frequency, that the ETFE's transient
removal absorbs and the spectral estimate averages out.

ETFE: the transient removed
---------------------------
What remains of the transient, now the fast modes' only, is a smooth function
of frequency. When the record's first period is used (a record of one
period, as the paper's), :func:`etfe` removes it by the local polynomial method
(Pintelon, Schoukens, Vandersteen & Barbe, "Estimation of nonparametric noise
and FRF models for multivariable systems -- Part I: Theory", *Mech. Syst.
Signal Process.* 24, 2010): around each excited DFT bin ``k``, over
``2 R + 1`` neighbouring bins, ``Y(k + r) = G_k(r) U(k + r) + T_k(r)`` with
``T_k`` a polynomial of degree 2 in ``r`` and ``G_k`` one of degree 2 when the
window holds enough excited bins (a prbs excites them all), of degree 0 when
it holds one (a multisine excites every few bins, and the bins between carry
the transient alone); R = 6. ``G_k(0)`` is the estimate. When the first
period is dropped (two periods or more, the default) the transient has had a
period to decay and the plain ratio is taken: the local polynomial of G
would only add its own bias where G bends within the window.

Spectral analysis: lag window, band, confidence
-----------------------------------------------
Covariances ``R_u(tau) = 1/N sum_t u(t + tau) u(t)`` (likewise ``R_yu``,
``R_y``) for ``|tau| < M``, the Hann lag window ``W(tau) = (1 + cos(pi tau / M)) / 2``
(MATLAB ``spa``'s; Ljung's Table 6.1 calls it Hamming's) and
``Phi(w) = sum W(tau) R(tau) exp(-j w tau)``; means are removed first.

* **Window width.** MATLAB's default ``M = min(N/10, 30)`` resolves no finer
  than ``2 pi / M`` rad/sample, 21 rad/s at Ts = 0.01 s with 30 lags: most of
  the closed loop's dynamics lie below. The default here is ``M = N/10``
  (:data:`LAGS_FRACTION`), e.g. 100 lags and 6.3 rad/s for the paper's 1000
  samples (at least 10 lags for short records): on the linearised plant,
  noise-free, prbs, rbs and rgs inputs of 1000 samples (bands [0, 1] and
  [0, 0.5], 8 seeds) the estimate then lies within 0.7 dB of the
  ZOH-equivalent response over its band (within 0.45 dB at 2000 samples,
  0.4 dB at 4000, the band reaching down to 3.1 and 1.6 rad/s); the
  variance, ``0.75 M / N`` times ``Phi_v / Phi_u``, is 3.3 times that of
  MATLAB's default at N = 1000. The window smooths a resonance narrower than
  its resolution down: more lags sharpen it, at the cost of variance.
* **Band drawn.** From one resolution ``2 pi / (M Ts)`` above the excited
  band's lower edge (above 0 the window would fold the negative frequencies
  in) to its upper edge, less one resolution unless that is the Nyquist
  frequency. The excited band is the caller's (``band``, as idinput's) or
  where the smoothed input spectrum is within 20 dB of its peak.
* **Confidence band.** Ljung sec. 6.4: ``Var G_hat ~ (C_W / N) Phi_v / Phi_u``,
  ``C_W = sum W(tau)^2`` (0.75 M for this window, Ljung's Table 6.1) and
  ``Phi_v = Phi_y - |Phi_yu|^2 / Phi_u``, the part of the output the input
  does not explain. Relative to ``|G_hat|^2`` this is
  ``(C_W / N) (1 / kappa^2 - 1)`` with the coherence
  ``kappa^2 = |Phi_yu|^2 / (Phi_u Phi_y)``, the same for ``u -> y_F`` as for
  ``u -> y``. The error is asymptotically circular complex normal (Ljung
  sec. 6.4), so ``|G - G_hat| <= rho`` with probability ``p`` for
  ``rho = sigma sqrt(-ln(1 - p))`` (1.73 sigma for 95 %), and the magnitude
  band is ``|G_hat| (1 -+ sqrt(-ln(1 - p)) sigma_rel)`` in dB, the lower edge
  ``-inf`` where it reaches 0 (the data cannot tell the response from
  none). This disc is exact for complex normal errors at any coherence,
  and conservative for the magnitude alone; the usual
  ``+- 1.96 sigma_rel / sqrt(2)`` on the log magnitude holds only where
  ``sigma_rel`` is small. Measured on the linearised plant with white output
  noise (rgs and rbs, 1000 samples, 8 seeds, noise 1e-4 to 1e-1 m), this
  band holds the true magnitude at 94-99 % of the frequencies on average,
  the log-magnitude one at 38-96 %, less as the coherence falls. It covers
  random error only: the window's bias (resolution) and a nonlinear
  plant's distortions that correlate with the input are not in it.

Only numpy and scipy are imported here.

Examples
--------
A first-order lag driven by a random binary signal, noise-free: the spectral
estimate (the input does not repeat) follows the ZOH-equivalent response.

>>> import numpy as np
>>> from eha_core.excitation import idinput
>>> from eha_core.identify._ctmodels import simulate_tf
>>> u = idinput(2000, "rbs", seed=1).u
>>> y = simulate_tf([10.0], [1.0, 10.0], u, 0.01)
>>> fr = data_frequency_response(u, y, 0.01)
>>> fr.method, fr.lags
('spa', 200)
>>> print(fr.description)  # doctest: +NORMALIZE_WHITESPACE
Spectral estimate (Blackman-Tukey, Hann window of 200 lags, 95 % band) from 3.14 to 314 rad/s:
the input does not repeat within the record.
>>> g = np.exp(-0.1)  # the ZOH equivalent: 0.0952 / (z - 0.905)
>>> true = (1 - g) / (np.exp(1j * fr.w * 0.01) - g)
>>> bool(np.max(np.abs(fr.magnitude_db - 20 * np.log10(np.abs(true)))) < 0.2)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal

from .._checks import not_allowed
from ._ctmodels import FrequencyResponseData, as_pair, as_ts, readonly

__all__ = [
    "DataFrequencyResponse",
    "LAGS_FRACTION",
    "SpectralEstimate",
    "data_frequency_response",
    "detect_period",
    "etfe",
    "spa",
]

#: Default lag window width: ``M = N // LAGS_FRACTION`` (MATLAB: ``min(N/10, 30)``), at least
#: ``MIN_LAGS`` (and fewer than the samples) so that a short record still has a band to draw.
LAGS_FRACTION = 10
MIN_LAGS = 10
#: Local polynomial method: half-width R of the window of DFT bins, degree of the polynomials.
LPM_HALF_WIDTH = 6
LPM_DEGREE = 2
#: The shortest period the ETFE takes: 7 DFT bins below the Nyquist frequency for the local polynomials.
ETFE_MIN_PERIOD = 16
#: Relative input level (DFT magnitude) that counts as excited, as etfe_periodic's.
EXCITED_THRESHOLD = 1e-3
#: Detected excited band of the spectral estimate: input spectrum within 20 dB of its peak.
BAND_LEVEL = 1e-2


# ---------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------
class _ReadsResponse:
    """``w``, ``magnitude_db`` and ``phase_deg`` read through from the ``response`` field."""

    response: FrequencyResponseData

    @property
    def w(self) -> np.ndarray:
        return self.response.w

    @property
    def magnitude_db(self) -> np.ndarray:
        return self.response.magnitude_db

    @property
    def phase_deg(self) -> np.ndarray:
        return self.response.phase_deg

    def to_pandas(self):
        """The response as a :class:`pandas.DataFrame` indexed by ``w`` [rad/s]: ``magnitude_db``,
        ``phase_deg``, and where the estimate has them ``lower_db``, ``upper_db`` (its confidence band) and
        ``coherence``."""
        import pandas as pd

        cols = {"magnitude_db": self.magnitude_db, "phase_deg": self.phase_deg}
        for name in ("lower_db", "upper_db", "coherence"):
            values = getattr(self, name, None)
            if values is not None:
                cols[name] = values
        return pd.DataFrame(cols, index=pd.Index(self.w, name="w"))


@dataclass(frozen=True, eq=False)
class SpectralEstimate(_ReadsResponse):
    """A Blackman-Tukey estimate of ``G(exp(j w Ts))`` with its confidence band.

    Attributes
    ----------
    response : FrequencyResponseData
        ``w`` [rad/s], complex ``response``, ``magnitude_db``, ``phase_deg``.
    lower_db, upper_db : numpy.ndarray
        The confidence band on the magnitude [dB]; ``lower_db`` is ``-inf``
        where the band reaches zero magnitude.
    relative_std : numpy.ndarray
        ``sigma_rel``: the standard deviation of ``G_hat`` (``sqrt(E|G_hat - G|^2)``)
        over ``|G_hat|``.
    coherence : numpy.ndarray
        Squared coherence ``kappa^2`` of input and (prewhitened) output, in [0, 1].
    lags : int
        Window width M: lags ``|tau| < M`` are used.
    window_energy : float
        ``C_W = sum W(tau)^2`` (about 0.75 M).
    n_samples : int
        Samples the covariances were computed from (N - 1: one is lost to
        the prewhitening filter).
    band : tuple of float
        ``(w_lo, w_hi)`` [rad/s], the range of ``w``.
    confidence : float
        Level of the band, e.g. 0.95.
    """

    response: FrequencyResponseData
    lower_db: np.ndarray
    upper_db: np.ndarray
    relative_std: np.ndarray
    coherence: np.ndarray
    lags: int
    window_energy: float
    n_samples: int
    band: tuple[float, float]
    confidence: float

    def __repr__(self) -> str:
        lo, hi = self.band
        return (f"SpectralEstimate: Blackman-Tukey (spa), {self.w.size} frequencies in [{lo:.3g}, {hi:.3g}] rad/s, "
                f"window of {self.lags} lags, {self.confidence:.0%} band, {self.n_samples} samples; .to_pandas()")


@dataclass(frozen=True, eq=False)
class DataFrequencyResponse(_ReadsResponse):
    """The data's frequency response as :func:`data_frequency_response` chose to estimate it.

    Attributes
    ----------
    response : FrequencyResponseData
        ``w`` [rad/s], complex ``response``, ``magnitude_db``, ``phase_deg``
        (also readable as ``self.w`` etc.).
    method : str
        ``"etfe"`` or ``"spa"``.
    lower_db, upper_db : numpy.ndarray or None
        The spectral estimate's confidence band on the magnitude [dB]
        (``lower_db`` is ``-inf`` where the band reaches zero magnitude); None
        for the ETFE (whose error on noise-free periodic data is the
        transient's residue, not a random error).
    band : tuple of float
        ``(w_lo, w_hi)`` [rad/s]: the excited frequencies' range (ETFE) or
        the range the window resolves inside the excited band (spa).
    description : str
        One sentence: what was computed and why.
    period : int or None
        Samples per period when the record was found periodic, else the
        period the caller stated (None if none).
    n_periods : int
        Whole periods in the record (0 when not periodic).
    lags : int or None
        The lag window width M (spa only).
    confidence : float or None
        Level of the band (spa only).
    """

    response: FrequencyResponseData
    method: str
    lower_db: np.ndarray | None
    upper_db: np.ndarray | None
    band: tuple[float, float]
    description: str
    period: int | None
    n_periods: int
    lags: int | None = None
    confidence: float | None = None

    def __repr__(self) -> str:
        from .._display import short

        lo, hi = self.band
        return (f"DataFrequencyResponse: {self.method}, {self.w.size} frequencies in [{lo:.3g}, {hi:.3g}] rad/s; "
                f".to_pandas()\n  {short(self.description)}")


# ---------------------------------------------------------------------------
# argument checks
# ---------------------------------------------------------------------------
def _whole_number(name: str, value, low: int, high: int | None = None, what: str = "") -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < low or (
            high is not None and value > high):
        span = f"in [{low}, {high}]" if high is not None else f">= {low}"
        raise not_allowed(name, value, f"must be a whole number {span}{what}")
    return int(value)


def _confidence(value) -> float:
    try:
        level = float(value)
    except (TypeError, ValueError):
        level = math.nan
    if isinstance(value, (bool, np.bool_)) or not 0.0 < level < 1.0:
        raise not_allowed("confidence", value, "must be a probability in (0, 1), e.g. 0.95")
    return level


def _band(value) -> tuple[float, float] | None:
    """idinput's ``[wlow, whigh]`` (fractions of the Nyquist frequency), or None."""
    if value is None:
        return None
    allowed = "need [wlow, whigh] with 0 <= wlow < whigh <= 1 (fractions of the Nyquist frequency), or None"
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise not_allowed("band", value, allowed) from None
    if not 0.0 <= lo < hi <= 1.0:
        raise not_allowed("band", value, allowed)
    return lo, hi


def _varying(u: np.ndarray) -> None:
    if np.ptp(u) == 0.0:
        raise not_allowed("u", u, "the input is constant: it excites no frequency; give a signal that varies")


def _prewhitening(y: np.ndarray) -> float:
    """``a`` of the output's prewhitening filter ``1 - a q^-1``: the lag-one autocorrelation, in (-1, 1)."""
    d = y - y.mean()
    energy = float(np.dot(d, d))
    return float(np.dot(d[1:], d[:-1]) / energy) if energy > 0 else 0.0


def _filtered(y: np.ndarray, a: float) -> np.ndarray:
    """``y(t) - a y(t-1)``, the sample before the record taken equal to the first (at rest)."""
    return y - a * np.concatenate(([y[0]], y[:-1]))


def _unfiltered(g_f: np.ndarray, omega: np.ndarray, a: float) -> np.ndarray:
    """G from the estimate of ``G (1 - a q^-1)``: divide by ``1 - a exp(-j w)`` (w in rad/sample, > 0)."""
    return g_f / (1.0 - a * np.exp(-1j * omega))


# ---------------------------------------------------------------------------
# period
# ---------------------------------------------------------------------------
def _repeats(u: np.ndarray, period: int) -> bool:
    scale = max(float(np.max(np.abs(u))), 1e-300)
    return bool(np.allclose(u[period:], u[:-period], rtol=0.0, atol=1e-9 * scale))


def detect_period(u) -> int | None:
    """The smallest period P >= 2 with which the input repeats at least twice over the record.

    The record must be a whole number (>= 2) of periods: ``u[P:] == u[:-P]``
    (to 1e-9 of the largest ``|u|``) and ``N`` a multiple of ``P``. A record
    of one period cannot be told from a non-periodic one by the signal alone;
    its period has to be stated (``period`` of :func:`data_frequency_response`).

    Parameters
    ----------
    u : array_like, shape (N,)
        Input samples.

    Returns
    -------
    int or None
        P, or None when the input does not repeat within the record.

    Examples
    --------
    >>> detect_period([1.0, 2.0, 0.0] * 4)
    3
    >>> detect_period([1.0, 2.0, 0.0, 1.0, 2.0]) is None
    True
    """
    u_arr, _ = as_pair(u, u, ("u", "u"))
    _varying(u_arr)
    n = u_arr.size
    for p in range(2, n // 2 + 1):
        if n % p == 0 and _repeats(u_arr, p):
            return p
    return None


# ---------------------------------------------------------------------------
# ETFE with the transient removed
# ---------------------------------------------------------------------------
def _excited_bins(u_dft: np.ndarray, period: int, freqs, kmax: int, band) -> np.ndarray:
    """DFT bins 1..kmax of the period that the input excites inside ``band`` (or those of ``freqs``)."""
    if freqs is None:
        bins = np.arange(1, kmax + 1)
        if band is not None:
            x = 2.0 * bins / period   # fractions of the Nyquist frequency
            bins = bins[(x >= band[0] - 1e-9) & (x <= band[1] + 1e-9)]
        mag = np.abs(u_dft[bins])
        if not bins.size or mag.max() == 0:
            raise not_allowed("band", list(band), f"the period of {period} samples has no excited DFT frequency "
                                                  "2 pi k / P inside it")
        return bins[mag > EXCITED_THRESHOLD * mag.max()]
    allowed = (f"must be a 1-D array of frequencies in rad/sample on the period's grid 2 pi k / {period}, "
               f"1 <= k <= {kmax}")
    try:
        omega = np.atleast_1d(np.asarray(freqs, dtype=float))
    except (TypeError, ValueError):
        raise not_allowed("freqs", freqs, allowed) from None
    k = omega * period / (2.0 * np.pi)
    bins = np.rint(k).astype(int) if omega.ndim == 1 and np.all(np.isfinite(k)) else np.zeros(0, int)
    if omega.ndim != 1 or omega.size == 0 or np.any(np.abs(k - bins) > 1e-6) or np.any(
            (bins < 1) | (bins > kmax)):
        raise not_allowed("freqs", omega if omega.ndim == 1 else f"an array of shape {omega.shape}", allowed)
    return np.unique(bins)


def _local_polynomial(u_dft, y_dft, bins, kmax, half_width, degree) -> np.ndarray:
    """``G(k)`` at ``bins``, the transient fitted away over neighbouring bins (Pintelon et al. 2010)."""
    width = 2 * half_width + 1
    excited = np.zeros(kmax + 1, dtype=bool)
    excited[bins] = True
    starts = np.clip(bins - half_width, 1, kmax - width + 1)
    windows = starts[:, None] + np.arange(width)[None, :]              # (K, width)
    r = (windows - bins[:, None]) / half_width                          # scaled offsets, |r| <= 2
    # G's polynomial: degree 2 where the window holds enough excited bins, else a constant
    n_excited = excited[windows].sum(axis=1)
    g_degree = np.minimum(degree, n_excited - 1)
    out = np.empty(bins.size, dtype=complex)
    for d in np.unique(g_degree):
        rows = np.flatnonzero(g_degree == d)
        rr = r[rows]
        a = np.concatenate([u_dft[windows[rows]][:, :, None] * rr[:, :, None] ** np.arange(d + 1),
                            rr[:, :, None].astype(complex) ** np.arange(degree + 1)], axis=2)
        ok = np.all(np.isfinite(a), axis=(1, 2)) & np.all(np.isfinite(y_dft[windows[rows]]), axis=1)
        out[rows] = np.nan                  # a window with a non-finite value: no estimate (and no LAPACK
        if ok.any():                        # complaint on the server's stderr)
            solution = np.linalg.pinv(a[ok]) @ y_dft[windows[rows[ok]]][:, :, None]
            out[rows[ok]] = solution[:, 0, 0]
    return out


def etfe(u, y, period, ts, *, freqs=None, band=None, drop_periods=None,
         remove_transient=None) -> FrequencyResponseData:
    """ETFE of periodic data at the excited frequencies, the start-up transient removed.

    The output is prewhitened, the kept periods averaged, ``Y(k) / U(k)``
    formed at the excited DFT bins, with the transient fitted away by the
    local polynomial method when the first period is used, and the filter
    divided out (module notes). With the paper's one-period multisine on the
    linearised plant it lies within 0.05 dB of the ZOH-equivalent response
    (0.5 dB with a one-period prbs of 1023 samples, at its lowest
    frequencies), where the plain ETFE
    (:func:`eha_core.identify.validate.etfe_periodic`) lies 13 dB off. When
    a period or more is dropped it is the plain ETFE of the prewhitened
    output, which a record in periodic steady state makes exact (the local
    polynomials would then only add their own bias where G bends within a
    window of 13 bins).

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input and output samples; a trailing partial period is ignored.
    period : int
        Samples per period, ``16 <= period <= N``.
    ts : float
        Sampling time [s].
    freqs : array_like, optional
        The excited frequencies in rad/sample, on the grid ``2 pi k / period``
        (an idinput 'sine' excitation's ``freqs``). Default: the bins where
        ``|U| > 1e-3 max |U|`` inside ``band``.
    band : (float, float), optional
        The excitation's design band ``[wlow, whigh]`` in fractions of the
        Nyquist frequency, as idinput's: without ``freqs``, only bins inside
        it count (an 'rbs' also has weak lines outside, where the estimate
        is poor). Default: all.
    drop_periods : int, optional
        Leading periods left out (they carry most of the transient). Default:
        1 when the record holds two periods or more, else 0.
    remove_transient : bool, optional
        Fit the transient away (local polynomial method). Default: when no
        period is dropped.

    Returns
    -------
    FrequencyResponseData
        ``w`` [rad/s], complex ``response``, ``magnitude_db``, ``phase_deg``.

    Examples
    --------
    One period of a multisine into a lag with a 7 s time constant, from rest:
    the transient lasts the whole record, yet the estimate is the ZOH response.

    >>> import numpy as np
    >>> from eha_core.excitation import idinput
    >>> from eha_core.identify._ctmodels import simulate_tf
    >>> exc = idinput([1000, 1, 1], "sine", [0, 1], [-1, 1], [100, 20, 1], seed=0)
    >>> y = simulate_tf([0.15], [1.0, 0.15], exc.u, 0.01)
    >>> fr = etfe(exc.u, y, 1000, 0.01, freqs=exc.freqs)
    >>> g = np.exp(-0.0015)
    >>> true = (1 - g) / (np.exp(1j * fr.w * 0.01) - g)
    >>> def worst_db(fr):
    ...     return round(float(np.max(np.abs(fr.magnitude_db - 20 * np.log10(np.abs(true))))), 2)
    >>> worst_db(fr)  # at the lowest frequency, 0.63 rad/s; 0.005 dB above 1 rad/s
    0.13
    >>> from eha_core.identify.validate import etfe_periodic
    >>> worst_db(etfe_periodic(exc.u, y, 1000, 0.01, freqs=exc.freqs))  # the plain ETFE
    1.77
    """
    u_arr, y_arr = as_pair(u, y, ("u", "y"))
    ts_f = as_ts(ts)
    _varying(u_arr)
    p = _whole_number("period", period, ETFE_MIN_PERIOD, u_arr.size,
                      " (samples per period, at most the record's length)")
    n_periods = u_arr.size // p
    default_drop = 1 if n_periods >= 2 else 0
    drop = _whole_number("drop_periods", default_drop if drop_periods is None else drop_periods, 0,
                         n_periods - 1, f" (the data hold {n_periods} whole periods and at least one must be left)")
    kept = slice(drop * p, n_periods * p)
    a = _prewhitening(y_arr)
    u_avg = u_arr[kept].reshape(-1, p).mean(axis=0)
    yd_avg = _filtered(y_arr, a)[kept].reshape(-1, p).mean(axis=0)
    u_dft = np.fft.rfft(u_avg)
    y_dft = np.fft.rfft(yd_avg)
    kmax = (p - 1) // 2   # the Nyquist bin (even P) is left out: a real line, no neighbour above
    bins = _excited_bins(u_dft, p, freqs, kmax, _band(band))
    if drop == 0 if remove_transient is None else remove_transient:
        half_width = min(LPM_HALF_WIDTH, (kmax - 1) // 2)
        g_d = _local_polynomial(u_dft, y_dft, bins, kmax, half_width, LPM_DEGREE)
    else:
        g_d = y_dft[bins] / u_dft[bins]
    omega = 2.0 * np.pi * bins / p
    return FrequencyResponseData.from_response(omega / ts_f, _unfiltered(g_d, omega, a))


# ---------------------------------------------------------------------------
# spectral analysis
# ---------------------------------------------------------------------------
def _covariances(u: np.ndarray, y: np.ndarray, lags: int):
    """Biased ``R_u, R_yu, R_y`` for ``tau = -(M-1) .. M-1`` (Ljung sec. 6.4)."""
    n = u.size
    tau = np.arange(-lags + 1, lags)

    def cov(a, b):  # 1/N sum_t a(t + tau) b(t)
        return scipy.signal.correlate(a, b, mode="full", method="auto")[n - 1 + tau] / n

    return tau, cov(u, u), cov(y, u), cov(y, y)


def _hann(tau: np.ndarray, lags: int) -> np.ndarray:
    return 0.5 * (1.0 + np.cos(np.pi * tau / lags))


def _spectra(u: np.ndarray, y: np.ndarray, lags: int, omega: np.ndarray):
    """Hann-windowed ``Phi_u, Phi_yu, Phi_y`` at ``omega`` [rad/sample], and ``C_W``."""
    tau, r_u, r_yu, r_y = _covariances(u, y, lags)
    window = _hann(tau, lags)
    lagged = np.stack([window * r_u, window * r_yu, window * r_y])
    spectra = np.empty((3, omega.size), dtype=complex)
    chunk = max(1, 2**18 // tau.size)   # a bounded block of exp(-j w tau) at a time
    for start in range(0, omega.size, chunk):
        kernel = np.exp(-1j * np.outer(omega[start:start + chunk], tau))
        spectra[:, start:start + chunk] = lagged @ kernel.T
    return spectra[0].real, spectra[1], spectra[2].real, float(np.sum(window**2))


def _input_spectrum_grid(u: np.ndarray, lags: int) -> tuple[np.ndarray, np.ndarray]:
    """Hann-windowed ``Phi_u`` on a uniform grid of [0, pi] (one FFT of the windowed covariance)."""
    n = u.size
    r_u = scipy.signal.correlate(u, u, mode="full", method="auto")[n - 1:n - 1 + lags] / n
    n_fft = max(2048, 1 << (2 * lags - 1).bit_length())
    circular = np.zeros(n_fft)
    weighted = _hann(np.arange(lags), lags) * r_u
    circular[:lags] = weighted
    circular[n_fft - lags + 1:] = weighted[:0:-1]   # negative lags, R_u(-tau) = R_u(tau)
    return np.linspace(0.0, np.pi, n_fft // 2 + 1), np.fft.rfft(circular).real


def _spa_band(u: np.ndarray, lags: int, band) -> tuple[float, float]:
    """``(w_lo, w_hi)`` in rad/sample: the excited band less one resolution at each inner edge."""
    resolution = 2.0 * np.pi / lags
    if band is None:
        grid, phi_u = _input_spectrum_grid(u, lags)
        inside = grid[phi_u >= BAND_LEVEL * phi_u.max()]
        edges = (float(inside[0]), float(inside[-1]))
    else:
        edges = (band[0] * np.pi, band[1] * np.pi)
    w_lo = edges[0] + resolution
    w_hi = np.pi if edges[1] >= np.pi * (1.0 - 1e-9) else edges[1] - resolution
    if not w_lo < w_hi:
        raise not_allowed("lags", lags, f"a window of {lags} lags resolves {resolution:.3g} rad/sample, too coarse "
                                        f"for the excited band [{edges[0]:.3g}, {edges[1]:.3g}] rad/sample; "
                                        "use more lags or a longer record")
    return w_lo, w_hi


def spa(u, y, ts, *, lags=None, band=None, n_points: int = 100, confidence: float = 0.95) -> SpectralEstimate:
    """Spectral analysis with a Hann lag window and its confidence band (Ljung sec. 6.4, MATLAB ``spa``).

    ``G = Phi_yu / Phi_u`` for ``u -> y_F``, divided by ``1 - a exp(-j w Ts)``
    (module notes), at ``n_points`` log-spaced frequencies over the band the
    window resolves.

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input and output samples; means are removed.
    ts : float
        Sampling time [s].
    lags : int, optional
        Window width M, ``2 <= M < N - 1``; default ``N // 10``, at least 10
        (module notes).
    band : (float, float), optional
        The excited band ``[wlow, whigh]`` in fractions of the Nyquist
        frequency, as idinput's; default: where the smoothed input spectrum
        is within 20 dB of its peak.
    n_points : int
        Frequencies of the estimate, at least 2.
    confidence : float
        Level of the band on the magnitude, in (0, 1).

    Returns
    -------
    SpectralEstimate

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.identify._ctmodels import simulate_tf
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(4000)
    >>> y = simulate_tf([10.0], [1.0, 10.0], u, 0.01) + 0.05 * rng.standard_normal(4000)
    >>> est = spa(u, y, 0.01, n_points=5)
    >>> est.lags, np.round(est.w, 1)
    (400, array([  1.6,   5.9,  22.2,  83.5, 314.2]))
    >>> bool(np.all(est.lower_db < est.magnitude_db) and np.all(est.magnitude_db < est.upper_db))
    True
    """
    u_arr, y_arr = as_pair(u, y, ("u", "y"))
    ts_f = as_ts(ts)
    _varying(u_arr)
    if u_arr.size < 20:
        raise not_allowed("u", u_arr, f"it has {u_arr.size} samples; spectral analysis needs at least 20")
    # u(t) -> y_F(t), t = 1 .. N-1: the first sample has no predecessor
    a = _prewhitening(y_arr)
    u_t = u_arr[1:] - u_arr[1:].mean()
    yd = _filtered(y_arr, a)[1:]
    yd = yd - yd.mean()
    n = u_t.size
    default = min(max(u_arr.size // LAGS_FRACTION, MIN_LAGS), n - 1)
    m = _whole_number("lags", default if lags is None else lags, 2, n - 1,
                      " (the lag window's width, fewer than the samples)")
    points = _whole_number("n_points", n_points, 2)
    level = _confidence(confidence)
    w_lo, w_hi = _spa_band(u_t, m, _band(band))
    omega = np.logspace(np.log10(w_lo), np.log10(w_hi), points)
    phi_u, phi_yu, phi_y, c_w = _spectra(u_t, yd, m, omega)
    keep = (phi_u > 0) & (phi_y > 0)   # the Hann window's negative side lobes can undercut a near-empty band
    omega, phi_u, phi_yu, phi_y = omega[keep], phi_u[keep], phi_yu[keep], phi_y[keep]
    g = _unfiltered(phi_yu / phi_u, omega, a)
    coherence = np.clip(np.abs(phi_yu) ** 2 / (phi_u * phi_y), 0.0, 1.0)
    # Ljung sec. 6.4: Var G ~ (C_W / N) Phi_v / Phi_u; relative to |G|^2, (C_W / N) (1 / kappa^2 - 1)
    rel_std = np.sqrt(c_w / n * (1.0 - coherence) / np.maximum(coherence, 1e-12))
    # a disc of radius rho around G_hat holds G with probability `level` (complex normal error)
    radius = np.sqrt(-np.log1p(-level)) * rel_std
    response = FrequencyResponseData.from_response(omega / ts_f, g)
    with np.errstate(divide="ignore"):
        lower = response.magnitude_db + 20.0 * np.log10(np.maximum(1.0 - radius, 0.0))
    upper = response.magnitude_db + 20.0 * np.log10(1.0 + radius)
    return SpectralEstimate(
        response=response, lower_db=readonly(lower), upper_db=readonly(upper), relative_std=readonly(rel_std),
        coherence=readonly(coherence), lags=m, window_energy=c_w, n_samples=n,
        band=(float(omega[0] / ts_f), float(omega[-1] / ts_f)) if omega.size else (math.nan, math.nan),
        confidence=level,
    )


# ---------------------------------------------------------------------------
# the choice
# ---------------------------------------------------------------------------
def _plural(count: int, word: str) -> str:
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def _whole_periods(u: np.ndarray, period) -> tuple[int | None, int, str]:
    """``(period, whole periods, why not)``: periods > 0 when the record is a whole number of them."""
    n = u.size
    if period is None:
        found = detect_period(u)
        if found is None:
            return None, 0, "the input does not repeat within the record"
        if found < ETFE_MIN_PERIOD:
            return found, 0, (f"the input repeats every {found} samples, too few for the ETFE "
                              f"(at least {ETFE_MIN_PERIOD})")
        return found, n // found, ""
    p = _whole_number("period", period, 2, None, " (samples per period of the excitation)")
    if n % p == 0 and n >= 2 * p and not _repeats(u, p):
        raise not_allowed("period", p, f"the input does not repeat every {p} samples; "
                                       "give the excitation's period, or None to look for one")
    if p < ETFE_MIN_PERIOD:
        return p, 0, f"the excitation's period of {p} samples is too short for the ETFE (at least {ETFE_MIN_PERIOD})"
    if n % p:
        return p, 0, f"the record's {n} samples are not a whole number of periods of {p} samples"
    return p, n // p, ""


def data_frequency_response(u, y, ts, *, period=None, freqs=None, band=None, lags=None,
                            confidence: float = 0.95) -> DataFrequencyResponse:
    """The data's frequency response: ETFE over whole periods, else a spectral estimate.

    ETFE (:func:`etfe`) when the record is a whole number (>= 1) of periods:
    of ``period`` samples when given (the excitation's design, e.g. idinput's
    'sine' period or a prbs's maximum-length period), else of the smallest
    period with which the input repeats at least twice (:func:`detect_period`).
    Otherwise spectral analysis (:func:`spa`).

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input and output samples.
    ts : float
        Sampling time [s].
    period : int, optional
        The excitation's period in samples, if it is periodic by design (it
        may exceed N: the record is then not a whole period). A record of
        two periods or more is checked to repeat.
    freqs : array_like, optional
        For the ETFE: the excited frequencies [rad/sample] (see :func:`etfe`).
    band : (float, float), optional
        The excitation's band in fractions of the Nyquist frequency, as
        idinput's (see :func:`etfe` and :func:`spa`).
    lags, confidence
        For spa (see :func:`spa`).

    Returns
    -------
    DataFrequencyResponse

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.excitation import idinput
    >>> from eha_core.identify._ctmodels import simulate_tf
    >>> exc = idinput([200, 1, 3], "rgs", [0, 0.5], seed=2)
    >>> y = simulate_tf([10.0], [1.0, 10.0], exc.u, 0.01)
    >>> fr = data_frequency_response(exc.u, y, 0.01)
    >>> fr.method, fr.period, fr.n_periods, fr.lower_db is None
    ('etfe', 200, 3, True)
    >>> print(fr.description)  # doctest: +NORMALIZE_WHITESPACE
    ETFE at the 50 excited frequencies: the record holds 3 whole periods of 200 samples
    (the first, which carries the start-up transient, left out).
    """
    u_arr, y_arr = as_pair(u, y, ("u", "y"))
    ts_f = as_ts(ts)
    _varying(u_arr)
    p, whole, why_not = _whole_periods(u_arr, period)
    if whole >= 1:
        fr = etfe(u_arr, y_arr, p, ts_f, freqs=freqs, band=band)
        held = f"the record holds {_plural(whole, 'whole period')} of {p} samples"
        dropped = " (the first, which carries the start-up transient, left out)" if whole >= 2 else ""
        return DataFrequencyResponse(
            response=fr, method="etfe", lower_db=None, upper_db=None,
            band=(float(fr.w.min()), float(fr.w.max())),
            description=f"ETFE at the {fr.w.size} excited frequencies: {held}{dropped}.",
            period=p, n_periods=whole)
    est = spa(u_arr, y_arr, ts_f, lags=lags, band=band, confidence=confidence)
    percent = f"{100 * est.confidence:.4g}"
    return DataFrequencyResponse(
        response=est.response, method="spa", lower_db=est.lower_db, upper_db=est.upper_db, band=est.band,
        description=(f"Spectral estimate (Blackman-Tukey, Hann window of {est.lags} lags, {percent} % band) "
                     f"from {est.band[0]:.3g} to {est.band[1]:.3g} rad/s: {why_not}."),
        period=p, n_periods=0, lags=est.lags, confidence=est.confidence)
