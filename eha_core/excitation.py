"""Excitation signals compatible with MATLAB's ``idinput`` (docs/model.md, section 4).

:func:`idinput` generates random Gaussian ('rgs'), random binary ('rbs'),
pseudo-random binary ('prbs') and sum-of-sinusoids ('sine') signals with
MATLAB's arguments and conventions, seeded through
:func:`numpy.random.default_rng`, and returns an :class:`Excitation` result
object (the signal, the sinusoid frequencies and the settings that made it).

Conventions adopted
-------------------
Confirmed from MATLAB's own ``idinput.m`` (System Identification Toolbox,
L. Ljung 1995, revision 1.13.2.2 of 2004, and a 2017 copy whose 'rgs', 'rbs'
and 'sine' code is the same) and its reference page
(mathworks.com/help/ident/ref/idinput.html):

* ``n = N`` | ``[P, Nu]`` | ``[P, Nu, M]``: one period of P samples is built
  and stacked M times, so the signal is exactly P-periodic with P*M samples.
* ``band = [wlow, whigh]`` in fractions of the Nyquist frequency; for 'prbs'
  ``band = [0, B]`` and the clock period (samples over which the signal is
  held) is ``floor(1/B)`` -- MATLAB uses ``floor``, not ``round``; we add a
  1e-9 guard so that ``B = 1/3`` gives 3.
* ``range = [min, max]``: for 'rgs' min/max are mean -/+ one standard deviation,
  met exactly over one period (MATLAB removes the sample mean and divides by
  the RMS with 1/P, i.e. ``ddof=0``); for 'rbs'/'prbs' the two levels (the
  sign -1 maps to min); for 'sine' the scaling is *symmetric*:
  ``m = max(|u1|)`` and ``u = min + (max - min) (u1 + m) / (2 m)``, so 0 maps
  to the mid-range, the signal stays in [min, max] and touches exactly the
  bound on the side of its largest absolute value (not necessarily both).
* 'sine' with ``sinedata = [NumSinusoids, NumTrials, GridSkip]`` (a shorter
  sequence is padded with MATLAB's defaults 10, 10, 1): the candidate
  frequencies are ``2*pi*k/P`` for ``k = 1, 1+GridSkip, ...  <= fix(P/2)``,
  kept when *strictly* inside ``(wlow*pi, whigh*pi)`` (so pi itself is never
  used).  The frequencies are **not** random: MATLAB's ``choose`` picks
  ``Nu*NumSinusoids`` of the candidates spread evenly from both ends of the
  band inwards, and channel ``ku`` gets every Nu-th of them (different
  frequencies per channel).  Only the phases are random (uniform on
  [0, 2 pi)); each of the NumTrials trials is ``sum cos(w*t + phi)`` and the
  one with the smallest peak-to-peak value is kept (first one on ties).  Too
  few candidates for ``Nu*NumSinusoids`` is an error in MATLAB, and here.
* 'prbs' is deterministic in MATLAB (no random numbers): a maximum-length
  sequence from a shift register with MATLAB's feedback taps for orders 3..18,
  started from all -1, the order being the largest with
  ``clock*(2**order - 1) <= P``.  If ``P`` is not ``clock*(2**order - 1)``:
  with M > 1 the period is changed to that length (``period`` then differs
  from the requested P; MATLAB prints a message, we warn); with M = 1 the
  first P samples of the sequence one order longer are returned (warned too).
  Channel ``ku`` is the first channel circularly shifted by ``ku*floor(P/Nu)``.
  Our 'prbs' output therefore reproduces MATLAB 2004's sample for sample;
  ``seed`` is unused for it.
* Frequencies returned in rad/sample; MATLAB returns them Nu-by-NumSinusoids,
  here shape (NumSinusoids,) for one channel and (NumSinusoids, Nu) otherwise,
  one column per channel like ``u``.

Differences and what could not be confirmed:

* Random streams cannot match MATLAB's ``randn``/``rand``; the draws are in
  MATLAB's order: 'sine' phases are ``rng.uniform(0, 2*pi, (Nu, NumTrials,
  NumSinusoids))`` (channel, trial, sinusoid loops), 'rgs'/'rbs' take
  ``rng.standard_normal((P, Nu))``.
* Band filtering of 'rgs'/'rbs': MATLAB draws 5P samples, filters them with
  an 8th-order Butterworth filter (``idfilt(u, 8, band)``, skipped when the
  band is [0, 1]) and keeps the middle P to drop transients; the stacked
  periods then have a jump where they meet, and the roll-off leaks outside the
  band.  We draw P samples and apply an ideal filter periodically in the
  frequency domain (zero every DFT bin of the period outside the closed band),
  so each period is exactly band-limited and the M-period signal has lines
  only inside the band.  'rbs' takes the sign of that signal, as MATLAB does.
* Newer MATLAB releases generate 'prbs' in an internal helper
  (``controllib.internal.util.genPRBS``) whose source we could not see; we
  follow the 2004 code.
* Our default ``type`` is 'rgs' (this project's API); MATLAB's is 'rbs'.
* Stricter checks than MATLAB's: ``min < max`` (MATLAB allows equal levels),
  ``0 <= wlow < whigh <= 1``, GridSkip >= 1, and 'rgs' (or a filtered 'rbs')
  needs at least one DFT frequency ``2*pi*k/P, k >= 1`` inside the band.
* With ``seed=None`` a fresh seed is drawn from the OS and stored in
  :attr:`Excitation.seed`, so any signal can be regenerated exactly.

Examples
--------
The paper's signal: one 1000-sample period of 100 sinusoids, Ts = 0.01 s.

>>> from eha_core.excitation import idinput
>>> exc = idinput([1000, 1, 1], "sine", [0, 1], [-1, 1], [100, 50, 1], seed=1)
>>> exc.u.shape, exc.freqs.shape
((1000,), (100,))
>>> exc.freqs_hz(0.01)[[0, 1, 2, -1]]  # 0.1 Hz grid, from 0.1 Hz to 49.9 Hz
array([ 0.1,  0.6,  1.1, 49.9])
>>> bool(exc.u.min() >= -1 and exc.u.max() <= 1)
True
>>> round(float(max(-exc.u.min(), exc.u.max())), 12)  # touches one bound
1.0
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import dataclass

import numpy as np

from ._checks import not_allowed

__all__ = ["Excitation", "idinput", "SIGNAL_TYPES"]

#: The signal types, as MATLAB spells them.
SIGNAL_TYPES = ("rgs", "rbs", "prbs", "sine")

# Feedback taps of MATLAB's PRBS shift register, per order n (1-based register
# positions; the new bit is the product of the +-1 values at these positions).
_PRBS_TAPS = {
    3: (1, 3),
    4: (1, 4),
    5: (2, 5),
    6: (1, 6),
    7: (1, 7),
    8: (1, 2, 7, 8),
    9: (4, 9),
    10: (3, 10),
    11: (9, 11),
    12: (6, 8, 11, 12),
    13: (9, 10, 12, 13),
    14: (4, 8, 13, 14),
    15: (14, 15),
    16: (4, 13, 15, 16),
    17: (14, 17),
    18: (11, 18),
}
_PRBS_MIN_ORDER, _PRBS_MAX_ORDER = 3, 18

# Relative tolerance used when a grid frequency falls on a band edge.
_EDGE_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class Excitation:
    """An excitation signal and the settings that produced it.

    Attributes
    ----------
    u : numpy.ndarray
        The signal, shape ``(period * n_periods,)`` for one channel, else
        ``(period * n_periods, n_channels)``.  Read-only.
    freqs : numpy.ndarray
        For 'sine': the sinusoid frequencies in rad/sample, shape
        ``(NumSinusoids,)`` for one channel, else ``(NumSinusoids, n_channels)``
        (column ``j`` belongs to channel ``j``).  Empty for other types.
    type : str
        'rgs', 'rbs', 'prbs' or 'sine' (lower case).
    period : int
        Samples per period P (for 'prbs' with more than one period, the
        adjusted period, see the module notes).
    n_channels : int
        Number of channels Nu.
    n_periods : int
        Number of periods M.
    band : tuple of float
        (wlow, whigh) in fractions of the Nyquist frequency.
    range : tuple of float
        (min, max) as in MATLAB's Range.
    seed : int or None
        Seed of :func:`numpy.random.default_rng` that reproduces the signal
        (None only for 'prbs', which draws no random numbers).
    sinedata : tuple of int or None
        (NumSinusoids, NumTrials, GridSkip) for 'sine', else None.
    clock_period : int or None
        For 'prbs': samples over which the signal is held, ``floor(1/B)``.
    """

    u: np.ndarray
    freqs: np.ndarray
    type: str
    period: int
    n_channels: int
    n_periods: int
    band: tuple[float, float]
    range: tuple[float, float]
    seed: int | None
    sinedata: tuple[int, int, int] | None = None
    clock_period: int | None = None

    @property
    def n_samples(self) -> int:
        """Total number of samples, ``period * n_periods``."""
        return self.period * self.n_periods

    def time_s(self, ts: float) -> np.ndarray:
        """Sample instants ``k * ts`` in seconds for a sample time ``ts`` [s]."""
        return np.arange(self.n_samples) * _check_ts(ts)

    def freqs_rad_s(self, ts: float) -> np.ndarray:
        """Sinusoid frequencies in rad/s for a sample time ``ts`` [s]."""
        return self.freqs / _check_ts(ts)

    def freqs_hz(self, ts: float) -> np.ndarray:
        """Sinusoid frequencies in Hz for a sample time ``ts`` [s].

        Examples
        --------
        >>> exc = idinput([200, 1, 1], "sine", [0, 1], [-1, 1], [3, 5, 1], seed=0)
        >>> exc.freqs_hz(0.01)  # the grid step is 1 / (P Ts) = 0.5 Hz
        array([ 0.5, 25. , 49.5])
        """
        return self.freqs / (2.0 * np.pi * _check_ts(ts))

    def to_pandas(self, ts: float | None = None):
        """The signal as a :class:`pandas.DataFrame`.

        Columns ``k`` (sample index), ``t_s`` (only when ``ts`` is given) and
        ``u`` for one channel or ``u1`` .. ``uNu`` for several.

        Examples
        --------
        >>> exc = idinput([7, 2], "prbs", [0, 1], [0, 1])  # u2 = u1 shifted by 7 // 2
        >>> exc.to_pandas(ts=0.5).head(3)
           k  t_s   u1   u2
        0  0  0.0  0.0  1.0
        1  1  0.5  0.0  0.0
        2  2  1.0  0.0  1.0
        """
        import pandas as pd  # lazy: the core does not need pandas to import

        columns: dict[str, np.ndarray] = {"k": np.arange(self.n_samples)}
        if ts is not None:
            columns["t_s"] = self.time_s(ts)
        if self.u.ndim == 1:
            columns["u"] = self.u
        else:
            for j in range(self.n_channels):
                columns[f"u{j + 1}"] = self.u[:, j]
        return pd.DataFrame(columns)

    def __repr__(self) -> str:
        extra = ""
        if self.sinedata is not None:
            extra = f", sinedata={self.sinedata}"
        if self.clock_period is not None:
            extra = f", clock_period={self.clock_period}"
        return (
            f"Excitation(type={self.type!r}, period={self.period}, "
            f"n_channels={self.n_channels}, n_periods={self.n_periods}, "
            f"band={self.band}, range={self.range}, seed={self.seed}{extra}, "
            f"u.shape={self.u.shape})"
        )


def idinput(
    n,
    type: str = "rgs",
    band=(0.0, 1.0),
    range=(-1.0, 1.0),
    sinedata=(10, 10, 1),
    *,
    seed: int | None = None,
) -> Excitation:
    """Generate an excitation signal the way MATLAB's ``idinput`` does.

    Parameters
    ----------
    n : int or sequence of int
        ``N`` (one channel, N samples), ``[P, Nu]`` (Nu channels of P samples)
        or ``[P, Nu, M]`` (M periods of P samples, P*M samples in all).
    type : {'rgs', 'rbs', 'prbs', 'sine'}, default 'rgs'
        Random Gaussian, random binary, pseudo-random binary (maximum-length
        sequence) or sum of sinusoids; case-insensitive.  (MATLAB's default
        is 'rbs'.)
    band : (float, float), default (0, 1)
        ``[wlow, whigh]``, the pass band in fractions of the Nyquist frequency,
        ``0 <= wlow < whigh <= 1``.  For 'prbs' it must be ``[0, B]``: the
        signal is held over ``floor(1/B)`` samples (the clock period).
    range : (float, float), default (-1, 1)
        ``[min, max]``.  'rgs': mean -/+ one standard deviation.  'rbs',
        'prbs': the two levels.  'sine': the signal is scaled symmetrically
        into [min, max] (0 maps to the mid-range, the largest absolute value
        to a bound).
    sinedata : sequence of int, default (10, 10, 1)
        ``[NumSinusoids, NumTrials, GridSkip]`` for 'sine' (missing trailing
        entries take MATLAB's defaults 10 and 1); ignored, but still
        validated, for other types.
    seed : int, optional
        Seed for :func:`numpy.random.default_rng`; the same seed gives the
        same signal.  None draws a fresh seed, which is stored in the result.

    Returns
    -------
    Excitation
        The signal ``u`` and, for 'sine', the frequencies ``freqs`` in
        rad/sample, with the settings used.

    Raises
    ------
    ValueError
        An argument outside what is allowed; the message names the argument,
        the rejected value and what would be accepted.

    Warns
    -----
    UserWarning
        'prbs' whose period is not a whole number of maximum-length periods
        (MATLAB prints the same information).

    See Also
    --------
    Module notes for the MATLAB conventions followed and the differences.

    Examples
    --------
    >>> from eha_core.excitation import idinput
    >>> idinput(7, "prbs", [0, 1], [0, 1]).u        # a full 2**3 - 1 sequence
    array([0., 0., 0., 1., 0., 1., 1.])
    >>> exc = idinput([500, 2, 3], "rgs", [0, 0.5], [1, 3], seed=7)
    >>> exc.u.shape
    (1500, 2)
    >>> bool(np.array_equal(exc.u[:500], exc.u[500:1000]))   # periodic
    True
    >>> [round(float(v), 12) for v in exc.u.mean(axis=0)]    # (min+max)/2
    [2.0, 2.0]
    >>> [round(float(v), 12) for v in exc.u.std(axis=0)]     # (max-min)/2
    [1.0, 1.0]
    >>> idinput(100, "sine", [0.2, 1.5])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    eha_core._checks.FieldError: band = [0.2, 1.5] is not allowed: need [wlow, whigh] with 0 <= wlow < whigh <= 1 (...)
    """
    kind = _parse_type(type)
    period, n_channels, n_periods = _parse_n(n)
    wlow, whigh = _parse_band(band, kind)
    lo, hi = _parse_range(range)
    n_sines, n_trials, grid_skip = _parse_sinedata(sinedata)

    clock = None
    freqs = np.empty(0)
    if kind == "prbs":
        one_period, period, clock = _prbs(period, n_channels, n_periods, whigh, lo, hi)
        seed_used = seed
    else:
        seed_used = _resolve_seed(seed)
        rng = np.random.default_rng(seed_used)
        if kind == "sine":
            one_period, freqs = _multisine(
                rng, period, n_channels, wlow, whigh, lo, hi, n_sines, n_trials, grid_skip
            )
        else:
            one_period = _random_signal(rng, kind, period, n_channels, wlow, whigh, lo, hi)

    u = np.tile(one_period, (n_periods, 1))
    if n_channels == 1:
        u = u[:, 0]
        freqs = freqs[:, 0] if freqs.ndim == 2 else freqs
    u = np.ascontiguousarray(u, dtype=float)
    u.setflags(write=False)
    freqs = np.ascontiguousarray(freqs, dtype=float)
    freqs.setflags(write=False)
    return Excitation(
        u=u,
        freqs=freqs,
        type=kind,
        period=period,
        n_channels=n_channels,
        n_periods=n_periods,
        band=(wlow, whigh),
        range=(lo, hi),
        seed=seed_used,
        sinedata=(n_sines, n_trials, grid_skip) if kind == "sine" else None,
        clock_period=clock,
    )


# --------------------------------------------------------------------------
# Signal generators (one period, shape (P, Nu))
# --------------------------------------------------------------------------


def _random_signal(rng, kind, period, n_channels, wlow, whigh, lo, hi) -> np.ndarray:
    """One period of 'rgs' or 'rbs': white Gaussian noise, ideal periodic band filter."""
    e = rng.standard_normal((period, n_channels))
    full_band = wlow == 0.0 and whigh == 1.0
    if not full_band or kind == "rgs":
        bins = np.arange(period // 2 + 1)
        in_band = _closed_band_mask(bins, period, wlow, whigh)
        if not np.any(in_band[1:]):
            raise not_allowed(
                "band", [wlow, whigh],
                f"with period P = {period} no DFT frequency 2*pi*k/P (k >= 1) lies inside "
                f"[wlow, whigh]*pi; need at least one: widen the band or lengthen the period",
            )
    if not full_band:
        # Ideal filter applied to one period in the frequency domain, so the
        # repeated signal is exactly periodic and band-limited (module notes).
        spectrum = np.fft.rfft(e, axis=0)
        spectrum[~in_band, :] = 0.0
        e = np.fft.irfft(spectrum, n=period, axis=0)
    if kind == "rbs":
        return np.where(e >= 0.0, hi, lo)
    e = e - e.mean(axis=0)
    rms = np.sqrt(np.mean(e**2, axis=0))
    return 0.5 * (lo + hi) + e * (0.5 * (hi - lo) / rms)


def _sine_grid(period: int, wlow: float, whigh: float, grid_skip: int) -> np.ndarray:
    """MATLAB's candidate bins k: 1:GridSkip:fix(P/2), 2k/P strictly inside the band."""
    k = np.arange(1, period // 2 + 1, grid_skip)
    x = 2.0 * k / period  # frequency in fractions of Nyquist
    on_edge = np.isclose(x, wlow, rtol=_EDGE_TOL, atol=_EDGE_TOL) | np.isclose(
        x, whigh, rtol=_EDGE_TOL, atol=_EDGE_TOL
    )
    return k[(x > wlow) & (x < whigh) & ~on_edge]


def _choose(n_available: int, n_pick: int) -> np.ndarray:
    """MATLAB idinput's ``choose``: n_pick of 0..n_available-1 spread evenly.

    Takes the two outermost remaining candidates, drops ``floor(nr/(nl-1))``
    from each end, and repeats inwards; three left -> first, middle, last;
    one left -> the middle.  Returns sorted 0-based indices.
    """
    remaining = np.arange(n_available)
    picked: list[int] = []
    left = n_pick
    while left > 0:
        nr = remaining.size
        if left == 3:
            picked += [remaining[0], remaining[math.ceil(nr / 2) - 1], remaining[-1]]
            left = 0
        elif left > 1:
            k = nr // (left - 1)
            picked += [remaining[0], remaining[-1]]
            remaining = remaining[k : nr - k]
            left -= 2
        else:
            picked.append(remaining[math.ceil(nr / 2) - 1])
            left -= 1
    return np.sort(np.asarray(picked, dtype=int))


def _multisine(
    rng, period, n_channels, wlow, whigh, lo, hi, n_sines, n_trials, grid_skip
) -> tuple[np.ndarray, np.ndarray]:
    """One period of 'sine' and the frequencies, shape (NumSinusoids, Nu)."""
    grid = _sine_grid(period, wlow, whigh, grid_skip)
    needed = n_channels * n_sines
    if grid.size < needed:
        raise not_allowed(
            "sinedata", [n_sines, n_trials, grid_skip],
            f"NumSinusoids = {n_sines} is too many with Nu = {n_channels}, P = {period}, "
            f"GridSkip = {grid_skip} and band = [{wlow:.6g}, {whigh:.6g}]: "
            f"need Nu*NumSinusoids <= {grid.size}, the number of grid frequencies "
            f"2*pi*k/P strictly inside the band (MATLAB errors here too); increase "
            f"the period or the band, or decrease the number of sinusoids",
        )
    chosen = grid[_choose(grid.size, needed)]
    # Draw order = MATLAB's loops: channel, trial, sinusoid.
    phases = rng.uniform(0.0, 2.0 * np.pi, size=(n_channels, n_trials, n_sines))
    u = np.empty((period, n_channels))
    bins = np.empty((n_sines, n_channels), dtype=int)
    chunk = max(1, 2**21 // period)  # bound the memory of the trial batch
    for ku in np.arange(n_channels):
        bins[:, ku] = chosen[ku::n_channels]
        best, best_ptp = None, np.inf
        for start in np.arange(0, n_trials, chunk):
            trials = _sum_of_cosines(period, bins[:, ku], phases[ku, start : start + chunk])
            ptp = trials.max(axis=1) - trials.min(axis=1)
            j = int(np.argmin(ptp))  # first minimum, as MATLAB's strict '<'
            if ptp[j] < best_ptp:
                best, best_ptp = trials[j], ptp[j]
        peak = np.max(np.abs(best))
        u[:, ku] = (hi - lo) * (best + peak) / (2.0 * peak) + lo
    return u, 2.0 * np.pi * bins / period


def _sum_of_cosines(period: int, bins: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """``sum_s cos(2*pi*bins[s]*t/P + phases[:, s])`` for t = 0..P-1, per row.

    All bins satisfy 1 <= k < P/2, so one inverse real FFT per trial is exact
    (to rounding) and much faster than summing the cosines.
    """
    spectrum = np.zeros((phases.shape[0], period // 2 + 1), dtype=complex)
    spectrum[:, bins] = 0.5 * period * np.exp(1j * phases)
    return np.fft.irfft(spectrum, n=period, axis=1)


def _prbs_chips(order: int, n_chips: int) -> np.ndarray:
    """First ``n_chips`` values (+-1) of MATLAB's maximum-length sequence of ``order``.

    MATLAB's register ``fi`` starts at all -1, outputs ``fi(order)`` and
    shifts in ``prod(fi(taps))``.  With bit 1 <-> -1 this is the recurrence
    ``a[t+n] = a[t] xor a[t+n-j]`` (j in taps, j < n) that
    :func:`scipy.signal.max_len_seq` runs from an all-ones state.
    """
    from scipy.signal import max_len_seq

    taps = [order - j for j in _PRBS_TAPS[order] if j != order]
    bits, _ = max_len_seq(order, length=n_chips, taps=taps)
    return 1.0 - 2.0 * bits


def _prbs(period, n_channels, n_periods, whigh, lo, hi):
    """One period of 'prbs', the (possibly adjusted) period and the clock period."""
    clock = max(1, int(math.floor(1.0 / whigh + 1e-9)))
    order = _PRBS_MIN_ORDER
    for candidate in np.arange(_PRBS_MIN_ORDER, _PRBS_MAX_ORDER + 1):
        if clock * (2**candidate - 1) <= period:
            order = int(candidate)
    full = clock * (2**order - 1)
    if full != period:
        if n_periods > 1:
            warnings.warn(
                f"idinput: the period of the PRBS signal has been changed from "
                f"{period} to {full} (clock period {clock} x {2**order - 1}); "
                f"the length of the input is {full * n_periods}",
                UserWarning,
                stacklevel=3,
            )
            period = full
        else:
            order = min(order + 1, _PRBS_MAX_ORDER)
            full = clock * (2**order - 1)
            if full < period:
                raise not_allowed(
                    "n", period,
                    f"P = {period} is too long for type prbs with clock period {clock}; "
                    f"need P <= {full} = {clock}*(2**{_PRBS_MAX_ORDER} - 1)",
                )
            warnings.warn(
                f"idinput: the PRBS signal delivered is the {period} first values "
                f"of a full sequence of length {full}",
                UserWarning,
                stacklevel=3,
            )
    n_chips = -(-period // clock)
    chips = np.repeat(_prbs_chips(order, n_chips), clock)[:period]
    shift = period // n_channels
    channels = [np.roll(chips, -shift * ku) for ku in np.arange(n_channels)]
    signal = np.stack(channels, axis=1)
    return lo + (hi - lo) * (signal + 1.0) / 2.0, period, clock


# --------------------------------------------------------------------------
# Argument parsing and validation
# --------------------------------------------------------------------------


def _as_sequence(value) -> list | None:
    """A flat list from a scalar or 1-D sequence, or None if it is neither."""
    if isinstance(value, str):
        return None
    try:
        arr = np.asarray(value, dtype=object)
    except (ValueError, TypeError):
        return None
    if arr.ndim == 0:
        return [arr.item()]
    if arr.ndim != 1:
        return None
    return list(arr)


def _positive_int(x) -> int | None:
    """``x`` as an int if it is a positive whole number (int or integral float)."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
        return None
    xf = float(x)
    if not math.isfinite(xf) or not xf.is_integer() or xf < 1:
        return None
    return int(xf)


def _real_pair(value) -> tuple[float, float] | None:
    items = _as_sequence(value)
    if items is None or len(items) != 2:
        return None
    out = []
    for x in items:
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
            return None
        if not math.isfinite(float(x)):
            return None
        out.append(float(x))
    return out[0], out[1]


def _parse_type(value) -> str:
    kind = value.lower() if isinstance(value, str) else None
    if kind not in SIGNAL_TYPES:
        raise not_allowed("type", value, "need one of rgs, rbs, prbs, sine (case-insensitive)")
    return kind


def _parse_n(value) -> tuple[int, int, int]:
    items = _as_sequence(value)
    ints = None if items is None else [_positive_int(x) for x in items]
    if ints is None or not 1 <= len(ints) <= 3 or any(i is None for i in ints):
        raise not_allowed("n", value, "need a positive integer N or a sequence [P, Nu] or "
                                                 "[P, Nu, M] of positive integers")
    ints += [1] * (3 - len(ints))
    return ints[0], ints[1], ints[2]


def _parse_band(value, kind: str) -> tuple[float, float]:
    pair = _real_pair(value)
    if pair is None or not 0.0 <= pair[0] < pair[1] <= 1.0:
        raise not_allowed("band", value, "need [wlow, whigh] with 0 <= wlow < whigh <= 1 "
                                                    "(fractions of the Nyquist frequency)")
    if kind == "prbs" and pair[0] != 0.0:
        raise not_allowed("band", value, "type prbs needs [0, B] with 0 < B <= 1 "
                                                    "(the signal is held over floor(1/B) samples)")
    return pair


def _parse_range(value) -> tuple[float, float]:
    pair = _real_pair(value)
    if pair is None or not pair[0] < pair[1]:
        raise not_allowed("range", value, "need [min, max] of finite numbers with min < max")
    return pair


def _parse_sinedata(value) -> tuple[int, int, int]:
    items = _as_sequence(value)
    ints = None if items is None else [_positive_int(x) for x in items]
    if ints is None or not 1 <= len(ints) <= 3 or any(i is None for i in ints):
        raise not_allowed("sinedata", value, "need [NumSinusoids, NumTrials, GridSkip] of "
                                                        "positive integers")
    ints += [10, 1][len(ints) - 1 :]
    return ints[0], ints[1], ints[2]


def _resolve_seed(seed) -> int:
    if seed is None:
        return int(np.random.SeedSequence().entropy)
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise not_allowed("seed", seed, "need None or a non-negative integer")
    return int(seed)


def _check_ts(ts) -> float:
    if (
        isinstance(ts, (bool, np.bool_))
        or not isinstance(ts, numbers.Real)
        or not math.isfinite(float(ts))
        or ts <= 0
    ):
        raise not_allowed("ts", ts, "need a finite sample time > 0 s")
    return float(ts)


def _closed_band_mask(bins: np.ndarray, period: int, wlow: float, whigh: float) -> np.ndarray:
    """True for DFT bins whose frequency 2k/P (x Nyquist) is in [wlow, whigh]."""
    x = 2.0 * bins / period
    tol = _EDGE_TOL * max(1.0, whigh)
    return (x >= wlow - tol) & (x <= whigh + tol)
