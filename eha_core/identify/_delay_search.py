"""The input-delay search of :func:`eha_core.identify.tfest.tfest` (``input_delay="estimate"``).

The model is ``y = G(s) e^(-s tau) (u + c)``, ``tau`` in seconds, not
necessarily a multiple of ``ts`` (MATLAB's ``IODelay``):

- the whole-sample part is searched first, as MATLAB's ``delayest``
  does: an ARX model (``np`` poles, ``np + 1`` input lags, a constant when
  the offset is estimated) is fitted by least squares for every delay
  ``0..max_delay`` on the same samples, and its loss gives the best whole
  delay ``d`` (:func:`arx_delay_losses`);
- SRIVC (:mod:`eha_core.identify._srivc`) runs at ``d - 1``, ``d``, ``d + 1``
  and the range is extended a sample at a time while the lowest output-error
  cost lies at one of its ends (ARX is biased by output noise and can be off
  by more than a sample). Only models that are not markedly unstable
  (:func:`is_stable`) are ranked: a delay that is too long cannot be made up
  and SRIVC ends in unstable models there, so while there are none the
  search moves to shorter delays. At each delay SRIVC starts from the best
  model so far (few iterations), and from the default starts too while no
  stable model has been found (:func:`delay_candidates`);
- the cost can have several local minima over the delay (a right-half-plane
  zero's undershoot mimicked by a longer delay, say), and that search stops
  at the first: the rest of ``0..max_delay`` is swept with a SRIVC iteration
  per delay from the model at the nearest delay, at a few delays over the
  whole range from the default starts too (a poor model carried from delay
  to delay stays poor: a lightly damped plant's search from ARX's delay,
  four samples long, was carried so down to the true one in 29 of 100
  records at 5 dB, never reaching the model that fits there; a better model
  found so is carried to its neighbours), and the lowest few local minima
  of the swept cost are converged at the whole sample;
- the output-error stage (:mod:`eha_core.identify._oe_refine`) then refines
  ``tau`` with the coefficients, from the best model of each of those minima;
- the answer is checked against :func:`noise_floor`, the residual variance
  of a long linear model of the record that fits any delay in its lags
  (:func:`above_floor`): when it is markedly above, :func:`delay_candidates`
  runs again with the default starts at every delay (``everywhere``), and
  an answer still above it is not a success.

Private as a module: its names are used by :mod:`eha_core.identify.tfest`.
Only numpy is imported here.
"""

from __future__ import annotations

import numpy as np

from ..cancel import CancelToken, check
from ._oe_criterion import OutputError
from ._srivc import srivc_candidates

__all__ = ["BASIN_COST_RATIO", "FLOOR_GAP", "FLOOR_RATIO", "FRESH_POINTS", "MAX_FLOOR_LAGS", "MAX_SWEEP", "N_BASINS",
           "SWEEP_ITERATIONS", "above_floor", "arx_delay_losses", "delay_candidates", "is_stable", "noise_floor"]


def arx_delay_losses(u: np.ndarray, y: np.ndarray, n: int, d_max: int, offset: bool,
                      cancel: CancelToken | None = None, intersample: str = "zoh") -> np.ndarray:
    """ARX loss for every whole-sample delay ``d = 0..d_max`` (MATLAB ``delayest``'s approach).

    ``y[k] + a_1 y[k-1] + ... + a_n y[k-n] = b_0 u[k-d-1] + ... + b_n u[k-d-1-n] (+ const)``:
    the exact ZOH model of ``G(s) e^(-s (d + f) ts)`` (strictly proper) has
    ``n + 1`` input lags from ``d + 1`` on; for an input linear between
    samples (``intersample="foh"``) it has ``n + 2`` from ``d`` on (the
    piece of input ending at the sample instant). Every delay is fitted on
    the same samples (``k >= d_max + n + 1``), so the losses compare. The
    output lags (and the constant) are projected out once; each delay then
    costs one small least-squares problem. ``cancel`` is looked at every 64
    delays.
    """
    n_b, first = (n + 1, 1) if intersample == "zoh" else (n + 2, 0)
    k0 = max(n, d_max + first + n_b - 1)
    n_rows = y.size - k0
    base = [-y[k0 - i:y.size - i] for i in range(1, n + 1)]
    if offset:
        base.append(np.ones(n_rows))
    q, _ = np.linalg.qr(np.column_stack(base))
    target = y[k0:] - q @ (q.T @ y[k0:])
    losses = np.empty(d_max + 1)
    for d in range(d_max + 1):
        if d % 64 == 0:
            check(cancel)
        lags = np.column_stack([u[k0 - d - first - j:u.size - d - first - j] for j in range(n_b)])
        lags -= q @ (q.T @ lags)
        if not (np.all(np.isfinite(lags)) and np.all(np.isfinite(target))):
            losses[d] = np.inf          # (LAPACK would print its complaint about NaN to stderr)
            continue
        coef, *_ = np.linalg.lstsq(lags, target, rcond=None)
        r = target - lags @ coef
        losses[d] = r @ r
    return losses


