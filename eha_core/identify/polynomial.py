"""Polynomial black-box models by the prediction-error method (MATLAB ``arx``, ``armax``, ``oe``, ``bj``, ``pem``).

The general model, in MATLAB's conventions,

    A(q) y(t) = B(q) / F(q) u(t) + C(q) / D(q) e(t),

with ``A, C, D, F`` monic polynomials in ``q^-1`` (``A = 1 + a1 q^-1 + ... + a_na q^-na``)
and ``B(q) = q^-nk (b0 + b1 q^-1 + ... + b_{nb-1} q^-(nb-1))``: ``b0`` multiplies
``u(t - nk)``, ``b_j`` multiplies ``u(t - nk - j)``. Each structure frees some of the
polynomials and fixes the rest to 1:

- ARX (``na, nb, nk``): ``A y = B u + e``, linear least squares (the rows of the
  regression begin after the longest lag of each experiment, never straddling two);
- ARMAX (``na, nb, nc, nk``): ``A y = B u + C e``;
- OE (``nb, nf, nk``): ``y = B/F u + e``;
- BJ (``nb, nc, nd, nf, nk``): ``y = B/F u + C/D e``.

ARMAX, OE and BJ minimise the sum of squared one-step prediction errors
``e = D/C (A y - B/F u)`` by Levenberg-Marquardt (damped Gauss-Newton) with the
analytic Jacobian, the regressors filtered as in Ljung (1999, sec. 10.3), started
from a linear estimate (Hannan-Rissanen for ARMAX and BJ's noise model,
Steiglitz-McBride for ``B/F``) and keeping ``C``, ``D`` and ``F`` stable (roots
outside the unit circle are reflected into it, at the start and after any step).
The parameter covariance is ``sigma^2 (J^T J)^-1`` at the optimum, ``sigma^2 =
SSE / (N - d)`` (less the initial conditions fitted). Several experiments
(:func:`~eha_core.identify.blackbox.merge`) are each filtered on their own: from rest
(``initial="zero"``) or from initial conditions fitted to each (``initial="estimate"``).
An estimate fails (``success`` False, the message saying why and what to try) when the
optimiser does not converge, the covariance is singular, or ``C``, ``D`` or ``F`` ends
on the unit circle (an integrating system does that to OE's ``F``); ARX and ARMAX leave
``A`` free and only note an unstable one.

Examples
--------
>>> import numpy as np, scipy.signal
>>> from eha_core.identify.blackbox import IdData
>>> rng = np.random.default_rng(0)
>>> u = rng.standard_normal(2000)
>>> y = scipy.signal.lfilter([0, 1.0, 0.5], [1, -1.5, 0.7], u) + 0.1 * rng.standard_normal(2000)
>>> model = oe(IdData(y, u, 0.01), nb=2, nf=2, nk=1)
>>> model.name, model.success
('OE(nb=2, nf=2, nk=1)', True)
>>> np.round(model.F, 2), np.round(model.B, 2)
(array([ 1. , -1.5,  0.7]), array([0. , 1. , 0.5]))
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.linalg.lapack
import scipy.signal

from .._checks import not_allowed
from .blackbox import INITIAL_CONDITIONS, Comparison, Criteria, EstimateFields, IdData, LinearModel, compare, criteria

__all__ = ["PolynomialModel", "STRUCTURES", "arx", "armax", "oe", "bj", "pem"]

#: each structure's orders, in MATLAB's order (``arx(data, [na nb nk])``...)
STRUCTURES = {
    "arx": ("na", "nb", "nk"),
    "armax": ("na", "nb", "nc", "nk"),
    "oe": ("nb", "nf", "nk"),
    "bj": ("nb", "nc", "nd", "nf", "nk"),
}

_POLYS = ("na", "nb", "nc", "nd", "nf")
# the column norms of a Jacobian are scaled to 1 before this condition number calls it singular
_SINGULAR_CONDITION = 1e10
# roots are kept this far inside the unit circle, so that a filter is never marginally stable
_MAX_ROOT = 1.0 - 1e-7
_lfilter = scipy.signal.lfilter


# ---------------------------------------------------------------------------
# the model
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False, repr=False)
class PolynomialModel(EstimateFields, LinearModel):
    """An ARX, ARMAX, OE or BJ estimate: ``A y = B/F u + C/D e`` (MATLAB ``idpoly``).

    Attributes
    ----------
    structure : str
        ``"arx"``, ``"armax"``, ``"oe"`` or ``"bj"``.
    name : str
        ``"ARX(na=2, nb=2, nk=1)"``.
    orders : dict
        The orders by name (``na``, ``nb``, ``nc``, ``nd``, ``nf``, ``nk`` of the structure).
    ts : float
        Sample time in seconds.
    params : numpy.ndarray
        ``a1..a_na, b0..b_{nb-1}, c1.., d1.., f1..``, the free coefficients; ``b0`` multiplies
        ``u(t - nk)``.
    param_names : tuple of str
        ``("a1", "a2", "b0", "b1", ...)``.
    covariance : numpy.ndarray
        Covariance of ``params``, ``sigma^2 (J^T J)^-1``.
    noise_variance : float
        ``sigma^2 = SSE / (N - d)`` of the one-step prediction errors.
    criteria : Criteria
        Loss, AIC, BIC and FPE of the one-step prediction errors.
    fit : Comparison
        The model on its estimation data: one-step prediction (simulation for OE, whose
        predictor is its simulation).
    initial : str
        ``"zero"`` (filters from rest) or ``"estimate"`` (each experiment's initial conditions
        fitted; ARX's regression always takes the first samples of each experiment as its
        initial conditions).
    n_samples : int
    success : bool
    message : str
        Why the estimate failed and what to try, or how it converged.
    nfev : int
        Evaluations of the prediction errors.
    A, B, C, D, F : numpy.ndarray
        The polynomials in ascending powers of ``q^-1``; all monic except ``B``, which begins
        with ``nk`` zeros. A polynomial the structure does not free is ``[1.0]``.
    """

    structure: str
    name: str
    orders: dict
    ts: float
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
    nfev: int
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    F: np.ndarray

    def g_poly(self) -> tuple[np.ndarray, np.ndarray]:
        """``(B, A F)``: ``G(q) = B(q) / (A(q) F(q))``, ascending powers of ``q^-1``."""
        return np.array(self.B, float), np.convolve(self.A, self.F)

    def h_poly(self) -> tuple[np.ndarray, np.ndarray]:
        """``(C, A D)``: ``H(q) = C(q) / (A(q) D(q))``, ascending powers of ``q^-1``."""
        return np.array(self.C, float), np.convolve(self.A, self.D)

    def polynomial_form(self) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, F)`` themselves: the predictor then never divides by ``A`` (an integrator's
        pole may land just outside the unit circle), as ARX's ``B u + (1 - A) y`` does not."""
        return tuple(np.array(p, float) for p in (self.A, self.B, self.C, self.D, self.F))


