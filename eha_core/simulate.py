"""Open- and closed-loop simulation of the nonlinear or linearised model.

Runs whose inputs are :mod:`eha_core.signals` signals go through a compiled
adaptive DOP853 (:mod:`eha_core._kernels`, numba) that stops at every jump of
the inputs (the signals' ``discontinuities``), at every controller instant and,
in open loop, where the command changes sign (the valve's branches, eq. 3).
Its error tolerance :data:`TOL` (1e-9) keeps the error near 2e-7 of each state's
range on the paper's smooth cases and 1e-8 on inputs with jumps
(benchmarks/bench_simulate.py, against Radau at rtol 1e-10).

Two kinds of input take the compiled fixed-step RK4 instead: a function of t
(its jumps are unknown), and a signal with more than
:data:`~eha_core._kernels.MAX_SMOOTH` (4) sines and chirps in one sum (the
adaptive kernel evaluates at most 4 per signal). Its step divides the output
interval ``dt`` (and the controller period ``ts``) and is at most ``h_max``
(default 5e-4 s); it is as accurate on smooth inputs (2e-7 of the range) but
not exact at jumps: a jump between its steps is seen at the next step, an error
of 2.5e-3 of the range on a square wave, 2.5e5 times the adaptive one's.
Linearised runs return absolute states: the operating
point is added back (eq. 14), as the paper plots them. The nonlinear model
enforces its physical bounds (pressures in [pr, ps], end stops); the linearised
model has none, by construction.

Structural effects (``params.effects``, :mod:`eha_core.variants`, docs/model.md
§6) are simulated by the same integrators: internal leakage and Stribeck
friction are terms of the model's right-hand side; the valve's spool dynamics
add two states [u_v, du_v/dt], integrated by the six-state kernels of
:mod:`eha_core._kernels_spool` (the results still hold x, v, p1, p2 and the
command u; the spool starts at rest at u_v = 0 unless six initial states are
given). The paper's model (every effect off) takes the four-state kernels, as
before.

For a server shared by many users: runs are integrated in chunks (the
adaptive kernel's of ``CHUNK_SECONDS`` simulated seconds, the RK4's of
``CHUNK_STEPS`` steps), the inputs prepared one chunk at a time, so memory
follows the output and not the step count; every function takes ``cancel``
(a :class:`~eha_core.cancel.CancelToken`, checked between chunks and, within
one, every ``CANCEL_CHECK_STEPS`` adaptive steps: a cancel stops a run within
about 5 ms of work however stiff its parameters); and
:func:`simulation_cost` tells the steps, samples and peak memory of a run
before it is started.

Examples
--------
>>> from eha_core.simulate import simulate
>>> from eha_core.signals import Sine
>>> res = simulate(u=Sine(6.0, 2.0), d=Sine(5e3, 1.0), t_end=5.0)
>>> res.success, len(res.t), round(float(res.x.max()), 3)
(True, 5001, 0.035)
>>> df = res.to_pandas()                 # indexed by t, one column per signal
>>> df.index.name, list(df.columns)
('t', ['x', 'v', 'p1', 'p2', 'u', 'd'])
>>> print(repr(res).splitlines()[0])
SimulationResult: nonlinear, open loop, 5001 samples over 0-5 s: success
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ._checks import not_allowed, positive_number
from .cancel import CancelToken
from .linear import N_PACKED_LINEAR, N_PACKED_LINEAR_SPOOL, VALVE_BRANCHES, OperatingPoint, linearize
from .model import N_PACKED_PARAMS, pack_params
from .params import ActuatorParams
from .signals import ZERO, Constant, Sampled, Signal

__all__ = [
    "SimulationResult", "RangeExcursion", "simulate", "simulate_many", "simulate_closed_loop", "runs_to_pandas",
    "simulation_cost", "SimulationCost", "DEFAULT_H_MAX", "MODELS", "SIMULATION_BRANCHES", "CONTROLLERS", "CHUNK_STEPS",
]

#: Largest integration step [s]. RK4 at 5e-4 s keeps the error near 2e-7 of
#: each state's range on the paper's cases, 50 times inside the 1e-5 target
#: (benchmarks/bench_simulate.py); the fastest linearised pole (-385 rad/s)
#: gives h lambda = 0.19, far inside RK4's stability region.
DEFAULT_H_MAX = 5e-4
MODELS = ("nonlinear", "linear")
#: How a linearised run uses the valve's branches: switching with the sign of u
#: (the paper's Fig. 3), or one of :data:`~eha_core.linear.VALVE_BRANCHES` throughout.
SIMULATION_BRANCHES = ("switching", *VALVE_BRANCHES)
CONTROLLERS = ("zoh", "continuous")
#: Guards so that one request cannot exhaust a shared server.
MAX_STEPS = 20_000_000
MAX_OUTPUT_SAMPLES = 2_000_000

_STATE_NAMES = ("x", "v", "p1", "p2")
#: Integration steps per chunk (rounded to a multiple of the output and
#: controller periods). Inputs are sampled at the RK4 stage times one chunk at
#: a time, so memory follows the output, not the step count (a 20 M-step closed
#: loop needed 1.3 GB of stage samples at once), and a computation can be
#: cancelled between chunks: 50 000 steps are about 10 ms of work, and the
#: per-chunk overhead (a kernel call, a few numpy calls) is below 1 %.
CHUNK_STEPS = 50_000


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """One simulated run, sampled at ``t``; SI units.

    ``r`` is the reference of a closed-loop run (None in open loop).
    ``success`` is False (with ``message``) when the state stopped being finite;
    the arrays then hold NaN from that point on.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    p1: np.ndarray
    p2: np.ndarray
    u: np.ndarray
    d: np.ndarray
    success: bool = True
    message: str = "ok"
    model: str = "nonlinear"
    label: str = ""
    params: ActuatorParams = field(default_factory=ActuatorParams, repr=False)
    r: np.ndarray | None = None
    controller: str = "open-loop"
    kp: float | None = None
    h: float = float("nan")

    @property
    def states(self) -> np.ndarray:
        """The states as an (N, 4) array [x, v, p1, p2]."""
        return np.column_stack([self.x, self.v, self.p1, self.p2])

    def to_pandas(self):
        """A :class:`pandas.DataFrame` indexed by the time ``t`` [s], one column per signal: x, v, p1, p2,
        u, d (and r), SI units (``df.reset_index()`` makes t a column)."""
        import pandas as pd

        cols = {"x": self.x, "v": self.v, "p1": self.p1, "p2": self.p2, "u": self.u, "d": self.d}
        if self.r is not None:
            cols["r"] = self.r
        return pd.DataFrame(cols, index=pd.Index(self.t, name="t"))

    def plot(self):
        """Draw the run with matplotlib (:func:`eha_core.plotting.plot_simulation`); returns the Figure."""
        from .plotting import plot_simulation

        return plot_simulation(self)

    def __repr__(self) -> str:
        from ._display import block, span

        times = f"{self.t[0]:g}-{self.t[-1]:g} s" if self.t.size else "no time"
        loop = "open loop" if self.kp is None else f"closed loop ({self.controller}, kp {self.kp:g} V/m)"
        head = f"SimulationResult: {self.model}, {loop}, {self.t.size} samples over {times}"
        ranges = [span(name, getattr(self, name)) for name in ("x", "v", "p1", "p2", "u")]
        notes = [f"label: {self.label}" if self.label else "", ".to_pandas(): the signals by t; .plot(): a figure"]
        return block(head, self.success, self.message, ranges, notes)

    def to_csv(self, path_or_buf=None, **kwargs):
        """Write the CSV (header t,x,v,p1,p2,u,d[,r]); returns text when no path.

        Parameters
        ----------
        path_or_buf : str, path or file-like, optional
            Where to write, as for :meth:`pandas.DataFrame.to_csv`; None returns the text.
        **kwargs
            Passed on to :meth:`pandas.DataFrame.to_csv` (``float_format`` defaults to ``"%.10g"``).
        """
        kwargs.setdefault("float_format", "%.10g")
        return self.to_pandas().reset_index().to_csv(path_or_buf, index=False, **kwargs)

    def beyond_physical_range(self) -> tuple[RangeExcursion, ...]:
        """Where the run leaves what the actuator can physically do.

        The nonlinear model is held within its bounds (the end stops ±0.8 L0,
        pressures in [pr, ps]); the linearised one (eqs. 20-24) is not, and
        far from its operating point it reaches pressures below the tank's or
        above the supply's and positions beyond the end stops: its results
        there mean nothing physically. Empty when the run stays within them.
        """
        p = self.params
        checks = (("x", self.x, -p.x_max, p.x_max), ("p1", self.p1, p.pr, p.ps), ("p2", self.p2, p.pr, p.ps))
        out = []
        for name, values, lo, hi in checks:
            finite = values[np.isfinite(values)]
            if finite.size == 0:
                continue
            vmin, vmax = float(finite.min()), float(finite.max())
            tol = 1e-9 * max(abs(lo), abs(hi), 1.0)
            if vmin < lo - tol:
                out.append(RangeExcursion(name, vmin, lo, "below"))
            if vmax > hi + tol:
                out.append(RangeExcursion(name, vmax, hi, "above"))
        return tuple(out)


