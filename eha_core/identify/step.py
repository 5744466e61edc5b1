"""Step responses of transfer functions and of the nonlinear closed loop, with their figures.

The figures (rise time 10-90 %, settling time 2 %, overshoot, undershoot,
peak, peak time, steady-state value) follow ``control.step_info`` of
python-control exactly, sample by sample, so that a student who checks them
there gets the same numbers:

* the steady-state value is the DC gain of a transfer function, or the last
  sample of a simulated response;
* the rise time is the time between the first samples at or beyond 10 % and
  90 % of it;
* the settling time is the time of the first sample after the last one
  outside the 2 % band around it (NaN when the last sample is outside);
* the overshoot is the peak beyond it in percent of it, the undershoot the
  largest excursion to the opposite side in percent, the peak the largest
  ``|y|`` and the peak time its first instant.

No interpolation between samples: a figure is as fine as the time grid.

A transfer function's step response is computed exactly at the samples (a
step is constant between samples, so the zero-order-hold discretisation of
:func:`eha_core.identify.validate.simulate_tf` is exact). The nonlinear
plant's is simulated in the closed loop of the paper's frequency experiment
(eq. 22: ``u = Kp (r - x)``, sampled every ``ts`` and held, the nonlinear
model of eqs. 1-4) with :func:`eha_core.simulate.simulate_closed_loop`, for a
reference step of ``amplitude_m`` metres. The identified ``H(s)`` of that
experiment and the linearised one of eq. 24 map ``r`` to ``x``, so their
responses, scaled by the amplitude, are comparable with it in metres; the
figures are computed on the responses normalised by the amplitude (a unit
step), so peak, steady-state value, ``settling_min`` and ``settling_max`` are
per metre of step.

Only numpy and scipy are imported at module import; python-control is not
needed (the tests compare with it); the simulator (numba) is imported when
the nonlinear plant is simulated.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .._checks import not_allowed, positive_number
from ._ctmodels import as_tf, readonly, simulate_tf

__all__ = [
    "StepComparison",
    "StepInfo",
    "StepResponse",
    "default_step_horizon",
    "nonlinear_step_response",
    "step_comparison",
    "step_info",
    "step_response",
]

#: ``control.step_info``'s defaults: 2 % settling band, 10-90 % rise.
SETTLING_THRESHOLD = 0.02
RISE_LIMITS = (0.1, 0.9)
#: Bounds of the automatic horizon [s]: a near-integrator (the paper's eq. 25
#: has a pole at -2e-10 rad/s) would otherwise ask for centuries.
MIN_HORIZON_S, MAX_HORIZON_S = 1.0, 120.0


# ---------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class StepInfo:
    """Step-response figures, as ``control.step_info`` defines them.

    Times in seconds; ``overshoot_percent`` and ``undershoot_percent`` in
    percent of the steady-state value; ``peak``, ``steady_state``,
    ``settling_min`` and ``settling_max`` in the units of the response the
    figures were computed on (per unit of step for :class:`StepResponse`).
    NaN (``peak``/``peak_time_s``: inf) where a figure is undefined, e.g.
    for an infinite DC gain (an integrator).
    """

    rise_time_s: float
    settling_time_s: float
    settling_min: float
    settling_max: float
    overshoot_percent: float
    undershoot_percent: float
    peak: float
    peak_time_s: float
    steady_state: float

    #: python-control's key for each field.
    CONTROL_KEYS = {"rise_time_s": "RiseTime", "settling_time_s": "SettlingTime", "settling_min": "SettlingMin",
                    "settling_max": "SettlingMax", "overshoot_percent": "Overshoot",
                    "undershoot_percent": "Undershoot", "peak": "Peak", "peak_time_s": "PeakTime",
                    "steady_state": "SteadyStateValue"}

    def to_dict(self) -> dict[str, float]:
        """The figures by field name (JSON-ready)."""
        return {name: float(getattr(self, name)) for name in self.CONTROL_KEYS}

    def to_control_dict(self) -> dict[str, float]:
        """The figures under ``control.step_info``'s keys."""
        return {key: float(getattr(self, name)) for name, key in self.CONTROL_KEYS.items()}