# ---------------------------------------------------------------------------
# orders and their checks
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class _Spec:
    """Which coefficients a structure frees, and how a parameter vector maps to the polynomials."""

    structure: str
    na: int = 0
    nb: int = 1
    nc: int = 0
    nd: int = 0
    nf: int = 0
    nk: int = 1
    estimate_initial: bool = False

    @property
    def n_params(self) -> int:
        return self.na + self.nb + self.nc + self.nd + self.nf

    @property
    def n_states(self) -> int:
        """Initial conditions estimated per experiment: the order of the predictor
        ``C F e = D A F y - D B u`` (its free response is that of ``1 / (C F)``), or 0."""
        if not self.estimate_initial:
            return 0
        return max(self.na + self.nd + self.nf, self.nc + self.nf, self.nd + self.nk + self.nb - 1)

    @property
    def max_lag(self) -> int:
        return max(self.na, self.nb + self.nk - 1, self.nc, self.nd, self.nf)

    def orders(self) -> dict:
        return {name: getattr(self, name) for name in STRUCTURES[self.structure]}

    def name(self) -> str:
        return f"{self.structure.upper()}(" + ", ".join(f"{k}={v}" for k, v in self.orders().items()) + ")"

    def param_names(self) -> tuple:
        return tuple([f"a{i}" for i in range(1, self.na + 1)] + [f"b{j}" for j in range(self.nb)]
                     + [f"c{i}" for i in range(1, self.nc + 1)] + [f"d{i}" for i in range(1, self.nd + 1)]
                     + [f"f{i}" for i in range(1, self.nf + 1)])

    def polys(self, theta: np.ndarray):
        """``A, B, C, D, F`` from the parameter vector (``B`` with its ``nk`` leading zeros)."""
        i = np.cumsum([0, self.na, self.nb, self.nc, self.nd, self.nf])
        one = np.ones(1)
        return (np.concatenate([one, theta[i[0]:i[1]]]), np.concatenate([np.zeros(self.nk), theta[i[1]:i[2]]]),
                np.concatenate([one, theta[i[2]:i[3]]]), np.concatenate([one, theta[i[3]:i[4]]]),
                np.concatenate([one, theta[i[4]:i[5]]]))

    def theta(self, A, B, C, D, F) -> np.ndarray:
        return np.concatenate([A[1:], B[self.nk:], C[1:], D[1:], F[1:]]).astype(float)

    def stabilized(self, theta: np.ndarray) -> np.ndarray:
        """``theta`` with the roots of ``C``, ``D`` and ``F`` reflected into the unit circle."""
        A, B, C, D, F = self.polys(theta)
        return self.theta(A, B, _stable(C), _stable(D), _stable(F))


def _whole(name: str, value, minimum: int) -> int:
    allowed = f"must be a whole number >= {minimum}"
    if isinstance(value, bool):
        raise not_allowed(name, value, allowed)
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise not_allowed(name, value, allowed) from None
    if not math.isfinite(number) or number != int(number) or number < minimum:
        raise not_allowed(name, value, allowed)
    return int(number)


def _checked_spec(data: IdData, structure: str, orders: dict, initial: str = "zero") -> _Spec:
    if not isinstance(data, IdData):
        raise not_allowed("data", type(data).__name__, "an IdData (eha_core.identify.blackbox.IdData)")
    values = {name: _whole(name, orders[name], 1 if name == "nb" else 0) for name in STRUCTURES[structure]}
    spec = _Spec(structure, **values, estimate_initial=initial == "estimate")
    shortest = min(y.size for y, _u in data.segments())
    where = "the record" if data.n_experiments == 1 else "the shortest experiment"
    if spec.nk >= shortest:
        raise not_allowed("nk", orders["nk"], f"the input delay must be shorter than the data: {where} has "
                                              f"{shortest} samples")
    # one sample more than parameters plus lags: the noise variance needs a degree of freedom
    needed = spec.n_params + max(spec.max_lag, spec.n_states) + 1
    if shortest < needed:
        # name the largest order: lowering it shortens the need most
        field = max(STRUCTURES[structure], key=lambda name: values[name])
        raise not_allowed(field, orders[field],
                          f"{spec.name()} has {spec.n_params} parameters and "
                          + (f"{spec.n_states} initial conditions to fit" if spec.n_states > spec.max_lag
                             else f"a longest lag of {spec.max_lag} samples")
                          + f", so it needs at least {needed} samples in each experiment and {where} has "
                          f"{shortest}: lower the orders or give a longer record")
    return spec


