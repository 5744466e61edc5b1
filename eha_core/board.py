"""A board of candidate models of the closed loop r -> x, compared the way a course compares them.

Every model is a continuous-time H(s) from the reference r to the position x
(the paper's eqs. 19-25), possibly with an input delay: a transfer-function
estimate, one from a student's own record, the linearised H(s) of eq. 24 built
from a least-squares run's estimates (eqs. 15-18 give M, B, Af, beta_e), or a
reference (eq. 24 with the actuator's values, the paper's Ĥ of eq. 25).

For each model :func:`model_views` computes, once, what the views draw: the
Bode diagram with a 95 % band when the model has a covariance, poles and zeros
with their 95 % regions, and the step response with its figures. All models
are compared on one validation record (:func:`validation_record`, a fresh
closed-loop experiment) by :func:`compare_on_record`, with MATLAB ``compare``
semantics: each model's initial state (and input offset) fitted to the record.

>>> from eha_core.linear import linearize
>>> h = reference_models()[0]
>>> v = model_views(h)
>>> round(v.step.info.steady_state, 3), v.band is None, len(v.pz.poles)
(1.0, True, 3)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._checks import ComputationError, not_allowed
from .cancel import CancelToken, check
from .params import ActuatorParams

__all__ = ["BoardModel", "PlantModel", "LinearisedEstimate", "plant_model", "plant_step", "greybox_plant",
           "linearised_estimate",
           "simulated_on_record", "ModelViews", "RecordComparison", "model_views", "compare_on_record",
           "validation_record", "reference_models", "lse_model", "BOARD_W", "STEP_T", "nonlinear_step"]

#: Frequencies of the board's Bode diagrams [rad/s]: 0.01 to the Nyquist frequency of Ts = 0.01 s.
BOARD_W = np.logspace(-2, math.log10(math.pi / 0.01), 300)
#: Time grid of the step responses [s]: the paper's closed loop settles in about 30 s (its slow pole
#: near -0.14 rad/s), 60 s shows it settled.
STEP_T = np.arange(3001) * 0.02


@dataclass(frozen=True, eq=False)
class BoardModel:
    """One model of the closed loop r -> x.

    ``kind``: ``"tf"`` (estimated from the frequency experiment), ``"record"``
    (from a student's file), ``"lse"`` (eq. 24 with a least-squares run's
    estimates), ``"greybox"`` (eq. 24 linearised at a grey-box estimate),
    ``"reference"``. ``params``: the actuator whose data it was estimated
    from (None when unknown). ``estimate`` (a
    :class:`~eha_core.identify.tfest.TFEstimate`) gives the covariance behind
    the regions and bands; None for a model without one.
    """

    name: str
    kind: str
    description: str
    num: np.ndarray
    den: np.ndarray
    input_delay: float = 0.0
    estimate: object | None = None
    ts: float | None = None
    kp: float | None = None       # the controller gain of the loop it describes (None: any)
    # the actuator it was identified on (None: unknown, e.g. a student's own record): a record of
    # another actuator compares it with a plant it was not made from, and the board says so
    params: ActuatorParams | None = None
    # a model of the actuator itself (a grey-box estimate): the board closes its loop with the
    # controller, simulates it on the record and steps it; num/den are its linearisation
    plant: PlantModel | None = None


@dataclass(frozen=True, eq=False)
class PlantModel:
    """A nonlinear model of the actuator (eqs. 1-10 with these values), e.g. a grey-box estimate.

    ``covariance`` (SI) over ``names``, the estimated parameters, gives the bands and regions of its
    linearisation (eq. 24) to first order; None for a model without one.
    """

    actuator: ActuatorParams
    names: tuple[str, ...] = ()
    covariance: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class LinearisedEstimate:
    """Eq. 24's closed loop at an estimated actuator, as the uncertainty functions read an estimate:
    ``num``, ``den`` (monic) and the covariance of ``[den[1:], num]`` carried from the parameters'
    by their Jacobian (the delta method)."""

    num: np.ndarray
    den: np.ndarray
    covariance: np.ndarray
    ts: float
    input_delay: float = 0.0


@dataclass(frozen=True, eq=False)
class ModelViews:
    """What the board draws of one model (computed once, when it is added)."""

    w: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray
    band: object | None           # BodeBand (95 %) or None
    pz: object                    # PoleZeroMap
    step: object                  # StepResponse of a unit step (the figures are those of the unit step)
    stable: bool
    # a plant model's step is the nonlinear loop's at this reference step [m] (stored per unit step)
    step_amplitude: float | None = None


@dataclass(frozen=True, eq=False)
class RecordComparison:
    """A model on the validation record: its output, the fit, and the residual tests with their verdicts."""

    y_hat: np.ndarray
    fit_percent: float
    assessment: object | None     # ResidualAssessment of x - y_hat against r (None if not simulable)


def _coefficients(model: BoardModel):
    return np.asarray(model.num, dtype=float), np.asarray(model.den, dtype=float)


def _closed_loop(actuator: ActuatorParams, kp: float) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of eq. 24's H(s) at ``actuator``, den monic."""
    from .linear import linearize

    num, den = linearize(actuator).closed_loop_coeffs(kp)
    den = np.asarray(den, dtype=float)
    return np.asarray(num, dtype=float) / den[0], den / den[0]


