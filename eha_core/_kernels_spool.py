"""Compiled integrators (numba) of the model with the valve's spool dynamics: six states.

With :attr:`eha_core.variants.Effects.spool` on, the orifices (eq. 3) see the
spool's position u_v (the valve's effective command) and u_v follows the command u
through a second order (eq. V1, docs/model.md §6.1): the states are
[x, v, p1, p2, u_v, du_v/dt]. This module has the integrators of
:mod:`eha_core._kernels` for them, with the same arguments and the same
results (rows of x, v, p1, p2, u): the adaptive DOP853 with dense output over
the segments of the inputs (:func:`integrate_segments`) and the fixed-step RK4
over stage samples (:func:`integrate`, :func:`integrate_batch`). The right-hand
side is the one implementation of the dynamics, :func:`eha_core.model.derivatives`
with u_v as its command, and :func:`eha_core.model.spool_derivatives`.

The paper's model keeps its own four-state kernels, with the stage sums
written out, untouched: its error norm (a root mean square over its four
states) and its speed do not change. Here the stages loop over the tableau of
:mod:`eha_core._dop853`, slower per step but the same method. The valve's
branches switch where u_v changes sign (eq. 3), a state rather than an input: a
step that carries u_v across zero is taken again to end where its dense output
crosses (found by bisection), as the four-state kernel ends its steps where an
open-loop command changes sign; the steps also stop at the jumps of the inputs
and the controller's instants. Imported lazily by :mod:`eha_core.simulate`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import model
from ._dop853 import E3 as _TE3
from ._dop853 import E5 as _TE5
from ._dop853 import A as _TA
from ._dop853 import B as _TB
from ._dop853 import C as _TC
from ._dop853 import D as _TD
from ._kernels import (
    CONTINUOUS,
    LINEAR_POSITIVE,
    LINEAR_SWITCHING,
    NONLINEAR,
    OPEN_LOOP,
    PAUSED,
    ZOH,
    _command_at,
    _control,
    _segment_inputs,
    _sig_d,
    _sig_r,
    _sig_u,
    _store,
    derivatives,
    project_state,
)

__all__ = ["N_STATES", "integrate", "integrate_batch", "integrate_segments"]

spool_derivatives = njit(cache=True, nogil=True, inline="always")(model.spool_derivatives)

#: States: x, v, p1, p2, u_v, du_v/dt.
N_STATES = 6
_N_STAGES = 12


@njit(cache=True, nogil=True, inline="always")
def _f(mode, y, u, d, prm, lin, out):
    """The right-hand side at the state ``y`` into ``out``: the nonlinear model with its spool, or the
    linearised one (eha_core.linear.PACKED_LINEAR_SPOOL): A_core dy + b(sign u_v) u_v + B u + E d - offset."""
    if mode == NONLINEAR:
        # eq. 3 sees the spool's position y[4]; eq. V1 drives it with the command u
        out[0], out[1], out[2], out[3] = derivatives(y[0], y[1], y[2], y[3], y[4], d, prm)
        out[4], out[5] = spool_derivatives(y[4], y[5], u, prm)
        return
    bo = 36 if mode == LINEAR_POSITIVE or (mode == LINEAR_SWITCHING and y[4] >= 0.0) else 42
    for r in range(N_STATES):
        acc = 0.0
        for c in range(N_STATES):
            acc += lin[N_STATES * r + c] * (y[c] - lin[60 + c])
        out[r] = acc + lin[bo + r] * y[4] + lin[48 + r] * u + lin[54 + r] * d - lin[66 + r]


@njit(cache=True, nogil=True, inline="always")
def _stage(t, y, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, out):
    """The right-hand side at a stage: the inputs of the segment ``sg`` at time ``t``, the command as the
    controller (or the input) gives it."""
    d = _sig_d(sg, t)
    if ctrl == OPEN_LOOP:
        u = _sig_u(sg, t)
    elif ctrl == ZOH:
        u = u_hold
    else:
        u = _control(kp, _sig_r(sg, t), y[0], u_limit)
    _f(mode, y, u, d, prm, lin, out)


@njit(cache=True, nogil=True)
def _project(y, prm):
    """The bounds on the actuator's states (the spool has none); True when they moved the state."""
    p0, p1, p2, p3 = project_state(y[0], y[1], y[2], y[3], prm)
    moved = p0 != y[0] or p1 != y[1] or p2 != y[2] or p3 != y[3]
    y[0], y[1], y[2], y[3] = p0, p1, p2, p3
    return moved