@dataclass(frozen=True, eq=False)
class StepResponse:
    """One model's response to a step of ``amplitude`` (reference units, m).

    Attributes
    ----------
    name : str
    t : numpy.ndarray
        Time [s], from 0.
    y : numpy.ndarray
        Response to the step of ``amplitude`` (for the nonlinear plant: the
        position's change from its initial value), in metres.
    amplitude : float
    info : StepInfo
        Figures of ``y / amplitude`` (a unit step).
    source : str
        ``"transfer function"`` or ``"nonlinear simulation"``.
    message : str
        What to know about the response (e.g. why a figure is undefined);
        ``"ok"`` otherwise.
    """

    name: str
    t: np.ndarray
    y: np.ndarray
    amplitude: float
    info: StepInfo
    source: str
    message: str = "ok"


@dataclass(frozen=True, eq=False)
class StepComparison:
    """Step responses of several models on one time grid, in metres.

    ``responses`` in the order given (the nonlinear plant last when it was
    simulated); ``response(name)`` (or ``comparison[name]``) finds one.
    """

    t: np.ndarray
    amplitude: float
    responses: tuple[StepResponse, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.responses)

    def response(self, name: str) -> StepResponse:
        """The response of the model called ``name``; a refusal naming the others when there is none."""
        for r in self.responses:
            if r.name == name:
                return r
        raise not_allowed("name", name, f"use one of {', '.join(self.names)}")

    __getitem__ = response

    def to_dict(self) -> dict:
        """The figures per model (JSON-ready)."""
        return {"amplitude_m": self.amplitude, "figures": {r.name: r.info.to_dict() for r in self.responses}}


# ---------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------
def _nan_info() -> StepInfo:
    nan = float("nan")
    return StepInfo(nan, nan, nan, nan, nan, nan, float("inf"), float("inf"), nan)