def linearised_estimate(plant: PlantModel, kp: float, ts: float) -> LinearisedEstimate | None:
    """Eq. 24 at ``plant.actuator`` with the covariance of its coefficients, J C Jᵀ, J by central
    differences of the linearisation over each estimated parameter (relative step 1e-5); None
    without a covariance.

    Parameters
    ----------
    plant : PlantModel
        The actuator and the covariance of its estimated parameters.
    kp : float
        The controller's gain [V/m] that closes the loop.
    ts : float
        Sample time [s] of the data it came from, kept with the estimate (the pole-zero map flags
        roots beyond its Nyquist frequency).
    """
    import dataclasses

    num, den = _closed_loop(plant.actuator, kp)
    cov = plant.covariance
    if cov is None or not plant.names:
        return None
    cov = np.asarray(cov, dtype=float)
    if cov.shape != (len(plant.names), len(plant.names)) or not np.all(np.isfinite(cov)):
        return None

    def theta(actuator):
        n, d = _closed_loop(actuator, kp)
        return np.concatenate([d[1:], n])

    jac = np.zeros((den.size - 1 + num.size, len(plant.names)))
    for j, name in enumerate(plant.names):
        value = float(getattr(plant.actuator, name))
        h = 1e-5 * max(abs(value), math.sqrt(max(cov[j, j], 0.0)), 1e-12)
        jac[:, j] = (theta(dataclasses.replace(plant.actuator, **{name: value + h}))
                     - theta(dataclasses.replace(plant.actuator, **{name: value - h}))) / (2 * h)
    return LinearisedEstimate(num=num, den=den, covariance=jac @ (0.5 * (cov + cov.T)) @ jac.T, ts=float(ts))


def greybox_plant(result) -> PlantModel:
    """The actuator a grey-box estimate ``result`` (:class:`~eha_core.identify.greybox.GreyBoxResult`)
    describes, with the covariance of the parameters it estimated (those it held have none)."""
    free = [i for i, n in enumerate(result.names)
            if n not in result.held and math.isfinite(result.std_errors.get(n, math.nan))]
    names = tuple(result.names[i] for i in free)
    std = np.array([result.std_errors[n] for n in names])
    cov = np.outer(std, std) * np.asarray(result.correlation, dtype=float)[np.ix_(free, free)] if names else None
    return PlantModel(actuator=result.params, names=names, covariance=cov)