@njit(cache=True, nogil=True)
def _finite(y):
    for r in range(y.shape[0]):
        if not np.isfinite(y[r]):
            return False
    return True


# -- the fixed-step RK4 (an input given as a function of t) ----------------------------------------------

@njit(cache=True, nogil=True)
def _rk4_step(y, h, ua, ub, uc, da, db, dc, ctrl, kp, r_st, i, u_limit, prm, mode, lin, k, ys):
    """Step ``i`` of the RK4, ``y`` in place: the stages' commands ``ua``, ``ub``, ``uc`` (the continuous
    controller's read from the stages' states and the reference ``r_st[i]``), ``k`` (4 x 6) and ``ys``
    scratch. The same stages as the four-state kernel's."""
    half = 0.5 * h
    _f(mode, y, ua, da, prm, lin, k[0])
    for r in range(N_STATES):
        ys[r] = y[r] + half * k[0, r]
    if ctrl == CONTINUOUS:
        ub = _control(kp, r_st[i, 1], ys[0], u_limit)
    _f(mode, ys, ub, db, prm, lin, k[1])
    for r in range(N_STATES):
        ys[r] = y[r] + half * k[1, r]
    _f(mode, ys, ub, db, prm, lin, k[2])
    for r in range(N_STATES):
        ys[r] = y[r] + h * k[2, r]
    if ctrl == CONTINUOUS:
        uc = _control(kp, r_st[i, 2], ys[0], u_limit)
    _f(mode, ys, uc, dc, prm, lin, k[3])
    for r in range(N_STATES):
        y[r] = y[r] + h / 6.0 * (k[0, r] + 2.0 * k[1, r] + 2.0 * k[2, r] + k[3, r])


@njit(cache=True, nogil=True)
def _command_at_end(n_steps, y, u_st, ctrl, kp, r_st, ctrl_every, u_limit, u_hold):
    """The command of the run's last sample, at t_end."""
    if ctrl == ZOH:
        if n_steps % ctrl_every == 0:
            u_hold = _control(kp, r_st[n_steps, 0], y[0], u_limit)
        return u_hold
    if ctrl == CONTINUOUS:
        return _control(kp, r_st[n_steps, 0], y[0], u_limit)
    return u_st[n_steps, 0]


@njit(cache=True, nogil=True)
def integrate(y0, h, n_steps, sub, prm, mode, lin, u_st, d_st, ctrl, kp, r_st, ctrl_every, u_limit, out, y_end):
    """:func:`eha_core._kernels.integrate` for the six states: fills ``out`` (n_out x 5: x, v, p1, p2, u)
    and ``y_end`` (6); returns -1, or the step at which the state stopped being finite."""
    y = y0.copy()
    k, ys = np.empty((4, N_STATES)), np.empty(N_STATES)
    bounded = mode == NONLINEAR
    u_hold = 0.0
    k_out = 0
    for i in range(n_steps):
        if ctrl == ZOH and i % ctrl_every == 0:
            u_hold = _control(kp, r_st[i, 0], y[0], u_limit)
        if ctrl == OPEN_LOOP:
            ua, ub, uc = u_st[i, 0], u_st[i, 1], u_st[i, 2]
        elif ctrl == ZOH:
            ua = ub = uc = u_hold
        else:
            ua = ub = uc = _control(kp, r_st[i, 0], y[0], u_limit)
        if i % sub == 0:
            _store(out, k_out, y[0], y[1], y[2], y[3], ua)
            k_out += 1
        _rk4_step(y, h, ua, ub, uc, d_st[i, 0], d_st[i, 1], d_st[i, 2], ctrl, kp, r_st, i, u_limit, prm, mode,
                  lin, k, ys)
        if bounded:
            _project(y, prm)
        if not _finite(y):
            return i
    for r in range(N_STATES):
        y_end[r] = y[r]
    if k_out < out.shape[0]:
        _store(out, k_out, y[0], y[1], y[2], y[3],
               _command_at_end(n_steps, y, u_st, ctrl, kp, r_st, ctrl_every, u_limit, u_hold))
    return -1


