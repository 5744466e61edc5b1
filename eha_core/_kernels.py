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
    # A = lin[0:16] row-major, B+ = lin[16:20], B- = lin[20:24], E = lin[24:28], and the valve's
    # offset lin[32:36] = B(sign u_e) u_e of an operating point that holds with u_e != 0 (internal
    # leakage, eq. V2; zero for the paper's model): dxi/dt = A dxi + B(sign u) u - B(sign u_e) u_e + E d
    dx0 = x - lin[28]
    dx1 = v - lin[29]
    dx2 = p1 - lin[30]
    dx3 = p2 - lin[31]
    if mode == LINEAR_POSITIVE or (mode == LINEAR_SWITCHING and u >= 0.0):
        b0, b1, b2, b3 = lin[16], lin[17], lin[18], lin[19]
    else:
        b0, b1, b2, b3 = lin[20], lin[21], lin[22], lin[23]
    r0 = lin[0] * dx0 + lin[1] * dx1 + lin[2] * dx2 + lin[3] * dx3 + b0 * u + lin[24] * d - lin[32]
    r1 = lin[4] * dx0 + lin[5] * dx1 + lin[6] * dx2 + lin[7] * dx3 + b1 * u + lin[25] * d - lin[33]
    r2 = lin[8] * dx0 + lin[9] * dx1 + lin[10] * dx2 + lin[11] * dx3 + b2 * u + lin[26] * d - lin[34]
    r3 = lin[12] * dx0 + lin[13] * dx1 + lin[14] * dx2 + lin[15] * dx3 + b3 * u + lin[27] * d - lin[35]
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


# -- the adaptive integrator (every simulation through eha_core.simulate) -------------------------------
#
# DOP853 (Dormand-Prince 8(5,3), Hairer's code and scipy's solve_ivp), error controlled, with its
# 7th-order dense output for the output samples, so a step spans as many output samples as the accuracy
# allows. The run is cut into segments at every time an input, the disturbance or the reference may
# jump or bend (the signals' own ``discontinuities``), and at every instant of the sampled controller:
# no step straddles one, so a jump costs a restart and not the order of the method. In open loop a step
# also ends where the command changes sign, where the valve's orifices switch (eq. 3) and the flows bend.
#
# Within a segment each signal is ``c0 + c1 (t - t_mid) + sum a sin((w + q t) t + phi)``: the held and
# linearly interpolated parts are one line per segment (computed in numpy), the sines and chirps (at most
# MAX_SMOOTH per signal) are evaluated at every stage. The inputs of a segment, the parameters and the
# linearised model reach the stages as tuples of numbers, not arrays: an array handed through the
# inlined stage functions costs two atomic reference-count updates per use, which were two thirds of
# the time of a step.

_N_STAGES = 12
#: What :func:`integrate_segments` returns when it stopped at its step budget (to be called again).
PAUSED = 3
#: Sines and chirps per signal that the adaptive kernel evaluates (a signal with more takes the RK4).
MAX_SMOOTH = 4
#: Length of a segment's input tuple (:func:`_segment_inputs`).
N_SEGMENT_INPUTS = 58


@njit(cache=True, nogil=True)
def _segment_inputs(s, seg_t, seg_u, seg_d, seg_r, sm_u, sm_d, sm_r, n_sm):
    """Segment ``s``'s inputs as one tuple: its middle, the lines (c0, c1) of u, d and r, how many
    smooth terms each has, and the terms (a, w, q, phi; MAX_SMOOTH rows each, unused rows zero)."""
    return (
        0.5 * (seg_t[s] + seg_t[s + 1]), seg_u[s, 0], seg_u[s, 1], seg_d[s, 0], seg_d[s, 1], seg_r[s, 0],
        seg_r[s, 1], n_sm[0], n_sm[1], n_sm[2], sm_u[0, 0], sm_u[0, 1], sm_u[0, 2], sm_u[0, 3], sm_u[1, 0],
        sm_u[1, 1], sm_u[1, 2], sm_u[1, 3], sm_u[2, 0], sm_u[2, 1], sm_u[2, 2], sm_u[2, 3], sm_u[3, 0], sm_u[3, 1],
        sm_u[3, 2], sm_u[3, 3], sm_d[0, 0], sm_d[0, 1], sm_d[0, 2], sm_d[0, 3], sm_d[1, 0], sm_d[1, 1], sm_d[1, 2],
        sm_d[1, 3], sm_d[2, 0], sm_d[2, 1], sm_d[2, 2], sm_d[2, 3], sm_d[3, 0], sm_d[3, 1], sm_d[3, 2], sm_d[3, 3],
        sm_r[0, 0], sm_r[0, 1], sm_r[0, 2], sm_r[0, 3], sm_r[1, 0], sm_r[1, 1], sm_r[1, 2], sm_r[1, 3], sm_r[2, 0],
        sm_r[2, 1], sm_r[2, 2], sm_r[2, 3], sm_r[3, 0], sm_r[3, 1], sm_r[3, 2], sm_r[3, 3])


@njit(cache=True, nogil=True)
def _params_tuple(prm):
    # the paper's parameters, then the effects' (eha_core.model.PARAM_INDEX)
    return (prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7], prm[8], prm[9], prm[10], prm[11],
            prm[12], prm[13], prm[14], prm[15], prm[16], prm[17], prm[18], prm[19], prm[20])


@njit(cache=True, nogil=True)
def _lin_tuple(lin):
    return (
        lin[0], lin[1], lin[2], lin[3], lin[4], lin[5], lin[6], lin[7], lin[8], lin[9], lin[10], lin[11], lin[12],
        lin[13], lin[14], lin[15], lin[16], lin[17], lin[18], lin[19], lin[20], lin[21], lin[22], lin[23], lin[24],
        lin[25], lin[26], lin[27], lin[28], lin[29], lin[30], lin[31], lin[32], lin[33], lin[34], lin[35])


