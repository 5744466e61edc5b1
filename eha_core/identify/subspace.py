"""Subspace identification of a state-space model (MATLAB ``n4sid``).

:func:`n4sid` estimates the innovation form

    x(t+1) = A x(t) + B u(t) + K e(t),
    y(t)   = C x(t) + D u(t) + e(t),

from block Hankel matrices of the data (van Overschee & De Moor, *Subspace
Identification for Linear Systems*, Kluwer 1996; Verhaegen, "Identification of
the deterministic part of MIMO state space models given in innovations form
from input-output data", Automatica 30, 1994):

1. past and future Hankel matrices ``U_p, Y_p, U_f, Y_f`` of ``horizon`` block
   rows each, one set per experiment, their columns stacked;
2. an LQ factorisation of ``[U_f; W_p; Y_f]`` (``W_p = [U_p; Y_p]``, the past as
   instrument): the block ``L32`` spans ``Y_f`` projected on the past with the
   future inputs removed, whose column space is the extended observability
   matrix ``Gamma`` (PO-MOESP; consistent for any noise independent of the input,
   whatever the horizon);
3. an SVD of ``W1 L32`` (``W1 = I`` for ``weighting="moesp"``,
   ``(Y_f Pi_Uf^perp Y_f^T)^(-1/2)`` for ``"cva"``, canonical variate analysis;
   ``"auto"``, the default, is CVA unless the data are noise-free): its
   singular values show the order (:func:`ss_order_svd`), its first ``n`` left
   vectors give ``Gamma``;
4. ``C`` is the first row of ``Gamma`` and ``A`` solves the shift equation
   ``Gamma_up A = Gamma_down`` by least squares;
5. ``B``, ``D`` (and the initial state of each experiment with
   ``initial="estimate"``) by linear least squares on the output, which is linear in them
   once ``A`` and ``C`` are fixed;
6. ``K`` from the state sequence ``X = Gamma^+ O`` (``O`` the oblique projection
   of ``Y_f`` on the past along ``U_f``): the covariances of the residuals of
   ``[x(t+1); y(t)] = [A B; C D] [x(t); u(t)]`` give ``Q, S, R`` and the
   stationary Kalman gain from the Riccati equation.

The estimate's parameters (:attr:`StateSpaceModel.params`) are those of the
observable canonical form, i.e. the coefficients of ``G = b/a`` and
``H = c/a`` (an ARMAX model with ``na = nb = nc = n``); their covariance is
``sigma^2 (J^T J)^-1`` with ``J`` the analytic Jacobian of the one-step
prediction errors ``e = (a y - b u) / c`` with respect to them at the
estimate: the asymptotic covariance a prediction-error estimate of the same
model would have (n4sid itself is not a prediction-error method).

Only numpy and scipy are imported here (python-control lazily, in
:meth:`StateSpaceModel.to_control`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal

from .._checks import not_allowed, whole_number
from ._ctmodels import state_numerators
from .blackbox import INITIAL_CONDITIONS, Comparison, Criteria, EstimateFields, IdData, LinearModel, compare, criteria

__all__ = ["StateSpaceModel", "n4sid", "ss_order_svd", "WEIGHTINGS"]

#: The weightings of the SVD: MOESP (``W1 = I``), canonical variate analysis, or CVA unless the data are
#: noise-free (then MOESP; MATLAB's ``N4Weight = 'auto'`` also chooses between the two).
WEIGHTINGS = ("auto", "moesp", "cva")

#: A pole this far outside the unit circle is unstable, not an integrator estimated with noise.
_UNSTABLE_RADIUS = 1.005


@dataclass(frozen=True, eq=False, repr=False)
class StateSpaceModel(EstimateFields, LinearModel):
    """A discrete-time state-space model in innovation form, estimated by :func:`n4sid`.

    ``x(t+1) = A x + B u + K e``, ``y = C x + D u + e``. Like
    :class:`scipy.optimize.OptimizeResult`, a failed estimate is data:
    ``success`` is False and ``message`` says why and what to try.

    Attributes
    ----------
    A, B, C, D, K : numpy.ndarray
        Shapes ``(n, n)``, ``(n, 1)``, ``(1, n)``, ``(1, 1)``, ``(n, 1)``.
    x0 : numpy.ndarray
        Initial state of each experiment, shape ``(n_experiments, n)`` (zeros with
        ``initial="zero"``).
    singular_values : numpy.ndarray
        The SVD's singular values (``horizon`` of them), for choosing ``n``.
    horizon : int
        Past and future block rows of the Hankel matrices.
    weighting : str
        The weighting used, ``"moesp"`` or ``"cva"``.
    structure, name, orders, ts, params, param_names, covariance, noise_variance, criteria, fit, initial,
    n_samples, success, message, nfev
        As every estimate (:class:`~eha_core.identify.blackbox.EstimateFields`); ``params`` are
        ``a1..an, b1..bn`` (``b0`` first with a feedthrough), ``c1..cn``; ``fit`` is the one-step
        prediction (the criterion of a model with a noise model, MATLAB's ``Focus = 'prediction'``).
    """

    structure: str
    name: str
    orders: dict
    ts: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    K: np.ndarray
    x0: np.ndarray
    singular_values: np.ndarray
    horizon: int
    weighting: str
    params: np.ndarray
    param_names: tuple
    covariance: np.ndarray
    noise_variance: float
    criteria: Criteria
    fit: Comparison
    initial: str
    n_samples: int
    success: bool
    message: str
    nfev: int = 0

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    def g_poly(self) -> tuple[np.ndarray, np.ndarray]:
        """``(gb, ga)`` of ``G = C (qI - A)^-1 B + D`` in ascending powers of ``q^-1``.

        ``scipy.signal.ss2tf`` gives descending powers of ``z`` with numerator and denominator of the
        same length, which are ascending powers of ``q^-1`` (``gb[0] = D``).
        """
        num, den = scipy.signal.ss2tf(self.A, self.B, self.C, self.D)
        return np.asarray(num[0], float), np.asarray(den, float)

    def h_poly(self) -> tuple[np.ndarray, np.ndarray]:
        """``(hc, hd)`` of ``H = C (qI - A)^-1 K + 1``; ``hc = det(qI - A + K C)``, ``hd = det(qI - A)``."""
        num, den = scipy.signal.ss2tf(self.A, self.K, self.C, np.ones((1, 1)))
        return np.asarray(num[0], float), np.asarray(den, float)

    def to_control(self):
        """The model from ``u`` to ``y`` as :class:`control.StateSpace` ``(A, B, C, D)``, ``dt = ts``."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, self.ts)


# ---------------------------------------------------------------------------
# arguments
# ---------------------------------------------------------------------------
def _check_data(data) -> IdData:
    if not isinstance(data, IdData):
        raise not_allowed("data", data, "an IdData (eha_core.identify.blackbox.IdData)")
    return data


def _check_initial(initial) -> str:
    if initial not in INITIAL_CONDITIONS:
        raise not_allowed("initial", initial, "zero or estimate")
    return initial


def _checked_horizon(data: IdData, n: int, horizon, n_name: str) -> int:
    """The horizon (default ``max(2 n, 10)``, shortened to what the record holds), checked against ``n``."""
    longest = max(y.size for y, _u in data.segments())
    if horizon is None:
        # default: twice the order and at least 10 block rows, but leave >= 4 columns per row of the LQ
        horizon = max(2 * n, 10)
        while horizon > n + 1 and _n_columns(data, horizon) < 8 * horizon:
            horizon -= 1
    else:
        horizon = whole_number("horizon", horizon, 2)
    if n >= horizon:
        raise not_allowed(n_name, n, f"the order must be below the horizon ({horizon} block rows): "
                                     f"give a longer horizon or a lower order")
    if 2 * horizon + 1 > longest:
        raise not_allowed("horizon", horizon, f"the longest experiment ({longest} samples) holds a horizon of at "
                                              f"most {(longest - 1) // 2}")
    if _n_columns(data, horizon) < 4 * horizon:
        raise not_allowed(n_name, n, f"the record ({data.n_samples} samples) is too short for order {n} with "
                                     f"horizon {horizon}: it needs about {6 * horizon} samples")
    return horizon


def _n_columns(data: IdData, horizon: int) -> int:
    return sum(max(0, y.size - 2 * horizon + 1) for y, _u in data.segments())


# ---------------------------------------------------------------------------
# the subspace steps
# ---------------------------------------------------------------------------
def _hankel_r(data: IdData, horizon: int):
    """The R factor of ``[U_f; U_p; Y_p; Y_f]^T`` (L = R^T) and the stacked Hankel matrix, per experiment.

    Returns ``(r, blocks)``: ``blocks`` is a list of ``(first_time, hankel)`` with ``hankel`` of shape
    ``(4 horizon, columns)`` (rows ``U_f, U_p, Y_p, Y_f``) and ``first_time`` the sample of the first
    future row's first column, for the experiments long enough for the horizon."""
    i = horizon
    blocks = []
    for y, u in data.segments():
        j = y.size - 2 * i + 1
        if j <= 0:
            continue  # too short for this horizon: it still counts in B, D and the fit
        uh = np.lib.stride_tricks.sliding_window_view(u, j)[:2 * i]
        yh = np.lib.stride_tricks.sliding_window_view(y, j)[:2 * i]
        blocks.append(np.vstack([uh[i:], uh[:i], yh[:i], yh[i:]]))
    # the LQ factorisation of the stacked matrix, as the QR of its transpose; the factors Q are not needed.
    # Tall-skinny QR (Demmel et al. 2012): the R factors of blocks of 1024 columns, stacked, factorised
    # again give the same R (up to signs) as stably, without the threaded LAPACK call on the whole
    # matrix that costs ten times more on a busy machine.
    partial = [np.linalg.qr(block[:, k:k + 1024].T, mode="r") for block in blocks
               for k in range(0, block.shape[1], 1024)]
    r = np.linalg.qr(np.vstack(partial), mode="r") if len(partial) > 1 else partial[0]
    if r.shape[0] < r.shape[1]:             # fewer columns than rows in total (refused before; be safe)
        r = np.vstack([r, np.zeros((r.shape[1] - r.shape[0], r.shape[1]))])
    return r, blocks


def _observability(r: np.ndarray, horizon: int, n: int, weighting: str):
    """``(Gamma, singular_values, problem, weighting used)`` from the LQ factor (step 3)."""
    i = horizon
    l32 = r[i:3 * i, 3 * i:].T                     # Y_f on the past, orthogonal to U_f
    if weighting in ("cva", "auto"):
        l33 = r[3 * i:, 3 * i:].T
        cov = l32 @ l32.T + l33 @ l33.T             # Y_f Pi_Uf^perp Y_f^T
        w, v = np.linalg.eigh(cov)
        singular = w[0] <= 1e-10 * max(w[-1], 1e-300)
        if singular and weighting == "cva":
            return None, np.zeros(i), ("the future outputs' covariance is singular (noise-free data?): "
                                       "CVA needs noise; use weighting='moesp'"), weighting
        weighting = "moesp" if singular else "cva"
    if weighting == "cva":
        w_half = (v / np.sqrt(w)) @ v.T
        w_half_inv = (v * np.sqrt(w)) @ v.T
        left, sv, _ = np.linalg.svd(w_half @ l32)
        gamma = w_half_inv @ left[:, :n] * np.sqrt(sv[:n])
    else:
        left, sv, _ = np.linalg.svd(l32)
        gamma = left[:, :n] * np.sqrt(sv[:n])
    sv = np.pad(sv, (0, max(0, i - sv.size)))
    if n and sv[n - 1] <= 1e-12 * sv[0]:
        return gamma, sv, (f"the data show fewer than {n} states (singular value {n} is "
                           f"{sv[n - 1]:.3g}, the first {sv[0]:.3g}): choose a lower order"), weighting
    return gamma, sv, "", weighting


def _output_regressors(a_mat, c_mat, data: IdData, feedthrough: bool, initial: str):
    """Columns of the output's regression on ``B`` (``D``) and each experiment's ``x0`` (step 5)."""
    n = a_mat.shape[0]
    den = np.real(np.poly(a_mat))
    # numerators of C (zI - A)^-1 e_j for every j at once: the transposed system, one input C^T
    nums = state_numerators(a_mat.T, c_mat.ravel().copy(), den, np.eye(n), np.zeros(n))
    segs = data.segments()
    n_x0 = n * len(segs) if initial == "estimate" else 0
    cols = np.zeros((data.n_samples, n + int(feedthrough) + n_x0))
    at = 0
    for s, (y, u) in enumerate(segs):
        rows = slice(at, at + y.size)
        for j in range(n):
            cols[rows, j] = scipy.signal.lfilter(nums[j], den, u)
        if feedthrough:
            cols[rows, n] = u
        if n_x0:
            impulse = np.zeros(y.size + 1)
            impulse[0] = 1.0
            for j in range(n):
                # C A^t e_j is the impulse response of C (zI - A)^-1 e_j one sample on
                cols[rows, n + int(feedthrough) + s * n + j] = scipy.signal.lfilter(nums[j], den, impulse)[1:]
        at += y.size
    return cols


def _kalman_gain(a_mat, b_mat, c_mat, d_mat, gamma, r, blocks, horizon):
    """``(K, problem)`` from the state sequence's residual covariances and the Riccati equation (step 6)."""
    i = horizon
    n = a_mat.shape[0]
    # oblique projection of Y_f on W_p along U_f: regress Y_f on [U_f; W_p] (min-norm: W_p may be rank
    # deficient on noise-free data), keep the W_p part
    coef, *_ = np.linalg.lstsq(r[:3 * i, :3 * i], r[:3 * i, 3 * i:], rcond=1e-10)
    lw = coef[i:3 * i].T
    gamma_pinv = np.linalg.pinv(gamma)
    ws, vs = [], []
    for block in blocks:
        x = gamma_pinv @ (lw @ block[i:3 * i])      # states at the future's first samples, consecutive
        u_now = block[0]
        y_now = block[3 * i]
        ws.append(x[:, 1:] - a_mat @ x[:, :-1] - b_mat @ u_now[None, :-1])
        vs.append(y_now - (c_mat @ x)[0] - d_mat[0, 0] * u_now)
    w = np.hstack(ws)
    v = np.hstack([vv[None, :-1] for vv in vs])     # the rows paired with w (last column has no successor)
    m = w.shape[1]
    q_cov, s_cov, r_cov = w @ w.T / m, w @ v.T / m, float((v @ v.T)[0, 0]) / m
    if not np.all(np.isfinite(q_cov)) or not math.isfinite(r_cov):
        return np.zeros((n, 1)), "the residual covariance of the state sequence is not finite"
    output_power = float(np.mean(np.concatenate([block[3 * i] for block in blocks]) ** 2))
    if r_cov <= 1e-16 * max(output_power, 1e-300):
        return np.zeros((n, 1)), ""     # noise-free data: no noise to model, K = 0
    try:
        # the filter's Riccati equation (the dual of control's): P = A P A' - (A P C' + S)(C P C' + R)^-1 (...)' + Q
        p = scipy.linalg.solve_discrete_are(a_mat.T, c_mat.T, q_cov, np.array([[r_cov]]), s=s_cov)
        k = (a_mat @ p @ c_mat.T + s_cov) / float((c_mat @ p @ c_mat.T)[0, 0] + r_cov)
    except (np.linalg.LinAlgError, ValueError):
        # no stabilising solution (Q - S R^-1 S' not positive semidefinite in a short record):
        # the state sequence is then the Kalman filter's own, and its gain is S R^-1
        k = s_cov / r_cov
    if np.max(np.abs(np.linalg.eigvals(a_mat - k @ c_mat)), initial=0.0) >= 1.0:
        return k, "the noise model's predictor A - K C is unstable"
    return k, ""


def _pem_covariance(hc, data: IdData, feedthrough: bool, e_all: np.ndarray, n: int, variance: float):
    """``sigma^2 (J^T J)^-1`` of ``[a, b, c]`` from the analytic Jacobian of ``e = (a y - b u) / c``."""
    n_b = n + int(feedthrough)
    jac = np.zeros((data.n_samples, 2 * n + n_b))
    at = 0
    for (y, u) in data.segments():
        rows = slice(at, at + y.size)
        e = e_all[rows]
        yf = scipy.signal.lfilter([1.0], hc, y)
        uf = scipy.signal.lfilter([1.0], hc, u)
        ef = scipy.signal.lfilter([1.0], hc, e)
        for k in range(1, n + 1):                   # de/da_k = q^-k y / c
            jac[at + k:at + y.size, k - 1] = yf[:y.size - k]
        for idx, k in enumerate(range(0 if feedthrough else 1, n + 1)):   # de/db_k = -q^-k u / c
            jac[at + k:at + y.size, n + idx] = -uf[:y.size - k]
        for k in range(1, n + 1):                   # de/dc_k = -q^-k e / c
            jac[at + k:at + y.size, n + n_b + k - 1] = -ef[:y.size - k]
        at += y.size
    info = jac.T @ jac
    if not np.all(np.isfinite(info)):
        return np.full(info.shape, np.nan), "the prediction errors' Jacobian is not finite"
    if variance <= 1e-24 * max(float(np.mean(data.y ** 2)), 1e-300):
        # noise-free data: the model is exact, the noise model's c is not identifiable (e = 0) and
        # every variance is zero to rounding
        return variance * np.linalg.pinv(info), ""
    try:
        cov = variance * np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return np.full(info.shape, np.nan), "the parameters' information matrix is singular: choose a lower order"
    if np.linalg.cond(info) > 1e14:
        return cov, "the parameters' information matrix is close to singular: choose a lower order"
    return cov, ""


def _output_grows(data: IdData) -> bool:
    """Whether the output of some experiment grows like an unstable system's (last quarter >> first)."""
    for y, _u in data.segments():
        q = max(y.size // 4, 1)
        first, last = np.sqrt(np.mean(y[:q] ** 2)), np.sqrt(np.mean(y[-q:] ** 2))
        if last > 10.0 * max(first, 1e-300):
            return True
    return False


# ---------------------------------------------------------------------------
# public functions
# ---------------------------------------------------------------------------
def ss_order_svd(data: IdData, max_order: int, horizon=None) -> np.ndarray:
    """The subspace SVD's singular values, for choosing the order (MATLAB ``n4sid(data, 1:max_order)``).

    A clear gap after the ``n``-th value says the data show ``n`` states.

    Parameters
    ----------
    data : IdData
        One or several experiments.
    max_order : int
        The highest order considered (it fixes the default horizon, ``max(2 max_order, 10)``).
    horizon : int, optional
        Block rows of the past and future Hankel matrices; must exceed ``max_order``.

    Returns
    -------
    numpy.ndarray
        The ``horizon`` singular values (MOESP weighting), largest first.

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> u = np.random.default_rng(0).standard_normal(500)
    >>> y = scipy.signal.lfilter([0, 1.0, 0.5], [1, -1.5, 0.7], u)
    >>> sv = ss_order_svd(IdData(y, u, 0.1), 4)
    >>> bool(sv[1] > 1e6 * sv[2])
    True
    """
    data = _check_data(data)
    max_order = whole_number("max_order", max_order, 1)
    i = _checked_horizon(data, max_order, horizon, "max_order")
    r, _blocks = _hankel_r(data, i)
    _gamma, sv, _problem, _used = _observability(r, i, 1, "moesp")
    return sv


def n4sid(data: IdData, n: int, *, horizon=None, weighting: str = "auto", feedthrough: bool = False,
          initial: str = "zero") -> StateSpaceModel:
    """A state-space model of order ``n`` by subspace identification (MATLAB ``n4sid``).

    Parameters
    ----------
    data : IdData
        One or several experiments (their Hankel matrices are stacked; no false transient joins them).
    n : int
        The order (number of states), >= 1 and below ``horizon``.
    horizon : int, optional
        Past and future block rows of the Hankel matrices; default ``max(2 n, 10)`` (fewer when the
        record is short).
    weighting : {"auto", "cva", "moesp"}
        The SVD's weighting. ``"cva"`` (canonical variate analysis) has the smaller finite-sample bias
        and variance with noise (with innovation noise at 1000 samples, MOESP's poles were biased by
        half a standard deviation, CVA's not) but needs noise; ``"moesp"`` works on noise-free data
        too. ``"auto"`` (default): CVA, or MOESP when the future outputs' covariance is singular
        (noise-free data). The result's ``weighting`` says which was used.
    feedthrough : bool
        Estimate ``D`` (default False: ``D = 0``, the input acts one sample later, as for a sampled
        physical system).
    initial : {"zero", "estimate"}
        The initial state of each experiment: zero, or estimated with ``B`` and ``D``.

    Returns
    -------
    StateSpaceModel
        ``success`` False with a message when the estimate cannot be trusted (an unstable ``A`` from data
        that do not grow, a singular matrix, fewer states in the data than ``n``).

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(2000)
    >>> y = scipy.signal.lfilter([0, 1.0, 0.5], [1, -1.5, 0.7], u) + 0.05 * rng.standard_normal(2000)
    >>> model = n4sid(IdData(y, u, 0.1), 2)
    >>> model.name, model.success
    ('State space (n4sid, n=2)', True)
    >>> np.round(np.sort_complex(model.poles()), 2)
    array([0.75-0.37j, 0.75+0.37j])
    """
    data = _check_data(data)
    n = whole_number("n", n, 1)
    if weighting not in WEIGHTINGS:
        raise not_allowed("weighting", weighting, "auto, cva or moesp")
    if not isinstance(feedthrough, (bool, np.bool_)):
        raise not_allowed("feedthrough", feedthrough, "True or False")
    initial = _check_initial(initial)
    i = _checked_horizon(data, n, horizon, "n")

    problems = []
    r, blocks = _hankel_r(data, i)
    gamma, sv, problem, weighting = _observability(r, i, n, weighting)
    problems.append(problem)
    a_mat = np.zeros((n, n))
    c_mat = np.zeros((1, n))
    b_mat = np.zeros((n, 1))
    d_mat = np.zeros((1, 1))
    k_mat = np.zeros((n, 1))
    x0 = np.zeros((data.n_experiments, n))
    if gamma is not None:
        c_mat = gamma[:1].copy()
        # shift invariance: Gamma without its last row times A = Gamma without its first row
        a_mat, *_ = np.linalg.lstsq(gamma[:-1], gamma[1:], rcond=None)
        cols = _output_regressors(a_mat, c_mat, data, bool(feedthrough), initial)
        if np.all(np.isfinite(cols)):
            theta, *_ = np.linalg.lstsq(cols, data.y, rcond=None)
            b_mat = theta[:n, None].copy()
            if feedthrough:
                d_mat = np.array([[theta[n]]])
            if initial == "estimate":
                x0 = theta[n + int(feedthrough):].reshape(data.n_experiments, n)
            k_mat, problem = _kalman_gain(a_mat, b_mat, c_mat, d_mat, gamma, r, blocks, i)
            problems.append(problem)
        else:
            problems.append("the output's regressors are not finite (A is far from stable)")
    radius = float(np.max(np.abs(np.linalg.eigvals(a_mat)), initial=0.0))
    if radius > _UNSTABLE_RADIUS and not _output_grows(data):
        problems.insert(0, f"the estimated A is unstable (a pole at |z| = {radius:.4g}) while the output "
                           f"does not grow: try a lower order, a longer horizon or detrended data")

    base = dict(structure="ss", name=f"State space (n4sid, n={n})", orders={"n": n, "horizon": i}, ts=data.ts,
                A=a_mat, B=b_mat, C=c_mat, D=d_mat, K=k_mat, x0=x0, singular_values=sv, horizon=i,
                weighting=weighting, initial=initial, n_samples=data.n_samples, nfev=0)
    n_params = 3 * n + int(bool(feedthrough))
    names = tuple([f"a{k}" for k in range(1, n + 1)]
                  + [f"b{k}" for k in range(0 if feedthrough else 1, n + 1)]
                  + [f"c{k}" for k in range(1, n + 1)])
    # a provisional model gives the polynomials and the one-step prediction errors
    provisional = StateSpaceModel(**base, params=np.zeros(n_params), param_names=names,
                                  covariance=np.zeros((n_params, n_params)), noise_variance=math.nan,
                                  criteria=None, fit=None, success=False, message="")
    with np.errstate(all="ignore"):
        gb, ga = provisional.g_poly()
        hc, _hd = provisional.h_poly()
        fit = compare(provisional, data, 1, initial)
        e = data.y - fit.yhat
    params = np.concatenate([ga[1:], gb if feedthrough else gb[1:], hc[1:]])
    crit = criteria(e, n_params) if np.all(np.isfinite(e)) else Criteria(math.nan, math.nan, math.nan, math.nan,
                                                                          n_params, data.n_samples)
    variance = float(np.sum(e ** 2) / max(data.n_samples - n_params, 1))
    if math.isfinite(variance) and not any(problems):
        with np.errstate(all="ignore"):
            cov, problem = _pem_covariance(hc, data, bool(feedthrough), e, n, variance)
        problems.append(problem)
    else:
        cov = np.full((n_params, n_params), np.nan)
    if not math.isfinite(crit.loss):
        problems.append("the prediction errors are not finite")
    problems = [p for p in problems if p]
    message = "; ".join(problems) if problems else (
        f"order {n} from the SVD of {i} block rows ({weighting}); fit {fit.fit_percent:.1f} % (1-step prediction)")
    return StateSpaceModel(**base, params=params, param_names=names, covariance=cov, noise_variance=variance,
                           criteria=crit, fit=fit, success=not problems, message=message)
