"""Validation of identified physical parameters on data the estimate was not fitted to.

The least squares (:mod:`eha_core.identify.lse`) and the grey-box estimate
(:mod:`eha_core.identify.greybox`) give physical parameters of the nonlinear model. How well they
describe the actuator shows on a record they did not see, in one of two ways:

- ``"second"``, a second experiment: the same plant, the same sensors (the same noise σ, a new
  draw) and the same disturbance (a random one drawn anew), under another excitation,
  :func:`validation_input`: two sines at 3 and 7 Hz, frequencies neither the paper's input
  (2 Hz) nor the rich one (2 and 5 Hz) holds, scaled to the estimation input's peak so that the
  valve works over the same range and the piston stays clear of the end stops (the model is
  validated where it was estimated, on motions it was not fitted to);
- ``"split"``: the record's last part (:data:`DEFAULT_HOLDOUT`, a third) is held out
  (:func:`split_record`); the estimator runs on the first part only.

The identified model is then simulated on the validation record's input (pure simulation, no
measured output read along the way) and compared with each measured signal by MATLAB's NRMSE
fit (:func:`eha_core.identify.blackbox.fit_percent`), in the words every fit of the project uses
(:func:`~eha_core.identify.blackbox.horizon_words`, :func:`~eha_core.identify.blackbox.initial_words`):
"fit 97.3 % (simulation, initial conditions estimated)". The initial conditions are estimated as a
rig would: the state at the validation record's first sample is read from the record for the
signals it measures (x, v, p1, p2); a state it does not measure is the model's own (its initial
state for a second experiment, which starts at rest as the first did; its simulation of the
estimation part continued to the split for a held-out part). :attr:`HoldoutValidation.initial_how`
says which.

Only the simulated record is used: the plant that made it (in an exercise, the student's hidden
actuator) never leaves the function that simulates it.

Examples
--------
>>> from eha_core.experiments import LSE_INPUT
>>> from eha_core.identify.greybox import greybox_data
>>> from eha_core.params import ActuatorParams
>>> truth = ActuatorParams()
>>> rec = second_greybox_record(truth, LSE_INPUT, t_end=2.0, seed=0)
>>> val = validate_params(truth, rec, kind="second")
>>> val.labels["x"]
'fit 100.0 % (simulation, initial conditions estimated)'
>>> est, held_out = split_record(greybox_data(truth, LSE_INPUT, t_end=3.0), 1 / 3)
>>> est.t.size, held_out.t.size, float(held_out.t[0])
(2001, 1000, 2.001)
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .._checks import not_allowed
from ..cancel import CancelToken, check
from ..params import ActuatorParams, ParameterError
from ..signals import ZERO, Constant, Sampled, Signal, Sine, Sum
from .blackbox import fit_percent, horizon_words, initial_words

__all__ = ["VALIDATIONS", "VALIDATION_WORDS", "DEFAULT_HOLDOUT", "VALIDATION_SEED_OFFSET", "HoldoutValidation",
           "validation_input", "validation_seed", "split_record", "second_lse_record", "second_greybox_record",
           "validate_params", "lse_model_params", "model_state_at"]

#: How an identification is validated: not at all (its fit on the estimation data only), on a second
#: experiment, on the record's held-out last part.
VALIDATIONS = ("none", "second", "split")
#: The choices in words, as the forms and reports show them.
VALIDATION_WORDS = {"none": "the estimation data only", "second": "a second experiment",
                    "split": "the record's last third"}
#: The share of the record held out of the estimation by default (as the record panel's last third).
DEFAULT_HOLDOUT = 1 / 3
#: A second experiment's noise seed is the first's plus this: beyond any seed a form offers (0 to 10^6),
#: so that no two experiments of a session share a noise draw.
VALIDATION_SEED_OFFSET = 1_000_003

#: The second experiment's excitation before scaling: two sines whose frequencies (3 and 7 Hz) the
#: estimation inputs do not hold, at a ratio that keeps the 7 Hz component visible in x.
_VALIDATION_SINES = ((0.7, 3.0), (0.3, 7.0))
_SIGNALS = ("x", "v", "p1", "p2")


def validation_seed(seed: int) -> int:
    """The noise seed of the second experiment of a record drawn with ``seed``.

    Examples
    --------
    >>> validation_seed(0)
    1000003
    """
    return int(seed) + VALIDATION_SEED_OFFSET


def validation_input(u: Signal, t_end: float, dt: float = 1e-3) -> Signal:
    """The second experiment's excitation for an estimation input ``u`` of ``t_end`` seconds.

    Two sines, ``a1 sin(6 pi t) + a2 sin(14 pi t)``, scaled so that their peak is ``u``'s peak
    over its record (``dt`` its sample time): the valve works over the same range, at frequencies
    the estimation input did not hold.

    Parameters
    ----------
    u : Signal
        The estimation record's input [V].
    t_end, dt : float
        Its length and sample time [s].

    Examples
    --------
    >>> from eha_core.experiments import LSE_INPUT
    >>> v = validation_input(LSE_INPUT, 5.0)
    >>> v.label
    '4.2 sin(6πt) + 1.8 sin(14πt)'
    """
    t = np.arange(int(round(t_end / dt)) + 1) * dt
    peak = float(np.max(np.abs(np.asarray(u(t), dtype=float)))) if t.size else 0.0
    if not (math.isfinite(peak) and peak > 0):
        raise not_allowed("excitation", getattr(u, "label", u), "a second experiment needs an input that moves")
    grid = np.arange(0.0, 1.0, 1e-4)        # the sum's period is 1 s
    base = np.max(np.abs(sum(a * np.sin(2 * np.pi * f * grid) for a, f in _VALIDATION_SINES)))
    scale = peak / base
    return Sum(tuple(Sine(float(f"{a * scale:.3g}"), f) for a, f in _VALIDATION_SINES))


def split_record(data, holdout: float = DEFAULT_HOLDOUT):
    """``(estimation part, held-out part)`` of a record: its last ``holdout`` share is held out.

    Parameters
    ----------
    data : MeasuredData or GreyBoxData
        The record (its times from any start).
    holdout : float
        The share of the samples held out, strictly between 0 and 1 (default a third).

    The estimation part keeps ``round((1 - holdout) N)`` samples; each part keeps its own times (the
    held-out one starts where the estimation part ends), its source says which part it is.
    """
    from .greybox import GreyBoxData
    from .lse import MeasuredData

    f = float(holdout)
    if not (math.isfinite(f) and 0.0 < f < 1.0):
        raise not_allowed("held-out share", holdout, "must lie strictly between 0 and 1")
    n = data.t.size
    k = int(round((1.0 - f) * n))
    minimum = 50 if isinstance(data, MeasuredData) else 3
    if k < minimum or n - k < minimum:
        raise not_allowed("held-out share", holdout, f"leaves fewer than {minimum} samples on one side of {n}")
    t_split = float(data.t[k])
    if isinstance(data, MeasuredData):
        cut = [MeasuredData(*(getattr(data, c)[s] for c in ("t", "x", "v", "p1", "p2", "u")), source=f"{data.source} — "
                            f"{which}") for s, which in ((slice(0, k), f"estimation part (t < {t_split:g} s)"),
                                                       (slice(k, n), f"held-out part (t ≥ {t_split:g} s)"))]
        return cut[0], cut[1]
    if not isinstance(data, GreyBoxData):
        raise not_allowed("record", type(data).__name__, "give MeasuredData or GreyBoxData")

    def part(s, which):
        opt = {name: (None if getattr(data, name) is None else np.asarray(getattr(data, name))[s])
               for name in ("u", "d", "r")}
        return dataclasses.replace(data, t=data.t[s], signals={k_: v[s] for k_, v in data.signals.items()},
                                   source=f"{data.source} — {which}", **opt)

    return (part(slice(0, k), f"estimation part (t < {t_split:g} s)"),
            part(slice(k, n), f"held-out part (t ≥ {t_split:g} s)"))


def second_lse_record(truth: ActuatorParams, u: Signal, *, t_end: float, disturbance: str | Signal = "none",
                      seed: int = 0, measurement_noise: dict | None = None, cancel: CancelToken | None = None):
    """The least squares' second experiment: :func:`~eha_core.experiments.lse_data` of the same plant
    and sensors under :func:`validation_input`, its noise (sensors', and the disturbance's when it is
    given as text) drawn from :func:`validation_seed`.

    Parameters
    ----------
    truth : ActuatorParams
        The plant (an exercise's hidden actuator: used here only to simulate the record).
    u : Signal
        The estimation record's input; the validation input follows from it.
    t_end : float
        The record's length [s] (the estimation record's).
    disturbance : str or Signal
        The load force, as for :func:`~eha_core.experiments.lse_data` (a Signal keeps its own draw:
        give the text, or the signal drawn with the validation seed).
    seed : int
        The estimation record's seed.
    measurement_noise : dict, optional
        The sensors' σ (SI), the estimation record's.
    cancel : eha_core.cancel.CancelToken, optional
        Reaches the simulation.
    """
    from ..experiments import lse_data

    val_u = validation_input(u, t_end)
    data = lse_data(truth, disturbance, u=val_u, t_end=t_end, seed=validation_seed(seed),
                    measurement_noise=measurement_noise, cancel=cancel)
    return dataclasses.replace(data, source=_second_name(val_u, seed))


def second_greybox_record(truth: ActuatorParams, u: Signal, *, t_end: float, dt: float = 1e-3,
                          d: Signal | None = None, noise: dict | None = None, seed: int = 0,
                          measured=_SIGNALS):
    """The grey-box estimate's second experiment: :func:`~eha_core.identify.greybox.greybox_data` of the
    same plant, known load and sensors under :func:`validation_input`, noise from :func:`validation_seed`.

    Parameters
    ----------
    truth : ActuatorParams
        The plant (only simulated here).
    u : Signal
        The estimation record's input.
    t_end, dt : float
        The record's length and sample time [s].
    d : Signal, optional
        The known load force (drawn anew by the caller when it is random).
    noise : dict, optional
        σ per measured signal (SI).
    seed : int
        The estimation record's seed.
    measured : iterable of str
        The signals recorded.
    """
    from .greybox import greybox_data

    val_u = validation_input(u, t_end, dt)
    rec = greybox_data(truth, val_u, t_end=t_end, dt=dt, d=d, noise=noise, seed=validation_seed(seed),
                       measured=tuple(measured))
    return dataclasses.replace(rec, source=_second_name(val_u, seed))


def _second_name(u: Signal, seed: int) -> str:
    return f"a second experiment (u = {u.label}, noise seed {validation_seed(seed)})"


def lse_model_params(result, params: ActuatorParams) -> tuple[ActuatorParams, Signal]:
    """The least squares' model: ``params`` with the estimates, and the disturbance it estimated beyond d0
    (the harmonic model's sinusoid; :data:`~eha_core.signals.ZERO` for the constant model), as
    :func:`~eha_core.experiments.lse_resimulation` simulates it. Raises ParameterError for an estimate
    that is not physical.

    Parameters
    ----------
    result : eha_core.identify.lse.LSEResult
        The estimate.
    params : ActuatorParams
        The known parameters the estimates replace some of.
    """
    est = result.estimated_params(params)
    d: Signal = ZERO
    if result.disturbance_model == "harmonic" and result.disturbance_freq_hz:
        f = result.disturbance_freq_hz
        d = Sine(result.estimates["d_sin"], f) + Sine(result.estimates["d_cos"], f, phase=math.pi / 2)
    return est, d


@dataclass(frozen=True, eq=False)
class HoldoutValidation:
    """A model simulated on a validation record, and its fit to each measured signal.

    Attributes
    ----------
    kind : str
        ``"second"`` (a second experiment) or ``"split"`` (the record's held-out part).
    record : str
        The validation record's name (what it is, its input, its noise seed or its times).
    t : numpy.ndarray
        Its times [s] (the held-out part's own times).
    measured : dict
        Each compared signal (x, v, p1, p2, SI) as recorded.
    simulated : numpy.ndarray or None
        The model's states (N x 4: x, v, p1, p2, SI) on the record; None when it could not be simulated.
    fits : dict
        NRMSE fit per compared signal [%].
    horizon : None
        Simulation (the words of :func:`~eha_core.identify.blackbox.horizon_words`).
    initial : str
        ``"estimate"``: the initial state is read from the record (:attr:`initial_how` says how).
    initial_how : str
        Which state came from where, in a sentence.
    success, message : bool, str
        False, with the reason, when the model cannot be simulated (an estimate that is not physical, a
        simulation that stopped being finite).
    """

    kind: str
    record: str
    t: np.ndarray
    measured: Mapping[str, np.ndarray]
    simulated: np.ndarray | None
    fits: Mapping[str, float]
    horizon: None = None
    initial: str = "estimate"
    initial_how: str = ""
    success: bool = True
    message: str = "ok"
    signals: tuple[str, ...] = field(default=())

    @property
    def words(self) -> str:
        """``"simulation, initial conditions estimated"``: how every fit here was computed."""
        return f"{horizon_words(self.horizon)}, {initial_words(self.initial)}"

    @property
    def labels(self) -> dict[str, str]:
        """Per signal: ``"fit 97.3 % (simulation, initial conditions estimated)"``."""
        return {s: f"fit {f:.1f} % ({self.words})" for s, f in self.fits.items()}

    @property
    def label(self) -> str:
        """Every signal's fit in one line: ``"x 99.1 %, p1 95.0 % (simulation, initial conditions estimated)"``."""
        if not self.fits:
            return f"no fit ({self.message})"
        return "fit " + ", ".join(f"{s} {f:.1f} %" for s, f in self.fits.items()) + f" ({self.words})"

    def to_dict(self) -> dict:
        """The validation as JSON types (no signal arrays)."""
        return {"kind": self.kind, "record": self.record, "fits": {s: float(f) for s, f in self.fits.items()},
                "labels": self.labels, "horizon": "simulation", "initial": self.initial,
                "initial_how": self.initial_how, "success": bool(self.success), "message": self.message}

    def __repr__(self) -> str:
        return f"HoldoutValidation({self.kind}: {self.label} on {self.record})"


def model_state_at(model: ActuatorParams, record, t_at: float, *, cancel: CancelToken | None = None) -> np.ndarray:
    """The model's state [x, v, p1, p2] at ``t_at``, simulated from its initial state on ``record``'s input
    (its samples of u and of a known load, linear between them): where a held-out part starts, for the
    states the record does not measure (:func:`validate_params`'s ``carried_state``).

    Parameters
    ----------
    model : ActuatorParams
        The identified parameters; the run starts at their initial state at the record's first time.
    record : MeasuredData or GreyBoxData
        The whole record (estimation part and held-out part).
    t_at : float
        The time [s] of the record at which the state is wanted.
    cancel : eha_core.cancel.CancelToken, optional
        Reaches the simulation.
    """
    from ..simulate import simulate

    t, _measured, u_samples, d_samples, hold = _record_parts(record)
    tr = t - t[0]
    d = Sampled(tr, np.asarray(d_samples, float), name="d") if d_samples is not None else ZERO
    ts = float(tr[-1] / (tr.size - 1))
    span = float(t_at - t[0])
    if span <= 0:
        return np.asarray(model.initial_state, float)
    run = simulate(model, u=Sampled(tr, u_samples, hold=hold, name="u"), d=d, t_end=span, dt=ts, cancel=cancel)
    if not run.success:
        return np.asarray(model.initial_state, float)
    return np.array([getattr(run, s)[-1] for s in _SIGNALS], dtype=float)


def _shifted(signal: Signal, t0: float) -> Signal | None:
    """``signal(t + t0)`` as a signal of the same kind, when it is made of constants and sines (None otherwise)."""
    if t0 == 0:
        return signal
    if isinstance(signal, Constant):
        return signal
    if isinstance(signal, Sine):
        return dataclasses.replace(signal, phase=signal.phase + 2 * math.pi * signal.freq_hz * t0)
    if isinstance(signal, Sum):
        terms = [_shifted(s, t0) for s in signal.terms]
        return None if any(s is None for s in terms) else Sum(tuple(terms))
    return None


def _record_parts(record):
    """(t, measured signals, u samples, d samples or None, hold) of a MeasuredData or GreyBoxData."""
    from .greybox import GreyBoxData

    if isinstance(record, GreyBoxData):
        if record.u is None:
            raise not_allowed("record", "a closed-loop record", "validation simulates the open-loop model: give "
                                                                 "a record of u")
        hold = "zoh" if record.intersample == "zoh" else "linear"
        return record.t, dict(record.signals), np.asarray(record.u, float), record.d, hold
    return (record.t, {s: np.asarray(getattr(record, s), float) for s in _SIGNALS}, np.asarray(record.u, float),
            None, "linear")


def validate_params(model: ActuatorParams, record, *, kind: str, signals=None, u: Signal | None = None,
                    d: Signal | None = None, carried_state=None, cancel: CancelToken | None = None
                    ) -> HoldoutValidation:
    """Simulate the nonlinear model ``model`` on ``record``'s input and compare it with the record.

    Parameters
    ----------
    model : ActuatorParams
        The identified parameters (with the known ones): the least squares'
        (:func:`lse_model_params`) or the grey-box estimate's ``params``.
    record : MeasuredData or GreyBoxData
        The validation record (a second experiment, or a held-out part: its times from any start).
    kind : {"second", "split"}
        What the record is (said in the result).
    signals : iterable of str, optional
        The signals compared (default every one the record measures).
    u : Signal, optional
        The record's input as a signal of time from t = 0 (the estimation's own, e.g. a sine): shifted to
        the record's start when it is made of sines, otherwise (and by default) the record's samples of u
        are used, linear between them (held for a grey-box record read as zoh).
    d : Signal, optional
        A load force the model applies, besides ``model.d0``, as a function of time from t = 0 (the
        least squares' harmonic disturbance); a grey-box record's known load ``d`` is taken from it.
    carried_state : array of 4, optional
        The model's state at the record's start for the signals it does not measure (a held-out part:
        the model's simulation of the estimation part, continued); default ``model.initial_state``.
    cancel : eha_core.cancel.CancelToken, optional
        Reaches the simulation.
    """
    from ..simulate import simulate

    if kind not in VALIDATIONS[1:]:
        raise not_allowed("validation", kind, "second (a second experiment) or split (the record's last part)")
    check(cancel)
    t, measured, u_samples, d_samples, hold = _record_parts(record)
    signals = tuple(s for s in _SIGNALS if s in (measured if signals is None else tuple(signals)))
    missing = [s for s in signals if s not in measured]
    if missing or not signals:
        raise not_allowed("signals", ",".join(signals) or "(none)",
                          f"compare signals the record has ({', '.join(measured)})")
    t0 = float(t[0])
    tr = t - t0
    name = getattr(record, "source", "validation record")
    start = np.asarray(model.initial_state if carried_state is None else carried_state, dtype=float).copy()
    for s in signals:
        start[_SIGNALS.index(s)] = measured[s][0]
    from_record = [s for s in _SIGNALS if s in signals]
    from_model = [s for s in _SIGNALS if s not in signals]
    how = ("the initial state: " + ", ".join(from_record) + " from the validation record's first sample"
           + (f"; {', '.join(from_model)} the model's own" + (" (its simulation continued to the split)"
                                                               if carried_state is not None else "")
              if from_model else ""))
    u_sig = _shifted(u, t0) if u is not None else None
    if u_sig is None:
        u_sig = Sampled(tr, u_samples, hold=hold, name="u")
    load = _shifted(d, t0) if d is not None else ZERO
    if load is None:
        load = Sampled(tr, d(t), name="d")
    if d_samples is not None and np.any(np.asarray(d_samples) != 0):
        load = load + Sampled(tr, np.asarray(d_samples, float), name="d")
    ts = float(tr[-1] / (tr.size - 1))

    def failed(message):
        return HoldoutValidation(kind, name, t, {s: measured[s] for s in signals}, None, {}, initial_how=how,
                                 success=False, message=message, signals=signals)

    try:
        run = simulate(model, u=u_sig, d=load, t_end=float(tr[-1]), dt=ts, initial_state=start,
                       label="validation", cancel=cancel)
    except (ParameterError, ValueError) as exc:
        return failed(f"the model cannot be simulated: {exc}")
    if not run.success:
        return failed(f"the model's simulation failed on the validation record: {run.message}")
    states = np.column_stack([np.interp(tr, run.t, getattr(run, s)) for s in _SIGNALS])
    fits = {s: fit_percent(measured[s], states[:, _SIGNALS.index(s)]) for s in signals}
    return HoldoutValidation(kind, name, t, {s: measured[s] for s in signals}, states, fits, initial_how=how,
                             signals=signals)