@njit(cache=True, nogil=True, parallel=True)
def integrate_batch(y0s, h, n_steps, sub, prms, mode, lin, u_sts, d_sts, ctrl, kp, r_sts, ctrl_every, u_limit,
                    outs, status, y_ends):
    """:func:`integrate` over a batch of runs, in parallel over the cores."""
    for j in prange(y0s.shape[0]):
        status[j] = integrate(y0s[j], h, n_steps, sub, prms[j], mode, lin[j], u_sts[j], d_sts[j],
                              ctrl, kp, r_sts[j], ctrl_every, u_limit, outs[j], y_ends[j])


# -- the adaptive DOP853 (every run whose inputs are signals) ---------------------------------------------

@njit(cache=True, nogil=True)
def _dop853_step(t, h, y, K, yn, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin):
    """Stages 1-11 of a DOP853 step from ``K[0]`` = f(t, y), the solution ``yn`` and its derivative K[12]."""
    for i in range(1, _N_STAGES):
        for r in range(N_STATES):
            acc = 0.0
            for j in range(i):
                acc += _TA[i, j] * K[j, r]
            ys[r] = y[r] + h * acc
        _stage(t + _TC[i] * h, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, K[i])
    for r in range(N_STATES):
        acc = 0.0
        for j in range(_N_STAGES):
            acc += _TB[j] * K[j, r]
        yn[r] = y[r] + h * acc
    _stage(t + h, yn, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, K[_N_STAGES])


@njit(cache=True, nogil=True)
def _dop853_error(h, K, sc):
    """The error of the step against the scales ``sc`` (<= 1: accepted), as DOP853 measures it."""
    e5 = 0.0
    e3 = 0.0
    for r in range(N_STATES):
        a5 = 0.0
        a3 = 0.0
        for j in range(_N_STAGES):
            a5 += _TE5[j] * K[j, r]
            a3 += _TE3[j] * K[j, r]
        a5 /= sc[r]
        a3 /= sc[r]
        e5 += a5 * a5
        e3 += a3 * a3
    if e5 == 0.0 and e3 == 0.0:
        return 0.0
    return h * e5 / np.sqrt((e5 + 0.01 * e3) * N_STATES)


@njit(cache=True, nogil=True)
def _dop853_dense(t, h, y, yn, K, F, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin):
    """The three more stages of the dense output and its coefficients ``F`` (7 x 6)."""
    for i in range(_N_STAGES + 1, 16):
        for r in range(N_STATES):
            acc = 0.0
            for j in range(i):
                acc += _TA[i, j] * K[j, r]
            ys[r] = y[r] + h * acc
        _stage(t + _TC[i] * h, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, K[i])
    for r in range(N_STATES):
        dy = yn[r] - y[r]
        F[0, r] = dy
        F[1, r] = h * K[0, r] - dy
        F[2, r] = 2.0 * dy - h * (K[12, r] + K[0, r])
        for m in range(4):
            acc = 0.0
            for j in range(16):
                acc += _TD[m, j] * K[j, r]
            F[3 + m, r] = h * acc


