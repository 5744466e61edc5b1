"""Least-squares identification of M, B, Af, d0 and beta_e (eqs. 15-18).

Two linear-in-parameter forms of the model (docs/model.md, section 4):

    y1 = A1 p1 - A2 p2 = M dv/dt + B v + Af S(v) + d          (eq. 15a)
    y2 = dp1/dt = beta_e phi2,
         phi2 = -v/(L0 + x) + Kq1 sqrt(dp1) u / (A1 (L0 + x))    (eq. 15b)

Both sides go through the same prefilter H(s) = 1/(tau_f s + 1) (eqs. 16-17);
a derivative on the left is s H(s) applied to the measured signal, computed
as (signal - H[signal]) / tau_f, which is exactly s/(tau_f s + 1). The signals
are interpolated between samples with cubic splines on a 16 times finer grid,
the regressors are formed there and filtered exactly (H discretised for
signals linear between the fine samples), then read back at the samples: the
filtered equation then holds to ~1e-5 N instead of ~2 N at 1 kHz. Every
filter starts in steady state at the first sample (the pressures start at
12 MPa, not at 0).

The disturbance d is modelled as

* ``constant``: d = d0, the paper's slow component;
* ``harmonic``: d = d0 + a sin(2 pi f t) + b cos(2 pi f t), with f given or
  estimated from the residual of the constant model (periodogram peak, then
  refined by minimising the harmonic model's residual).

Estimates come from a column-scaled SVD least-squares solve (never an explicit
inverse). Their standard errors account for the colour the prefilter gives the
residual: a Newey-West (HAC) covariance with a bandwidth of ``20 tau_f``; the
textbook ``s^2 (Phi^T Phi)^-1`` is reported too, to show how narrow it is.

Two estimators (``estimator``): the paper's least squares, and instrumental
variables (IV). A noisy load force makes the least squares biased: it enters
the filtered acceleration s H[v], a regressor of eq. 15a, so the regressor is
correlated with the error (M -0.74 %, -0.96 standard error at sigma = 2000 N,
growing as sigma^2; B and Af, correlated with it, -0.27 and +0.23);
the IV's instruments are the same regressors formed from a noise-free
simulation of the model at the current estimates, driven by the measured u
(as SRIVC builds its own, :mod:`eha_core.identify._srivc`). Two kinds of
intervals (``intervals``): Newey-West with the normal quantile, the least
squares' default, or equal-weighted cosines with Student's t quantile
(honest over 1000 seeds), the IV's default.

Examples
--------
>>> from eha_core.experiments import lse_data
>>> from eha_core.identify.lse import identify_lse
>>> res = identify_lse(lse_data(disturbance="none"))
>>> {k: abs(e) < 1e-4 for k, e in res.rel_error.items()}    # each within 0.01 % (B, the worst: 0.004 %)
{'M': True, 'B': True, 'Af': True, 'beta_e': True}
>>> abs(res.estimates["d0"]) < 0.01
True
>>> iv = identify_lse(lse_data(disturbance="white:2000", seed=1), estimator="iv")
>>> iv.estimator, iv.intervals, iv.cosine_terms, round(iv.critical_value, 3)
('iv', 'ewc', 15, 2.131)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, signal

from .._checks import ComputationError, not_allowed, shown
from ..cancel import CancelToken, check
from ..params import ActuatorParams
from ._stats import Z95
from .disturbance import DISTURBANCE_MODELS
from .lse_choices import DEFAULT_INTERVALS, ESTIMATORS, INTERVALS, checked_choices

__all__ = ["MeasuredData", "LSEResult", "identify_lse", "prefilter", "default_cosine_terms", "DISTURBANCE_MODELS",
           "ESTIMATORS", "INTERVALS", "DEFAULT_INTERVALS", "IV_MAX_ITERATIONS", "MIN_COSINE_TERMS"]

#: Cap on the fine grid (samples x upsampling factor) to bound memory.
_MAX_FINE_SAMPLES = 2_000_000
#: Fewest samples :class:`MeasuredData` accepts (the CSV reader asks as many).
_MIN_ROWS = 50
#: IV iterations at most, after the least squares that starts them.
IV_MAX_ITERATIONS = 5
#: Relative change of the estimates (in the regressors' scale) that ends the IV iterations.
_IV_TOL = 1e-6
#: Fewest cosines of the EWC intervals (a t with fewer degrees of freedom is too wide to tell much).
MIN_COSINE_TERMS = 4


def _check_uniform(t: np.ndarray) -> None:
    """Refuse times that do not increase uniformly, naming the first row that breaks it.

    The criterion: every step > 0 and the steps' spread (max - min) at most
    1e-6 times their mean. The row named is the first at which the steps so
    far spread more than that.
    """
    dt = np.diff(t)
    decreasing = np.flatnonzero(dt <= 0)
    if decreasing.size:
        k = int(decreasing[0]) + 2          # the row (from 1) of the later sample
        raise not_allowed("t", t, f"the time does not increase at row {k} ({t[k - 1]:g} after "
                                         f"{t[k - 2]:g}); the sampling must be uniform and increasing")
    tol = 1e-6 * dt.mean()
    if np.ptp(dt) > tol:
        spread = np.maximum.accumulate(dt) - np.minimum.accumulate(dt)
        i = int(np.flatnonzero(spread > tol)[0])
        k = i + 2
        raise not_allowed("t", t, f"the sampling is not uniform at row {k} (a step of {dt[i]:.6g} s "
                                         f"after steps of {np.median(dt[:i]):.6g} s); resample the data "
                                         "at a constant interval")


@dataclass(frozen=True, eq=False)
class MeasuredData:
    """Sampled measurements for identification: t [s], x [m], v [m/s], p1, p2 [Pa], u [V].

    Build it from arrays, a :class:`~eha_core.simulate.SimulationResult`
    (:meth:`from_simulation`) or a table with those columns (:meth:`from_table`).
    Sampling must be uniform.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    u: np.ndarray
    source: str = "data"

    def __post_init__(self):
        # Rows are counted from 1, the first sample being row 1, as the CSV
        # reader (eha_core.data) counts a file's data rows.
        names = ("t", "x", "v", "p1", "p2", "u")
        arrays = {}
        for n in names:
            a = np.asarray(getattr(self, n), dtype=float).ravel()
            if not np.all(np.isfinite(a)):
                k = int(np.argmin(np.isfinite(a)))
                raise not_allowed(n, a, f"row {k + 1} is {a[k]:g}; every value must be a finite number")
            arrays[n] = a
        for n in names[1:]:
            if arrays[n].size != arrays["t"].size:
                raise not_allowed(n, arrays[n], f"it has {arrays[n].size} rows where t has {arrays['t'].size}; "
                                                       "every column needs one value per time")
        t = arrays["t"]
        if t.size < _MIN_ROWS:
            raise not_allowed("t", t, f"{t.size} rows of data; need at least {_MIN_ROWS}")
        _check_uniform(t)
        for n in names:
            object.__setattr__(self, n, arrays[n])

    @property
    def ts(self) -> float:
        """Sample interval [s]."""
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))

    @classmethod
    def from_simulation(cls, res, source: str = "simulation") -> MeasuredData:
        """The sensors of a simulated run ``res`` (a :class:`~eha_core.simulate.SimulationResult`),
        noise-free; ``source`` says where they come from."""
        return cls(res.t, res.x, res.v, res.p1, res.p2, res.u, source=source)

    @classmethod
    def from_table(cls, table, source: str = "table") -> MeasuredData:
        """From a pandas DataFrame or a mapping with columns t, x, v, p1, p2, u.

        ``table`` holds the columns in SI units; ``source`` says where they come from.
        """
        missing = [c for c in ("t", "x", "v", "p1", "p2", "u") if c not in table]
        if missing:
            have = ", ".join(str(c) for c in table) or "none"
            raise not_allowed("table", f"a table with columns {have}",
                              f"no column {', '.join(missing)}; need t, x, v, p1, p2, u")
        return cls(*(np.asarray(table[c], dtype=float) for c in ("t", "x", "v", "p1", "p2", "u")), source=source)

    @classmethod
    def from_csv(cls, path, *, name: str = "--data", mapping: dict[str, str] | None = None) -> MeasuredData:
        """From a CSV file with columns t, x, v, p1, p2, u (SI units), read by
        :func:`eha_core.data.read_columns` (a bad cell is named by column and row).

        ``path`` is the file's name or an open file; a refusal names it ``name`` (the option
        or form field that gave it); ``mapping`` says which of the file's columns holds each
        of t, x, v, p1, p2, u (``{"x": "position[mm]"}``; by default the columns of those names).
        """
        from ..data import read_columns, sample_time

        cols = read_columns(path, ("t", "x", "v", "p1", "p2", "u"), name=name, min_rows=_MIN_ROWS, mapping=mapping)
        sample_time(cols["t"], name=name, path=path)
        return cls(*(cols[c] for c in ("t", "x", "v", "p1", "p2", "u")), source=str(path))

    def with_noise(self, sigmas: dict[str, float], seed: int = 0) -> MeasuredData:
        """Add white Gaussian measurement noise per sensor, e.g. {'v': 1e-4, 'p1': 1e4}.

        Parameters
        ----------
        sigmas : dict of str to float
            Standard deviation per sensor (x, v, p1, p2), in the sensor's SI unit (m, m/s, Pa);
            a sensor not named stays noise-free.
        seed : int
            Seed of the noise (:func:`numpy.random.default_rng`).
        """
        rng = np.random.default_rng(seed)
        cols = {n: getattr(self, n) for n in ("x", "v", "p1", "p2")}
        for name, sigma in sigmas.items():
            if name not in cols:
                raise not_allowed(f"sigmas[{shown(name)}]", sigma, f"{shown(name)} is not a sensor; use x, v, p1, p2")
            if not (math.isfinite(sigma) and sigma >= 0):
                raise not_allowed(f"sigmas[{name}]", sigma, "must be a standard deviation >= 0 (in the sensor's units)")
            cols[name] = cols[name] + sigma * rng.standard_normal(self.t.size)
        return MeasuredData(self.t, cols["x"], cols["v"], cols["p1"], cols["p2"], self.u,
                            source=self.source + " + noise")


