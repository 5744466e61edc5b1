"""The grey-box estimate repeated over noise seeds: are its intervals honest, is it efficient?

One estimate gives a value and a standard error; only repetition shows whether the error is honest
(the 95 % intervals of about 95 % of the seeds hold the truth) and whether the estimator wastes
information (its spread over the seeds against the Cramér-Rao bound, the smallest standard deviation
an unbiased estimator can have on this experiment).

The experiment (:class:`GreyBoxStudyConfig`): the paper's, on the nonlinear plant (``truth``, by
default the paper's values), u = 6 sin(4 pi t) (:data:`eha_core.experiments.LSE_INPUT`), a load
d = 5000 sin(2 pi t) the model knows, ``t_end`` = 5 s at Ts = 1 ms, white noise on each measured
signal at ``snr_db`` = 30 dB: σ = the clean signal's standard deviation / 10^(snr/20) (its
variations', not its mean's: the pressures sit at 12-19 MPa). For the paper's values that is
x 0.26 mm, p1 78 kPa, p2 111 kPa. Seed k draws the noise as
``greybox_data(seed=k)``; each seed's estimate starts from ``guess`` (the paper's values).

Per parameter the study gives the mean and standard deviation of the estimates, the mean reported
standard error, the bias in those (``bias_se``), the coverage of the 95 % intervals, the Cramér-Rao
bound (:func:`cramer_rao_bound`: sqrt(diag((JᵀJ)⁻¹)) with J the σ-weighted sensitivities at the truth,
for a positive parameter through its logarithm, as the estimator scales it) and std / CRB. A parameter
the estimator holds in most seeds (the data do not determine it: :func:`identify_greybox` holds it at
the guess) counts as known in the bound of the others; its own bound is that of all of them (it says
why it is held).

Measured (the defaults, seeds 0-199, ``eha study greybox --seeds 200``): from x, p1, p2 the coverage
of M, B, Af, βe is 0.975, 0.935, 0.965, 0.970, std / CRB 0.91, 1.00, 0.98, 0.93, every bias within
0.13 standard error; over 1000 seeds 0.948-0.958 and 0.96-1.00. From x alone B is held in every seed
(its bound is 2.5 times its value); M, Af, βe cover 0.960, 0.940, 0.965 with std / CRB 0.96, 1.01,
0.99. 0.17-0.35 s a seed on two busy cores (0.03-0.06 s with the simulator's coarser grid).

Examples
--------
>>> res = run_greybox_study(GreyBoxStudyConfig(n_seeds=3, t_end=2.0))
>>> sorted(res.coverage) == sorted(GreyBoxStudyConfig().params), res.n_completed
(True, 3)
>>> 0.5 < res.std_over_crb["M"] < 3
True
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .._checks import not_allowed
from ..cancel import CancelToken
from ..params import ActuatorParams
from ..signals import Sine
from .greybox import (
    GREYBOX_SIGNALS,
    LINEAR_SCALE,
    greybox_data,
    identify_greybox,
    param_value,
    simulate_with_sensitivities,
)

__all__ = ["GreyBoxStudyConfig", "GreyBoxStudyResult", "run_greybox_study", "cramer_rao", "cramer_rao_bound",
           "snr_noise", "greybox_seed", "study_setup", "bound_with_held"]

_ROWS = {"x": 0, "v": 1, "p1": 2, "p2": 3}
#: The load the model knows: 5000 sin(2 pi t) N.
LOAD = Sine(5000.0, 1.0)


@dataclass(frozen=True)
class GreyBoxStudyConfig:
    """What a grey-box study repeats (see the module). ``truth``: the plant simulated (None: the
    paper's values); ``guess``: each seed's initial guess (None: the paper's values); ``hold``: the
    estimator holds at the guess what the record does not determine there (False: estimates all)."""

    n_seeds: int = 30
    first_seed: int = 0
    params: tuple[str, ...] = ("M", "B", "Af", "beta_e")
    measured: tuple[str, ...] = ("x", "p1", "p2")
    snr_db: float = 30.0
    t_end: float = 5.0
    dt: float = 1e-3
    truth: ActuatorParams | None = None
    guess: ActuatorParams | None = None
    hold: bool = True

    def __post_init__(self):
        object.__setattr__(self, "params", tuple(self.params))
        object.__setattr__(self, "measured", tuple(self.measured))
        if not (isinstance(self.n_seeds, int) and 1 <= self.n_seeds <= 1000):
            raise not_allowed("n_seeds", self.n_seeds, "use 1 to 1000 seeds")
        if not (isinstance(self.first_seed, int) and self.first_seed >= 0):
            raise not_allowed("first_seed", self.first_seed, "use a whole number >= 0")
        for s in self.measured:
            if s not in GREYBOX_SIGNALS:
                raise not_allowed("measured", ",".join(self.measured),
                                  f"{s} is not a signal; use {', '.join(GREYBOX_SIGNALS)}")
        if not self.measured:
            raise not_allowed("measured", "(none)", f"name at least one of {', '.join(GREYBOX_SIGNALS)}")
        if not (math.isfinite(self.snr_db) and -20 <= self.snr_db <= 120):
            raise not_allowed("snr_db", self.snr_db, "use a signal-to-noise ratio from -20 to 120 dB")
        if not (math.isfinite(self.t_end) and 0.1 <= self.t_end <= 120):
            raise not_allowed("t_end", self.t_end, "use a record length from 0.1 to 120 s")

    @property
    def plant(self) -> ActuatorParams:
        return self.truth if self.truth is not None else ActuatorParams()


def snr_noise(params: ActuatorParams, snr_db: float, measured, *, t_end: float = 5.0,
              dt: float = 1e-3) -> dict[str, float]:
    """σ of white noise ``snr_db`` below each measured signal of the experiment: the clean signal's
    standard deviation / 10^(snr_db / 20) (SI).

    Parameters
    ----------
    params : ActuatorParams
        The simulated plant.
    snr_db : float
        The signal-to-noise ratio [dB].
    measured : iterable of str
        The measured signals, of x, v, p1, p2.
    t_end, dt : float
        The record's length and sample time [s].
    """
    from ..experiments import LSE_INPUT

    clean = greybox_data(params, LSE_INPUT, t_end=t_end, dt=dt, d=LOAD, measured=tuple(measured))
    return {s: float(np.std(y)) / 10 ** (snr_db / 20) for s, y in clean.signals.items()}


def cramer_rao(J: np.ndarray) -> np.ndarray:
    """sqrt(diag((JᵀJ)⁻¹)): the smallest standard deviation of an unbiased estimate of each column's
    parameter, with ``J`` the Jacobian of residuals in units of their noise σ (Gaussian white noise:
    JᵀJ is the Fisher information), one column per parameter, in the parameters' own units."""
    J = np.asarray(J, dtype=float)
    return np.sqrt(np.diag(np.linalg.inv(J.T @ J)))


def cramer_rao_bound(params: ActuatorParams, names, data, sigma: dict) -> dict[str, float]:
    """The Cramér-Rao bound (SI) of ``names`` on the record ``data`` (its input and load; its
    measured signals are those of ``sigma``, each with noise σ ``sigma[signal]``), from the
    sensitivities at ``params``. A positive parameter's is its value times its logarithm's (the
    estimator's scale; to first order the same)."""
    names = tuple(names)
    log = tuple(n not in LINEAR_SCALE for n in names)
    _, sens = simulate_with_sensitivities(params, names, data, log=log)
    rows = [_ROWS[s] for s in sigma]
    w = np.array([sigma[s] for s in sigma])
    J = (sens[:, rows, :] / w[None, :, None]).reshape(-1, len(names))
    bound = cramer_rao(J)
    return {n: float(bound[j] * (param_value(params, n) if lg else LINEAR_SCALE[n]))
            for j, (n, lg) in enumerate(zip(names, log, strict=True))}


@dataclass
class GreyBoxStudyResult:
    """Per parameter: ``truth``, ``mean``, ``std`` (over the seeds), ``mean_std_error`` (reported),
    ``bias_se`` ((mean - truth) / mean_std_error), ``coverage`` (of the 95 % intervals), ``crb``
    (Cramér-Rao bound), ``std_over_crb``; ``held``: in how many seeds the estimator held it (not
    counted in the rest); ``noise``: σ per signal. ``without_hold``: when the estimator held a parameter
    in some seed, the same seeds with every parameter estimated (``coverage``, ``n_completed``,
    ``n_failed``): what the hold costs or saves the others' coverage; None otherwise. A seed whose
    estimate failed its own checks (:attr:`GreyBoxResult.success`) is a failure, not a completed seed."""

    config: GreyBoxStudyConfig
    truth: dict
    mean: dict
    std: dict
    mean_std_error: dict
    bias_se: dict
    coverage: dict
    crb: dict
    std_over_crb: dict
    held: dict
    noise: dict
    estimates: list = field(default_factory=list)
    n_completed: int = 0
    n_failed: int = 0
    elapsed_s: float = 0.0
    cancelled: bool = False
    failures: list = field(default_factory=list)
    without_hold: dict | None = None

    @property
    def seconds_per_seed(self) -> float:
        return self.elapsed_s / max(self.n_completed + self.n_failed, 1)

    def to_pandas(self):
        """The statistics as a :class:`pandas.DataFrame` indexed by parameter: ``truth``, ``mean``, ``std``,
        ``mean_std_error``, ``bias_se``, ``coverage``, ``crb``, ``std_over_crb`` (SI), ``held`` (seeds that held
        it), then ``unit``, ``display_unit``, ``display_scale``."""
        import pandas as pd

        from .._display import unit_columns

        names = list(self.config.params)
        cols = {c: [float(getattr(self, c).get(n, math.nan)) for n in names]
                for c in ("truth", "mean", "std", "mean_std_error", "bias_se", "coverage", "crb", "std_over_crb")}
        cols["held"] = [int(self.held.get(n, 0)) for n in names]
        cols.update(unit_columns(names))
        return pd.DataFrame(cols, index=pd.Index(names, name="parameter"))

    def __repr__(self) -> str:
        from .._display import block, short, with_error

        cfg = self.config
        head = (f"GreyBoxStudyResult: grey box over seeds {cfg.first_seed}-{cfg.first_seed + cfg.n_seeds - 1}, "
                f"{', '.join(cfg.measured)} measured at {cfg.snr_db:g} dB")
        state = f"{self.n_completed} of {cfg.n_seeds} seeds passed their checks" + (", cancelled" if self.cancelled
                                                                                   else "")
        items = []
        for n in cfg.params:
            cover, ratio = self.coverage.get(n, math.nan), self.std_over_crb.get(n, math.nan)
            items.append(with_error(n, self.mean.get(n, math.nan), self.std.get(n, math.nan))
                         + (f" (covers {cover:.0%}, std/CRB {ratio:.2g})" if math.isfinite(cover) else ""))
        notes = ["mean ± std over the seeds; coverage of the 95 % intervals; std over the Cramér-Rao bound; "
                 ".to_pandas()"]
        if self.failures:
            notes.append(f"{self.n_failed} failed, first: {short(self.failures[0], 160)}")
        return block(head, self.n_completed > 0, "no seed passed its checks" + (
            f": {short(self.failures[0], 160)}" if self.failures else ""), items, notes, passed=state)

    def to_dict(self) -> dict:
        """The statistics, settings and estimates as JSON-able values (NaN written as null)."""
        cfg = self.config
        return _json_safe({
            "coverage": self.coverage, "mean": self.mean, "std": self.std, "crb": self.crb, "bias_se": self.bias_se,
            "std_over_crb": self.std_over_crb, "mean_std_error": self.mean_std_error, "truth": self.truth,
            "held": self.held, "noise": self.noise, "n_completed": self.n_completed, "n_failed": self.n_failed,
            "failures": self.failures[:10], "elapsed_s": self.elapsed_s, "seconds_per_seed": self.seconds_per_seed,
            "cancelled": self.cancelled, "without_hold": self.without_hold,
            "settings": {"n_seeds": cfg.n_seeds, "first_seed": cfg.first_seed, "params": list(cfg.params),
                         "measured": list(cfg.measured), "snr_db": cfg.snr_db, "t_end": cfg.t_end, "dt": cfg.dt,
                         "load": "5000 sin(2 pi t) N, known", "input": "6 sin(4 pi t) V"},
            "estimates": self.estimates})


def _json_safe(value):
    """JSON has no NaN: a held parameter's statistics and errors become null."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def run_greybox_study(config: GreyBoxStudyConfig | None = None, *, workers: int = 2,
                      progress: Callable[[int, int], object] | None = None,
                      cancel: CancelToken | None = None) -> GreyBoxStudyResult:
    """Run the study (seeds on ``workers`` threads: the simulator's kernel releases the GIL).

    Parameters
    ----------
    config : GreyBoxStudyConfig, optional
        The study; default :class:`GreyBoxStudyConfig`'s.
    workers : int
        Threads the seeds run on.
    progress : callable, optional
        ``progress(done, n_seeds)`` after each seed.
    cancel : eha_core.cancel.CancelToken, optional
        Stops the study after the seeds under way; the result then holds the seeds completed.
    """
    config = config or GreyBoxStudyConfig()
    truth = config.plant
    guess = config.guess if config.guess is not None else ActuatorParams()
    t0 = time.perf_counter()
    noise, clean, crb = study_setup(config, truth)

    def one(seed):
        if cancel is not None and cancel.cancelled:
            return seed, None
        try:
            res = greybox_seed(config, truth, guess, noise, seed, cancel)
        except Exception as exc:                    # one seed's failure is a count, not the study's end
            return seed, f"seed {seed}: {type(exc).__name__}: {exc}"
        return seed, res

    seeds = range(config.first_seed, config.first_seed + config.n_seeds)
    rows, failures, done = [], [], 0
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        for seed, res in pool.map(one, seeds):
            done += 1
            if progress is not None:
                progress(done, config.n_seeds)
            if res is None:
                continue
            if isinstance(res, str) or not res.success:
                failures.append(res if isinstance(res, str) else f"seed {seed}: {res.message}")
                continue
            rows.append({"seed": seed, "estimates": dict(res.estimates), "std_errors": dict(res.std_errors),
                         "ci95": {k: list(v) for k, v in res.ci95.items()}, "held": list(res.held)})
    crb = bound_with_held(crb, truth, config.params, clean, noise, [r["held"] for r in rows])
    cancelled = bool(cancel is not None and cancel.cancelled)
    without = None
    if config.hold and any(r["held"] for r in rows) and not cancelled:
        # the same seeds with nothing held: a held parameter's wrong value biases the others, and only the
        # comparison shows by how much their coverage pays for it
        from dataclasses import replace

        free = run_greybox_study(replace(config, hold=False), workers=workers, cancel=cancel)
        without = {"coverage": free.coverage, "n_completed": free.n_completed, "n_failed": free.n_failed}
    res = _summary(config, truth, noise, crb, rows, failures, time.perf_counter() - t0, cancelled)
    res.without_hold = without
    return res


def greybox_seed(config: GreyBoxStudyConfig, truth: ActuatorParams, guess: ActuatorParams, noise: dict, seed: int,
                 cancel: CancelToken | None = None):
    """One seed of the study: the record of ``truth`` with the noise drawn from ``seed``, estimated from
    ``guess`` (a :class:`~eha_core.identify.greybox.GreyBoxResult`).

    Parameters
    ----------
    config : GreyBoxStudyConfig
        The experiment and the parameters estimated.
    truth, guess : ActuatorParams
        The simulated plant, and the estimate's initial guess.
    noise : dict of str to float
        σ of the white noise per measured signal (SI), e.g. :func:`snr_noise`'s.
    seed : int
        Seed of the noise.
    cancel : eha_core.cancel.CancelToken, optional
        Reaches the estimator.
    """
    from ..experiments import LSE_INPUT

    data = greybox_data(truth, LSE_INPUT, t_end=config.t_end, dt=config.dt, d=LOAD, noise=noise, seed=seed,
                        measured=config.measured)
    return identify_greybox(data, config.params, measured=config.measured, guess=guess, cancel=cancel,
                            hold_unidentifiable=config.hold)


def study_setup(config: GreyBoxStudyConfig, truth: ActuatorParams):
    """(noise σ per measured signal, the clean record, the Cramér-Rao bound with every parameter free) of
    the study of ``config`` on ``truth``."""
    from ..experiments import LSE_INPUT

    noise = snr_noise(truth, config.snr_db, config.measured, t_end=config.t_end, dt=config.dt)
    clean = greybox_data(truth, LSE_INPUT, t_end=config.t_end, dt=config.dt, d=LOAD, measured=config.measured)
    return noise, clean, cramer_rao_bound(truth, config.params, clean, noise)


def bound_with_held(crb: dict, truth: ActuatorParams, names, clean, noise: dict, held_per_seed) -> dict:
    """The bound the seeds are measured against: a parameter the estimator held (at its guess) in most
    seeds is known to the rest of the estimate, so their bound is the one with it known (narrower when it
    is correlated with them); its own stays that of them all.

    Parameters
    ----------
    crb : dict of str to float
        The Cramér-Rao bound (SI) with every parameter free (:func:`study_setup`).
    truth : ActuatorParams
        The simulated plant.
    names : iterable of str
        The parameters estimated.
    clean : GreyBoxData
        The noise-free record.
    noise : dict of str to float
        σ of the white noise per measured signal (SI).
    held_per_seed : iterable of iterable of str
        The parameters the estimator held, per completed seed.
    """
    held_per_seed = list(held_per_seed)
    held = {n for n in names if 2 * sum(n in h for h in held_per_seed) > len(held_per_seed)}
    free = tuple(n for n in names if n not in held)
    if held and free:
        return {**crb, **cramer_rao_bound(truth, free, clean, noise)}
    return dict(crb)


def _summary(config, truth, noise, crb, rows, failures, elapsed, cancelled) -> GreyBoxStudyResult:
    stats = {k: {} for k in ("truth", "mean", "std", "mean_std_error", "bias_se", "coverage", "std_over_crb",
                             "held")}
    for n in config.params:
        true = param_value(truth, n)
        live = [r for r in rows if n not in r["held"]]
        est = np.array([r["estimates"][n] for r in live])
        se = np.array([r["std_errors"][n] for r in live])
        cover = [r["ci95"][n][0] <= true <= r["ci95"][n][1] for r in live]
        mean = float(np.mean(est)) if est.size else math.nan
        std = float(np.std(est, ddof=1)) if est.size > 1 else math.nan
        mse = float(np.mean(se)) if se.size else math.nan
        stats["truth"][n] = true
        stats["mean"][n] = mean
        stats["std"][n] = std
        stats["mean_std_error"][n] = mse
        stats["bias_se"][n] = (mean - true) / mse if mse > 0 else math.nan
        stats["coverage"][n] = float(np.mean(cover)) if cover else math.nan
        stats["std_over_crb"][n] = std / crb[n] if crb[n] > 0 else math.nan
        stats["held"][n] = len(rows) - len(live)
    return GreyBoxStudyResult(config=config, crb=crb, noise=noise, estimates=rows, n_completed=len(rows),
                              n_failed=len(failures), elapsed_s=elapsed, cancelled=cancelled, failures=failures,
                              **stats)