def plant_model(plant: PlantModel, kp: float, *, name: str, description: str, ts: float = 0.01,
                params: ActuatorParams | None = None) -> BoardModel:
    """A board model of ``plant`` in the loop of ``kp``: its linearisation (eq. 24) with the bands its
    covariance gives, simulated as the nonlinear model on the record and for the step.

    Raises :class:`~eha_core.params.ParameterError` for an actuator that cannot be linearised.

    Parameters
    ----------
    plant : PlantModel
        The actuator, e.g. :func:`greybox_plant` of an estimate.
    kp : float
        The controller's gain [V/m] that closes the loop.
    name, description : str
        The model's name and one line about it, as the board shows them.
    ts : float
        Sample time [s] of the data it was estimated from, kept in the model and its estimate.
    params : ActuatorParams, optional
        The actuator the data came from (None: unknown).
    """
    num, den = _closed_loop(plant.actuator, kp)
    return BoardModel(name=name, kind="greybox", description=description, num=num, den=den,
                      estimate=linearised_estimate(plant, kp, ts), ts=float(ts), kp=float(kp), params=params,
                      plant=plant)


def plant_step(model: BoardModel, amplitude_m: float, *, step_t=STEP_T, cancel: CancelToken | None = None):
    """A plant model's step response under its controller (the nonlinear loop, as the plant's own), per
    unit step like a transfer function's (``y`` divided by ``amplitude_m``).

    Parameters
    ----------
    model : BoardModel
        A model with a ``plant`` (:func:`plant_model`).
    amplitude_m : float
        The reference step simulated [m].
    step_t : array
        Not used: the nonlinear step runs on :data:`STEP_T`'s horizon at 0.01 s (:func:`nonlinear_step`).
    cancel : eha_core.cancel.CancelToken, optional
        Checked before and during the simulation.
    """
    import dataclasses

    out = nonlinear_step(model.plant.actuator, model.kp, amplitude_m, cancel=cancel)
    return dataclasses.replace(out, name=model.name, y=out.y / amplitude_m, amplitude=1.0,
                               source="nonlinear simulation of the model")


def model_views(model: BoardModel, *, w=BOARD_W, step_t=STEP_T, level: float = 0.95, n_draws: int = 300,
                seed: int = 0, amplitude_m: float = 0.01) -> ModelViews:
    """Bode curve (and band), pole-zero map (with regions) and unit step response of ``model``; a plant
    model's step is its nonlinear loop's to a step of ``amplitude_m`` (per unit step).

    Parameters
    ----------
    model : BoardModel
        The model drawn.
    w : array
        Frequencies of the Bode curve [rad/s].
    step_t : array
        Times of a transfer function's step response [s] (a plant model's runs on :data:`STEP_T`).
    level : float
        Confidence level of the band and the regions, in (0, 1).
    n_draws : int
        Draws of the coefficients for the Bode band (:func:`~eha_core.identify.uncertainty.bode_band`).
    seed : int
        Seed of those draws.
    amplitude_m : float
        Reference step of a plant model's nonlinear step [m].
    """
    from .identify._ctmodels import frequency_response
    from .identify.step import step_response
    from .identify.uncertainty import bode_band, pole_zero_regions, reference_roots

    num, den = _coefficients(model)
    fr = frequency_response(num, den, w, input_delay=model.input_delay)
    est = model.estimate
    has_cov = est is not None and np.all(np.isfinite(est.covariance)) and est.covariance.size > 0
    band = bode_band(est, w, level=level, n_draws=n_draws, seed=seed) if has_cov else None
    if has_cov:
        pz = pole_zero_regions(est, level=level, name=model.name)
    else:
        # a model without a covariance has no region, and nothing to call weakly determined
        pz = reference_roots(num, den, ts=None, name=model.name)
    poles = np.roots(den)
    stable = bool(np.all(poles.real < 0))
    if model.plant is not None:
        step = plant_step(model, amplitude_m)
    else:
        step = step_response((num, den), np.asarray(step_t, dtype=float), name=model.name,
                             input_delay=model.input_delay)
    return ModelViews(w=np.asarray(w), magnitude_db=fr.magnitude_db, phase_deg=fr.phase_deg, band=band, pz=pz,
                      step=step, stable=stable, step_amplitude=amplitude_m if model.plant is not None else None)


