"""Validation of identified transfer functions: simulation, fit, ETFE, residuals.

The one exact simulator of a continuous-time transfer function on a sampled
input, held (ZOH) or linear (FOH) between samples (:func:`simulate_tf`), and
MATLAB's fit (:func:`fit_percent`) live in the private module
:mod:`eha_core.identify._ctmodels`, with the discretisation behind them;
:mod:`eha_core.identify.tfest` uses the same code for its
output-error stage, so the fit reported by the estimator and the fit reported
by :func:`compare` are computed by the same code. They are public here.

State convention
----------------
Initial states (``initial_state``) refer to the *observability canonical form* of
``G(s) = num(s) / den(s)`` (Kailath): ``x_1 = y - h_0 u`` and
``x_{i+1} = x_i' - h_i u``, where ``h_k`` are the Markov parameters of the
expansion ``G(s) = sum_k h_k s^-k``. For a strictly proper model
``initial_state[0] = y(0)``; for an all-pole model ``b / A(s)`` the state is simply
``[y, y', ..., y^(n-1)]`` at ``t = 0`` (position, velocity, acceleration for
the actuator's third-order model).

Input offset
------------
A model may carry a constant input offset ``c`` (in input units, like MATLAB's
``InputOffset``): ``y = G(s) (u + c)``, the offset applied from ``t = 0`` on.
Its response ``c G(s) 1(t)`` is linear in ``c``, as the free response is in
``initial_state``, so both are estimated together by linear least squares
(:func:`eha_core.identify._ctmodels.fit_linear_terms`, shared with
:mod:`eha_core.identify.tfest`).

Only numpy and scipy are imported here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

from .._checks import not_allowed
from ._ctmodels import (
    FrequencyResponseData,
    as_pair,
    as_tf,
    as_ts,
    check_delay,
    check_intersample,
    discretise,
    fit_linear_terms,
    fit_percent,
    frequency_response,
    linear_columns,
    readonly,
    simulate_tf,
)

__all__ = [
    "CompareResult",
    "FrequencyResponseData",
    "ResidualAnalysis",
    "compare",
    "etfe_periodic",
    "fit_percent",
    "fit_conditions",
    "FIT_DEFINITION",
    "frequency_response",
    "residual_analysis",
    "simulate_tf",
]


# ---------------------------------------------------------------------------
# compare
# ---------------------------------------------------------------------------
#: How every fit of the project is computed unless its label says otherwise (MATLAB ``compare``).
FIT_DEFINITION = "initial state and input offset fitted"


def fit_conditions(initial_condition, input_offset) -> str:
    """How a fit's simulation started, in words, for the label beside the number.

    The project's one definition of fit is MATLAB ``compare``'s with the
    initial state and a constant input offset fitted by least squares (the
    model board, Figs. 11 and 13 and the estimates of Ĥ(s) by default); a
    number computed otherwise says so.

    Parameters
    ----------
    initial_condition : {'estimate', 'zero'}, None or array
        As given to :func:`compare`: fitted, at rest (``"zero"`` or None), or a given initial state.
    input_offset : {'estimate', 'zero'}, None or float
        As given to :func:`compare`: fitted, none (``"zero"`` or None), or a given offset.

    Examples
    --------
    >>> fit_conditions("estimate", "estimate")
    'initial state and input offset fitted'
    >>> fit_conditions("zero", None)
    'from rest, no input offset'
    """
    ic = "estimate" if isinstance(initial_condition, str) and initial_condition == "estimate" else (
        "zero" if initial_condition is None or (isinstance(initial_condition, str) and initial_condition == "zero")
        else "given")
    fitted_offset = isinstance(input_offset, str) and input_offset == "estimate"
    no_offset = input_offset is None or (isinstance(input_offset, str) and input_offset == "zero")
    if ic == "estimate":
        return "initial state and input offset fitted" if fitted_offset else (
            "initial state fitted, no input offset" if no_offset else "initial state fitted, input offset given")
    start = "from rest" if ic == "zero" else "from a given initial state"
    return f"{start}, input offset fitted" if fitted_offset else (
        f"{start}, no input offset" if no_offset else f"{start}, input offset given")


@dataclass(frozen=True, eq=False)
class CompareResult:
    """Simulated output of a model against measured data (MATLAB ``compare``).

    Attributes
    ----------
    y_hat : numpy.ndarray
        Simulated output (the input held or linear between samples, ``intersample``).
    fit_percent : float
        ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)``.
    initial_condition : str
        ``"zero"``, ``"estimate"`` (least squares) or ``"given"``.
    initial_state : numpy.ndarray or None
        Initial state used (observability canonical form); None when zero.
    input_offset : float or None
        Constant input offset ``c`` used, in input units (``y_hat`` is the
        response to ``u + c``); None when no offset was applied.
    input_delay : float
        Input delay used, in seconds (0.0 when none).
    intersample : str
        ``"zoh"`` or ``"foh"``: the input's behaviour between samples used.
    """

    y_hat: np.ndarray
    fit_percent: float
    initial_condition: str
    initial_state: np.ndarray | None
    input_offset: float | None = None
    input_delay: float = 0.0
    intersample: str = "zoh"

    def __repr__(self) -> str:
        offset = "" if self.input_offset is None else f", input offset {self.input_offset:.4g}"
        delay = f", input delay {self.input_delay:g} s" if self.input_delay else ""
        return (f"CompareResult: fit {self.fit_percent:.2f} % over {np.size(self.y_hat)} samples (initial state "
                f"{self.initial_condition}{offset}{delay}, {self.intersample}); the model's output in .y_hat")


def _check_compare_offset(input_offset):
    """``(estimate, value)`` from ``"zero"``, ``"estimate"``, None or a number."""
    if input_offset is None:
        return False, None
    if isinstance(input_offset, str):
        if input_offset in ("zero", "estimate"):
            return input_offset == "estimate", None
    elif not isinstance(input_offset, (bool, np.bool_)):
        try:
            value = float(input_offset)
        except (TypeError, ValueError):
            value = np.nan
        if np.isfinite(value):
            return False, value
    raise not_allowed("input_offset", input_offset,
                      "use zero, estimate, None or a finite number (input units)")


def compare(num, den, u, y, ts, initial_condition="zero", input_offset="zero", input_delay=0.0,
            intersample="zoh") -> CompareResult:
    """Simulate a transfer function on data and report MATLAB's fit.

    Parameters
    ----------
    num, den : array_like
        Model coefficients, descending powers of s.
    u, y : array_like, shape (N,)
        Measured input and output, sampled at ``ts``.
    ts : float
        Sampling time in seconds.
    initial_condition : {"zero", "estimate"} or array_like
        ``"zero"``: start at rest. ``"estimate"``: the least-squares initial
        state (the response is linear in it). An array: that initial state.
    input_offset : {"zero", "estimate"}, float or None
        Constant offset ``c`` added to ``u`` from the first sample on (input
        units). ``"zero"`` or None: none. ``"estimate"``: least squares
        (jointly with the initial state when that is estimated too). A number:
        that offset (e.g. a ``TFEstimate.input_offset``).
        An offset estimated on one record rarely holds on another (it stands
        for effects such as a valve's asymmetry that depend on the
        excitation), so validation data usually need their own.
    input_delay : float
        Input delay ``tau >= 0`` in seconds (e.g. a ``TFEstimate.input_delay``):
        the model is ``y = G(s) e^(-s tau) (u + c)``, simulated exactly for the
        held input (any ``tau``, not only multiples of ``ts``), the input
        before the first sample taken as zero. Default 0.
    intersample : {"zoh", "foh"}
        The input held (default) or linear between samples (MATLAB's
        ``InterSample``; e.g. a ``TFEstimate.intersample``), see
        :func:`simulate_tf`.

    Returns
    -------
    CompareResult

    Examples
    --------
    >>> import numpy as np
    >>> u = np.ones(50)
    >>> y = simulate_tf([1.0], [1.0, 1.0], u, 0.1, initial_state=[0.5])
    >>> compare([1.0], [1.0, 1.0], u, y, 0.1).fit_percent < 90
    True
    >>> res = compare([1.0], [1.0, 1.0], u, y, 0.1, initial_condition="estimate")
    >>> round(res.fit_percent, 6), np.round(res.initial_state, 6)
    (100.0, array([0.5]))
    >>> y = simulate_tf([1.0], [1.0, 1.0], u - 0.2, 0.1)  # an offset of -0.2 on u
    >>> res = compare([1.0], [1.0, 1.0], u, y, 0.1, input_offset="estimate")
    >>> round(res.fit_percent, 6), round(res.input_offset, 6)
    (100.0, -0.2)
    >>> y = simulate_tf([1.0], [1.0, 1.0], u, 0.1, input_delay=0.25)
    >>> round(compare([1.0], [1.0, 1.0], u, y, 0.1, input_delay=0.25).fit_percent, 6)
    100.0
    """
    num_n, den_n = as_tf(num, den)
    u_arr, y_arr = as_pair(u, y, ("u", "y"))
    estimate_offset, offset = _check_compare_offset(input_offset)
    tau = check_delay(input_delay)
    intersample = check_intersample(intersample)
    model = discretise(num_n, den_n, as_ts(ts), tau, intersample)
    initial_state = None
    estimate_initial_state = False
    allowed = f"use zero, estimate or an array of shape ({model.order},), one initial state per pole"
    if isinstance(initial_condition, str):
        if initial_condition == "estimate":
            label = "estimate"
            estimate_initial_state = model.order > 0
        elif initial_condition == "zero":
            label = "zero"
        else:
            raise not_allowed("initial_condition", initial_condition, allowed)
    else:
        try:
            initial_state = np.atleast_1d(np.asarray(initial_condition, dtype=float))
        except (TypeError, ValueError):
            raise not_allowed("initial_condition", initial_condition, allowed) from None
        if initial_state.shape != (model.order,):
            raise not_allowed("initial_condition", initial_state,
                              f"{allowed}; this array has shape {initial_state.shape}")
        label = "given"
    y_hat = model.forced(u_arr if offset is None else u_arr + offset)
    if initial_state is not None:
        y_hat = y_hat + model.free_basis(u_arr.size) @ initial_state
    if estimate_offset or estimate_initial_state:
        # the offset's and the initial state's responses are linear: one
        # least-squares problem for both
        columns = linear_columns(model, u_arr.size, offset=estimate_offset, initial_state=estimate_initial_state)
        coef = fit_linear_terms(columns, y_arr - y_hat)
        y_hat = y_hat + columns @ coef
        if estimate_offset:
            offset = float(coef[0])
        if estimate_initial_state:
            initial_state = coef[int(estimate_offset):]
    return CompareResult(
        y_hat=readonly(y_hat),
        fit_percent=fit_percent(y_arr, y_hat),
        initial_condition=label,
        initial_state=None if initial_state is None else readonly(initial_state),
        input_offset=offset,
        input_delay=tau,
        intersample=intersample,
    )


# ---------------------------------------------------------------------------
# frequency domain
# ---------------------------------------------------------------------------
def etfe_periodic(u, y, period, ts, freqs=None, *, drop_periods=0,
                  threshold=1e-3) -> FrequencyResponseData:
    """Empirical transfer function estimate of periodic data at excited frequencies.

    The record is cut into whole periods (a trailing partial period is
    ignored), optionally without the first ones (which carry the start-up
    transient), and averaged; then ``G = Y / U`` from the DFT of the averaged
    period. For a periodic input and a system in periodic steady state this is
    exact at every excited frequency; averaging ``M`` periods divides the noise
    variance by ``M``.

    With a zero-order-hold input the sampled data obey the ZOH-equivalent
    discrete transfer function, so the estimate is ``G_zoh(exp(j w ts))``: it
    matches ``H(j w)`` well below the Nyquist frequency, but carries the hold's
    half-sample delay (phase ``-w ts / 2``) and sinc roll-off near it.

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input and output samples.
    period : int
        Samples per period, ``2 <= period <= N``.
    ts : float
        Sampling time in seconds.
    freqs : array_like, optional
        Frequencies in rad/sample (``0 < f <= pi``) at which to evaluate
        (DTFT of the averaged period). Default: the DFT bins ``2 pi k /
        period``, ``k >= 1``, where ``|U| > threshold * max |U|``.
    drop_periods : int
        Number of leading periods to discard (start-up transient); 1 drops the
        first period. A transient lasts about 5 time constants of the slowest
        pole.
    threshold : float
        Relative input magnitude that counts as "excited" (default 1e-3).

    Returns
    -------
    FrequencyResponseData
        ``w`` in rad/s, complex ``response``, ``magnitude_db``, ``phase_deg``.

    Examples
    --------
    >>> import numpy as np
    >>> k = np.arange(400)
    >>> u = np.sin(2 * np.pi * 5 * k / 100)
    >>> y = 0.5 * np.roll(u, 1)  # half gain, one-sample delay, periodic
    >>> est = etfe_periodic(u, y, period=100, ts=0.01)
    >>> est.w, np.round(np.abs(est.response), 6)
    (array([31.41592654]), array([0.5]))
    """
    u_arr, y_arr = as_pair(u, y, ("u", "y"))
    ts_f = as_ts(ts)
    if isinstance(period, bool) or not isinstance(period, (int, np.integer)) or not (
        2 <= period <= u_arr.size
    ):
        raise not_allowed("period", period,
                          f"must be a whole number of samples in [2, {u_arr.size}] (the record's length)")
    n_periods = u_arr.size // period
    if isinstance(drop_periods, bool) or not isinstance(drop_periods, (int, np.integer)) or not (
        0 <= drop_periods < n_periods
    ):
        raise not_allowed("drop_periods", drop_periods,
                          f"must be a whole number in [0, {n_periods - 1}] (the data hold "
                          f"{n_periods} whole periods and at least one must be left)")
    first = int(drop_periods)
    if not (np.isfinite(threshold) and 0.0 <= threshold < 1.0):
        raise not_allowed("threshold", threshold, "must be a relative input magnitude in [0, 1)")
    u_avg = u_arr[first * period:n_periods * period].reshape(-1, period).mean(axis=0)
    y_avg = y_arr[first * period:n_periods * period].reshape(-1, period).mean(axis=0)
    if freqs is None:
        u_dft = np.fft.rfft(u_avg)
        y_dft = np.fft.rfft(y_avg)
        bins = np.arange(u_dft.size)
        mag = np.abs(u_dft)
        excited = (bins >= 1) & (mag > threshold * mag.max()) & (mag > 0)
        omega = 2.0 * np.pi * bins[excited] / period
        response = y_dft[excited] / u_dft[excited]
    else:
        allowed = "must be a 1-D array of frequencies in rad/sample in (0, pi]"
        try:
            omega = np.atleast_1d(np.asarray(freqs, dtype=float))
        except (TypeError, ValueError):
            raise not_allowed("freqs", freqs, allowed) from None
        if omega.ndim != 1:
            raise not_allowed("freqs", f"an array of shape {omega.shape}", allowed)
        if not np.all((omega > 0) & (omega <= np.pi)):
            raise not_allowed("freqs", omega, allowed)
        kernel = np.exp(-1j * np.outer(omega, np.arange(period)))
        u_dtft = kernel @ u_avg
        if np.any(np.abs(u_dtft) == 0):
            silent = float(omega[np.abs(u_dtft) == 0][0])
            raise not_allowed("freqs", omega,
                              f"the input has no energy at {silent:.6g} rad/sample; "
                              "give frequencies the input excites")
        response = (kernel @ y_avg) / u_dtft
    return FrequencyResponseData.from_response(omega / ts_f, response)


# ---------------------------------------------------------------------------
# residual analysis
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ResidualAnalysis:
    """Whiteness and input-independence tests of residuals (MATLAB ``resid``).

    Attributes
    ----------
    lags : numpy.ndarray
        ``0..max_lag`` for the autocorrelation.
    autocorrelation : numpy.ndarray
        Normalised ``r_ee(tau) / r_ee(0)``.
    cross_lags : numpy.ndarray
        ``-max_lag..max_lag``.
    cross_correlation : numpy.ndarray
        Normalised ``r_ue(tau) = sum_t u(t) e(t + tau) / sqrt(sum u^2 sum e^2)``;
        positive lags: residual after input (unmodelled dynamics); negative
        lags: input after residual (feedback).
    confidence_bound : float
        99 % band ``2.58 / sqrt(N)`` (for both correlations).
    whiteness_ok : bool
        Autocorrelation inside the band at every lag except 0.
    independence_ok : bool
        Cross-correlation inside the band at every lag.
    n_samples : int
    """

    lags: np.ndarray
    autocorrelation: np.ndarray
    cross_lags: np.ndarray
    cross_correlation: np.ndarray
    confidence_bound: float
    whiteness_ok: bool
    independence_ok: bool
    n_samples: int

    def __repr__(self) -> str:
        return (f"ResidualAnalysis: {self.n_samples} samples, lags up to {int(self.lags[-1])}, 99 % band "
                f"±{self.confidence_bound:.3g}: white: {'yes' if self.whiteness_ok else 'no'}, independent of the "
                f"input: {'yes' if self.independence_ok else 'no'} (every lag inside the band)")


def _correlation(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """``sum_t a(t) b(t + tau)`` for tau = -max_lag..max_lag (no normalisation)."""
    full = scipy.signal.correlate(b, a, mode="full", method="auto")
    centre = a.size - 1
    return full[centre - max_lag:centre + max_lag + 1]


def residual_analysis(e, u, max_lag=25, *, remove_mean=False) -> ResidualAnalysis:
    """Autocorrelation of residuals and cross-correlation with the input.

    A good model leaves residuals that are white (autocorrelation inside the
    99 % band ``2.58/sqrt(N)`` at every lag but 0) and uncorrelated with past
    inputs (cross-correlation inside the band).

    Parameters
    ----------
    e, u : array_like, shape (N,)
        Residuals ``y - y_hat`` and the input.
    max_lag : int
        Largest lag, ``1 <= max_lag < N``.
    remove_mean : bool
        Subtract the means first (default False, as MATLAB ``resid``: a biased
        residual then shows up as correlation).

    Returns
    -------
    ResidualAnalysis

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> res = residual_analysis(rng.standard_normal(2000), rng.standard_normal(2000))
    >>> res.whiteness_ok, res.independence_ok
    (True, True)
    """
    e_arr, u_arr = as_pair(e, u, ("e", "u"))
    n = e_arr.size
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)) or not (
        1 <= max_lag < n
    ):
        raise not_allowed("max_lag", max_lag, f"must be a whole number in [1, {n - 1}] (fewer than the samples)")
    max_lag = int(max_lag)
    e_given, u_given = e_arr, u_arr
    if remove_mean:
        e_arr = e_arr - e_arr.mean()
        u_arr = u_arr - u_arr.mean()
    ee0 = float(e_arr @ e_arr)
    uu0 = float(u_arr @ u_arr)
    for name, given, energy in (("e", e_given, ee0), ("u", u_given, uu0)):
        if energy == 0.0:
            zero = "constant, zero after removing its mean" if remove_mean else "identically zero"
            raise not_allowed(name, given, f"it is {zero}, so its correlations are undefined; "
                                                  "give a signal that varies")
    auto = _correlation(e_arr, e_arr, max_lag)[max_lag:] / ee0
    cross = _correlation(u_arr, e_arr, max_lag) / np.sqrt(ee0 * uu0)
    bound = 2.58 / np.sqrt(n)
    return ResidualAnalysis(
        lags=readonly(np.arange(max_lag + 1)),
        autocorrelation=readonly(auto),
        cross_lags=readonly(np.arange(-max_lag, max_lag + 1)),
        cross_correlation=readonly(cross),
        confidence_bound=float(bound),
        whiteness_ok=bool(np.all(np.abs(auto[1:]) <= bound)),
        independence_ok=bool(np.all(np.abs(cross) <= bound)),
        n_samples=n,
    )
