"""Validation of identified transfer functions: simulation, fit, ETFE, residuals.

The one exact zero-order-hold (ZOH) simulator of a continuous-time transfer
function lives here (:func:`simulate_tf`); :mod:`eha_core.identify.tfest` uses
it for its output-error stage, so the fit reported by the estimator and the
fit reported by :func:`compare` are computed by the same code.

State convention
----------------
Initial states ``x0`` refer to the *observability canonical form* of
``G(s) = num(s) / den(s)`` (Kailath): ``x_1 = y - h_0 u`` and
``x_{i+1} = x_i' - h_i u``, where ``h_k`` are the Markov parameters of the
expansion ``G(s) = sum_k h_k s^-k``. For a strictly proper model
``x0[0] = y(0)``; for an all-pole model ``b / A(s)`` the state is simply
``[y, y', ..., y^(n-1)]`` at ``t = 0`` (position, velocity, acceleration for
the actuator's third-order model).

Input offset
------------
A model may carry a constant input offset ``c`` (in input units, like MATLAB's
``InputOffset``): ``y = G(s) (u + c)``, the offset applied from ``t = 0`` on.
Its response ``c G(s) 1(t)`` is linear in ``c``, as the free response is in
``x0``, so both are estimated together by linear least squares
(:func:`_fit_linear_terms`, shared with :mod:`eha_core.identify.tfest`).

Only numpy and scipy are imported here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._checks import positive_number
import scipy.linalg
import scipy.signal

__all__ = [
    "CompareResult",
    "FrequencyResponseData",
    "ResidualAnalysis",
    "compare",
    "etfe_periodic",
    "fit_percent",
    "frequency_response",
    "residual_analysis",
    "simulate_tf",
]


# ---------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------
def _readonly(array) -> np.ndarray:
    """A read-only float/complex copy, so frozen results stay frozen."""
    out = np.array(array, copy=True)
    out.setflags(write=False)
    return out


def _as_signal(values, name: str, *, allow_2d: bool = False) -> np.ndarray:
    """Validate a finite real 1-D (or 2-D) signal."""
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0:
        raise ValueError(f"{name} must be a 1-D array of samples, got a scalar {arr!r}")
    if arr.ndim > (2 if allow_2d else 1):
        allowed = "1-D or 2-D" if allow_2d else "1-D"
        raise ValueError(f"{name} must be {allowed}, got an array of shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{name} must not be empty, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain only finite values (no NaN or inf)")
    return arr


def _as_ts(ts) -> float:
    return positive_number("ts", ts, "must be a finite sample time > 0 s")


def _as_tf(num, den) -> tuple[np.ndarray, np.ndarray]:
    """Validate and normalise a transfer function: monic ``den``, proper ``num``.

    Leading zeros are stripped from both polynomials (as python-control does).
    """
    den_arr = np.atleast_1d(np.asarray(den, dtype=float))
    num_arr = np.atleast_1d(np.asarray(num, dtype=float))
    if den_arr.ndim != 1 or num_arr.ndim != 1:
        raise ValueError(
            "num and den must be 1-D coefficient sequences in descending powers of s, "
            f"got shapes {num_arr.shape} and {den_arr.shape}"
        )
    if not (np.all(np.isfinite(den_arr)) and np.all(np.isfinite(num_arr))):
        raise ValueError("num and den must contain only finite coefficients")
    nonzero = np.flatnonzero(den_arr)
    if nonzero.size == 0:
        raise ValueError(f"den must have a non-zero coefficient, got {den_arr.tolist()}")
    den_arr = den_arr[nonzero[0]:]
    nonzero = np.flatnonzero(num_arr)
    num_arr = num_arr[nonzero[0]:] if nonzero.size else np.zeros(1)
    if num_arr.size > den_arr.size:
        raise ValueError(
            f"num has degree {num_arr.size - 1} > den degree {den_arr.size - 1}: "
            "the transfer function must be proper (degree of num <= degree of den)"
        )
    lead = den_arr[0]
    return num_arr / lead, den_arr / lead


# ---------------------------------------------------------------------------
# exact ZOH discretisation and simulation (shared with tfest)
# ---------------------------------------------------------------------------
def _markov_parameters(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``h_0..h_n`` of ``num/den = sum h_k s^-k`` (den monic, num padded)."""
    n = den.size - 1
    b = np.zeros(n + 1)
    b[n + 1 - num.size:] = num
    h = np.zeros(n + 1)
    for k in range(n + 1):
        h[k] = b[k] - np.dot(den[1:k + 1], h[k - 1::-1][:k]) if k else b[0]
    return h