def prefilter(y: np.ndarray, ts: float, tau_f: float) -> tuple[np.ndarray, np.ndarray]:
    """H[y] and (s H)[y] for H(s) = 1/(tau_f s + 1) (eq. 17).

    H is discretised exactly for y linear between samples and starts in steady
    state at y[0]; (s H)[y] = (y - H[y]) / tau_f is the exact derivative filter.

    Parameters
    ----------
    y : array
        The signal, uniformly sampled.
    ts : float
        Sample interval [s].
    tau_f : float
        Prefilter time constant [s].
    """
    a = math.exp(-ts / tau_f)
    c = tau_f / ts * (1.0 - a)
    b = np.array([1.0 - c, c - a])           # y_k and y_{k-1} weights
    den = np.array([1.0, -a])
    zi = signal.lfilter_zi(b, den) * y[0]
    hy, _ = signal.lfilter(b, den, y, zi=zi)
    return hy, (y - hy) / tau_f


@dataclass(frozen=True, eq=False)
class LSEResult:
    """Estimates with standard errors and 95 % intervals, and the data behind them.

    ``estimates``, ``std_errors``, ``ci95`` are keyed by parameter name: M, B,
    Af, d0 (and d_sin, d_cos for the harmonic model) and beta_e.
    ``std_errors_textbook`` is s^2 (Phi^T Phi)^-1 (for the IV, s^2 (Z^T
    Phi)^-1 Z^T Z (Phi^T Z)^-1), which ignores the colour of the filtered
    residual (too narrow under noise). ``nominal`` and ``rel_error`` are
    filled when the true parameters are known.

    ``estimator`` is ``ls`` or ``iv`` (:func:`identify_lse`), ``iterations``
    the IV iterations run (0 for ``ls``). ``intervals`` says how the standard
    errors were computed: ``newey-west`` over ``hac_lags`` lags, or ``ewc``
    over ``cosine_terms`` cosines (``hac_lags`` is then 0, ``cosine_terms``
    None otherwise). ``ci95`` is ``estimate +- critical_value * std_error``:
    1.96 (normal) for ``newey-west``, Student's t quantile with
    ``cosine_terms`` degrees of freedom for ``ewc``. ``condition_number`` is
    that of the column-scaled regressors (``ls``) or of ``Q^T Phi``, Q the
    orthonormalised instruments (``iv``).
    """

    estimates: dict[str, float]
    std_errors: dict[str, float]
    std_errors_textbook: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    disturbance_model: str
    disturbance_freq_hz: float | None
    freq_estimated: bool
    tau_f: float
    ts: float
    n_samples: int
    hac_lags: int
    residual_rms: dict[str, float]
    condition_number: float
    success: bool
    message: str
    nominal: dict[str, float] = field(default_factory=dict)
    estimator: str = "ls"
    intervals: str = "newey-west"
    cosine_terms: int | None = None
    critical_value: float = Z95
    iterations: int = 0
    t: np.ndarray = field(default=None, repr=False)
    y1f: np.ndarray = field(default=None, repr=False)
    y1_fit: np.ndarray = field(default=None, repr=False)
    y2f: np.ndarray = field(default=None, repr=False)
    y2_fit: np.ndarray = field(default=None, repr=False)

    @property
    def rel_error(self) -> dict[str, float]:
        """(estimate - nominal) / nominal for the parameters with a non-zero nominal value."""
        return {k: (self.estimates[k] - v) / v for k, v in self.nominal.items() if v != 0 and k in self.estimates}

    def covers(self, name: str) -> bool:
        """Whether the 95 % interval of ``name`` contains its nominal value."""
        lo, hi = self.ci95[name]
        return lo <= self.nominal[name] <= hi

    def estimated_params(self, base: ActuatorParams) -> ActuatorParams:
        """``base`` with M, B, Af, beta_e and d0 replaced by the estimates (when valid)."""
        changes = {k: self.estimates[k] for k in ("M", "B", "Af", "beta_e", "d0")}
        return base.replace(**changes)

    def to_dict(self) -> dict:
        """The estimates, their errors and the settings as plain JSON-able values (SI)."""
        return {
            "estimates": self.estimates, "std_errors": self.std_errors,
            "std_errors_textbook": self.std_errors_textbook,
            "ci95": {k: list(v) for k, v in self.ci95.items()},
            "nominal": self.nominal, "rel_error": self.rel_error,
            "disturbance_model": self.disturbance_model,
            "disturbance_freq_hz": self.disturbance_freq_hz, "freq_estimated": self.freq_estimated,
            "tau_f": self.tau_f, "ts": self.ts, "n_samples": self.n_samples, "hac_lags": self.hac_lags,
            "residual_rms": self.residual_rms, "condition_number": self.condition_number,
            "success": self.success, "message": self.message,
            "estimator": self.estimator, "iterations": self.iterations, "intervals": self.intervals,
            "cosine_terms": self.cosine_terms, "critical_value": self.critical_value,
        }

    def to_pandas(self):
        """The estimates as a :class:`pandas.DataFrame` indexed by parameter (M, B, Af, d0, [d_sin, d_cos,]
        beta_e): ``value``, ``std_error``, ``ci95_low``, ``ci95_high`` (SI), ``unit``, ``display_unit``,
        ``display_scale`` and ``std_error_textbook``."""
        from .._display import estimates_frame

        names = list(self.estimates)
        return estimates_frame(((n, self.estimates[n], self.std_errors[n], *self.ci95[n]) for n in names),
                               extra={"std_error_textbook": [self.std_errors_textbook[n] for n in names]})

    def plot(self):
        """Draw the two filtered equations and the fit with matplotlib (:func:`eha_core.plotting.plot_lse`);
        returns the Figure."""
        from ..plotting import plot_lse

        return plot_lse(self)

    def __repr__(self) -> str:
        from .._display import block, with_error

        route = "least squares" if self.estimator == "ls" else "instrumental variables"
        model = f"{self.disturbance_model} disturbance"
        if self.disturbance_freq_hz is not None:
            model += f" at {self.disturbance_freq_hz:.4g} Hz" + (" (estimated)" if self.freq_estimated else "")
        head = f"LSEResult: {route} (eqs. 15-18), {model}, {self.n_samples} samples"
        items = [with_error(n, v, self.std_errors.get(n)) for n, v in self.estimates.items()]
        how = "Newey-West" if self.intervals == "newey-west" else f"{self.cosine_terms} equal-weighted cosines"
        notes = [f"± 1 standard error ({how}); .to_pandas(): the 95 % intervals; .plot(): the fit"]
        return block(head, self.success, self.message, items, notes)


