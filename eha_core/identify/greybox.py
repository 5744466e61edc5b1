"""Grey-box identification: the actuator's physical parameters from what a rig measures.

Prediction-error (output-error) estimation on the nonlinear model itself, as MATLAB's ``nlgreyest``:
simulate the model (eqs. 1-4) with candidate parameters, compare the simulated signals with the
measured ones, minimise the weighted sum of squares. Any subset of :class:`ActuatorParams` can be
estimated (M, B, Af, βe, Kq1, Kq2, L0, k_f, d0 and the initial state x0, v0, p1(0), p2(0)) from the
input u and any subset of the measured signals {x, v, p1, p2}, position alone included, in open loop
or under the P controller; the rest are held at the given values.

How
    The parameters are scaled: the logarithm of a positive one (a step is a relative change; the
    estimate stays positive), a multiple of its scale for one that may be 0 or negative (d0: 1000 N,
    x0: 10 mm, v0: 10 mm/s). The Jacobian comes from the forward sensitivity equations, integrated
    with the states by the compiled kernel (:func:`eha_core._kernels.integrate_sensitivities`, on the
    simulator's own step grid and dynamics), not from finite differences of whole simulations. A
    trust-region Gauss-Newton (:func:`scipy.optimize.least_squares`, ``trf``) within each parameter's
    physical range (:data:`eha_core.identify._greybox_checks.RANGES`). Each signal's residual is
    divided by its noise σ: first estimated from the data (the spread of its second differences),
    then from the residuals of the fit, and the fit repeated once if they differ by more than 20 %.
    The default strategy (``shooting="auto"``) fits a growing start of the record (1 s, 3 s, 9 s, ...,
    each from where the last ended), then all of it; when the estimate fails its checks, a parameter
    held at the guess is estimated with the rest, then multiple shooting from the guess is tried, and
    the better attempt kept.

What it gives
    Estimates, standard errors and 95 % intervals from the Jacobian at the estimate and the noise
    variances (the inverse Fisher information, as ``nlgreyest``'s covariance), the correlation
    matrix, the fit of every signal (MATLAB ``compare``'s NRMSE fit), residual tests with verdicts,
    and, from the singular values of the scaled Jacobian, what the data cannot determine, in words
    (:func:`identifiability`); a parameter the data do not determine at the initial guess is held
    there, and the result says so and what a 10 % error of it does to the others (``held_bias``).
    ``success`` is the estimate's own checks (:mod:`eha_core.identify._greybox_checks`): the optimiser
    converged, the residuals are each signal's noise and white, no estimate at a bound, a Jacobian
    of full rank. A result that fails them says what each found and what to try (``checks``,
    ``advice``) and gives no interval, standard error or correlation (NaN).

Multiple shooting (``shooting="multiple"``) cuts the record into segments whose initial states are
estimated with the parameters and joined by continuity, then polishes by output error; it costs
several times a single-shooting fit, so the default strategy uses it only when the checks fail.

Its limits: one record, output error only (no process-noise model: a disturbance the model does
not know biases the estimate and fails its checks; a known d(t) is an input), local minima from poor
guesses (the growing record avoids most; the checks catch the rest), the valve's switching and the end
stops are kinks the Gauss-Newton steps see only through their averages.

Examples
--------
>>> from eha_core.experiments import LSE_INPUT
>>> truth = ActuatorParams(M=5200.0, B=1900.0, Af=2400.0, beta_e=9.0e8)
>>> data = greybox_data(truth, LSE_INPUT, t_end=5.0, noise={"x": 1e-5, "p1": 5e4, "p2": 5e4}, seed=3,
...                     measured=("x", "p1", "p2"))
>>> res = identify_greybox(data, ("M", "B", "Af", "beta_e"))
>>> res.success, all(res.ci95[n][0] < getattr(truth, n) < res.ci95[n][1] for n in ("M", "Af", "beta_e"))
(True, True)
>>> f"{res.estimates['M']:.0f} ± {res.std_errors['M']:.0f} kg"
'5199 ± 3 kg'
"""

from __future__ import annotations

import math
import sys
import time
import weakref
from dataclasses import dataclass, field, replace

import numpy as np

from .._checks import ComputationError, not_allowed
from ..cancel import CancelToken, check
from ..model import PARAM_INDEX, pack_params
from ..params import ActuatorParams
from ..signals import ZERO, Signal

__all__ = ["GREYBOX_PARAMS", "GREYBOX_SIGNALS", "INTERSAMPLE", "SHOOTING", "read_intersample", "GreyBoxData",
           "GreyBoxResult", "greybox_data", "identify_greybox", "simulate_with_sensitivities", "identifiability",
           "noise_guess", "param_value", "LINEAR_SCALE"]

#: What can be estimated: the model's parameters and the initial state.
GREYBOX_PARAMS = ("M", "B", "Af", "beta_e", "Kq1", "Kq2", "L0", "k_f", "d0", "x0", "v0", "p1_0", "p2_0")
#: How the input moves between samples: read from the record (:func:`read_intersample`), linearly (foh)
#: or held (zoh).
INTERSAMPLE = ("read", "foh", "zoh")
#: The signals a record may hold besides the input.
GREYBOX_SIGNALS = ("x", "v", "p1", "p2")
_STATE_INDEX = {"x0": 0, "v0": 1, "p1_0": 2, "p2_0": 3}
_SIGNAL_INDEX = {"x": 0, "v": 1, "p1": 2, "p2": 3}
#: A parameter that may be 0 or negative is estimated as a multiple of this scale (SI).
LINEAR_SCALE = {"d0": 1000.0, "x0": 0.01, "v0": 0.01}
Z95 = 1.959963984540054
#: log of the largest float: math.exp of more raises OverflowError ("math range error").
_LOG_FLOAT_MAX = math.log(sys.float_info.max)
#: A parameter with at least this share of a direction (unit vector) the data do not fix has no bound.
_UNFIXED_SHARE = 1e-6
#: The states' scales in multiple shooting (x, v, p1, p2 in SI): a segment's initial state is
#: estimated in these units.
STATE_SCALE = np.array([0.01, 0.01, 1e6, 1e6])