@dataclass(frozen=True)
class RangeExcursion:
    """A state beyond its physical bound: ``extreme`` (SI) past ``bound``, ``side`` 'below' or 'above'."""

    state: str
    extreme: float
    bound: float
    side: str


def runs_to_pandas(results):
    """Several runs as one long table: run, model, t, x, v, p1, p2, u, d (and r).

    Parameters
    ----------
    results : iterable of SimulationResult
        The runs; each one's ``label`` fills the column ``run``, its ``model`` the column ``model``.
    """
    import pandas as pd

    frames = []
    for r in results:
        df = r.to_pandas().reset_index()
        df.insert(0, "model", r.model)
        df.insert(0, "run", r.label)
        frames.append(df)
    if not frames:
        return pd.DataFrame(columns=["run", "model", "t", "x", "v", "p1", "p2", "u", "d"])
    return pd.concat(frames, ignore_index=True)


# -- argument handling ------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class _Callable(Signal):
    """A user function of time wrapped as a signal (vectorised if it can be)."""

    fn: Callable

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        try:
            out = np.asarray(self.fn(t), dtype=float)
            if out.shape == t.shape:
                return out
            if out.ndim == 0:
                return np.full(t.shape, float(out))
        except Exception:
            pass
        return np.array([float(self.fn(float(s))) for s in t.ravel()]).reshape(t.shape)

    @property
    def spec(self):
        return getattr(self.fn, "__name__", "function")


def _as_signal(obj, name: str, t_out: np.ndarray, hold: str = "linear") -> Signal:
    """Accept a Signal, a function of t, a number, or samples at ``t_out``."""
    if obj is None:
        return ZERO
    if isinstance(obj, Signal):
        return obj
    if callable(obj):
        return _Callable(obj)
    if np.ndim(obj) == 0:
        return Constant(float(obj))
    arr = np.asarray(obj, dtype=float).ravel()
    if arr.size != t_out.size:
        raise not_allowed(name, arr, f"{arr.size} samples given, but the run has {t_out.size} output samples "
                         f"(t = 0, dt, ..., t_end); give one value per output sample")
    return Sampled(t_out, arr, hold=hold, name=name)


def _sample(sig: Signal, name: str, t: np.ndarray) -> np.ndarray:
    vals = np.asarray(sig(t), dtype=float)
    if vals.shape != t.shape:
        raise not_allowed(name, sig, f"the signal returned shape {vals.shape} for {t.shape} times")
    if not np.all(np.isfinite(vals)):
        bad = t[~np.isfinite(vals)][0]
        raise not_allowed(name, sig, f"the signal is not finite at t = {bad:g} s")
    return vals


def _stage_samples(sig: Signal, name: str, h: float, n_steps: int, start: int = 0) -> np.ndarray:
    """Values at the RK4 stage times (start, middle, end) of steps ``start .. start + n_steps``.

    For a signal that can jump, the end value is taken just before the step's
    end, so that a value held from the next sample on is not seen early.
    Times are integer multiples of h/2 counted from t = 0, so a chunk's
    samples equal those of the whole run bit for bit.
    """
    half = _sample(sig, name, (2 * start + np.arange(2 * n_steps + 3)) * (0.5 * h))
    out = np.empty((n_steps + 1, 3))
    out[:, 0] = half[0:2 * n_steps + 1:2]
    out[:, 1] = half[1:2 * n_steps + 2:2]
    if sig.continuous:
        out[:, 2] = half[2:2 * n_steps + 3:2]
    else:
        out[:, 2] = _sample(sig, name, (start + np.arange(n_steps + 1)) * h + h * (1.0 - 1e-6))
    return out


