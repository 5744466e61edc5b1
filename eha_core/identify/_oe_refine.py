"""Stage 2 of :func:`eha_core.identify.tfest.tfest` (and all of ``oe_fit``): output-error refinement.

Minimise ``||y - y_hat(theta)||^2`` where ``y_hat`` is the exact
simulation of the continuous-time model (the input held or linear between
samples)
(:class:`eha_core.identify._oe_criterion.OutputError`, on the machinery of
:func:`eha_core.identify.validate.simulate_tf`: matrix exponential of the
augmented state matrix, then ``scipy.signal.lfilter``), with
:func:`scipy.optimize.least_squares` (trust-region reflective,
``x_scale='jac'``) on the scaled parameters of
:func:`eha_core.identify._oe_criterion.parameter_scale` (:func:`oe_refine`).
With ``initial_condition="estimate"`` the initial state joins the
parameters; it enters the response linearly, so it is eliminated by linear
least squares inside every residual evaluation (variable projection): same
minimiser, better conditioning. An input offset ``c`` enters linearly too
(its response is ``c`` times the step response) and is eliminated the same
way, jointly with the initial state. An estimated input delay joins the
parameter vector, bounded to ``[0, max_delay]``: the exact simulation is
smooth in it.

The statistics of the estimate come from the same criterion
(:func:`oe_covariance`): the Gauss-Newton covariance of the coefficients,
from the central-difference Jacobian with the linear terms projected out,
and that of the linear terms. :func:`estimate_result` assembles the
:class:`~eha_core.identify.tfresult.TFEstimate` at the final parameters,
whichever stage found them; :func:`failed_estimate` is the NaN one.

Private as a module: its names are used by :mod:`eha_core.identify.tfest`.
Only numpy and scipy are imported here.
"""

from __future__ import annotations

import numpy as np
import scipy.optimize

from ._ctmodels import fit_percent, readonly
from ._oe_criterion import OutputError, split_theta
from .tfresult import TFEstimate

__all__ = ["estimate_result", "failed_estimate", "oe_covariance", "oe_refine"]


def oe_covariance(criterion: OutputError, theta: np.ndarray, scale: np.ndarray,
                residual: np.ndarray, linear: np.ndarray | None):
    """Gauss-Newton covariances of the coefficients and of the linear terms.

    ``J`` is the central-difference Jacobian of ``y_hat`` with respect to the
    scaled coefficients at fixed linear terms ``linear`` (input offset,
    initial state), ``L`` the linear terms' columns. The coefficients'
    covariance is ``sigma^2 (J^T P J)^-1`` with ``P`` the projector orthogonal
    to ``L`` (the coefficient block of the joint covariance), and the linear
    terms' is ``sigma^2 (L^+ L^+T + L^+ J (J^T P J)^-1 J^T L^+T)``.

    Returns ``(covariance, variance, linear_covariance)``.
    """
    p = theta / scale
    n_lin = 0 if linear is None else linear.size
    nan = np.full((p.size, p.size), np.nan), np.nan, np.full((n_lin, n_lin), np.nan)
    jac = np.empty((residual.size, p.size))
    for i in range(p.size):
        h = 1e-6 * max(1.0, abs(p[i]))
        step = np.zeros_like(p)
        step[i] = h
        r_plus, _ = criterion.evaluate((p + step) * scale, linear)
        r_minus, _ = criterion.evaluate((p - step) * scale, linear)
        if criterion.estimate_delay and i == p.size - 1 and (r_plus is None) != (r_minus is None):
            # an estimated delay at a bound of its search (0, say): one-sided
            # difference, ``residual`` being the residual at ``theta`` itself
            r_plus, r_minus, h = (residual, r_minus, h / 2.0) if r_plus is None else (r_plus, residual, h / 2.0)
        if r_plus is None or r_minus is None:
            return nan
        # residual = y - y_hat, so d(y_hat)/dp = -d(residual)/dp
        jac[:, i] = -(r_plus - r_minus) / (2.0 * h)
    dof = residual.size - p.size - n_lin
    variance = float(residual @ residual) / dof
    if not np.all(np.isfinite(jac)):
        return nan                      # (an SVD of NaN would print LAPACK's complaint to stderr)
    jac_projected = jac
    if n_lin:
        columns = criterion.columns(theta)
        norms = np.linalg.norm(columns, axis=0)
        norms[norms == 0] = 1.0
        if not (np.all(np.isfinite(columns)) and np.all(np.isfinite(norms))):
            return nan
        u_l, s_l, vt_l = np.linalg.svd(columns / norms, full_matrices=False)
        keep_l = s_l > s_l[0] * max(columns.shape) * np.finfo(float).eps
        jac_projected = jac - u_l[:, keep_l] @ (u_l[:, keep_l].T @ jac)
    _, sing, vt = np.linalg.svd(jac_projected, full_matrices=False)
    keep = sing > sing[0] * 1e-13 if sing[0] > 0 else np.zeros_like(sing, dtype=bool)
    inv = (vt[keep].T / sing[keep] ** 2) @ vt[keep]
    if not np.all(keep):
        inv = np.full_like(inv, np.nan)
    cov_lin = np.zeros((0, 0))
    if n_lin:
        # L^+ of the unnormalised columns; NaN if the linear terms are not
        # all identifiable (e.g. an offset with a zero at s = 0)
        pinv_cols = ((vt_l[keep_l].T / s_l[keep_l]) @ u_l[:, keep_l].T) / norms[:, None]
        if not np.all(keep_l):
            pinv_cols = np.full_like(pinv_cols, np.nan)
        pj = pinv_cols @ jac
        cov_lin = variance * (pinv_cols @ pinv_cols.T + pj @ inv @ pj.T)
    cov_p = variance * inv
    return cov_p * scale[:, None] * scale[None, :], variance, cov_lin


