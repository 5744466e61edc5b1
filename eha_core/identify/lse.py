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

Examples
--------
>>> from eha_core.experiments import lse_data
>>> from eha_core.identify.lse import identify_lse
>>> res = identify_lse(lse_data(disturbance="none"))
>>> {k: f"{100 * e:+.3f} %" for k, e in res.rel_error.items()}
{'M': '-0.000 %', 'B': '-0.003 %', 'Af': '+0.000 %', 'beta_e': '+0.000 %'}
>>> abs(res.estimates["d0"]) < 0.01
True
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

__all__ = ["MeasuredData", "LSEResult", "identify_lse", "prefilter", "DISTURBANCE_MODELS"]

#: Cap on the fine grid (samples x upsampling factor) to bound memory.
_MAX_FINE_SAMPLES = 2_000_000
#: Fewest samples :class:`MeasuredData` accepts (the CSV reader asks as many).
_MIN_ROWS = 50


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
        return cls(res.t, res.x, res.v, res.p1, res.p2, res.u, source=source)

    @classmethod
    def from_table(cls, table, source: str = "table") -> MeasuredData:
        """From a pandas DataFrame or a mapping with columns t, x, v, p1, p2, u."""
        missing = [c for c in ("t", "x", "v", "p1", "p2", "u") if c not in table]
        if missing:
            have = ", ".join(str(c) for c in table) or "none"
            raise not_allowed("table", f"a table with columns {have}",
                              f"no column {', '.join(missing)}; need t, x, v, p1, p2, u")
        return cls(*(np.asarray(table[c], dtype=float) for c in ("t", "x", "v", "p1", "p2", "u")), source=source)

    @classmethod
    def from_csv(cls, path, *, name: str = "--data") -> MeasuredData:
        """From a CSV file with columns t, x, v, p1, p2, u (SI units), read by
        :func:`eha_core.data.read_columns` (a bad cell is named by column and row)."""
        from ..data import read_columns, sample_time

        cols = read_columns(path, ("t", "x", "v", "p1", "p2", "u"), name=name, min_rows=_MIN_ROWS)
        sample_time(cols["t"], name=name, path=path)
        return cls(*(cols[c] for c in ("t", "x", "v", "p1", "p2", "u")), source=str(path))

    def with_noise(self, sigmas: dict[str, float], seed: int = 0) -> MeasuredData:
        """Add white Gaussian measurement noise per sensor, e.g. {'v': 1e-4, 'p1': 1e4}."""
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
    ``std_errors_textbook`` is s^2 (Phi^T Phi)^-1, which ignores the colour of
    the filtered residual (too narrow under noise). ``nominal`` and
    ``rel_error`` are filled when the true parameters are known.
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
        }


