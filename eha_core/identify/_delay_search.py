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
  per delay from the model at the nearest delay, and the lowest few local
  minima of the swept cost are converged at the whole sample;
- the output-error stage (:mod:`eha_core.identify._oe_refine`) then refines
  ``tau`` with the coefficients, from the best model of each of those minima.

Private as a module: its names are used by :mod:`eha_core.identify.tfest`.
Only numpy is imported here.
"""

from __future__ import annotations

import numpy as np

from ..cancel import CancelToken, check
from ._oe_criterion import OutputError
from ._srivc import srivc_candidates

__all__ = ["BASIN_COST_RATIO", "MAX_SWEEP", "N_BASINS", "SWEEP_ITERATIONS", "arx_delay_losses", "delay_candidates",
           "is_stable"]


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


#: Most delays the SRIVC sweep of the whole range evaluates: a longer range is swept with a coarser step.
MAX_SWEEP = 128
#: SRIVC iterations per delay of the sweep, each started from the model at the nearest delay swept.
SWEEP_ITERATIONS = 1
#: Local minima of the cost over the whole-sample delays whose models the output-error stage refines.
N_BASINS = 3
#: Local minima whose cost exceeds the lowest one's this many times are not refined.
BASIN_COST_RATIO = 2.0


def delay_candidates(criterion: OutputError, m: int, starts, start_names, max_iter: int, tol: float):
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
    3. At the lowest local minima of the swept cost (:data:`N_BASINS` of
       them, those within :data:`BASIN_COST_RATIO` times the lowest: a
       minimum that much worse does not win after the output-error stage,
       which only adds the fraction of a sample), a coarse sweep is
       descended to the whole sample, and SRIVC is run to convergence from
       the model there: those are the ``basins``.
    """
    search = _DelaySearch(criterion, m, max_iter, tol)
    search.local_search(starts, start_names)
    if not search.stable_best:
        return search.candidates, search.nit_total, []
    search.sweep_range()
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
        self.stable_cost[d] = min((f[1] for f in found_stable), default=np.inf)
        if found_stable:
            self.stable_best[d] = min(found_stable, key=lambda f: f[1])
        else:
            self.stable_best.pop(d, None)
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
        found, found_stable = self.srivc_at(d, d_starts, d_names, self.max_iter)
        self.candidates.extend(found)
        self.stable.extend(found_stable)

    def sweep(self, d: int) -> None:
        """:data:`SWEEP_ITERATIONS` of SRIVC at ``d`` from the stable model at the nearest delay tried."""
        near = min(self.stable_best, key=lambda e: (abs(e - d), e))
        _, self.swept[d] = self.srivc_at(d, [("model", self.stable_best[near][0][:-1])],
                                         [f"the estimate at a delay of {near} samples"], SWEEP_ITERATIONS)

    def local_search(self, starts, start_names) -> None:
        """Step 1: from the delay of least ARX loss, while the lowest cost lies at an end of the range tried."""
        c = self.criterion
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
        """Step 2: the rest of ``0..d_max`` (every ``step``-th delay), outwards from the range searched."""
        lo, hi = min(self.stable_cost), max(self.stable_cost)
        step = int(np.ceil((self.d_max + 1) / MAX_SWEEP))
        grid = set(range(0, self.d_max + 1, step)) | {self.d_max}
        for d in sorted((d for d in grid if d < lo), reverse=True) + sorted(d for d in grid if d > hi):
            self.sweep(d)

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
        found, found_stable = self.srivc_at(d, [("model", start[0][:-1])],
                                            [f"the estimate of the sweep at a delay of {d} samples"], self.max_iter)
        del self.swept[d]
        self.candidates.extend(found)
        if not found_stable:  # the iterations went unstable: keep the sweep's model
            self.stable_cost[d], self.stable_best[d] = start[1], start
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
