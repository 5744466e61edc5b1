"""Black-box identification's shared ground: data, horizons, fits and criteria.

Every black-box model of the project (ARX, ARMAX, OE and BJ in
:mod:`eha_core.identify.polynomial`, the subspace state-space model in
:mod:`eha_core.identify.subspace`, the process models in
:mod:`eha_core.identify.process`) is a discrete-time linear model

    y(t) = G(q) u(t) + H(q) e(t),

with ``G = gb(q^-1) / ga(q^-1)`` and ``H = hc(q^-1) / hd(q^-1)`` given by its
:meth:`LinearModel.g_poly` and :meth:`LinearModel.h_poly` (coefficients in
ascending powers of ``q^-1``, each denominator and ``hc`` monic). This module
simulates and predicts any of them the same way, so a fit reads the same
wherever it is shown:

- ``horizon=None``: simulation, ``y_hat = G u`` (MATLAB ``compare(..., Inf)``);
- ``horizon=k``: k-step-ahead prediction, ``y_hat(t | t-k)`` (``compare(..., k)``);
  ``k=1`` is the prediction-error method's own criterion.

and initial conditions are ``"zero"`` (filters at rest) or ``"estimate"``
(the free response of the simulation's filter fitted by linear least squares,
for each experiment). :class:`IdData` holds one or several experiments of the
same sample time (:func:`merge`); estimators and :func:`compare` treat each
experiment on its own (filters restart at each), as MATLAB's ``merge`` does.

Only numpy and scipy are imported here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.signal

from .._checks import not_allowed

__all__ = ["IdData", "merge", "LinearModel", "EstimateFields", "ContinuousEquivalent", "continuous_equivalent",
           "Comparison", "compare", "simulate", "predict", "fit_percent", "criteria", "Criteria", "horizon_words",
           "initial_words", "INITIAL_CONDITIONS"]

INITIAL_CONDITIONS = ("zero", "estimate")


# ---------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class IdData:
    """Sampled input-output data of one or several experiments (MATLAB ``iddata``).

    Parameters
    ----------
    y, u : array_like, shape (N,)
        Output and input; for several experiments, concatenated.
    ts : float
        Sample time in seconds, shared by every experiment.
    starts : tuple of int
        Index where each experiment begins (``(0,)`` for one experiment).
    name : str
        What the data are (shown in tables and reports).

    Examples
    --------
    >>> import numpy as np
    >>> d = IdData(np.arange(10.0), np.ones(10), 0.1)
    >>> est, val = d.split(0.6)
    >>> est.n_samples, val.n_samples
    (6, 4)
    >>> merge(est, val).n_experiments
    2
    """

    y: np.ndarray
    u: np.ndarray
    ts: float
    starts: tuple = (0,)
    name: str = "data"

    def __post_init__(self):
        y = np.asarray(self.y, dtype=float).ravel()
        u = np.asarray(self.u, dtype=float).ravel()
        if y.size != u.size:
            raise not_allowed("u", f"{u.size} samples", f"the input needs as many samples as the output ({y.size})")
        if y.size < 2:
            raise not_allowed("y", f"{y.size} samples", "a record needs at least 2 samples")
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
            raise not_allowed("y, u", "values that are not finite", "every sample must be a finite number")
        ts = float(self.ts)
        if not (math.isfinite(ts) and ts > 0):
            raise not_allowed("ts", self.ts, "the sample time must be a finite number of seconds > 0")
        starts = tuple(int(s) for s in self.starts)
        increasing = all(b > a for a, b in zip(starts, starts[1:], strict=False))
        if not starts or starts[0] != 0 or not increasing or starts[-1] >= y.size:
            raise not_allowed("starts", list(starts), f"increasing indices from 0, each below {y.size}")
        for name, arr in (("y", y), ("u", u)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "ts", ts)
        object.__setattr__(self, "starts", starts)

    @property
    def n_samples(self) -> int:
        return int(self.y.size)

    @property
    def n_experiments(self) -> int:
        return len(self.starts)

    def experiments(self) -> list[IdData]:
        """Each experiment as data of its own."""
        bounds = list(self.starts) + [self.n_samples]
        if len(bounds) == 2:
            return [self]
        return [IdData(self.y[a:b], self.u[a:b], self.ts, name=f"{self.name} ({i + 1})")
                for i, (a, b) in enumerate(zip(bounds, bounds[1:], strict=False))]

    def segments(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """``(y, u)`` of each experiment (views, no copy)."""
        bounds = list(self.starts) + [self.n_samples]
        return [(self.y[a:b], self.u[a:b]) for a, b in zip(bounds, bounds[1:], strict=False)]

    def split(self, fraction: float = 0.5) -> tuple[IdData, IdData]:
        """The first ``fraction`` of the samples for estimation, the rest for validation.

        Only one experiment can be split (merged data keep their experiments whole: give a
        second experiment for validation instead)."""
        f = float(fraction)
        if not (0.0 < f < 1.0) or not math.isfinite(f):
            raise not_allowed("estimation fraction", fraction, "must lie strictly between 0 and 1")
        if self.n_experiments > 1:
            raise not_allowed("estimation fraction", fraction,
                              "merged experiments are not split: validate on another experiment")
        k = int(round(f * self.n_samples))
        if k < 2 or self.n_samples - k < 2:
            raise not_allowed("estimation fraction", fraction,
                              f"leaves fewer than 2 samples on one side of {self.n_samples}")
        return (IdData(self.y[:k], self.u[:k], self.ts, name=f"{self.name}, estimation part"),
                IdData(self.y[k:], self.u[k:], self.ts, name=f"{self.name}, validation part"))

    def detrended(self) -> IdData:
        """Each experiment with its means removed (MATLAB ``detrend(data, 0)``)."""
        ys, us = [], []
        for y, u in self.segments():
            ys.append(y - y.mean())
            us.append(u - u.mean())
        return IdData(np.concatenate(ys), np.concatenate(us), self.ts, self.starts, self.name)


def merge(*datas: IdData, name: str | None = None) -> IdData:
    """Several experiments as one data set for estimation (MATLAB ``merge``).

    Every experiment must have the same sample time; the estimators restart
    their filters at each experiment, so no false transient joins them.

    Parameters
    ----------
    *datas : IdData
        The experiments (each may itself hold several).
    name : str, optional
        The merged data's name; default the experiments' names joined by " + ".
    """
    if not datas:
        raise not_allowed("experiments", "none", "merge needs at least one experiment")
    ts = datas[0].ts
    ys, us, starts, at = [], [], [], 0
    for i, d in enumerate(datas):
        if not math.isclose(d.ts, ts, rel_tol=1e-9):
            raise not_allowed(f"experiment {i + 1}'s sample time", f"{d.ts:g} s",
                              f"every merged experiment needs the first one's sample time, {ts:g} s")
        for y, u in d.segments():
            starts.append(at)
            ys.append(y)
            us.append(u)
            at += y.size
    return IdData(np.concatenate(ys), np.concatenate(us), ts, tuple(starts),
                  name or " + ".join(d.name for d in datas))


# ---------------------------------------------------------------------------
# models
# ---------------------------------------------------------------------------
class LinearModel:
    """What every black-box model gives: ``G`` and ``H`` as polynomials in ``q^-1``.

    Subclasses (frozen dataclasses) define ``ts`` and implement :meth:`g_poly` and
    :meth:`h_poly`; the rest follows from them."""

    ts: float

    #: A constant input offset ``c`` in input units (MATLAB's ``InputOffset``): the model is
    #: ``y = G (u + c)``, the offset applied from each experiment's start; None: no offset.
    input_offset = None

    def g_poly(self) -> tuple[np.ndarray, np.ndarray]:           # pragma: no cover - abstract
        """``(gb, ga)``: ``G(q) = gb(q^-1) / ga(q^-1)``, ``ga[0] == 1``."""
        raise NotImplementedError

    def h_poly(self) -> tuple[np.ndarray, np.ndarray]:
        """``(hc, hd)``: ``H(q) = hc(q^-1) / hd(q^-1)``, both monic (default ``H = 1``: output error)."""
        return np.array([1.0]), np.array([1.0])

    def polynomial_form(self) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, F)`` of the general form ``A y = B/F u + C/D e`` (Ljung 1999, eq. 4.33):
        by default ``A = 1``, ``B, F`` from :meth:`g_poly` and ``C, D`` from :meth:`h_poly`. A model
        whose ``G`` and ``H`` share ``A`` gives it here, so that its predictor needs no ``1/A``."""
        gb, ga = self.g_poly()
        hc, hd = self.h_poly()
        return np.array([1.0]), np.asarray(gb, float), np.asarray(hc, float), np.asarray(hd, float), \
            np.asarray(ga, float)

    def poles(self) -> np.ndarray:
        """Poles of ``G`` (roots in ``z``)."""
        _gb, ga = self.g_poly()
        return np.roots(np.trim_zeros(ga, "b")) if np.trim_zeros(ga, "b").size > 1 else np.array([])

    def zeros(self) -> np.ndarray:
        """Zeros of ``G`` (roots in ``z``; the input delay's zeros at the origin left out)."""
        gb, _ga = self.g_poly()
        gb = np.trim_zeros(np.trim_zeros(np.asarray(gb, float), "f"), "b")
        return np.roots(gb) if gb.size > 1 else np.array([])

    def to_control(self):
        """``G`` as a discrete-time :class:`control.TransferFunction` (``dt = ts``)."""
        import control

        gb, ga = self.g_poly()
        n = max(len(gb), len(ga))
        # powers of q^-1 -> powers of z: pad both to the same length
        return control.tf(np.pad(gb, (0, n - len(gb))), np.pad(ga, (0, n - len(ga))), self.ts)

    def noise_to_control(self):
        """``H`` as a discrete-time :class:`control.TransferFunction`."""
        import control

        hc, hd = self.h_poly()
        n = max(len(hc), len(hd))
        return control.tf(np.pad(hc, (0, n - len(hc))), np.pad(hd, (0, n - len(hd))), self.ts)


