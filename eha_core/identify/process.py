"""Low-order continuous-time process models with a delay (MATLAB ``procest``).

:func:`procest` fits one of MATLAB's process models, named by its type code,

==========  =====================================================  ====================
kind        G(s)                                                   parameters
==========  =====================================================  ====================
``P1D``     ``K e^(-Td s) / (1 + Tp1 s)``                          K, Tp1, Td
``P2D``     ``K e^(-Td s) / ((1 + Tp1 s)(1 + Tp2 s))``             K, Tp1, Tp2, Td
``P2DU``    ``K e^(-Td s) / (1 + 2 Zeta Tw s + (Tw s)^2)``         K, Tw, Zeta, Td
``P1DI``    ``K e^(-Td s) / (s (1 + Tp1 s))``                      K, Tp1, Td
``P2DI``    ``K e^(-Td s) / (s (1 + Tp1 s)(1 + Tp2 s))``           K, Tp1, Tp2, Td
==========  =====================================================  ====================

(without ``D`` in the code, ``Td = 0``), to sampled data whose input was held
between samples (zero-order hold). The position of a hydraulic actuator is the
integral of the flow the valve lets through: from valve voltage to position it
is an integrating process, ``P1DI`` or ``P2DI``.

The model's discrete form at the data's sample time is the exact ZOH
discretisation with the delay ``Td = (d + f) ts`` (:func:`zoh_poly`): ``d``
whole samples as leading zeros of the numerator, the fraction ``f`` through the
two input vectors of the modified z-transform (Franklin, Powell & Workman,
*Digital Control of Dynamic Systems*, 3rd ed., sec. 4.3.4), computed from a
cascade state-space form that needs no balancing (the tests compare it with
:func:`eha_core.identify._ctmodels.discretise`).

The parameters minimise the simulation error ``y - G u`` (an output-error
model, ``H = 1``) by Gauss-Newton with bounds (scipy's trust-region-reflective
``least_squares``: time constants > 0, ``0 <= Td`` below the record's length).
``K`` (and the initial states with ``initial="estimate"``) enter the output
linearly and are solved for at every step (variable projection), so the search
sees only the time constants and the delay; two real poles are searched as
``Tw = sqrt(Tp1 Tp2)``, ``Zeta = (Tp1 + Tp2) / (2 Tw) >= 1``, smooth where
``Tp1 = Tp2`` folds the ``(Tp1, Tp2)`` plane. As MATLAB's ``procest`` it starts
from several delays: the best whole-sample delays of a scan of ARX fits and
half a sample either side, with the ARX fit's time constants and a few fixed
ones, screened by their error; the search runs from the best two, and once more
when it ends where the delay stands in for a time constant. The covariance is
``sigma^2 (J^T J)^-1`` with ``J`` the Jacobian of the simulated output with
respect to the reported parameters, by central differences (one-sided at
``Td = 0``), ``sigma^2`` the residuals' sum of squares over ``N - p``.

Input offset
------------
With ``input_offset="estimate"`` (MATLAB's ``InputOffset``) the model is
``y = G(s) (u + c)``, ``c`` a constant in input units applied from each
experiment's start, as :mod:`eha_core.identify.validate` defines it for
``tfest``. A single-rod cylinder needs it: the valve's flow, and so the rod's
velocity, is larger one way than the other (eqs. 1-4), and under a zero-mean
binary input ``±a`` that asymmetry is exactly an offset, ``v = K (u + c)``;
without it an integrating model sees the drift as a gain error and its fit
falls below zero. ``c`` enters the output as ``K c`` times the step response,
linear given the poles, so it is projected out with ``K`` and the initial
states and the search still sees only the time constants and the delay. One
``c`` is shared by every experiment of merged data: it belongs to the process
(its asymmetry at this input amplitude), not to a record, and only a shared
value carries over to validation data. The estimate keeps it as
``input_offset`` (the last parameter, ``"input_offset"``, with its standard
error) and :func:`eha_core.identify.blackbox.compare` applies it.

Only numpy and scipy are imported here (python-control lazily).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal

from .._checks import not_allowed
from ._ctmodels import expm_pade13, fit_linear_terms, split_delay, state_numerators
from .blackbox import INITIAL_CONDITIONS, Comparison, Criteria, EstimateFields, IdData, LinearModel, compare, criteria

__all__ = ["ProcessModel", "procest", "process_tf", "zoh_poly", "KINDS", "INPUT_OFFSETS"]

#: The type codes :func:`procest` accepts (``D``: a delay, ``I``: an integrator, ``U``: underdamped).
KINDS = ("P1", "P1D", "P1I", "P1DI", "P2", "P2D", "P2I", "P2DI", "P2U", "P2DU", "P2IU", "P2DIU")

#: How :func:`procest` treats a constant input offset: none, or estimated (one for all experiments).
INPUT_OFFSETS = ("zero", "estimate")

_KIND_PATTERN = re.compile(r"^P([12])([DIU]*)$")

#: Lower bound of a time constant, in sample times: below it the pole is beyond what the data show.
_TP_MIN_SAMPLES = 1e-3

#: Upper bound of the search's Zeta for two real poles (Tp2 / Tp1 = 1 / (4 Zeta^2) = 2.5e-7 there).
_ZETA_MAX = 1e3


@dataclass(frozen=True)
class _Kind:
    code: str
    poles: int           # poles besides the integrator
    delay: bool
    integrator: bool
    underdamped: bool

    @property
    def shape_names(self) -> tuple:
        if self.underdamped:
            return ("Tw", "Zeta")
        return ("Tp1",) if self.poles == 1 else ("Tp1", "Tp2")


def _parse_kind(kind) -> _Kind:
    text = kind.strip().upper() if isinstance(kind, str) else None
    match = _KIND_PATTERN.match(text) if text else None
    letters = match.group(2) if match else ""
    if (match is None or len(set(letters)) != len(letters)
            or ("U" in letters and match.group(1) != "2")):
        raise not_allowed("kind", kind, "a process type code: P1, P2 with D (delay), I (integrator), "
                                        "U (underdamped, P2 only), e.g. P1D, P2D, P1DI, P2DI, P2DU")
    code = "P" + match.group(1) + "".join(c for c in "DIU" if c in letters)   # MATLAB's order
    return _Kind(code, int(match.group(1)), "D" in letters, "I" in letters, "U" in letters)


def process_tf(kind, values: dict) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of the process model without its delay, descending powers of ``s``.

    Parameters
    ----------
    kind : str
        The type code (``"P1D"``, ``"P2DI"``...).
    values : dict
        ``K`` and the kind's time constants (``Tp1``, ``Tp2`` or ``Tw``, ``Zeta``).

    Examples
    --------
    >>> process_tf("P1DI", {"K": 2.0, "Tp1": 0.5})
    (array([2.]), array([0.5, 1. , 0. ]))
    """
    k = _parse_kind(kind)
    if k.underdamped:
        den = np.array([values["Tw"] ** 2, 2.0 * values["Zeta"] * values["Tw"], 1.0])
    else:
        den = np.array([values["Tp1"], 1.0])
        if k.poles == 2:
            den = np.convolve(den, [values["Tp2"], 1.0])
    if k.integrator:
        den = np.append(den, 0.0)
    return np.array([float(values["K"])]), den