def _checked_initial(initial: str) -> str:
    if initial not in INITIAL_CONDITIONS:
        raise not_allowed("initial", initial, "zero (each experiment's filters start at rest) or estimate "
                                              "(each experiment's initial conditions fitted)")
    return initial


def _checked_iterations(max_iterations) -> int:
    return _whole("max_iterations", max_iterations, 1)


# ---------------------------------------------------------------------------
# linear algebra shared by the estimators
# ---------------------------------------------------------------------------
def _stable(poly: np.ndarray) -> np.ndarray:
    """A monic polynomial in ``q^-1`` with its roots (in ``z``) outside the unit circle reflected into it."""
    if poly.size < 2 or not np.all(np.isfinite(poly)):
        return poly
    roots = np.roots(poly)
    mag = np.abs(roots)
    if np.all(mag <= _MAX_ROOT):
        return poly
    # reflection keeps the spectrum's shape (|C(e^jw)| up to a constant), as MATLAB does
    roots = np.where(mag > 1.0, 1.0 / np.conj(roots), roots)
    mag = np.abs(roots)
    roots = np.where(mag > _MAX_ROOT, roots * (_MAX_ROOT / np.maximum(mag, 1e-300)), roots)
    return np.real(np.poly(roots))


def _largest_root(poly: np.ndarray) -> float:
    """The largest magnitude of a root of a polynomial in ``q^-1`` (0 for a constant, inf if not finite)."""
    if poly.size < 2:
        return 0.0
    if not np.all(np.isfinite(poly)):
        return math.inf
    return float(np.max(np.abs(np.roots(poly)))) if np.any(poly[1:]) else 0.0


def _is_stable(poly: np.ndarray) -> bool:
    return _largest_root(poly) < 1.0


def _at_limit(poly: np.ndarray) -> bool:
    """A root held at the edge of the unit circle by :func:`_stable` (within 1e-6 of it)."""
    return _largest_root(poly) > 1.0 - 1e-6


def _unstable_a_note(A: np.ndarray) -> str:
    """ARX and ARMAX leave ``A`` free (their predictor needs no stable ``A``): an unstable one is noted."""
    radius = _largest_root(A)
    if radius <= 1.0:
        return ""
    return (f"; note: A has a root outside the unit circle (|z| = {radius:.6g}), so G is unstable and its "
            "simulation diverges (an integrating system's pole at z = 1 lands on either side of the circle)")


def _lagged(x: np.ndarray, lags, start: int) -> np.ndarray:
    """Columns ``x(t - lag)`` for ``t = start .. N-1``, one per lag."""
    n = x.size
    return np.column_stack([x[start - lag:n - lag] for lag in lags]) if len(lags) else np.zeros((n - start, 0))


def _regression(segments, blocks, start: int) -> tuple[np.ndarray, np.ndarray]:
    """Stacked regression rows of every experiment: ``target(t)`` against ``sign * x(t - lag)``.

    ``segments`` is a list of dicts of signals; ``blocks`` a list of ``(signal name, lags, sign)``.
    The rows of each experiment begin at ``start``, so none reaches into another experiment."""
    rows, targets = [], []
    for signals in segments:
        cols = [sign * _lagged(signals[key], lags, start) for key, lags, sign in blocks]
        rows.append(np.hstack(cols))
        targets.append(signals["target"][start:])
    return np.vstack(rows), np.concatenate(targets)


def _lstsq(phi: np.ndarray, target: np.ndarray) -> np.ndarray:
    theta, *_ = np.linalg.lstsq(phi, target, rcond=None)
    return theta