def _solve(Phi: np.ndarray, y: np.ndarray, lags: int, cancel: CancelToken | None = None,
           cosine_terms: int | None = None):
    """Column-scaled SVD least squares with textbook and HAC covariances.

    The HAC covariance is Newey-West's over ``lags``, or with ``cosine_terms``
    the equal-weighted cosine one (:func:`_cosine_long_run`). ``cancel`` is
    checked at every Newey-West lag (each a pass over the data).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        scale = np.sqrt(np.sum(Phi * Phi, axis=0))
    if not (np.all(np.isfinite(Phi)) and np.all(np.isfinite(y)) and np.all(np.isfinite(scale))):
        # LAPACK would print to the server's stderr and fail with "SVD did not converge"
        raise ComputationError("the least squares failed: its regressors (eq. 15) are not finite, or too large to "
                               "square, with this record and these parameters")
    scale[scale == 0] = 1.0
    Z = Phi / scale
    theta_z, _, rank, sv = np.linalg.lstsq(Z, y, rcond=None)
    theta = theta_z / scale
    e = y - Phi @ theta
    n, p = Phi.shape
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    ZtZ_inv = np.linalg.pinv(Z.T @ Z)
    s2 = float(e @ e) / max(n - p, 1)
    cov_text = s2 * ZtZ_inv / np.outer(scale, scale)
    # HAC: the prefilter makes the residual correlated over ~tau_f
    g = Z * e[:, None]
    S = _newey_west(g, lags, n - p, cancel) if cosine_terms is None else _cosine_long_run(g, cosine_terms)
    cov_hac = ZtZ_inv @ S @ ZtZ_inv / np.outer(scale, scale)
    return theta, e, cov_text, cov_hac, rank, cond


def _newey_west(g: np.ndarray, lags: int, dof: int, cancel: CancelToken | None = None) -> np.ndarray:
    """Newey-West (Bartlett) long-run covariance of the rows of ``g`` (their sum's), scaled by n / dof.

    ``cancel`` is checked at every lag (each a pass over the data).
    """
    n = g.shape[0]
    S = g.T @ g
    for lag in range(1, min(lags, n - 1) + 1):
        check(cancel)
        w = 1.0 - lag / (lags + 1.0)
        G = g[lag:].T @ g[:-lag]
        S += w * (G + G.T)
    S *= n / max(dof, 1)
    return S


def _cosine_long_run(g: np.ndarray, terms: int) -> np.ndarray:
    """Equal-weighted cosine (EWC) long-run covariance of the rows of ``g`` (their sum's).

    The cosine transforms ``L_j = sqrt(2/n) sum_t g_t cos(pi j (t + 1/2) / n)``,
    ``j = 1..terms`` (a DCT-II), are nearly independent, each with the
    long-run covariance of ``g`` as its covariance, where the spectrum of ``g``
    is flat over the frequencies they cover (up to ``terms / (2 n ts)``). Their
    mean square (times n, the scale of a sum) makes a t statistic with
    ``terms`` degrees of freedom: the interval is ``estimate +- t_terms(0.975)
    se``, exact however few the terms (Lazarus, Lewis, Stock and Watson, J.
    Bus. Econ. Stat. 36, 2018). Newey-West's Bartlett weights instead reach
    far in frequency: they mix in the high-frequency part of the residual.
    """
    from scipy.fft import dct

    n = g.shape[0]
    lam = dct(g, type=2, axis=0)[1:terms + 1] / math.sqrt(2.0 * n)
    return n * (lam.T @ lam) / lam.shape[0]


def _iv_solve(Phi: np.ndarray, Z: np.ndarray, y: np.ndarray, lags: int, cancel: CancelToken | None = None,
              cosine_terms: int | None = None):
    """Instrumental-variable solution ``(Z^T Phi)^-1 Z^T y`` with textbook and HAC covariances.

    Column-scaled, and solved through a QR factorisation ``Z = Q R``: the same
    solution ``(Q^T Phi)^-1 Q^T y`` without squaring the conditioning. The
    HAC covariance is the sandwich ``G^-1 S G^-T`` with ``G = Q^T Phi`` and
    ``S`` the long-run covariance of ``q_t e_t`` (Newey-West over ``lags``,
    or EWC over ``cosine_terms``). Returns ``(theta, e, cov_text, cov_hac,
    cond)``, ``cond`` the condition number of ``G``, or None when the
    instruments are linearly dependent or do not determine every parameter.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        scale = np.sqrt(np.sum(Phi * Phi, axis=0))
        zscale = np.sqrt(np.sum(Z * Z, axis=0))
    if not (np.all(np.isfinite(Z)) and np.all(np.isfinite(zscale))):
        return None
    scale[scale == 0] = 1.0
    if np.any(zscale == 0):
        return None
    q, _ = np.linalg.qr(Z / zscale)
    G = q.T @ (Phi / scale)
    sv = np.linalg.svd(G, compute_uv=False)
    if not sv[-1] > 1e-10 * sv[0]:
        return None
    G_inv = np.linalg.inv(G)
    theta = (G_inv @ (q.T @ y)) / scale
    e = y - Phi @ theta
    n, p = Phi.shape
    s2 = float(e @ e) / max(n - p, 1)
    outer = np.outer(scale, scale)
    cov_text = s2 * (G_inv @ G_inv.T) / outer
    g = q * e[:, None]
    S = _newey_west(g, lags, n - p, cancel) if cosine_terms is None else _cosine_long_run(g, cosine_terms)
    cov_hac = G_inv @ S @ G_inv.T / outer
    return theta, e, cov_text, cov_hac, float(sv[0] / sv[-1])


def fine_grid_factor(n_samples: int) -> int:
    """How many times finer than the data the cubic interpolation's grid is:
    16, less for records so long that the grid would exceed ``_MAX_FINE_SAMPLES``."""
    return max(1, min(16, _MAX_FINE_SAMPLES // max(int(n_samples), 1)))


def _fine_grid(data, upsample: int, dp1: bool = False):
    """The measured signals on a grid ``upsample`` times finer (cubic splines).

    The regressors are nonlinear functions of the measurements (S(v) switches
    from -1 to +1 within a few samples as v crosses zero) and the pressures
    carry the hydraulic resonance near 21 Hz; filtering samples as if they were
    linear in between biases B by about 1.5 % at 1 kHz. Interpolating with
    cubic splines (error O(h^4) instead of O(h^2)), forming the regressors on
    the fine grid and filtering there removes that bias. With ``dp1`` the
    derivative of p1's spline on the fine grid is appended (None without a
    fine grid).
    """
    t = data.t
    if upsample <= 1:
        return (t, data.ts, data.x, data.v, data.p1, data.p2, data.u) + ((None,) if dp1 else ())
    from scipy.interpolate import CubicSpline

    h = data.ts / upsample
    t_fine = t[0] + np.arange((t.size - 1) * upsample + 1) * h
    splines = {n: CubicSpline(t, getattr(data, n)) for n in ("x", "v", "p1", "p2", "u")}
    out = (t_fine, h) + tuple(splines[n](t_fine) for n in ("x", "v", "p1", "p2", "u"))
    return out + ((splines["p1"](t_fine, 1),) if dp1 else ())


def _regressors(p: ActuatorParams, data, upsample: int, tau_f: float, cancel: CancelToken | None = None,
                spline_dp1: bool = False):
    """The filtered sides of eqs. 15a and 15b at the samples: y1f, H[v], sH[v], H[S(v)], sH[p1], H[phi2].

    ``data`` holds t, x, v, p1, p2, u (measured, or simulated for the
    instruments of the IV estimator); ``cancel`` is checked before each filter.
    With ``spline_dp1`` (and a fine grid) sH[p1] is taken as H applied to the
    derivative of p1's spline: the same in continuous time, but discretised as
    H[phi2] is, so that the fine grid's O(h^2) errors of the two sides of
    eq. 15b cancel (see :func:`identify_lse`, ``estimator``).
    """
    _, hf, x, v, p1, p2, u, *dp1_fine = _fine_grid(data, upsample, dp1=spline_dp1)

    def f(sig):
        """H[sig] and (s H)[sig] at the samples."""
        check(cancel)
        hy, dhy = prefilter(sig, hf, tau_f)
        return hy[::upsample], dhy[::upsample]

    y1f, _ = f(p.A1 * p1 - p.A2 * p2)
    vf, dvf = f(v)
    Sf, _ = f((2.0 / math.pi) * np.arctan(p.k_f * v))                  # eq. 2
    if spline_dp1 and dp1_fine[0] is not None:
        dp1f, _ = f(dp1_fine[0])
    else:
        _, dp1f = f(p1)
    dp1 = np.where(u >= 0, p.ps - p1, p1 - p.pr).clip(min=0.0)         # eq. 3
    phi2f, _ = f(-v / (p.L0 + x) + p.Kq1 * np.sqrt(dp1) * u / (p.A1 * (p.L0 + x)))
    return y1f, vf, dvf, Sf, dp1f, phi2f


def _harmonic_regressors(t, f_hz, ts, tau_f):
    s_f, _ = prefilter(np.sin(2 * np.pi * f_hz * t), ts, tau_f)
    c_f, _ = prefilter(np.cos(2 * np.pi * f_hz * t), ts, tau_f)
    return s_f, c_f


def _estimate_frequency(t, e, Phi, y, ts, tau_f, keep, cancel: CancelToken | None = None):
    """Frequency [Hz] of a sinusoidal disturbance hidden in the residual ``e``.

    ``cancel`` is checked at every trial frequency (each a least-squares fit).
    """
    n = e.size
    nfft = 1 << int(math.ceil(math.log2(8 * n)))
    spec = np.abs(np.fft.rfft((e - e.mean()) * np.hanning(n), nfft))
    freqs = np.fft.rfftfreq(nfft, ts)
    lo = 2.0 / (n * ts)                       # at least two periods in the record
    band = freqs >= lo
    f0 = float(freqs[band][np.argmax(spec[band])])
    df = 1.0 / (n * ts)

    def rss(f):
        check(cancel)
        s_f, c_f = _harmonic_regressors(t, f, ts, tau_f)
        P = np.column_stack([Phi, s_f[keep], c_f[keep]])
        norms = np.linalg.norm(P, axis=0)
        norms[norms == 0] = 1.0             # a regressor that is zero throughout (no motion): 0/0 would be NaN
        P = P / norms
        th, *_ = np.linalg.lstsq(P, y, rcond=None)
        r = y - P @ th
        return float(r @ r)

    res = optimize.minimize_scalar(rss, bounds=(max(lo, f0 - df), f0 + df), method="bounded",
                                   options={"xatol": 1e-6 * max(f0, 1.0)})
    return float(res.x) if res.success else f0


def _auxiliary_run(p: ActuatorParams, data: MeasuredData, estimates: dict[str, float], freq: float | None,
                   cancel: CancelToken | None) -> MeasuredData | str:
    """The nonlinear model at ``estimates``, driven by the measured u, without noise: the instruments' signals.

    Started from the measured first sample; the disturbance is the estimated
    d0 (and the harmonic model's sinusoid at ``freq``). B and Af are taken
    >= 0 (a model with negative friction is refused; the instruments need not
    come from the true model, only from one free of the noise). Returns the
    simulated record at the data's times, or a sentence saying why there is
    none.
    """
    from ..simulate import simulate_many

    try:
        model = p.replace(M=estimates["M"], B=max(estimates["B"], 0.0), Af=max(estimates["Af"], 0.0),
                          beta_e=estimates["beta_e"], d0=estimates["d0"])
    except ValueError as exc:
        return f"the auxiliary model of the instruments cannot be built at the estimates: {exc}"
    d = None
    if freq is not None:
        w = 2.0 * np.pi * freq * data.t
        d = estimates["d_sin"] * np.sin(w) + estimates["d_cos"] * np.cos(w)
    n = data.t.size
    start = [data.x[0], data.v[0], data.p1[0], data.p2[0]]
    try:
        # one thread: identify_lse may run in a worker thread of a study or a server
        run = simulate_many([model], [data.u], [d], t_end=(n - 1) * data.ts, dt=data.ts, initial_states=[start],
                            labels=["auxiliary model"], cancel=cancel, parallel=False)[0]
    except ValueError as exc:
        return f"the auxiliary model of the instruments cannot be simulated: {exc}"
    if not run.success or run.t.size != n:
        return f"the auxiliary model of the instruments failed: {run.message}"
    return MeasuredData(data.t, run.x, run.v, run.p1, run.p2, data.u, source="auxiliary model")


def _iv(p, data, names, theta1, theta2, freq, upsample, tau_f, keep, exogenous, Phi1, y1, Phi2, y2, lags,
        terms, cancel):
    """The IV iterations from the least-squares estimates ``theta1`` (eq. 15a) and ``theta2`` (eq. 15b).

    Each iteration simulates the model at the current estimates without noise
    (:func:`_auxiliary_run`), forms the regressors of eqs. 15a-b from the
    simulated signals through the same prefilter (eq. 17) as the
    instruments, and solves ``(Z^T Phi)^-1 Z^T y`` for both equations;
    ``exogenous`` (the constant's and the harmonic model's regressors, noise
    free) are their own instruments. At most :data:`IV_MAX_ITERATIONS`, ended
    earlier when the estimates change by less than ``_IV_TOL`` (relative, in
    the scale of the regressors). Returns ``(sol1, sol2, iterations)``, each
    ``sol`` as :func:`_iv_solve` gives it, or a sentence saying why the IV
    failed.
    """
    scale1 = np.sqrt(np.sum(Phi1 * Phi1, axis=0))
    sol1 = sol2 = None
    iterations = 0
    for _ in range(IV_MAX_ITERATIONS):
        check(cancel)
        estimates = dict(zip(names, map(float, theta1), strict=True))
        estimates["beta_e"] = float(theta2[0])
        aux = _auxiliary_run(p, data, estimates, freq, cancel)
        if isinstance(aux, str):
            return aux
        _, zvf, zdvf, zSf, _, zphi2f = _regressors(p, aux, upsample, tau_f, cancel)
        Z1 = np.column_stack([zdvf, zvf, zSf, *exogenous])[keep]
        sol1 = _iv_solve(Phi1, Z1, y1, lags, cancel, terms)
        sol2 = _iv_solve(Phi2, zphi2f[keep, None], y2, lags, cancel, terms)
        if sol1 is None or sol2 is None:
            return ("the instruments do not determine every parameter: the auxiliary model's regressors are "
                    "linearly dependent")
        iterations += 1
        new1, new2 = sol1[0], sol2[0]
        if not (np.all(np.isfinite(new1)) and np.all(np.isfinite(new2))):
            return "the instrumental variables gave estimates that are not finite"
        tiny = np.finfo(float).tiny
        change = max(np.linalg.norm((new1 - theta1) * scale1) / max(np.linalg.norm(new1 * scale1), tiny),
                     abs(new2[0] - theta2[0]) / max(abs(new2[0]), tiny))
        theta1, theta2 = new1, new2
        if change < _IV_TOL:
            break
    return sol1, sol2, iterations


def default_cosine_terms(n_samples: int, ts: float, tau_f: float) -> int:
    """Cosines of the EWC intervals by default: those below a tenth of the prefilter's corner frequency.

    ``n_samples`` are the samples fitted, ``ts`` their interval [s], ``tau_f``
    the prefilter's time constant [s]; the terms are
    ``n_samples ts / (10 pi tau_f)`` (15 for the default 5 s record, tau_f =
    0.01 s), at least :data:`MIN_COSINE_TERMS`. The cosines cover frequencies
    up to ``terms / (2 n ts)``, 1.6 Hz here: the score ``q_t e_t`` must have a
    flat spectrum there. That of eq. 15b rises from 0 Hz (its residual is the
    interpolation's error at the kinks the force noise gives v, high-pass):
    over 1000 seeds (IV, white force noise) beta_e's standard error was 1 %
    wide with 15 cosines (coverage 0.957), 5 % with 24 (0.965), 28 % with 64
    (0.987), as wide as Newey-West's over 200 lags (0.993).
    """
    return max(MIN_COSINE_TERMS, int(n_samples * ts / (10.0 * math.pi * tau_f)))


def _checked_estimator(estimator, intervals, hac_lags, cosine_terms) -> str:
    """The intervals ``estimator`` takes (its default when ``intervals`` is None), the choices checked."""
    _, intervals = checked_choices(estimator, intervals)
    if hac_lags is not None and intervals != "newey-west":
        raise not_allowed("hac_lags", hac_lags, "it is the bandwidth of the newey-west intervals; the ewc "
                                                "intervals take cosine_terms", context=f"with intervals {intervals}")
    if cosine_terms is not None and intervals != "ewc":
        raise not_allowed("cosine_terms", cosine_terms, "they set the ewc intervals; newey-west takes hac_lags",
                          context=f"with intervals {intervals}")
    return intervals


def _checked_terms(cosine_terms, n_kept: int, ts: float, tau_f: float) -> int:
    """The cosines of the ewc intervals: ``cosine_terms`` checked, or the default."""
    if cosine_terms is None:
        return default_cosine_terms(n_kept, ts, tau_f)
    if (isinstance(cosine_terms, bool) or not isinstance(cosine_terms, (int, np.integer))
            or not 1 <= cosine_terms <= n_kept // 2):
        raise not_allowed("cosine_terms", cosine_terms, f"use a whole number from 1 to {n_kept // 2} (half the "
                                                        "samples fitted)")
    return int(cosine_terms)


def _t_quantile(dof: int) -> float:
    """The 0.975 quantile of Student's t with ``dof`` degrees of freedom."""
    from scipy.special import stdtrit

    return float(stdtrit(dof, 0.975))


def _longest_tau_f(t: np.ndarray) -> float:
    """The longest prefilter time constant whose start-up (5 tau_f, left out) leaves 20 samples of the
    record at times ``t``, written with four digits, rounded down (the value shown is one that works)."""
    longest = (t[-20] - t[0]) / 5
    step = 10.0 ** (math.floor(math.log10(longest)) - 3)
    longest = math.floor(longest / step) * step
    while longest > step and np.count_nonzero(t - t[0] >= 5 * longest) < 20:
        longest -= step
    return longest


def identify_lse(data: MeasuredData, params: ActuatorParams | None = None, *, tau_f: float = 0.01,
                 disturbance_model: str = "constant", disturbance_freq_hz: float | None = None,
                 skip_s: float | None = None, hac_lags: int | None = None,
                 interpolation: str = "cubic", nominal: ActuatorParams | None = None,
                 estimator: str = "ls", intervals: str | None = None, cosine_terms: int | None = None,
                 cancel: CancelToken | None = None) -> LSEResult:
    """Estimate M, B, Af, d0 (eq. 15a) and beta_e (eq. 15b) by filtered least squares (eq. 18), or by IV.

    Parameters
    ----------
    data : MeasuredData
        Uniformly sampled t, x, v, p1, p2, u.
    params : ActuatorParams, optional
        The known (measured) quantities: Dc, dc, L0, Kq1, Kq2, ps, pr, k_f.
        Defaults to the paper's.
    tau_f : float
        Prefilter time constant [s] (eq. 17; the paper's 0.01).
    disturbance_model : {'constant', 'harmonic'}
        The load disturbance's model: d = d0 (the paper's), or d0 plus a
        sinusoid ``d_sin sin(2 pi f t) + d_cos cos(2 pi f t)``.
    disturbance_freq_hz : float, optional
        Frequency f of the harmonic disturbance [Hz]; estimated from the data when None.
    skip_s : float, optional
        Initial stretch left out of the fit, default 5 tau_f (filter start-up).
    hac_lags : int, optional
        Newey-West bandwidth in samples (``intervals="newey-west"`` only),
        default 20 tau_f / ts (coverage 0.95 for every parameter over 60
        seeds under white force noise; 10 tau_f gives 0.92 for d0).
    interpolation : {'cubic', 'linear'}
        How the signals are taken between samples when filtering: cubic
        splines on a 16 times finer grid (default; see :func:`_fine_grid`), or
        linear (the classical discretisation; biased at 1 kHz).
    nominal : ActuatorParams, optional
        True parameters, when known (simulated data), for relative errors;
        defaults to ``params``.
    estimator : {'ls', 'iv'}
        ``ls``: the paper's least squares (eq. 18). Under a noisy load force
        it is biased: the force enters the filtered acceleration s H[v], a
        regressor, which is then correlated with the equation's error (over
        1000 seeds at sigma = 2000 N: M -0.96 standard error, B -0.27, Af
        +0.23; the bias grows as sigma^2). And beta_e
        (eq. 15b) is pulled down as sigma^2 by the interpolation's error at the
        kinks the force noise gives v (an error in a regressor). ``iv``:
        instrumental variables, iterated from the least squares as SRIVC
        does (:mod:`eha_core.identify._srivc`): the model is simulated
        without noise at the current estimates, driven by the measured u;
        the regressors formed from its signals, through the same prefilter,
        are the instruments Z, and ``(Z^T Phi)^-1 Z^T y`` the estimate, for
        both equations; at most :data:`IV_MAX_ITERATIONS` times. The
        instruments are free of the noise, so the estimate is unbiased (over
        1000 seeds at sigma = 2000 N: bias under 0.05 standard errors for
        every parameter; see benchmarks/bench_lse_coverage.py). For ``iv``
        the derivative of eq. 15b's left side is the filtered derivative of
        p1's spline, H[dp1/dt], discretised as H[phi2] is: the fine grid's
        O(h^2) errors of the two sides then cancel (with s H[p1] they bias
        beta_e by +470 Pa, 4e-7, which is 0.2 standard error at 2000 N).
        Failures of the IV (a model that cannot be simulated at the
        estimates, instruments that do not determine every parameter) are
        data: ``success`` False, the message says why, the estimates are the
        least squares' that started it.
    intervals : {'newey-west', 'ewc'}, optional
        How the standard errors and 95 % intervals account for the colour the
        prefilter gives the residual. ``newey-west``: Newey-West over
        ``hac_lags`` with the normal quantile 1.96 (its errors run 6-8 % narrow
        for M, B, Af, d0 and 25 % wide for beta_e under white force noise).
        ``ewc``: equal-weighted cosines (:func:`_cosine_long_run`) over
        ``cosine_terms`` with Student's t quantile (2.13 for 15 terms): over
        1000 seeds every parameter's unbiased estimator covered within the
        binomial band of 0.95. Default: ``newey-west`` for ``ls`` (the
        paper's estimator, unchanged), ``ewc`` for ``iv``.
    cosine_terms : int, optional
        Cosines of the ``ewc`` intervals (their degrees of freedom), default
        :func:`default_cosine_terms`.
    cancel : eha_core.cancel.CancelToken, optional
        Checked on entry and between the stages (interpolation, each filter,
        each Newey-West lag, each trial frequency, each IV iteration and its
        auxiliary simulation); raises :class:`~eha_core.cancel.Cancelled` when
        set.
    """
    check(cancel)
    params = params if params is not None else ActuatorParams()
    nominal = nominal if nominal is not None else params
    if not (isinstance(tau_f, (int, float)) and math.isfinite(tau_f) and tau_f > 0):
        raise not_allowed("tau_f", tau_f, "must be a time constant > 0 s")
    if interpolation not in ("cubic", "linear"):
        raise not_allowed("interpolation", interpolation, "use cubic or linear")
    if disturbance_model not in DISTURBANCE_MODELS:
        raise not_allowed("disturbance_model", disturbance_model, f"use one of {', '.join(DISTURBANCE_MODELS)}")
    if disturbance_freq_hz is not None and not (math.isfinite(disturbance_freq_hz) and disturbance_freq_hz > 0):
        raise not_allowed("disturbance_freq_hz", disturbance_freq_hz, "must be > 0 Hz, or None to estimate it")
    intervals = _checked_estimator(estimator, intervals, hac_lags, cosine_terms)
    ts = data.ts
    if disturbance_freq_hz is not None and disturbance_freq_hz >= 0.5 / ts:
        raise not_allowed("disturbance_freq_hz", disturbance_freq_hz,
                          f"must be below the Nyquist frequency {0.5 / ts:g} Hz")
    skip_given = skip_s is not None
    skip_s = 5 * tau_f if skip_s is None else float(skip_s)
    keep = data.t - data.t[0] >= skip_s
    n_kept = int(keep.sum())
    if n_kept < 20:
        record = f"a record of {data.t[-1] - data.t[0]:g} s"
        if skip_given:
            raise not_allowed("skip_s", skip_s, f"it leaves {n_kept} samples of {record}; need at least 20")
        # the skip is the filter's start-up, 5 tau_f: the time constant is what the user chose
        allowed = f"use at most {_longest_tau_f(data.t):.4g} s" if data.t.size > 20 else "use a longer record"
        raise not_allowed("tau_f", tau_f, f"the first 5 tau_f (the prefilter's start-up) are left out and leave "
                                          f"{n_kept} samples of {record}; need at least 20: {allowed}")
    terms = _checked_terms(cosine_terms, n_kept, ts, tau_f) if intervals == "ewc" else None
    lags = int(math.ceil(20 * tau_f / ts)) if hac_lags is None else int(hac_lags)

    p = params
    t = data.t
    upsample = 1 if interpolation == "linear" else fine_grid_factor(t.size)
    y1f, vf, dvf, Sf, dp1f, phi2f = _regressors(p, data, upsample, tau_f, cancel, spline_dp1=estimator == "iv")
    onef = np.ones_like(t)

    names = ["M", "B", "Af", "d0"]
    cols = [dvf, vf, Sf, onef]
    freq, freq_estimated = None, False
    base = np.column_stack(cols)[keep]
    if disturbance_model == "harmonic":
        if disturbance_freq_hz is None:
            theta0, e0, *_ = _solve(base, y1f[keep], 0)
            freq = _estimate_frequency(t, e0, base, y1f[keep], ts, tau_f, keep, cancel)
            freq_estimated = True
        else:
            freq = float(disturbance_freq_hz)
        s_f, c_f = _harmonic_regressors(t, freq, ts, tau_f)
        cols += [s_f, c_f]
        names += ["d_sin", "d_cos"]
    Phi1 = np.column_stack(cols)[keep]
    theta1, e1, cov1_t, cov1_h, rank, cond = _solve(Phi1, y1f[keep], lags, cancel, terms)
    Phi2 = phi2f[keep, None]
    theta2, e2, cov2_t, cov2_h, _, _ = _solve(Phi2, dp1f[keep], lags, cancel, terms)
    success = rank == Phi1.shape[1]
    message = "ok" if success else (
        f"the regressors are linearly dependent (rank {rank} of {Phi1.shape[1]}): the input does not excite "
        "every parameter; use a richer input")
    iterations = 0
    if estimator == "iv" and success:
        iv = _iv(p, data, names, theta1, theta2, freq, upsample, tau_f, keep, cols[3:], Phi1, y1f[keep], Phi2,
                 dp1f[keep], lags, terms, cancel)
        if isinstance(iv, str):
            success, message = False, f"{iv}; the estimates are the least squares' that started the IV"
        else:
            (theta1, e1, cov1_t, cov1_h, cond), (theta2, e2, cov2_t, cov2_h, _), iterations = iv

    estimates = {n: float(th) for n, th in zip(names, theta1, strict=True)}
    estimates["beta_e"] = float(theta2[0])
    se = {n: float(math.sqrt(max(cov1_h[i, i], 0.0))) for i, n in enumerate(names)}
    se["beta_e"] = float(math.sqrt(max(cov2_h[0, 0], 0.0)))
    se_t = {n: float(math.sqrt(max(cov1_t[i, i], 0.0))) for i, n in enumerate(names)}
    se_t["beta_e"] = float(math.sqrt(max(cov2_t[0, 0], 0.0)))
    crit = Z95 if terms is None else _t_quantile(terms)
    ci = {n: (estimates[n] - crit * se[n], estimates[n] + crit * se[n]) for n in estimates}

    y1_fit = np.full(t.shape, np.nan)
    y1_fit[keep] = Phi1 @ theta1
    y2_fit = np.full(t.shape, np.nan)
    y2_fit[keep] = phi2f[keep] * theta2[0]
    nom = {"M": nominal.M, "B": nominal.B, "Af": nominal.Af, "d0": nominal.d0, "beta_e": nominal.beta_e}
    return LSEResult(
        estimates=estimates, std_errors=se, std_errors_textbook=se_t, ci95=ci,
        disturbance_model=disturbance_model, disturbance_freq_hz=freq, freq_estimated=freq_estimated,
        tau_f=float(tau_f), ts=ts, n_samples=n_kept, hac_lags=lags if terms is None else 0,
        residual_rms={"y1": float(np.sqrt(np.mean(e1**2))), "y2": float(np.sqrt(np.mean(e2**2)))},
        condition_number=cond, success=bool(success), message=message, nominal=nom,
        estimator=estimator, intervals=intervals, cosine_terms=terms, critical_value=crit, iterations=iterations,
        t=t, y1f=y1f, y1_fit=y1_fit, y2f=dp1f, y2_fit=y2_fit,
    )