@dataclass(frozen=True, eq=False, repr=False)
class ProcessModel(EstimateFields, LinearModel):
    """A continuous-time process model estimated by :func:`procest`, and its exact ZOH discrete form.

    Like :class:`scipy.optimize.OptimizeResult`, a failed estimate is data: ``success`` is False and
    ``message`` says why and what to try.

    Attributes
    ----------
    kind : str
        MATLAB's type code (``"P1D"``, ``"P2DI"``...).
    values : dict
        The continuous-time values: ``K``, the time constants (``Tp1``, ``Tp2`` or ``Tw``, ``Zeta``) in
        seconds and ``Td`` in seconds (fixed ones included).
    discrete_num, discrete_den : numpy.ndarray
        ``G`` at ``ts`` (exact ZOH, the delay included), ascending powers of ``q^-1``.
    structure, name, orders, ts, params, param_names, covariance, noise_variance, criteria, fit, initial,
    n_samples, success, message, nfev
        As every estimate (:class:`~eha_core.identify.blackbox.EstimateFields`); ``params`` are the estimated
        values in the order of ``param_names``; ``fit`` is the simulation (``H = 1``: it is also the one-step
        prediction).
    input_offset : float or None
        The estimated constant input offset ``c`` (input units; the model is ``y = G (u + c)``), also the
        last of ``params``; None when not estimated. :func:`~eha_core.identify.blackbox.compare` applies it.
    """

    structure: str
    name: str
    orders: dict
    ts: float
    kind: str
    values: dict
    discrete_num: np.ndarray
    discrete_den: np.ndarray
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
    input_offset: float | None = None

    def g_poly(self) -> tuple[np.ndarray, np.ndarray]:
        """``(gb, ga)``: the exact ZOH discretisation at ``ts`` with the delay, ascending powers of ``q^-1``."""
        return self.discrete_num.copy(), self.discrete_den.copy()

    def continuous(self):
        """``(G, Td)``: the model without its delay as a :class:`control.TransferFunction`, and the delay in s."""
        import control

        num, den = process_tf(self.kind, self.values)
        return control.tf(num, den), float(self.values["Td"])