def _rough_lstsq(phi: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Least squares by the (column-scaled) normal equations: a start needs no more, and a long
    model's SVD would cost most of an estimate's time. Falls back to the SVD if they are singular."""
    norms = np.linalg.norm(phi, axis=0)
    norms[norms == 0] = 1.0
    scaled = phi / norms
    try:
        factor = scipy.linalg.cho_factor(scaled.T @ scaled, check_finite=False)
        theta = scipy.linalg.cho_solve(factor, scaled.T @ target, check_finite=False) / norms
    except (np.linalg.LinAlgError, ValueError):
        return _lstsq(phi, target)
    return theta if np.all(np.isfinite(theta)) else _lstsq(phi, target)


def _covariance(jac: np.ndarray, sigma2: float) -> tuple[np.ndarray, str]:
    """``sigma2 (J^T J)^-1`` through the QR factor of the column-scaled Jacobian, or why not."""
    d = jac.shape[1]
    if d == 0:
        return np.zeros((0, 0)), ""
    norms = np.linalg.norm(jac, axis=0)
    if not np.all(np.isfinite(jac)) or np.any(norms == 0):
        return np.full((d, d), np.nan), "a parameter has no effect on the prediction errors"
    r = scipy.linalg.qr(jac / norms, mode="r", check_finite=False)[0][:d]
    singular = np.linalg.svd(r, compute_uv=False)
    if singular[-1] <= singular[0] / _SINGULAR_CONDITION:
        return np.full((d, d), np.nan), (f"the covariance is singular (condition number "
                                         f"{singular[0] / max(singular[-1], 1e-300):.2g})")
    # LAPACK's own small-matrix inverse: a BLAS-3 solve would wake every BLAS thread for a d x d matrix
    r_inv, info = scipy.linalg.lapack.dtrtri(r, lower=0)
    if info != 0:
        return np.full((d, d), np.nan), "the covariance is singular"
    cov = sigma2 * (r_inv @ r_inv.T) / np.outer(norms, norms)
    if not np.all(np.isfinite(cov)):
        return np.full((d, d), np.nan), "the covariance is not finite"
    return cov, ""


# ---------------------------------------------------------------------------
# ARX
# ---------------------------------------------------------------------------
def _arx_theta(segments, na: int, nb: int, nk: int, solve=_lstsq):
    """ARX's least-squares parameters ``[a, b]``, the regression and its residuals."""
    start = max(na, nb + nk - 1, 0)
    signals = [{"target": y, "y": y, "u": u} for y, u in segments]
    phi, target = _regression(signals, [("y", range(1, na + 1), -1.0), ("u", range(nk, nk + nb), 1.0)], start)
    theta = solve(phi, target)
    return theta, phi, target - phi @ theta


def arx(data: IdData, na: int, nb: int, nk: int) -> PolynomialModel:
    """ARX model ``A(q) y(t) = B(q) u(t) + e(t)`` by linear least squares (MATLAB ``arx``).

    The regression ``y(t) = -a1 y(t-1) - ... + b0 u(t-nk) + ... + b_{nb-1} u(t-nk-nb+1) + e(t)``
    is solved by ``numpy.linalg.lstsq`` (SVD) over the rows ``t >= max(na, nb + nk - 1)`` of each
    experiment: the first samples serve as initial conditions (``initial="estimate"``) and no row
    straddles two experiments.

    Parameters
    ----------
    data : IdData
        Estimation data, one or several experiments.
    na : int
        Order of ``A`` (>= 0; 0 gives an FIR model).
    nb : int
        Number of ``B`` coefficients (>= 1); ``b0`` multiplies ``u(t - nk)``.
    nk : int
        Input delay in samples (>= 0).

    Returns
    -------
    PolynomialModel
        ``covariance = sigma^2 (Phi^T Phi)^-1``, ``sigma^2 = SSE / (N - d)`` over the ``N`` rows;
        ``fit`` the one-step prediction.

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> from eha_core.identify.blackbox import IdData
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(1000)
    >>> e = 0.1 * rng.standard_normal(1000)
    >>> y = scipy.signal.lfilter([0, 0.5], [1, -0.8], u) + scipy.signal.lfilter([1], [1, -0.8], e)
    >>> model = arx(IdData(y, u, 0.1), 1, 1, 1)
    >>> model.name, model.param_names, np.round(model.params, 1)
    ('ARX(na=1, nb=1, nk=1)', ('a1', 'b0'), array([-0.8,  0.5]))
    """
    spec = _checked_spec(data, "arx", {"na": na, "nb": nb, "nk": nk})
    theta, phi, residuals = _arx_theta(data.segments(), spec.na, spec.nb, spec.nk)
    n_rows, d = phi.shape
    sse = float(residuals @ residuals)
    sigma2 = sse / (n_rows - d)
    cov, problem = _covariance(phi, sigma2)
    message = "least squares: unique solution" if not problem else (
        f"{problem}: the regressors are (nearly) collinear; lower na or nb, or excite the input more")
    message += _unstable_a_note(np.concatenate([[1.0], theta[:spec.na]]))
    return _finish(spec, data, theta, cov, sigma2, residuals, "estimate", not problem, message, 1)


# ---------------------------------------------------------------------------
# the prediction errors and their Jacobian (Ljung 1999, sec. 10.3)
# ---------------------------------------------------------------------------
def _shift_into(out: np.ndarray, col: int, signal: np.ndarray, lag: int, sign: float):
    # zero initial conditions: filtering commutes with the delay, so one filtered signal serves every lag
    n = signal.size
    if lag < n:
        out[lag:, col] = signal[:n - lag] if sign > 0 else -signal[:n - lag]


def _free_responses(CF: np.ndarray, n: int, n_states: int) -> np.ndarray:
    """An orthonormal basis of the predictor's free responses ``s / (C F)`` over ``n`` samples."""
    impulse = np.zeros(n)
    impulse[0] = 1.0
    response = _lfilter([1.0], CF, impulse)
    free = np.zeros((n, n_states))
    for i in range(n_states):
        _shift_into(free, i, response, i, 1.0)
    # the columns are triangular with a unit diagonal: always of full rank
    return np.linalg.qr(free)[0]


def _segment_jacobian(spec: _Spec, polys, y, u, w, v, e, z) -> np.ndarray:
    """``de/dtheta`` of one experiment (Ljung 1999, sec. 10.3), each block one filtered signal delayed.

    ``w = B/F u``, ``v = A y - w``, ``e`` the errors (free response ``z`` included, or None)."""
    A, B, C, D, F = polys
    CF = np.convolve(C, F)
    blocks = []                                          # (signal, first lag, count, sign)
    if spec.na:
        blocks.append((_lfilter(D, C, y), 1, spec.na, 1.0))             # de/da_k = D/C y(t-k)
    blocks.append((_lfilter(D, CF, u), spec.nk, spec.nb, -1.0))         # de/db_j = -D/(CF) u(t-nk-j)
    if spec.nc:
        blocks.append((_lfilter([1.0], C, e), 1, spec.nc, -1.0))        # de/dc_k = -1/C e(t-k)
    if spec.nd:
        blocks.append((_lfilter([1.0], C, v), 1, spec.nd, 1.0))         # de/dd_k = 1/C v(t-k)
    if spec.nf:
        signal = _lfilter(D, CF, w)                                     # de/df_k = D/(CF) w(t-k)
        if z is not None:
            signal = signal - _lfilter([1.0], F, z)                     # ... - 1/F z(t-k)
        blocks.append((signal, 1, spec.nf, 1.0))
    jac = np.zeros((y.size, spec.n_params))
    col = 0
    for signal, first, count, sign in blocks:
        for lag in range(first, first + count):
            _shift_into(jac, col, signal, lag, sign)
            col += 1
    return jac


def _errors(spec: _Spec, theta: np.ndarray, segments, with_jacobian: bool = True):
    """One-step prediction errors ``e = D/C (A y - B/F u)`` of every experiment and ``de/dtheta``.

    With ``spec.estimate_initial``, each experiment's errors are those of the best initial
    conditions: the free response ``z = s / (C F)`` of the predictor (``s`` any sequence of
    ``spec.n_states`` samples) is fitted by least squares and added, and the Jacobian is
    Kaufman's variable-projection one, ``P (de/dtheta at fixed s)`` with ``P`` the projection
    off the free responses: it gives the exact gradient of the loss. The derivative of ``z``
    at fixed ``s`` turns ``e`` into ``e + z`` in the ``c`` columns and adds ``-1/F z(t-k)`` to
    the ``f`` columns."""
    polys = spec.polys(theta)
    A, B, C, D, F = polys
    errors, jacobians = [], []
    for y, u in segments:
        w = _lfilter(B, F, u)                                   # the noise-free output B/F u
        v = (_lfilter(A, [1.0], y) if spec.na else y) - w       # the equation error A y - w
        e = _lfilter(D, C, v)
        basis = z = None
        if spec.n_states:
            basis = _free_responses(np.convolve(C, F), y.size, spec.n_states)
            z = -basis @ (basis.T @ e)
            e = e + z
        errors.append(e)
        if with_jacobian:
            jac = _segment_jacobian(spec, polys, y, u, w, v, e, z)
            if basis is not None:
                jac -= basis @ (basis.T @ jac)
            jacobians.append(jac)
    e = np.concatenate(errors)
    return e, (np.vstack(jacobians) if with_jacobian else None)


def _levenberg_marquardt(spec: _Spec, theta0: np.ndarray, segments, max_iterations: int):
    """Levenberg-Marquardt on the prediction errors, every iterate's ``C, D, F`` kept stable.

    Returns ``(theta, e, J, nfev, converged, why)``. A step solves the damped Gauss-Newton
    equations (Marquardt's scaling by the diagonal of ``J^T J``); the damping follows the ratio
    of the actual to the predicted decrease of the loss (Nielsen's update), so that a step that
    overshoots (the zig-zag of Gauss-Newton when the residuals are large) is shortened, and a
    step that does not lower the loss is retried with more damping. The iteration stops when
    the undamped Gauss-Newton step's predicted decrease ``g^T (J^T J)^-1 g`` falls below
    ``TOL`` of the loss (an error of ``sqrt(TOL N)`` standard deviations at most), when a step
    lowers the loss by less than 1e-13 relative, or when no damping finds a lower loss."""
    # written here rather than scipy.optimize.least_squares: its steps cannot be projected back to
    # stable C, D, F, and a trial step with an unstable 1/C or 1/F overflows over a long record
    theta = spec.stabilized(theta0)
    e, jac = _errors(spec, theta, segments)
    nfev = 1
    cost = float(e @ e)
    if not math.isfinite(cost):
        return theta, e, jac, nfev, False, "the prediction errors of the initial estimate are not finite"
    # the statistical scale of the loss: stopping at g^T H^-1 g < 1e-6 cost / N leaves the estimate
    # within 1e-3 of its standard deviation of the minimum
    tolerance = 1e-6 / e.size
    lam, growth = 1e-3, 2.0
    for _iteration in range(max_iterations):
        grad = jac.T @ e
        hess = jac.T @ jac
        if not np.all(np.isfinite(hess)):
            return theta, e, jac, nfev, False, "the Jacobian is not finite"
        scale = np.diag(hess).copy()
        scale[scale <= 0] = 1.0
        gauss_newton, *_ = np.linalg.lstsq(hess, -grad, rcond=None)
        if -float(grad @ gauss_newton) <= tolerance * cost:
            return theta, e, jac, nfev, True, "the Gauss-Newton step would change the loss by less than its noise"
        for _attempt in range(30):
            try:
                step = np.linalg.solve(hess + lam * np.diag(scale), -grad)
            except np.linalg.LinAlgError:
                lam, growth = lam * growth, 2 * growth
                continue
            candidate = spec.stabilized(theta + step)
            with np.errstate(all="ignore"):
                e_new, jac_new = _errors(spec, candidate, segments)
            nfev += 1
            cost_new = float(e_new @ e_new)
            if math.isfinite(cost_new) and cost_new < cost:
                break
            lam, growth = lam * growth, 2 * growth
        else:
            return theta, e, jac, nfev, True, "no step lowers the loss: a minimum"
        predicted = -float(2 * grad @ step + step @ hess @ step)
        ratio = (cost - cost_new) / predicted if predicted > 0 else 0.0
        lam, growth = lam * max(1 / 3, 1 - (2 * ratio - 1) ** 3), 2.0
        lam = max(lam, 1e-12)
        decrease = (cost - cost_new) / cost
        theta, e, jac, cost = candidate, e_new, jac_new, cost_new
        if decrease < 1e-13:
            return theta, e, jac, nfev, True, "the loss stopped decreasing"
    return theta, e, jac, nfev, False, f"no convergence in {max_iterations} iterations"


def _pem(spec: _Spec, data: IdData, theta0: np.ndarray, initial: str, max_iterations: int) -> PolynomialModel:
    segments = data.segments()
    theta, e, jac, nfev, converged, why = _levenberg_marquardt(spec, theta0, segments, max_iterations)
    n, d = e.size, spec.n_params
    sse = float(e @ e)
    # the initial conditions fitted for each experiment use degrees of freedom too
    sigma2 = sse / (n - d - spec.n_states * len(segments))
    problems = []
    if not converged:
        advice = ("raise max_iterations or try lower orders" if why.startswith("no convergence")
                  else "try lower orders, or detrend and scale the data")
        problems.append(f"the optimiser stopped: {why}; {advice}")
    A, B, C, D, F = spec.polys(theta)
    unstable = [name for name, poly in (("C", C), ("D", D), ("F", F)) if not _is_stable(poly)]
    if unstable:
        problems.append(f"{', '.join(unstable)} ended unstable; try lower orders")
    limit = [name for name, poly in (("C", C), ("D", D), ("F", F)) if name not in unstable and _at_limit(poly)]
    if limit:
        problems.append(f"{', '.join(limit)} ended with a root on the unit circle, where the estimation holds it: "
                        "the predictor is at the edge of stability and the intervals do not hold there (an "
                        "integrating system, a pole at z = 1, does this to F, and to C of ARMAX); try ARX, "
                        "or model the differenced output")
    if math.isfinite(sse):
        cov, problem = _covariance(jac, sigma2)
        if problem:
            problems.append(f"{problem}: a pole may cancel a zero; lower the orders")
    else:
        cov = np.full((d, d), np.nan)
    success = not problems
    message = f"converged: {why} after {nfev} evaluations" if success else "; ".join(problems)
    message += _unstable_a_note(A)
    return _finish(spec, data, theta, cov, sigma2, e, initial, success, message, nfev)


def _finish(spec, data, theta, cov, sigma2, residuals, initial, success, message, nfev) -> PolynomialModel:
    A, B, C, D, F = spec.polys(np.asarray(theta, float))
    model = PolynomialModel(
        structure=spec.structure, name=spec.name(), orders=spec.orders(), ts=data.ts,
        params=np.asarray(theta, float), param_names=spec.param_names(), covariance=cov,
        noise_variance=float(sigma2), criteria=criteria(residuals, spec.n_params), fit=None, initial=initial,
        n_samples=data.n_samples, success=bool(success), message=message, nfev=int(nfev), A=A, B=B, C=C, D=D, F=F)
    # OE's one-step predictor is its simulation; the others are judged on the criterion they minimise
    horizon = None if spec.structure == "oe" else 1
    try:
        with np.errstate(all="ignore"):
            fit = compare(model, data, horizon, initial)
    except (ValueError, np.linalg.LinAlgError):
        # a failed estimate still shows: its fit is not a number
        fit = Comparison(data.y, np.full(data.n_samples, np.nan), math.nan, horizon, initial, data.name,
                         np.arange(data.n_samples) * data.ts)
    return dataclasses.replace(model, fit=fit)


# ---------------------------------------------------------------------------
# initial estimates
# ---------------------------------------------------------------------------
def _long_order(spec: _Spec, segments, wanted: int) -> int:
    """A high order for a long AR or ARX model that the shortest experiment still supports."""
    shortest = min(y.size for y, _u in segments)
    return int(max(1, min(wanted, (shortest - spec.nk) // 4)))


def _innovations(segments, order: int, nk: int, with_input: bool = True) -> list[np.ndarray]:
    """The residuals of a long ARX (or AR, ``with_input=False``) model: estimates of ``e``."""
    if with_input:
        theta, *_ = _arx_theta(segments, order, order, nk, _rough_lstsq)
        a, b = theta[:order], theta[order:]
        gb = np.concatenate([np.zeros(nk), b])
    else:
        signals = [{"target": y, "y": y} for y, _u in segments]
        phi, target = _regression(signals, [("y", range(1, order + 1), -1.0)], order)
        a, gb = _rough_lstsq(phi, target), np.zeros(1)
    poly_a = np.concatenate([[1.0], a])
    out = []
    for y, u in segments:
        e = _lfilter(poly_a, [1.0], y) - _lfilter(gb, [1.0], u)
        # the first samples lack their regressors; they are set to zero rather than guessed
        e[:max(order, gb.size - 1)] = 0.0
        out.append(e)
    return out


def _armax_start(spec: _Spec, segments) -> np.ndarray:
    """Hannan-Rissanen: a long ARX model estimates ``e``; then ``A, B, C`` by least squares."""
    order = _long_order(spec, segments, max(20, 3 * (spec.na + spec.nc)))
    e_hat = _innovations(segments, order, spec.nk)
    start = max(order, spec.max_lag)
    signals = [{"target": y, "y": y, "u": u, "e": e} for (y, u), e in zip(segments, e_hat, strict=True)]
    blocks = [("y", range(1, spec.na + 1), -1.0), ("u", range(spec.nk, spec.nk + spec.nb), 1.0),
              ("e", range(1, spec.nc + 1), 1.0)]
    phi, target = _regression(signals, blocks, start)
    return _lstsq(phi, target)


def _oe_start(spec: _Spec, segments, iterations: int = 6) -> np.ndarray:
    """Steiglitz-McBride: ARX on the data filtered by ``1/F`` of the previous step, ``F`` kept stable."""
    theta, *_ = _arx_theta(segments, spec.nf, spec.nb, spec.nk)
    for _ in range(iterations if spec.nf else 0):
        F = _stable(np.concatenate([[1.0], theta[:spec.nf]]))
        filtered = [(_lfilter([1.0], F, y), _lfilter([1.0], F, u)) for y, u in segments]
        new, *_ = _arx_theta(filtered, spec.nf, spec.nb, spec.nk)
        if not np.all(np.isfinite(new)):
            break
        theta = new
    f, b = theta[:spec.nf], theta[spec.nf:]
    return np.concatenate([b, _stable(np.concatenate([[1.0], f]))[1:]])


def _arma_start(spec: _Spec, noises) -> tuple[np.ndarray, np.ndarray]:
    """Hannan-Rissanen for ``v = C/D e``: a long AR model of ``v`` estimates ``e``, then ``D, C``."""
    pairs = [(v, np.zeros_like(v)) for v in noises]
    if spec.nc == 0 and spec.nd == 0:
        return np.zeros(0), np.zeros(0)
    order = _long_order(spec, pairs, max(20, 3 * (spec.nc + spec.nd)))
    e_hat = _innovations(pairs, order, spec.nk, with_input=False)
    start = max(order, spec.nc, spec.nd)
    signals = [{"target": v, "v": v, "e": e} for v, e in zip(noises, e_hat, strict=True)]
    phi, target = _regression(signals, [("e", range(1, spec.nc + 1), 1.0), ("v", range(1, spec.nd + 1), -1.0)], start)
    theta = _lstsq(phi, target)
    return theta[:spec.nc], theta[spec.nc:]


# ---------------------------------------------------------------------------
# ARMAX, OE, BJ and the dispatcher
# ---------------------------------------------------------------------------
def armax(data: IdData, na: int, nb: int, nc: int, nk: int, *, initial: str = "zero",
          max_iterations: int = 100) -> PolynomialModel:
    """ARMAX model ``A(q) y(t) = B(q) u(t) + C(q) e(t)`` by the prediction-error method (MATLAB ``armax``).

    Starts from Hannan-Rissanen (a long ARX model estimates ``e``, then ``A, B, C`` by least
    squares) and minimises the one-step prediction errors ``e = (A y - B u) / C`` by
    Levenberg-Marquardt with the analytic Jacobian, ``C`` kept stable.

    Parameters
    ----------
    data : IdData
        Estimation data, one or several experiments (each filtered on its own).
    na : int
        Order of ``A`` (>= 0).
    nb : int
        Number of ``B`` coefficients (>= 1); ``b0`` multiplies ``u(t - nk)``.
    nc : int
        Order of ``C`` (>= 0).
    nk : int
        Input delay in samples (>= 0).
    initial : str
        ``"zero"``: the filters of each experiment start at rest; ``"estimate"``: each
        experiment's initial conditions (the predictor's free response) are fitted by least
        squares at every step (variable projection), for records that do not start at rest.
    max_iterations : int
        Most Levenberg-Marquardt iterations.

    Returns
    -------
    PolynomialModel

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> from eha_core.identify.blackbox import IdData
    >>> rng = np.random.default_rng(2)
    >>> u, e = rng.standard_normal(2000), 0.2 * rng.standard_normal(2000)
    >>> y = scipy.signal.lfilter([0, 1.0], [1, -0.7], u) + scipy.signal.lfilter([1, 0.5], [1, -0.7], e)
    >>> model = armax(IdData(y, u, 1.0), 1, 1, 1, 1)
    >>> model.param_names, np.round(model.params, 1)
    (('a1', 'b0', 'c1'), array([-0.7,  1. ,  0.5]))
    """
    initial, iterations = _checked_initial(initial), _checked_iterations(max_iterations)
    spec = _checked_spec(data, "armax", {"na": na, "nb": nb, "nc": nc, "nk": nk}, initial)
    return _pem(spec, data, _armax_start(spec, data.segments()), initial, iterations)


def oe(data: IdData, nb: int, nf: int, nk: int, *, initial: str = "zero", max_iterations: int = 100) -> PolynomialModel:
    """Output-error model ``y(t) = B(q)/F(q) u(t) + e(t)`` by the prediction-error method (MATLAB ``oe``).

    Starts from Steiglitz-McBride (ARX refitted on data filtered by ``1/F``) and minimises the
    output error ``e = y - B/F u`` by Levenberg-Marquardt with the analytic Jacobian, ``F``
    kept stable. The fit is the simulation (OE's predictor is its simulation).

    Parameters
    ----------
    data : IdData
        Estimation data, one or several experiments (each simulated on its own).
    nb : int
        Number of ``B`` coefficients (>= 1); ``b0`` multiplies ``u(t - nk)``.
    nf : int
        Order of ``F`` (>= 0).
    nk : int
        Input delay in samples (>= 0).
    initial : str
        ``"zero"``: the filters of each experiment start at rest; ``"estimate"``: each
        experiment's initial conditions (the predictor's free response) are fitted by least
        squares at every step (variable projection), for records that do not start at rest.
    max_iterations : int
        Most Levenberg-Marquardt iterations.

    Returns
    -------
    PolynomialModel

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> from eha_core.identify.blackbox import IdData
    >>> rng = np.random.default_rng(3)
    >>> u = rng.standard_normal(1000)
    >>> y = scipy.signal.lfilter([0, 0, 0.3], [1, -0.9], u) + 0.05 * rng.standard_normal(1000)
    >>> model = oe(IdData(y, u, 1.0), 1, 1, 2)
    >>> model.B.size, np.round(model.F, 2), model.fit.horizon
    (3, array([ 1. , -0.9]), None)
    """
    initial, iterations = _checked_initial(initial), _checked_iterations(max_iterations)
    spec = _checked_spec(data, "oe", {"nb": nb, "nf": nf, "nk": nk}, initial)
    return _pem(spec, data, _oe_start(spec, data.segments()), initial, iterations)


def bj(data: IdData, nb: int, nc: int, nd: int, nf: int, nk: int, *, initial: str = "zero",
       max_iterations: int = 100) -> PolynomialModel:
    """Box-Jenkins model ``y(t) = B(q)/F(q) u(t) + C(q)/D(q) e(t)`` by the prediction-error method (MATLAB ``bj``).

    Starts ``B/F`` from Steiglitz-McBride and ``C/D`` from Hannan-Rissanen on the output
    error, then minimises ``e = D/C (y - B/F u)`` by Levenberg-Marquardt with the analytic
    Jacobian, ``C``, ``D`` and ``F`` kept stable.

    Parameters
    ----------
    data : IdData
        Estimation data, one or several experiments (each filtered on its own).
    nb : int
        Number of ``B`` coefficients (>= 1); ``b0`` multiplies ``u(t - nk)``.
    nc : int
        Order of ``C`` (>= 0).
    nd : int
        Order of ``D`` (>= 0).
    nf : int
        Order of ``F`` (>= 0).
    nk : int
        Input delay in samples (>= 0).
    initial : str
        ``"zero"``: the filters of each experiment start at rest; ``"estimate"``: each
        experiment's initial conditions (the predictor's free response) are fitted by least
        squares at every step (variable projection), for records that do not start at rest.
    max_iterations : int
        Most Levenberg-Marquardt iterations.

    Returns
    -------
    PolynomialModel

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> from eha_core.identify.blackbox import IdData
    >>> rng = np.random.default_rng(4)
    >>> u, e = rng.standard_normal(3000), 0.3 * rng.standard_normal(3000)
    >>> y = scipy.signal.lfilter([0, 1.0], [1, -0.8], u) + scipy.signal.lfilter([1.0], [1, -0.9], e)
    >>> model = bj(IdData(y, u, 1.0), 1, 0, 1, 1, 1)
    >>> model.name, np.round(model.params, 1)
    ('BJ(nb=1, nc=0, nd=1, nf=1, nk=1)', array([ 1. , -0.9, -0.8]))
    """
    initial, iterations = _checked_initial(initial), _checked_iterations(max_iterations)
    spec = _checked_spec(data, "bj", {"nb": nb, "nc": nc, "nd": nd, "nf": nf, "nk": nk}, initial)
    segments = data.segments()
    g_theta = _oe_start(spec, segments)
    b, f = g_theta[:spec.nb], g_theta[spec.nb:]
    gb, gf = np.concatenate([np.zeros(spec.nk), b]), np.concatenate([[1.0], f])
    c, d = _arma_start(spec, [y - _lfilter(gb, gf, u) for y, u in segments])
    return _pem(spec, data, np.concatenate([b, c, d, f]), initial, iterations)


def pem(data: IdData, structure: str, orders, *, initial: str = "zero", max_iterations: int = 100) -> PolynomialModel:
    """A polynomial model of the named structure (MATLAB ``pem`` with ``arx``/``armax``/``oe``/``bj`` orders).

    Parameters
    ----------
    data : IdData
        Estimation data, one or several experiments.
    structure : str
        ``"arx"``, ``"armax"``, ``"oe"`` or ``"bj"``.
    orders : dict or sequence of int
        The orders by name (``{"na": 2, "nb": 2, "nk": 1}``) or in MATLAB's order
        (:data:`STRUCTURES`: ``[na nb nk]``, ``[na nb nc nk]``, ``[nb nf nk]``, ``[nb nc nd nf nk]``).
    initial : str
        ``"zero"`` or ``"estimate"`` for ARMAX, OE and BJ; ARX takes its first samples as initial
        conditions and ignores it.
    max_iterations : int
        Most Levenberg-Marquardt iterations (not used by ARX).

    Returns
    -------
    PolynomialModel

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.identify.blackbox import IdData
    >>> u = np.random.default_rng(5).standard_normal(200)
    >>> y = np.convolve(u, [0, 1.0, 0.5])[:200]
    >>> pem(IdData(y, u, 1.0), "arx", [0, 2, 1]).name
    'ARX(na=0, nb=2, nk=1)'
    """
    key = str(structure).strip().lower()
    if key not in STRUCTURES:
        raise not_allowed("structure", structure, "one of " + ", ".join(STRUCTURES))
    names = STRUCTURES[key]
    if isinstance(orders, dict):
        unknown = sorted(set(orders) - set(names))
        missing = [name for name in names if name not in orders]
        if unknown or missing:
            raise not_allowed("orders", orders, f"{key} takes the orders {', '.join(names)}")
        values = dict(orders)
    else:
        values = list(np.ravel(np.asarray(orders, dtype=object)))
        if len(values) != len(names):
            raise not_allowed("orders", orders, f"{key} takes {len(names)} orders: [{' '.join(names)}]")
        values = dict(zip(names, values, strict=True))
    if key == "arx":
        return arx(data, **values)
    return {"armax": armax, "oe": oe, "bj": bj}[key](data, **values, initial=initial, max_iterations=max_iterations)