@njit(cache=True, nogil=True, inline="always")
def _sig_u(sg, t):
    """The command at ``t`` within the segment ``sg`` (:func:`_segment_inputs`)."""
    val = sg[1] + sg[2] * (t - sg[0])
    if sg[7] > 0.0:
        val += sg[10] * np.sin((sg[11] + sg[12] * t) * t + sg[13])
        if sg[7] > 1.0:
            val += sg[14] * np.sin((sg[15] + sg[16] * t) * t + sg[17])
            if sg[7] > 2.0:
                val += sg[18] * np.sin((sg[19] + sg[20] * t) * t + sg[21])
                if sg[7] > 3.0:
                    val += sg[22] * np.sin((sg[23] + sg[24] * t) * t + sg[25])
    return val


@njit(cache=True, nogil=True, inline="always")
def _sig_d(sg, t):
    """The disturbance at ``t`` within the segment ``sg`` (:func:`_segment_inputs`)."""
    val = sg[3] + sg[4] * (t - sg[0])
    if sg[8] > 0.0:
        val += sg[26] * np.sin((sg[27] + sg[28] * t) * t + sg[29])
        if sg[8] > 1.0:
            val += sg[30] * np.sin((sg[31] + sg[32] * t) * t + sg[33])
            if sg[8] > 2.0:
                val += sg[34] * np.sin((sg[35] + sg[36] * t) * t + sg[37])
                if sg[8] > 3.0:
                    val += sg[38] * np.sin((sg[39] + sg[40] * t) * t + sg[41])
    return val


@njit(cache=True, nogil=True, inline="always")
def _sig_r(sg, t):
    """The reference at ``t`` within the segment ``sg`` (:func:`_segment_inputs`)."""
    val = sg[5] + sg[6] * (t - sg[0])
    if sg[9] > 0.0:
        val += sg[42] * np.sin((sg[43] + sg[44] * t) * t + sg[45])
        if sg[9] > 1.0:
            val += sg[46] * np.sin((sg[47] + sg[48] * t) * t + sg[49])
            if sg[9] > 2.0:
                val += sg[50] * np.sin((sg[51] + sg[52] * t) * t + sg[53])
                if sg[9] > 3.0:
                    val += sg[54] * np.sin((sg[55] + sg[56] * t) * t + sg[57])
    return val


@njit(cache=True, nogil=True, inline="always")
def _stage_f(t, x, v, p1, p2, sg, ctrl, kp, u_hold, u_limit, P, mode, L):
    """The right-hand side at a stage: the inputs of the segment ``sg`` at time ``t``, the command as the
    controller (or the input) gives it."""
    d = _sig_d(sg, t)
    if ctrl == OPEN_LOOP:
        u = _sig_u(sg, t)
    elif ctrl == ZOH:
        u = u_hold
    else:
        u = _control(kp, _sig_r(sg, t), x, u_limit)
    return _f(mode, x, v, p1, p2, u, d, P, L)


@njit(cache=True, nogil=True)
def _command_at(t, x, sg, ctrl, kp, u_hold, u_limit):
    if ctrl == OPEN_LOOP:
        return _sig_u(sg, t)
    if ctrl == ZOH:
        return u_hold
    return _control(kp, _sig_r(sg, t), x, u_limit)


@njit(cache=True, nogil=True)
def _u_crossing(sg, ta, tb):
    """The first time in (ta, tb] on the other side of zero from the open-loop command at ``ta``, when
    the command at ``tb`` is on that side (bisection, to rounding); else ``tb``."""
    side = _sig_u(sg, ta) >= 0.0
    if (_sig_u(sg, tb) >= 0.0) == side:
        return tb
    a, b = ta, tb
    for _ in range(80):
        m = 0.5 * (a + b)
        if m <= a or m >= b:
            break
        if (_sig_u(sg, m) >= 0.0) == side:
            a = m
        else:
            b = m
    return b


# -- generated from eha_core/_dop853.py: the stage sums written out with their coefficients (zeros
# left out), as Hairer's Fortran does; the loops over the tableau were twice as slow per step.