@njit(cache=True, nogil=True)
def _dense_samples(t, h, t_new, y, yn, K, F, yy, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, dt, out,
                   k_out):
    """The output samples in [t, t_new) of an accepted step, from its dense output; returns the next sample."""
    _dop853_dense(t, h, y, yn, K, F, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin)
    n_out = out.shape[0]
    while k_out < n_out and k_out * dt < t_new - 1e-9 * dt:
        tk = k_out * dt
        xq = (tk - t) / h
        for r in range(N_STATES):
            v = 0.0
            for m in range(6, -1, -1):
                v += F[m, r]
                v *= xq if (6 - m) % 2 == 0 else 1.0 - xq
            yy[r] = y[r] + v
        if mode == NONLINEAR:
            _project(yy, prm)
        _store(out, k_out, yy[0], yy[1], yy[2], yy[3], _command_at(tk, yy[0], sg, ctrl, kp, u_hold, u_limit))
        k_out += 1
    return k_out


@njit(cache=True, nogil=True)
def _spool_crossing(F, y):
    """Where in the step (a fraction of it, in (0, 1]) the dense output of the spool's position first
    is on the other side of zero from its start (bisection, to rounding); 1 when nowhere before the end."""
    side = y[4] >= 0.0
    a, b = 0.0, 1.0
    for _ in range(80):
        m = 0.5 * (a + b)
        if m <= a or m >= b:
            break
        v = 0.0
        for k in range(6, -1, -1):
            v += F[k, 4]
            v *= m if (6 - k) % 2 == 0 else 1.0 - m
        if (y[4] + v >= 0.0) == side:
            a = m
        else:
            b = m
    return b


@njit(cache=True, nogil=True)
def _step_size(t, tb, tiny, h_prop, h_max, h_to_crossing):
    """The next step (h, cut short, its end): the proposed one, cut at the segment's end ``tb`` and at
    the spool's crossing of zero ``h_to_crossing`` (0: none known)."""
    h = min(h_prop, h_max)
    cut = False
    if t + h >= tb - tiny:
        h = tb - t
        cut = True
    if h_to_crossing > 0.0:
        # the step again, to where the spool's position crosses zero
        h = min(h, h_to_crossing)
        cut = True
    return h, cut, tb if t + h >= tb - tiny else t + h


@njit(cache=True, nogil=True)
def _to_crossing(t, h, tiny, y, yn, K, F, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, counts):
    """The length of the step to where an accepted step from ``y`` to ``yn`` carries the spool's position
    across zero, where the flows bend (eq. 3); 0 when it does not, or does at its very start (a step that
    ended at a crossing)."""
    if (y[4] >= 0.0) == (yn[4] >= 0.0):
        return 0.0
    _dop853_dense(t, h, y, yn, K, F, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin)
    counts[3] += 3
    frac = _spool_crossing(F, y)
    if 1e-6 < frac < 1.0 and h * frac > tiny:
        return h * frac
    return 0.0


