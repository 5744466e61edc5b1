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
- the output-error stage (:mod:`eha_core.identify._oe_refine`) then refines
  ``tau`` with the coefficients.

Private as a module: its names are used by :mod:`eha_core.identify.tfest`.
Only numpy is imported here.
"""

from __future__ import annotations

import numpy as np

from ..cancel import CancelToken, check
from ._oe_criterion import OutputError
from ._srivc import srivc_candidates

__all__ = ["arx_delay_losses", "delay_candidates", "is_stable"]


def arx_delay_losses(u: np.ndarray, y: np.ndarray, n: int, d_max: int, offset: bool,
                      cancel: CancelToken | None = None) -> np.ndarray:
    """ARX loss for every whole-sample delay ``d = 0..d_max`` (MATLAB ``delayest``'s approach).

    ``y[k] + a_1 y[k-1] + ... + a_n y[k-n] = b_0 u[k-d-1] + ... + b_n u[k-d-1-n] (+ const)``:
    the exact ZOH model of ``G(s) e^(-s (d + f) ts)`` (strictly proper) has
    ``n + 1`` input lags from ``d + 1`` on. Every delay is fitted on the same
    samples (``k >= d_max + n + 1``), so the losses compare. The output lags
    (and the constant) are projected out once; each delay then costs one
    small least-squares problem. ``cancel`` is looked at every 64 delays.
    """
    n_b = n + 1
    k0 = max(n, d_max + n_b)
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
        lags = np.column_stack([u[k0 - d - 1 - j:u.size - d - 1 - j] for j in range(n_b)])
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


def delay_candidates(criterion: OutputError, m: int, starts, start_names, max_iter: int, tol: float):
    """SRIVC candidates for an estimated delay, their ``theta`` ending with the delay (s).

    A local search over whole-sample delays on the SRIVC/output-error cost,
    started at the delay ``d`` of least ARX loss (:func:`arx_delay_losses`):
    ``d - 1``, ``d``, ``d + 1`` are tried, then the range is extended by one
    sample on the side where the lowest cost lies, as long as it lies at an
    end. ARX is biased by output noise and can be off by more than a sample.
    A delay that is too long cannot be made up by the model (it would have to
    anticipate the input), and SRIVC then ends in unstable models whose
    costs say nothing about the direction to go; a delay that is too short
    is partly made up by slower poles, and the cost falls towards the true
    delay. So only models that are not markedly unstable (no pole growing
    faster than once over the record) are ranked, and while there are none
    the search moves to shorter delays.

    At each delay SRIVC starts from the best such model found so far (the
    dynamics barely change with a sample of delay, so few iterations are
    needed); while there is none, the default starts are tried too.
    """
    u, y, ts, n = criterion.u, criterion.y, criterion.ts, criterion.n
    d_max = int(np.floor(criterion.max_delay / ts + 1e-10))
    rate = 1.0 / (u.size * ts)
    d_arx = int(np.argmin(arx_delay_losses(u, y, n, d_max, criterion.estimate_offset, criterion.cancel)))
    candidates, stable = [], []
    stable_cost = {}  # lowest cost of a stable model at each delay tried (inf: none)
    nit_total = 0

    def run(d: int) -> None:
        nonlocal nit_total
        best = min(stable or candidates, key=lambda c: c[1]) if candidates else None
        d_starts, d_names = [], []
        if best is not None:
            d_starts.append(("model", best[0][:-1]))
            d_names.append(f"the estimate at a delay of {round(best[0][-1] / ts)} samples")
        if not stable:
            d_starts += starts
            d_names += start_names
        fixed = OutputError(u, y, ts, n, criterion.estimate_initial_state, criterion.estimate_offset,
                             criterion.cancel, input_delay=d * ts)
        found, nit = srivc_candidates(fixed, m, d_starts, d_names, max_iter, tol)
        nit_total += nit
        found = [(np.r_[c[0], d * ts], c[1], c[2], f"{c[3]} (delay {d} samples)", c[4]) for c in found]
        candidates.extend(found)
        found_stable = [c for c in found if is_stable(c[0], n, rate)]
        stable.extend(found_stable)
        stable_cost[d] = min((c[1] for c in found_stable), default=np.inf)

    for d in (d_arx, d_arx - 1, d_arx + 1):
        if 0 <= d <= d_max:
            run(d)
    while True:
        lo, hi = min(stable_cost), max(stable_cost)
        lowest = min(stable_cost, key=stable_cost.get)
        if not np.isfinite(stable_cost[lowest]):
            if lo == 0:
                break  # unstable at every delay down to 0: rank what there is by cost
            run(lo - 1)
        elif lowest == lo and lo > 0:
            run(lo - 1)
        elif lowest == hi and hi < d_max:
            run(hi + 1)
        else:
            break
    return candidates, nit_total