def _rk4_h_max(h_max):
    """The fixed-step RK4's largest step: the one given, else :data:`DEFAULT_H_MAX`."""
    return DEFAULT_H_MAX if h_max is None else h_max


def _grid(t_end, dt, h_max, ts=None):
    """Step h, steps per output sample, steps per controller sample, counts."""
    t_end = positive_number("t_end", t_end, "must be a finite number of seconds > 0")
    dt = positive_number("dt", dt, "must be a finite number of seconds > 0")
    h_max = positive_number("h_max", h_max, "must be a finite number of seconds > 0")
    if dt > t_end:
        raise not_allowed("dt", dt, f"must not exceed t_end = {t_end:g} s")
    n_out = t_end / dt
    if abs(n_out - round(n_out)) > 1e-6 * max(1.0, n_out):
        raise not_allowed("t_end", t_end, f"must be a whole number of output intervals dt = {dt:g} s")
    n_out = int(round(n_out))
    base = dt
    if ts is not None:
        ratio = max(dt, ts) / min(dt, ts)
        if abs(ratio - round(ratio)) > 1e-6 * ratio:
            raise not_allowed("ts", ts, f"dt = {dt:g} and ts must be whole multiples of one another")
        base = min(dt, ts)
    per_base = max(1, math.ceil(base / h_max - 1e-9))
    h = base / per_base
    sub = int(round(dt / h))
    ctrl_every = int(round(ts / h)) if ts is not None else 1
    n_steps = n_out * sub
    if n_steps > MAX_STEPS:
        raise not_allowed("t_end", t_end, f"{n_steps} integration steps (h_max = {h_max:g} s) exceed the limit "
                                          f"{MAX_STEPS}; shorten the run")
    if n_out + 1 > MAX_OUTPUT_SAMPLES:
        raise not_allowed("dt", dt, f"{n_out + 1} output samples over t_end = {t_end:g} s exceed the limit "
                                    f"{MAX_OUTPUT_SAMPLES}; use a larger dt")
    return h, sub, ctrl_every, n_steps, n_out + 1


def _mode(model: str, branch: str) -> int:
    from . import _kernels as K

    if model not in MODELS:
        raise not_allowed("model", model, f"use one of {', '.join(MODELS)}")
    if branch not in SIMULATION_BRANCHES:
        raise not_allowed("branch", branch, f"use one of {', '.join(SIMULATION_BRANCHES)}")
    if model == "nonlinear":
        return K.NONLINEAR
    return {"switching": K.LINEAR_SWITCHING, "positive": K.LINEAR_POSITIVE, "negative": K.LINEAR_NEGATIVE}[branch]


def _lin_vector(params: ActuatorParams, op: OperatingPoint | None, needed: bool) -> np.ndarray:
    if not needed:
        return np.zeros(N_PACKED_LINEAR_SPOOL if params.effects.spool else N_PACKED_LINEAR)
    return linearize(params, op).packed()


def _kernels_of(params: ActuatorParams):
    """The compiled integrators for ``params``: the four-state ones, or the six-state ones of the spool."""
    if params.effects.spool:
        from . import _kernels_spool as K
    else:
        from . import _kernels as K
    return K


def _initial(params: ActuatorParams, initial_state) -> np.ndarray:
    """The run's initial state: given ([x, v, p1, p2], with the spool also [..., u_v, du_v/dt]) or the
    parameters' initial conditions (the spool at rest at u_v = 0)."""
    spool = params.effects.spool
    if initial_state is None:
        y0 = params.initial_state
        return np.concatenate([y0, [0.0, 0.0]]) if spool else y0
    y0 = np.asarray(initial_state, dtype=float).ravel()
    if y0.size not in ((4, 6) if spool else (4,)) or not np.all(np.isfinite(y0)):
        raise not_allowed("initial_state", initial_state, "give four finite numbers [x, v, p1, p2], or six with "
                          "the valve's spool dynamics [x, v, p1, p2, u_v, du_v/dt]" if spool else
                          "give four finite numbers [x, v, p1, p2]")
    return np.concatenate([y0, [0.0, 0.0]]) if spool and y0.size == 4 else y0


def _model_label(model: str, branch: str) -> str:
    return model if model == "nonlinear" else ("linear" if branch == "switching" else f"linear-{branch}")


def _simulation_result(out, status, t, d_vals, params, model_label, label, r=None, controller="open-loop", kp=None,
                       h=float("nan"), t_fail=None):
    success = status < 0
    message = "ok"
    if not success:
        if t_fail is None:          # the fixed-step integrator reports the step
            t_fail = status * h
            message = f"the state stopped being finite at t = {t_fail:.6g} s"
        elif status == 1:
            message = f"the state stopped being finite at t = {t_fail:.6g} s"
        else:
            message = (f"the integrator's step collapsed at t = {t_fail:.6g} s (a model too stiff or "
                       f"diverging to be followed)")
        # samples after the failure are meaningless
        out[t > t_fail - 1e-12, :] = np.nan
    return SimulationResult(
        t=t, x=out[:, 0].copy(), v=out[:, 1].copy(), p1=out[:, 2].copy(), p2=out[:, 3].copy(),
        u=out[:, 4].copy(), d=d_vals, success=success, message=message, model=model_label,
        label=label, params=params, r=r, controller=controller, kp=kp, h=h,
    )