def validation_record(params: ActuatorParams | None = None, *, kp: float = 10.0, seed: int = 1,
                      n_samples: int = 1000, ts: float = 0.01, model: str = "nonlinear",
                      noise_x: float = 0.0, disturbance: str = "none", cancel: CancelToken | None = None):
    """A fresh closed-loop experiment (the paper's idinput sine excitation, ``seed``) to compare models on.

    Parameters
    ----------
    params : ActuatorParams, optional
        The actuator in the loop; defaults to the paper's parameters.
    kp : float
        The controller's gain [V/m].
    seed : int
        Seed of the excitation, in [0, 1000000].
    n_samples : int
        Samples of the record.
    ts : float
        Sample time of the record and the controller [s].
    model : {'nonlinear', 'linear'}
        The model simulated.
    noise_x, disturbance
        As in :class:`~eha_core.experiments.FrequencyExperiment`: σ of the position
        sensor's noise [m], and a load force d(t) [N] as signal text.
    cancel : eha_core.cancel.CancelToken, optional
        Checked between integration chunks.

    Returns
    -------
    eha_core.simulate.SimulationResult
        The record (``t``, ``r``, ``x``, ...).
    """
    from .experiments import FrequencyExperiment

    if not isinstance(seed, (int, np.integer)) or not 0 <= seed <= 10**6:
        raise not_allowed("seed", seed, "must be a whole number in [0, 1000000]")
    cfg = FrequencyExperiment(n_samples=n_samples, ts=ts, seed=int(seed), kp=kp, model=model, noise_x=noise_x,
                              disturbance=disturbance)
    data = cfg.closed_loop(params if params is not None else ActuatorParams(), cfg.excitation(), cancel)
    if not data.success:
        raise ComputationError(f"the validation experiment failed: {data.message}")
    return data


def compare_on_record(model: BoardModel, record) -> RecordComparison:
    """``model`` on the ``record`` (MATLAB ``compare``: initial state and input offset fitted), with the
    residual tests of its error against the reference and their verdict sentences.

    ``record`` is a closed-loop :class:`~eha_core.simulate.SimulationResult` (its ``t``, ``r``
    and ``x``), e.g. :func:`validation_record`'s.
    """
    from .identify.assessment import assess_residuals
    from .identify.validate import compare, fit_percent, residual_analysis

    ts = float(record.t[1] - record.t[0])
    if model.plant is not None:
        y_hat = simulated_on_record(model, record)
        fit = fit_percent(record.x, y_hat) if np.all(np.isfinite(y_hat)) else float("nan")
    else:
        num, den = _coefficients(model)
        res = compare(num, den, record.r, record.x, ts, initial_condition="estimate", input_offset="estimate",
                      input_delay=model.input_delay)
        y_hat, fit = res.y_hat, res.fit_percent
    assessment = None
    error = record.x - y_hat
    # (a model that is the record's own actuator, noise-free, leaves no error to test)
    if np.all(np.isfinite(y_hat)) and np.any(error != 0):
        assessment = assess_residuals(residual_analysis(error, record.r))
    return RecordComparison(y_hat=y_hat, fit_percent=float(fit), assessment=assessment)


def simulated_on_record(model: BoardModel, record, cancel: CancelToken | None = None) -> np.ndarray:
    """A plant model's position on the record: the nonlinear model from its own initial state, in the
    loop of its Kp sampled at the record's Ts, driven by the record's reference; no load (the model
    does not know the record's). NaN where the simulation failed.

    Parameters
    ----------
    model : BoardModel
        A model with a ``plant`` (:func:`plant_model`).
    record : eha_core.simulate.SimulationResult
        The closed-loop record: its ``t``, ``r`` [m] and ``x`` [m].
    cancel : eha_core.cancel.CancelToken, optional
        Checked between integration chunks.
    """
    from .simulate import simulate_closed_loop

    ts = float(record.t[1] - record.t[0])
    res = simulate_closed_loop(model.plant.actuator, np.asarray(record.r, dtype=float), kp=model.kp, ts=ts,
                               cancel=cancel)
    y_hat = np.full(np.shape(record.x), np.nan)
    if res.success:
        n = min(y_hat.size, res.x.size)
        y_hat[:n] = res.x[:n]
    return y_hat


