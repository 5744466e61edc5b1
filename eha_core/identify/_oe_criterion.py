"""The output-error criterion of :func:`eha_core.identify.tfest.tfest`, shared by its stages.

Private as a module (like :mod:`eha_core.identify._ctmodels`): its names are
used by :mod:`eha_core.identify.tfest` and by the stage modules
:mod:`~eha_core.identify._srivc` (which ranks its iterates by this cost),
:mod:`~eha_core.identify._delay_search` and :mod:`~eha_core.identify._oe_refine`.
It holds

* the parameter vector ``theta = [a_1..a_np, b_0..b_nz]`` of
  ``G(s) = (b_0 s^nz + ... + b_nz) / (s^np + a_1 s^(np-1) + ... + a_np)``,
  with the input delay ``tau`` (seconds) appended when it is estimated:
  :func:`split_theta` gives ``(num, den)``, :func:`parameter_scale` the scale
  that makes every entry O(1) (coefficients such as 1, 430.1, 1.721e4, 2437
  are optimised relative to their starting values; near-zero ones, an
  integrator's ``a_np``, get a floor from the model's frequency scale
  ``w0 = max_i |a_i|^(1/i)``);
* :class:`OutputError`, the residual ``y - y_hat(theta)`` of the exact
  simulation for the input's intersample behaviour, held (ZOH) or linear
  (FOH) between samples (:func:`eha_core.identify._ctmodels.discretise`), the terms that
  enter it linearly (input offset, initial state) eliminated by linear least
  squares in every evaluation (variable projection: Golub & Pereyra, SIAM J.
  Numer. Anal. 10, 1973).

Only numpy and scipy are imported here.
"""

from __future__ import annotations

import numpy as np

from ..cancel import CancelToken, check
from ._ctmodels import discretise, fit_linear_terms, linear_columns

__all__ = ["OutputError", "parameter_scale", "split_theta"]