def _chunk_length(n_steps: int, *aligns: int) -> int:
    """Steps per chunk: a multiple of every alignment (output interval, controller
    period), so each chunk starts at an output sample and a controller instant."""
    period = 1
    for a in aligns:
        period = period * a // math.gcd(period, a)
    return max(period, (CHUNK_STEPS // period) * period)


def _integrate_chunked(n_runs, y0s, h, n_steps, sub, prms, mode, lins, stage_sources, ctrl, kp, ctrl_every,
                       u_limit, n_out, cancel, parallel, K=None):
    """Integrate ``n_runs`` runs chunk by chunk; returns (outs, status).

    ``stage_sources(j, start, count)`` gives run j's (u, d, r) stage samples
    for steps ``start .. start + count``. Each chunk starts at an output sample
    and a controller instant (:func:`_chunk_length`), where the kernel starts
    afresh: it writes the chunk's output rows, samples the controller at its
    first step, and leaves the state for the next chunk in ``y_end``. The
    result is bitwise that of one kernel call over all steps
    (tests/core/test_chunks_and_cancel.py checks it); a failure is reported at
    its global step. ``K``: the kernels' module (default the four-state :mod:`eha_core._kernels`; the
    states are the columns of ``y0s``).
    """
    if K is None:
        from . import _kernels as K

    chunk = _chunk_length(n_steps, sub, ctrl_every)
    outs = np.zeros((n_runs, n_out, 5))
    status = np.full(n_runs, -1, dtype=np.int64)
    n_states = np.shape(y0s)[-1]
    y = np.array(y0s, dtype=float).reshape(n_runs, n_states)
    start = 0
    while start < n_steps:
        if cancel is not None:
            cancel.check()
        count = min(chunk, n_steps - start)
        last = start + count == n_steps
        k0 = start // sub
        rows = count // sub + (1 if last else 0)
        # runs that failed are left alone: their state is not finite any more
        alive = np.flatnonzero(status < 0)
        y_end = np.empty((n_runs, n_states))
        if alive.size == 1 or not parallel:
            for j in alive:
                u_st, d_st, r_st = stage_sources(j, start, count)
                st = K.integrate(y[j], h, count, sub, prms[j], mode, lins[j], u_st, d_st, ctrl, kp, r_st,
                                 ctrl_every, u_limit, outs[j, k0:k0 + rows], y_end[j])
                if st >= 0:
                    status[j] = start + st
        else:
            # views, not copies, while every run is alive (the usual case)
            sel = slice(None) if alive.size == n_runs else alive
            stages = [stage_sources(j, start, count) for j in alive]
            buf = np.zeros((alive.size, rows, 5))
            st = np.full(alive.size, -1, dtype=np.int64)
            ends = np.empty((alive.size, n_states))
            K.integrate_batch(y[sel], h, count, sub, prms[sel], mode, lins[sel],
                              np.stack([g[0] for g in stages]), np.stack([g[1] for g in stages]), ctrl, kp,
                              np.stack([g[2] for g in stages]), ctrl_every, u_limit, buf, st, ends)
            del stages
            outs[sel, k0:k0 + rows] = buf
            y_end[sel] = ends
            failed = st >= 0
            status[alive[failed]] = start + st[failed]
        y = y_end
        start += count
        if np.all(status >= 0):
            break
    return outs, status


@dataclass(frozen=True)
class SimulationCost:
    """Estimated cost of a computation, known before running it.

    Attributes
    ----------
    steps : int
        RK4 steps over all runs.
    output_samples : int
        Output samples over all runs.
    peak_bytes : int
        Estimated peak of the memory the computation allocates [bytes]
        (within a factor of 2 of tracemalloc's peak; tested).
    h : float
        Integration step [s].
    other_seconds : float
        Estimated time of the work that is not integration (estimators) [s].
    """

    steps: int
    output_samples: int
    peak_bytes: int
    h: float = float("nan")
    other_seconds: float = 0.0

    #: RK4 steps per second on one core, the sampling of the inputs included:
    #: 5-6 M/s for the nonlinear model in open and closed loop on the 2-core
    #: machine this was written on (a 4 M-step closed loop in 0.65 s, a 2 M-step
    #: open loop in 0.39 s; 10 M/s for the linearised model). A rough guide:
    #: another machine, or a loaded one, differs.
    STEPS_PER_SECOND = 5.0e6

    @property
    def seconds_estimate(self) -> float:
        """Rough wall time on one core [s]: ``steps / STEPS_PER_SECOND + other_seconds``."""
        return self.steps / self.STEPS_PER_SECOND + self.other_seconds

    def __add__(self, other: SimulationCost) -> SimulationCost:
        """Two computations one after the other: counts and times add, the peak is the larger."""
        return SimulationCost(self.steps + other.steps, self.output_samples + other.output_samples,
                              max(self.peak_bytes, other.peak_bytes), self.h,
                              self.other_seconds + other.other_seconds)


def simulation_cost(t_end: float, dt: float, *, ts: float | None = None, h_max: float | None = None,
                    n_runs: int = 1, parallel: bool = True) -> SimulationCost:
    """What a simulation will cost, without running it: steps, samples, peak memory, seconds.

    Parameters
    ----------
    t_end, dt : float
        Horizon and output interval [s], as given to :func:`simulate`.
    ts : float, optional
        Controller sample time [s] of a closed-loop run
        (:func:`simulate_closed_loop`); the step grid is aligned with it.
    h_max : float, optional
        Largest integration step [s]. None (default): the adaptive integrator chooses its steps by
        its error control alone, and the fixed-step RK4 (an input given as a function of t) steps
        at :data:`DEFAULT_H_MAX`.
    n_runs : int
        Runs simulated together (:func:`simulate_many`).
    parallel : bool
        As given to :func:`simulate_many`: a parallel batch holds every run's
        stage samples of a chunk at once.

    Returns
    -------
    SimulationCost
        ``peak_bytes`` is the larger of the memory while integrating (outputs,
        one chunk's stage samples, the temporaries of sampling a signal) and
        at the end (outputs, the result's copies of them, t, d and r). The
        chunked integration never holds the inputs of more than one chunk, so
        it does not grow with the step count. Within a factor of 2 of
        tracemalloc's peak (tests/core/test_chunks_and_cancel.py).

    Raises
    ------
    ValueError
        As the simulation would: a grid that does not fit, or beyond the
        guards ``MAX_STEPS`` and ``MAX_OUTPUT_SAMPLES``.

    Examples
    --------
    >>> c = simulation_cost(5.0, 1e-3, n_runs=4)
    >>> c.steps, c.output_samples
    (40000, 20004)
    """
    if isinstance(n_runs, bool) or not isinstance(n_runs, (int, np.integer)) or n_runs < 1:
        raise not_allowed("n_runs", n_runs, "must be a whole number of runs >= 1")
    h, sub, ctrl_every, n_steps, n_out = _grid(t_end, dt, _rk4_h_max(h_max), ts)
    # the adaptive integrator builds one chunk's segments at a time, for as many runs at once as threads
    # (two here): at most one per output interval or controller period (a held input changes no
    # faster than the output is sampled), each with its bound, flag and three lines (value, slope)
    segments = min(n_out, math.ceil(CHUNK_SECONDS / min(dt, ts or dt))) + 1
    building = 10 * segments * 8 * (min(n_runs, 2) if parallel else 1)
    # while the disturbance (and reference) is sampled at the output times: about four temporaries
    sampling = 5 * n_out * 8
    integrating = n_runs * n_out * (5 + 1) * 8 + building + sampling
    # at the end: the outputs (x, v, p1, p2, u), the results' copies of them,
    # and t, d and r
    finishing = n_runs * n_out * (5 + 5 + 3) * 8
    return SimulationCost(steps=n_runs * n_steps, output_samples=n_runs * n_out,
                          peak_bytes=max(integrating, finishing), h=h)


# -- the adaptive integrator's segments ------------------------------------------------

#: Error tolerance of the adaptive integrator (DOP853): a step's error is kept below TOL times each
#: state's :data:`_SCALE` plus its size. 1e-9 keeps the error near 2e-7 of each state's range against
#: a tight implicit reference (Radau, rtol 1e-10), with jumps off the output grid and without: 1.9e-7 on
#: the paper's cases, 1e-8 on a square wave and a step (benchmarks/bench_simulate.py). Looser
#: tolerances are erratic on the paper's cases (2e-6 at 3e-9, 2e-5 at 1e-8): the friction S(v) (eq. 2)
#: bends within |v| < 1/k_f, which a step's error estimate can miss when it spans the velocity's zero.
TOL = 1e-9
#: The scales of the states in the error test [m, m/s, Pa, Pa] (the pressures also count their size).
_SCALE = np.array([0.01, 0.01, 1e6, 1e6])
#: The same with the spool's dynamics (docs/model.md §6.1): its position u_v [V] and rate [V/s] (a command of
#: a volt through the 150 rad/s spool of the variant moves it at about 100 V/s).
_SCALE_SPOOL = np.array([0.01, 0.01, 1e6, 1e6, 1.0, 100.0])
#: Simulated seconds per chunk of the adaptive integrator: the segments (and held inputs) of one chunk
#: are built at a time, and ``cancel`` is checked between chunks. A chunk's start is a restart of the
#: integrator like any breakpoint (exact: the state is continuous there).
CHUNK_SECONDS = 10.0
#: Steps (accepted and rejected) after which the adaptive kernel pauses within a chunk so that ``cancel``
#: is checked: the work between checks is bounded whatever a simulated second costs (a stiff parameter
#: set takes 10^5 steps or more per simulated second). 8192 steps are about 5 ms of work (0.7 us a step on
#: the nonlinear model); a pause resumes to the same bits, and a kernel call costs about as much as 10 steps.
CANCEL_CHECK_STEPS = 8192
#: Steps (accepted and rejected) per run before the adaptive integrator gives up.
MAX_ADAPTIVE_STEPS = MAX_STEPS


def _segment_form(sig: Signal):
    """``(smooth, n, held)``: a signal's sines and chirps as rows (a, w, q, phi) of
    ``a sin((w + q t) t + phi)`` for the kernel (:data:`~eha_core._kernels.MAX_SMOOTH` rows, unused
    ones zero), how many, and its other terms (constant, held or interpolated within each segment); None
    for a signal the kernel cannot follow (a function of t: its jumps are not known; more sines and
    chirps than it evaluates)."""
    from . import _kernels as K
    from .signals import Chirp, Sine, Square, Step, Sum, WhiteNoise

    terms = sig.terms if isinstance(sig, Sum) else (sig,)
    smooth, held = [], []
    for term in terms:
        if isinstance(term, Sine):
            smooth.append((term.amplitude, 2.0 * np.pi * term.freq_hz, 0.0, term.phase))
            if term.offset:
                held.append(Constant(term.offset))
        elif isinstance(term, Chirp):
            smooth.append((term.amplitude, 2.0 * np.pi * term.f0_hz, np.pi * (term.f1_hz - term.f0_hz) / term.t1,
                           0.0))
        elif isinstance(term, (Constant, Step, Square, WhiteNoise, Sampled)):
            held.append(term)
        else:
            return None
    if len(smooth) > K.MAX_SMOOTH:
        return None
    rows = np.zeros((K.MAX_SMOOTH, 4))
    if smooth:
        rows[:len(smooth)] = smooth
    return rows, len(smooth), held


def _segment_lines(held, name: str, seg_t: np.ndarray) -> np.ndarray:
    """Each segment's line (value at its middle, slope) of the held and interpolated terms: constant
    or linear within a segment, as every sample time of theirs is a segment boundary."""
    ta, tb = seg_t[:-1], seg_t[1:]
    mid = 0.5 * (ta + tb)
    lines = np.zeros((mid.size, 2))
    for term in held:
        lines[:, 0] += _sample(term, name, mid)
        if isinstance(term, Sampled) and term.hold == "linear":
            lines[:, 1] += (_sample(term, name, tb) - _sample(term, name, ta)) / (tb - ta)
    return lines


def _segment_bounds(sigs, a: float, b: float, ts: float | None, t_end: float):
    """The segment boundaries in [a, b] (a and b included): every discontinuity of the signals and
    every controller instant k ts; and which boundaries are controller instants."""
    pts = [np.array([a, b])]
    for sig in sigs:
        pts.append(sig.discontinuities(b, a))
    if ts is not None:
        k = np.arange(math.ceil(a / ts - 1e-9), math.floor(b / ts + 1e-9) + 1)
        inst = k * ts
        pts.append(inst)
    bounds = np.unique(np.concatenate(pts))
    bounds = bounds[(bounds >= a) & (bounds <= b)]
    # times closer than rounding are one time (a square's edge and a sample at the same instant)
    tiny = 1e-12 * max(1.0, t_end)
    keep = np.concatenate([[True], np.diff(bounds) > tiny])
    bounds = bounds[keep]
    bounds[-1] = b
    if ts is None:
        return bounds, np.zeros(bounds.size, dtype=np.bool_)
    k = np.round(bounds / ts)
    return bounds, np.abs(bounds - k * ts) <= tiny


def _adaptive_runs(n_runs, y0s, prms, mode, lins, sigs, forms, ctrl, kp, u_limit, ts, t_end, dt, n_out,
                   cancel, parallel, h_max=None, K=None):
    """Integrate runs with the adaptive kernel, chunk by chunk; returns (outs, status, fail_t, steps).

    ``sigs[j]`` and ``forms[j]``: run j's (u, d, r) signals and their :func:`_segment_form`. ``K``: the
    kernels' module (default the four-state :mod:`eha_core._kernels`; the states are the columns of ``y0s``).
    """
    if K is None:
        from . import _kernels as K

    h_max = math.inf if h_max is None else h_max
    outs = np.zeros((n_runs, n_out, 5))
    status = np.full(n_runs, -1, dtype=np.int64)
    fail_t = np.full(n_runs, np.nan)
    n_states = np.shape(y0s)[-1]
    scale = _SCALE if n_states == 4 else _SCALE_SPOOL
    y = np.array(y0s, dtype=float).reshape(n_runs, n_states).copy()
    # state: [proposed step, held command, time of failure, time of a pause]; counts: [next output sample,
    # accepted steps, rejected steps, right-hand side evaluations, segment of a pause]
    state = np.zeros((n_runs, 4))
    state[:, 0] = min(dt, 1e-3) * 0.1           # a first step; the error control corrects it
    counts = np.zeros((n_runs, 5), dtype=np.int64)
    n_chunks = max(1, math.ceil(t_end / CHUNK_SECONDS - 1e-9))

    def one(j, a, b, final):
        seg_t, seg_ctrl = _segment_bounds(sigs[j], a, b, ts if ctrl == K.ZOH else None, t_end)
        lines = [_segment_lines(forms[j][i][2], name, seg_t) for i, name in enumerate(("u", "d", "r"))]
        n_sm = np.array([forms[j][i][1] for i in range(3)], dtype=float)
        state[j, 3] = np.nan
        counts[j, 4] = 0
        while True:
            st = K.integrate_segments(y[j], state[j], counts[j], seg_t.size - 1, seg_t, lines[0], lines[1],
                                      lines[2], seg_ctrl, forms[j][0][0], forms[j][1][0], forms[j][2][0], n_sm,
                                      prms[j], mode, lins[j], ctrl, kp, u_limit, TOL, scale, dt, h_max, outs[j],
                                      MAX_ADAPTIVE_STEPS, final, counts[j, 1] + counts[j, 2] + CANCEL_CHECK_STEPS)
            if st != K.PAUSED:
                break
            if cancel is not None:
                cancel.check()
        if st >= 0:
            status[j] = st
            fail_t[j] = state[j, 2]

    pool = None
    if parallel and n_runs > 1:
        from concurrent.futures import ThreadPoolExecutor

        import numba

        pool = ThreadPoolExecutor(max_workers=max(1, min(n_runs, numba.get_num_threads())))
    try:
        for c in range(n_chunks):
            if cancel is not None:
                cancel.check()
            a = c * CHUNK_SECONDS
            final = c == n_chunks - 1
            b = t_end if final else (c + 1) * CHUNK_SECONDS
            alive = [j for j in range(n_runs) if status[j] < 0]
            if pool is not None:
                list(pool.map(lambda j, a=a, b=b, final=final: one(j, a, b, final), alive))
            else:
                for j in alive:
                    one(j, a, b, final)
            if not alive:
                break
    finally:
        if pool is not None:
            pool.shutdown()
    return outs, status, fail_t, counts


# -- public API --------------------------------------------------------------------

def simulate(params: ActuatorParams | None = None, u=None, d=None, *, t_end: float = 5.0,
             dt: float = 1e-3, model: str = "nonlinear", branch: str = "switching",
             initial_state=None, op: OperatingPoint | None = None, h_max: float | None = None,
             label: str = "", cancel: CancelToken | None = None) -> SimulationResult:
    """Open-loop run: valve command ``u(t)`` [V] and load disturbance ``d(t)`` [N].

    Parameters
    ----------
    params : ActuatorParams, optional
        Defaults to the paper's parameters.
    u, d : Signal, callable, number or array, optional
        A :mod:`eha_core.signals` signal, a function of t (vectorised or not),
        a constant, or one sample per output time (interpolated linearly).
        A function of t, or a signal with more than 4 sines and chirps, takes
        the fixed-step RK4, not exact at jumps (see Notes).
    t_end, dt : float
        Horizon and output interval [s]; the result has ``t_end/dt + 1`` samples.
    model : {'nonlinear', 'linear'}
        The nonlinear model (eqs. 1-4) or the one linearised at ``op`` (eqs. 20-24).
    branch : {'switching', 'positive', 'negative'}
        Linear model only: switch l5, l6 with the sign of u (default, as the
        paper's Fig. 3), or keep one branch.
    initial_state : array of 4 (or 6), optional
        Initial state [x, v, p1, p2]; defaults to the parameters' initial conditions. With the valve's
        spool dynamics (``params.effects``) six may be given, [x, v, p1, p2, u_v, du_v/dt]; with four the
        spool starts at rest at u_v = 0.
    op : OperatingPoint, optional
        Linearisation point (default :func:`eha_core.linear.operating_point`).
    h_max : float, optional
        Largest integration step [s]. None (default): the adaptive integrator chooses its steps by
        its error control alone, and the fixed-step RK4 (an input given as a function of t) steps
        at :data:`DEFAULT_H_MAX`.
    label : str
        The run's name, kept in :attr:`SimulationResult.label`.
    cancel : eha_core.cancel.CancelToken, optional
        Checked between integration chunks (and every ``CANCEL_CHECK_STEPS`` adaptive steps); raises
        Cancelled when set.

    Notes
    -----
    Two integrators. Inputs that are :mod:`eha_core.signals` signals with at most
    :data:`~eha_core._kernels.MAX_SMOOTH` (4) sines and chirps each (held, stepped, square,
    sampled and noise terms in any number) take the adaptive DOP853 with dense output, restarted at
    every jump of the inputs and where u changes sign (eq. 3), error tolerance :data:`TOL` = 1e-9:
    its error is near 2e-7 of each state's range on the paper's smooth cases and 1e-8 on a square
    wave and a step (benchmarks/bench_simulate.py, against Radau at rtol 1e-10). Against
    numbalsoda's solvers at the tolerance that matches that accuracy: as fast as its DOP853 on the
    smooth cases within the timing's noise (its time over ours 0.89 in one run, 1.38 in another),
    1.6 times faster on the jumps, which it steps over, and twice as fast as its LSODA.

    A function of t (its jumps are unknown) or a signal with more than 4 sines and chirps takes the
    fixed-step RK4 at ``h_max`` (default :data:`DEFAULT_H_MAX`, 5e-4 s): on smooth inputs as
    accurate (2e-7 of the range), but a jump between its steps is seen only at the next step, an
    error of 2.5e-3 of the range on the square wave. Give jumps as signals (``Square``, ``Step``,
    ``Sampled``) to have them exact.
    """
    params = params if params is not None else ActuatorParams()
    return simulate_many([params], [u], [d], t_end=t_end, dt=dt, model=model, branch=branch,
                         initial_states=None if initial_state is None else [initial_state], op=op, h_max=h_max,
                         labels=[label], cancel=cancel)[0]


def simulate_many(params: ActuatorParams | Sequence[ActuatorParams] | None, us: Sequence, ds: Sequence | None = None,
                  *, t_end: float = 5.0, dt: float = 1e-3, model: str = "nonlinear",
                  branch: str = "switching", initial_states: Sequence | None = None,
                  op: OperatingPoint | None = None, h_max: float | None = None,
                  labels: Sequence[str] | None = None, cancel: CancelToken | None = None,
                  parallel: bool = True) -> list[SimulationResult]:
    """Several open-loop runs on one time grid, integrated in parallel.

    Parameters
    ----------
    params : ActuatorParams or sequence of ActuatorParams, optional
        One parameter set for all runs, or one per run.
    us, ds : sequence
        Each run's input and disturbance (see :func:`simulate`).
    t_end, dt, model, branch, op, h_max
        As for :func:`simulate`.
    initial_states : sequence of arrays of 4 (or 6), optional
        Each run's initial state (see :func:`simulate`).
    labels : sequence of str, optional
        Each run's name (:attr:`SimulationResult.label`); default empty.
    cancel : eha_core.cancel.CancelToken, optional
        Checked between integration chunks (and every ``CANCEL_CHECK_STEPS`` adaptive steps); raises
        :class:`~eha_core.cancel.Cancelled` when set.
    parallel : bool
        True: the runs are integrated at once by numba's parallel kernel, over
        as many threads as ``numba.get_num_threads()`` in the calling thread
        (all cores by default). False: one after another on the calling
        thread's core, bitwise the same results. A server running several
        users' jobs in worker threads wants one core per job: ``parallel=False``
        gives that with any numba threading layer, and never launches a
        parallel region from several threads at once (which aborts the process
        under the 'workqueue' layer). ``numba.set_num_threads(1)`` in the
        worker thread also confines this call to one thread: numba keeps that
        setting per thread, as checked with the 'omp' layer (numba 0.68).

    Returns
    -------
    list of SimulationResult
    """
    n = len(us)
    if n == 0:
        return []
    ds = list(ds) if ds is not None else [None] * n
    if len(ds) != n:
        raise not_allowed("ds", ds, f"{len(ds)} disturbances given for {n} inputs; give one per input")
    if params is None or isinstance(params, ActuatorParams):
        params_list = [params or ActuatorParams()] * n
    else:
        params_list = list(params)
        if len(params_list) != n:
            raise not_allowed("params", params_list, f"{len(params_list)} parameter sets given for {n} runs; "
                                                     "give one, or one per run")
    labels = list(labels) if labels is not None else [""] * n
    mode = _mode(model, branch)
    spools = [p.effects.spool for p in params_list]
    if any(spools) and not all(spools):
        # the models with and without the spool's states take different kernels: a batch for each
        results: list = [None] * n
        for group in (False, True):
            idx = [j for j in range(n) if spools[j] == group]
            runs = simulate_many([params_list[j] for j in idx], [us[j] for j in idx], [ds[j] for j in idx],
                                 t_end=t_end, dt=dt, model=model, branch=branch,
                                 initial_states=None if initial_states is None else [initial_states[j] for j in idx],
                                 op=op, h_max=h_max, labels=[labels[j] for j in idx], cancel=cancel,
                                 parallel=parallel)
            for j, run in zip(idx, runs, strict=True):
                results[j] = run
        return results
    K = _kernels_of(params_list[0])
    spool = spools[0]

    h, sub, _, n_steps, n_out = _grid(t_end, dt, _rk4_h_max(h_max))
    t = np.arange(n_out) * dt

    y0s = np.empty((n, 6 if spool else 4))
    prms = np.empty((n, N_PACKED_PARAMS))
    lins = np.empty((n, N_PACKED_LINEAR_SPOOL if spool else N_PACKED_LINEAR))
    u_sigs, d_sigs, d_out = [], [], []
    for j in range(n):
        p = params_list[j]
        y0s[j] = _initial(p, initial_states[j] if initial_states is not None else None)
        prms[j] = pack_params(p)
        lins[j] = _lin_vector(p, op, mode != K.NONLINEAR)
        u_sigs.append(_as_signal(us[j], "u", t))
        d_sigs.append(_as_signal(ds[j], "d", t))
        d_out.append(_sample(d_sigs[j], "d", t))
    name = _model_label(model, branch)
    forms = [(_segment_form(u_sigs[j]), _segment_form(d_sigs[j]), _segment_form(ZERO)) for j in range(n)]
    if all(f is not None for fs in forms for f in fs):
        t_end_grid = (n_out - 1) * dt
        sigs = [(u_sigs[j], d_sigs[j], ZERO) for j in range(n)]
        outs, status, fail_t, counts = _adaptive_runs(n, y0s, prms, mode, lins, sigs, forms, K.OPEN_LOOP, 0.0, 0.0,
                                                      None, t_end_grid, dt, n_out, cancel, parallel, h_max, K)
        return [_simulation_result(outs[j], int(status[j]), t, d_out[j], params_list[j], name, labels[j],
                                   h=t_end_grid / max(1, counts[j, 1]), t_fail=fail_t[j]) for j in range(n)]

    # a function of t: its jumps are not known, so the fixed-step RK4 on the output grid
    no_r = np.zeros((1, 3))

    def stages(j, start, count):
        return (_stage_samples(u_sigs[j], "u", h, count, start), _stage_samples(d_sigs[j], "d", h, count, start),
                no_r)

    outs, status = _integrate_chunked(n, y0s, h, n_steps, sub, prms, mode, lins, stages, K.OPEN_LOOP, 0.0, 1,
                                      0.0, n_out, cancel, parallel, K)
    return [_simulation_result(outs[j], int(status[j]), t, d_out[j], params_list[j], name, labels[j], h=h)
            for j in range(n)]


def simulate_closed_loop(params: ActuatorParams | None = None, r=None, *, kp: float = 10.0,
                         ts: float = 0.01, controller: str = "zoh", d=None,
                         t_end: float | None = None, dt: float | None = None,
                         model: str = "nonlinear", branch: str = "switching", initial_state=None,
                         op: OperatingPoint | None = None, u_limit: float | None = None,
                         h_max: float | None = None, label: str = "",
                         cancel: CancelToken | None = None) -> SimulationResult:
    """Closed loop with the proportional controller u = Kp (r - x) (eq. 22).

    Parameters
    ----------
    params : ActuatorParams, optional
        Defaults to the paper's parameters.
    r : Signal, callable or array
        Reference position [m]. An array is taken as samples at ``ts`` held
        between samples (zero-order hold), as a digital reference would be;
        ``t_end`` then defaults to the time of its last sample.
    kp : float
        Proportional gain [V/m].
    ts : float
        Controller sample time [s] (``controller='zoh'``): the controller reads
        x at k ts and holds u until the next sample.
    controller : {'zoh', 'continuous'}
        Sampled controller held between samples (default), or u computed continuously.
    d : Signal, callable, number or array, optional
        Load disturbance [N], as for :func:`simulate` (an array is one sample per output time); default 0.
    t_end : float, optional
        Horizon [s]; required unless ``r`` is an array of samples.
    dt : float, optional
        Output interval [s], default ``ts``; it and ``ts`` must be whole multiples of one another.
    model : {'nonlinear', 'linear'}
        The nonlinear model (eqs. 1-4) or the one linearised at ``op`` (eqs. 20-24).
    branch : {'switching', 'positive', 'negative'}
        Linear model only: the valve's branch, as for :func:`simulate`.
    initial_state : array of 4 (or 6), optional
        Initial state [x, v, p1, p2] (SI units); defaults to the parameters' initial conditions. With
        the valve's spool dynamics (``params.effects``) six may be given, [x, v, p1, p2, u_v, du_v/dt];
        with four the spool starts at rest at u_v = 0.
    op : OperatingPoint, optional
        Linearisation point (default :func:`eha_core.linear.operating_point`).
    u_limit : float, optional
        Saturate the valve command to +-u_limit [V] (no limit by default).
    h_max : float, optional
        Largest integration step [s]. None (default): the adaptive integrator chooses its steps by
        its error control alone, and the fixed-step RK4 (an input given as a function of t) steps
        at :data:`DEFAULT_H_MAX`.
    label : str
        The run's name, kept in :attr:`SimulationResult.label`.
    cancel : eha_core.cancel.CancelToken, optional
        Checked between integration chunks (and every ``CANCEL_CHECK_STEPS`` adaptive steps); raises
        Cancelled when set.

    Notes
    -----
    The integrators are those of :func:`simulate`: ``r`` and ``d`` as signals (or an array of
    samples) take the adaptive DOP853, restarted at every controller instant and every jump of
    theirs; a function of t, or a signal with more than 4 sines and chirps, takes the fixed-step
    RK4, not exact at jumps.
    """
    params = params if params is not None else ActuatorParams()
    K = _kernels_of(params)
    kp = positive_number("kp", kp, "must be a finite gain > 0 V/m")
    ts = positive_number("ts", ts, "must be a finite sample time > 0 s")
    if controller not in CONTROLLERS:
        raise not_allowed("controller", controller, f"use one of {', '.join(CONTROLLERS)}")
    if u_limit is not None:
        u_limit = positive_number("u_limit", u_limit, "must be a finite voltage > 0, or None for no limit")
    if r is None:
        raise not_allowed("r", r, "a reference signal is required")
    if t_end is None:
        if isinstance(r, Signal) or callable(r) or np.ndim(r) == 0:
            raise not_allowed("t_end", t_end, "give the horizon when the reference is not an array of samples")
        t_end = (np.asarray(r).size - 1) * ts
    dt = ts if dt is None else dt
    mode = _mode(model, branch)
    h, sub, ctrl_every, n_steps, n_out = _grid(t_end, dt, _rk4_h_max(h_max), ts=ts)
    t = np.arange(n_out) * dt
    if isinstance(r, Signal) or callable(r) or np.ndim(r) == 0:
        r_sig = _as_signal(r, "r", t)
    else:
        r_arr = np.asarray(r, dtype=float).ravel()
        r_sig = Sampled(np.arange(r_arr.size) * ts, r_arr, hold="zoh", name="r")
    d_sig = _as_signal(d, "d", t)
    ctrl = K.ZOH if controller == "zoh" else K.CONTINUOUS
    u_lim = 0.0 if u_limit is None else u_limit
    y0 = _initial(params, initial_state)[None, :]
    lin = _lin_vector(params, op, mode != K.NONLINEAR)[None, :]
    forms = (_segment_form(ZERO), _segment_form(d_sig), _segment_form(r_sig))
    if all(f is not None for f in forms):
        t_end_grid = (n_out - 1) * dt
        outs, status, fail_t, counts = _adaptive_runs(1, y0, pack_params(params)[None, :], mode, lin,
                                                      [(ZERO, d_sig, r_sig)], [forms], ctrl, kp, u_lim, ts,
                                                      t_end_grid, dt, n_out, cancel, False, h_max, K)
        return _simulation_result(outs[0], int(status[0]), t, _sample(d_sig, "d", t), params,
                                  _model_label(model, branch), label, r=_sample(r_sig, "r", t),
                                  controller=controller, kp=kp, h=t_end_grid / max(1, counts[0, 1]),
                                  t_fail=fail_t[0])

    # a function of t: the fixed-step RK4 on the output and controller grid
    no_u = np.zeros((1, 3))

    def stages(_j, start, count):
        return no_u, _stage_samples(d_sig, "d", h, count, start), _stage_samples(r_sig, "r", h, count, start)

    outs, status = _integrate_chunked(1, y0, h, n_steps, sub, pack_params(params)[None, :], mode, lin, stages,
                                      ctrl, kp, ctrl_every, u_lim, n_out, cancel, False, K)
    return _simulation_result(outs[0], int(status[0]), t, _sample(d_sig, "d", t), params, _model_label(model, branch),
                              label, r=_sample(r_sig, "r", t), controller=controller, kp=kp, h=h)
