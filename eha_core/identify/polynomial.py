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
analytic Jacobian, the regressors filtered as in Ljung (1999, sec. 10.3), keeping
``C``, ``D`` and ``F`` stable (roots outside the unit circle are reflected into it, at
the start and after any step). The criterion has local minima (a pole cancelling a
zero near z = 1 on closed-loop records; Söderström's with a coloured input), so, as
MATLAB's ``pem`` does, the search starts from several linear estimates:
Steiglitz-McBride for ``B/F``; the poles of a long ARX model reduced by balanced
truncation (or of ``n4sid``) with ``B`` by least squares; Hannan-Rissanen and ARX for
ARMAX; Hannan-Rissanen on the output error for BJ's noise model. The starts are ranked
(BJ's by the output error they leave, whitened by a long AR model), the best three
get five iterations each, two of those (in different basins) 40 more, and the lower
is continued to convergence; an estimate whose ``C``, ``D`` or ``F`` is held at the
unit circle gives way to one inside it unless the data demand the edge (Akaike's
margin), and the message says what the other fits. On a record longer than 4000
samples the search runs on its first 2000 and the estimate is then polished on the
whole record.
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

from .._checks import not_allowed, whole_number
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
# the search: every start's loss is evaluated, the best few get a few Levenberg-Marquardt iterations
# (enough to fall into their basin), and the lowest of those is continued
_PROBED_STARTS = 3
_PROBE_ITERATIONS = 5
_CONTINUED_PROBES = 2
_COMPARE_ITERATIONS = 40
# Levenberg-Marquardt stops when this many steps in a row each lower the loss V by less than
# _STALLED_CHANGE V / N, that is N log V (twice the negative log-likelihood) by less than 1e-4
_STALLED_STEPS = 3
_STALLED_CHANGE = 1e-4
# the search runs on the first 2000 samples of a longer record (at least 200 of each experiment):
# that is enough to tell the basins apart, and the whole record only polishes the best one
_SEARCH_SAMPLES = 2000
_SEARCH_SAMPLES_MIN = 200
# the long ARX model whose balanced truncation gives a start for F (or A)
_LONG_ARX_ORDER = 20
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


def _checked_spec(data: IdData, structure: str, orders: dict, initial: str = "zero") -> _Spec:
    if not isinstance(data, IdData):
        raise not_allowed("data", type(data).__name__, "an IdData (eha_core.identify.blackbox.IdData)")
    values = {name: whole_number(name, orders[name], 1 if name == "nb" else 0) for name in STRUCTURES[structure]}
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
    return whole_number("max_iterations", max_iterations, 1)


# ---------------------------------------------------------------------------
# linear algebra shared by the estimators
# ---------------------------------------------------------------------------
def _inside(poly: np.ndarray, radius: float) -> bool:
    """Whether every root of a monic polynomial in ``q^-1`` lies strictly inside ``|z| < radius``.

    The Schur-Cohn step-down recursion (the reflection coefficients of the polynomial scaled to
    ``|z| < 1`` are all below 1 in magnitude): a few multiplications where ``numpy.roots`` needs an
    eigenvalue problem, which cost a fifth of an estimate's time when every trial step needed it."""
    a = poly[1:] / radius ** np.arange(1, poly.size)
    while a.size:
        k = a[-1]
        if not abs(k) < 1.0:
            return False
        a = (a[:-1] - k * a[-2::-1]) / (1.0 - k * k)
    return True


def _stable(poly: np.ndarray) -> np.ndarray:
    """A monic polynomial in ``q^-1`` with its roots (in ``z``) outside the unit circle reflected into it."""
    if poly.size < 2 or not np.all(np.isfinite(poly)):
        return poly
    if _inside(poly, _MAX_ROOT):
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


def _levenberg_marquardt(spec: _Spec, theta0: np.ndarray, segments, max_iterations: int, lam: float = 1e-3):
    """Levenberg-Marquardt on the prediction errors, every iterate's ``C, D, F`` kept stable.

    Returns ``(theta, e, J, nfev, converged, why, iterations, lam)`` (``lam`` the damping reached,
    to continue from). A step solves the damped Gauss-Newton
    equations (Marquardt's scaling by the diagonal of ``J^T J``); the damping follows the ratio
    of the actual to the predicted decrease of the loss (Nielsen's update), so that a step that
    overshoots (the zig-zag of Gauss-Newton when the residuals are large) is shortened, and a
    step that does not lower the loss is retried with more damping. The iteration stops when
    the undamped Gauss-Newton step's predicted decrease ``g^T (J^T J)^-1 g`` falls below
    ``TOL`` of the loss (an error of ``sqrt(TOL N)`` standard deviations at most), when a step
    lowers the loss by less than 1e-13 relative (or, when the step was pulled back inside the unit
    circle, by less than the statistical scale ``TOL``: the minimum lies on the stability limit and
    the projected steps only creep along it), when :data:`_STALLED_STEPS` steps in a row each lower
    ``N log V`` by less than :data:`_STALLED_CHANGE` (a root creeping towards the circle, the loss
    flat to far below its noise), or when no damping finds a lower loss."""
    # written here rather than scipy.optimize.least_squares: its steps cannot be projected back to
    # stable C, D, F, and a trial step with an unstable 1/C or 1/F overflows over a long record
    theta = spec.stabilized(theta0)
    e, jac = _errors(spec, theta, segments)
    nfev = 1
    cost = float(e @ e)
    if not math.isfinite(cost):
        return theta, e, jac, nfev, False, "the prediction errors of the initial estimate are not finite", 0, lam
    # the statistical scale of the loss: stopping at g^T H^-1 g < 1e-6 cost / N leaves the estimate
    # within 1e-3 of its standard deviation of the minimum
    tolerance = 1e-6 / e.size
    growth, stalled = 2.0, 0
    for iteration in range(max_iterations):
        grad = jac.T @ e
        hess = jac.T @ jac
        if not np.all(np.isfinite(hess)):
            return theta, e, jac, nfev, False, "the Jacobian is not finite", iteration, lam
        scale = np.diag(hess).copy()
        scale[scale <= 0] = 1.0
        gauss_newton, *_ = np.linalg.lstsq(hess, -grad, rcond=None)
        if -float(grad @ gauss_newton) <= tolerance * cost:
            return (theta, e, jac, nfev, True, "the Gauss-Newton step would change the loss by less than its noise",
                    iteration, lam)
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
            return theta, e, jac, nfev, True, "no step lowers the loss: a minimum", iteration, lam
        predicted = -float(2 * grad @ step + step @ hess @ step)
        ratio = (cost - cost_new) / predicted if predicted > 0 else 0.0
        lam, growth = lam * max(1 / 3, 1 - (2 * ratio - 1) ** 3), 2.0
        lam = max(lam, 1e-12)
        decrease = (cost - cost_new) / cost
        projected = not np.allclose(candidate, theta + step, rtol=0.0, atol=1e-12)
        theta, e, jac, cost = candidate, e_new, jac_new, cost_new
        if decrease < 1e-13:
            return theta, e, jac, nfev, True, "the loss stopped decreasing", iteration + 1, lam
        if projected and decrease < tolerance:
            return (theta, e, jac, nfev, True, "the loss stopped decreasing at the stability limit", iteration + 1,
                    lam)
        # creeping towards the unit circle, a root approaches it step by step without reaching it
        stalled = stalled + 1 if decrease < _STALLED_CHANGE / e.size else 0
        if stalled >= _STALLED_STEPS:
            return (theta, e, jac, nfev, True, f"the loss stalled ({_STALLED_STEPS} steps in a row each lowered "
                    "it by less than its noise)", iteration + 1, lam)
    return theta, e, jac, nfev, False, f"no convergence in {max_iterations} iterations", max_iterations, lam


def _held(spec: _Spec, theta: np.ndarray) -> bool:
    """Whether a root of ``C``, ``D`` or ``F`` is held at the unit circle by :func:`_stable`."""
    _A, _B, C, D, F = spec.polys(theta)
    return any(_at_limit(poly) for poly in (C, D, F))


def _whitened_output_error(spec: _Spec, theta: np.ndarray, segments) -> float:
    """BJ's loss were its noise model free: the innovations variance of a long AR model of the output
    error ``y - B/F u``. It ranks the starts of ``B/F`` by what they allow, not by how good the
    rough noise model started with them happens to be (on closed-loop data the true ``B/F`` started
    with a poor noise model had a 40 times larger loss than a local minimum's)."""
    _A, B, C, D, F = spec.polys(theta)
    with np.errstate(all="ignore"):
        noises = [y - _lfilter(B, F, u) for y, u in segments]
        if not all(np.all(np.isfinite(v)) for v in noises):
            return math.inf
        pairs = [(v, np.zeros_like(v)) for v in noises]
        order = _long_order(spec, pairs, _LONG_ARX_ORDER)
        residuals = np.concatenate(_innovations(pairs, order, spec.nk, with_input=False))
    cost = float(residuals @ residuals)
    return cost if math.isfinite(cost) else math.inf


def _loss(run) -> float:
    cost = float(run[1] @ run[1])
    return cost if math.isfinite(cost) else math.inf


def _ranked_starts(spec: _Spec, starts, segments, score) -> tuple[list, int]:
    """The starts (made stable) from the lowest score to the highest, and the evaluations spent."""
    nfev = 0
    scored = []
    for theta in starts:
        theta = spec.stabilized(np.asarray(theta, float))
        if not np.all(np.isfinite(theta)):
            continue
        if score is None:
            with np.errstate(all="ignore"):
                e, _ = _errors(spec, theta, segments, with_jacobian=False)
            nfev += 1
            value = float(e @ e)
        else:
            value = score(spec, theta, segments)
        if math.isfinite(value):
            scored.append((value, len(scored), theta))
    if not scored:
        # every start is useless: the first one still gives an answer that says why
        return [spec.stabilized(np.asarray(starts[0], float))], nfev
    scored.sort(key=lambda item: item[:2])
    return [theta for _value, _index, theta in scored], nfev


def _picked_probes(spec: _Spec, probes, segments, score) -> list[int]:
    """Which probes to continue: the best by ``score`` (if given), then the lowest losses in other
    places, :data:`_CONTINUED_PROBES` in all.

    A basin's floor can lie far below where a few iterations leave it (along the unit circle they
    creep), so the lowest probe alone is not enough; two probes within 1 % of each other are in
    one basin, and continuing both would waste the time of one."""
    picked = []
    if score is not None:
        picked.append(min(range(len(probes)), key=lambda k: score(spec, probes[k][0], segments)))
    for k in sorted(range(len(probes)), key=lambda k: _loss(probes[k])):
        theta = probes[k][0]
        if len(picked) < _CONTINUED_PROBES and all(
                np.linalg.norm(theta - probes[j][0]) > 1e-2 * np.linalg.norm(probes[j][0]) for j in picked):
            picked.append(k)
    return picked


def _multistart(spec: _Spec, starts, segments, max_iterations: int, score=None):
    """Levenberg-Marquardt from the best of several starts: the global minimum, not the nearest one.

    The starts are ranked by ``score(spec, theta, segments)`` (default the loss, one evaluation
    each); the best :data:`_PROBED_STARTS` are each given :data:`_PROBE_ITERATIONS` iterations,
    which take each into its basin. The probe of the lowest score (if ``score`` is given) and those
    of the lowest loss, :data:`_CONTINUED_PROBES` in all and in different places, get
    :data:`_COMPARE_ITERATIONS` more, and the lowest loss is continued to convergence, except
    that an estimate with a root of ``C``, ``D`` or ``F`` held at the unit circle gives way to one
    inside it whose loss it does not beat by Akaike's margin (``N log(V_inside / V_held) <= 2 d``:
    the data do not demand the root on the circle); the note returned says what the other fits.
    On a record much longer than :data:`_SEARCH_SAMPLES`, all this runs on its first part
    (:func:`_shortened`) and the chosen estimate is then polished on the whole record. Returns
    ``(theta, e, J, nfev, converged, why, note)``, ``nfev`` counting every evaluation."""
    full_segments, segments = segments, _shortened(segments, _SEARCH_SAMPLES)
    ranked, nfev = _ranked_starts(spec, starts, segments, score)
    probe_iterations = min(_PROBE_ITERATIONS, max_iterations) if len(ranked) > 1 else max_iterations
    probes = []
    for theta in ranked[:_PROBED_STARTS]:
        run = _levenberg_marquardt(spec, theta, segments, probe_iterations)
        nfev += run[3]
        probes.append(run)
    # the picked probes run a few more iterations side by side; only the best runs on to convergence
    compared = []
    for k in _picked_probes(spec, probes, segments, score):
        run, more = _continued(spec, probes[k], segments, _COMPARE_ITERATIONS, max_iterations)
        nfev += more
        compared.append(run)
    best = min(compared, key=_loss)
    note = ""
    if _held(spec, best[0]):
        # a root held at the unit circle is the edge of the model set, not a minimum, and its intervals
        # do not hold there: an estimate inside is taken unless the data demand the edge (Akaike's
        # margin: N log(V_inside / V_held) > 2 d), and the user is told what the other one fits
        inside = [run for run in compared if not _held(spec, run[0]) and math.isfinite(_loss(run))]
        if inside and _loss(best) > 0:
            candidate = min(inside, key=_loss)
            n_errors = best[1].size
            held_loss, inside_loss = _loss(best) / n_errors, _loss(candidate) / n_errors
            if n_errors * math.log(max(inside_loss, 1e-300) / held_loss) <= 2 * spec.n_params:
                best = candidate
                note = (f"; note: with a root held at the unit circle the loss is a little lower ({held_loss:.4g} "
                        f"against {inside_loss:.4g})")
            else:
                note = (f"; with every root inside the unit circle the loss is higher ({inside_loss:.4g} against "
                        f"{held_loss:.4g})")
    best, more = _continued(spec, best, segments, max_iterations, max_iterations)
    nfev += more
    theta, e, jac, _nfev, converged, why, _iterations, lam = best
    if segments is not full_segments:
        # the basin is chosen on a part of the record; the whole record polishes the minimum in it
        theta, e, jac, more, converged, why, _iterations, _lam = _levenberg_marquardt(
            spec, theta, full_segments, max_iterations, lam)
        nfev += more
    return theta, e, jac, nfev, converged, why, note


def _continued(spec: _Spec, run, segments, budget: int, max_iterations: int):
    """``run`` (a :func:`_levenberg_marquardt` result) given up to ``budget`` more iterations, never
    more than ``max_iterations`` in all; returns the new result and the evaluations spent."""
    theta, _e, _jac, _nfev, converged, _why, iterations, lam = run
    budget = min(budget, max_iterations - iterations)
    if converged or budget <= 0 or not math.isfinite(_loss(run)):
        return run, 0
    more = _levenberg_marquardt(spec, theta, segments, budget, lam)
    done = iterations + more[6]
    why = more[5] if more[4] else f"no convergence in {done} iterations"
    return more[:5] + (why, done, more[7]), more[3]


def _shortened(segments, samples: int):
    """The first part of every experiment, ``samples`` in all (the same share of each), or the
    experiments themselves when they are not much longer: where the search chooses its basin."""
    total = sum(y.size for y, _u in segments)
    if total <= 2 * samples:
        return segments
    share = samples / total
    kept = [min(y.size, max(int(share * y.size), _SEARCH_SAMPLES_MIN)) for y, _u in segments]
    return [(y[:k], u[:k]) for (y, u), k in zip(segments, kept, strict=True)]


def _pem(spec: _Spec, data: IdData, starts, initial: str, max_iterations: int, score=None) -> PolynomialModel:
    segments = data.segments()
    theta, e, jac, nfev, converged, why, note = _multistart(spec, starts, segments, max_iterations, score)
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
    message += note + _unstable_a_note(A)
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


def _armax_starts(spec: _Spec, data: IdData, segments) -> list[np.ndarray]:
    """Starts of ARMAX: Hannan-Rissanen, ARX with ``C = 1``, and ``A`` from a long ARX model reduced
    by balanced truncation (``B`` by least squares, ``C = 1``)."""
    starts = [_armax_start(spec, segments)]
    arx_theta, *_ = _arx_theta(segments, spec.na, spec.nb, spec.nk)
    starts.append(np.concatenate([arx_theta, np.zeros(spec.nc)]))
    A = _reduced_arx_poles(spec, segments, spec.na) if spec.na else None
    if A is not None:
        starts.append(np.concatenate([A[1:], _b_given_f(spec, segments, A), np.zeros(spec.nc)]))
    return [start for start in starts if np.all(np.isfinite(start))] or starts[:1]


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


def _balanced_poles(num: np.ndarray, den: np.ndarray, order: int) -> np.ndarray | None:
    """The monic denominator (in ``q^-1``) of ``order`` of the balanced truncation of ``num / den``, or None.

    Balanced truncation keeps the states that are both well excited and well seen (the largest
    Hankel singular values); its poles are those of the dominant dynamics, whatever the noise
    did to the long model's other poles. ``den`` is first made stable by reflection."""
    den = _stable(np.asarray(den, float))
    size = max(den.size, num.size)
    num, den = np.pad(num, (0, size - num.size)), np.pad(den, (0, size - den.size))
    n = size - 1
    if order < 1 or n <= order:
        return den if n == order else None
    # controllable companion form of the strictly proper part: G = num[0] + c (zI - A)^-1 b
    a_mat = np.zeros((n, n))
    a_mat[0] = -den[1:]
    a_mat[1:, :-1] = np.eye(n - 1)
    b_vec = np.zeros((n, 1))
    b_vec[0] = 1.0
    c_vec = (num[1:] - num[0] * den[1:])[None, :]
    try:
        gram_c = scipy.linalg.solve_discrete_lyapunov(a_mat, b_vec @ b_vec.T)
        gram_o = scipy.linalg.solve_discrete_lyapunov(a_mat.T, c_vec.T @ c_vec)
        roots = []
        for gram in (gram_c, gram_o):
            w, v = np.linalg.eigh((gram + gram.T) / 2)
            roots.append(v * np.sqrt(np.maximum(w, 0.0)))
        u_mat, hankel, vt_mat = np.linalg.svd(roots[1].T @ roots[0])
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(hankel)) or hankel[order - 1] <= 1e-12 * hankel[0]:
        return None
    scale = np.sqrt(hankel[:order])
    right = roots[0] @ vt_mat[:order].T / scale
    left = (u_mat[:, :order] / scale).T @ roots[1].T
    poles = np.linalg.eigvals(left @ a_mat @ right)
    poly = np.real(np.poly(poles))
    return poly if np.all(np.isfinite(poly)) else None


def _reduced_arx_poles(spec: _Spec, segments, order: int) -> np.ndarray | None:
    """The poles of a long ARX model's ``B/A`` reduced to ``order`` by balanced truncation (or None).

    The long model is fitted to the data less their means: an offset would otherwise take a pole
    near z = 1, which the truncation keeps as dominant."""
    long = _long_order(spec, segments, max(_LONG_ARX_ORDER, 3 * order))
    if long <= order:
        return None
    centred = [(y - np.mean(y), u - np.mean(u)) for y, u in segments]
    theta, *_ = _arx_theta(centred, long, long, spec.nk, _rough_lstsq)
    if not np.all(np.isfinite(theta)):
        return None
    return _balanced_poles(np.concatenate([np.zeros(spec.nk), theta[long:]]),
                           np.concatenate([[1.0], theta[:long]]), order)


def _subspace_poles(data: IdData, spec: _Spec, order: int) -> np.ndarray | None:
    """The poles of an ``n4sid`` model of ``order`` (None if the subspace module is absent or fails).

    Only for a delay of at most one sample: the state-space model's states would otherwise spend
    themselves on the delay."""
    if spec.nk > 1 or order < 1:
        return None
    try:
        from .subspace import n4sid
    except ImportError:
        return None
    try:
        with np.errstate(all="ignore"):
            model = n4sid(data, order)
        poles = np.asarray(model.poles(), complex)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None
    if not model.success or poles.size != order or not np.all(np.isfinite(poles)):
        return None
    return np.real(np.poly(poles))


def _b_given_f(spec: _Spec, segments, F: np.ndarray) -> np.ndarray:
    """``B`` by least squares for a given ``F``: ``y = B (u / F) + e`` is linear in ``B``."""
    signals = [{"target": y, "w": _lfilter([1.0], F, u)} for y, u in segments]
    phi, target = _regression(signals, [("w", range(spec.nk, spec.nk + spec.nb), 1.0)], spec.nk + spec.nb - 1)
    return _lstsq(phi, target)


def _g_starts(spec: _Spec, data: IdData, segments) -> list[np.ndarray]:
    """Starts ``[b, f]`` of ``B/F``: Steiglitz-McBride, and ``F`` from the poles of a long ARX model
    reduced by balanced truncation (or, if that fails, of ``n4sid``), ``B`` by least squares.

    Steiglitz-McBride can settle where a pole cancels a zero (on closed-loop data it did, near
    z = 1); the reduced models' poles are those of the dominant dynamics."""
    starts = [_oe_start(spec, segments)]
    if spec.nf:
        # n4sid only where the balanced truncation fails: on the actuator's records the two gave the
        # same poles, and n4sid cost more than the rest of the search at 400 samples
        F = _reduced_arx_poles(spec, segments, spec.nf)
        F = _subspace_poles(data, spec, spec.nf) if F is None else F
        if F is not None:
            F = _stable(F)
            starts.append(np.concatenate([_b_given_f(spec, segments, F), F[1:]]))
    return [start for start in starts if np.all(np.isfinite(start))] or starts[:1]


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
    squares), from ARX with ``C = 1`` and from ``A`` of a long ARX model reduced by balanced
    truncation, and minimises the one-step prediction errors ``e = (A y - B u) / C`` by
    Levenberg-Marquardt with the analytic Jacobian from the best of them (see the module's
    description), ``C`` kept stable.

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
        Most Levenberg-Marquardt iterations of the estimate that is kept (its short first run
        included; the polish on a long record's whole has as many again).

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
    # the starts need no more than the part of a long record the search runs on
    return _pem(spec, data, _armax_starts(spec, data, _shortened(data.segments(), _SEARCH_SAMPLES)), initial,
                iterations)


def oe(data: IdData, nb: int, nf: int, nk: int, *, initial: str = "zero", max_iterations: int = 100) -> PolynomialModel:
    """Output-error model ``y(t) = B(q)/F(q) u(t) + e(t)`` by the prediction-error method (MATLAB ``oe``).

    Starts from Steiglitz-McBride (ARX refitted on data filtered by ``1/F``) and from the poles
    of a long ARX model reduced by balanced truncation (``B`` by least squares), and minimises
    the output error ``e = y - B/F u`` by Levenberg-Marquardt with the analytic Jacobian from
    the best of them (see the module's description), ``F`` kept stable. The fit is the
    simulation (OE's predictor is its simulation).

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
        Most Levenberg-Marquardt iterations of the estimate that is kept (its short first run
        included; the polish on a long record's whole has as many again).

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
    # the starts need no more than the part of a long record the search runs on
    return _pem(spec, data, _g_starts(spec, data, _shortened(data.segments(), _SEARCH_SAMPLES)), initial,
                iterations)


def bj(data: IdData, nb: int, nc: int, nd: int, nf: int, nk: int, *, initial: str = "zero",
       max_iterations: int = 100) -> PolynomialModel:
    """Box-Jenkins model ``y(t) = B(q)/F(q) u(t) + C(q)/D(q) e(t)`` by the prediction-error method (MATLAB ``bj``).

    Starts ``B/F`` as :func:`oe` does and ``C/D`` from Hannan-Rissanen on each start's output
    error, ranks the starts by that output error whitened by a long AR model (what ``B/F``
    allows, whatever the rough noise model), then minimises ``e = D/C (y - B/F u)`` by
    Levenberg-Marquardt with the analytic Jacobian from the best of them (see the module's
    description), ``C``, ``D`` and ``F`` kept stable.

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
        Most Levenberg-Marquardt iterations of the estimate that is kept (its short first run
        included; the polish on a long record's whole has as many again).

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
    # the starts need no more than the part of a long record the search runs on
    segments = _shortened(data.segments(), _SEARCH_SAMPLES)
    starts = []
    for g_theta in _g_starts(spec, data, segments):
        b, f = g_theta[:spec.nb], g_theta[spec.nb:]
        gb, gf = np.concatenate([np.zeros(spec.nk), b]), np.concatenate([[1.0], f])
        c, d = _arma_start(spec, [y - _lfilter(gb, gf, u) for y, u in segments])
        starts.append(np.concatenate([b, c, d, f]))
    # with a noise model, the starts are ranked by the output error they leave, whitened
    score = _whitened_output_error if spec.nc or spec.nd else None
    return _pem(spec, data, starts, initial, iterations, score)


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
