"""The black-box course's experiment: a record of the actuator for ARX, ARMAX, OE, BJ, subspace and process models.

Two set-ups, as a lab has them:

- ``loop="closed"``: the reference r [mm] of the P controller (Kp, sampled at Ts) to the position
  x [mm], the set-up of the frequency-domain tab (docs/model.md §4). The loop is stable: every
  structure applies.
- ``loop="open"``: the valve command u [V], held between samples (a DAC), to the position x [mm]. The
  position integrates the valve's flow (eqs. 1-4): a process model with an integrator (P1DI, P2DI)
  describes it; a zero-mean random binary input keeps the rod off its end stops.

The nonlinear model (eqs. 1-4) is simulated, so a linear structure only approximates it; the position
sensor adds white noise of σ ``noise_x`` [m]. Validation data are a second experiment, its input
drawn from another seed (``validation="second experiment"``, the default), or the record's last part
(``validation="split"``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .._checks import not_allowed
from ..params import ActuatorParams
from .blackbox import IdData, merge

__all__ = ["BlackBoxExperiment", "LOOPS", "VALIDATIONS"]

LOOPS = ("closed", "open")
VALIDATIONS = ("second experiment", "split")
SIGNAL_TYPES = ("prbs", "rbs", "rgs", "sine")


@dataclass(frozen=True)
class BlackBoxExperiment:
    """What is recorded for black-box identification, and how it is split for validation.

    Parameters
    ----------
    loop : {"closed", "open"}
        r -> x under the P controller, or u -> x in open loop.
    signal_type : {"prbs", "rbs", "rgs", "sine"}
        The excitation, as MATLAB ``idinput`` makes it.
    n_samples : int
        Samples of the estimation record (and of the validation experiment).
    ts : float
        Sample time [s].
    r_amplitude : float
        Closed loop: the reference's levels, ±r_amplitude [mm].
    u_amplitude : float
        Open loop: the valve command's levels, ±u_amplitude [V].
    band : float
        The excitation's upper band edge, a fraction of the Nyquist frequency (0, 1].
    kp : float
        The controller's gain [V/m] (closed loop): by default the paper's 10 V/m, the loop the model
        board compares models on. Its slow pole is near 10 s: the default record (150 s at Ts = 0.1 s,
        the input held 2 s on average) excites it.
    noise_x : float
        σ of the position sensor's white noise [m].
    seed : int
        Seed of the estimation record's input and noise; the validation experiment uses ``seed + 1``.
    validation : {"second experiment", "split"}
        Validate on a fresh experiment, or on the last ``1 - estimation_fraction`` of the record.
    estimation_fraction : float
        The share of the record used for estimation when split.
    n_experiments : int
        Experiments merged into the estimation data (MATLAB ``merge``), drawn from seeds ``seed``,
        ``seed + 1``, ...; the validation experiment then uses ``seed + n_experiments``. Merged data are
        validated on a second experiment, not split.

    Examples
    --------
    >>> est, val = BlackBoxExperiment(n_samples=400).records()
    >>> est.n_samples, val.n_samples, est.ts
    (400, 400, 0.1)
    """

    loop: str = "closed"
    signal_type: str = "rbs"
    n_samples: int = 1500
    ts: float = 0.1
    r_amplitude: float = 10.0
    u_amplitude: float = 1.0
    band: float = 0.05
    kp: float = 10.0
    noise_x: float = 1e-5
    seed: int = 0
    validation: str = "second experiment"
    estimation_fraction: float = 0.5
    n_experiments: int = 1

    def __post_init__(self):
        if self.loop not in LOOPS:
            raise not_allowed("loop", self.loop, "closed (r to x under the P controller) or open (u to x)")
        if self.signal_type not in SIGNAL_TYPES:
            raise not_allowed("excitation", self.signal_type, f"one of {', '.join(SIGNAL_TYPES)}")
        n = self.n_samples
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 50 <= n <= 200_000:
            raise not_allowed("samples", n, "a whole number from 50 to 200000")
        for name, lo, hi, unit in (("ts", 1e-4, 1.0, "s"), ("r_amplitude", 1e-3, 100.0, "mm"),
                                   ("u_amplitude", 1e-3, 10.0, "V"),
                                   ("kp", 1e-3, 1e4, "V/m"), ("band", 1e-3, 1.0, "of Nyquist")):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
                raise not_allowed(name, v, f"a number from {lo:g} to {hi:g} {unit}")
        if not (isinstance(self.noise_x, (int, float)) and math.isfinite(self.noise_x) and 0 <= self.noise_x <= 0.01):
            raise not_allowed("noise_x", self.noise_x, "a σ from 0 to 0.01 m")
        if self.validation not in VALIDATIONS:
            raise not_allowed("validation", self.validation, "second experiment or split")
        f = self.estimation_fraction
        if not (isinstance(f, (int, float)) and 0.1 <= f <= 0.9):
            raise not_allowed("estimation fraction", f, "a fraction from 0.1 to 0.9")
        k = self.n_experiments
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= 5:
            raise not_allowed("experiments", k, "a whole number from 1 to 5")
        if k > 1 and self.validation == "split":
            raise not_allowed("experiments", k, "merged experiments are validated on a second experiment, not "
                                                "split: choose validation on a second experiment")

    @property
    def input_name(self) -> str:
        return "r [mm]" if self.loop == "closed" else "u [V]"

    @property
    def output_name(self) -> str:
        return "x [mm]"

    def record(self, params: ActuatorParams | None = None, seed: int | None = None, name: str = "") -> IdData:
        """One experiment on the nonlinear actuator ``params`` (default the paper's): input and
        position in the units shown (mm, V), drawn from ``seed`` (default the experiment's), called
        ``name`` (default "experiment, seed S")."""
        import warnings

        from ..excitation import idinput

        params = params or ActuatorParams()
        seed = self.seed if seed is None else int(seed)
        amp = float(self.r_amplitude if self.loop == "closed" else self.u_amplitude)
        band = (0.0, float(self.band))
        with warnings.catch_warnings():
            # a PRBS cut to the record's length: idinput says so; the cut signal is what we want
            warnings.simplefilter("ignore", UserWarning)
            ex = idinput([self.n_samples, 1, 1], self.signal_type, band, (-amp, amp), seed=seed)
        rng = np.random.default_rng([seed, 0xB1AC])
        if self.signal_type == "prbs":
            # a maximum-length sequence is the same for every seed (idinput's): the seed picks where its
            # period starts, so the validation experiment's input is not the estimation's
            ex = dataclasses.replace(ex, u=np.roll(ex.u, int(rng.integers(ex.u.size))))
        if self.loop == "closed":
            from ..experiments import FrequencyExperiment

            fe = FrequencyExperiment(n_samples=self.n_samples, ts=self.ts, kp=self.kp, seed=seed)
            run = fe.closed_loop(params, dataclasses.replace(ex, u=ex.u * 1e-3))       # r in m
            u_shown = np.asarray(run.r, float) * 1e3
        else:
            from ..signals import Sampled
            from ..simulate import simulate

            t = np.arange(self.n_samples) * self.ts
            run = simulate(params, Sampled(t, np.asarray(ex.u, float), hold="zoh", name="u"),
                           t_end=t[-1], dt=self.ts)
            u_shown = np.asarray(run.u, float)
        if not run.success:
            from .._checks import ComputationError

            raise ComputationError(f"the simulation failed: {run.message}")
        x = np.asarray(run.x, float)
        x = x + self.noise_x * rng.standard_normal(x.size) if self.noise_x > 0 else x
        n = min(self.n_samples, x.size, u_shown.size)
        return IdData(x[:n] * 1e3, u_shown[:n], self.ts, name=name or f"experiment, seed {seed}")

    def records(self, params: ActuatorParams | None = None) -> tuple[IdData, IdData]:
        """``(estimation, validation)`` data of the actuator ``params`` (default the paper's), as
        :attr:`validation` says."""
        if self.validation == "split":
            whole = self.record(params, name="the record")
            return whole.split(self.estimation_fraction)
        k = self.n_experiments
        if k == 1:
            est = self.record(params, name=f"estimation experiment (seed {self.seed})")
        else:
            est = merge(*(self.record(params, self.seed + i, name=f"seed {self.seed + i}") for i in range(k)),
                        name=f"{k} estimation experiments merged (seeds {self.seed}-{self.seed + k - 1})")
        return est, self.record(params, self.seed + k, name=f"validation experiment (seed {self.seed + k})")