@dataclass(frozen=True, eq=False)
class GreyBoxData:
    """A record for grey-box identification: ``t`` (uniform) [s], the input: the valve command ``u``
    [V] in open loop, or the reference ``r`` [m] with the gain ``kp`` [V/m] under the sampled P
    controller (Ts = the sample time), a known load ``d`` [N] (None: none), and the measured signals
    (``signals``: name -> samples, SI, any of x, v, p1, p2). ``intersample``: how the open-loop command
    moves between its samples, linearly (foh: a smooth signal sampled) or held (zoh: a DAC's output), or
    ``read`` (the default) from the record by :func:`identify_greybox` (:func:`read_intersample`);
    held by half a sample too long, a 2 Hz sine at 1 kHz moves x by 50 µm, five times 30 dB noise.
    ``noise``: the sensors' σ per measured signal (SI; 0 for a noise-free one) when it is known, which the
    estimate's noise check compares its residuals with; None: not stated, the check then compares them
    with the record's own sample-to-sample scatter."""

    t: np.ndarray
    u: np.ndarray | None
    signals: dict
    d: np.ndarray | None = None
    r: np.ndarray | None = None
    kp: float | None = None
    source: str = "data"
    intersample: str = "read"
    noise: dict | None = None

    def __post_init__(self):
        t = np.asarray(self.t, dtype=float).ravel()
        if t.size < 3 or not np.all(np.isfinite(t)):
            raise not_allowed("t", t.size, "give at least 3 finite sample times")
        dt = np.diff(t)
        if not np.all(dt > 0) or np.ptp(dt) > 1e-6 * np.mean(dt):
            raise not_allowed("t", "(times)", "the samples must be uniformly spaced and increasing")
        if (self.u is None) == (self.r is None):
            raise not_allowed("input", "(u and r)", "give the command u (open loop) or the reference r with kp "
                                                     "(closed loop), one of them")
        if self.r is not None and not (self.kp and math.isfinite(self.kp) and self.kp > 0):
            raise not_allowed("kp", self.kp, "a closed-loop record needs the controller gain kp > 0 [V/m]")
        if self.intersample not in INTERSAMPLE:
            raise not_allowed("intersample", self.intersample, "use read (from the record), foh (the command varies "
                                                               "linearly between "
                                                               "samples) or zoh (it is held, as by a DAC)")
        if not self.signals:
            raise not_allowed("signals", "(none)", f"give at least one measured signal of {', '.join(GREYBOX_SIGNALS)}")
        for name, y in self.signals.items():
            if name not in GREYBOX_SIGNALS:
                raise not_allowed("signals", name, f"{name} is not a signal; use {', '.join(GREYBOX_SIGNALS)}")
            y = np.asarray(y, dtype=float).ravel()
            if y.size != t.size or not np.all(np.isfinite(y)):
                raise not_allowed(name, y.size, f"give {t.size} finite samples, one per time")
        if self.noise is not None:
            for name, sigma in self.noise.items():
                if name not in self.signals or not (isinstance(sigma, (int, float)) and math.isfinite(sigma)
                                                    and sigma >= 0):
                    raise not_allowed("noise", f"{name}={sigma}", "give a σ >= 0 (SI) for signals of the record")
            object.__setattr__(self, "noise", {k: float(v) for k, v in self.noise.items()})
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "signals", {k: np.asarray(v, dtype=float).ravel() for k, v in self.signals.items()})

    @property
    def ts(self) -> float:
        return float(self.t[1] - self.t[0])


def greybox_data(params: ActuatorParams, u: Signal | None = None, *, t_end: float = 5.0, dt: float = 1e-3,
                 d: Signal | None = None, r: Signal | None = None, kp: float | None = None,
                 noise: dict | None = None, seed: int = 0, measured=GREYBOX_SIGNALS) -> GreyBoxData:
    """A simulated record of the nonlinear plant ``params``: open loop under ``u``, or under the P
    controller (``r``, ``kp``, Ts = ``dt``); white noise of σ ``noise[signal]`` (SI) on the measured
    signals, drawn from ``seed``.

    Parameters
    ----------
    params : ActuatorParams
        The simulated actuator (the truth).
    u : Signal, optional
        Open loop: the valve command [V], sampled at the record's times and linear between them.
        Default (neither ``u`` nor ``r`` given): the paper's least-squares input 6 sin(4 pi t) V
        (:data:`eha_core.experiments.LSE_INPUT`), the app's grey-box excitation by default.
    t_end, dt : float
        The record's length and sample time [s] (``dt`` is also the controller's Ts).
    d : Signal, optional
        A known load force [N], kept in the record; none by default.
    r : Signal, optional
        Closed loop: the reference position [m]; give it or ``u``.
    kp : float, optional
        Closed loop: the controller's gain [V/m].
    noise : dict of str to float, optional
        σ of the white noise on each measured signal, SI units (m, m/s, Pa); none by default.
    seed : int
        Seed of the noise.
    measured : iterable of str
        The signals the record keeps, of :data:`GREYBOX_SIGNALS`.
    """
    from ..signals import Sampled
    from ..simulate import simulate, simulate_closed_loop

    # the plant is driven by the samples the record keeps, between them as the record says (foh): the
    # model then sees exactly the plant's input, and only the noise stands between them
    t = np.arange(int(round(t_end / dt)) + 1) * dt
    if d is not None and d is not ZERO:
        d = Sampled(t, np.asarray(d(t), dtype=float), hold="linear", name="d")
    if r is not None:
        run = simulate_closed_loop(params, r, kp=kp, ts=dt, d=d, t_end=t_end, dt=dt)
    else:
        if u is None:
            from ..experiments import LSE_INPUT

            u = LSE_INPUT
        u = Sampled(t, np.asarray(u(t), dtype=float), hold="linear", name="u")
        run = simulate(params, u, d, t_end=t_end, dt=dt)
    if not run.success:
        raise ComputationError(f"the simulation failed: {run.message}")
    rng = np.random.default_rng(seed)
    signals = {}
    for name in measured:
        y = np.asarray(getattr(run, name), dtype=float)
        sigma = float((noise or {}).get(name, 0.0))
        signals[name] = y + sigma * rng.standard_normal(y.size) if sigma > 0 else y.copy()
    return GreyBoxData(t=run.t, u=None if r is not None else run.u, r=run.r if r is not None else None, kp=kp,
                       d=run.d, signals=signals, source=f"simulated, seed {seed}", intersample="foh",
                       noise={name: float((noise or {}).get(name, 0.0)) for name in measured})


# -- the model with its sensitivities -----------------------------------------------------------------

@dataclass(frozen=True)
class _Setup:
    names: tuple[str, ...]
    log: tuple[bool, ...]
    base: ActuatorParams
    data: GreyBoxData

    def params_at(self, z: np.ndarray) -> ActuatorParams:
        values = {}
        for n, lg, zj in zip(self.names, self.log, z, strict=True):
            if lg and zj > _LOG_FLOAT_MAX:
                # a step of the optimiser to exp(huge): math.exp would raise OverflowError ("math range
                # error"), which no caller expects; this is a model that cannot be simulated
                raise ComputationError(f"{n} = exp({zj:.4g}) is beyond the largest number a float holds")
            values[n] = math.exp(zj) if lg else zj * LINEAR_SCALE[n]
        return self.base.replace(**values)

    def z_of(self, params: ActuatorParams) -> np.ndarray:
        return np.array([math.log(param_value(params, n)) if lg else param_value(params, n) / LINEAR_SCALE[n]
                         for n, lg in zip(self.names, self.log, strict=True)])

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Each parameter's physical range (:func:`~eha_core.identify._greybox_checks.estimate_range`) in
        the scaled terms the optimiser moves in."""
        from ._greybox_checks import estimate_range

        lo, hi = [], []
        for n, lg in zip(self.names, self.log, strict=True):
            a, b = estimate_range(n)
            lo.append(math.log(a) if lg else a / LINEAR_SCALE[n])
            hi.append(math.log(b) if lg else b / LINEAR_SCALE[n])
        return np.array(lo), np.array(hi)

    def clip(self, z: np.ndarray) -> np.ndarray:
        """``z`` moved just inside the physical ranges (an initial guess outside them starts at their end)."""
        lo, hi = self.bounds
        room = 1e-6 * np.maximum(1.0, np.abs(hi - lo))
        return np.clip(z, lo + room, hi - room)


def param_value(params: ActuatorParams, name: str) -> float:
    """The value (SI) of the estimable parameter ``name`` of ``params``: a field, or p2(0) as the
    initial state has it (a blank one follows from the force balance)."""
    return float(params.initial_state[_STATE_INDEX[name]]) if name == "p2_0" else float(getattr(params, name))


def simulate_with_sensitivities(params: ActuatorParams, names, data: GreyBoxData, *, log=None,
                                initial: np.ndarray | None = None,
                                cancel: CancelToken | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The states (N x 4: x, v, p1, p2) at ``data.t`` and their sensitivities (N x 4 x P) to the
    parameters ``names``: d/d log(θ) for the positive ones (``log``), d/d(θ / scale) for the others.

    ``initial``: a segment's own initial state (multiple shooting): the parameters then do not move it,
    and four more columns hold the sensitivities to it, in :data:`STATE_SCALE` units.

    Parameters
    ----------
    params : ActuatorParams
        The parameters simulated with.
    names : iterable of str
        The parameters of the sensitivities, of :data:`GREYBOX_PARAMS`.
    data : GreyBoxData
        The record: its times, input and load.
    log : iterable of bool, optional
        Per parameter: sensitivity to its logarithm (True) or to its multiple of
        :data:`LINEAR_SCALE` (False); default True for all but those of :data:`LINEAR_SCALE`.
    initial : array of 4, optional
        The initial state [x, v, p1, p2] (SI) of a segment; default that of ``params``.
    cancel : eha_core.cancel.CancelToken, optional
        Checked before the integration.
    """
    from .. import _kernels as K

    names = tuple(names)
    log = tuple(log) if log is not None else tuple(n not in LINEAR_SCALE for n in names)
    h, sub, ctrl_every, n_steps, n_out, u_st, d_st, r_st, ctrl, kp = _inputs(data)
    prm = pack_params(params)
    P = len(names) + (4 if initial is not None else 0)
    pidx = np.full(P, -1, dtype=np.int64)
    pstep = np.zeros(P)
    s0 = np.zeros((4, P))
    y0 = params.initial_state if initial is None else np.asarray(initial, dtype=float)
    if initial is not None:
        s0[:, len(names):] = np.diag(STATE_SCALE)
    for j, (n, lg) in enumerate(zip(names, log, strict=True)):
        scale = param_value(params, n) if lg else LINEAR_SCALE[n]
        if n in PARAM_INDEX and n not in _STATE_INDEX:
            pidx[j], pstep[j] = PARAM_INDEX[n], scale
        if initial is not None:
            continue
        # the initial state's sensitivity: directly for x0, v0, p1(0), p2(0); through the force balance
        # of a blank p2(0) for the parameters it depends on (d0, p1(0), ...), by a difference (it is linear)
        eps = 1e-6
        up = params.replace(**{n: param_value(params, n) + eps * scale})
        dn = params.replace(**{n: param_value(params, n) - eps * scale})
        s0[:, j] = (up.initial_state - dn.initial_state) / (2 * eps)
    check(cancel)
    out = np.zeros((n_out, 4))
    sout = np.zeros((n_out, 4, P))
    status = K.integrate_sensitivities(y0, s0, h, n_steps, sub, prm, pidx, pstep, u_st, d_st, ctrl, kp, r_st,
                                       ctrl_every, 0.0, out, sout)
    if status >= 0:
        raise ComputationError(f"the model's simulation stopped being finite at t = {status * h:.4g} s")
    return out, sout


_INPUTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _inputs(data: GreyBoxData):
    """The step grid and the inputs sampled at every RK4 stage: the record's alone, so computed once per
    record (an estimate simulates it some twenty times)."""
    from .. import _kernels as K
    from ..simulate import DEFAULT_H_MAX, _as_signal, _grid, _stage_samples

    if data not in _INPUTS:
        t = data.t
        ts = data.ts
        # the simulator's own step bound: the model is the simulator's, step for step
        h, sub, ctrl_every, n_steps, n_out = _grid(t[-1] - t[0], ts, DEFAULT_H_MAX,
                                                   ts if data.r is not None else None)
        t0 = t - t[0]
        n_out = min(n_out, t.size)
        hold = "linear" if data.intersample == "foh" else "zoh"
        d_sig = _as_signal(data.d, "d", t0, hold=hold) if data.d is not None else ZERO
        if data.r is not None:
            r_sig = _as_signal(data.r, "r", t0, hold="zoh")
            u_st, r_st, ctrl, kp = np.zeros((1, 3)), _stage_samples(r_sig, "r", h, n_steps), K.ZOH, float(data.kp)
        else:
            u_sig = _as_signal(data.u, "u", t0, hold=hold)
            u_st, r_st, ctrl, kp = _stage_samples(u_sig, "u", h, n_steps), np.zeros((1, 3)), K.OPEN_LOOP, 0.0
        _INPUTS[data] = (h, sub, ctrl_every, n_steps, n_out, u_st, _stage_samples(d_sig, "d", h, n_steps), r_st,
                         ctrl, kp)
    return _INPUTS[data]


def read_intersample(data: GreyBoxData) -> tuple[str | None, str]:
    """How ``data``'s open-loop input moves between samples, as far as its samples tell: ``("zoh", why)``
    when it is piecewise constant over runs of samples (a command held longer than the record's sample
    time: at least half of the steps repeat the last value), ``(None, why)`` when the samples cannot
    tell (a held command changes at every sample just as a smooth one does); a closed-loop record's
    reference is held by the controller. The record's own ``intersample`` when it is not ``read``."""
    if data.intersample != "read":
        return data.intersample, "as the record states"
    if data.u is None:
        return "zoh", "the sampled controller holds its command"
    du = np.diff(np.asarray(data.u, dtype=float))
    moves = np.abs(du) > 1e-12 * (float(np.max(np.abs(data.u))) + 1e-300)
    if moves.any() and np.mean(~moves) >= 0.5:
        runs = du.size / max(int(moves.sum()), 1)
        return "zoh", f"u is piecewise constant in the record (it changes once every {runs:.3g} samples): held"
    if not moves.any():
        return "foh", "u is constant"
    return None, "the samples of u cannot tell whether it was held or linear between them"


def noise_guess(y: np.ndarray) -> float:
    """σ of white noise on a smooth signal ``y`` (in its own unit): its second differences' spread (the
    signal's own curvature at 1 kHz is far below the noise), robustly (median absolute deviation)."""
    d2 = np.diff(y, 2)
    mad = np.median(np.abs(d2 - np.median(d2))) * 1.4826
    return float(mad / math.sqrt(6.0)) if mad > 0 else float(np.std(y) * 1e-3 + 1e-30)


# -- identifiability ----------------------------------------------------------------------------------------

def identifiability(J: np.ndarray, names, *, v_max: float | None = None, k_f: float | None = None,
                    pressures: bool = True, threshold: float = 1.0) -> list[tuple[tuple[str, ...], str]]:
    """What the data cannot determine, from the scaled, weighted Jacobian ``J`` (residuals in units of
    their noise σ, parameters in log or scale units): each singular direction whose standard error
    exceeds ``threshold`` (1: a change by a factor e, or by one scale, within one standard error), as
    ``(the parameters in it, a sentence)``. ``names`` are the parameters of ``J``'s columns, in order.
    ``v_max`` (the record's largest |v|, m/s), ``k_f`` (the friction law's slope, s/m) and
    ``pressures`` (are pressures measured?) let the sentence say why.

    >>> J = np.array([[1.0, 1.0], [2.0, 2.0], [0.5, 0.5]]) * 1e3      # two columns that move together
    >>> [s for _, s in identifiability(J, ("beta_e", "Kq1"), pressures=False)]
    ['beta_e and Kq1 enter only as their product without pressure measurements: the data determine that, not each']
    """
    names = tuple(names)
    if J.size == 0:
        return []
    col = np.linalg.norm(J, axis=0)
    out = [((names[j],), f"{names[j]} does not affect the measured signals at all: it cannot be estimated from them")
           for j in range(len(names)) if col[j] == 0]
    live = [j for j in range(len(names)) if col[j] > 0]
    if not live:
        return out
    _, s, vt = np.linalg.svd(J[:, live], full_matrices=False)
    for k in range(len(s)):
        if s[k] > 0 and 1.0 / s[k] <= threshold:
            continue
        v = vt[k]
        order = [i for i in range(len(v)) if abs(v[i]) >= 0.3 * np.max(np.abs(v))]       # in the order asked
        who = tuple(names[live[i]] for i in order)
        out.append((who, _sentence(who, [v[i] for i in order], v_max, k_f, pressures)))
    return out