@njit(cache=True, nogil=True)
def _integrate_segment(y, work, ta, tb, sg, prm, mode, lin, ctrl, kp, u_hold, u_limit, tol, scale, dt, h_max, out,
                       state, counts, max_steps, pause_at):
    """Integrate from ``ta`` to ``tb``, where the inputs are those of ``sg``; see :func:`integrate_segments`.

    ``work``: scratch (27 x 6): the stages K (16), the dense output F (7), the new state, a sample's state,
    the error scales, a stage's state. Returns -1, :data:`PAUSED` or the failure code, as the four-state
    kernel's.
    """
    K = work[0:16]
    F = work[16:23]
    yn = work[23]
    yy = work[24]
    sc = work[25]
    ys = work[26]
    bounded = mode == NONLINEAR
    # the valve's branches follow the sign of the spool's position (eq. 3)
    switching = mode == NONLINEAR or mode == LINEAR_SWITCHING
    h_prop = state[0]
    tiny = 1e-12 * max(1.0, abs(tb))
    t = ta
    _stage(t, y, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, K[0])
    counts[3] += 1
    rejected = False
    h_to_crossing = 0.0
    while tb - t > tiny:
        h, cut, t_new = _step_size(t, tb, tiny, h_prop, h_max, h_to_crossing)
        _dop853_step(t, h, y, K, yn, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin)
        counts[3] += _N_STAGES
        for r in range(N_STATES):
            sc[r] = tol * (scale[r] + max(abs(y[r]), abs(yn[r])))
        err = _dop853_error(h, K, sc)
        if not np.isfinite(err) or err > 1.0:
            fac = 0.5 if not np.isfinite(err) else max(0.2, 0.9 * err ** (-1.0 / 8.0))
            h_prop = h * fac
            rejected = True
            counts[2] += 1
            h_to_crossing = 0.0
            if h_prop < 1e-14 * max(1.0, abs(t)) or counts[1] + counts[2] > max_steps:
                state[2] = t
                return 2 if np.isfinite(err) else 1
            continue
        if switching and h_to_crossing == 0.0:
            # a step that carries u_v across zero is taken again, to end there
            h_to_crossing = _to_crossing(t, h, tiny, y, yn, K, F, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin,
                                         counts)
            if h_to_crossing > 0.0:
                continue
        h_to_crossing = 0.0
        if counts[0] < out.shape[0] and counts[0] * dt < t_new - 1e-9 * dt:
            counts[0] = _dense_samples(t, h, t_new, y, yn, K, F, yy, ys, sg, ctrl, kp, u_hold, u_limit, prm, mode,
                                       lin, dt, out, counts[0])
            counts[3] += 3
        counts[1] += 1
        fac = 10.0 if err == 0.0 else min(10.0, 0.9 * err ** (-1.0 / 8.0))
        if rejected:            # no growth right after a rejection (Hairer's DOP853)
            fac = min(fac, 1.0)
            rejected = False
        h_prop = max(h_prop, h * fac) if cut else h * fac
        t = t_new
        moved = _project(yn, prm) if bounded else False
        for r in range(N_STATES):
            y[r] = yn[r]
        if not _finite(y):
            state[2] = t
            return 1
        if moved:
            # a bound held the state: the derivative at the end is that of the held state
            _stage(t, y, sg, ctrl, kp, u_hold, u_limit, prm, mode, lin, K[0])
            counts[3] += 1
        else:
            for r in range(N_STATES):
                K[0, r] = K[_N_STAGES, r]
        if counts[1] + counts[2] > max_steps:
            state[2] = t
            return 2
        if counts[1] + counts[2] >= pause_at and tb - t > tiny:
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
    """:func:`eha_core._kernels.integrate_segments` for the six states (``y``, ``scale``: 6): the same
    arguments, pauses and results. The steps do not stop where the command changes sign: the valve's
    branches follow the spool's position, a state."""
    work = np.empty((27, N_STATES))
    u_hold = state[1]
    s0 = counts[4]
    resume = np.isfinite(state[3])
    for s in range(s0, n_seg):
        ta = seg_t[s]
        sg = _segment_inputs(s, seg_t, seg_u, seg_d, seg_r, sm_u, sm_d, sm_r, n_sm)
        if resume and s == s0:
            ta = state[3]
        else:
            if ctrl == ZOH and seg_ctrl[s]:
                u_hold = _control(kp, _sig_r(sg, ta), y[0], u_limit)
            counts[0] = _samples_at(ta, y, sg, ctrl, kp, u_hold, u_limit, dt, out, counts[0])
            if state[0] <= 0.0:
                state[0] = seg_t[s + 1] - ta
        st = _integrate_segment(y, work, ta, seg_t[s + 1], sg, prm, mode, lin, ctrl, kp, u_hold, u_limit, tol,
                                scale, dt, h_max, out, state, counts, max_steps, pause_at)
        if st == PAUSED:
            counts[4] = s
            state[1] = u_hold
            return st
        if st >= 0:
            return st
    state[3] = np.nan
    counts[4] = 0
    s = n_seg - 1
    tb = seg_t[n_seg]
    sg = _segment_inputs(s, seg_t, seg_u, seg_d, seg_r, sm_u, sm_d, sm_r, n_sm)
    if final and ctrl == ZOH and seg_ctrl[n_seg]:
        u_hold = _control(kp, _sig_r(sg, tb), y[0], u_limit)
    if final:
        counts[0] = _samples_at(tb, y, sg, ctrl, kp, u_hold, u_limit, dt, out, counts[0])
    state[1] = u_hold
    return -1