@njit(cache=True, nogil=True)
def _dop853_step(t, h, y, K, yn, sg, ctrl, kp, u_hold, u_limit, P, mode, L):
    """Stages 1-11 of a DOP853 step from ``K[0]`` = f(t, y), the solution ``yn`` and its derivative K[12]."""
    K[1, 0], K[1, 1], K[1, 2], K[1, 3] = _stage_f(
        t + 0.05260015195876773 * h,
        y[0] + h * (0.05260015195876773 * K[0, 0]),
        y[1] + h * (0.05260015195876773 * K[0, 1]),
        y[2] + h * (0.05260015195876773 * K[0, 2]),
        y[3] + h * (0.05260015195876773 * K[0, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[2, 0], K[2, 1], K[2, 2], K[2, 3] = _stage_f(
        t + 0.0789002279381516 * h,
        y[0] + h * (0.0197250569845379 * K[0, 0] + 0.0591751709536137 * K[1, 0]),
        y[1] + h * (0.0197250569845379 * K[0, 1] + 0.0591751709536137 * K[1, 1]),
        y[2] + h * (0.0197250569845379 * K[0, 2] + 0.0591751709536137 * K[1, 2]),
        y[3] + h * (0.0197250569845379 * K[0, 3] + 0.0591751709536137 * K[1, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[3, 0], K[3, 1], K[3, 2], K[3, 3] = _stage_f(
        t + 0.1183503419072274 * h,
        y[0] + h * (0.02958758547680685 * K[0, 0] + 0.08876275643042054 * K[2, 0]),
        y[1] + h * (0.02958758547680685 * K[0, 1] + 0.08876275643042054 * K[2, 1]),
        y[2] + h * (0.02958758547680685 * K[0, 2] + 0.08876275643042054 * K[2, 2]),
        y[3] + h * (0.02958758547680685 * K[0, 3] + 0.08876275643042054 * K[2, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[4, 0], K[4, 1], K[4, 2], K[4, 3] = _stage_f(
        t + 0.2816496580927726 * h,
        y[0] + h * (0.2413651341592667 * K[0, 0] + -0.8845494793282861 * K[2, 0] + 0.924834003261792 * K[3, 0]),
        y[1] + h * (0.2413651341592667 * K[0, 1] + -0.8845494793282861 * K[2, 1] + 0.924834003261792 * K[3, 1]),
        y[2] + h * (0.2413651341592667 * K[0, 2] + -0.8845494793282861 * K[2, 2] + 0.924834003261792 * K[3, 2]),
        y[3] + h * (0.2413651341592667 * K[0, 3] + -0.8845494793282861 * K[2, 3] + 0.924834003261792 * K[3, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[5, 0], K[5, 1], K[5, 2], K[5, 3] = _stage_f(
        t + 0.3333333333333333 * h,
        y[0] + h * (0.037037037037037035 * K[0, 0] + 0.17082860872947386 * K[3, 0] + 0.12546768756682242 * K[4,
            0]),
        y[1] + h * (0.037037037037037035 * K[0, 1] + 0.17082860872947386 * K[3, 1] + 0.12546768756682242 * K[4,
            1]),
        y[2] + h * (0.037037037037037035 * K[0, 2] + 0.17082860872947386 * K[3, 2] + 0.12546768756682242 * K[4,
            2]),
        y[3] + h * (0.037037037037037035 * K[0, 3] + 0.17082860872947386 * K[3, 3] + 0.12546768756682242 * K[4,
            3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[6, 0], K[6, 1], K[6, 2], K[6, 3] = _stage_f(
        t + 0.25 * h,
        y[0] + h * (0.037109375 * K[0, 0] + 0.17025221101954405 * K[3, 0] + 0.06021653898045596 * K[4, 0] +
            -0.017578125 * K[5, 0]),
        y[1] + h * (0.037109375 * K[0, 1] + 0.17025221101954405 * K[3, 1] + 0.06021653898045596 * K[4, 1] +
            -0.017578125 * K[5, 1]),
        y[2] + h * (0.037109375 * K[0, 2] + 0.17025221101954405 * K[3, 2] + 0.06021653898045596 * K[4, 2] +
            -0.017578125 * K[5, 2]),
        y[3] + h * (0.037109375 * K[0, 3] + 0.17025221101954405 * K[3, 3] + 0.06021653898045596 * K[4, 3] +
            -0.017578125 * K[5, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[7, 0], K[7, 1], K[7, 2], K[7, 3] = _stage_f(
        t + 0.3076923076923077 * h,
        y[0] + h * (0.03709200011850479 * K[0, 0] + 0.17038392571223998 * K[3, 0] + 0.10726203044637328 * K[4, 0]
            + -0.015319437748624402 * K[5, 0] + 0.008273789163814023 * K[6, 0]),
        y[1] + h * (0.03709200011850479 * K[0, 1] + 0.17038392571223998 * K[3, 1] + 0.10726203044637328 * K[4, 1]
            + -0.015319437748624402 * K[5, 1] + 0.008273789163814023 * K[6, 1]),
        y[2] + h * (0.03709200011850479 * K[0, 2] + 0.17038392571223998 * K[3, 2] + 0.10726203044637328 * K[4, 2]
            + -0.015319437748624402 * K[5, 2] + 0.008273789163814023 * K[6, 2]),
        y[3] + h * (0.03709200011850479 * K[0, 3] + 0.17038392571223998 * K[3, 3] + 0.10726203044637328 * K[4, 3]
            + -0.015319437748624402 * K[5, 3] + 0.008273789163814023 * K[6, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[8, 0], K[8, 1], K[8, 2], K[8, 3] = _stage_f(
        t + 0.6512820512820513 * h,
        y[0] + h * (0.6241109587160757 * K[0, 0] + -3.3608926294469414 * K[3, 0] + -0.868219346841726 * K[4, 0] +
            27.59209969944671 * K[5, 0] + 20.154067550477894 * K[6, 0] + -43.48988418106996 * K[7, 0]),
        y[1] + h * (0.6241109587160757 * K[0, 1] + -3.3608926294469414 * K[3, 1] + -0.868219346841726 * K[4, 1] +
            27.59209969944671 * K[5, 1] + 20.154067550477894 * K[6, 1] + -43.48988418106996 * K[7, 1]),
        y[2] + h * (0.6241109587160757 * K[0, 2] + -3.3608926294469414 * K[3, 2] + -0.868219346841726 * K[4, 2] +
            27.59209969944671 * K[5, 2] + 20.154067550477894 * K[6, 2] + -43.48988418106996 * K[7, 2]),
        y[3] + h * (0.6241109587160757 * K[0, 3] + -3.3608926294469414 * K[3, 3] + -0.868219346841726 * K[4, 3] +
            27.59209969944671 * K[5, 3] + 20.154067550477894 * K[6, 3] + -43.48988418106996 * K[7, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[9, 0], K[9, 1], K[9, 2], K[9, 3] = _stage_f(
        t + 0.6 * h,
        y[0] + h * (0.47766253643826434 * K[0, 0] + -2.4881146199716677 * K[3, 0] + -0.590290826836843 * K[4, 0] +
            21.230051448181193 * K[5, 0] + 15.279233632882423 * K[6, 0] + -33.28821096898486 * K[7, 0] +
            -0.020331201708508627 * K[8, 0]),
        y[1] + h * (0.47766253643826434 * K[0, 1] + -2.4881146199716677 * K[3, 1] + -0.590290826836843 * K[4, 1] +
            21.230051448181193 * K[5, 1] + 15.279233632882423 * K[6, 1] + -33.28821096898486 * K[7, 1] +
            -0.020331201708508627 * K[8, 1]),
        y[2] + h * (0.47766253643826434 * K[0, 2] + -2.4881146199716677 * K[3, 2] + -0.590290826836843 * K[4, 2] +
            21.230051448181193 * K[5, 2] + 15.279233632882423 * K[6, 2] + -33.28821096898486 * K[7, 2] +
            -0.020331201708508627 * K[8, 2]),
        y[3] + h * (0.47766253643826434 * K[0, 3] + -2.4881146199716677 * K[3, 3] + -0.590290826836843 * K[4, 3] +
            21.230051448181193 * K[5, 3] + 15.279233632882423 * K[6, 3] + -33.28821096898486 * K[7, 3] +
            -0.020331201708508627 * K[8, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[10, 0], K[10, 1], K[10, 2], K[10, 3] = _stage_f(
        t + 0.8571428571428571 * h,
        y[0] + h * (-0.9371424300859873 * K[0, 0] + 5.186372428844064 * K[3, 0] + 1.0914373489967295 * K[4, 0] +
            -8.149787010746927 * K[5, 0] + -18.52006565999696 * K[6, 0] + 22.739487099350505 * K[7, 0] +
            2.4936055526796523 * K[8, 0] + -3.0467644718982196 * K[9, 0]),
        y[1] + h * (-0.9371424300859873 * K[0, 1] + 5.186372428844064 * K[3, 1] + 1.0914373489967295 * K[4, 1] +
            -8.149787010746927 * K[5, 1] + -18.52006565999696 * K[6, 1] + 22.739487099350505 * K[7, 1] +
            2.4936055526796523 * K[8, 1] + -3.0467644718982196 * K[9, 1]),
        y[2] + h * (-0.9371424300859873 * K[0, 2] + 5.186372428844064 * K[3, 2] + 1.0914373489967295 * K[4, 2] +
            -8.149787010746927 * K[5, 2] + -18.52006565999696 * K[6, 2] + 22.739487099350505 * K[7, 2] +
            2.4936055526796523 * K[8, 2] + -3.0467644718982196 * K[9, 2]),
        y[3] + h * (-0.9371424300859873 * K[0, 3] + 5.186372428844064 * K[3, 3] + 1.0914373489967295 * K[4, 3] +
            -8.149787010746927 * K[5, 3] + -18.52006565999696 * K[6, 3] + 22.739487099350505 * K[7, 3] +
            2.4936055526796523 * K[8, 3] + -3.0467644718982196 * K[9, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[11, 0], K[11, 1], K[11, 2], K[11, 3] = _stage_f(
        t + 1.0 * h,
        y[0] + h * (2.273310147516538 * K[0, 0] + -10.53449546673725 * K[3, 0] + -2.0008720582248625 * K[4, 0] +
            -17.9589318631188 * K[5, 0] + 27.94888452941996 * K[6, 0] + -2.8589982771350235 * K[7, 0] +
            -8.87285693353063 * K[8, 0] + 12.360567175794303 * K[9, 0] + 0.6433927460157636 * K[10, 0]),
        y[1] + h * (2.273310147516538 * K[0, 1] + -10.53449546673725 * K[3, 1] + -2.0008720582248625 * K[4, 1] +
            -17.9589318631188 * K[5, 1] + 27.94888452941996 * K[6, 1] + -2.8589982771350235 * K[7, 1] +
            -8.87285693353063 * K[8, 1] + 12.360567175794303 * K[9, 1] + 0.6433927460157636 * K[10, 1]),
        y[2] + h * (2.273310147516538 * K[0, 2] + -10.53449546673725 * K[3, 2] + -2.0008720582248625 * K[4, 2] +
            -17.9589318631188 * K[5, 2] + 27.94888452941996 * K[6, 2] + -2.8589982771350235 * K[7, 2] +
            -8.87285693353063 * K[8, 2] + 12.360567175794303 * K[9, 2] + 0.6433927460157636 * K[10, 2]),
        y[3] + h * (2.273310147516538 * K[0, 3] + -10.53449546673725 * K[3, 3] + -2.0008720582248625 * K[4, 3] +
            -17.9589318631188 * K[5, 3] + 27.94888452941996 * K[6, 3] + -2.8589982771350235 * K[7, 3] +
            -8.87285693353063 * K[8, 3] + 12.360567175794303 * K[9, 3] + 0.6433927460157636 * K[10, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    yn[0] = y[0] + h * (0.054293734116568765 * K[0, 0] + 4.450312892752409 * K[5, 0] + 1.8915178993145003 * K[6,
        0] + -5.801203960010585 * K[7, 0] + 0.3111643669578199 * K[8, 0] + -0.1521609496625161 * K[9, 0] +
        0.20136540080403034 * K[10, 0] + 0.04471061572777259 * K[11, 0])
    yn[1] = y[1] + h * (0.054293734116568765 * K[0, 1] + 4.450312892752409 * K[5, 1] + 1.8915178993145003 * K[6,
        1] + -5.801203960010585 * K[7, 1] + 0.3111643669578199 * K[8, 1] + -0.1521609496625161 * K[9, 1] +
        0.20136540080403034 * K[10, 1] + 0.04471061572777259 * K[11, 1])
    yn[2] = y[2] + h * (0.054293734116568765 * K[0, 2] + 4.450312892752409 * K[5, 2] + 1.8915178993145003 * K[6,
        2] + -5.801203960010585 * K[7, 2] + 0.3111643669578199 * K[8, 2] + -0.1521609496625161 * K[9, 2] +
        0.20136540080403034 * K[10, 2] + 0.04471061572777259 * K[11, 2])
    yn[3] = y[3] + h * (0.054293734116568765 * K[0, 3] + 4.450312892752409 * K[5, 3] + 1.8915178993145003 * K[6,
        3] + -5.801203960010585 * K[7, 3] + 0.3111643669578199 * K[8, 3] + -0.1521609496625161 * K[9, 3] +
        0.20136540080403034 * K[10, 3] + 0.04471061572777259 * K[11, 3])
    K[12, 0], K[12, 1], K[12, 2], K[12, 3] = _stage_f(t + h, yn[0], yn[1], yn[2], yn[3],
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)


@njit(cache=True, nogil=True)
def _dop853_error(h, K, sc):
    """The error of the step against the scales ``sc`` (<= 1: accepted), as DOP853 measures it."""
    e5_0 = (0.01312004499419488 * K[0, 0] + -1.2251564463762044 * K[5, 0] + -0.4957589496572502 * K[6, 0] +
        1.6643771824549864 * K[7, 0] + -0.35032884874997366 * K[8, 0] + 0.3341791187130175 * K[9, 0] +
        0.08192320648511571 * K[10, 0] + -0.022355307863886294 * K[11, 0]) / sc[0]
    e3_0 = (-0.18980075407240762 * K[0, 0] + 4.450312892752409 * K[5, 0] + 1.8915178993145003 * K[6, 0] +
        -5.801203960010585 * K[7, 0] + -0.4226823213237919 * K[8, 0] + -0.1521609496625161 * K[9, 0] +
        0.20136540080403034 * K[10, 0] + 0.02265179219836082 * K[11, 0]) / sc[0]
    e5_1 = (0.01312004499419488 * K[0, 1] + -1.2251564463762044 * K[5, 1] + -0.4957589496572502 * K[6, 1] +
        1.6643771824549864 * K[7, 1] + -0.35032884874997366 * K[8, 1] + 0.3341791187130175 * K[9, 1] +
        0.08192320648511571 * K[10, 1] + -0.022355307863886294 * K[11, 1]) / sc[1]
    e3_1 = (-0.18980075407240762 * K[0, 1] + 4.450312892752409 * K[5, 1] + 1.8915178993145003 * K[6, 1] +
        -5.801203960010585 * K[7, 1] + -0.4226823213237919 * K[8, 1] + -0.1521609496625161 * K[9, 1] +
        0.20136540080403034 * K[10, 1] + 0.02265179219836082 * K[11, 1]) / sc[1]
    e5_2 = (0.01312004499419488 * K[0, 2] + -1.2251564463762044 * K[5, 2] + -0.4957589496572502 * K[6, 2] +
        1.6643771824549864 * K[7, 2] + -0.35032884874997366 * K[8, 2] + 0.3341791187130175 * K[9, 2] +
        0.08192320648511571 * K[10, 2] + -0.022355307863886294 * K[11, 2]) / sc[2]
    e3_2 = (-0.18980075407240762 * K[0, 2] + 4.450312892752409 * K[5, 2] + 1.8915178993145003 * K[6, 2] +
        -5.801203960010585 * K[7, 2] + -0.4226823213237919 * K[8, 2] + -0.1521609496625161 * K[9, 2] +
        0.20136540080403034 * K[10, 2] + 0.02265179219836082 * K[11, 2]) / sc[2]
    e5_3 = (0.01312004499419488 * K[0, 3] + -1.2251564463762044 * K[5, 3] + -0.4957589496572502 * K[6, 3] +
        1.6643771824549864 * K[7, 3] + -0.35032884874997366 * K[8, 3] + 0.3341791187130175 * K[9, 3] +
        0.08192320648511571 * K[10, 3] + -0.022355307863886294 * K[11, 3]) / sc[3]
    e3_3 = (-0.18980075407240762 * K[0, 3] + 4.450312892752409 * K[5, 3] + 1.8915178993145003 * K[6, 3] +
        -5.801203960010585 * K[7, 3] + -0.4226823213237919 * K[8, 3] + -0.1521609496625161 * K[9, 3] +
        0.20136540080403034 * K[10, 3] + 0.02265179219836082 * K[11, 3]) / sc[3]
    e5 = e5_0 * e5_0 + e5_1 * e5_1 + e5_2 * e5_2 + e5_3 * e5_3
    e3 = e3_0 * e3_0 + e3_1 * e3_1 + e3_2 * e3_2 + e3_3 * e3_3
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return h * e5 / np.sqrt((e5 + 0.01 * e3) * 4.0)


@njit(cache=True, nogil=True)
def _dop853_dense(t, h, y, yn, K, F, yy, sg, ctrl, kp, u_hold, u_limit, P, mode, L):
    """The three more stages of the dense output and its coefficients ``F`` (7 x 4)."""
    K[13, 0], K[13, 1], K[13, 2], K[13, 3] = _stage_f(
        t + 0.1 * h,
        y[0] + h * (0.056167502283047954 * K[0, 0] + 0.25350021021662483 * K[6, 0] + -0.2462390374708025 * K[7, 0]
            + -0.12419142326381637 * K[8, 0] + 0.15329179827876568 * K[9, 0] + 0.00820105229563469 * K[10, 0] +
            0.007567897660545699 * K[11, 0] + -0.008298 * K[12, 0]),
        y[1] + h * (0.056167502283047954 * K[0, 1] + 0.25350021021662483 * K[6, 1] + -0.2462390374708025 * K[7, 1]
            + -0.12419142326381637 * K[8, 1] + 0.15329179827876568 * K[9, 1] + 0.00820105229563469 * K[10, 1] +
            0.007567897660545699 * K[11, 1] + -0.008298 * K[12, 1]),
        y[2] + h * (0.056167502283047954 * K[0, 2] + 0.25350021021662483 * K[6, 2] + -0.2462390374708025 * K[7, 2]
            + -0.12419142326381637 * K[8, 2] + 0.15329179827876568 * K[9, 2] + 0.00820105229563469 * K[10, 2] +
            0.007567897660545699 * K[11, 2] + -0.008298 * K[12, 2]),
        y[3] + h * (0.056167502283047954 * K[0, 3] + 0.25350021021662483 * K[6, 3] + -0.2462390374708025 * K[7, 3]
            + -0.12419142326381637 * K[8, 3] + 0.15329179827876568 * K[9, 3] + 0.00820105229563469 * K[10, 3] +
            0.007567897660545699 * K[11, 3] + -0.008298 * K[12, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[14, 0], K[14, 1], K[14, 2], K[14, 3] = _stage_f(
        t + 0.2 * h,
        y[0] + h * (0.03183464816350214 * K[0, 0] + 0.028300909672366776 * K[5, 0] + 0.053541988307438566 * K[6,
            0] + -0.05492374857139099 * K[7, 0] + -0.00010834732869724932 * K[10, 0] + 0.0003825710908356584 * K[11,
            0] + -0.00034046500868740456 * K[12, 0] + 0.1413124436746325 * K[13, 0]),
        y[1] + h * (0.03183464816350214 * K[0, 1] + 0.028300909672366776 * K[5, 1] + 0.053541988307438566 * K[6,
            1] + -0.05492374857139099 * K[7, 1] + -0.00010834732869724932 * K[10, 1] + 0.0003825710908356584 * K[11,
            1] + -0.00034046500868740456 * K[12, 1] + 0.1413124436746325 * K[13, 1]),
        y[2] + h * (0.03183464816350214 * K[0, 2] + 0.028300909672366776 * K[5, 2] + 0.053541988307438566 * K[6,
            2] + -0.05492374857139099 * K[7, 2] + -0.00010834732869724932 * K[10, 2] + 0.0003825710908356584 * K[11,
            2] + -0.00034046500868740456 * K[12, 2] + 0.1413124436746325 * K[13, 2]),
        y[3] + h * (0.03183464816350214 * K[0, 3] + 0.028300909672366776 * K[5, 3] + 0.053541988307438566 * K[6,
            3] + -0.05492374857139099 * K[7, 3] + -0.00010834732869724932 * K[10, 3] + 0.0003825710908356584 * K[11,
            3] + -0.00034046500868740456 * K[12, 3] + 0.1413124436746325 * K[13, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    K[15, 0], K[15, 1], K[15, 2], K[15, 3] = _stage_f(
        t + 0.7777777777777778 * h,
        y[0] + h * (-0.42889630158379194 * K[0, 0] + -4.697621415361164 * K[5, 0] + 7.683421196062599 * K[6, 0] +
            4.06898981839711 * K[7, 0] + 0.3567271874552811 * K[8, 0] + -0.0013990241651590145 * K[12, 0] +
            2.9475147891527724 * K[13, 0] + -9.15095847217987 * K[14, 0]),
        y[1] + h * (-0.42889630158379194 * K[0, 1] + -4.697621415361164 * K[5, 1] + 7.683421196062599 * K[6, 1] +
            4.06898981839711 * K[7, 1] + 0.3567271874552811 * K[8, 1] + -0.0013990241651590145 * K[12, 1] +
            2.9475147891527724 * K[13, 1] + -9.15095847217987 * K[14, 1]),
        y[2] + h * (-0.42889630158379194 * K[0, 2] + -4.697621415361164 * K[5, 2] + 7.683421196062599 * K[6, 2] +
            4.06898981839711 * K[7, 2] + 0.3567271874552811 * K[8, 2] + -0.0013990241651590145 * K[12, 2] +
            2.9475147891527724 * K[13, 2] + -9.15095847217987 * K[14, 2]),
        y[3] + h * (-0.42889630158379194 * K[0, 3] + -4.697621415361164 * K[5, 3] + 7.683421196062599 * K[6, 3] +
            4.06898981839711 * K[7, 3] + 0.3567271874552811 * K[8, 3] + -0.0013990241651590145 * K[12, 3] +
            2.9475147891527724 * K[13, 3] + -9.15095847217987 * K[14, 3]),
        sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    for r in range(4):
        dy = yn[r] - y[r]
        F[0, r] = dy
        F[1, r] = h * K[0, r] - dy
        F[2, r] = 2.0 * dy - h * (K[12, r] + K[0, r])
        F[3, r] = h * (-8.428938276109013 * K[0, r] + 0.5667149535193777 * K[5, r] + -3.0689499459498917 * K[6, r]
            + 2.38466765651207 * K[7, r] + 2.117034582445028 * K[8, r] + -0.871391583777973 * K[9, r] +
            2.2404374302607883 * K[10, r] + 0.6315787787694688 * K[11, r] + -0.08899033645133331 * K[12, r] +
            18.148505520854727 * K[13, r] + -9.194632392478356 * K[14, r] + -4.436036387594894 * K[15, r])
        F[4, r] = h * (10.427508642579134 * K[0, r] + 242.28349177525817 * K[5, r] + 165.20045171727028 * K[6, r]
            + -374.5467547226902 * K[7, r] + -22.113666853125306 * K[8, r] + 7.733432668472264 * K[9, r] +
            -30.674084731089398 * K[10, r] + -9.332130526430229 * K[11, r] + 15.697238121770845 * K[12, r] +
            -31.139403219565178 * K[13, r] + -9.35292435884448 * K[14, r] + 35.81684148639408 * K[15, r])
        F[5, r] = h * (19.985053242002433 * K[0, r] + -387.0373087493518 * K[5, r] + -189.17813819516758 * K[6, r]
            + 527.8081592054236 * K[7, r] + -11.57390253995963 * K[8, r] + 6.8812326946963 * K[9, r] +
            -1.0006050966910838 * K[10, r] + 0.7777137798053443 * K[11, r] + -2.778205752353508 * K[12, r] +
            -60.19669523126412 * K[13, r] + 84.32040550667716 * K[14, r] + 11.99229113618279 * K[15, r])
        F[6, r] = h * (-25.69393346270375 * K[0, r] + -154.18974869023643 * K[5, r] + -231.5293791760455 * K[6, r]
            + 357.6391179106141 * K[7, r] + 93.40532418362432 * K[8, r] + -37.45832313645163 * K[9, r] +
            104.0996495089623 * K[10, r] + 29.8402934266605 * K[11, r] + -43.53345659001114 * K[12, r] +
            96.32455395918828 * K[13, r] + -39.17726167561544 * K[14, r] + -149.72683625798564 * K[15, r])


@njit(cache=True, nogil=True)
def _dense_samples(t, h, t_new, y, yn, K, F, yy, sg, ctrl, kp, u_hold, u_limit, P, mode, L, dt, out, k_out):
    """The output samples in [t, t_new) of an accepted step, from its dense output; returns the next sample."""
    _dop853_dense(t, h, y, yn, K, F, yy, sg, ctrl, kp, u_hold, u_limit, P, mode, L)
    n_out = out.shape[0]
    while k_out < n_out and k_out * dt < t_new - 1e-9 * dt:
        tk = k_out * dt
        xq = (tk - t) / h
        for r in range(4):
            v = 0.0
            for m in range(6, -1, -1):
                v += F[m, r]
                v *= xq if (6 - m) % 2 == 0 else 1.0 - xq
            yy[r] = y[r] + v
        if mode == NONLINEAR:
            yy[0], yy[1], yy[2], yy[3] = project_state(yy[0], yy[1], yy[2], yy[3], P)
        _store(out, k_out, yy[0], yy[1], yy[2], yy[3], _command_at(tk, yy[0], sg, ctrl, kp, u_hold, u_limit))
        k_out += 1
    return k_out


@njit(cache=True, nogil=True)
def _take_step(y, yn, P, bounded):
    """Move to the step's end ``yn`` (the bounds enforced on the nonlinear model); True when a bound held it."""
    moved = False
    if bounded:
        p0, p1, p2, p3 = project_state(yn[0], yn[1], yn[2], yn[3], P)
        moved = p0 != yn[0] or p1 != yn[1] or p2 != yn[2] or p3 != yn[3]
        yn[0], yn[1], yn[2], yn[3] = p0, p1, p2, p3
    for r in range(4):
        y[r] = yn[r]
    return moved


@njit(cache=True, nogil=True)
def _integrate_segment(y, work, ta, tb, sg, check_u, P, mode, L, ctrl, kp, u_hold, u_limit, tol, scale, dt,
                       h_max, out, state, counts, max_steps, pause_at):
    """Integrate from ``ta`` to ``tb``, where the inputs are those of ``sg``; see :func:`integrate_segments`.

    ``work``: scratch (26 x 4): the stages K (16), the dense output F (7), the new state, a sample's state,
    the error scales. Returns -1, :data:`PAUSED` (``state[3]``: the time reached) once the steps taken reach
    ``pause_at`` before ``tb``, or the failure code.
    """
    K = work[0:16]
    F = work[16:23]
    yn = work[23]
    yy = work[24]
    sc = work[25]
    bounded = mode == NONLINEAR
    h_prop = state[0]
    tiny = 1e-12 * max(1.0, abs(tb))
    t = ta
    K[0, 0], K[0, 1], K[0, 2], K[0, 3] = _stage_f(t, y[0], y[1], y[2], y[3], sg, ctrl, kp, u_hold, u_limit, P,
                                                  mode, L)
    counts[3] += 1
    rejected = False
    while tb - t > tiny:
        h = min(h_prop, h_max)
        cut = False
        if t + h >= tb - tiny:
            h = tb - t
            cut = True
        if check_u:
            # the valve's branches switch where the command changes sign (eq. 3): the step ends there
            tc = _u_crossing(sg, t, t + h)
            if tc - t > tiny and tb - tc > tiny and tc < t + h:
                h = tc - t
                cut = False
        t_new = tb if t + h >= tb - tiny else t + h
        # the step: stages 1-11, the solution, the derivative at its end (stage 12)
        _dop853_step(t, h, y, K, yn, sg, ctrl, kp, u_hold, u_limit, P, mode, L)
        counts[3] += _N_STAGES
        for r in range(4):
            sc[r] = tol * (scale[r] + max(abs(y[r]), abs(yn[r])))
        err = _dop853_error(h, K, sc)
        if not np.isfinite(err) or err > 1.0:
            # rejected: shrink (a non-finite stage halves the step until the state is finite again)
            fac = 0.5 if not np.isfinite(err) else max(0.2, 0.9 * err ** (-1.0 / 8.0))
            h_prop = h * fac
            rejected = True
            counts[2] += 1
            if h_prop < 1e-14 * max(1.0, abs(t)) or counts[1] + counts[2] > max_steps:
                state[2] = t
                return 2 if np.isfinite(err) else 1
            continue
        # accepted: the output samples inside the step, from the dense output
        if counts[0] < out.shape[0] and counts[0] * dt < t_new - 1e-9 * dt:
            counts[0] = _dense_samples(t, h, t_new, y, yn, K, F, yy, sg, ctrl, kp, u_hold, u_limit, P, mode, L,
                                       dt, out, counts[0])
            counts[3] += 3
        counts[1] += 1
        fac = 10.0 if err == 0.0 else min(10.0, 0.9 * err ** (-1.0 / 8.0))
        if rejected:            # no growth right after a rejection (Hairer's DOP853)
            fac = min(fac, 1.0)
            rejected = False
        # a step cut short by the segment's end or a switch keeps the step proposed before it
        h_prop = max(h_prop, h * fac) if cut else h * fac
        t = t_new
        moved = _take_step(y, yn, P, bounded)
        if not (np.isfinite(y[0]) and np.isfinite(y[1]) and np.isfinite(y[2]) and np.isfinite(y[3])):
            state[2] = t
            return 1
        if moved:
            # a bound held the state: the derivative at the end is that of the held state
            K[0, 0], K[0, 1], K[0, 2], K[0, 3] = _stage_f(t, y[0], y[1], y[2], y[3], sg, ctrl, kp, u_hold,
                                                          u_limit, P, mode, L)
            counts[3] += 1
        else:
            for r in range(4):
                K[0, r] = K[_N_STAGES, r]
        if counts[1] + counts[2] > max_steps:
            state[2] = t
            return 2
        if counts[1] + counts[2] >= pause_at and tb - t > tiny:
            # after an accepted step the integrator's whole state is y, the proposed step and f(t, y),
            # which a resumed call recomputes to the same bits: pausing here changes nothing
            state[0] = h_prop
            state[3] = t
            return PAUSED
    state[0] = h_prop
    return -1


@njit(cache=True, nogil=True)
def _samples_at(t, y, sg, ctrl, kp, u_hold, u_limit, dt, out, k_out):
    """The output samples at ``t`` (a segment's start or the run's end): the state there, the inputs of ``sg``."""
    while k_out < out.shape[0] and k_out * dt <= t + 1e-9 * dt:
        _store(out, k_out, y[0], y[1], y[2], y[3], _command_at(t, y[0], sg, ctrl, kp, u_hold, u_limit))
        k_out += 1
    return k_out


@njit(cache=True, nogil=True)
def integrate_segments(y, state, counts, n_seg, seg_t, seg_u, seg_d, seg_r, seg_ctrl, sm_u, sm_d, sm_r, n_sm,
                       prm, mode, lin, ctrl, kp, u_limit, tol, scale, dt, h_max, out, max_steps, final, pause_at):
    """Integrate one run over segments ``0 .. n_seg - 1`` (``seg_t[s]`` to ``seg_t[s + 1]``).

    ``y`` (4) is the state at ``seg_t[0]`` and is left at the end of the last segment. ``state`` carries
    what one call leaves to the next: [proposed step, held command, time of failure, time of a pause];
    ``counts``: [next output sample, accepted steps, rejected steps, right-hand side evaluations, segment
    of a pause]. Once the steps taken (accepted and rejected, counted over the run) reach ``pause_at``,
    the call returns :data:`PAUSED` after its next accepted step, with the time and segment reached in
    ``state[3]`` and ``counts[4]``; called again with the same segments it goes on from there (the
    caller checks for a cancel in between), to the same bits as without the pause. A fresh call has
    ``state[3]`` NaN and ``counts[4]`` 0. The output
    samples ``k dt`` are written into ``out`` (rows of x, v, p1, p2, u) as the steps pass them. The
    error of a step is measured against ``tol (scale_i + |y_i|)`` for each state i, as DOP853's; no
    step is longer than ``h_max``. ``seg_u``, ``seg_d``, ``seg_r``: each segment's line (value at its
    middle, slope); ``sm_u``, ``sm_d``, ``sm_r`` (MAX_SMOOTH x 4): the sines and chirps, ``n_sm`` how
    many of each. ``seg_ctrl[s]``: the sampled controller reads the state at boundary s (n_seg + 1
    flags). ``final``: the last call of the run, which writes the sample at its end.

    Returns -1, :data:`PAUSED`, or 1 when the state stopped being finite, 2 when the step size collapsed
    or the steps exceeded ``max_steps`` (``state[2]``: the time).
    """
    work = np.empty((26, 4))
    P = _params_tuple(prm)
    L = _lin_tuple(lin)
    u_hold = state[1]
    switching = ctrl == OPEN_LOOP and (mode == NONLINEAR or mode == LINEAR_SWITCHING)
    s0 = counts[4]
    resume = np.isfinite(state[3])
    for s in range(s0, n_seg):
        ta = seg_t[s]
        sg = _segment_inputs(s, seg_t, seg_u, seg_d, seg_r, sm_u, sm_d, sm_r, n_sm)
        if resume and s == s0:
            # going on from a pause inside the segment: its controller instant and samples are behind
            ta = state[3]
        else:
            if ctrl == ZOH and seg_ctrl[s]:
                u_hold = _control(kp, _sig_r(sg, ta), y[0], u_limit)
            # samples at the segment's start: the state there, the inputs from this segment on
            counts[0] = _samples_at(ta, y, sg, ctrl, kp, u_hold, u_limit, dt, out, counts[0])
            if state[0] <= 0.0:
                state[0] = seg_t[s + 1] - ta
        check_u = switching and (n_sm[0] > 0.0 or seg_u[s, 1] != 0.0)
        st = _integrate_segment(y, work, ta, seg_t[s + 1], sg, check_u, P, mode, L, ctrl, kp, u_hold, u_limit,
                                tol, scale, dt, h_max, out, state, counts, max_steps, pause_at)
        if st == PAUSED:
            counts[4] = s
            state[1] = u_hold
            return st
        if st >= 0:
            return st
    state[3] = np.nan
    counts[4] = 0
    # the sample at the run's end (a later call writes one at its first segment's start)
    s = n_seg - 1
    tb = seg_t[n_seg]
    sg = _segment_inputs(s, seg_t, seg_u, seg_d, seg_r, sm_u, sm_d, sm_r, n_sm)
    if final and ctrl == ZOH and seg_ctrl[n_seg]:
        # the run ends at a controller instant: its last sample holds the command read there
        u_hold = _control(kp, _sig_r(sg, tb), y[0], u_limit)
    if final:
        counts[0] = _samples_at(tb, y, sg, ctrl, kp, u_hold, u_limit, dt, out, counts[0])
    state[1] = u_hold
    return -1