# ---------------------------------------------------------------------------
# the model on the data
# ---------------------------------------------------------------------------
def _discrete(kind: _Kind, values: dict, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """``(gb, ga)`` of the exact ZOH discretisation, ascending powers of ``q^-1``, the delay included.

    The model as a cascade of first-order lags (or the scaled second-order section ``Tw x1' = x2``,
    ``Tw x2' = u - x1 - 2 Zeta x2``) and the integrator, well scaled whatever the time constants, so
    that the augmented exponential (Van Loan 1978) needs no balancing: five times faster than the
    general :func:`eha_core.identify._ctmodels.discretise`, which the tests compare it with. With
    ``Td = (d + f) ts`` the input switches ``f ts`` into each interval: ``Gamma0 = Gamma((1 - f) ts)``
    acts on ``u[k-d]`` and ``Gamma1 = e^(A (1-f) ts) Gamma(f ts)`` on ``u[k-d-1]``."""
    if kind.underdamped:
        tw, zeta = values["Tw"], values["Zeta"]
        a_rows = [[0.0, 1.0 / tw], [-1.0 / tw, -2.0 * zeta / tw]]
        b_col = [0.0, 1.0 / tw]
        s_poles = np.roots([tw * tw, 2.0 * zeta * tw, 1.0])
    else:
        taus = [values["Tp1"]] + ([values["Tp2"]] if kind.poles == 2 else [])
        n_lag = len(taus)
        a_rows = np.zeros((n_lag, n_lag))
        for i, tau in enumerate(taus):
            a_rows[i, i] = -1.0 / tau
            if i:
                a_rows[i, i - 1] = 1.0 / tau
        b_col = np.zeros(n_lag)
        b_col[0] = 1.0 / taus[0]
        s_poles = np.array([-1.0 / tau for tau in taus])
    a_mat, b_vec = np.asarray(a_rows, float), np.asarray(b_col, float)
    n = a_mat.shape[0] + int(kind.integrator)
    m = np.zeros((n + 1, n + 1))
    m[:a_mat.shape[0], :a_mat.shape[0]] = a_mat
    m[:a_mat.shape[0], n] = b_vec
    out = 0 if kind.underdamped else a_mat.shape[0] - 1     # the state that is the output of the lags
    if kind.integrator:
        m[n - 1, out] = 1.0               # the integrator integrates it
        s_poles = np.append(s_poles, 0.0)
        out = n - 1
    c_vec = np.zeros(n)
    c_vec[out] = float(values["K"])
    d_samples, frac = split_delay(float(values.get("Td", 0.0)), ts)
    den_z = np.real(np.poly(np.exp(s_poles * ts)))
    if frac == 0.0:
        e = expm_pade13(m * ts)
        num_z = state_numerators(e[:n, :n], e[:n, n], den_z, c_vec[None, :], np.zeros(1))[0]
    else:
        late = expm_pade13(m * ((1.0 - frac) * ts))     # the new input's part of the interval
        early = expm_pade13(m * (frac * ts))            # the old input's part
        ad = late[:n, :n] @ early[:n, :n]
        gamma0, gamma1 = late[:n, n], late[:n, :n] @ early[:n, n]
        num0 = state_numerators(ad, gamma0, den_z, c_vec[None, :], np.zeros(1))[0]
        num1 = state_numerators(ad, gamma1, den_z, c_vec[None, :], np.zeros(1))[0]
        num_z = np.zeros(n + 2)
        num_z[:n + 1] += num0
        num_z[1:] += num1                               # u[k-d-1]: one sample later
    return np.concatenate([np.zeros(d_samples), num_z]), den_z


def zoh_poly(kind, values: dict, ts: float) -> tuple[np.ndarray, np.ndarray]:
    """``(gb, ga)``: the exact ZOH discretisation of a process model at ``ts``, ascending powers of ``q^-1``.

    ``Td = (d + f) ts``: ``d`` leading zeros of ``gb``; a fraction ``f > 0`` adds one coefficient (the input
    switching inside the sample interval, the modified z-transform).

    Parameters
    ----------
    kind : str
        The type code (``"P1D"``, ``"P2DI"``...).
    values : dict
        ``K``, the kind's time constants in seconds and ``Td`` in seconds (default 0).
    ts : float
        The sample time in seconds.

    Examples
    --------
    >>> gb, ga = zoh_poly("P1D", {"K": 1.0, "Tp1": 1.0, "Td": 0.2}, 0.1)
    >>> np.round(gb, 6), np.round(ga, 6)
    (array([0.      , 0.      , 0.      , 0.095163]), array([ 1.      , -0.904837]))
    """
    k = _parse_kind(kind)
    if not (isinstance(ts, (int, float, np.floating)) and math.isfinite(ts) and ts > 0):
        raise not_allowed("ts", ts, "the sample time must be a finite number of seconds > 0")
    needed = ("K",) + k.shape_names
    missing = [n for n in needed if n not in values]
    if missing:
        raise not_allowed("values", sorted(values), f"a {k.code} model needs {', '.join(needed)}")
    if not (math.isfinite(float(values.get("Td", 0.0))) and float(values.get("Td", 0.0)) >= 0.0):
        raise not_allowed("Td", values.get("Td"), "the delay must be a finite number of seconds >= 0")
    return _discrete(k, values, float(ts))


@dataclass(frozen=True, eq=False)
class _Responses:
    """The model's responses on every experiment (concatenated) that the output is linear in."""

    forced: np.ndarray               # to u, unit gain
    step: np.ndarray | None          # to a unit input offset from each experiment's start, unit gain
    states: np.ndarray | None        # free responses, one column per state of each experiment


def _responses(gb, ga, segments, initial: str, offset: bool = False) -> _Responses:
    """Each experiment's forced response to ``u``, (``offset``) its step response and (``initial="estimate"``)
    its free responses, each experiment from rest.

    The free response of ``G = gb / ga`` from the i-th state of :func:`scipy.signal.lfilter`'s realisation
    (transposed direct form II; with the input at zero its states never see ``gb``) is ``1 / ga``'s impulse
    response delayed by i samples, so one filtering gives every free column."""
    sizes = [u.size for _y, u in segments]
    total, longest = sum(sizes), max(sizes)
    # every experiment's step and impulse responses are the start of the longest one's
    step_1 = scipy.signal.lfilter(gb, ga, np.ones(longest)) if offset else None
    order = len(ga) - 1
    states = np.zeros((total, len(segments) * order)) if initial == "estimate" else None
    impulse = scipy.signal.lfilter([1.0], ga, np.eye(1, longest)[0]) if states is not None else None
    forced = np.empty(total)
    step = np.empty(total) if offset else None
    at = 0
    for s, (_y, u) in enumerate(segments):
        n = u.size
        forced[at:at + n] = scipy.signal.lfilter(gb, ga, u)
        if offset:
            step[at:at + n] = step_1[:n]
        if states is not None:
            for i in range(min(order, n)):
                states[at + i:at + n, s * order + i] = impulse[:n - i]
        at += n
    return _Responses(forced, step, states)


#: Above this condition number of the normalised normal equations, :func:`_least_squares` solves by SVD.
_GRAM_COND_MAX = 1e8


def _least_squares(cols: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Least-squares coefficients of the few ``cols`` for ``target``.

    The normal equations of the normalised columns (an integrator's step response, a ramp, dwarfs the free
    responses) cost one pass over the N rows, a third to a seventh of an SVD's time at N = 10,000 and two
    to six columns (the search solves them at every step); they square the columns' condition number, so
    above :data:`_GRAM_COND_MAX` (relative error ``1e-16 * cond`` of the coefficients, 1e-8 there) the SVD
    solves instead (:func:`~eha_core.identify._ctmodels.fit_linear_terms`, NaN for non-finite columns)."""
    gram = cols.T @ cols
    scale = np.sqrt(np.diag(gram))
    if np.all(np.isfinite(gram)) and np.all(scale > 0):
        normal = gram / np.outer(scale, scale)
        eig = np.linalg.eigvalsh(normal)
        if eig[0] > eig[-1] / _GRAM_COND_MAX:
            return np.linalg.solve(normal, (cols.T @ target) / scale) / scale
    return fit_linear_terms(cols, target)


def _fitted(target: np.ndarray, resp: _Responses, gain=None, offset=0.0):
    """The output fitted linearly: ``K`` and ``c`` (unless ``gain`` and ``offset`` are given) and each
    experiment's initial state.

    Returns ``(y_hat, K, c)`` (``c`` 0 without an offset). The gain, the product ``K c`` (its column the
    step responses of every experiment: one offset for all) and the initial states enter the output
    linearly, so they are solved for exactly at every step of the search (variable projection, Golub &
    Pereyra 1973): the search sees only the time constants and the delay."""
    y1, step, states = resp.forced, resp.step, resp.states
    if gain is not None:
        known = gain * (y1 + offset * step) if step is not None else gain * y1
        if states is None or states.shape[1] == 0:
            return known, gain, offset
        return known + states @ _least_squares(states, target - known), gain, offset
    if step is None and states is None:
        den = float(y1 @ y1)
        gain = float(y1 @ target) / den if den > 0 else 0.0
        return gain * y1, gain, 0.0
    blocks = [y1[:, None]] + ([step[:, None]] if step is not None else []) + ([states] if states is not None else [])
    cols = np.hstack(blocks)
    coef = _least_squares(cols, target)
    gain = float(coef[0])
    if step is None:
        return cols @ coef, gain, 0.0
    return cols @ coef, gain, (float(coef[1]) / gain if gain != 0.0 else 0.0)


def _shape_values(kind: _Kind, inner) -> dict:
    """The reported time constants from the search's: ``Tp1`` for one pole; ``(Tw, Zeta)`` for two.

    Two real poles are searched as ``Tw = sqrt(Tp1 Tp2)``, ``Zeta = (Tp1 + Tp2) / (2 Tw) >= 1``: the model is
    smooth there where ``Tp1 = Tp2`` is a fold of ``(Tp1, Tp2)`` (two equal columns of the Jacobian, a
    saddle a search sticks to)."""
    if kind.poles == 1:
        return {"Tp1": float(inner[0])}
    tw, zeta = float(inner[0]), float(inner[1])
    if kind.underdamped:
        return {"Tw": tw, "Zeta": zeta}
    root = math.sqrt(max(zeta * zeta - 1.0, 0.0))
    return {"Tp1": tw * (zeta + root), "Tp2": tw / (zeta + root)}   # Tp1 >= Tp2, no cancellation


class _Problem:
    """The estimation problem: the values searched, their bounds, the simulated output."""

    def __init__(self, kind: _Kind, data: IdData, initial: str, fixed_td: float | None, td_max: float,
                 offset: bool = False):
        self.kind, self.data, self.initial, self.offset = kind, data, initial, offset
        self.segments = data.segments()
        self.free_td = fixed_td is None
        self.names = (("K",) + kind.shape_names + (("Td",) if self.free_td else ())
                      + (("input_offset",) if offset else ()))
        self.fixed_td = 0.0 if fixed_td is None else fixed_td
        self.tp_min = _TP_MIN_SAMPLES * data.ts
        self.t_max = 100.0 * data.n_samples * data.ts
        self.td_max = td_max
        # the search's own values: the time constants (Tw, Zeta for two poles) and Td; K is projected out
        if kind.poles == 1:
            low, high = [self.tp_min], [self.t_max]
        elif kind.underdamped:
            low, high = [self.tp_min, 1e-4], [self.t_max, 10.0]
        else:
            low, high = [self.tp_min, 1.0], [self.t_max, _ZETA_MAX]
        if self.free_td:
            low, high = low + [0.0], high + [td_max]
        self.inner_lower, self.inner_upper = np.array(low), np.array(high)
        self.nfev = 0

    def inner_start(self, start: dict) -> np.ndarray:
        if self.kind.poles == 1:
            inner = [start["Tp1"]]
        elif self.kind.underdamped:
            inner = [start["Tw"], start["Zeta"]]
        else:
            tw = math.sqrt(start["Tp1"] * start["Tp2"])
            inner = [tw, max((start["Tp1"] + start["Tp2"]) / (2.0 * tw), 1.05)]
        if self.free_td:
            inner.append(start["Td"])
        return np.clip(inner, self.inner_lower, self.inner_upper)

    def inner_values(self, inner, gain: float = 1.0) -> dict:
        out = {"K": gain, **_shape_values(self.kind, inner)}
        out["Td"] = float(inner[-1]) if self.free_td else self.fixed_td
        return out

    def projected(self, inner):
        """``(y_hat, K, c)`` of the search's values, ``K``, the offset ``c`` and the initial states fitted."""
        self.nfev += 1
        gb, ga = _discrete(self.kind, self.inner_values(inner), self.data.ts)
        return _fitted(self.data.y, _responses(gb, ga, self.segments, self.initial, self.offset))

    def residual(self, inner) -> np.ndarray:
        return self.data.y - self.projected(inner)[0]

    def values(self, theta) -> dict:
        """The model's values (``K``, time constants, ``Td``) of the reported ``theta``, the offset left out."""
        out = dict(zip(self.names, (float(v) for v in theta), strict=True))
        out.pop("input_offset", None)
        out.setdefault("Td", self.fixed_td)
        return out

    def output(self, theta) -> np.ndarray:
        """The output of the reported values ``theta`` (the initial states fitted with ``"estimate"``)."""
        self.nfev += 1
        values = self.values(theta)
        gb, ga = _discrete(self.kind, {**values, "K": 1.0}, self.data.ts)   # the gain is applied by _fitted
        offset = float(theta[-1]) if self.offset else 0.0
        resp = _responses(gb, ga, self.segments, self.initial, self.offset)
        return _fitted(self.data.y, resp, gain=values["K"], offset=offset)[0]

    def jacobian(self, theta) -> np.ndarray:
        """``d y_hat / d theta`` of the reported values by central differences, one-sided at Td = 0."""
        theta = np.asarray(theta, float)
        jac = np.empty((self.data.n_samples, theta.size))
        u_rms = float(np.sqrt(np.mean(self.data.u ** 2))) or 1.0
        for j, name in enumerate(self.names):
            typical = 1.0 if name in ("K", "Zeta") else (u_rms if name == "input_offset" else self.data.ts)
            h = 1e-6 * max(abs(theta[j]), typical)
            up, down = theta.copy(), theta.copy()
            if name == "Td" and theta[j] - h < 0.0:
                up[j] += h
                jac[:, j] = (self.output(up) - self.output(theta)) / h
            else:
                up[j] += h
                down[j] -= h
                jac[:, j] = (self.output(up) - self.output(down)) / (2.0 * h)
        return jac


# ---------------------------------------------------------------------------
# starting values
# ---------------------------------------------------------------------------
def _arx_scan(kind: _Kind, data: IdData, delays, offset: bool = False):
    """ARX fits with ``kind.poles`` poles at each whole-sample delay of ``delays``: ``(losses, fits)``.

    An integrating kind is fitted to the integrated input (``ts cumsum(u)``): the integrator moved to the
    input leaves the output's noise as it is, where differencing the output would amplify it. With an
    input offset ``c`` the regression gains a constant (``B(1) c``) and, for an integrating kind, a ramp
    (the integrated offset ``c ts (k + 1)``), so that the drift does not bend the poles."""
    na, nb = kind.poles, 2
    segments = [(y, np.cumsum(u) * data.ts if kind.integrator else u) for y, u in data.segments()]
    losses, fits = [], []
    for d in delays:
        rows_y, rows_x = [], []
        for y, u in segments:
            first = max(na, d + nb)
            if y.size <= first + 2:
                continue
            cols = [-y[first - k:y.size - k] for k in range(1, na + 1)]
            cols += [u[first - d - k:u.size - d - k] for k in range(1, nb + 1)]
            if offset:
                cols.append(np.ones(y.size - first))
                if kind.integrator:
                    cols.append(np.arange(first, y.size) * data.ts)
            rows_x.append(np.column_stack(cols))
            rows_y.append(y[first:])
        if not rows_x:
            continue
        x, target = np.vstack(rows_x), np.concatenate(rows_y)
        coef = _least_squares(x, target)
        if not np.all(np.isfinite(coef)):
            continue
        losses.append(float(np.mean((target - x @ coef) ** 2)))
        fits.append((int(d), np.concatenate([[1.0], coef[:na]]), coef[na:na + nb]))
    return losses, fits


def _shape_from_arx(a: np.ndarray, ts: float):
    """Time constants (and ``Tw, Zeta``) of an ARX denominator's stable poles, or None."""
    s_poles = [np.log(complex(p)) / ts for p in np.roots(a) if 1e-6 < abs(p) < 1.0]
    taus = sorted((-1.0 / s.real for s in s_poles if s.real < 0), reverse=True)
    if not taus:
        return None
    shape = {"Tp1": taus[0], "Tp2": taus[1] if len(taus) > 1 else taus[0] / 4.0}
    complex_s = [s for s in s_poles if abs(s.imag) > 1e-9 and s.real < 0]
    if complex_s:
        wn = abs(complex_s[0])
        shape["Tw"], shape["Zeta"] = 1.0 / wn, float(-complex_s[0].real / wn)
    else:
        shape["Tw"] = math.sqrt(shape["Tp1"] * shape["Tp2"])
        shape["Zeta"] = min((shape["Tp1"] + shape["Tp2"]) / (2.0 * shape["Tw"]), 5.0)
    return shape


def _start_values(kind: _Kind, data: IdData, fixed_td: float | None, td_max: float, offset: bool = False) -> list:
    """Starting values (dicts) for procest to screen: shapes times delays.

    The shapes: the best ARX fit's poles, and time constants of 2, 10 and 50 samples (an ARX fit is
    biased by output noise, and a poor start can end in the valley where a delay stands in for a short
    time constant). The delays: the three best whole-sample delays of the ARX scan and half a sample
    either side of each (a fractional delay lies between two whole ones), and zero. ``K`` is not
    searched (it is fitted linearly at each step), so it needs no start."""
    ts = data.ts
    shortest = min(y.size for y, _u in data.segments())
    if fixed_td is None and kind.delay:
        # at most 40 delays up to a quarter of the shortest experiment (and 200 samples)
        max_delay = max(int(min(td_max / ts, shortest // 4, 200)), 0)
        delays = np.unique(np.round(np.linspace(0, max_delay, min(max_delay + 1, 40))).astype(int))
    else:
        delays = [int(math.floor((fixed_td or 0.0) / ts + 1e-9))]
    losses, fits = _arx_scan(kind, data, delays, offset)
    order = list(np.argsort(losses)) if losses else []
    shapes = []
    if order:
        arx = _shape_from_arx(fits[order[0]][1], ts)
        if arx is not None:
            shapes.append(arx)
    for samples in (2.0, 10.0, 50.0):
        t = samples * ts
        shapes.append({"Tp1": t, "Tp2": t / 4.0, "Tw": t / 2.0, "Zeta": 0.5})
    tp_min, tp_max = 2 * _TP_MIN_SAMPLES * ts, 10.0 * data.n_samples * ts
    for shape in shapes:
        shape["K"] = 1.0
        for name in ("Tp1", "Tp2", "Tw"):
            shape[name] = float(np.clip(shape[name], tp_min, tp_max))
    if fixed_td is not None or not kind.delay:
        return shapes
    tds = [0.0]
    for idx in order[:3]:
        d_ts = fits[idx][0] * ts
        tds += [d_ts, d_ts + 0.5 * ts, d_ts - 0.5 * ts]
    tds = [td for td in dict.fromkeys(tds) if 0.0 <= td <= td_max]
    # every delay with the first shape; the other shapes with the two best whole-sample delays only
    # (each start costs a simulation to screen)
    best_tds = [fits[idx][0] * ts for idx in order[:2]] or [0.0]
    return ([{**shapes[0], "Td": float(td)} for td in tds]
            + [{**shape, "Td": float(td)} for shape in shapes[1:] for td in best_tds if td <= td_max])


# ---------------------------------------------------------------------------
# the estimator
# ---------------------------------------------------------------------------
def _check_fixed_delay(delay, kind: _Kind, data: IdData):
    """``None`` (Td estimated) or the fixed Td in seconds."""
    if isinstance(delay, (bool, np.bool_)):
        return None if (delay and kind.delay) else 0.0
    try:
        td = float(delay)
    except (TypeError, ValueError):
        raise not_allowed("delay", delay, "True (estimate Td), False (Td = 0) or a fixed Td in seconds") from None
    shortest = min(y.size for y, _u in data.segments())
    if not math.isfinite(td) or td < 0:
        raise not_allowed("delay", delay, "a fixed Td must be a finite number of seconds >= 0")
    if td >= (shortest - 1) * data.ts:
        raise not_allowed("delay", delay, f"a delay must be shorter than the record "
                                          f"({(shortest - 1) * data.ts:g} s, the shortest experiment)")
    return td


def procest(data: IdData, kind: str, *, initial: str = "zero", delay=True,
            input_offset: str = "zero") -> ProcessModel:
    """A continuous-time process model by output error on held-input data (MATLAB ``procest``).

    Parameters
    ----------
    data : IdData
        One or several experiments, the input held between samples (zero-order hold).
    kind : str
        MATLAB's type code: ``"P1D"``, ``"P2D"``, ``"P2DU"``, ``"P1DI"``, ``"P2DI"`` (see the module's
        table); without ``D`` the model has no delay.
    initial : {"zero", "estimate"}
        Initial conditions of each experiment: at rest, or the free response fitted by least squares
        at each step of the search.
    delay : bool or float
        True (default): ``Td`` estimated when the kind has ``D``; False: ``Td = 0``; a number: ``Td`` fixed
        at that many seconds (below the shortest experiment's length).
    input_offset : {"zero", "estimate"}
        ``"estimate"``: the model is ``y = G(s) (u + c)`` with a constant input offset ``c`` (input units,
        MATLAB's ``InputOffset``), one for all experiments, fitted linearly with ``K``; it is the last
        parameter (``"input_offset"``) and the model's :attr:`ProcessModel.input_offset`, which
        :func:`~eha_core.identify.blackbox.compare` applies. An integrating process driven by a valve that
        flows more one way than the other needs it. ``"zero"`` (default): no offset.

    Returns
    -------
    ProcessModel
        ``success`` False with a message when the search failed, a time constant or the delay ran to its
        bound, or the parameters are not identifiable from these data.

    Examples
    --------
    >>> import numpy as np, scipy.signal
    >>> u = np.repeat(np.random.default_rng(0).choice([-1.0, 1.0], 60), 5)
    >>> gb, ga = zoh_poly("P1D", {"K": 2.0, "Tp1": 0.5, "Td": 0.23}, 0.1)
    >>> y = scipy.signal.lfilter(gb, ga, u)
    >>> model = procest(IdData(y, u, 0.1), "P1D")
    >>> model.name, model.success
    ('P1D (K, Tp1, Td)', True)
    >>> {k: round(v, 6) for k, v in model.values.items()}
    {'K': 2.0, 'Tp1': 0.5, 'Td': 0.23}

    An integrating process that runs faster one way: an input offset of 0.1

    >>> gb, ga = zoh_poly("P1DI", {"K": 2.0, "Tp1": 0.5, "Td": 0.23}, 0.1)
    >>> y = scipy.signal.lfilter(gb, ga, u + 0.1)
    >>> model = procest(IdData(y, u, 0.1), "P1DI", input_offset="estimate")
    >>> model.param_names, round(model.input_offset, 6), round(model.values["K"], 6)
    (('K', 'Tp1', 'Td', 'input_offset'), 0.1, 2.0)
    """
    if not isinstance(data, IdData):
        raise not_allowed("data", data, "an IdData (eha_core.identify.blackbox.IdData)")
    k = _parse_kind(kind)
    if initial not in INITIAL_CONDITIONS:
        raise not_allowed("initial", initial, "zero or estimate")
    if not (isinstance(input_offset, str) and input_offset in INPUT_OFFSETS):
        raise not_allowed("input_offset", input_offset, "zero (no offset) or estimate (y = G (u + c), c fitted)")
    fixed_td = _check_fixed_delay(delay, k, data)
    shortest = min(y.size for y, _u in data.segments())
    td_max = (shortest - 2) * data.ts
    offset = input_offset == "estimate"
    problem = _Problem(k, data, initial, fixed_td, max(td_max, 0.0), offset)
    n_free = len(problem.names)
    if data.n_samples <= n_free + 2:
        raise not_allowed("data", f"{data.n_samples} samples", f"a {k.code} model needs more than {n_free + 2}")

    with np.errstate(all="ignore"):
        inner, best_gain, best_offset, problems = _search(problem)
    values = problem.inner_values(inner, best_gain)

    gb, ga = _discrete(k, values, data.ts)
    theta = np.array([values[n] for n in problem.names if n != "input_offset"] + ([best_offset] if offset else []))
    base = dict(structure="process", name=f"{k.code} ({', '.join(problem.names)})",
                orders={"poles": k.poles + int(k.integrator), "integrator": k.integrator, "delay": k.delay},
                ts=data.ts, kind=k.code, values=values, discrete_num=gb, discrete_den=ga,
                params=theta, param_names=problem.names, initial=initial, n_samples=data.n_samples,
                input_offset=float(best_offset) if offset else None)
    shell = ProcessModel(**base, covariance=np.zeros((n_free, n_free)), noise_variance=math.nan, criteria=None,
                         fit=None, success=False, message="", nfev=problem.nfev)
    with np.errstate(all="ignore"):
        fit = compare(shell, data, None, initial)
    e = data.y - fit.yhat
    finite = bool(np.all(np.isfinite(e)))
    crit = criteria(e, n_free) if finite else Criteria(math.nan, math.nan, math.nan, math.nan, n_free,
                                                         data.n_samples)
    variance = float(np.sum(e ** 2) / max(data.n_samples - n_free, 1))
    cov = np.full((n_free, n_free), np.nan)
    if not problems:
        problems += _bound_problems(problem, values)
        with np.errstate(all="ignore"):
            jac = problem.jacobian(theta)
        info = jac.T @ jac
        if not finite or not np.all(np.isfinite(info)):
            problems.append("the simulated output is not finite")
        else:
            cov = variance * np.linalg.pinv(info)
            if np.linalg.cond(info) > 1e14 and variance > 1e-24 * float(np.mean(data.y ** 2)):
                problems.append("the parameters are not identifiable from these data (singular information "
                                "matrix): try a simpler kind or an input that excites the process more")
    message = "; ".join(problems) if problems else (
        f"{k.code} by output error from {problem.nfev} simulations; {fit.label}")
    return ProcessModel(**base, covariance=cov, noise_variance=variance, criteria=crit, fit=fit,
                        success=not problems, message=message, nfev=problem.nfev)


def _search(problem: _Problem):
    """``(inner, K, c, problems)``: the searched values at the least error, their gain and input offset
    (0 when not estimated), and what went wrong.

    The starting points are screened by their error (one simulation each); the search runs from the best
    and from the best one whose delay is more than 1.5 samples away from where the first search ended,
    unless its error is more than three times the best start's; an end in the valley where the delay
    stands in for a time constant gets one more search (:func:`_valley_search`)."""
    data, n_inner = problem.data, problem.inner_lower.size
    fixed_td = None if problem.free_td else problem.fixed_td
    best, errors = None, []
    starts = [problem.inner_start(start)
              for start in _start_values(problem.kind, data, fixed_td, problem.td_max, problem.offset)]
    costs = [float(np.sum(problem.residual(x0) ** 2)) for x0 in starts]
    ranking = np.argsort(np.nan_to_num(costs, nan=np.inf))
    searched = []
    for j in ranking:
        x0 = starts[j]
        if len(searched) == 2 or costs[j] > 3.0 * costs[ranking[0]]:
            break
        if searched and problem.free_td and abs(x0[-1] - searched[0][-1]) <= 1.5 * data.ts:
            continue
        try:
            res = scipy.optimize.least_squares(problem.residual, x0, bounds=(problem.inner_lower, problem.inner_upper),
                                               x_scale="jac", xtol=1e-10, ftol=1e-12, gtol=1e-12,
                                               max_nfev=50 * n_inner)
        except (ValueError, np.linalg.LinAlgError) as err:
            errors.append(str(err))
            continue
        searched.append(res.x)
        if np.isfinite(res.cost) and (best is None or res.cost < best.cost):
            best = res
        if not problem.free_td:
            break
    if best is not None and problem.free_td and _bound_problems(problem, problem.inner_values(best.x)):
        res = _valley_search(problem, best.x, n_inner)
        if res is not None and np.isfinite(res.cost) and res.cost < best.cost:
            best = res
    if best is None or best.status <= 0:
        why = best.message if best is not None else "; ".join(errors) or "no starting point gave a finite error"
        inner = best.x if best is not None else starts[0]
        return inner, 1.0, 0.0, [f"the search failed ({why}): try another kind or a fixed delay"]
    _y_hat, gain, offset = problem.projected(best.x)
    return best.x, gain, offset, []


def _valley_search(problem: _Problem, inner: np.ndarray, n_inner: int):
    """A search from ``inner`` with 1.5 samples of its delay moved into the shortest time constant."""
    ts = problem.data.ts
    values = problem.inner_values(inner)
    td = max(values["Td"] - 1.5 * ts, 0.0)
    moved = max(values["Td"] - td, ts)
    start = dict(values, Td=td)
    if problem.kind.underdamped:
        start["Tw"] = max(values["Tw"], moved)
    elif problem.kind.poles == 1:
        start["Tp1"] = max(values["Tp1"], moved)
    else:
        start["Tp2"] = max(values["Tp2"], moved)
        start["Tp1"] = max(values["Tp1"], 1.5 * start["Tp2"])
    try:
        return scipy.optimize.least_squares(problem.residual, problem.inner_start(start),
                                            bounds=(problem.inner_lower, problem.inner_upper), x_scale="jac",
                                            xtol=1e-10, ftol=1e-12, gtol=1e-12, max_nfev=50 * n_inner)
    except (ValueError, np.linalg.LinAlgError):
        return None


def _bound_problems(problem: _Problem, values: dict) -> list:
    out = []
    kind = problem.kind
    if kind.poles == 2 and not kind.underdamped and values["Tp1"] <= values["Tp2"] * (1 + 1e-6):
        simpler = kind.code.replace("2", "1")
        out.append(f"Tp1 = Tp2 = {values['Tp1']:.3g} s at the optimum: the data want two equal or complex poles "
                   f"(their intervals are not meaningful); try {kind.code}U (underdamped) or {simpler}")
    for name in ("Tp1", "Tp2", "Tw"):
        if name not in values:
            continue
        at_zeta_max = (name == "Tp2" and (values["Tp1"] + values["Tp2"])
                       >= 0.99 * _ZETA_MAX * 2.0 * math.sqrt(values["Tp1"] * values["Tp2"]))
        if values[name] <= 1.01 * problem.tp_min or at_zeta_max:
            out.append(f"{name} ran to its lower bound ({values[name]:.3g} s): the data do not show this time "
                       f"constant; try a kind with fewer poles")
        elif values[name] >= 0.99 * problem.t_max:
            out.append(f"{name} ran to its upper bound ({values[name]:.3g} s): try an integrating kind (I)")
    if problem.free_td and problem.td_max > 0 and values["Td"] >= problem.td_max * (1 - 1e-9):
        out.append(f"Td ran to its upper bound ({values['Td']:.3g} s): try a fixed delay")
    return out