def _solve(Phi: np.ndarray, y: np.ndarray, lags: int, cancel: CancelToken | None = None):
    """Column-scaled SVD least squares with textbook and HAC covariances.

    ``cancel`` is checked at every Newey-West lag (each a pass over the data).
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
    # Newey-West: the prefilter makes the residual correlated over ~tau_f
    g = Z * e[:, None]
    S = g.T @ g
    for lag in range(1, min(lags, n - 1) + 1):
        check(cancel)
        w = 1.0 - lag / (lags + 1.0)
        G = g[lag:].T @ g[:-lag]
        S += w * (G + G.T)
    S *= n / max(n - p, 1)
    cov_hac = ZtZ_inv @ S @ ZtZ_inv / np.outer(scale, scale)
    return theta, e, cov_text, cov_hac, rank, cond


def fine_grid_factor(n_samples: int) -> int:
    """How many times finer than the data the cubic interpolation's grid is:
    16, less for records so long that the grid would exceed ``_MAX_FINE_SAMPLES``."""
    return max(1, min(16, _MAX_FINE_SAMPLES // max(int(n_samples), 1)))


def _fine_grid(data: MeasuredData, upsample: int):
    """The measured signals on a grid ``upsample`` times finer (cubic splines).

    The regressors are nonlinear functions of the measurements (S(v) switches
    from -1 to +1 within a few samples as v crosses zero) and the pressures
    carry the hydraulic resonance near 21 Hz; filtering samples as if they were
    linear in between biases B by about 1.5 % at 1 kHz. Interpolating with
    cubic splines (error O(h^4) instead of O(h^2)), forming the regressors on
    the fine grid and filtering there removes that bias.
    """
    t = data.t
    if upsample <= 1:
        return t, data.ts, data.x, data.v, data.p1, data.p2, data.u
    from scipy.interpolate import CubicSpline

    h = data.ts / upsample
    t_fine = t[0] + np.arange((t.size - 1) * upsample + 1) * h
    return (t_fine, h) + tuple(CubicSpline(t, getattr(data, n))(t_fine) for n in ("x", "v", "p1", "p2", "u"))


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


def identify_lse(data: MeasuredData, params: ActuatorParams | None = None, *, tau_f: float = 0.01,
                 disturbance_model: str = "constant", disturbance_freq_hz: float | None = None,
                 skip_s: float | None = None, hac_lags: int | None = None,
                 interpolation: str = "cubic", nominal: ActuatorParams | None = None,
                 cancel: CancelToken | None = None) -> LSEResult:
    """Estimate M, B, Af, d0 (eq. 15a) and beta_e (eq. 15b) by filtered least squares (eq. 18).

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
    disturbance_freq_hz : float, optional
        Frequency of the harmonic disturbance; estimated from the data when None.
    skip_s : float, optional
        Initial stretch left out of the fit, default 5 tau_f (filter start-up).
    hac_lags : int, optional
        Newey-West bandwidth in samples, default 20 tau_f / ts (coverage 0.95
        for every parameter over 60 seeds under white force noise; 10 tau_f
        gives 0.92 for d0).
    interpolation : {'cubic', 'linear'}
        How the signals are taken between samples when filtering: cubic
        splines on a 16 times finer grid (default; see :func:`_fine_grid`), or
        linear (the classical discretisation; biased at 1 kHz).
    nominal : ActuatorParams, optional
        True parameters, when known (simulated data), for relative errors;
        defaults to ``params``.
    cancel : eha_core.cancel.CancelToken, optional
        Checked on entry and between the stages (interpolation, each filter,
        each Newey-West lag, each trial frequency); raises
        :class:`~eha_core.cancel.Cancelled` when set.
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
    ts = data.ts
    if disturbance_freq_hz is not None and disturbance_freq_hz >= 0.5 / ts:
        raise not_allowed("disturbance_freq_hz", disturbance_freq_hz,
                          f"must be below the Nyquist frequency {0.5 / ts:g} Hz")
    skip_s = 5 * tau_f if skip_s is None else float(skip_s)
    keep = data.t - data.t[0] >= skip_s
    if keep.sum() < 20:
        raise not_allowed("skip_s", skip_s, f"it leaves {int(keep.sum())} samples of a record of "
                                            f"{data.t[-1] - data.t[0]:g} s; need at least 20")
    lags = int(math.ceil(20 * tau_f / ts)) if hac_lags is None else int(hac_lags)

    p = params
    t = data.t
    upsample = 1 if interpolation == "linear" else fine_grid_factor(t.size)
    tf_, hf, x, v, p1, p2, u = _fine_grid(data, upsample)

    def f(sig):
        """H[sig] and (s H)[sig] at the samples."""
        check(cancel)
        hy, dhy = prefilter(sig, hf, tau_f)
        return hy[::upsample], dhy[::upsample]

    y1f, _ = f(p.A1 * p1 - p.A2 * p2)
    vf, dvf = f(v)
    Sf, _ = f((2.0 / math.pi) * np.arctan(p.k_f * v))                  # eq. 2
    onef = np.ones_like(t)
    _, dp1f = f(p1)
    dp1 = np.where(u >= 0, p.ps - p1, p1 - p.pr).clip(min=0.0)         # eq. 3
    phi2f, _ = f(-v / (p.L0 + x) + p.Kq1 * np.sqrt(dp1) * u / (p.A1 * (p.L0 + x)))

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
    theta1, e1, cov1_t, cov1_h, rank, cond = _solve(Phi1, y1f[keep], lags, cancel)
    Phi2 = phi2f[keep, None]
    theta2, e2, cov2_t, cov2_h, _, _ = _solve(Phi2, dp1f[keep], lags, cancel)

    estimates = {n: float(th) for n, th in zip(names, theta1, strict=True)}
    estimates["beta_e"] = float(theta2[0])
    se = {n: float(math.sqrt(max(cov1_h[i, i], 0.0))) for i, n in enumerate(names)}
    se["beta_e"] = float(math.sqrt(max(cov2_h[0, 0], 0.0)))
    se_t = {n: float(math.sqrt(max(cov1_t[i, i], 0.0))) for i, n in enumerate(names)}
    se_t["beta_e"] = float(math.sqrt(max(cov2_t[0, 0], 0.0)))
    ci = {n: (estimates[n] - Z95 * se[n], estimates[n] + Z95 * se[n]) for n in estimates}

    success = rank == Phi1.shape[1]
    message = "ok" if success else (
        f"the regressors are linearly dependent (rank {rank} of {Phi1.shape[1]}): the input does not excite "
        "every parameter; use a richer input")
    y1_fit = np.full(t.shape, np.nan)
    y1_fit[keep] = Phi1 @ theta1
    y2_fit = np.full(t.shape, np.nan)
    y2_fit[keep] = phi2f[keep] * theta2[0]
    nom = {"M": nominal.M, "B": nominal.B, "Af": nominal.Af, "d0": nominal.d0, "beta_e": nominal.beta_e}
    return LSEResult(
        estimates=estimates, std_errors=se, std_errors_textbook=se_t, ci95=ci,
        disturbance_model=disturbance_model, disturbance_freq_hz=freq, freq_estimated=freq_estimated,
        tau_f=float(tau_f), ts=ts, n_samples=int(keep.sum()), hac_lags=lags,
        residual_rms={"y1": float(np.sqrt(np.mean(e1**2))), "y2": float(np.sqrt(np.mean(e2**2)))},
        condition_number=cond, success=bool(success), message=message, nominal=nom,
        t=t, y1f=y1f, y1_fit=y1_fit, y2f=dp1f, y2_fit=y2_fit,
    )