def _sentence(who, v, v_max, k_f, pressures) -> str:
    linear_friction = v_max is not None and k_f is not None and k_f * v_max < 1.0
    if linear_friction and set(who) <= {"B", "Af"}:
        why = (f"the record never leaves |v| < {1e3 * v_max:.3g} mm/s, where the friction law is linear: only "
               "B + 2 kf Af / π counts there")
        return (f"B and Af are not separable: {why}" if len(who) == 2 else
                f"the data do not determine {who[0]}: {why}")
    if len(who) == 1:
        return f"the data do not determine {who[0]}: its standard error exceeds its own size"
    extra = "" if pressures else " without pressure measurements"
    if len(who) == 2:
        kind = "their product" if v[0] * v[1] < 0 else "their ratio"
        return f"{who[0]} and {who[1]} enter only as {kind}{extra}: the data determine that, not each"
    return (f"{', '.join(who[:-1])} and {who[-1]} are not separable{extra}: the data determine only a combination "
            "of them")


# -- the estimate ------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class GreyBoxResult:
    """A grey-box estimate (SI). ``std_errors`` and ``ci95`` from the inverse Fisher information at the
    estimate; ``fit`` per measured signal in %; ``held`` the parameters held at their initial value
    because the data do not determine them (``identifiability`` says why). ``success`` is the claim
    that the answer holds: the optimiser stopped at a minimum (its own flag is
    ``extras["optimiser_success"]``) and every estimated parameter's interval is bounded."""

    names: tuple[str, ...]
    estimates: dict
    std_errors: dict
    ci95: dict
    correlation: np.ndarray
    fit: dict
    noise_std: dict
    params: ActuatorParams
    simulated: np.ndarray
    assessment: object
    identifiability: tuple = ()
    held: tuple[str, ...] = ()
    nfev: int = 0
    iterations: int = 0
    time_s: float = 0.0
    success: bool = True
    message: str = ""
    measured: tuple[str, ...] = ()
    extras: dict = field(default_factory=dict)
    checks: tuple = ()
    advice: tuple[str, ...] = ()
    strategy: str = ""
    held_bias: dict = field(default_factory=dict)
    #: the record estimated from (what :meth:`plot` draws the model against)
    data: GreyBoxData | None = field(default=None, repr=False)

    @property
    def failed_checks(self) -> tuple:
        """The checks the estimate failed (:class:`~eha_core.identify._greybox_checks.FitCheck`)."""
        return tuple(c for c in self.checks if not c.passed)

    def to_dict(self) -> dict:
        """The estimate, its statistics and fits as plain JSON-able values."""
        return {"estimates": dict(self.estimates), "std_errors": dict(self.std_errors),
                "ci95": {k: list(v) for k, v in self.ci95.items()},
                "correlation": {a: {b: float(self.correlation[i, j]) for j, b in enumerate(self.names)}
                                for i, a in enumerate(self.names)},
                "fit": dict(self.fit), "noise_std": dict(self.noise_std), "held": list(self.held),
                "identifiability": [s for _, s in self.identifiability], "success": self.success,
                "message": self.message, "checks": [c.to_dict() for c in self.checks], "advice": list(self.advice),
                "strategy": self.strategy, "held_bias": {h: dict(v) for h, v in self.held_bias.items()},
                "nfev": self.nfev, "time_s": self.time_s}

    def to_pandas(self):
        """The estimates as a :class:`pandas.DataFrame` indexed by parameter: ``value``, ``std_error``,
        ``ci95_low``, ``ci95_high`` (SI; NaN for a held parameter and for every one when the checks failed),
        ``unit``, ``display_unit``, ``display_scale``, and ``held`` (held at the initial guess)."""
        from .._display import estimates_frame

        nan = (math.nan, math.nan)
        return estimates_frame(((n, self.estimates[n], self.std_errors.get(n, math.nan), *self.ci95.get(n, nan))
                                for n in self.names), extra={"held": [n in self.held for n in self.names]})

    def plot(self):
        """Draw each measured signal against the estimated model's with matplotlib
        (:func:`eha_core.plotting.plot_greybox`); returns the Figure."""
        from ..plotting import plot_greybox

        return plot_greybox(self)

    def __repr__(self) -> str:
        from .._display import block, short, with_error

        fits = ", ".join(f"{s} {self.fit[s]:.1f} %" for s in self.measured)
        head = f"GreyBoxResult: output error on the nonlinear model, fit {fits}"
        items = [with_error(n, self.estimates[n], self.std_errors.get(n)) + (" (held)" if n in self.held else "")
                 for n in self.names]
        notes = ["± 1 standard error; .to_pandas(): the 95 % intervals; .plot(): the fit"]
        if not self.success:
            notes = [f"failed checks: {', '.join(c.name for c in self.failed_checks)}; no interval is given",
                     "try: " + short("; ".join(self.advice), 200)]
        return block(head, self.success, self.message, items, notes, passed="checks passed")


def _check_request(data, names, measured, guess):
    if not names:
        raise not_allowed("params", "(none)", f"name at least one of {', '.join(GREYBOX_PARAMS)}")
    for n in names:
        if n not in GREYBOX_PARAMS:
            raise not_allowed("params", ",".join(names), f"{n} cannot be estimated; use {', '.join(GREYBOX_PARAMS)}")
    if len(set(names)) != len(names):
        raise not_allowed("params", ",".join(names), "name each parameter once")
    if not measured:
        raise not_allowed("measured", "(none)", f"name at least one of {', '.join(GREYBOX_SIGNALS)}")
    for s in measured:
        if s not in GREYBOX_SIGNALS:
            raise not_allowed("measured", ",".join(measured), f"{s} is not a signal; use {', '.join(GREYBOX_SIGNALS)}")
        if s not in data.signals:
            raise not_allowed("measured", ",".join(measured), f"the record has no {s}; it has "
                                                             f"{', '.join(data.signals) or 'no signal'}")
    n_data = data.t.size * len(measured)
    if n_data < 10 * len(names):
        raise not_allowed("record", f"{data.t.size} samples", f"too short for {len(names)} parameters: give at least "
                                                              f"{math.ceil(10 * len(names) / len(measured))} samples")
    for n in names:
        if n not in LINEAR_SCALE and not param_value(guess, n) > 0:
            raise not_allowed(n, param_value(guess, n), "the initial guess of a positive parameter must be > 0")


