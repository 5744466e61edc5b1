"""Is the lab's grading fair? Many students of one exercise, each identifying their own actuator.

An exercise judges a hand-in by the precision of the student's own record
(:meth:`eha_core.exercise.Exercise.judge`, grading "zscore"): a value is
accepted within k standard errors of the truth, the standard error the
server computed on the record, and only when k standard errors are within
the parameter's tolerance. Whether that is fair is a measurable property of
each route:

* an honest student (their own record, a sound experiment) is refused rarely:
  with honest standard errors about 0.3 % of values at k = 3, more where the
  route's own model error (eq. 27's linearisation, the least squares'
  noisy regressors) exceeds both the standard error and the floor;
* a student who hands in a neighbour's values (copied, with the neighbour's
  record behind them) is refused;
* a student spraying guesses around the paper's values gains nothing under
  the exercise's score rule;
* a better experiment earns a tighter acceptance (``band``: k standard errors
  relative to the estimate, what the student sees).

:func:`run_grading_study` runs ``n_students`` students of the exercise (ids
``student0``, ``student1``...; student i's noise seed is i) by one route with
the page's default experiment or a sound one (:data:`EXPERIMENTS`), and
compares each student's hand-in with the next student's (the neighbour).

Examples
--------
>>> res = run_grading_study(GradingStudyConfig("lse", n_students=4, experiment="sound"))
>>> res.n_students, sorted(res.band_median)
(4, ['Af', 'B', 'M', 'beta_e'])
>>> 0.0 <= res.honest_rejected <= 1.0 and 0.0 <= res.neighbour_rejected <= 1.0
True
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ._checks import not_allowed
from .cancel import Cancelled, CancelToken, check
from .exercise import Exercise
from .params import ActuatorParams

__all__ = ["GradingStudyConfig", "GradingStudyResult", "run_grading_study", "ROUTES", "EXPERIMENTS",
           "study_exercise", "route_estimate", "lse_model_error", "frequency_model_error", "greybox_model_error"]

#: The routes a hand-in comes from, and the parameters each hands in.
ROUTES = {"lse": ("M", "B", "Af", "beta_e"), "frequency": ("beta_e",), "greybox": ("M", "B", "Af", "beta_e")}
#: The two experiments per route: the page's default run, and a sound one (the student's choices).
EXPERIMENTS = {
    "lse": {"default": "the paper's input u = 6 sin(4πt), 5 s, least squares",
            "sound": "the rich input 8 sin(4πt) + 4 sin(10πt), 20 s, instrumental variables"},
    "frequency": {"default": "the paper's experiment, βe backed out (eq. 27) with the paper's M, B, Af",
                  "sound": "the paper's experiment, βe backed out with the student's own M, B, Af (identified "
                           "by another route; the study takes the truth)"},
    "greybox": {"default": "the paper's input, 5 s, x, p1, p2 measured, started from the paper's values",
                "sound": "the rich input, 20 s, x, p1, p2 measured, started from the paper's values"},
}
#: The default study's exercise secret (fixed: the same students every run).
_SECRET = "5eed" * 16


def study_exercise(**changes) -> Exercise:
    """The exercise a study grades: ``eha exercise new``'s defaults (M, B, Af, βe hidden, 25 % variation,
    the default conditions; tolerance 5 %, B 10 %; zscore grading at k = 3, floor 0.5 %; the last hand-in
    counts), a fixed secret, and ``changes`` (fields of :class:`Exercise`)."""
    ex = Exercise.new(hide=("M", "B", "Af", "beta_e"), tolerance={"B": 0.10}, secret=_SECRET)
    return ex.replace(**changes) if changes else ex


#: The least squares' model error is a mean over this many records (its own spread is then half a
#: standard error: the acceptance of an honest estimate widens by about 12 %).
LSE_REFERENCE_RECORDS = 4


def lse_model_error(truth: ActuatorParams, u, t_end: float, disturbance, *, harmonic: bool | None = None,
                    measured=("x", "v", "p1", "p2"), noise: dict | None = None, seed: int = 0,
                    records: int = LSE_REFERENCE_RECORDS, cancel: CancelToken | None = None) -> dict[str, float]:
    """The least squares' own error on an experiment (SI, mean estimate minus truth per parameter): the
    route at its best (instrumental variables; the harmonic disturbance model when the load ``disturbance``,
    signal text or a Signal, holds a sinusoid; ``harmonic`` says so for a Signal) on ``records`` records of
    ``truth`` with the input ``u`` for ``t_end`` s, the sensor ``noise`` (σ per signal, SI) and the load
    realisation of ``seed``, each with noise of its own. It is the error no choice of the student's
    removes: the regression's Coulomb term (eq. 15) sees the noise of the measured v through a
    nonlinearity (B and Af come out about a standard error apart, in opposite directions, at the default
    noise floors), and the record's start is not steady.

    Parameters
    ----------
    truth : ActuatorParams
        The student's actuator.
    u, t_end
        The input (a Signal) and the record's length [s].
    disturbance : str or Signal
        The load as the student's record has it.
    harmonic : bool, optional
        Whether the load holds a sinusoid (default: read from ``disturbance``'s text).
    measured : tuple of str
        The signals measured (without v, v is dx/dt of the measured x).
    noise : dict, optional
        σ of each sensor (SI).
    seed : int
        The load's noise seed (the student's).
    records : int
        Records averaged.
    cancel : CancelToken, optional
        Checked in the simulations and the estimator.
    """
    import dataclasses

    from . import experiments as E
    from .identify.lse import identify_lse

    if harmonic is None:
        harmonic = "sine" in str(disturbance).lower()
    model = "harmonic" if harmonic else "constant"
    sums: dict[str, float] = {}
    for r in range(max(1, records)):
        # the load as the student's record has it (seed), the sensors' noise of a record of its own
        data = E.lse_data(truth, disturbance, u=u, t_end=t_end, seed=seed, cancel=cancel)
        if noise:
            data = data.with_noise(noise, seed=10_007 * (r + 1) + seed)
        if "v" not in measured:
            data = dataclasses.replace(data, v=np.gradient(data.x, data.t))
        res = identify_lse(data, truth, estimator="iv", disturbance_model=model, cancel=cancel)
        for n in ROUTES["lse"]:
            if n in res.estimates:
                sums[n] = sums.get(n, 0.0) + float(res.estimates[n]) - float(getattr(truth, n))
    return {n: s / max(1, records) for n, s in sums.items()}


def frequency_model_error(truth: ActuatorParams, config, cancel: CancelToken | None = None) -> dict[str, float]:
    """The frequency route's own model error (SI, βe minus truth): the experiment ``config``
    (:class:`~eha_core.experiments.FrequencyExperiment`) without sensor noise on ``truth``, βe backed out
    from the s coefficient (eq. 27b-d) with the true M, B, Af. Eq. 27 holds for the linearised plant; the
    friction's slope at v = 0 is not what the experiment's velocities see (docs/model.md), so the backed-out
    βe is off by a fraction of a percent that depends on the actuator, whatever the student does.

    Parameters
    ----------
    truth : ActuatorParams
        The student's actuator.
    config : FrequencyExperiment
        The student's experiment.
    cancel : CancelToken, optional
        Checked in the simulation and tfest.
    """
    import dataclasses

    from . import experiments as E
    from .identify.backout import backout
    from .linear import operating_point

    fi = E.run_frequency_identification(truth, dataclasses.replace(config, noise_x=0.0), cancel=cancel)
    if fi.open_loop is None:
        return {}
    b = backout(*fi.open_loop, truth, operating_point(truth), kp=fi.config.kp)
    return {"beta_e": float(b.beta_e_from_stiffness) - float(truth.beta_e)}


def greybox_model_error(truth: ActuatorParams, u, t_end: float, names, *, d=None, measured=("x", "p1", "p2"),
                        guess: ActuatorParams | None = None, cancel: CancelToken | None = None) -> dict[str, float]:
    """The grey-box's own error on an experiment (SI, estimate minus truth per parameter of ``names``): the
    estimate from a noise-free record of ``truth`` with the input ``u`` for ``t_end`` s, the load ``d``
    (a Signal or None) and the signals ``measured``, started from ``guess`` (the paper's values by
    default). On the paper's model it is 0 (the grey-box's model is the plant's) and not computed; on a
    variant (``truth.effects`` on: a lagging spool, leakage, Stribeck friction) the paper's model the
    grey-box fits cannot be the plant, and this is how far that alone moves the estimate.

    Parameters
    ----------
    truth : ActuatorParams
        The student's actuator (its ``effects`` included).
    u, t_end
        The input (a Signal) and the record's length [s].
    names : iterable of str
        The parameters estimated.
    d : Signal, optional
        The load, known to the model.
    measured : tuple of str
        The signals compared.
    guess : ActuatorParams, optional
        The initial values (and the model's other parameters), the paper's model's.
    cancel : CancelToken, optional
        Checked in the estimate.
    """
    effects = getattr(truth, "effects", None)
    if effects is None or effects.off:
        return {n: 0.0 for n in names}
    from .identify.greybox import greybox_data, identify_greybox

    data = greybox_data(truth, u, t_end=t_end, d=d, noise={}, seed=0, measured=tuple(measured))
    res = identify_greybox(data, tuple(names), measured=tuple(measured), guess=guess or ActuatorParams(),
                           cancel=cancel)
    return {n: float(res.estimates[n]) - float(getattr(truth, n)) for n in names if n in res.estimates}


@dataclass(frozen=True)
class GradingStudyConfig:
    """``route``: a key of :data:`ROUTES`; ``experiment``: "default" or "sound" (:data:`EXPERIMENTS`);
    ``n_students`` students; ``exercise``: the exercise (default :func:`study_exercise`)."""

    route: str = "greybox"
    n_students: int = 200
    experiment: str = "sound"
    exercise: Exercise | None = field(default=None, repr=False)

    def __post_init__(self):
        if self.route not in ROUTES:
            raise not_allowed("route", self.route, f"one of {', '.join(ROUTES)}")
        if self.experiment not in ("default", "sound"):
            raise not_allowed("experiment", self.experiment, "default or sound")
        if not (isinstance(self.n_students, int) and 2 <= self.n_students <= 5000):
            raise not_allowed("students", self.n_students, "a whole number in 2-5000 (each compared with the next)")


def route_estimate(route: str, experiment: str, exercise: Exercise, student: str, seed: int,
                   cancel: CancelToken | None = None) -> tuple[dict, dict, dict]:
    """``(estimates, standard errors, the route's model error)`` (SI) of ``student``'s own actuator by
    ``route`` with ``experiment``, under the exercise's conditions (its noise floors and disturbance),
    noise seed ``seed``: what the server computes for that student's hand-in. A failed estimate (the
    grey-box's checks) gives no standard errors; the grey-box has no model error of its own (its model
    is the plant's).

    Parameters
    ----------
    route : str
        A key of :data:`ROUTES`.
    experiment : str
        "default" or "sound" (:data:`EXPERIMENTS`).
    exercise : Exercise
        The exercise (its conditions and the student's actuator).
    student : str
        The student's id.
    seed : int
        The noise seed of the student's record.
    cancel : CancelToken, optional
        Checked in every computation.
    """
    from . import experiments as E
    from .signals import parse_signal

    truth = exercise.student_params(student)
    cond = exercise.conditions
    noise = dict(cond.noise)
    sound = experiment == "sound"
    disturbance = cond.disturbance
    if route == "lse":
        from .identify.lse import identify_lse

        u, t_end = (E.LSE_INPUT_RICH, E.LSE_INPUT_RICH_T_END) if sound else (E.LSE_INPUT, 5.0)
        data = E.lse_data(truth, disturbance, u=u, t_end=t_end, seed=seed, measurement_noise=noise, cancel=cancel)
        res = identify_lse(data, truth, estimator="iv" if sound else "ls", cancel=cancel)
        names = [n for n in ROUTES[route] if n in res.estimates]
        model = lse_model_error(truth, u, t_end, disturbance, measured=cond.measured, noise=noise, seed=seed,
                                cancel=cancel)
        return ({n: float(res.estimates[n]) for n in names}, {n: float(res.std_errors[n]) for n in names}, model)
    if route == "greybox":
        from .identify.greybox import greybox_data, identify_greybox

        u, t_end = (E.LSE_INPUT_RICH, E.LSE_INPUT_RICH_T_END) if sound else (E.LSE_INPUT, 5.0)
        measured = tuple(s for s in ("x", "p1", "p2") if s in cond.measured)
        d = parse_signal(disturbance, name="disturbance", seed=seed, hold_s=1e-3)
        data = greybox_data(truth, u, t_end=t_end, d=d, noise={s: noise.get(s, 0.0) for s in measured}, seed=seed,
                            measured=measured)
        res = identify_greybox(data, ROUTES[route], measured=measured, guess=ActuatorParams(), cancel=cancel)
        est = {n: float(res.estimates[n]) for n in ROUTES[route] if n not in res.held}
        model = greybox_model_error(truth, u, t_end, tuple(est), d=d, measured=measured, cancel=cancel)
        return est, ({n: float(res.std_errors[n]) for n in est} if res.success else {}), model
    from .identify.backout import backout
    from .linear import operating_point

    config = E.FrequencyExperiment(noise_x=noise.get("x", 0.0), seed=seed, disturbance=disturbance)
    fi = E.run_frequency_identification(truth, config, cancel=cancel)
    if fi.open_loop is None:
        return {}, {}, {}
    assumed = truth if sound else ActuatorParams()
    b = backout(*fi.open_loop, assumed, operating_point(assumed), std_h=fi.estimate.param_std, kp=fi.config.kp)
    return ({"beta_e": float(b.beta_e_from_stiffness)}, {"beta_e": float(b.beta_e_from_stiffness_std)},
            frequency_model_error(truth, config, cancel))


@dataclass(frozen=True)
class GradingStudyResult:
    """What :func:`run_grading_study` found (fractions in [0, 1]).

    ``honest_rejected``: of the values the students' own records determine to the lab's precision, the
    fraction refused (outside k standard errors and the floor); ``imprecise``: of all values handed
    in, the fraction whose record does not determine them to the tolerance; ``honest_accepted``: the
    hand-ins accepted on every parameter; ``neighbour_rejected``: the hand-ins of a neighbour's values
    refused on at least one parameter; ``spray_score``: the mean score of a student handing in the
    paper's values times 0.84, 1.00 and 1.17 (with their own record's standard errors) under the
    exercise's score rule, ``one_guess_score`` that of the middle guess alone; ``band_median``: per
    parameter, the median acceptance half-width relative to the estimate; ``z``: every (student,
    parameter) z-score."""

    config: GradingStudyConfig
    n_students: int
    honest_rejected: float
    imprecise: float
    honest_accepted: float
    neighbour_rejected: float
    spray_score: float
    one_guess_score: float
    band_median: dict
    z: dict
    failures: int
    time_s: float
    cancelled: bool = False

    def summary(self) -> str:
        """One line, as the command line prints it."""
        bands = ", ".join(f"{n} ±{100 * b:.3g} %" for n, b in self.band_median.items())
        return (f"route={self.config.route} experiment={self.config.experiment} students={self.n_students} "
                f"honest_rejected={100 * self.honest_rejected:.1f}% imprecise={100 * self.imprecise:.1f}% "
                f"honest_accepted={100 * self.honest_accepted:.1f}% "
                f"neighbour_rejected={100 * self.neighbour_rejected:.1f}% spray_score={self.spray_score:.3f} "
                f"one_guess_score={self.one_guess_score:.3f} failures={self.failures} acceptance: {bands}")

    def to_dict(self) -> dict:
        """The figures as plain JSON-able values (the z-scores left out)."""
        return {"route": self.config.route, "experiment": self.config.experiment, "students": self.n_students,
                "honest_rejected": self.honest_rejected, "imprecise": self.imprecise,
                "honest_accepted": self.honest_accepted, "neighbour_rejected": self.neighbour_rejected,
                "spray_score": self.spray_score, "one_guess_score": self.one_guess_score,
                "band_median": dict(self.band_median), "failures": self.failures, "time_s": self.time_s,
                "cancelled": self.cancelled}


def run_grading_study(config: GradingStudyConfig | None = None, *, workers: int = 2,
                      progress: Callable[[int, int], None] | None = None,
                      cancel: CancelToken | None = None) -> GradingStudyResult:
    """Grade ``config.n_students`` students of the exercise by one route (see the module's text).

    Parameters
    ----------
    config : GradingStudyConfig, optional
        The route, the experiment, the students, the exercise.
    workers : int
        Threads running the students.
    progress : callable, optional
        ``progress(done, total)``, called after each student.
    cancel : CancelToken, optional
        Stops the study, which then reports the students done (``cancelled`` True).
    """
    config = config if config is not None else GradingStudyConfig()
    ex = config.exercise if config.exercise is not None else study_exercise()
    t0 = time.perf_counter()
    ids = [f"student{i}" for i in range(config.n_students)]
    out: list = [None] * len(ids)

    def one(i):
        check(cancel)
        try:
            return route_estimate(config.route, config.experiment, ex, ids[i], i, cancel)
        except Cancelled:
            raise
        except (ValueError, ArithmeticError, RuntimeError):
            return None             # counted as a failure (the route's own error)

    done = 0
    cancelled = False
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        futures = {pool.submit(one, i): i for i in range(len(ids))}
        for fut in futures:
            try:
                out[futures[fut]] = fut.result()
            except Cancelled:                   # keep what was done
                cancelled = True
                for f in futures:
                    f.cancel()
                break
            done += 1
            if progress is not None:
                progress(done, len(ids))
    ok = [i for i, o in enumerate(out) if o is not None and o[0]]
    failures = len(ids) - len(ok) if not cancelled else sum(1 for o in out if o is not None and not o[0])
    determined = rejected = imprecise = values = accepted = 0
    bands: dict[str, list] = {}
    zs: dict[str, list] = {}
    for i in ok:
        est, se, me = out[i]
        judged = ex.judge(ids[i], est, se, me)
        whole = True
        for n in est:
            j = judged[n]
            values += 1
            if j.reason == "imprecise" or j.reason == "no-error":
                imprecise += 1
                whole = False
            else:
                determined += 1
                rejected += not j.ok
                whole = whole and j.ok
            if j.band is not None:
                bands.setdefault(n, []).append(j.band)
            if j.z is not None:
                zs.setdefault(n, []).append(j.z)
        accepted += whole
    # a neighbour's values: student i hands in student i+1's estimates with their record's errors
    pairs = [(i, k) for i, k in zip(ok, ok[1:] + ok[:1], strict=True) if i != k]
    # (judged on the parameters the route hands in: the others are missing from any of its hand-ins)
    # (the model error is the server's, for the student who hands in: their own actuator's)
    copied_refused = sum(1 for i, k in pairs
                         if not all(ok_ for n, ok_ in ex.verdicts(ids[i], out[k][0], out[k][1], out[i][2]).items()
                                    if n in out[k][0]))
    # spraying: three guesses around the paper's values, with the student's own record's errors
    paper = ActuatorParams()
    spray, single = [], []
    for i in ok:
        est, se, me = out[i]
        guesses = [{n: getattr(paper, n) * f for n in est} for f in (0.84, 1.00, 1.17)]
        spray.append(ex.score([ex.verdicts(ids[i], g, se, me) for g in guesses]))
        single.append(ex.score([ex.verdicts(ids[i], guesses[1], se, me)]))
    n_ok = max(len(ok), 1)
    return GradingStudyResult(
        config=config, n_students=len(ok), honest_rejected=rejected / max(determined, 1),
        imprecise=imprecise / max(values, 1), honest_accepted=accepted / n_ok,
        neighbour_rejected=copied_refused / max(len(pairs), 1),
        spray_score=float(np.mean(spray)) if spray else math.nan,
        one_guess_score=float(np.mean(single)) if single else math.nan,
        band_median={n: float(np.median(b)) for n, b in bands.items()}, z={n: list(v) for n, v in zs.items()},
        failures=failures, time_s=time.perf_counter() - t0, cancelled=cancelled)