def _observability_form(num: np.ndarray, den: np.ndarray):
    """(A, B, C, D) of the observability canonical form (see module docstring)."""
    n = den.size - 1
    h = _markov_parameters(num, den)
    a_mat = np.eye(n, k=1)
    a_mat[-1, :] = -den[:0:-1]  # last row: -a_n, ..., -a_1
    b_vec = h[1:].copy()
    c_vec = np.zeros(n)
    c_vec[0] = 1.0
    return a_mat, b_vec, c_vec, float(h[0])


def _expm_balanced(m: np.ndarray) -> np.ndarray:
    """``expm(m)`` after diagonal balancing.

    Companion matrices of physical models have coefficients spanning many
    orders of magnitude (1, 430.1, 1.721e4, 2437); balancing by a diagonal
    similarity keeps the exponential accurate.
    """
    balanced, t = scipy.linalg.matrix_balance(m, permute=False, separate=True)
    scale = t[0]
    e = _expm_pade13(balanced)
    return e * scale[:, None] / scale[None, :]


_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
           1187353796428800.0, 129060195264000.0, 10559470521600.0,
           670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0,
           16380.0, 182.0, 1.0)


def _expm_pade13(m: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring with the [13/13] Pade
    approximant (Higham 2005, the algorithm behind ``scipy.linalg.expm``).

    Written out with numpy because ``scipy.linalg.expm`` costs 0.5-5 ms per
    call on tiny matrices (BLAS threading overhead) and the estimators call
    it hundreds of times; this takes tens of microseconds for a 5 x 5 matrix.
    """
    b = _PADE13
    norm = np.linalg.norm(m, 1)
    squarings = max(0, int(np.ceil(np.log2(norm / 5.371920351148152)))) if norm > 0 else 0
    a = m / 2.0**squarings
    ident = np.eye(m.shape[0])
    a2 = a @ a
    a4 = a2 @ a2
    a6 = a4 @ a2
    u = a @ (a6 @ (b[13] * a6 + b[11] * a4 + b[9] * a2)
             + b[7] * a6 + b[5] * a4 + b[3] * a2 + b[1] * ident)
    v = (a6 @ (b[12] * a6 + b[10] * a4 + b[8] * a2)
         + b[6] * a6 + b[4] * a4 + b[2] * a2 + b[0] * ident)
    r = np.linalg.solve(v - u, v + u)
    for _ in range(squarings):
        r = r @ r
    return r


def _zoh_matrices(a_mat: np.ndarray, b_vec: np.ndarray, ts: float):
    """Exact ZOH discretisation ``(Ad, Bd)`` via the augmented exponential."""
    n = a_mat.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n] = a_mat * ts
    m[:n, n] = b_vec * ts
    e = _expm_balanced(m)
    return e[:n, :n], e[:n, n]


def _state_numerators(ad: np.ndarray, bd: np.ndarray, den_z: np.ndarray,
                      c_mat: np.ndarray, d_vec: np.ndarray) -> np.ndarray:
    """Numerators over ``den_z`` of ``c_mat (zI - Ad)^-1 bd + d_vec``, one per row.

    Uses the Markov parameters ``g_0 = d``, ``g_k = C Ad^(k-1) bd`` and
    ``num = (den_z * g)`` truncated to ``n + 1`` terms.
    """
    n = ad.shape[0]
    g = np.empty((c_mat.shape[0], n + 1))
    g[:, 0] = d_vec
    v = bd.copy()
    for k in range(1, n + 1):
        g[:, k] = c_mat @ v
        v = ad @ v
    num = np.zeros_like(g)
    for k in range(n + 1):
        num[:, k] = g[:, k::-1] @ den_z[:k + 1]
    return num


@dataclass(frozen=True, eq=False)
class _DiscreteModel:
    """Exact ZOH equivalent of ``num/den``: state space and ``num_z/den_z``."""

    ad: np.ndarray
    bd: np.ndarray
    c: np.ndarray
    d: float
    num_z: np.ndarray
    den_z: np.ndarray

    @property
    def order(self) -> int:
        return self.ad.shape[0]

    def forced(self, u: np.ndarray) -> np.ndarray:
        """Zero-state response to the ZOH input ``u`` (C speed via lfilter)."""
        if self.order == 0:
            return self.d * u
        return scipy.signal.lfilter(self.num_z, self.den_z, u)

    def free_basis(self, n_samples: int) -> np.ndarray:
        """``O[k, i] = C Ad^k e_i``: the free response is ``O @ x0``."""
        n = self.order
        obs = np.empty((n + 1, n))
        row = self.c.copy()
        for k in range(n + 1):
            obs[k] = row
            row = row @ self.ad
        impulse = np.zeros(n_samples)
        impulse[0] = 1.0
        basis = np.empty((n_samples, n))
        for i in range(n):
            num_i = np.array([obs[k::-1, i] @ self.den_z[:k + 1] for k in range(n + 1)])
            basis[:, i] = scipy.signal.lfilter(num_i, self.den_z, impulse)
        return basis


def _discretise(num: np.ndarray, den: np.ndarray, ts: float) -> _DiscreteModel:
    """ZOH discretisation of a normalised (monic, proper) transfer function."""
    n = den.size - 1
    if n == 0:
        gain = float(num[-1])
        empty = np.zeros((0, 0))
        return _DiscreteModel(empty, np.zeros(0), np.zeros(0), gain,
                              np.array([gain]), np.array([1.0]))
    a_mat, b_vec, c_vec, d = _observability_form(num, den)
    ad, bd = _zoh_matrices(a_mat, b_vec, ts)
    den_z = np.real(np.poly(np.linalg.eigvals(ad)))
    num_z = _state_numerators(ad, bd, den_z, c_vec[None, :], np.array([d]))[0]
    return _DiscreteModel(ad, bd, c_vec, d, num_z, den_z)


def _linear_columns(model: _DiscreteModel, n_samples: int, *, offset: bool,
                    x0: bool) -> np.ndarray:
    """Responses that enter the output linearly: ``[step, free basis]``.

    Column 0 (with ``offset``) is the ZOH-exact unit-step response, the
    response to a unit input offset; then (with ``x0``) the ``n`` columns of
    :meth:`_DiscreteModel.free_basis`. Shape ``(n_samples, k)``.
    """
    cols = []
    if offset:
        cols.append(model.forced(np.ones(n_samples))[:, None])
    if x0 and model.order:
        cols.append(model.free_basis(n_samples))
    return np.hstack(cols) if cols else np.zeros((n_samples, 0))


def _fit_linear_terms(columns: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of ``columns`` for ``residual``.

    The columns are normalised first: the step response of an integrating or
    slow model can be orders of magnitude larger than the free responses, and
    the rank cut-off of :func:`numpy.linalg.lstsq` is relative to the largest
    singular value.
    """
    if columns.shape[1] == 0:
        return np.zeros(0)
    norms = np.linalg.norm(columns, axis=0)
    norms[(norms == 0) | ~np.isfinite(norms)] = 1.0
    coef, *_ = np.linalg.lstsq(columns / norms, residual, rcond=None)
    return coef / norms


def simulate_tf(num, den, u, ts, x0=None) -> np.ndarray:
    """Exact zero-order-hold response of a continuous-time transfer function.

    The input is held constant between samples (ZOH), so the sampled output
    is exact: the model is discretised with the matrix exponential of the
    augmented state matrix and simulated with :func:`scipy.signal.lfilter`.
    Integrators and poles faster than the Nyquist frequency are handled.

    Parameters
    ----------
    num, den : array_like
        Coefficients in descending powers of s; ``len(num) <= len(den)``.
    u : array_like, shape (N,)
        Input samples ``u[k] = u(k ts)``, held over ``[k ts, (k+1) ts)``.
    ts : float
        Sampling time in seconds.
    x0 : array_like, shape (n,), optional
        Initial state of the observability canonical form (see the module
        docstring; for ``b / A(s)`` it is ``[y, y', ...]`` at t = 0).
        Default: zero.

    Returns
    -------
    numpy.ndarray, shape (N,)
        Output samples ``y(k ts)``.

    Examples
    --------
    >>> import numpy as np
    >>> y = simulate_tf([2.0], [1.0, 2.0], np.ones(4), ts=0.5)
    >>> np.allclose(y, 1.0 - np.exp(-2.0 * 0.5 * np.arange(4)))
    True
    >>> simulate_tf([1.0], [1.0, 0.0], np.zeros(3), ts=0.1, x0=[2.0])
    array([2., 2., 2.])
    """
    num_n, den_n = _as_tf(num, den)
    u_arr = _as_signal(u, "u")
    model = _discretise(num_n, den_n, _as_ts(ts))
    y = model.forced(u_arr)
    if x0 is not None:
        x0_arr = np.atleast_1d(np.asarray(x0, dtype=float))
        if x0_arr.shape != (model.order,):
            raise ValueError(
                f"x0 must have shape ({model.order},) (one entry per pole), "
                f"got shape {x0_arr.shape}"
            )
        if model.order:
            y = y + model.free_basis(u_arr.size) @ x0_arr
    return y


# ---------------------------------------------------------------------------
# fit and compare
# ---------------------------------------------------------------------------
def fit_percent(y, y_hat):
    """Normalised root-mean-square fit in percent, exactly as MATLAB ``compare``.

    ``fit = 100 (1 - ||y - y_hat|| / ||y - mean(y)||)``, per column for 2-D
    input. 100 is a perfect fit; 0 is no better than the mean; it can be
    negative. A constant ``y`` gives ``-inf`` (or ``nan`` if ``y_hat == y``),
    as MATLAB does.

    Parameters
    ----------
    y, y_hat : array_like, shape (N,) or (N, ny)
        Measured and simulated outputs.

    Returns
    -------
    float or numpy.ndarray
        Fit in percent (an array of ``ny`` values for 2-D input).

    Examples
    --------
    >>> fit_percent([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    100.0
    >>> round(fit_percent([0.0, 2.0], [0.5, 1.5]), 6)
    50.0
    """
    y_arr = _as_signal(y, "y", allow_2d=True)
    y_hat_arr = _as_signal(y_hat, "y_hat", allow_2d=True)
    if y_arr.shape != y_hat_arr.shape:
        raise ValueError(
            f"y_hat must have the same shape as y {y_arr.shape}, got {y_hat_arr.shape}"
        )
    err = np.linalg.norm(y_arr - y_hat_arr, axis=0)
    spread = np.linalg.norm(y_arr - y_arr.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        fit = 100.0 * (1.0 - err / spread)
    return float(fit) if np.ndim(fit) == 0 else fit


@dataclass(frozen=True, eq=False)
class CompareResult:
    """Simulated output of a model against measured data (MATLAB ``compare``).

    Attributes
    ----------
    y_hat : numpy.ndarray
        Simulated output (ZOH input).
    fit_percent : float
        ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)``.
    initial_condition : str
        ``"zero"``, ``"estimated"`` (least squares) or ``"given"``.
    x0 : numpy.ndarray or None
        Initial state used (observability canonical form); None when zero.
    input_offset : float or None
        Constant input offset ``c`` used, in input units (``y_hat`` is the
        response to ``u + c``); None when no offset was applied.
    """

    y_hat: np.ndarray
    fit_percent: float
    initial_condition: str
    x0: np.ndarray | None
    input_offset: float | None = None


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
    raise ValueError(
        f"input_offset must be 'zero', 'estimate', None or a finite number (input units), "
        f"got {input_offset!r}"
    )


def compare(num, den, u, y, ts, initial_condition="zero", input_offset="zero") -> CompareResult:
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

    Returns
    -------
    CompareResult

    Examples
    --------
    >>> import numpy as np
    >>> u = np.ones(50)
    >>> y = simulate_tf([1.0], [1.0, 1.0], u, 0.1, x0=[0.5])
    >>> compare([1.0], [1.0, 1.0], u, y, 0.1).fit_percent < 90
    True
    >>> res = compare([1.0], [1.0, 1.0], u, y, 0.1, initial_condition="estimate")
    >>> round(res.fit_percent, 6), np.round(res.x0, 6)
    (100.0, array([0.5]))
    >>> y = simulate_tf([1.0], [1.0, 1.0], u - 0.2, 0.1)  # an offset of -0.2 on u
    >>> res = compare([1.0], [1.0, 1.0], u, y, 0.1, input_offset="estimate")
    >>> round(res.fit_percent, 6), round(res.input_offset, 6)
    (100.0, -0.2)
    """
    num_n, den_n = _as_tf(num, den)
    u_arr = _as_signal(u, "u")
    y_arr = _as_signal(y, "y")
    if u_arr.shape != y_arr.shape:
        raise ValueError(f"y must have the same length as u ({u_arr.size}), got {y_arr.size}")
    estimate_offset, offset = _check_compare_offset(input_offset)
    model = _discretise(num_n, den_n, _as_ts(ts))
    x0 = None
    estimate_x0 = False
    if isinstance(initial_condition, str):
        if initial_condition == "estimate":
            label = "estimated"
            estimate_x0 = model.order > 0
        elif initial_condition == "zero":
            label = "zero"
        else:
            raise ValueError(
                f"initial_condition must be 'zero', 'estimate' or an array of "
                f"{model.order} initial states, got {initial_condition!r}"
            )
    else:
        x0 = np.atleast_1d(np.asarray(initial_condition, dtype=float))
        if x0.shape != (model.order,):
            raise ValueError(
                f"initial_condition must be 'zero', 'estimate' or an array of "
                f"{model.order} initial states, got shape {x0.shape}"
            )
        label = "given"
    y_hat = model.forced(u_arr if offset is None else u_arr + offset)
    if x0 is not None:
        y_hat = y_hat + model.free_basis(u_arr.size) @ x0
    if estimate_offset or estimate_x0:
        # the offset's and the initial state's responses are linear: one
        # least-squares problem for both
        columns = _linear_columns(model, u_arr.size, offset=estimate_offset, x0=estimate_x0)
        coef = _fit_linear_terms(columns, y_arr - y_hat)
        y_hat = y_hat + columns @ coef
        if estimate_offset:
            offset = float(coef[0])
        if estimate_x0:
            x0 = coef[int(estimate_offset):]
    return CompareResult(
        y_hat=_readonly(y_hat),
        fit_percent=fit_percent(y_arr, y_hat),
        initial_condition=label,
        x0=None if x0 is None else _readonly(x0),
        input_offset=offset,
    )


# ---------------------------------------------------------------------------
# frequency domain
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FrequencyResponseData:
    """Complex frequency response with Bode-ready magnitude and phase.

    Attributes
    ----------
    w : numpy.ndarray
        Frequencies in rad/s.
    response : numpy.ndarray
        Complex values ``G(j w)``.
    magnitude_db : numpy.ndarray
        ``20 log10 |G|``.
    phase_deg : numpy.ndarray
        Phase in degrees, unwrapped along ``w``.
    """

    w: np.ndarray
    response: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray

    @classmethod
    def from_response(cls, w, response) -> FrequencyResponseData:
        response = np.asarray(response, dtype=complex)
        with np.errstate(divide="ignore"):
            magnitude_db = 20.0 * np.log10(np.abs(response))
        phase_deg = np.degrees(np.unwrap(np.angle(response))) if response.size else response.real
        return cls(_readonly(np.asarray(w, dtype=float)), _readonly(response),
                   _readonly(magnitude_db), _readonly(phase_deg))


def frequency_response(num, den, w) -> FrequencyResponseData:
    """Frequency response ``G(j w)`` of a continuous-time transfer function.

    Parameters
    ----------
    num, den : array_like
        Coefficients, descending powers of s.
    w : array_like
        Frequencies in rad/s.

    Returns
    -------
    FrequencyResponseData
        ``w``, complex ``response``, ``magnitude_db`` and unwrapped
        ``phase_deg``.

    Examples
    --------
    >>> fr = frequency_response([1.0], [1.0, 1.0], [1.0])
    >>> round(float(fr.magnitude_db[0]), 3), round(float(fr.phase_deg[0]), 3)
    (-3.01, -45.0)
    """
    num_n, den_n = _as_tf(num, den)
    w_arr = np.atleast_1d(np.asarray(w, dtype=float))
    if w_arr.ndim != 1 or not np.all(np.isfinite(w_arr)):
        raise ValueError(f"w must be a 1-D array of finite frequencies in rad/s, got {w!r}")
    s = 1j * w_arr
    return FrequencyResponseData.from_response(w_arr, np.polyval(num_n, s) / np.polyval(den_n, s))


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
    u_arr = _as_signal(u, "u")
    y_arr = _as_signal(y, "y")
    if u_arr.shape != y_arr.shape:
        raise ValueError(f"y must have the same length as u ({u_arr.size}), got {y_arr.size}")
    ts_f = _as_ts(ts)
    if isinstance(period, bool) or not isinstance(period, (int, np.integer)) or not (
        2 <= period <= u_arr.size
    ):
        raise ValueError(
            f"period must be an integer number of samples in [2, {u_arr.size}], got {period!r}"
        )
    n_periods = u_arr.size // period
    if isinstance(drop_periods, bool) or not isinstance(drop_periods, (int, np.integer)) or not (
        0 <= drop_periods < n_periods
    ):
        raise ValueError(
            f"drop_periods must be an integer in [0, {n_periods - 1}] (the data hold "
            f"{n_periods} whole periods), got {drop_periods!r}"
        )
    first = int(drop_periods)
    if not (np.isfinite(threshold) and 0.0 <= threshold < 1.0):
        raise ValueError(f"threshold must be in [0, 1), got {threshold!r}")
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
        omega = np.atleast_1d(np.asarray(freqs, dtype=float))
        if omega.ndim != 1 or not np.all((omega > 0) & (omega <= np.pi)):
            raise ValueError(f"freqs must be frequencies in rad/sample in (0, pi], got {freqs!r}")
        kernel = np.exp(-1j * np.outer(omega, np.arange(period)))
        u_dtft = kernel @ u_avg
        if np.any(np.abs(u_dtft) == 0):
            raise ValueError("freqs contains a frequency at which the input has no energy")
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
    e_arr = _as_signal(e, "e")
    u_arr = _as_signal(u, "u")
    if e_arr.shape != u_arr.shape:
        raise ValueError(f"u must have the same length as e ({e_arr.size}), got {u_arr.size}")
    n = e_arr.size
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)) or not (
        1 <= max_lag < n
    ):
        raise ValueError(f"max_lag must be an integer in [1, {n - 1}], got {max_lag!r}")
    max_lag = int(max_lag)
    if remove_mean:
        e_arr = e_arr - e_arr.mean()
        u_arr = u_arr - u_arr.mean()
    ee0 = float(e_arr @ e_arr)
    uu0 = float(u_arr @ u_arr)
    if ee0 == 0.0 or uu0 == 0.0:
        raise ValueError("e and u must not be identically zero (correlations undefined)")
    auto = _correlation(e_arr, e_arr, max_lag)[max_lag:] / ee0
    cross = _correlation(u_arr, e_arr, max_lag) / np.sqrt(ee0 * uu0)
    bound = 2.58 / np.sqrt(n)
    return ResidualAnalysis(
        lags=_readonly(np.arange(max_lag + 1)),
        autocorrelation=_readonly(auto),
        cross_lags=_readonly(np.arange(-max_lag, max_lag + 1)),
        cross_correlation=_readonly(cross),
        confidence_bound=float(bound),
        whiteness_ok=bool(np.all(np.abs(auto[1:]) <= bound)),
        independence_ok=bool(np.all(np.abs(cross) <= bound)),
        n_samples=n,
    )