def is_stable(theta: np.ndarray, n: int, rate: float) -> bool:
    """No pole of ``theta``'s denominator with a real part above ``rate`` (1/s).

    ``rate`` is about one over the record's length: a pole growing slower
    than that is indistinguishable from an integrator (which an estimate
    may put slightly to the right of zero).
    """
    poles = np.roots(np.r_[1.0, theta[:n]])
    return bool(np.all(poles.real <= rate))


#: Most input lags of :func:`noise_floor`'s linear model (its least squares cost N L^2).
MAX_FLOOR_LAGS = 256
#: An estimate whose noise variance exceeds :func:`noise_floor`'s this many times ...
FLOOR_RATIO = 1.4
#: ... and by this fraction of the output's variance is not claimed found (:func:`above_floor`).
FLOOR_GAP = 0.1


def above_floor(noise_variance: float, floor: float, y: np.ndarray) -> bool:
    """Whether an estimate's noise variance is markedly above :func:`noise_floor`'s: a model to doubt.

    Both :data:`FLOOR_RATIO` times the floor and :data:`FLOOR_GAP` of the
    output's variance above it: the first says more than the noise is left,
    the second that it matters. A wrong local minimum of the delay search
    leaves a large part of the output unexplained (on a lightly damped
    third-order plant at 5 dB SNR, 21 % of its variance or more; a right
    answer, under 3 %); on nearly noise-free records any small mismatch of
    the model (a nonlinear plant, an initial state taken as zero) is many
    times the floor, and only the second condition keeps it from counting
    (the paper's frequency experiment with the initial state taken as zero:
    7 %).
    """
    return bool(noise_variance > FLOOR_RATIO * floor and noise_variance - floor > FLOOR_GAP * np.var(y))


def noise_floor(u: np.ndarray, y: np.ndarray, n: int, d_max: int, offset: bool) -> tuple[float, int]:
    """Residual variance of a long linear model of the record, by least squares: ``(variance, input lags)``.

    ``y[k] = -a_1 y[k-1] - ... - a_n y[k-n] + b_0 u[k] + ... + b_L u[k-L] (+ const)``
    on ``k >= L``, ``L = min(d_max + N / 10, N / 4, MAX_FLOOR_LAGS)`` input
    lags (the whole delay range and a tail), the variance ``RSS / (rows -
    rank)``. Any
    delay in the range and any response that has mostly died out within
    ``L`` samples are inside this model, so output noise white and
    independent of the input leaves a variance near its own whatever the
    delay; a model of the right order at the right delay, near it too (in
    the tests, 0.9 to 1.1 times). A response longer than ``L`` or a
    nonlinearity only raise it: the check it serves can miss, it does not
    accuse a right answer. A delay search that ended in a worse local
    minimum leaves the model's noise variance well above it (2 to 4 times on
    a lightly damped third-order plant at 5 dB SNR, the cost's ratio to the
    one at the true delay).
    """
    size = y.size
    lags = int(min(d_max + size // 10, size // 4, MAX_FLOOR_LAGS))
    first = max(lags, n)
    columns = [u[first - j:size - j] for j in range(lags + 1)] + [-y[first - i:size - i] for i in range(1, n + 1)]
    if offset:
        columns.append(np.ones(size - first))
    x = np.column_stack(columns)
    target = y[first:]
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(target))) or target.size <= x.shape[1]:
        return np.nan, lags
    coef, _, rank, _ = np.linalg.lstsq(x, target, rcond=None)
    r = target - x @ coef
    # the rank, not the columns: a step or a sine makes the lags collinear
    return float(r @ r) / (target.size - rank), lags