def step_info(t, y, steady_state=None, *, settling_threshold=SETTLING_THRESHOLD,
              rise_limits=RISE_LIMITS) -> StepInfo:
    """Figures of a sampled step response, with ``control.step_info``'s definitions.

    Parameters
    ----------
    t, y : array_like, shape (N,)
        Times [s] and the response to a unit step (or any step: the
        percentages are relative, the levels in ``y``'s units).
    steady_state : float, optional
        The final value; default: the last sample (as ``control.step_info``
        for response data). A transfer function's is its DC gain.
    settling_threshold : float
        Half-width of the settling band, relative (default 0.02).
    rise_limits : tuple of float
        Fractions of the steady-state value between which the rise time is
        measured (default (0.1, 0.9)).

    Returns
    -------
    StepInfo

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 10.0, 1001)
    >>> info = step_info(t, 1.0 - np.exp(-t), steady_state=1.0)
    >>> round(info.rise_time_s, 2), round(info.settling_time_s, 2), info.overshoot_percent
    (2.2, 3.92, 0.0)
    """
    t_arr = np.asarray(t, dtype=float).ravel()
    y_arr = np.asarray(y, dtype=float).ravel()
    if t_arr.size == 0 or t_arr.shape != y_arr.shape:
        raise not_allowed("y", y_arr, f"it has {y_arr.size} samples where t has {t_arr.size}; "
                                      "need one sample per instant, at least one")
    if not (0 < settling_threshold < 1):
        raise not_allowed("settling_threshold", settling_threshold, "must be a fraction in (0, 1), e.g. 0.02")
    lo, hi = rise_limits
    if not (0 <= lo < hi <= 1):
        raise not_allowed("rise_limits", rise_limits, "must be two fractions 0 <= low < high <= 1, e.g. (0.1, 0.9)")
    final = float(y_arr[-1]) if steady_state is None else float(steady_state)
    if not math.isfinite(final) or not np.all(np.isfinite(y_arr)):
        return _nan_info()
    sign = np.sign(final)
    # first samples at or beyond the rise limits (step_info: sign * (y - k final) >= 0)
    reached_lo = np.flatnonzero(sign * (y_arr - lo * final) >= 0)
    reached_hi = np.flatnonzero(sign * (y_arr - hi * final) >= 0)
    if reached_lo.size == 0 or reached_hi.size == 0:
        # control.step_info would fail here (an IndexError); the figures are undefined
        return _nan_info()
    i_lo, i_hi = reached_lo[0], reached_hi[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        outside = np.flatnonzero(np.abs(y_arr / final - 1.0) >= settling_threshold)
    settled = 0 if outside.size == 0 else outside[-1] + 1
    settling_time = float(t_arr[settled]) if settled < t_arr.size else float("nan")
    tail = y_arr[i_hi:]
    y_os = float((sign * y_arr).max())
    excess = abs(y_os) - abs(final)
    overshoot = abs(100.0 * excess / final) if excess > 0 else 0.0
    y_us = float(y_arr[int((sign * y_arr).argmin())])
    undershoot = -100.0 * y_us / final if sign * y_us < 0 else 0.0
    i_peak = int(np.abs(y_arr).argmax())
    return StepInfo(
        rise_time_s=float(t_arr[i_hi] - t_arr[i_lo]),
        settling_time_s=settling_time,
        settling_min=float(min(tail.min(), final)),
        settling_max=float(max(tail.max(), final)),
        overshoot_percent=overshoot,
        undershoot_percent=undershoot,
        peak=float(abs(y_arr[i_peak])),
        peak_time_s=float(t_arr[i_peak]),
        steady_state=final,
    )


# ---------------------------------------------------------------------------
# transfer functions
# ---------------------------------------------------------------------------
def _num_den(model, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of a pair, a TFEstimate or a ``control.TransferFunction``."""
    if hasattr(model, "num") and hasattr(model, "den"):
        num, den = model.num, model.den
        if isinstance(num, list):  # control.TransferFunction: nested lists (SISO)
            num, den = num[0][0], den[0][0]
        return as_tf(num, den, (f"{name}.num", f"{name}.den"))
    try:
        num, den = model
    except (TypeError, ValueError):
        raise not_allowed(name, model, "must be a (num, den) pair or a transfer function") from None
    return as_tf(num, den, (f"{name}[0]", f"{name}[1]"))


def _dc_gain(num: np.ndarray, den: np.ndarray) -> float:
    """``G(0)``; inf for a pole at s = 0 (as python-control's ``dcgain``)."""
    if den[-1] == 0.0:
        return float("inf") if num[-1] != 0.0 else float("nan")
    return float(num[-1] / den[-1])


def _uniform_grid(t) -> tuple[np.ndarray, float]:
    """``t`` as a uniform grid from 0, and its step."""
    allowed = "must be a uniform time grid starting at 0 s, at least 2 samples (e.g. numpy.arange(N) * dt)"
    try:
        t_arr = np.asarray(t, dtype=float).ravel()
    except (TypeError, ValueError):
        raise not_allowed("t", t, allowed) from None
    if t_arr.size < 2 or not np.all(np.isfinite(t_arr)) or t_arr[0] != 0.0:
        raise not_allowed("t", t_arr, allowed)
    dt = float(t_arr[1] - t_arr[0])
    if dt <= 0 or np.max(np.abs(np.diff(t_arr) - dt)) > 1e-9 * max(dt, t_arr[-1]):
        raise not_allowed("t", t_arr, allowed)
    return t_arr, dt


def default_step_horizon(*models) -> float:
    """A horizon [s] in which the models' step responses settle.

    As python-control's default: the slowest stable pole decays by a factor
    1000, ``ln(1000) / min |Re p|``; poles at the origin or in the right
    half-plane do not settle and are ignored. Clipped to [1, 120] s.

    Examples
    --------
    >>> round(default_step_horizon(([2437.0], [1.0, 430.1, 1.721e4, 2437.0])), 1)
    48.6
    """
    rates = []
    for i, model in enumerate(models):
        _, den = _num_den(model, f"models[{i}]")
        poles = np.roots(den) if den.size > 1 else np.zeros(0)
        decaying = -poles.real[poles.real < -1e-9 * max(1.0, float(np.max(np.abs(poles), initial=1.0)))]
        if decaying.size:
            rates.append(float(decaying.min()))
    if not rates:
        return 10.0
    return float(np.clip(np.log(1000.0) / min(rates), MIN_HORIZON_S, MAX_HORIZON_S))


def step_response(model, t=None, *, amplitude=1.0, name="model", dt=None, input_delay=None) -> StepResponse:
    """Exact step response of a continuous-time transfer function.

    Parameters
    ----------
    model : (num, den), TFEstimate or control.TransferFunction
        The transfer function, coefficients in descending powers of s.
    t : array_like, optional
        Uniform time grid from 0 [s]. Default: :func:`default_step_horizon`
        with ``dt`` (default: 1/1000 of the horizon).
    amplitude : float
        Step height (e.g. metres of reference); ``y`` is scaled by it, the
        figures are those of the unit step (steady state = the DC gain).
    name : str
        The response's name, as a figure's legend shows it.
    dt : float, optional
        Step of the default grid [s] (ignored when ``t`` is given).
    input_delay : float, optional
        Dead time of the model's input [s]; default: the model's own (a
        TFEstimate's ``input_delay``), else 0.

    Returns
    -------
    StepResponse

    Examples
    --------
    >>> import numpy as np
    >>> r = step_response(([4.0], [1.0, 1.6, 4.0]), np.arange(1001) * 0.01, amplitude=0.02)
    >>> round(r.info.overshoot_percent, 2), round(r.info.peak_time_s, 2), round(float(r.y[-1]), 4)
    (25.38, 1.71, 0.02)
    """
    num, den = _num_den(model, "model")
    amplitude = _check_amplitude(amplitude)
    if t is None:
        horizon = default_step_horizon((num, den))
        step = horizon / 1000.0 if dt is None else positive_number("dt", dt, "must be a finite time step > 0 s")
        t = np.arange(int(round(horizon / step)) + 1) * step
    t_arr, step = _uniform_grid(t)
    # a step is constant between samples: the ZOH discretisation is exact
    if input_delay is None:
        input_delay = getattr(model, "input_delay", 0.0) or 0.0
    y_unit = simulate_tf(num, den, np.ones(t_arr.size), step, input_delay=input_delay)
    gain = _dc_gain(num, den)
    unstable = den.size > 1 and bool(np.any(np.roots(den).real > 0))
    message = "ok"
    if not math.isfinite(gain):
        message = "the DC gain is infinite (a pole at s = 0): the response does not settle and the figures are NaN"
    elif unstable:
        message = "the model is unstable: the figures, taken against its DC gain, mean little"
    return StepResponse(name=str(name), t=readonly(t_arr), y=readonly(amplitude * y_unit), amplitude=amplitude,
                        info=step_info(t_arr, y_unit, gain), source="transfer function", message=message)


def _check_amplitude(amplitude) -> float:
    try:
        out = float(amplitude)
    except (TypeError, ValueError):
        out = float("nan")
    if not math.isfinite(out) or out == 0.0:
        raise not_allowed("amplitude", amplitude, "must be a finite, non-zero step height")
    return out


# ---------------------------------------------------------------------------
# the nonlinear closed loop
# ---------------------------------------------------------------------------
def nonlinear_step_response(params=None, *, amplitude_m=0.01, t_end_s=20.0, dt_s=0.001, kp=10.0, ts=0.01,
                            controller="zoh", name="nonlinear plant", cancel=None) -> StepResponse:
    """Step response of the nonlinear plant under the proportional controller.

    The closed loop of the paper's frequency experiment (eq. 22,
    :func:`eha_core.simulate.simulate_closed_loop`): reference ``r`` a step
    of ``amplitude_m`` metres at t = 0, ``u = Kp (r - x)`` sampled every
    ``ts`` and held (``controller="zoh"``), the nonlinear model with its
    bounds, from the parameters' initial conditions.

    Parameters
    ----------
    params : ActuatorParams, optional
        Default: the paper's.
    amplitude_m : float
        Step of the reference [m] (the valve sees ``Kp amplitude_m`` volts at
        first: the response is not proportional to it).
    t_end_s, dt_s : float
        Horizon and output interval [s]; ``ts`` and ``dt_s`` must be whole
        multiples of one another.
    kp, ts, controller
        As for :func:`~eha_core.simulate.simulate_closed_loop`.
    name : str
        The response's name (the run's label).
    cancel : eha_core.cancel.CancelToken, optional
        Checked between integration chunks; raises :class:`~eha_core.cancel.Cancelled` when set.

    Returns
    -------
    StepResponse
        ``y = x(t) - x(0)`` [m]; the figures of ``y / amplitude_m`` with the
        last sample as steady state (``control.step_info``'s convention for
        response data): let the horizon be long enough for it to settle.
        ``message`` says when the simulation failed or the piston reached
        an end stop.
    """
    from ..signals import Step
    from ..simulate import simulate_closed_loop

    amplitude = _check_amplitude(amplitude_m)
    run = simulate_closed_loop(params, Step(amplitude), kp=kp, ts=ts, controller=controller, t_end=t_end_s, dt=dt_s,
                               model="nonlinear", label=str(name), cancel=cancel)
    y = run.x - run.x[0]
    messages = []
    if not run.success:
        messages.append(run.message)
    reached = np.abs(run.x[np.isfinite(run.x)])      # a failed run may hold nothing finite
    if reached.size and reached.max() >= run.params.x_max * (1.0 - 1e-9):
        messages.append("the piston reached an end stop: the step is too large for the stroke")
    info = step_info(run.t, y / amplitude) if run.success else _nan_info()
    if run.success and not np.isnan(info.settling_time_s) and abs(info.steady_state - 1.0) > SETTLING_THRESHOLD:
        messages.append(f"the response ends at {info.steady_state:.3g} of the step, not 1: lengthen the horizon "
                        "or mind the load")
    return StepResponse(name=str(name), t=readonly(run.t), y=readonly(y), amplitude=amplitude, info=info,
                        source="nonlinear simulation", message="; ".join(messages) or "ok")


def step_comparison(models: Mapping, *, amplitude_m=0.01, t_end_s=None, dt_s=0.001, nonlinear=True,
                    params=None, kp=10.0, ts=0.01, controller="zoh", nonlinear_name="nonlinear plant",
                    cancel=None) -> StepComparison:
    """Step responses of named models (and of the nonlinear plant) on one grid, in metres.

    Parameters
    ----------
    models : mapping of str to model
        Transfer functions from r to x: ``(num, den)``, TFEstimate or
        ``control.TransferFunction`` (e.g. ``{"eq. 24": lin.closed_loop_coeffs(10),
        "estimate": est}``).
    amplitude_m : float
        Height of the reference step [m].
    t_end_s : float, optional
        Horizon [s]; default :func:`default_step_horizon` of the models,
        rounded up to a whole ``ts`` (20 s without models).
    dt_s : float
        Output interval [s] (a whole fraction or multiple of ``ts``).
    nonlinear : bool
        Also simulate the nonlinear plant (:func:`nonlinear_step_response`).
    params, kp, ts, controller, nonlinear_name, cancel
        Of the nonlinear closed loop.

    Returns
    -------
    StepComparison

    Examples
    --------
    >>> cmp = step_comparison({"eq. 24": ([2437.0], [1.0, 430.1, 1.721e4, 2437.0])}, nonlinear=False)
    >>> cmp.names, round(cmp["eq. 24"].info.rise_time_s, 2)
    (('eq. 24',), 15.46)
    """
    if not isinstance(models, Mapping):
        raise not_allowed("models", models, "must be a mapping of names to transfer functions")
    pairs = {str(k): _num_den(v, f"models[{k!r}]") for k, v in models.items()}
    if not pairs and not nonlinear:
        raise not_allowed("models", models, "give at least one model, or nonlinear=True")
    dt_s = positive_number("dt_s", dt_s, "must be a finite output interval > 0 s")
    ts = positive_number("ts", ts, "must be a finite sample time > 0 s")
    if t_end_s is None:
        t_end_s = default_step_horizon(*pairs.values()) if pairs else 20.0
        grain = max(ts, dt_s)
        t_end_s = math.ceil(t_end_s / grain - 1e-9) * grain
    t_end_s = positive_number("t_end_s", t_end_s, "must be a finite horizon > 0 s")
    n = int(round(t_end_s / dt_s))
    if n < 1 or abs(n * dt_s - t_end_s) > 1e-6 * dt_s:
        raise not_allowed("t_end_s", t_end_s, f"must be a whole number of output intervals dt_s = {dt_s:g} s")
    t = np.arange(n + 1) * dt_s
    amplitude = _check_amplitude(amplitude_m)
    responses = [step_response(pair, t, amplitude=amplitude, name=name) for name, pair in pairs.items()]
    if nonlinear:
        responses.append(nonlinear_step_response(params, amplitude_m=amplitude, t_end_s=t_end_s, dt_s=dt_s, kp=kp,
                                                 ts=ts, controller=controller, name=nonlinear_name, cancel=cancel))
    return StepComparison(t=readonly(t), amplitude=amplitude, responses=tuple(responses))