def identify_greybox(data: GreyBoxData, params=("M", "B", "Af", "beta_e"), *, measured=None,
                     guess: ActuatorParams | None = None, shooting: str = "auto", segments: int | None = None,
                     max_nfev: int = 60, hold_unidentifiable: bool = True,
                     cancel: CancelToken | None = None, progress=None) -> GreyBoxResult:
    """Estimate ``params`` of the nonlinear model from ``data`` (output error; see the module).

    Parameters
    ----------
    data : GreyBoxData
        The record.
    params : iterable of str
        The parameters estimated, of :data:`GREYBOX_PARAMS`.
    measured : iterable of str, optional
        The signals compared; default every signal of the record.
    guess : ActuatorParams, optional
        The initial values and the values of everything not estimated; default the paper's.
    shooting : {'auto', 'single', 'multiple'}
        ``"auto"`` (default): single shooting over a growing start of the record (1 s, 3 s, ...,
        each fit starting where the last ended), then over all of it; when that estimate fails its
        checks, multiple shooting from the guess too, and the better of the two. ``"single"``:
        single shooting over the whole record from the guess. ``"multiple"``: first multiple
        shooting over ``segments`` pieces of the record, then output error from where it ended
        (the estimate and its statistics are output error's).
    segments : int, optional
        Pieces of multiple shooting, at least 2 and 20 samples each; default one per second.
    max_nfev : int
        Most model evaluations of each fit (:func:`scipy.optimize.least_squares`'s ``max_nfev``).
    hold_unidentifiable : bool
        Hold at the guess the parameters the data do not determine there (:func:`identifiability`),
        and say so in the result; False estimates them all.
    cancel : eha_core.cancel.CancelToken, optional
        Checked before every simulation of the model; raises :class:`~eha_core.cancel.Cancelled` when set.
    progress : callable, optional
        ``progress(text)`` at each stage of the estimate (what it is doing now, in words).
    """
    t_start = time.perf_counter()
    names = tuple(params)
    measured = tuple(measured) if measured is not None else tuple(s for s in GREYBOX_SIGNALS if s in data.signals)
    guess = guess if guess is not None else ActuatorParams()
    _check_request(data, names, measured, guess)
    if shooting not in SHOOTING:
        raise not_allowed("shooting", shooting, f"use {', '.join(SHOOTING)}")
    tell = progress if progress is not None else (lambda _text: None)
    read, read_why = read_intersample(data)
    unread = data
    data = replace(data, intersample=read or "foh")
    rows = [_SIGNAL_INDEX[s] for s in measured]
    y_meas = np.stack([data.signals[s] for s in measured], axis=1)
    scatter = np.array([noise_guess(data.signals[s]) for s in measured])
    sigma = np.maximum(scatter, 1e-9 * (np.std(y_meas, axis=0) + 1e-30))
    tell("which parameters the record determines at the initial guess")
    held, sentences = _held_at_guess(data, names, guess, rows, sigma, hold_unidentifiable, cancel)
    first_sentences = list(sentences)
    free = tuple(n for n in names if n not in held)
    if not free:
        raise ComputationError("the data determine none of the parameters asked: "
                               + "; ".join(s for _, s in sentences))
    if read is None:
        data, read_why = _intersample_by_fit(unread, free, guess, rows, y_meas, sigma, max_nfev, cancel, read_why,
                                             tell)
    setup = _Setup(free, tuple(n not in LINEAR_SCALE for n in free), guess, data)
    problem = _Problem(setup, data, measured, rows, y_meas, sigma, scatter, max_nfev, cancel)
    tries, steps = [], []
    if shooting != "multiple":
        z0, nfev0 = setup.clip(setup.z_of(guess)), 0
        if shooting == "auto":
            z0, nfev0, grown = _grow(problem, z0, tell)
            steps.append(f"single shooting over the first {grown} of the record, then all of it" if grown else
                         "single shooting")
        else:
            steps.append("single shooting")
        tell("single shooting over the whole record")
        tries.append(_attempt(problem, z0, nfev0, steps[-1], held))
    if held and shooting == "auto" and not tries[-1].passed:
        # held at the guess, where the record hardly moves with it, a parameter may still be determined
        # nearer the truth; held at a wrong value it biases the rest: estimated with them, the fit may pass
        freed, held = held, ()
        setup = _Setup(names, tuple(n not in LINEAR_SCALE for n in names), guess, data)
        problem = _Problem(setup, data, measured, rows, y_meas, sigma, scatter, max_nfev, cancel)
        tell(f"the checks failed with {', '.join(freed)} held: estimating {'it' if len(freed) == 1 else 'them'} too")
        z0, nfev0, grown = _grow(problem, setup.clip(setup.z_of(guess)), tell)
        tries.append(_attempt(problem, z0, nfev0, f"{', '.join(freed)} estimated too (held at the guess, the fit "
                                                  "failed its checks)", held))
        sentences = [((n,), f"{n} was not determined at the initial guess, but held there the fit failed its checks: "
                            "it is estimated with the rest") for n in freed]
    if shooting == "multiple" or (shooting == "auto" and not tries[-1].passed):
        if tries:
            tell("the checks failed: multiple shooting from the initial guess")
        n_seg = segments if segments is not None else max(2, min(round(float(data.t[-1] - data.t[0])),
                                                                  data.t.size // 20))
        if not (isinstance(n_seg, int) and 2 <= n_seg <= data.t.size // 20):
            raise not_allowed("segments", n_seg, f"a whole number in [2, {data.t.size // 20}] (20 samples each)")
        z_ms, ms_nfev = _multiple_shooting(setup, data, measured, rows, y_meas, sigma, n_seg, max_nfev, cancel)
        steps.append(f"multiple shooting over {n_seg} segments, then single shooting from its end")
        tries.append(_attempt(problem, setup.clip(z_ms), ms_nfev, steps[-1], held))
    best = min(tries, key=lambda a: (not a.passed, a.cost))
    tell("the estimate's statistics")
    if best.held != held:
        sentences = list(first_sentences)
    res = _result(best.problem, best, names, best.held, guess, sentences, tries, time.perf_counter() - t_start)
    res.extras["intersample"] = {"used": best.problem.data.intersample, "how": read_why}
    return replace(res, data=best.problem.data)


def _intersample_by_fit(data, free, guess, rows, y_meas, sigma, max_nfev, cancel, why, tell):
    """The record with the intersample behaviour that explains its first seconds better: the samples do
    not say how u moved between them, and a held command read as linear biases B by tens of per cent.
    Both are fitted over the first :data:`_GROW_FIRST_S` s (the whole record when shorter) from the
    guess; the lower cost wins. Returns the record and the sentence that says how it was read."""
    n = min(data.t.size - 1, int(round(_GROW_FIRST_S / data.ts)))
    costs = {}
    for how in ("foh", "zoh"):
        tell(f"u {'linear' if how == 'foh' else 'held'} between samples: how well it explains the record")
        part = _segment(replace(data, intersample=how), 0, n)
        setup = _Setup(free, tuple(f not in LINEAR_SCALE for f in free), guess, part)
        z, _, _, _, _, out, _ = _fit(setup, part, rows, y_meas[:n + 1], sigma, max_nfev, cancel, repeat=False)
        costs[how] = float(np.sum(((y_meas[:n + 1] - out[:, rows]) / sigma) ** 2))
    how = min(costs, key=costs.get)
    other = "zoh" if how == "foh" else "foh"
    words = {"foh": "linear", "zoh": "held"}
    return replace(data, intersample=how), (f"{why}: u taken as {words[how]} between samples, which explains the "
                                            f"first {n * data.ts:g} s better (cost {costs[how]:.6g} against "
                                            f"{costs[other]:.6g} with u {words[other]})")


#: The fitting strategies: ``auto`` (single shooting over a growing record, multiple shooting when its
#: checks fail), ``single`` (single shooting over the whole record from the guess), ``multiple``.
SHOOTING = ("auto", "single", "multiple")
#: The growing record of ``auto``: its first piece [s], each next one this many times longer.
_GROW_FIRST_S, _GROW_FACTOR = 1.0, 3.0
#: The tolerance (scipy's ``xtol``, ``ftol``) of the growing record's pieces before the whole record's.
_GROW_TOL = 1e-4


@dataclass(frozen=True)
class _Problem:
    """What every fit of one estimate shares: the parameters, the record and the weights."""
    setup: _Setup
    data: GreyBoxData
    measured: tuple
    rows: list
    y_meas: np.ndarray
    sigma: np.ndarray            # the first weights: each signal's noise from the record's scatter
    scatter: np.ndarray          # that scatter itself (before the floor of sigma)
    max_nfev: int
    cancel: object


@dataclass(frozen=True)
class _Attempt:
    """One way to the estimate and where it ended: the scaled estimate, the weights the fit ended with,
    the simulation and sensitivities there, the checks and the cost in the first weights (which
    compares attempts)."""
    z: np.ndarray
    sigma: np.ndarray
    optimiser_success: bool
    optimiser_message: str
    nfev: int
    njev: int
    out: np.ndarray
    sout: np.ndarray
    checks: tuple
    cost: float
    how: str
    problem: _Problem
    held: tuple

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)


def _grow(problem: _Problem, z: np.ndarray, tell) -> tuple[np.ndarray, int, str]:
    """Single shooting over a growing start of the record (1 s, 3 s, 9 s, ...), each piece's estimate the
    next one's start: a short record's cost has a wide basin (a wrong parameter has not yet had time to
    drift the simulation a whole cycle away from the data), and each longer one starts near its
    minimum. Returns the scaled estimate, the simulations spent and the lengths fitted (text)."""
    data = problem.data
    span = float(data.t[-1] - data.t[0])
    nfev, lengths = 0, []
    length = _GROW_FIRST_S
    while length * 1.5 < span:
        n = int(round(length / data.ts))
        part = _segment(data, 0, n)
        tell(f"single shooting over the first {length:g} s of {span:g} s")
        setup = _Setup(problem.setup.names, problem.setup.log, problem.setup.base, part)
        # a piece's estimate is only the next one's start: to a few parts in 10^4 (the whole record's fit
        # ends at the same minimum from there, in as many steps as from the exact one)
        z, _, sol, used, _, _, _ = _fit(setup, part, problem.rows, problem.y_meas[:n + 1], problem.sigma,
                                        problem.max_nfev, problem.cancel, start=z, repeat=False, tol=_GROW_TOL)
        nfev += used
        lengths.append(f"{length:g} s")
        length *= _GROW_FACTOR
    return z, nfev, ", ".join(lengths)


def _attempt(problem: _Problem, z0: np.ndarray, nfev0: int, how: str, held: tuple) -> _Attempt:
    """The fit over the whole record from ``z0`` and its checks."""
    from . import _greybox_checks as C

    p = problem
    z, sigma, sol, nfev, njev, out, sout = _fit(p.setup, p.data, p.rows, p.y_meas, p.sigma, p.max_nfev, p.cancel,
                                                start=z0)
    resid = p.y_meas - out[:, p.rows]
    cost = float(np.sum((resid / p.sigma) ** 2))
    stated = p.data.noise is not None and all(s in p.data.noise for s in p.measured)
    reference = {s: (p.data.noise[s] if stated else float(p.scatter[k])) for k, s in enumerate(p.measured)}
    got = {s: float(np.sqrt(np.mean(resid[:, k] ** 2))) for k, s in enumerate(p.measured)}
    spans = {s: float(np.ptp(p.y_meas[:, k])) for k, s in enumerate(p.measured)}
    lower, upper = p.setup.bounds
    est = p.setup.params_at(z)
    values = {n: param_value(est, n) for n in p.setup.names}
    J = _weighted_jacobian(sout, p.rows, sigma)
    at_bound = C.bounds_check(p.setup.names, z, lower, upper, values, _in_units)
    inner = [j for j, n in enumerate(p.setup.names) if n not in at_bound.about]
    checks = (
        C.FitCheck("optimiser", bool(sol.success), "the optimiser converged" if sol.success else
                   f"the optimiser did not converge: {sol.message}"),
        C.noise_check(got, reference, stated, spans, _in_units),
        C.whiteness_check({s: resid[:, k] for k, s in enumerate(p.measured)}, spans),
        at_bound,
        C.rank_check(J[:, inner], [p.setup.names[j] for j in inner]) if inner else
        C.FitCheck("rank", True, "every estimate is at a bound"),
    )
    return _Attempt(z, sigma, bool(sol.success), str(sol.message), nfev + nfev0, njev, out, sout, checks, cost, how,
                    problem, tuple(held))


def _in_units(name: str, value: float) -> str:
    """``value`` (SI) of a signal or parameter in the unit a user reads it in."""
    from ..param_table import FIELD_INFO

    signal_units = {"x": ("mm", 1e-3), "v": ("mm/s", 1e-3), "p1": ("MPa", 1e6), "p2": ("MPa", 1e6)}
    if name in signal_units:
        unit, scale = signal_units[name]
    elif name in FIELD_INFO:
        unit, scale = FIELD_INFO[name].display_unit, FIELD_INFO[name].display_scale
    else:
        return f"{value:.3g}"
    return f"{value / scale:.3g} {unit}"


def _result(problem: _Problem, best: _Attempt, names, held, guess, sentences, tries, time_s) -> GreyBoxResult:
    """The result of the attempt ``best``: statistics where its checks passed, and what happened."""
    from . import _greybox_checks as C
    from .assessment import assess_residuals
    from .validate import residual_analysis

    p, setup, data = problem, problem.setup, problem.data
    est_params = setup.params_at(best.z)
    J = _weighted_jacobian(best.sout, p.rows, best.sigma)
    estimates, std_errors, ci95, corr = _statistics(J, setup, est_params, names, held, guess)
    unbounded = [n for n in setup.names if not all(math.isfinite(c) for c in ci95[n])]
    fit = {}
    for k, s in enumerate(p.measured):
        y, yh = p.y_meas[:, k], best.out[:, p.rows[k]]
        denom = np.linalg.norm(y - y.mean())
        fit[s] = float(100.0 * (1.0 - np.linalg.norm(y - yh) / denom)) if denom > 0 else math.nan
    e = p.y_meas[:, 0] - best.out[:, p.rows[0]]
    assessment = assess_residuals(residual_analysis(e, data.u if data.u is not None else data.r,
                                                    max_lag=min(25, e.size - 1)), remedy=GREYBOX_REMEDY)
    at_bound = next(c for c in best.checks if c.name == "bounds").about
    inner = [j for j, n in enumerate(setup.names) if n not in at_bound]
    after = (identifiability(J[:, inner], [setup.names[j] for j in inner], **_context(best.out, data, est_params))
             if inner and np.all(np.isfinite(J)) else [])
    bound_sentences = [((n,), f"{n} ended at a bound of its range: the fit pushed it there (see the checks)")
                       for n in at_bound]
    success = best.passed and not unbounded
    checks = best.checks
    if unbounded and best.passed:
        who = ", ".join(unbounded)
        checks = checks + (C.FitCheck("rank", False, f"the data do not determine {who} at the estimate: the simulated "
                                      f"signals hardly move with {'it' if len(unbounded) == 1 else 'them'} there, so "
                                      "no interval can be given", tuple(unbounded)),)
    bias = {}
    if held:
        bias = _held_bias(problem, est_params, held, J, best.sigma, estimates)
    failed = [c for c in checks if not c.passed]
    what_to_try = C.advice(checks, shooting_tried=any("multiple" in a.how for a in tries), measured=p.measured,
                           names=names)
    message = ("the estimate passed its checks: the optimiser converged, the residuals are the sensors' noise and "
               "white, no estimate is at a bound, the Jacobian has full rank" if success else
               "the estimate may be wrong: " + "; ".join(c.says for c in failed) + ". Try: " + "; ".join(what_to_try))
    extras = {"optimiser_success": best.optimiser_success, "optimiser_message": best.optimiser_message,
              "attempts": [{"how": a.how, "passed": a.passed, "cost": a.cost, "nfev": a.nfev} for a in tries]}
    if not success:
        # the intervals of a fit whose own checks failed describe a minimum that may not be the answer:
        # kept for who wants to look, never shown as intervals
        extras["ci95_unchecked"] = dict(ci95)
        extras["std_errors_unchecked"] = dict(std_errors)
        ci95 = {n: (math.nan, math.nan) for n in names}
        std_errors = {n: math.nan for n in names}
        corr = np.full_like(corr, np.nan)
    return GreyBoxResult(
        names=names, estimates=estimates, std_errors=std_errors, ci95=ci95, correlation=corr, fit=fit,
        noise_std={s: float(best.sigma[k]) for k, s in enumerate(p.measured)}, params=est_params,
        simulated=best.out, assessment=assessment,
        identifiability=tuple(sentences) + tuple(after) + tuple(bound_sentences), held=held,
        nfev=sum(a.nfev for a in tries), iterations=sum(a.njev for a in tries), time_s=time_s, success=success,
        message=message, measured=p.measured, extras=extras, checks=checks, advice=what_to_try,
        strategy="; then ".join(a.how for a in tries), held_bias=bias)


def _held_bias(problem: _Problem, est_params, held, J_free, sigma, estimates) -> dict:
    """How each held parameter, if 10 % off, moves the estimates (one more simulation, at the estimate,
    with the held parameters' sensitivities)."""
    from . import _greybox_checks as C

    setup = problem.setup
    log_held = [h for h in held if h not in LINEAR_SCALE]
    if not log_held:
        return {}
    try:
        _, s_held = simulate_with_sensitivities(est_params, log_held, problem.data, cancel=problem.cancel)
    except ComputationError:
        return {}
    J_held = _weighted_jacobian(s_held, problem.rows, sigma)
    scale = [None if lg else LINEAR_SCALE[n] for n, lg in zip(setup.names, setup.log, strict=True)]
    return C.held_bias(J_free, J_held, setup.names, log_held, scale, estimates)


#: What the residual tests advise when a grey-box model's residuals follow the input.
GREYBOX_REMEDY = ("a local minimum (try multiple shooting or another start), a parameter held at a wrong value, or "
                  "physics the model lacks (a load it does not know, another intersample behaviour)")


def _context(states, data, params) -> dict:
    """What the identifiability sentences say why with: the record's largest |v| (the model's), k_f, and
    whether pressures are measured."""
    return {"v_max": float(np.max(np.abs(states[:, 1]))), "k_f": params.k_f,
            "pressures": bool({"p1", "p2"} & set(data.signals))}


def _held_at_guess(data, names, guess, rows, sigma, hold, cancel):
    """The parameters the data do not determine at the initial guess (held there) and why."""
    log = tuple(n not in LINEAR_SCALE for n in names)
    try:
        out0, s0 = simulate_with_sensitivities(guess, names, data, log=log, cancel=cancel)
    except ComputationError as exc:
        raise ComputationError(f"the model cannot be simulated at the initial guess: {exc}") from None
    found = identifiability(_weighted_jacobian(s0, rows, sigma), names, **_context(out0, data, guess))
    if not found:
        return (), []
    if not hold:            # estimated anyway, as asked: the result still says what the guess showed
        return (), [(who, f"at the initial guess {text}") for who, text in found]
    return tuple(dict.fromkeys(who[-1] for who, _ in found)), found


def _fit(setup, data, rows, y_meas, sigma, max_nfev, cancel, *, start=None, repeat=True, tol=1e-8):
    """A trust-region Gauss-Newton fit within the physical ranges (scipy's ``trf`` with bounds) with the
    sensitivities' Jacobian, from ``start`` (default the setup's guess); with ``repeat``, the noise σ
    re-estimated from the residuals and the fit repeated once if they moved by more than 20 %. ``tol``:
    scipy's ``xtol`` and ``ftol`` (a looser one where the fit only gives the next one its start)."""
    from scipy.optimize import least_squares

    cache = {}

    def model(z, sensitivities):
        """The states and their sensitivities (Levenberg-Marquardt asks the Jacobian at nearly every
        point it evaluates: computing both at once is cheaper than the states alone, then again)."""
        sensitivities = True
        key = (z.tobytes(), sensitivities)
        full = (z.tobytes(), True)
        if full in cache:
            return cache[full]
        if key not in cache:
            if len(cache) > 4:
                cache.clear()
            check(cancel)
            try:
                cache[key] = simulate_with_sensitivities(setup.params_at(z), setup.names if sensitivities else (),
                                                         data, log=setup.log if sensitivities else (), cancel=cancel)
            except (ComputationError, ValueError, ArithmeticError):   # a step to exp(huge) is a failed simulation
                cache[key] = (None, None)
        return cache[key]

    def fun(z, sigma):
        out, _ = model(z, False)
        return np.full(y_meas.size, 1e6) if out is None else ((out[:, rows] - y_meas) / sigma).ravel()

    def jac(z, sigma):
        out, sout = model(z, True)
        return np.zeros((y_meas.size, len(setup.names))) if out is None else _weighted_jacobian(sout, rows, sigma)

    z = setup.clip(setup.z_of(setup.base) if start is None else start)
    bounds = setup.bounds
    nfev = njev = 0
    for _ in range(2 if repeat else 1):
        with np.errstate(over="ignore", invalid="ignore"):    # a trial step far off: its cost is inf, refused
            sol = least_squares(fun, z, jac=jac, args=(sigma,), method=_METHOD,
                                bounds=bounds if _METHOD != "lm" else (-np.inf, np.inf), max_nfev=max_nfev,
                                xtol=tol, ftol=tol)
        z, nfev, njev = sol.x, nfev + sol.nfev, njev + (sol.njev or 0)
        if _METHOD == "lm":
            z = setup.clip(z)
        out, _ = model(z, False)
        if out is None or not repeat:
            break
        new_sigma = np.maximum(np.sqrt(np.mean((out[:, rows] - y_meas) ** 2, axis=0)),
                               1e-12 * (np.std(y_meas, axis=0) + 1e-30))
        changed = np.max(np.abs(np.log(new_sigma / sigma))) > math.log(1.2)
        sigma = new_sigma
        if not changed:
            break
    out, sout = model(z, True)
    if out is None:
        # where the optimiser ended the model does not simulate (it ran to a corner no actuator has): the
        # attempt ends where it started, said not converged, and its checks say the rest
        from types import SimpleNamespace

        z = setup.clip(setup.z_of(setup.base) if start is None else start)
        out, sout = model(z, True)
        if out is None:
            raise ComputationError("the model cannot be simulated at the start of the fit")
        sol = SimpleNamespace(success=False, message="the model could not be simulated where the optimiser ended",
                              x=z, nfev=sol.nfev, njev=sol.njev)
    return z, sigma, sol, nfev, njev, out, sout


_METHOD = "trf"


def _segment(data: GreyBoxData, a: int, b: int) -> GreyBoxData:
    """Samples ``a..b`` (both included) of a record."""
    def cut(x):
        return None if x is None else np.asarray(x)[a:b + 1]
    return GreyBoxData(t=data.t[a:b + 1], u=cut(data.u), r=cut(data.r), kp=data.kp, d=cut(data.d),
                       signals={k: v[a:b + 1] for k, v in data.signals.items()}, intersample=data.intersample,
                       source=data.source, noise=data.noise)


def _shooting_start(setup, data, bounds, measured, cancel) -> np.ndarray:
    """Each later segment's initial state: the measured signals where they are measured (velocity from
    the measured position's slope without a velocity sensor), the initial guess's simulation elsewhere."""
    guess_run, _ = simulate_with_sensitivities(setup.base, (), data, cancel=cancel)
    starts = []
    for a in bounds[1:-1]:
        y = guess_run[a].copy()
        for k, name in enumerate(GREYBOX_SIGNALS):
            if name in measured:
                y[k] = data.signals[name][a]
        if "v" not in measured and "x" in measured:
            lo, hi = max(a - 5, 0), min(a + 5, data.t.size - 1)
            y[1] = (data.signals["x"][hi] - data.signals["x"][lo]) / (data.t[hi] - data.t[lo])
        starts.append(y / STATE_SCALE)
    return np.concatenate(starts) if starts else np.zeros(0)


def _shooting_jacobian(runs, bounds, rows, sigma, weight, P, n_rows, n_free) -> np.ndarray:
    """Multiple shooting's Jacobian: each segment's residuals against the parameters and its own initial
    state; each continuity defect against the parameters, the segment's initial state and the next's."""
    segments = len(runs)
    J = np.zeros((n_rows, n_free))
    r0 = 0
    for i, (_, sout) in enumerate(runs):
        a, b = bounds[i], bounds[i + 1] + (1 if i == segments - 1 else 0)
        block = (sout[:b - a][:, rows, :] / sigma[None, :, None]).reshape(-1, sout.shape[2])
        J[r0:r0 + block.shape[0], :P] = block[:, :P]
        if i > 0:
            J[r0:r0 + block.shape[0], P + 4 * (i - 1):P + 4 * i] = block[:, P:]
        r0 += block.shape[0]
    for i in range(segments - 1):
        end = runs[i][1][-1] / STATE_SCALE[:, None] * weight[:, None]         # 4 x (P [+ 4])
        J[r0:r0 + 4, :P] = end[:, :P]
        if i > 0:
            J[r0:r0 + 4, P + 4 * (i - 1):P + 4 * i] = end[:, P:]
        J[r0:r0 + 4, P + 4 * i:P + 4 * i + 4] = -np.diag(weight)
        r0 += 4
    return J


def _multiple_shooting(setup, data, measured, rows, y_meas, sigma, segments, max_nfev, cancel):
    """The parameters by multiple shooting: the record cut into ``segments``, each simulated from an
    initial state of its own (estimated with the parameters), the segments joined by continuity
    (a defect costs as much as a residual of a tenth of the state's noise, or of 1e-4 of its scale
    when it is not measured). A wrong initial guess then leaves each segment near its data instead of
    drifting off over the whole record: the basin is wider. Returns the parameters (scaled)."""
    from scipy.optimize import least_squares

    n = data.t.size
    bounds = [round(i * (n - 1) / segments) for i in range(segments + 1)]
    parts = [_segment(data, bounds[i], bounds[i + 1]) for i in range(segments)]
    P = len(setup.names)
    state_sigma = np.array([sigma[measured.index(s)] if s in measured else 1e-4 * STATE_SCALE[k]
                            for k, s in enumerate(GREYBOX_SIGNALS)])
    weight = STATE_SCALE / (0.1 * state_sigma)          # per scaled unit of defect
    cache = {}

    def run(w):
        key = w.tobytes()
        if key not in cache:
            cache.clear()
            check(cancel)
            runs = []
            try:
                p = setup.params_at(w[:P])
                for i, part in enumerate(parts):
                    start = None if i == 0 else w[P + 4 * (i - 1):P + 4 * i] * STATE_SCALE
                    runs.append(simulate_with_sensitivities(p, setup.names, part, log=setup.log, initial=start,
                                                            cancel=cancel))
            except (ComputationError, ValueError, ArithmeticError):   # a step to exp(huge) is a failed simulation
                runs = None
            cache[key] = runs
        return cache[key]

    n_free = P + 4 * (segments - 1)
    n_rows = y_meas.size + 4 * (segments - 1)

    def fun(w):
        runs = run(w)
        if runs is None:
            return np.full(n_rows, 1e6)
        res = []
        for i, (out, _) in enumerate(runs):
            a, b = bounds[i], bounds[i + 1] + (1 if i == segments - 1 else 0)
            res.append(((out[:b - a, rows] - y_meas[a:b]) / sigma).ravel())
        for i in range(segments - 1):
            end = runs[i][0][-1]
            res.append((end / STATE_SCALE - w[P + 4 * i:P + 4 * i + 4]) * weight)
        return np.concatenate(res)

    def jac(w):
        runs = run(w)
        return (np.zeros((n_rows, n_free)) if runs is None else
                _shooting_jacobian(runs, bounds, rows, sigma, weight, P, n_rows, n_free))

    w0 = np.concatenate([setup.clip(setup.z_of(setup.base)), _shooting_start(setup, data, bounds, measured, cancel)])
    if max_nfev == 0:                       # the problem itself, for a check of its Jacobian
        return fun, jac, w0
    lo, hi = setup.bounds             # the parameters within their physical ranges, the states free
    free_states = np.full(w0.size - P, np.inf)
    with np.errstate(over="ignore", invalid="ignore"):
        sol = least_squares(fun, w0, jac=jac, method="trf", bounds=(np.concatenate([lo, -free_states]),
                                                                      np.concatenate([hi, free_states])),
                            max_nfev=max_nfev, xtol=1e-8, ftol=1e-8)
    return sol.x[:P], sol.nfev


def _statistics(J, setup, est_params, names, held, guess):
    """Estimates, standard errors, 95 % intervals (a positive parameter's from its logarithm's: never
    below 0) and the correlation matrix, from the inverse Fisher information ``(J^T J)^-1``.

    A parameter the data do not fix at the estimate (its signals do not move with it there: a
    record in other units than SI drives the fit to such places) has an unbounded interval, (0, inf)
    or (-inf, inf), and an infinite standard error, not the 0 a pseudo-inverse gives it; an interval
    wider than a float reaches ends at inf rather than raising OverflowError."""
    cov_z, se_z = _inverse_fisher(J)
    estimates, std_errors, ci95 = {}, {}, {}
    for j, (n, lg) in enumerate(zip(setup.names, setup.log, strict=True)):
        value = param_value(est_params, n)
        estimates[n] = value
        if lg:
            std_errors[n] = value * se_z[j]
            ci95[n] = (value * _exp_or_inf(-Z95 * se_z[j]), value * _exp_or_inf(Z95 * se_z[j]))
        else:
            std_errors[n] = LINEAR_SCALE[n] * se_z[j]
            ci95[n] = (value - Z95 * std_errors[n], value + Z95 * std_errors[n])
    for n in held:
        estimates[n], std_errors[n], ci95[n] = param_value(guess, n), math.nan, (math.nan, math.nan)
    d = np.sqrt(np.clip(np.diag(cov_z), 1e-300, None))
    corr_free = cov_z / np.outer(d, d)
    unbounded = ~np.isfinite(se_z)
    corr_free[unbounded, :] = corr_free[:, unbounded] = np.nan
    corr = np.full((len(names), len(names)), np.nan)
    for a, na in enumerate(setup.names):
        for b, nb in enumerate(setup.names):
            corr[names.index(na), names.index(nb)] = corr_free[a, b]
    return estimates, std_errors, ci95, corr


def _inverse_fisher(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(J^T J)^-1`` (as ``np.linalg.pinv`` of it: the directions it keeps, the same numbers) and the
    standard errors, infinite for a parameter with a share of a direction pinv drops (a singular
    value of J below 3e-8 of the largest: more than 3e7 times less determined than the best, 0 for
    a parameter that does not move the signals at all), or for all when J is not finite."""
    P = J.shape[1]
    if not np.all(np.isfinite(J)):
        return np.full((P, P), np.nan), np.full(P, np.inf)
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    eig = s**2                                     # J^T J's eigenvalues; pinv drops those below 1e-15 of the top
    kept = eig > 1e-15 * eig[0] if eig.size and eig[0] > 0 else np.zeros(eig.size, dtype=bool)
    v_kept = vt[kept].T / s[kept]
    cov_z = v_kept @ v_kept.T
    se_z = np.sqrt(np.clip(np.diag(cov_z), 0, None))
    unfixed = np.any(np.abs(vt[~kept]) >= _UNFIXED_SHARE, axis=0) if (~kept).any() else np.zeros(P, dtype=bool)
    se_z[unfixed] = np.inf
    return cov_z, se_z


def _exp_or_inf(x: float) -> float:
    """``math.exp(x)``, inf beyond the floats (where math.exp raises OverflowError)."""
    return math.inf if x > _LOG_FLOAT_MAX else math.exp(x)


def _weighted_jacobian(sout: np.ndarray, rows, sigma: np.ndarray) -> np.ndarray:
    """(N·S x P): the sensitivities of the measured signals, each divided by its noise σ, in the
    residuals' order (sample by sample, the signals of a sample together)."""
    sel = sout[:, rows, :] / sigma[None, :, None]
    return sel.reshape(-1, sout.shape[2])