#: Most delays the SRIVC sweep of the whole range evaluates: a longer range is swept with a coarser step.
MAX_SWEEP = 128
#: SRIVC iterations per delay of the sweep, each started from the model at the nearest delay swept.
SWEEP_ITERATIONS = 1
#: Delays spread over the whole range where the sweep starts SRIVC from the default starts too.
FRESH_POINTS = 16
#: Local minima of the cost over the whole-sample delays whose models the output-error stage refines.
N_BASINS = 3
#: Local minima whose cost exceeds the lowest one's this many times are not refined.
BASIN_COST_RATIO = 2.0


def delay_candidates(criterion: OutputError, m: int, starts, start_names, max_iter: int, tol: float,
                     everywhere: bool = False):
    """SRIVC candidates for an estimated delay: ``(candidates, iterations, basins)``.

    Every candidate's ``theta`` ends with its delay (s). ``basins`` holds the
    best stable candidate at each of the (up to :data:`N_BASINS`) lowest
    local minima of the cost over the whole-sample delays, lowest first: the
    output-error stage refines each of them.

    1. A local search over whole-sample delays on the SRIVC/output-error
       cost, started at the delay ``d`` of least ARX loss
       (:func:`arx_delay_losses`): ``d - 1``, ``d``, ``d + 1`` are tried, then
       the range is extended by one sample on the side where the lowest cost
       lies, as long as it lies at an end. ARX is biased by output noise and
       can be off by more than a sample. A delay that is too long cannot be
       made up by the model (it would have to anticipate the input), and
       SRIVC then ends in unstable models whose costs say nothing about the
       direction to go; a delay that is too short is partly made up by
       slower poles, and the cost falls towards the true delay. So only
       models that are not markedly unstable (no pole growing faster than
       once over the record) are ranked, and while there are none the search
       moves to shorter delays. At each delay SRIVC starts from the best such
       model found so far (the dynamics barely change with a sample of
       delay, so few iterations are needed); while there is none, the
       default starts are tried too.
    2. The cost can have several local minima over the delay, and the
       search above stops at the first: a right-half-plane zero's initial
       undershoot, say, is mimicked by a longer delay and a zero in the left
       half-plane. (At 5 dB SNR, ``(1 - s) / (s^2 + s + 1)`` behind 8 s sampled
       at 0.5 s: ARX points at 9.5 s, the search stopped there in 17 of 200
       records, the output error at about 9.4 s with a cost 4 to 14 % above
       the one at 8 s.) So the rest of ``0..max_delay`` is swept, every sample (every
       ``ceil((d_max + 1) / MAX_SWEEP)``-th on a longer range), by
       :data:`SWEEP_ITERATIONS` SRIVC iterations from the stable model at the
       nearest delay swept; this needs a stable model from step 1.
       At :data:`FRESH_POINTS` delays spread over the range SRIVC also
       starts from the default starts (a model carried from a poor local
       minimum stays poor), and a model found so that is better than the
       one carried there is carried on to the neighbouring delays while it
       stays better. With ``everywhere``, steps 1 and 2 are replaced by a
       sweep of every delay from the default starts too (and the carrying).
    3. At the lowest local minima of the swept cost (:data:`N_BASINS` of
       them, those within :data:`BASIN_COST_RATIO` times the lowest: a
       minimum that much worse does not win after the output-error stage,
       which only adds the fraction of a sample), a coarse sweep is
       descended to the whole sample, and SRIVC is run to convergence from
       the model there: those are the ``basins``.
    """
    search = _DelaySearch(criterion, m, max_iter, tol)
    if everywhere:
        search.sweep_everywhere(starts, start_names)
    else:
        search.local_search(starts, start_names)
        if not search.stable_best:
            return search.candidates, search.nit_total, []
        search.sweep_range()
    if not search.stable_best:
        return search.candidates_with_swept(), search.nit_total, []
    basins = search.basins()
    return search.candidates_with_swept(), search.nit_total, basins