def oe_refine(criterion: OutputError, theta0: np.ndarray, n: int, m: int,
               max_nfev: int, tol: float):
    """``least_squares`` on the exact output error, from ``theta0``.

    An estimated delay (the last parameter) is bounded to
    ``[0, criterion.max_delay]``; the coefficients are free.
    """
    scale = criterion.scale(theta0, n, m)
    bounds = (-np.inf, np.inf)
    if criterion.estimate_delay:
        lower = np.full(theta0.size, -np.inf)
        upper = np.full(theta0.size, np.inf)
        lower[-1], upper[-1] = 0.0, criterion.max_delay / scale[-1]
        bounds = (lower, upper)

    def residual(p):
        r, _ = criterion.evaluate(p * scale)
        return np.full(criterion.y.size, np.inf) if r is None else r

    try:
        # a trial step to an unstable model can overflow scipy's reduction ratio
        with np.errstate(over="ignore"):
            res = scipy.optimize.least_squares(
                residual, theta0 / scale, method="trf", x_scale="jac", jac="2-point",
                xtol=tol, ftol=tol, gtol=tol, max_nfev=max_nfev, bounds=bounds,
            )
    except ValueError as exc:  # e.g. non-finite residuals at the start point
        return theta0, np.inf, False, f"output-error refinement not possible: {exc}"
    return res.x * scale, float(res.cost), bool(res.success), res.message


def failed_estimate(n, m, ts, n_samples, estimate_initial_state, estimate_offset, message, nit, nfev,
                  input_delay=0.0, intersample="zoh"):
    """A failed estimate; ``input_delay`` is the fixed delay, or None when it was to be estimated."""
    p = n + m + 1
    return TFEstimate(
        num=readonly(np.full(m + 1, np.nan)), den=readonly(np.r_[1.0, np.full(n, np.nan)]),
        ts=ts, n_poles=n, n_zeros=m, fit_percent=np.nan, cost=np.nan, mse=np.nan,
        noise_variance=np.nan, initial_condition="estimate" if estimate_initial_state else "zero",
        initial_state=None, input_offset=np.nan if estimate_offset else None,
        input_offset_std=np.nan if estimate_offset else None, success=False,
        message=message, method="none", nit_srivc=nit, nfev_oe=nfev,
        param_std=readonly(np.full(p, np.nan)), covariance=readonly(np.full((p, p), np.nan)),
        srivc_num=None, srivc_den=None, srivc_cost=np.nan, n_samples=n_samples,
        input_delay=np.nan if input_delay is None else float(input_delay),
        input_delay_std=np.nan if input_delay is None else None, intersample=intersample,
    )


def estimate_result(criterion, theta, n, m, ts, success, message, method, nit, srivc_theta,
                     srivc_cost) -> TFEstimate:
    """Assemble the result: fit, covariance, initial_state and input offset at the final estimate."""
    nfev = criterion.nfev
    residual, linear = criterion.evaluate(theta)
    if residual is None:
        return failed_estimate(n, m, ts, criterion.y.size, criterion.estimate_initial_state,
                             criterion.estimate_offset,
                             message + "; the final model cannot be simulated", nit, nfev,
                             None if criterion.estimate_delay else criterion.input_delay, criterion.intersample)
    covariance, variance, cov_linear = oe_covariance(
        criterion, theta, criterion.scale(theta, n, m), residual, linear)
    theta, tau = criterion.split_delay(theta)
    tau_std = None
    if criterion.estimate_delay:
        # the coefficients' block of the joint covariance keeps the delay's
        # uncertainty in it (a marginal, not a conditional, covariance)
        tau_std = float(np.sqrt(abs(covariance[-1, -1])))
        covariance = covariance[:-1, :-1]
        message += f"; input delay estimated: {tau:.6g} s ({tau / ts:.4g} samples)"
    if srivc_theta is not None:
        srivc_theta, _ = criterion.split_delay(srivc_theta)
    initial_state, offset = criterion.split_linear(linear)
    offset_std = None
    if criterion.estimate_offset:
        offset_std = float(np.sqrt(abs(cov_linear[0, 0])))
        message += f"; input offset estimated: {offset:.6g} (input units)"
    num, den = split_theta(theta, n)
    poles = np.roots(den)
    if np.any(poles.real > 1e-9 * max(1.0, np.max(np.abs(poles)))):
        message += (f"; note: the estimate is unstable (largest pole real part "
                    f"{np.max(poles.real):.4g} rad/s)")
    y_hat = criterion.y - residual
    sse = float(residual @ residual)
    srivc_num = srivc_den = None
    if srivc_theta is not None:
        srivc_num, srivc_den = split_theta(srivc_theta, n)
    return TFEstimate(
        num=readonly(num), den=readonly(den), ts=ts, n_poles=n, n_zeros=m,
        fit_percent=fit_percent(criterion.y, y_hat), cost=0.5 * sse,
        mse=sse / residual.size, noise_variance=variance,
        initial_condition="estimate" if criterion.estimate_initial_state else "zero",
        initial_state=None if initial_state is None else readonly(initial_state), input_offset=offset,
        input_offset_std=offset_std, success=bool(success), message=message,
        method=method, nit_srivc=nit, nfev_oe=nfev,
        param_std=readonly(np.sqrt(np.abs(np.diag(covariance)))),
        covariance=readonly(covariance),
        srivc_num=None if srivc_num is None else readonly(srivc_num),
        srivc_den=None if srivc_den is None else readonly(srivc_den),
        srivc_cost=float(srivc_cost), n_samples=residual.size,
        input_delay=float(tau), input_delay_std=tau_std, intersample=criterion.intersample,
    )