class EstimateFields:
    """What every black-box estimate carries and exports, on top of :class:`LinearModel`.

    A subclass (a frozen dataclass) has the fields ``structure`` (``"arx"``, ``"armax"``, ``"oe"``,
    ``"bj"``, ``"ss"``, ``"process"``), ``name`` (``"ARX(na=2, nb=2, nk=1)"``), ``orders`` (dict),
    ``ts``, ``params`` and ``param_names`` (the estimated parameters), ``covariance`` (of ``params``),
    ``noise_variance``, ``criteria`` (:class:`Criteria` of the one-step prediction errors on the
    estimation data), ``fit`` (:class:`Comparison` on the estimation data, its horizon and initial
    conditions stated), ``initial`` (how the estimation handled initial conditions), ``n_samples``,
    ``success``, ``message`` and ``nfev``. Like :class:`scipy.optimize.OptimizeResult`, a failed
    estimate is data: ``success`` False and ``message`` saying why."""

    @property
    def param_std(self) -> np.ndarray:
        cov = np.asarray(self.covariance, float)
        return np.sqrt(np.clip(np.diag(cov), 0.0, None)) if cov.size else np.zeros(0)

    def intervals(self, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """Two-sided normal intervals of ``params`` at ``level``."""
        from scipy.stats import norm

        z = float(norm.ppf(0.5 + level / 2))
        p = np.asarray(self.params, float)
        return p - z * self.param_std, p + z * self.param_std

    def to_dict(self) -> dict:
        """Everything a user needs to rebuild and judge the model, as JSON types."""
        gb, ga = self.g_poly()
        hc, hd = self.h_poly()
        crit = self.criteria
        return {
            "structure": self.structure, "name": self.name, "orders": dict(self.orders), "ts": self.ts,
            "param_names": list(self.param_names), "params": [float(v) for v in self.params],
            "param_std": [float(v) for v in self.param_std],
            "covariance": np.asarray(self.covariance, float).tolist(),
            "noise_variance": float(self.noise_variance),
            "G": {"num": np.asarray(gb, float).tolist(), "den": np.asarray(ga, float).tolist(), "variable": "q^-1"},
            "H": {"num": np.asarray(hc, float).tolist(), "den": np.asarray(hd, float).tolist(), "variable": "q^-1"},
            "criteria": {"loss": crit.loss, "aic": crit.aic, "bic": crit.bic, "fpe": crit.fpe},
            "fit": {"percent": self.fit.fit_percent, "label": self.fit.label},
            "input_offset": None if self.input_offset is None else float(self.input_offset),
            "initial": self.initial, "n_samples": int(self.n_samples),
            "success": bool(self.success), "message": self.message,
        }

    def to_json(self, **kwargs) -> str:
        """:meth:`to_dict` as JSON text; ``**kwargs`` go to :func:`json.dumps` (``indent=2``...)."""
        import json

        return json.dumps(self.to_dict(), **kwargs)

    def __repr__(self) -> str:
        state = "" if self.success else ", FAILED"
        return f"<{self.name}: {self.fit.label}{state}>"


@dataclass(frozen=True)
class ContinuousEquivalent:
    """A black-box model of a sampled system as a continuous-time ``G(s) = num / den`` (descending
    powers of s) with an input delay, and how it was obtained (``how``: empty for the exact
    zero-order-hold equivalent, else what was done instead)."""

    num: np.ndarray
    den: np.ndarray
    input_delay: float
    how: str = ""


def continuous_equivalent(model: LinearModel) -> ContinuousEquivalent:
    """``G`` of ``model`` as a continuous-time system (python-control's ``d2c`` with ``"zoh"``).

    A model with its own continuous-time form (a process model's ``continuous()``) gives it with its delay;
    a discrete model ``G(q)`` is taken to the continuous-time system whose zero-order-hold discretisation
    it is (the matrix logarithm of its sampled state-space form, with ``nk - 1`` whole samples as the
    input delay); where there is none (a pole on the negative real axis of z), the bilinear (Tustin)
    equivalent, ``how`` saying so. :class:`ValueError` for a model with no continuous-time equivalent at
    all (a pole at z = -1, a G that is zero or not finite).

    Parameters
    ----------
    model : LinearModel
        Any black-box model.

    Examples
    --------
    >>> import numpy as np
    >>> from eha_core.identify.process import zoh_poly
    >>> class Lag(LinearModel):
    ...     ts = 0.1
    ...     def g_poly(self):
    ...         return np.array([0.0, 1 - np.exp(-0.2)]), np.array([1.0, -np.exp(-0.2)])
    >>> c = continuous_equivalent(Lag())                  # the ZOH form of 1 / (0.5 s + 1)
    >>> np.round(c.num / c.den[-1], 6), np.round(c.den / c.den[-1], 6), c.input_delay, c.how
    (array([1.]), array([0.5, 1. ]), 0.0, '')
    """
    import warnings

    import scipy.signal

    ts = float(model.ts)
    if hasattr(model, "continuous"):
        g, td = model.continuous()
        num, den = np.asarray(g.num[0][0], float), np.asarray(g.den[0][0], float)
        return ContinuousEquivalent(num / den[0], den / den[0], float(td))
    gb, ga = (np.asarray(p, float) for p in model.g_poly())
    gb, ga = np.trim_zeros(gb, "b"), np.trim_zeros(ga, "b")
    if not gb.size or not np.all(np.isfinite(gb)) or not np.all(np.isfinite(ga)):
        raise ValueError("the model's G(q) is zero or not finite")
    lead = int(np.argmax(gb != 0))
    delay = max(lead - 1, 0)            # whole samples beyond the hold's own one
    gb = gb[delay:]
    n = max(gb.size, ga.size)
    num_z, den_z = np.pad(gb, (0, n - gb.size)), np.pad(ga, (0, n - ga.size)) / ga[0]
    num_z = num_z / ga[0]
    if n == 1:
        return ContinuousEquivalent(num_z, np.ones(1), delay * ts)
    with warnings.catch_warnings():
        # a numerator that begins with zeros (the hold's delay) is what is meant, not a badly conditioned one
        warnings.simplefilter("ignore", scipy.signal.BadCoefficients)
        num_s, den_s, how = _zoh_inverse(num_z, den_z, ts)
    num_s = np.asarray(num_s, float)
    num_s[np.abs(num_s) < 1e-12 * max(1.0, float(np.max(np.abs(num_s))))] = 0.0
    num_s = np.trim_zeros(num_s, "f") if np.any(num_s) else np.zeros(1)
    den_s = np.asarray(den_s, float)
    return ContinuousEquivalent(num_s / den_s[0], den_s / den_s[0], delay * ts, how)


def _zoh_inverse(num_z: np.ndarray, den_z: np.ndarray, ts: float) -> tuple[np.ndarray, np.ndarray, str]:
    """``(num_s, den_s, note)``: the continuous-time system whose zero-order-hold discretisation is
    ``num_z / den_z`` (descending powers of z, one length); where there is none (a pole on the negative
    real axis of z, or at 0), the bilinear (Tustin) equivalent, ``note`` saying so."""
    import scipy.linalg
    import scipy.signal

    a, b, c, d = scipy.signal.tf2ss(num_z, den_z)
    order = a.shape[0]
    if not any(abs(p) < 1e-9 or (abs(p.imag) <= 1e-9 * max(1.0, abs(p)) and p.real < 0)
               for p in np.linalg.eigvals(a)):
        m = np.zeros((order + 1, order + 1))
        m[:order, :order], m[:order, order:], m[order, order] = a, b, 1.0
        log = scipy.linalg.logm(m) / ts
        if np.all(np.isfinite(log)) and np.max(np.abs(np.imag(log))) <= 1e-6 * max(
                1.0, float(np.max(np.abs(np.real(log))))):
            log = np.real(log)
            num_s, den_s = scipy.signal.ss2tf(log[:order, :order], log[:order, order:], c, d)
            return np.asarray(num_s[0], float), np.asarray(den_s, float), ""
    # z = (1 + s ts/2) / (1 - s ts/2): z^k -> (1 + s ts/2)^k (1 - s ts/2)^(n - k), times (1 - s ts/2)^n
    if np.any(np.abs(np.polyval(den_z, -1.0)) < 1e-12):
        raise ValueError("G has a pole at z = -1 (the Nyquist frequency): it has no continuous-time equivalent; "
                         "try lower orders")
    n = num_z.size - 1
    plus, minus = np.array([ts / 2, 1.0]), np.array([-ts / 2, 1.0])

    def mapped(poly):
        out = np.zeros(n + 1)
        for i, coef in enumerate(poly):          # coef of z^(n - i)
            k = n - i
            term = np.array([coef])
            for _ in range(k):
                term = np.polymul(term, plus)
            for _ in range(n - k):
                term = np.polymul(term, minus)
            out = np.polyadd(out, term)[-(n + 1):]
        return out

    return (mapped(num_z), mapped(den_z),
            "the bilinear (Tustin) mapping: a pole on z's negative real axis has no zero-order-hold "
            "equivalent")


def _filter_free_basis(num: np.ndarray, den: np.ndarray, n: int) -> np.ndarray:
    """Free responses of the filter ``num / den`` (in ``q^-1``) over n samples, one column per state of
    its realisation (``max(len(num), len(den)) - 1`` states: an FIR filter's state is the past inputs
    it has not seen)."""
    order = max(len(num), len(den)) - 1
    if order == 0:
        return np.zeros((n, 0))
    cols = np.empty((n, order))
    z = np.zeros(n)
    for i in range(order):
        zi = np.zeros(order)
        zi[i] = 1.0
        cols[:, i], _ = scipy.signal.lfilter(num, den, z, zi=zi)
    return cols


def _check_initial(initial: str) -> str:
    if initial not in INITIAL_CONDITIONS:
        raise not_allowed("initial conditions", initial, "zero or estimate")
    return initial


def _check_horizon(horizon):
    if horizon is None:
        return None
    if isinstance(horizon, float) and math.isinf(horizon):
        return None
    try:
        k = int(horizon)
    except (TypeError, ValueError):
        raise not_allowed("horizon", horizon, "a whole number of steps >= 1, or inf for simulation") from None
    if k != horizon or k < 1:
        raise not_allowed("horizon", horizon, "a whole number of steps >= 1, or inf for simulation")
    return k


def _polymul(a, b):
    return np.convolve(np.asarray(a, float), np.asarray(b, float))


def _segment_output(model: LinearModel, y: np.ndarray, u: np.ndarray, horizon, initial: str) -> np.ndarray:
    gb, ga = model.g_poly()
    offset = getattr(model, "input_offset", None)
    if offset is not None:
        u = u + float(offset)          # y = G (u + c): the offset's step response rides along with u's
    if horizon is None:
        yhat = scipy.signal.lfilter(gb, ga, u)
        if initial == "estimate":
            basis = _filter_free_basis(np.asarray(gb, float), np.asarray(ga, float), y.size)
            if basis.shape[1]:
                coef, *_ = np.linalg.lstsq(basis, y - yhat, rcond=None)
                yhat = yhat + basis @ coef
        return yhat
    pa, pb, pc, pd, pf = model.polynomial_form()
    # k-step predictor (Ljung 1999, eq. 3.31): y_hat = Wk H^-1 G u + (1 - Wk H^-1) y, with H = C/(A D),
    # G = B/(A F) and Wk the first k terms of H's impulse response; A cancels from H^-1 G = D B/(C F),
    # and 1 - Wk H^-1 = (C - Wk A D)/C, so the predictor never divides by A (nor runs 1/A unstable)
    impulse = np.zeros(horizon)
    impulse[0] = 1.0
    wk = scipy.signal.lfilter(pc, _polymul(pa, pd), impulse)
    num_u = _polymul(_polymul(wk, pd), pb)
    den_u = _polymul(pc, pf)
    wad = _polymul(wk, _polymul(pa, pd))
    n = max(len(pc), len(wad))
    one_minus = np.pad(pc, (0, n - len(pc))) - np.pad(wad, (0, n - len(wad)))
    yhat = scipy.signal.lfilter(num_u, den_u, u) + scipy.signal.lfilter(one_minus, pc, y)
    if initial == "estimate":
        # the predictor's transients: free responses of its two filters, fitted by least squares
        basis = np.hstack([_filter_free_basis(num_u, den_u, y.size), _filter_free_basis(one_minus, pc, y.size)])
        if basis.shape[1]:
            coef, *_ = np.linalg.lstsq(basis, y - yhat, rcond=None)
            yhat = yhat + basis @ coef
    return yhat


def simulate(model: LinearModel, data: IdData, initial: str = "zero") -> np.ndarray:
    """The model's simulated output ``G u`` on ``data``.

    Parameters
    ----------
    model : LinearModel
        Any black-box model.
    data : IdData
        Its input ``u`` drives the model; with ``initial="estimate"`` its output ``y`` fits the free
        response of each experiment.
    initial : {"zero", "estimate"}
        Each experiment from rest, or its free response fitted by linear least squares.
    """
    return predict(model, data, None, initial)


def predict(model: LinearModel, data: IdData, horizon=1, initial: str = "zero") -> np.ndarray:
    """The model's k-step-ahead prediction on ``data``.

    Parameters
    ----------
    model : LinearModel
        Any black-box model.
    data : IdData
        The input and the measured output the predictor reads (up to ``t - k``).
    horizon : int or None
        k >= 1 steps ahead; None (or ``math.inf``) for simulation.
    initial : {"zero", "estimate"}
        The predictor's filters from rest, or their free responses fitted by linear least squares.
    """
    k, initial = _check_horizon(horizon), _check_initial(initial)
    return np.concatenate([_segment_output(model, y, u, k, initial) for y, u in data.segments()])


# ---------------------------------------------------------------------------
# fit and criteria
# ---------------------------------------------------------------------------
def fit_percent(y, yhat) -> float:
    """MATLAB's fit, ``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` (NRMSE), of ``yhat`` to ``y``
    (NaN for a constant ``y``)."""
    y, yhat = np.asarray(y, float), np.asarray(yhat, float)
    den = np.linalg.norm(y - y.mean())
    return float("nan") if den == 0 else float(100.0 * (1.0 - np.linalg.norm(y - yhat) / den))


def horizon_words(horizon) -> str:
    """How a fit's ``horizon`` (None or inf: simulation; k: k-step prediction) reads everywhere it is shown."""
    k = _check_horizon(horizon)
    return "simulation" if k is None else f"{k}-step prediction"


def initial_words(initial: str) -> str:
    """How a fit's ``initial`` conditions (zero, estimate) read everywhere they are shown."""
    return {"zero": "zero initial conditions", "estimate": "initial conditions estimated"}[_check_initial(initial)]


@dataclass(frozen=True, eq=False)
class Comparison:
    """A model's output on data and its fit (MATLAB ``compare``), with how it was computed.

    Attributes
    ----------
    y, yhat : numpy.ndarray
        The data's output and the model's (all experiments, concatenated).
    fit_percent : float
        NRMSE fit over all samples.
    horizon : int or None
        None: simulation; k: k-step prediction.
    initial : str
        ``"zero"`` or ``"estimate"``.
    data_name : str
    """

    y: np.ndarray
    yhat: np.ndarray
    fit_percent: float
    horizon: int | None
    initial: str
    data_name: str = ""
    t: np.ndarray = field(default=None, repr=False)
    input_offset: float | None = None

    @property
    def label(self) -> str:
        """``"fit 93.2 % (simulation, zero initial conditions)"``: the same words everywhere (``", input
        offset estimated"`` added when the model carries one)."""
        offset = "" if self.input_offset is None else ", input offset estimated"
        return (f"fit {self.fit_percent:.1f} % ({horizon_words(self.horizon)}, {initial_words(self.initial)}"
                f"{offset})")

    def __repr__(self) -> str:
        return f"Comparison({self.label} on {self.data_name or 'data'})"


def compare(model: LinearModel, data: IdData, horizon=None, initial: str = "zero") -> Comparison:
    """The model on ``data``: its simulated or k-step predicted output and the fit (MATLAB ``compare``).

    Parameters
    ----------
    model : LinearModel
        Any black-box model.
    data : IdData
        Estimation or validation data.
    horizon : int or None
        None (or ``math.inf``): simulation; k: k-step prediction.
    initial : {"zero", "estimate"}
        How initial conditions are handled; stated in the result's :attr:`Comparison.label`.
    """
    yhat = predict(model, data, horizon, initial)
    return Comparison(data.y, yhat, fit_percent(data.y, yhat), _check_horizon(horizon), initial, data.name,
                      np.arange(data.n_samples) * data.ts,
                      None if getattr(model, "input_offset", None) is None else float(model.input_offset))


@dataclass(frozen=True)
class Criteria:
    """Loss and information criteria of an estimate (MATLAB ``Report.Fit``).

    ``loss`` is ``V = mean(e^2)`` of the one-step prediction errors; ``aic`` and ``bic`` are MATLAB's raw
    ``N log V + 2 d + N (log 2 pi + 1)`` and ``N log V + d log N + N (log 2 pi + 1)``; ``fpe`` is Akaike's
    ``V (1 + d/N) / (1 - d/N)``."""

    loss: float
    aic: float
    bic: float
    fpe: float
    n_params: int
    n_samples: int


def criteria(residuals, n_params: int) -> Criteria:
    """The criteria of one-step prediction errors ``residuals`` for a model of ``n_params`` parameters."""
    e = np.asarray(residuals, float)
    n, d = e.size, int(n_params)
    v = float(np.mean(e ** 2))
    log_v = math.log(v) if v > 0 else -math.inf
    const = n * (math.log(2 * math.pi) + 1.0)
    fpe = v * (1 + d / n) / (1 - d / n) if d < n else math.inf
    return Criteria(v, n * log_v + 2 * d + const, n * log_v + d * math.log(n) + const, fpe, d, n)