class _DelaySearch:
    """The state of :func:`delay_candidates`: the candidates and the cost at every delay tried."""

    def __init__(self, criterion: OutputError, m: int, max_iter: int, tol: float):
        self.criterion, self.m, self.max_iter, self.tol = criterion, m, max_iter, tol
        self.ts, self.n = criterion.ts, criterion.n
        self.d_max = int(np.floor(criterion.max_delay / self.ts + 1e-10))
        self.rate = 1.0 / (criterion.u.size * self.ts)
        self.candidates, self.stable = [], []
        self.stable_cost = {}  # lowest cost of a stable model at each delay tried (inf: none)
        self.stable_best = {}  # the best stable candidate at each delay tried
        self.swept = {}  # the stable candidates of the sweep at each delay (not yet in candidates)
        self.fresh = set()  # the delays where SRIVC was started from the default starts too
        self.fresh_won = set()  # the delays of the sweep where a default start beat the model carried there
        self.starts, self.start_names = [], []
        self.nit_total = 0

    def srivc_at(self, d: int, starts, names, iterations: int):
        """SRIVC at a delay of ``d`` samples: ``(candidates, stable candidates)``, costs recorded."""
        c = self.criterion
        fixed = OutputError(c.u, c.y, self.ts, self.n, c.estimate_initial_state, c.estimate_offset, c.cancel,
                            input_delay=d * self.ts, intersample=c.intersample)
        found, nit = srivc_candidates(fixed, self.m, starts, names, iterations, self.tol)
        self.nit_total += nit
        found = [(np.r_[f[0], d * self.ts], f[1], f[2], f"{f[3]} (delay {d} samples)", f[4]) for f in found]
        found_stable = [f for f in found if is_stable(f[0], self.n, self.rate)]
        # a delay tried again (a sweep from another model) keeps the better of the two
        new = min(found_stable, key=lambda f: f[1]) if found_stable else None
        if new is not None and new[1] < self.stable_cost.get(d, np.inf):
            self.stable_cost[d], self.stable_best[d] = new[1], new
        else:
            self.stable_cost.setdefault(d, np.inf)
        return found, found_stable

    def run(self, d: int, starts, start_names) -> None:
        """SRIVC to convergence at ``d`` from the best model so far (and the default starts while none is stable)."""
        best = min(self.stable or self.candidates, key=lambda f: f[1]) if self.candidates else None
        d_starts, d_names = [], []
        if best is not None:
            d_starts.append(("model", best[0][:-1]))
            d_names.append(f"the estimate at a delay of {round(best[0][-1] / self.ts)} samples")
        if not self.stable:
            d_starts += starts
            d_names += start_names
            self.fresh.add(d)
        found, found_stable = self.srivc_at(d, d_starts, d_names, self.max_iter)
        self.candidates.extend(found)
        self.stable.extend(found_stable)

    def sweep(self, d: int, source: int | None = None, fresh: bool = False) -> bool:
        """:data:`SWEEP_ITERATIONS` of SRIVC at ``d`` from the stable model at ``source``.

        ``source`` defaults to the nearest other delay tried; with ``fresh``
        the default starts are tried too. True when the model at ``d``
        improved (or is the first stable one there); the stable candidates
        found then wait in :attr:`swept` for :meth:`basins`.
        """
        others = [e for e in self.stable_best if e != d]
        if source is None and others:
            source = min(others, key=lambda e: (abs(e - d), e))
        before = self.stable_best.get(d)
        found_stable = []
        if source is not None:
            _, found_stable = self.srivc_at(d, [("model", self.stable_best[source][0][:-1])],
                                            [f"the estimate at a delay of {source} samples"], SWEEP_ITERATIONS)
        if fresh:
            self.fresh.add(d)
            carried = self.stable_best.get(d)
            _, found_fresh = self.srivc_at(d, self.starts, self.start_names, SWEEP_ITERATIONS)
            found_stable += found_fresh
            if self.stable_best.get(d) is not carried:
                self.fresh_won.add(d)
        if self.stable_best.get(d) is before:
            return False
        self.swept[d] = self.swept.get(d, []) + found_stable
        return True

    def local_search(self, starts, start_names) -> None:
        """Step 1: from the delay of least ARX loss, while the lowest cost lies at an end of the range tried."""
        c = self.criterion
        self.starts, self.start_names = list(starts), list(start_names)
        d_arx = int(np.argmin(arx_delay_losses(c.u, c.y, self.n, self.d_max, c.estimate_offset, c.cancel,
                                               c.intersample)))
        for d in (d_arx, d_arx - 1, d_arx + 1):
            if 0 <= d <= self.d_max:
                self.run(d, starts, start_names)
        cost = self.stable_cost
        while True:
            lo, hi = min(cost), max(cost)
            lowest = min(cost, key=cost.get)
            if not np.isfinite(cost[lowest]):
                if lo == 0:
                    break  # unstable at every delay down to 0: rank what there is by cost
                self.run(lo - 1, starts, start_names)
            elif lowest == lo and lo > 0:
                self.run(lo - 1, starts, start_names)
            elif lowest == hi and hi < self.d_max:
                self.run(hi + 1, starts, start_names)
            else:
                break

    def sweep_range(self) -> None:
        """Step 2: the rest of ``0..d_max`` (every ``step``-th delay), outwards from the range searched.

        At :data:`FRESH_POINTS` delays spread over the whole range (those
        of the local search included) the default starts are tried too, and
        a model found so that is better than the one carried there is
        carried on to the neighbouring delays while it stays better.
        """
        lo, hi = min(self.stable_cost), max(self.stable_cost)
        grid = self.grid()
        fresh = set(grid[::max(1, int(np.ceil(len(grid) / FRESH_POINTS)))]) | {self.d_max}
        for d in [d for d in reversed(grid) if d < lo] + [d for d in grid if d > hi]:
            self.sweep(d, fresh=d in fresh and d not in self.fresh)
        for d in sorted(fresh - self.fresh):
            self.sweep(d, fresh=True)
        self.carry()

    def sweep_everywhere(self, starts, start_names) -> None:
        """Instead of steps 1 and 2: every delay swept started from the default starts too (upwards from 0)."""
        self.starts, self.start_names = list(starts), list(start_names)
        for d in self.grid():
            self.sweep(d, fresh=True)
        self.carry()

    def grid(self) -> list:
        """The delays swept: every one of ``0..d_max``, every ``ceil((d_max + 1) / MAX_SWEEP)``-th on a longer range."""
        step = int(np.ceil((self.d_max + 1) / MAX_SWEEP))
        return sorted(set(range(0, self.d_max + 1, step)) | {self.d_max})

    def carry(self) -> None:
        """Carry the models a default start found better than the one carried there to the neighbouring delays.

        From each delay, while they stay better there; a default start's
        model markedly worse than the best so far (more than
        :data:`BASIN_COST_RATIO` times) is not carried: such a minimum
        would not be refined either.
        """
        if not self.stable_best:
            return
        least = min(self.stable_cost.values())
        carry = [d for d in sorted(self.fresh_won) if self.stable_cost[d] <= BASIN_COST_RATIO * least]
        while carry:
            d = carry.pop()
            for e in self.neighbours(d):
                if self.sweep(e, source=d):
                    carry.append(e)

    def neighbours(self, d: int) -> list:
        """The nearest delays tried below and above ``d``."""
        below = [e for e in self.stable_cost if e < d]
        above = [e for e in self.stable_cost if e > d]
        return ([max(below)] if below else []) + ([min(above)] if above else [])

    def descend(self, d: int) -> int:
        """From a local minimum of a coarse sweep to one at the whole sample."""
        while True:
            for e in (d - 1, d + 1):
                if 0 <= e <= self.d_max and e not in self.stable_cost:
                    self.sweep(e)
            lower = min((e for e in (d - 1, d, d + 1) if 0 <= e <= self.d_max), key=self.stable_cost.get)
            if lower == d:
                return d
            d = lower

    def converge(self, d: int) -> None:
        """SRIVC to convergence at a delay only swept, from the sweep's model there."""
        start = self.stable_best[d]
        found, _ = self.srivc_at(d, [("model", start[0][:-1])],
                                 [f"the estimate of the sweep at a delay of {d} samples"], self.max_iter)
        del self.swept[d]
        self.candidates.extend(found)
        if self.stable_best[d] is start:  # the iterations went unstable or no lower: keep the sweep's model
            self.candidates.append(start)

    def basins(self) -> list:
        """Step 3: the best stable candidate at each of the lowest local minima of the cost, lowest first."""
        tried = sorted(self.stable_cost)
        costs = [self.stable_cost[d] for d in tried]
        minima = [d for i, d in enumerate(tried) if np.isfinite(costs[i])
                  and (i == 0 or costs[i] <= costs[i - 1]) and (i == len(tried) - 1 or costs[i] <= costs[i + 1])]
        least = min(self.stable_cost[d] for d in minima)
        minima = [d for d in sorted(minima, key=self.stable_cost.get)
                  if self.stable_cost[d] <= BASIN_COST_RATIO * least]
        basins = []
        for d in minima[:N_BASINS]:
            d = self.descend(d)
            if d in self.swept:
                self.converge(d)
            if d in self.stable_best and all(b is not self.stable_best[d] for b in basins):
                basins.append(self.stable_best[d])
        return sorted(basins, key=lambda b: b[1])

    def candidates_with_swept(self) -> list:
        """The candidates, with the stable ones of the sweep (called after :meth:`basins`)."""
        return self.candidates + [f for found in self.swept.values() for f in found]