def split_theta(theta: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` from ``theta = [a_1..a_n, b_0..b_m]``."""
    return theta[n:].copy(), np.concatenate([[1.0], theta[:n]])


def parameter_scale(theta: np.ndarray, n: int, m: int) -> np.ndarray:
    """Scale so that ``theta / scale`` is O(1); floors for near-zero entries."""
    a, b = theta[:n], theta[n:]
    powers = np.arange(1, n + 1)
    w0 = np.max(np.abs(a) ** (1.0 / powers))
    if not np.isfinite(w0) or w0 <= 0:
        w0 = 1.0
    floor_a = 1e-6 * w0**powers
    j = np.arange(m + 1)
    b_ref = np.abs(b) * w0 ** (-j)
    floor_b = 1e-6 * np.max(b_ref) * w0**j if np.max(b_ref) > 0 else np.ones(m + 1)
    scale = np.maximum(np.abs(theta), np.concatenate([floor_a, floor_b]))
    scale[~np.isfinite(scale) | (scale == 0)] = 1.0
    return scale


class OutputError:
    """Residual ``y - y_hat(theta)`` of the exact simulation (``intersample``: ZOH or FOH input).

    The terms that enter ``y_hat`` linearly, the response ``c G(s) 1(t)`` to a
    constant input offset (with ``estimate_offset``) and the free response to
    the initial state (with ``estimate_initial_state``), are eliminated by linear least
    squares in every evaluation (variable projection). Their coefficients,
    ``[c, initial_state...]`` in that order, are the ``linear`` vector.

    The model's input delay is ``input_delay`` (seconds), or, with
    ``max_delay`` given, the last entry of ``theta`` (estimated, in
    ``[0, max_delay]``): ``theta = [a_1..a_n, b_0..b_m, tau]``.
    """

    def __init__(self, u: np.ndarray, y: np.ndarray, ts: float, n: int, estimate_initial_state: bool,
                 estimate_offset: bool = False, cancel: CancelToken | None = None, *,
                 input_delay: float = 0.0, max_delay: float | None = None, intersample: str = "zoh"):
        self.u, self.y, self.ts, self.n = u, y, ts, n
        self.intersample = intersample
        self.estimate_initial_state = estimate_initial_state
        self.estimate_offset = estimate_offset
        self.input_delay = input_delay
        self.max_delay = max_delay
        self.nfev = 0
        # checked at every evaluation (each residual of the output-error stage,
        # each Jacobian column of the covariance) and by every SRIVC iteration:
        # a cancelled computation stops within one simulation of the model
        self.cancel = cancel

    @property
    def n_linear(self) -> int:
        return int(self.estimate_offset) + (self.n if self.estimate_initial_state else 0)

    @property
    def estimate_delay(self) -> bool:
        return self.max_delay is not None

    def split_delay(self, theta: np.ndarray) -> tuple[np.ndarray, float]:
        """``(coefficients, delay in s)`` of a parameter vector."""
        if self.estimate_delay:
            return theta[:-1], float(theta[-1])
        return theta, self.input_delay

    def model(self, theta: np.ndarray):
        """The exact discretisation at ``theta`` (with its delay, for the input's intersample behaviour)."""
        coefficients, tau = self.split_delay(theta)
        num, den = split_theta(coefficients, self.n)
        return discretise(num, den, self.ts, tau, self.intersample)

    def scale(self, theta: np.ndarray, n: int, m: int) -> np.ndarray:
        """:func:`parameter_scale`, and ``ts`` for an estimated delay (so it is counted in samples)."""
        coefficients, _ = self.split_delay(theta)
        scale = parameter_scale(coefficients, n, m)
        return np.r_[scale, self.ts] if self.estimate_delay else scale

    def split_linear(self, linear):
        """``(initial_state, offset)`` from the ``linear`` coefficients (None when not estimated)."""
        if linear is None:
            return None, None
        offset = float(linear[0]) if self.estimate_offset else None
        initial_state = linear[int(self.estimate_offset):] if self.estimate_initial_state else None
        return initial_state, offset

    def columns(self, theta: np.ndarray) -> np.ndarray:
        """The responses of the linear terms at ``theta``, shape ``(N, n_linear)``."""
        return linear_columns(self.model(theta), self.u.size,
                               offset=self.estimate_offset, initial_state=self.estimate_initial_state)

    def evaluate(self, theta: np.ndarray, linear: np.ndarray | None = None):
        """``(residual, linear)``; residual is None if the simulation is not finite.

        With ``linear`` given, those coefficients are used instead of the
        least-squares ones (for the Jacobian at fixed linear terms).
        """
        check(self.cancel)
        self.nfev += 1
        if not np.all(np.isfinite(theta)):
            return None, None
        if self.estimate_delay and not 0.0 <= theta[-1] <= self.max_delay:
            return None, None  # a finite-difference step out of the bounds
        try:
            with np.errstate(all="ignore"):
                model = self.model(theta)
                residual = self.y - model.forced(self.u)
                coef = None
                if self.n_linear and np.all(np.isfinite(residual)):
                    columns = linear_columns(model, self.u.size, offset=self.estimate_offset,
                                              initial_state=self.estimate_initial_state)
                    if not np.all(np.isfinite(columns)):
                        return None, None
                    coef = fit_linear_terms(columns, residual) if linear is None else linear
                    residual = residual - columns @ coef
        except (np.linalg.LinAlgError, ValueError):  # e.g. eigenvalues of an overflowed matrix
            return None, None
        with np.errstate(over="ignore", invalid="ignore"):
            finite = np.isfinite(residual @ residual)  # also catches overflow of the sum
        if not finite:
            return None, None
        return residual, coef

    def cost(self, theta: np.ndarray) -> float:
        residual, _ = self.evaluate(theta)
        return np.inf if residual is None else 0.5 * float(residual @ residual)