def reference_models(params: ActuatorParams | None = None, kp: float = 10.0, *,
                     linearised: bool = True) -> list[BoardModel]:
    """The references: eq. 24's H(s) with the actuator's values (unless ``linearised`` is False, e.g.
    when an exercise hides them) and the paper's Ĥ(s) of eq. 25.

    ``params`` is the actuator (default the paper's), ``kp`` the controller's gain [V/m] of eq. 24.
    """
    from .experiments import PAPER_EQ25
    from .linear import linearize

    out = []
    if linearised:
        num, den = linearize(params if params is not None else ActuatorParams()).closed_loop_coeffs(kp)
        out.append(BoardModel(name="H(s) eq. 24", kind="reference",
                              description=f"linearised at v = 0, Kp = {kp:g} V/m", num=np.asarray(num),
                              den=np.asarray(den), ts=0.01))
    out.append(BoardModel(name="Ĥ paper", kind="reference", description="the paper's estimate, eq. 25",
                          num=np.asarray(PAPER_EQ25[0], dtype=float), den=np.asarray(PAPER_EQ25[1], dtype=float),
                          ts=0.01))
    return out


def lse_model(result, params: ActuatorParams, kp: float, name: str, description: str) -> BoardModel:
    """Eq. 24's H(s) with a least-squares run's estimates of M, B, Af, beta_e (the rest as measured).

    Raises :class:`~eha_core.params.ParameterError` when an estimate is not physical (e.g. B < 0).

    Parameters
    ----------
    result : eha_core.identify.lse.LSEResult
        The least-squares estimate.
    params : ActuatorParams
        The actuator the data came from: the measured values the estimates replace some of.
    kp : float
        The controller's gain [V/m] that closes the loop.
    name, description : str
        The model's name and one line about it, as the board shows them.
    """
    from .linear import linearize

    est = result.estimated_params(params)
    num, den = linearize(est).closed_loop_coeffs(kp)
    return BoardModel(name=name, kind="lse", description=description, num=np.asarray(num), den=np.asarray(den),
                      ts=float(result.ts), kp=float(kp), params=params)


def nonlinear_step(params: ActuatorParams, kp: float, amplitude_m: float, *, noise_x: float = 0.0, seed: int = 0,
                   cancel: CancelToken | None = None):
    """The nonlinear plant's step response under the same controller, on :data:`STEP_T`'s horizon; with
    ``noise_x`` (σ, m) as a position sensor would record it, its characteristics read from that record.

    Parameters
    ----------
    params : ActuatorParams
        The actuator.
    kp : float
        The controller's gain [V/m], sampled at 0.01 s.
    amplitude_m : float
        The reference step [m].
    noise_x : float
        σ of the position sensor's white noise [m]; 0: none.
    seed : int
        Seed of that noise.
    cancel : eha_core.cancel.CancelToken, optional
        Checked before and during the simulation.
    """
    import dataclasses

    from .identify.step import nonlinear_step_response, step_info

    check(cancel)
    out = nonlinear_step_response(params, amplitude_m=amplitude_m, t_end_s=float(STEP_T[-1]), dt_s=0.01, kp=kp,
                                  ts=0.01, cancel=cancel)
    if noise_x > 0 and out.message == "ok":
        y = out.y + noise_x * np.random.default_rng([seed, 0x57E9]).standard_normal(out.y.shape)
        out = dataclasses.replace(out, y=y, info=step_info(out.t, y / out.amplitude),
                                  source="nonlinear simulation, measured")
    return out
