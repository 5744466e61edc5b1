"""Compiled integrators (numba). Imported lazily by :mod:`eha_core.simulate`.

The kernels release the GIL (``nogil``), so a web server can run one
session's simulation in a worker thread while it keeps serving the others.

A fixed-step classical Runge-Kutta (RK4) with the bounds enforced after every
step (:func:`eha_core.model.project_state`). Fixed steps suit this model: the
right-hand side has kinks (valve switching at u = 0, clipping, end stops) and
the inputs may be held piecewise constant (noise, the sampled controller), so
the step grid is aligned with every input sample and controller instant. The
step is chosen by :mod:`eha_core.simulate` to keep the error below 1e-5 of each
state's range against a tight implicit reference (benchmarks/bench_simulate.py).

Inputs are pre-sampled in numpy for every step at its three RK4 stage times
(start, middle, just before the end), so any Python callable can drive the
compiled loop without calling back into Python. A long run is integrated in
chunks of steps, each sampled just before its kernel call: a chunk starts at an
output sample and at a controller instant, so the kernel needs nothing from the
previous chunk but its final state (``y_end``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import model

# the one implementation of the dynamics, compiled
derivatives = njit(cache=True, nogil=True, inline="always")(model.derivatives)
project_state = njit(cache=True, nogil=True, inline="always")(model.project_state)

# mode codes
NONLINEAR = 0
LINEAR_SWITCHING = 1
LINEAR_POSITIVE = 2
LINEAR_NEGATIVE = 3
# controller codes
OPEN_LOOP = 0
ZOH = 1
CONTINUOUS = 2


@njit(cache=True, nogil=True, inline="always")
def _f(mode, x, v, p1, p2, u, d, prm, lin):
    if mode == NONLINEAR:
        return derivatives(x, v, p1, p2, u, d, prm)
    # linearised model about lin[28:32] (x, v, p1, p2 of the operating point);
    # A = lin[0:16] row-major, B+ = lin[16:20], B- = lin[20:24], E = lin[24:28]
    dx0 = x - lin[28]
    dx1 = v - lin[29]
    dx2 = p1 - lin[30]
    dx3 = p2 - lin[31]
    if mode == LINEAR_POSITIVE or (mode == LINEAR_SWITCHING and u >= 0.0):
        b = 16
    else:
        b = 20
    r0 = lin[0] * dx0 + lin[1] * dx1 + lin[2] * dx2 + lin[3] * dx3 + lin[b] * u + lin[24] * d
    r1 = lin[4] * dx0 + lin[5] * dx1 + lin[6] * dx2 + lin[7] * dx3 + lin[b + 1] * u + lin[25] * d
    r2 = lin[8] * dx0 + lin[9] * dx1 + lin[10] * dx2 + lin[11] * dx3 + lin[b + 2] * u + lin[26] * d
    r3 = lin[12] * dx0 + lin[13] * dx1 + lin[14] * dx2 + lin[15] * dx3 + lin[b + 3] * u + lin[27] * d
    return r0, r1, r2, r3


@njit(cache=True, nogil=True)
def _control(kp, r, x, u_limit):
    """The proportional controller ``u = Kp (r - x)``, clipped to ±u_limit when u_limit > 0."""
    u = kp * (r - x)
    if u_limit > 0.0:
        u = min(max(u, -u_limit), u_limit)
    return u


@njit(cache=True, nogil=True)
def _store(out, k, x, v, p1, p2, u):
    out[k, 0] = x
    out[k, 1] = v
    out[k, 2] = p1
    out[k, 3] = p2
    out[k, 4] = u


@njit(cache=True, nogil=True)
def integrate(y0, h, n_steps, sub, prm, mode, lin, u_st, d_st,
              ctrl, kp, r_st, ctrl_every, u_limit, out, y_end):
    """Integrate one run; fill ``out`` (n_out x 5: x, v, p1, p2, u) and the final state ``y_end``.

    Returns the number of the step at which the state stopped being finite,
    or -1 when the run completed. A long run is integrated in chunks (see
    :mod:`eha_core.simulate`): a chunk starts at an output sample and a
    controller instant, and gets an ``out`` with one row per output sample it
    starts (plus the last one, at t_end, for the last chunk only).
    """
    x, v, p1, p2 = y0[0], y0[1], y0[2], y0[3]
    bounded = mode == NONLINEAR
    half = 0.5 * h
    u_hold = 0.0
    k_out = 0
    for i in range(n_steps):
        # the controller: sampled (zero-order hold) or continuous
        if ctrl == ZOH and i % ctrl_every == 0:
            u_hold = _control(kp, r_st[i, 0], x, u_limit)
        if ctrl == OPEN_LOOP:
            ua, ub, uc = u_st[i, 0], u_st[i, 1], u_st[i, 2]
        elif ctrl == ZOH:
            ua = ub = uc = u_hold
        else:
            ua = _control(kp, r_st[i, 0], x, u_limit)
        if i % sub == 0:
            _store(out, k_out, x, v, p1, p2, ua)
            k_out += 1
        da, db, dc = d_st[i, 0], d_st[i, 1], d_st[i, 2]

        k1x, k1v, k1p, k1q = _f(mode, x, v, p1, p2, ua, da, prm, lin)
        x2 = x + half * k1x
        v2 = v + half * k1v
        if ctrl == CONTINUOUS:
            ub = _control(kp, r_st[i, 1], x2, u_limit)
        k2x, k2v, k2p, k2q = _f(mode, x2, v2, p1 + half * k1p, p2 + half * k1q, ub, db, prm, lin)
        x3 = x + half * k2x
        k3x, k3v, k3p, k3q = _f(mode, x3, v + half * k2v, p1 + half * k2p, p2 + half * k2q, ub, db, prm, lin)
        x4 = x + h * k3x
        if ctrl == CONTINUOUS:
            uc = _control(kp, r_st[i, 2], x4, u_limit)
        k4x, k4v, k4p, k4q = _f(mode, x4, v + h * k3v, p1 + h * k3p, p2 + h * k3q, uc, dc, prm, lin)

        x = x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        v = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
        p1 = p1 + h / 6.0 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
        p2 = p2 + h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        if bounded:
            x, v, p1, p2 = project_state(x, v, p1, p2, prm)
        if not (np.isfinite(x) and np.isfinite(v) and np.isfinite(p1) and np.isfinite(p2)):
            return i
    y_end[0] = x
    y_end[1] = v
    y_end[2] = p1
    y_end[3] = p2
    # the last sample, at t_end
    if k_out < out.shape[0]:
        if ctrl == ZOH:
            if n_steps % ctrl_every == 0:
                u_hold = _control(kp, r_st[n_steps, 0], x, u_limit)
            ue = u_hold
        elif ctrl == CONTINUOUS:
            ue = _control(kp, r_st[n_steps, 0], x, u_limit)
        else:
            ue = u_st[n_steps, 0]
        _store(out, k_out, x, v, p1, p2, ue)
    return -1


@njit(cache=True, nogil=True, parallel=True)
def integrate_batch(y0s, h, n_steps, sub, prms, mode, lin, u_sts, d_sts,
                    ctrl, kp, r_sts, ctrl_every, u_limit, outs, status, y_ends):
    """:func:`integrate` over a batch of runs, in parallel over the cores."""
    for j in prange(y0s.shape[0]):
        status[j] = integrate(y0s[j], h, n_steps, sub, prms[j], mode, lin[j], u_sts[j], d_sts[j],
                              ctrl, kp, r_sts[j], ctrl_every, u_limit, outs[j], y_ends[j])


# -- forward sensitivities (grey-box identification) -----------------------------------------------------
#
# The sensitivities S = dy/dz of the states to P parameters z (a packed parameter's logarithm or a
# multiple of it, an initial state) obey the variational equation dS_j/dt = (df/dy) S_j + df/dz_j.
# Its right-hand side is the derivative of f along the direction (S_j, du_j, dprm_j): computed here
# by a forward difference of the one dynamics implementation (derivatives) at every RK4 stage, from
# the stage's own evaluation, so the sensitivities are integrated with the states, step by step, by
# the same scheme, at one more evaluation of f per parameter. The step of the difference is 1e-7 of
# the direction in each quantity's own scale (position x_max, velocity 1 m/s, pressures ps, command
# 1 V, each parameter its own value): ~1e-7 relative, checked against differences of whole runs in
# tests/core/test_greybox.py; Levenberg-Marquardt needs far less.

@njit(cache=True, nogil=True)
def _along(x, v, p1, p2, u, d, prm, f0, sx, sv, s1, s2, su, pi, ps_, work):
    """Derivative of f(y, u, prm) along (S, su, ps_ on the packed parameter ``pi``; pi < 0: none), by a
    forward difference from ``f0`` = f(y, u, prm). ``work`` is a copy of ``prm``, left as it was found."""
    n = max(abs(sx) / prm[12], abs(sv), abs(s1) / prm[9], abs(s2) / prm[9], abs(su))
    if pi >= 0:                 # a parameter at 0 (d0) in the direction's own scale
        n = max(n, abs(ps_) / max(abs(prm[pi]), abs(ps_)))
    if n == 0.0:
        return 0.0, 0.0, 0.0, 0.0
    e = 1e-7 / n
    if pi >= 0:
        work[pi] = prm[pi] + e * ps_
    a0, a1, a2, a3 = derivatives(x + e * sx, v + e * sv, p1 + e * s1, p2 + e * s2, u + e * su, d, work)
    if pi >= 0:
        work[pi] = prm[pi]
    k = 1.0 / e
    return (a0 - f0[0]) * k, (a1 - f0[1]) * k, (a2 - f0[2]) * k, (a3 - f0[3]) * k


@njit(cache=True, nogil=True)
def _stage_sensitivities(K, S, Kprev, c, x, v, p1, p2, u, d, prm, f0, su, pidx, pstep, work):
    """One RK4 stage of the sensitivities: K[:, j] = df/dy (S + c Kprev)[:, j] + df/dz_j."""
    for j in range(S.shape[1]):
        K[0, j], K[1, j], K[2, j], K[3, j] = _along(
            x, v, p1, p2, u, d, prm, f0, S[0, j] + c * Kprev[0, j], S[1, j] + c * Kprev[1, j],
            S[2, j] + c * Kprev[2, j], S[3, j] + c * Kprev[3, j], su[j], pidx[j], pstep[j], work)


@njit(cache=True, nogil=True)
def _store_sensitivities(out, sout, k, x, v, p1, p2, S):
    out[k, 0] = x
    out[k, 1] = v
    out[k, 2] = p1
    out[k, 3] = p2
    for r in range(4):
        for j in range(S.shape[1]):
            sout[k, r, j] = S[r, j]


@njit(cache=True, nogil=True)
def _held_at_bounds(S, before, after):
    """A state the bounds held does not move with the parameters: its sensitivities are zero."""
    for r in range(4):
        if before[r] != after[r]:
            for j in range(S.shape[1]):
                S[r, j] = 0.0


@njit(cache=True, nogil=True)
def integrate_sensitivities(y0, s0, h, n_steps, sub, prm, pidx, pstep, u_st, d_st, ctrl, kp, r_st, ctrl_every,
                            u_limit, out, sout):
    """The nonlinear model's states and their sensitivities to P parameters, on the grid of
    :func:`integrate` (RK4, bounds after every step, open loop or a sampled P controller).

    ``s0`` (4 x P): the sensitivities of the initial state; parameter j moves the packed parameter
    ``pidx[j]`` by ``pstep[j]`` per unit (``pidx[j] < 0``: none, an initial state). Fills ``out``
    (n_out x 4) and ``sout`` (n_out x 4 x P) at the output samples; returns -1, or the step at which
    the state stopped being finite.
    """
    P = pidx.shape[0]
    x, v, p1, p2 = y0[0], y0[1], y0[2], y0[3]
    S = s0.copy()
    Z = np.zeros((4, P))
    K1, K2, K3, K4 = np.empty((4, P)), np.empty((4, P)), np.empty((4, P)), np.empty((4, P))
    work = prm.copy()
    f0 = np.empty(4)
    su = np.zeros(P)                    # the command's sensitivity: -Kp S_x, held with the command
    before, after = np.empty(4), np.empty(4)
    u_hold = 0.0
    half = 0.5 * h
    k_out = 0
    for i in range(n_steps):
        if ctrl == ZOH and i % ctrl_every == 0:
            u_hold = _control(kp, r_st[i, 0], x, u_limit)
            free = u_limit <= 0.0 or abs(u_hold) < u_limit
            for j in range(P):
                su[j] = -kp * S[0, j] if free else 0.0
        if ctrl == ZOH:
            ua = ub = uc = u_hold
        else:
            ua, ub, uc = u_st[i, 0], u_st[i, 1], u_st[i, 2]
        if i % sub == 0:
            _store_sensitivities(out, sout, k_out, x, v, p1, p2, S)
            k_out += 1
        da, db, dc = d_st[i, 0], d_st[i, 1], d_st[i, 2]
        f0[0], f0[1], f0[2], f0[3] = derivatives(x, v, p1, p2, ua, da, prm)
        k1x, k1v, k1p, k1q = f0[0], f0[1], f0[2], f0[3]
        _stage_sensitivities(K1, S, Z, 0.0, x, v, p1, p2, ua, da, prm, f0, su, pidx, pstep, work)
        x2, v2, q2, w2 = x + half * k1x, v + half * k1v, p1 + half * k1p, p2 + half * k1q
        f0[0], f0[1], f0[2], f0[3] = derivatives(x2, v2, q2, w2, ub, db, prm)
        k2x, k2v, k2p, k2q = f0[0], f0[1], f0[2], f0[3]
        _stage_sensitivities(K2, S, K1, half, x2, v2, q2, w2, ub, db, prm, f0, su, pidx, pstep, work)
        x3, v3, q3, w3 = x + half * k2x, v + half * k2v, p1 + half * k2p, p2 + half * k2q
        f0[0], f0[1], f0[2], f0[3] = derivatives(x3, v3, q3, w3, ub, db, prm)
        k3x, k3v, k3p, k3q = f0[0], f0[1], f0[2], f0[3]
        _stage_sensitivities(K3, S, K2, half, x3, v3, q3, w3, ub, db, prm, f0, su, pidx, pstep, work)
        x4, v4, q4, w4 = x + h * k3x, v + h * k3v, p1 + h * k3p, p2 + h * k3q
        f0[0], f0[1], f0[2], f0[3] = derivatives(x4, v4, q4, w4, uc, dc, prm)
        k4x, k4v, k4p, k4q = f0[0], f0[1], f0[2], f0[3]
        _stage_sensitivities(K4, S, K3, h, x4, v4, q4, w4, uc, dc, prm, f0, su, pidx, pstep, work)
        before[0] = x + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
        before[1] = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
        before[2] = p1 + h / 6.0 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
        before[3] = p2 + h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q)
        S += h / 6.0 * (K1 + 2.0 * K2 + 2.0 * K3 + K4)
        x, v, p1, p2 = project_state(before[0], before[1], before[2], before[3], prm)
        after[0], after[1], after[2], after[3] = x, v, p1, p2
        _held_at_bounds(S, before, after)
        if not (np.isfinite(x) and np.isfinite(v) and np.isfinite(p1) and np.isfinite(p2)):
            return i
    if k_out < out.shape[0]:
        _store_sensitivities(out, sout, k_out, x, v, p1, p2, S)
    return -1
