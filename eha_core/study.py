"""A study: one experiment repeated over many noise seeds, to see an estimator's spread.

A single run gives an estimate and a standard error; only repetition shows
whether the standard error is honest. A study runs the same experiment with
seeds ``first_seed .. first_seed + n_seeds - 1`` and reports, per parameter,
the mean and spread of the estimates, the mean reported standard error, and
the *coverage*: the fraction of seeds whose 95 % interval contains the truth.
An honest interval covers in about 95 % of the seeds
(:func:`coverage_band` gives the range a binomial count allows).

Two experiments (:class:`StudyConfig`, ``kind``):

``"lse"``
    The least squares of docs/model.md §4 (eqs. 15-18): the nonlinear plant
    under a load disturbance written as signal text (``white:1000``,
    ``sine:5000:1``, ``none``), optional white sensor noise, identified with
    the constant or harmonic disturbance model. Seed k draws the
    disturbance's noise exactly as ``run_lse(seed=k)`` does (and
    ``eha identify lse --seed k``). The truth is the parameters simulated.
    The estimator is the paper's least squares (``estimator="ls"``) or
    instrumental variables (``"iv"``, unbiased under the noisy load force
    that biases M and beta_e of the least squares): the study's ``bias``,
    against the reported standard errors (``bias_per_std_error``) and against
    its own Monte Carlo error (:meth:`StudyResult.biased`), tells which is
    biased.
``"tf"``
    The paper's closed-loop experiment (docs/model.md §4, eqs. 19-25): seed k
    draws the idinput excitation (as ``eha identify tf --seed k``) and the
    white noise added to the recorded position; H(s) = b0 / (s^3 + a1 s^2 +
    a2 s + a3) is estimated by tfest. The nominal values are the linearised
    closed loop H(s) of eq. 24. With the linear plant (``model="linear"``)
    that is the truth: the loop is simulated on the u >= 0 valve branch, the
    branch H(s) is computed on, so the plant is the linear system H(s)
    describes (the paper's Fig. 3 switches the branch with the sign of u,
    which biases b0 by half a standard error at noise_m = 0.1 mm). The
    controller still reads x every Ts (ZOH, the paper's): the sampled loop
    departs from H(s) by under 1 % of a standard error at 0.1 mm (a bias
    that grows as 1 / noise_m; the experiment's ``controller="continuous"``
    removes it). With the nonlinear plant no transfer function is exact:
    H(s) is a *reference* and the result says so (``nominal_is_truth``
    False); its s^2 coefficient is far from what the data give (see
    :mod:`eha_core.identify.backout`).

The seeds run on a thread pool (:func:`run_study`, ``workers``, default 2).
:func:`run_study` blocks its caller until the study ends: a web app calls it
from a thread of its own, as it runs every computation.
``progress(done, total)`` is called in that calling thread after every seed;
a :class:`~eha_core.cancel.CancelToken` stops the study, which then returns
the seeds completed (``cancelled`` True) instead of raising. Seed k gives the
same estimate whatever the number of workers: every seed's random numbers
come from its own generators.

The threads speed the least squares up little. Numba's kernels and numpy's
element-wise passes release the GIL, but about half of identify_lse's time
holds it: scipy's CubicSpline, built and evaluated five times for the
16-times-finer grid (``_fine_grid``), and numpy's matmul (``@``) in the
Newey-West sums (``_solve``). On this project's two cores two threads ran
0.85-1.15 times as fast as one; a least-squares seed costs 20-30 ms, so 200
seeds take 4-6 s all the same. Nor does tfest gain (0.97): its time goes to
thousands of small calls (filters, eigenvalues, matrix exponentials on a
1000-sample record), each holding the GIL for its overhead.

Examples
--------
>>> from eha_core.study import StudyConfig, run_study
>>> res = run_study(StudyConfig("lse", n_seeds=4, disturbance="white:1000"))
>>> res.n_completed, sorted(res.coverage)
(4, ['Af', 'B', 'M', 'beta_e', 'd0'])
>>> abs(res.mean["M"] / res.nominal["M"] - 1) < 0.01
True
>>> coverage_band(100)
(0.89, 1.0)
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Mapping
from concurrent.futures import CancelledError, ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from ._checks import ComputationError, not_allowed, shown
from .cancel import Cancelled, CancelToken, check
from .experiments import LSE_INPUT, FrequencyExperiment
from .identify._stats import Z95
from .params import ActuatorParams
from .signals import Constant, Signal, Sine, Sum, WhiteNoise, parse_signal

__all__ = ["STUDY_KINDS", "MAX_SEEDS", "MAX_WORKERS", "DEFAULT_WORKERS", "TF_PARAMETERS", "StudyConfig",
           "SeedEstimate", "StudyResult", "run_study", "combine_studies", "coverage_band", "estimated_parameters"]

#: The experiments a study repeats.
STUDY_KINDS = ("lse", "tf", "greybox")
#: Seeds in one study at most: 1000 least-squares seeds take about 25-30 s
#: on this project's two cores (with the IV estimator 1-2 minutes), 1000
#: transfer-function seeds 2-4 minutes.
MAX_SEEDS = 1000
#: Worker threads at most (more than the cores only adds contention).
MAX_WORKERS = 16
DEFAULT_WORKERS = 2
#: The transfer-function study's coefficients: H(s) = b0 / (s^3 + a1 s^2 + a2 s + a3).
TF_PARAMETERS = ("a1", "a2", "a3", "b0")
#: Sensors that may carry white noise in the least-squares study.
_SENSORS = ("x", "v", "p1", "p2")
#: Streams of a seed's generators besides the disturbance's (which is
#: default_rng(seed), as in run_lse): each is SeedSequence([seed, stream]),
#: independent of the disturbance and of every other seed's streams.
#: (lse_data would draw the sensor noise from default_rng(seed + 1), the
#: disturbance stream of the next seed: the two runs would share their draws.)
_SENSOR_STREAM = 1
_POSITION_STREAM = 2


def _stream(seed: int, stream: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([int(seed), stream])


def _terms(sig: Signal) -> list[Signal]:
    """The terms of a sum of signals (a signal that is no sum is one term)."""
    if isinstance(sig, Sum):
        return [t for term in sig.terms for t in _terms(term)]
    return [sig]


def coverage_band(n: int, level: float = 0.95, probability: float = 0.99) -> tuple[float, float]:
    """The coverage fractions an honest interval gives in ``n`` seeds, with ``probability``.

    The number of seeds whose ``level`` interval covers the truth is
    Binomial(n, level) when the intervals are exact and the seeds
    independent. Returned: the lowest and highest fraction k/n such that
    each tail beyond them holds at most (1 - probability) / 2 (exact
    binomial sums, no normal approximation: few seeds are allowed).

    Examples
    --------
    >>> coverage_band(20)
    (0.8, 1.0)
    >>> coverage_band(1000)
    (0.931, 0.967)
    """
    n = int(n)
    if n < 1:
        raise not_allowed("n", n, "must be a whole number >= 1")
    tail = (1.0 - probability) / 2.0
    pmf = [math.comb(n, k) * level**k * (1.0 - level) ** (n - k) for k in range(n + 1)]
    lo, below = 0, 0.0
    while below + pmf[lo] <= tail:
        below += pmf[lo]
        lo += 1
    hi, above = n, 0.0
    while above + pmf[hi] <= tail:
        above += pmf[hi]
        hi -= 1
    return lo / n, hi / n


@dataclass(frozen=True)
class StudyConfig:
    """What a study repeats, checked at construction.

    Parameters
    ----------
    kind : {'lse', 'tf'}
        Least squares (eqs. 15-18) or the closed-loop transfer-function
        estimate (eqs. 19-25).
    n_seeds : int
        Runs, 1 to :data:`MAX_SEEDS`.
    first_seed : int
        Seed of the first run (>= 0); run i has seed ``first_seed + i``.
    disturbance : str, optional
        ``lse``: the load disturbance d(t) as signal text
        (:func:`eha_core.signals.parse_signal`), default ``white:1000`` (the
        paper's white-noise scenario); its noise terms must not carry a seed
        of their own (they take the run's). ``tf``: ``none`` (the default).
    disturbance_model : {'constant', 'harmonic'}
        ``lse``: d0 alone (the paper's) or d0 plus a sinusoid.
    disturbance_freq_hz : float, optional
        ``lse``, harmonic model: its frequency, estimated per seed when None.
    sensor_noise : mapping, optional
        ``lse``: standard deviation of white noise per sensor, in SI units,
        e.g. ``{"p1": 1e4, "p2": 1e4}`` (sensors x, v, p1, p2; as the app's
        measurement noise). Stored as sorted ``(sensor, sigma)`` pairs.
    u : Signal or str
        ``lse``: the valve command (default the paper's 6 sin(4 pi t)).
    t_end : float
        ``lse``: record length [s] (0 < t_end <= 600).
    tau_f : float
        ``lse``: prefilter time constant [s] (eq. 17).
    estimator : {'ls', 'iv'}
        ``lse``: the paper's least squares (default) or instrumental
        variables (:func:`eha_core.identify.lse.identify_lse`).
    intervals : {'newey-west', 'ewc'}, optional
        ``lse``: how the standard errors and intervals are computed; None
        (the default) takes the estimator's own (Newey-West for ``ls``,
        equal-weighted cosines for ``iv``), and is stored as that.
    experiment : FrequencyExperiment, optional
        ``tf``: the closed-loop experiment (excitation, Ts, Kp, controller,
        plant model, initial condition and input offset); its ``seed`` is
        replaced by each run's. Must have 3 poles and no zero (the form of
        eq. 24).
    noise_m : float
        ``tf``: standard deviation of the white noise added to the recorded
        position [m] (default 0.1 mm, a fit near 98 % on the linear plant).
        The loop is closed on the true position: a noisy feedback would
        colour the output noise through the loop, and tfest's covariance
        assumes white output noise.
    """

    kind: str = "lse"
    n_seeds: int = 100
    first_seed: int = 0
    disturbance: str | None = None
    disturbance_model: str = "constant"
    disturbance_freq_hz: float | None = None
    sensor_noise: tuple[tuple[str, float], ...] | Mapping[str, float] | None = ()
    u: Signal | str = LSE_INPUT
    t_end: float = 5.0
    tau_f: float = 0.01
    experiment: FrequencyExperiment | None = None
    noise_m: float = 1e-4
    estimator: str = "ls"
    intervals: str | None = None
    greybox: object | None = None

    def __post_init__(self):
        from .identify.disturbance import DISTURBANCE_MODELS, MAX_FREQ_HZ

        def whole(name, lo, hi, what):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise not_allowed(name, v, what)
            object.__setattr__(self, name, int(v))

        if self.kind not in STUDY_KINDS:
            raise not_allowed("kind", self.kind, "use lse (least squares), tf (transfer function) or greybox")
        if self.disturbance is None:
            object.__setattr__(self, "disturbance", "white:1000" if self.kind == "lse" else "none")
        whole("n_seeds", 1, MAX_SEEDS, f"use 1 to {MAX_SEEDS} seeds")
        whole("first_seed", 0, 2**32 - 1 - MAX_SEEDS, f"use a whole number from 0 to {2**32 - 1 - MAX_SEEDS}")
        if self.disturbance_model not in DISTURBANCE_MODELS:
            raise not_allowed("disturbance_model", self.disturbance_model,
                              f"use one of {', '.join(DISTURBANCE_MODELS)}")
        f = self.disturbance_freq_hz
        if f is not None and not (isinstance(f, (int, float)) and math.isfinite(f) and 0 < f < MAX_FREQ_HZ):
            raise not_allowed("disturbance_freq_hz", f, f"must be a frequency in (0, {MAX_FREQ_HZ:g}) Hz, "
                                                        "or None to estimate it")
        self._check_sensor_noise()
        object.__setattr__(self, "u", parse_signal(self.u, name="u"))
        for name, hi in (("t_end", 600.0), ("tau_f", math.inf)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= hi):
                raise not_allowed(name, v, "must be a time > 0 s" + (f" and at most {hi:g} s" if hi < math.inf
                                                                      else ""))
        if not (isinstance(self.noise_m, (int, float)) and math.isfinite(self.noise_m) and self.noise_m >= 0):
            raise not_allowed("noise_m", self.noise_m, "must be a standard deviation >= 0 m")
        self._check_estimator()
        if self.kind == "lse":
            self._check_disturbance()
        elif self.kind == "tf":
            self._check_tf_noise()
        else:
            self._check_greybox()
        exp = self.experiment if self.experiment is not None else FrequencyExperiment()
        if not isinstance(exp, FrequencyExperiment):
            raise not_allowed("experiment", exp, "must be a FrequencyExperiment")
        if (exp.n_poles, exp.n_zeros) != (3, 0):
            raise not_allowed("experiment.n_poles", exp.n_poles,
                              "the study compares with the linearised H(s) of eq. 24: 3 poles and no zero")
        object.__setattr__(self, "experiment", exp)

    def _check_sensor_noise(self) -> None:
        """``sensor_noise`` as sorted ``(sensor, sigma)`` pairs (hashable), zeros left out."""
        noise = self.sensor_noise or ()
        pairs = sorted(noise.items() if isinstance(noise, Mapping) else noise)
        for name, sigma in pairs:
            if name not in _SENSORS:
                raise not_allowed(f"sensor_noise[{shown(name)}]", sigma,
                                  f"{shown(name)} is not a sensor; use {', '.join(_SENSORS)}")
            if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma >= 0):
                raise not_allowed(f"sensor_noise[{name}]", sigma,
                                  "must be a standard deviation >= 0 (in the sensor's SI unit)")
        object.__setattr__(self, "sensor_noise", tuple((n, float(s)) for n, s in pairs if s > 0))

    def _check_estimator(self) -> None:
        """The least squares' estimator and intervals (stored resolved); the transfer function has its own."""
        from .identify.lse_choices import checked_choices

        estimator, intervals = checked_choices(self.estimator, self.intervals)
        if self.kind != "lse" and (estimator, self.intervals) != ("ls", None):
            name, value = ("estimator", estimator) if estimator != "ls" else ("intervals", intervals)
            own = ("the transfer-function study's estimator is tfest" if self.kind == "tf"
                   else "the grey-box study's estimator is the grey-box estimate")
            raise not_allowed(name, value, f"{own}, with its own standard errors; leave estimator and intervals "
                                           "to the least squares")
        if self.kind == "lse":
            object.__setattr__(self, "intervals", intervals)

    def _check_tf_noise(self) -> None:
        """The transfer-function study's noise is the position sensor's alone."""
        if parse_signal(self.disturbance, name="disturbance") != Constant(0.0):
            raise not_allowed("disturbance", self.disturbance,
                              "the transfer-function study has no load disturbance; use none (its noise is "
                              "the position sensor's, noise_m)")
        if self.sensor_noise:
            raise not_allowed("sensor_noise", dict(self.sensor_noise),
                              "the transfer-function study's only sensor is the position; use noise_m")

    def _check_greybox(self) -> None:
        """The grey-box study: its experiment (parameters, signals, noise) in a GreyBoxStudyConfig; its
        load is the one the model knows, its noise the sensors' at the experiment's SNR."""
        from .identify.greybox_study import GreyBoxStudyConfig

        g = self.greybox if self.greybox is not None else GreyBoxStudyConfig()
        if not isinstance(g, GreyBoxStudyConfig):
            raise not_allowed("greybox", g, "must be a GreyBoxStudyConfig")
        if parse_signal(self.disturbance, name="disturbance") != Constant(0.0):
            raise not_allowed("disturbance", self.disturbance, "the grey-box study's load is its experiment's, "
                                                               "known to the model; use none")
        if self.sensor_noise:
            raise not_allowed("sensor_noise", dict(self.sensor_noise), "the grey-box study's noise is set by "
                                                                       "its experiment's snr_db")
        object.__setattr__(self, "greybox", g)

    def _check_disturbance(self) -> None:
        """Refuse a disturbance whose noise would be the same in every run."""
        first = parse_signal(self.disturbance, name="disturbance", seed=0)
        second = parse_signal(self.disturbance, name="disturbance", seed=1)
        fixed = [a for a, b in zip(_terms(first), _terms(second), strict=True)
                 if isinstance(a, WhiteNoise) and a.seed == b.seed]
        if fixed:
            raise not_allowed("disturbance", self.disturbance,
                              f"its noise term {fixed[0].spec} has a seed of its own and would be the same in "
                              "every run; leave the seed out (run k draws seed k)")

    @property
    def model(self) -> str:
        """The plant: ``nonlinear`` for the least squares, the experiment's for ``tf``."""
        return self.experiment.model if self.kind == "tf" else "nonlinear"

    @property
    def seed_range(self) -> range:
        """The seeds the study runs: ``first_seed .. first_seed + n_seeds - 1``."""
        return range(self.first_seed, self.first_seed + self.n_seeds)

    def to_dict(self) -> dict:
        """The settings as plain values (JSON-ready), those of ``kind`` only."""
        out = {"kind": self.kind, "n_seeds": self.n_seeds, "first_seed": self.first_seed, "model": self.model}
        if self.kind == "lse":
            out.update(disturbance=self.disturbance, disturbance_model=self.disturbance_model,
                       disturbance_freq_hz=self.disturbance_freq_hz, sensor_noise=dict(self.sensor_noise),
                       u=self.u.spec, t_end_s=self.t_end, tau_f_s=self.tau_f, estimator=self.estimator,
                       intervals=self.intervals)
        elif self.kind == "greybox":
            g = self.greybox
            out.update(params=list(g.params), measured=list(g.measured), snr_db=g.snr_db, t_end_s=g.t_end, dt_s=g.dt)
        else:
            e = self.experiment
            out.update(noise_m=self.noise_m, n_samples=e.n_samples, ts_s=e.ts, kp=e.kp,
                       signal_type=e.signal_type, controller=e.controller,
                       initial_condition=e.initial_condition, input_offset=e.input_offset)
        return out


def _finite_or_none(d: Mapping[str, float]) -> dict[str, float | None]:
    # NaN is not JSON: a statistic without data is null
    return {k: (float(v) if math.isfinite(v) else None) for k, v in d.items()}


@dataclass(frozen=True)
class SeedEstimate:
    """One run of a study: its estimates and their standard errors, by parameter.

    ``success`` False (``message`` says why: the estimator's message, or the
    simulation's failure) leaves the seed out of the statistics.
    ``elapsed_s`` is the run's wall time in its worker thread.
    ``critical_value`` is the multiple of the standard error that makes the
    run's 95 % interval: 1.96 (normal), or Student's t quantile for the
    least squares' ``ewc`` intervals.
    """

    seed: int
    estimates: dict[str, float]
    std_errors: dict[str, float]
    success: bool
    message: str
    elapsed_s: float
    critical_value: float = Z95
    intervals: tuple[tuple[str, float, float], ...] = ()

    def interval(self, name: str) -> tuple[float, float]:
        """The 95 % interval of ``name``: the estimator's own where it gave one (the grey-box estimate's
        of a positive parameter is its logarithm's), else ``estimate +- critical_value * std_error``."""
        for n, lo, hi in self.intervals:
            if n == name:
                return lo, hi
        e, s = self.estimates[name], self.std_errors[name]
        return e - self.critical_value * s, e + self.critical_value * s

    def covers(self, name: str, value: float) -> bool:
        """Whether the 95 % interval of ``name`` contains ``value``."""
        lo, hi = self.interval(name)
        return bool(lo <= value <= hi)

    def usable(self, name: str) -> bool:
        """A successful run with a finite estimate and standard error of ``name``."""
        return (self.success and name in self.estimates and math.isfinite(self.estimates[name])
                and math.isfinite(self.std_errors.get(name, math.nan)))

    def to_dict(self) -> dict:
        """The run as plain values (JSON-ready; a failed run's missing numbers are None)."""
        return {"seed": self.seed, "estimates": _finite_or_none(self.estimates),
                "std_errors": _finite_or_none(self.std_errors), "critical_value": self.critical_value,
                "success": self.success, "message": self.message, "elapsed_s": self.elapsed_s,
                **({"ci95": {n: [lo, hi] for n, lo, hi in self.intervals}} if self.intervals else {})}


@dataclass(frozen=True, eq=False)
class StudyResult:
    """A study's seeds and what they say together.

    Attributes
    ----------
    config : StudyConfig
    params : ActuatorParams
        The parameters simulated.
    parameters : tuple of str
        The estimated parameters, in the estimator's order.
    nominal : dict
        The value each interval is checked against: the truth (``lse``; ``tf``
        on the linear plant) or the linearised H(s)'s coefficient (``tf`` on
        the nonlinear plant: a reference). Parameters without a known value
        (e.g. d0 under a step disturbance) are absent.
    nominal_is_truth : bool
    reference : str
        What ``nominal`` is, in one sentence.
    seeds : tuple of SeedEstimate
        The completed runs, by seed.
    n_requested, n_completed, n_failed : int
        Seeds asked for; seeds run to the end (successful or not); of those,
        the failed ones.
    mean, std, mean_std_error : dict
        Over the successful seeds, per parameter: the estimates' mean and
        sample standard deviation (ddof 1; NaN with fewer than 2 seeds), and
        the mean of the standard errors the estimator reported. An honest
        standard error has ``mean_std_error`` close to ``std``.
    coverage : dict
        Per parameter with a nominal value: the fraction of successful seeds
        whose 95 % interval contains it (NaN without a successful seed).
    bias, bias_std_error, bias_per_std_error : dict
        Per parameter with a nominal value: ``mean - nominal``; its Monte
        Carlo standard error ``std / sqrt(n)`` (how well the seeds pin the
        bias down); and the bias in units of the mean reported standard error
        (how far off the truth a single run sits, against its own interval's
        half-width of about 2 of those). NaN without the data for them (fewer
        than 2 seeds for the second). :meth:`biased` says whether the seeds
        show a bias.
    bound : dict
        ``greybox``: the Cramér-Rao bound per parameter (the smallest standard deviation an unbiased
        estimate can have on this experiment), to set ``std`` against; empty for the others.
    elapsed_s : float
        Wall time of the study [s].
    workers : int
    cancelled : bool
        The study was stopped by its CancelToken; ``seeds`` holds those done.
    message : str
        ``ok``, or what the reader should know (cancelled, failed seeds,
        nominal values that are a reference, data without noise).
    """

    config: StudyConfig
    params: ActuatorParams
    parameters: tuple[str, ...]
    nominal: dict[str, float]
    nominal_is_truth: bool
    reference: str
    seeds: tuple[SeedEstimate, ...]
    n_requested: int
    n_completed: int
    n_failed: int
    mean: dict[str, float]
    std: dict[str, float]
    mean_std_error: dict[str, float]
    coverage: dict[str, float]
    elapsed_s: float
    workers: int
    cancelled: bool
    message: str
    bias: dict[str, float] = field(default_factory=dict)
    bias_std_error: dict[str, float] = field(default_factory=dict)
    bias_per_std_error: dict[str, float] = field(default_factory=dict)
    bound: dict[str, float] = field(default_factory=dict)

    def biased(self, name: str, probability: float = 0.99) -> bool:
        """Whether the seeds show that ``name``'s estimator is biased: ``|bias|`` beyond its two-sided
        ``probability`` band, ``z bias_std_error`` (z = 2.58 for 0.99). False without the data to tell."""
        from statistics import NormalDist

        if not 0 < probability < 1:
            raise not_allowed("probability", probability, "must be a probability in (0, 1)")
        bias, err = self.bias.get(name, math.nan), self.bias_std_error.get(name, math.nan)
        if not (math.isfinite(bias) and math.isfinite(err)):
            return False
        return abs(bias) > NormalDist().inv_cdf(0.5 + probability / 2) * err

    @property
    def n_successful(self) -> int:
        return self.n_completed - self.n_failed

    @property
    def seconds_per_seed(self) -> float:
        """Wall time per completed seed [s] (all workers together)."""
        return self.elapsed_s / self.n_completed if self.n_completed else math.nan

    def values(self, name: str) -> np.ndarray:
        """The successful seeds' estimates of ``name``, by seed."""
        return np.array([s.estimates[name] for s in self.seeds if s.usable(name)])

    def std_errors(self, name: str) -> np.ndarray:
        """The successful seeds' standard errors of ``name``, by seed."""
        return np.array([s.std_errors[name] for s in self.seeds if s.usable(name)])

    def coverage_band(self, probability: float = 0.99) -> tuple[float, float]:
        """:func:`coverage_band` for this study's successful seeds, holding with ``probability``."""
        return coverage_band(max(self.n_successful, 1), probability=probability)

    def to_dict(self) -> dict:
        """Everything as plain values (JSON-ready; a statistic without data is None)."""
        return {
            "kind": self.config.kind, "settings": self.config.to_dict(), "params": self.params.to_dict(),
            "parameters": list(self.parameters),
            "nominal": self.nominal, "nominal_is_truth": self.nominal_is_truth, "reference": self.reference,
            "n_seeds": self.n_requested, "n_completed": self.n_completed, "n_failed": self.n_failed,
            "mean": _finite_or_none(self.mean), "std": _finite_or_none(self.std),
            "mean_std_error": _finite_or_none(self.mean_std_error), "coverage": _finite_or_none(self.coverage),
            "bias": _finite_or_none(self.bias), "bias_std_error": _finite_or_none(self.bias_std_error),
            "bias_per_std_error": _finite_or_none(self.bias_per_std_error), "bound": _finite_or_none(self.bound),
            "coverage_band_99": list(self.coverage_band()) if self.n_successful else None,
            "elapsed_s": self.elapsed_s, "seconds_per_seed": None if not self.n_completed else self.seconds_per_seed,
            "workers": self.workers, "cancelled": self.cancelled, "message": self.message,
            "seeds": [s.to_dict() for s in self.seeds],
        }

    def to_pandas(self):
        """The statistics as a :class:`pandas.DataFrame` indexed by parameter: ``nominal`` (NaN where none
        is known), ``mean``, ``std``, ``mean_std_error``, ``coverage``, ``bias``, ``bias_std_error``,
        ``bias_per_std_error``, ``bound`` (the grey-box study's Cramér-Rao bound, else NaN), all SI, then
        ``unit``, ``display_unit``, ``display_scale``. The seeds themselves: :meth:`seeds_to_pandas`."""
        import pandas as pd

        from ._display import TF_UNITS, unit_columns

        names = list(self.parameters)
        cols = {c: [float(getattr(self, c).get(n, math.nan)) for n in names]
                for c in ("nominal", "mean", "std", "mean_std_error", "coverage", "bias", "bias_std_error",
                          "bias_per_std_error", "bound")}
        cols.update(unit_columns(names, TF_UNITS if self.config.kind == "tf" else None))
        return pd.DataFrame(cols, index=pd.Index(names, name="parameter"))

    def seeds_to_pandas(self):
        """One row per completed seed (indexed by seed): ``success``, then each parameter's estimate and its
        standard error (``NAME`` and ``NAME_std_error``, SI)."""
        import pandas as pd

        rows = [{"success": s.success, **{n: s.estimates.get(n, math.nan) for n in self.parameters},
                 **{f"{n}_std_error": s.std_errors.get(n, math.nan) for n in self.parameters}} for s in self.seeds]
        return pd.DataFrame(rows, index=pd.Index([s.seed for s in self.seeds], name="seed"))

    def __repr__(self) -> str:
        from ._display import block, in_units, short, with_error

        route = {"lse": f"least squares ({self.config.estimator})", "tf": "tfest on the closed loop",
                 "greybox": "grey box"}[self.config.kind]
        head = (f"StudyResult: {route}, {self.config.model} plant, seeds {self.config.first_seed}-"
                f"{self.config.first_seed + self.n_requested - 1}")
        state = f"{self.n_successful} of {self.n_requested} seeds successful" + (", cancelled" if self.cancelled
                                                                                  else "")
        items = []
        for n in self.parameters:
            mean, spread = self.mean.get(n, math.nan), self.std.get(n, math.nan)
            # one seed has no spread: its mean alone
            text = with_error(n, mean, spread) if math.isfinite(spread) else f"{n} = {in_units(n, mean, 6)}"
            cover = self.coverage.get(n, math.nan)
            items.append(f"{text} (s.e. {in_units(n, self.mean_std_error.get(n, math.nan), 3)}"
                         + (f", covers {cover:.0%})" if math.isfinite(cover) else ")"))
        notes = [f"mean ± std over the seeds, the mean reported s.e., the coverage of the 95 % intervals of "
                 f"{'the truth' if self.nominal_is_truth else 'a reference'}; .to_pandas(), .seeds_to_pandas()",
                 f"message: {short(self.message, 200)}"]
        return block(head, self.n_successful > 0, self.message, items, notes, passed=state)


# -- the experiments, one seed at a time -----------------------------------------------------


def estimated_parameters(config: StudyConfig) -> tuple[str, ...]:
    """The parameters a study of ``config`` estimates, in the estimator's order (known before any
    seed runs: a page draws the study's figures before its results come).

    >>> estimated_parameters(StudyConfig("lse"))
    ('M', 'B', 'Af', 'd0', 'beta_e')
    >>> estimated_parameters(StudyConfig("tf"))
    ('a1', 'a2', 'a3', 'b0')
    """
    if config.kind == "lse":
        harmonic = config.disturbance_model == "harmonic"
        return ("M", "B", "Af", "d0") + (("d_sin", "d_cos") if harmonic else ()) + ("beta_e",)
    if config.kind == "tf":
        return TF_PARAMETERS
    return tuple(config.greybox.params)


class _LsePlan:
    """The least-squares experiment, ready to run per seed (thread-safe: no state is changed)."""

    def __init__(self, config: StudyConfig, params: ActuatorParams):
        self.config, self.params = config, params
        self.parameters = estimated_parameters(config)
        self.nominal = {"M": params.M, "B": params.B, "Af": params.Af, "beta_e": params.beta_e,
                        **self._disturbance_truth()}
        self.nominal_is_truth = True
        self.reference = "the parameters simulated (the truth)"

    def _disturbance_truth(self) -> dict[str, float]:
        """d0 (and d_sin, d_cos) of the simulated disturbance, where the model can state them.

        White noise has mean zero; constants and the sines' offsets add to
        d0; a sine A sin(2 pi f t + phi) is d_sin = A cos(phi), d_cos = A
        sin(phi) when the harmonic model's frequency is f. Steps, squares,
        chirps have no d0 the model can hold: no truth is claimed.
        """
        cfg = self.config
        terms = _terms(parse_signal(cfg.disturbance, name="disturbance", seed=0))
        if any(not isinstance(t, (Constant, Sine, WhiteNoise)) for t in terms):
            return {}
        sines = [t for t in terms if isinstance(t, Sine)]
        d0 = self.params.d0 + sum(t.value for t in terms if isinstance(t, Constant)) + sum(s.offset for s in sines)
        truth = {"d0": float(d0)}
        if cfg.disturbance_model == "harmonic":
            freqs = {s.freq_hz for s in sines}
            given = cfg.disturbance_freq_hz
            if not sines:
                truth.update(d_sin=0.0, d_cos=0.0)           # no sinusoid at any frequency
            elif len(freqs) == 1 and (given is None or math.isclose(given, sines[0].freq_hz, rel_tol=1e-9)):
                truth.update(d_sin=float(sum(s.amplitude * math.cos(s.phase) for s in sines)),
                             d_cos=float(sum(s.amplitude * math.sin(s.phase) for s in sines)))
        return truth

    def run(self, seed: int, cancel: CancelToken | None) -> SeedEstimate:
        from .experiments import lse_data
        from .identify.lse import identify_lse

        cfg = self.config
        t0 = time.perf_counter()
        try:
            data = lse_data(self.params, cfg.disturbance, u=cfg.u, t_end=cfg.t_end, seed=seed, cancel=cancel)
            if cfg.sensor_noise:
                sensor_seed = int(_stream(seed, _SENSOR_STREAM).generate_state(1, np.uint64)[0])
                data = data.with_noise(dict(cfg.sensor_noise), seed=sensor_seed)
            res = identify_lse(data, self.params, tau_f=cfg.tau_f, disturbance_model=cfg.disturbance_model,
                               disturbance_freq_hz=cfg.disturbance_freq_hz, estimator=cfg.estimator,
                               intervals=cfg.intervals, cancel=cancel)
        except (RuntimeError, ValueError, ArithmeticError) as exc:   # the simulation or the estimator failed
            return _failed(seed, self.parameters, exc, t0)
        # only the numbers are kept: a result's arrays (t, y1f, ...) would
        # take 200 kB a seed, 200 MB for a study of 1000
        return SeedEstimate(seed=seed, estimates=dict(res.estimates), std_errors=dict(res.std_errors),
                            success=res.success, message=res.message, elapsed_s=time.perf_counter() - t0,
                            critical_value=res.critical_value)


class _TfPlan:
    """The closed-loop transfer-function experiment, ready to run per seed."""

    def __init__(self, config: StudyConfig, params: ActuatorParams):
        from .linear import linearize

        self.config, self.params = config, params
        exp = config.experiment
        self.reference_tf = linearize(params).closed_loop_coeffs(exp.kp)
        num, den = self.reference_tf
        self.parameters = estimated_parameters(config)
        self.nominal = dict(zip(TF_PARAMETERS, map(float, [*den[1:], *num]), strict=True))
        self.nominal_is_truth = exp.model == "linear"
        self.reference = (
            "the linearised closed loop H(s) of eq. 24: the truth, the linear plant being simulated on the "
            "u >= 0 valve branch H(s) is computed on" if self.nominal_is_truth else
            "the linearised closed loop H(s) of eq. 24: a reference, not the truth (the nonlinear plant has no "
            "exact transfer function; its friction saturates, which moves a1 far from H(s)'s)")

    def run(self, seed: int, cancel: CancelToken | None) -> SeedEstimate:
        from .identify.tfest import tfest
        from .simulate import simulate_closed_loop

        cfg, exp = self.config, self.config.experiment
        t0 = time.perf_counter()
        try:
            excitation = exp.excitation(seed)
            # the linear plant on one valve branch: exactly the system H(s)
            # describes (the default "switching" is not linear in u)
            branch = "positive" if exp.model == "linear" else "switching"
            data = simulate_closed_loop(self.params, excitation.u, kp=exp.kp, ts=exp.ts, controller=exp.controller,
                                        model=exp.model, branch=branch, label=f"study seed {seed}", cancel=cancel)
            if not data.success:
                raise ComputationError(f"the closed-loop simulation failed: {data.message}")
            rng = np.random.default_rng(_stream(seed, _POSITION_STREAM))
            y = data.x + cfg.noise_m * rng.standard_normal(data.x.size)
            est = tfest(data.r, y, exp.ts, 3, 0, initial_condition=exp.initial_condition,
                        input_offset=exp.input_offset, init=self.reference_tf, cancel=cancel)
        except (RuntimeError, ValueError, ArithmeticError) as exc:
            return _failed(seed, self.parameters, exc, t0)
        values = [*est.den[1:], *est.num]
        std = est.param_std if est.param_std is not None else np.full(len(values), np.nan)
        return SeedEstimate(seed=seed, estimates=dict(zip(TF_PARAMETERS, map(float, values), strict=True)),
                            std_errors=dict(zip(TF_PARAMETERS, map(float, std), strict=True)),
                            success=bool(est.success), message=est.message, elapsed_s=time.perf_counter() - t0)


class _GreyBoxPlan:
    """The grey-box experiment (:mod:`eha_core.identify.greybox_study`) on ``params``, each seed estimated
    from the paper's values; its noise and Cramér-Rao bound computed once per actuator and experiment."""

    def __init__(self, config: StudyConfig, params: ActuatorParams):
        from .identify.greybox import param_value

        g = config.greybox
        self.config, self.params, self.greybox = config, params, g
        self.guess = g.guess if g.guess is not None else ActuatorParams()
        self.parameters = estimated_parameters(config)
        self.nominal = {n: param_value(params, n) for n in g.params}
        self.nominal_is_truth = True
        self.reference = ("the parameters simulated (the truth); every seed's estimate starts from the paper's "
                          "values")
        self.noise, self.clean, self.crb = _greybox_setup(g, params)

    def bound(self, seeds) -> dict[str, float]:
        from .identify.greybox_study import bound_with_held

        held = [tuple(n for n in self.parameters if not math.isfinite(s.std_errors.get(n, math.nan)))
                for s in seeds if s.success]
        return bound_with_held(self.crb, self.params, self.parameters, self.clean, self.noise, held)

    def run(self, seed: int, cancel: CancelToken | None) -> SeedEstimate:
        from .identify.greybox_study import greybox_seed

        t0 = time.perf_counter()
        try:
            res = greybox_seed(self.greybox, self.params, self.guess, self.noise, seed, cancel)
        except (RuntimeError, ValueError, ArithmeticError) as exc:
            return _failed(seed, self.parameters, exc, t0)
        return SeedEstimate(seed=seed, estimates={n: float(v) for n, v in res.estimates.items()},
                            std_errors={n: float(v) for n, v in res.std_errors.items()}, success=bool(res.success),
                            message=res.message, elapsed_s=time.perf_counter() - t0,
                            intervals=tuple((n, float(lo), float(hi)) for n, (lo, hi) in res.ci95.items()))


@functools.lru_cache(maxsize=16)
def _greybox_setup(g, params: ActuatorParams):
    """A grey-box study's noise, clean record and bound: a function of the experiment and the actuator
    alone, shared by the parts of a long study (and by students with the same actuator)."""
    from .identify.greybox_study import study_setup

    return study_setup(g, params)


def _plan(config: StudyConfig, params: ActuatorParams):
    return {"lse": _LsePlan, "tf": _TfPlan, "greybox": _GreyBoxPlan}[config.kind](config, params)


def _failed(seed: int, names, exc: BaseException, t0: float) -> SeedEstimate:
    nan = dict.fromkeys(names, math.nan)
    return SeedEstimate(seed=seed, estimates=nan, std_errors=dict(nan), success=False,
                        message=" ".join(str(exc).split()) or type(exc).__name__, elapsed_s=time.perf_counter() - t0)


def _statistics(plan, seeds: list[SeedEstimate]) -> dict[str, dict[str, float]]:
    """The statistics of :class:`StudyResult`, by field name, each per parameter."""
    out = {k: {} for k in ("mean", "std", "mean_std_error", "coverage", "bias", "bias_std_error",
                           "bias_per_std_error")}
    for name in plan.parameters:
        used = [s for s in seeds if s.usable(name)]
        est = np.array([s.estimates[name] for s in used])
        se = np.array([s.std_errors[name] for s in used])
        mean = out["mean"][name] = float(est.mean()) if est.size else math.nan
        std = out["std"][name] = float(est.std(ddof=1)) if est.size >= 2 else math.nan
        mean_se = out["mean_std_error"][name] = float(se.mean()) if se.size else math.nan
        if name in plan.nominal:
            out["coverage"][name] = ((sum(s.covers(name, plan.nominal[name]) for s in used) / len(used)) if used
                                     else math.nan)
            bias = out["bias"][name] = mean - plan.nominal[name]
            out["bias_std_error"][name] = std / math.sqrt(est.size) if est.size >= 2 else math.nan
            out["bias_per_std_error"][name] = bias / mean_se if mean_se > 0 else math.nan
    return out


def _message(config: StudyConfig, plan, seeds: list[SeedEstimate], cancelled: bool, reason: str) -> str:
    notes = []
    if cancelled:
        notes.append(f"cancelled ({reason}) after {len(seeds)} of {config.n_seeds} seeds")
    failed = [s for s in seeds if not s.success]
    if failed:
        notes.append(f"{len(failed)} seed(s) failed, left out of the statistics (seed {failed[0].seed}: "
                     f"{failed[0].message})")
    if not plan.nominal_is_truth:
        notes.append(f"the nominal values are {plan.reference}")
    if config.kind == "lse":
        noisy = config.sensor_noise or any(isinstance(t, WhiteNoise) for t in _terms(
            parse_signal(config.disturbance, name="disturbance")))
    elif config.kind == "greybox":
        noisy = True                    # its noise is the sensors' at a finite SNR
    else:
        noisy = config.noise_m > 0
    if not noisy:
        notes.append("the data have no noise: every seed gives the same estimate" if config.kind == "lse"
                     else "the data have no noise: the seeds differ only by their excitation")
    return "; ".join(notes) or "ok"


def run_study(config: StudyConfig | None = None, params: ActuatorParams | None = None, *,
              workers: int = DEFAULT_WORKERS, progress: Callable[[int, int], object] | None = None,
              cancel: CancelToken | None = None, pause: Callable[[], object] | None = None) -> StudyResult:
    """Run a study's seeds on a thread pool and sum them up.

    Parameters
    ----------
    config : StudyConfig, optional
        What to repeat, how many times; default 100 least-squares seeds under
        white force noise (sigma 1000 N).
    params : ActuatorParams, optional
        The plant simulated (and, for the least squares, the measured
        quantities known to the estimator); default the paper's.
    workers : int
        Threads, 1 to :data:`MAX_WORKERS` (default 2, this project's cores).
    progress : callable, optional
        ``progress(done, total)``, called in the calling thread after each
        seed (successful or not); ``total`` is ``config.n_seeds``.
    cancel : eha_core.cancel.CancelToken, optional
        Checked by every seed's simulation and estimator; once set, no new
        seed starts, the running ones stop at their next check, and the
        result holds the seeds completed, with ``cancelled`` True (no
        exception is raised).
    pause : callable, optional
        Called in the worker thread before each seed starts: a server that
        runs the study as background work waits there while others need
        the CPU.

    Returns
    -------
    StudyResult
    """
    config = config if config is not None else StudyConfig()
    if not isinstance(config, StudyConfig):
        raise not_allowed("config", config, "must be a StudyConfig")
    params = params if params is not None else ActuatorParams()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or not 1 <= workers <= MAX_WORKERS:
        raise not_allowed("workers", workers, f"use 1 to {MAX_WORKERS} threads")
    plan = _plan(config, params)
    total = config.n_seeds
    done: list[SeedEstimate] = []
    t0 = time.perf_counter()

    def one(seed: int) -> SeedEstimate:
        check(cancel)                 # a seed queued before the cancel does not start
        if pause is not None:
            pause()
            check(cancel)
        return plan.run(seed, cancel)

    if cancel is None or not cancel.cancelled:
        with ThreadPoolExecutor(max_workers=int(workers), thread_name_prefix="eha-study") as pool:
            futures = [pool.submit(one, seed) for seed in config.seed_range]
            try:
                for fut in as_completed(futures):
                    try:
                        done.append(fut.result())
                    except (Cancelled, CancelledError):
                        pass
                    else:
                        if progress is not None:
                            progress(len(done), total)
                    if cancel is not None and cancel.cancelled:
                        for f in futures:  # the queued seeds; the running ones stop at their next check
                            f.cancel()
            finally:
                # e.g. progress raised: the queued seeds are dropped, not run
                for f in futures:
                    f.cancel()
    cancelled = cancel is not None and cancel.cancelled and len(done) < total
    done.sort(key=lambda s: s.seed)
    stats = _statistics(plan, done)
    return StudyResult(
        config=config, params=params, parameters=tuple(plan.parameters), nominal=dict(plan.nominal),
        nominal_is_truth=plan.nominal_is_truth, reference=plan.reference, seeds=tuple(done),
        n_requested=total, n_completed=len(done), n_failed=sum(not s.success for s in done),
        elapsed_s=time.perf_counter() - t0, workers=int(workers), cancelled=cancelled,
        message=_message(config, plan, done, cancelled, cancel.reason if cancel is not None else ""),
        bound=plan.bound(done) if isinstance(plan, _GreyBoxPlan) else {}, **stats,
    )


def combine_studies(config: StudyConfig, parts, params: ActuatorParams | None = None, *,
                    cancelled: bool = False) -> StudyResult:
    """One study from its parts: results of :func:`run_study` over consecutive seed ranges of ``config``.

    A web server runs a long study as short jobs, so that other students'
    computations come between them; the combined result equals
    :func:`run_study` over all the seeds (seed k's estimate does not depend on
    how the seeds were split).

    Parameters
    ----------
    config : StudyConfig
        The whole study, as every part ran a seed range of it.
    parts : sequence of StudyResult
        The parts' results, in any order.
    params : ActuatorParams, optional
        The plant the parts simulated; default the paper's.
    cancelled : bool
        The study was stopped before its last part.
    """
    params = params if params is not None else ActuatorParams()
    plan = _plan(config, params)
    done = sorted((s for part in parts for s in part.seeds), key=lambda s: s.seed)
    cancelled = bool(cancelled or any(part.cancelled for part in parts)) and len(done) < config.n_seeds
    stats = _statistics(plan, done)
    return StudyResult(
        config=config, params=params, parameters=tuple(plan.parameters), nominal=dict(plan.nominal),
        nominal_is_truth=plan.nominal_is_truth, reference=plan.reference, seeds=tuple(done),
        n_requested=config.n_seeds, n_completed=len(done), n_failed=sum(not s.success for s in done),
        elapsed_s=float(sum(part.elapsed_s for part in parts)),
        workers=max((part.workers for part in parts), default=1), cancelled=cancelled,
        message=_message(config, plan, done, cancelled, "the study was cancelled" if cancelled else ""),
        bound=plan.bound(done) if isinstance(plan, _GreyBoxPlan) else {}, **stats,
    )
