"""The nonlinear actuator dynamics (eqs. 1-4, 6-8), one implementation, with bounds.

:func:`derivatives` is written as plain scalar Python on a packed parameter
vector so that the *same source* runs interpreted (checks, the reference
solver, the python-control peer in the benchmark) and compiled by numba
(:mod:`eha_core._kernels`, used by every simulation).

States xi = [x, v, p1, p2] (SI units), input u [V], load disturbance d [N].

The structural variants of :mod:`eha_core.variants` (docs/model.md §6) are
read from the packed vector's tail and are off for the paper's model:
internal leakage and Stribeck friction are terms of :func:`derivatives`; with
the valve's spool dynamics on, the orifices see the spool's position ``u_v``
(the valve's effective command, in volts) instead of ``u``, and
:func:`spool_derivatives` gives the two more states ``[u_v, du_v/dt]``.

Physical bounds are part of the model (docs/model.md §1):

* the pressure drop under each square root is clipped at zero;
* pr <= p1, p2 <= ps: at a bound a pressure does not move further outward;
* end stops |x| <= 0.8 L0: at a stop the piston stays put until the net force
  pulls it back. The impact itself (velocity set to zero) is applied by
  :func:`project_state` after each integration step.

Examples
--------
>>> from eha_core.params import ActuatorParams
>>> from eha_core.model import rhs
>>> p = ActuatorParams()
>>> rhs(p.initial_state, 0.0, 0.0, p)       # the operating point is an equilibrium
array([0., 0., 0., 0.])
"""

from __future__ import annotations

import math

import numpy as np

from ._checks import not_allowed
from .param_table import PACKED
from .params import ActuatorParams
from .variants import EFFECT_FIELDS

__all__ = ["pack_params", "derivatives", "spool_derivatives", "project_state", "rhs", "PARAM_INDEX",
           "N_PACKED_PARAMS"]

#: Layout of the packed parameter vector used by the compiled code: the paper's parameters
#: (eha_core.param_table.PACKED), then the effects' (eha_core.variants.EFFECT_FIELDS, all off for the
#: paper's model); :func:`derivatives`, :func:`spool_derivatives` and :func:`project_state` read it by
#: these indices.
PARAM_INDEX = {name: i for i, name in enumerate(PACKED + EFFECT_FIELDS)}
#: Length of the packed parameter vector.
N_PACKED_PARAMS = len(PARAM_INDEX)


def pack_params(params: ActuatorParams) -> np.ndarray:
    """Pack the parameters ``params`` (fields and derived A1, A2, x_max, SI, then the effects' values)
    into the float vector :func:`derivatives` reads, in the order of :data:`PARAM_INDEX`."""
    return np.array([getattr(params, name) for name in PACKED] + list(params.effects.packed()), dtype=np.float64)


def derivatives(x, v, p1, p2, u, d, prm):
    """Time derivatives (dx, dv, dp1, dp2) of the nonlinear model.

    Parameters
    ----------
    x, v, p1, p2 : float
        Position [m], velocity [m/s], piston- and rod-chamber pressure [Pa].
    u : float
        Valve command [V]: the command itself, or the spool's position ``u_v`` when the spool
        dynamics are on (eq. V1, :func:`spool_derivatives`).
    d : float
        Load disturbance [N]; the constant part ``d0`` of the parameters is added.
    prm : ndarray
        Packed parameters, see :func:`pack_params`.
    """
    M = prm[0]
    B = prm[1]
    Af = prm[2]
    beta_e = prm[3]
    A1 = prm[4]
    A2 = prm[5]
    L0 = prm[6]
    Kq1 = prm[7]
    Kq2 = prm[8]
    ps = prm[9]
    pr = prm[10]
    k_f = prm[11]
    x_max = prm[12]
    d0 = prm[13]
    C_L = prm[16]
    F_c = prm[17]
    F_s = prm[18]
    v_s = prm[19]
    v_eps = prm[20]

    # eq. 3: the orifices switch with the sign of the valve command
    if u >= 0.0:
        dp_1 = ps - p1
        dp_2 = p2 - pr
    else:
        dp_1 = p1 - pr
        dp_2 = ps - p2
    # a pressure difference under a square root never goes negative
    if dp_1 < 0.0:
        dp_1 = 0.0
    if dp_2 < 0.0:
        dp_2 = 0.0
    q1 = Kq1 * u * math.sqrt(dp_1)
    q2 = Kq2 * u * math.sqrt(dp_2)

    # eq. 1a with S(v) = (2/pi) atan(k_f v) (eq. 2)
    friction = B * v + Af * (2.0 / math.pi) * math.atan(k_f * v)
    if F_s != 0.0 or F_c != 0.0:
        # eq. V3: the Stribeck term, static level F_s decaying to F_c over v_s (off: the paper's, exactly)
        r = v / v_s
        friction += (F_c + (F_s - F_c) * math.exp(-r * r)) * math.tanh(v / v_eps)
    acc = (A1 * p1 - A2 * p2 - friction - d - d0) / M
    vel = v
    # end stops: the piston does not pass them and stays until pulled back
    if x >= x_max:
        if vel > 0.0:
            vel = 0.0
        if v >= 0.0 and acc > 0.0:
            acc = 0.0
    elif x <= -x_max:
        if vel < 0.0:
            vel = 0.0
        if v <= 0.0 and acc < 0.0:
            acc = 0.0

    # eqs. 1b-1c / 4b-4c: chamber volumes V1 = A1 (L0 + x), V2 = A2 (L0 - x);
    # the volume changes with the piston's actual motion (zero at a stop)
    net1 = q1 - A1 * vel
    net2 = A2 * vel - q2
    if C_L != 0.0:
        # eq. V2: laminar leakage past the piston, out of chamber 1 and into chamber 2 (off: the paper's, exactly)
        q_leak = C_L * (p1 - p2)
        net1 -= q_leak
        net2 += q_leak
    dp1 = beta_e / (A1 * (L0 + x)) * net1
    dp2 = beta_e / (A2 * (L0 - x)) * net2
    # pressures stay within [pr, ps]
    if (p1 >= ps and dp1 > 0.0) or (p1 <= pr and dp1 < 0.0):
        dp1 = 0.0
    if (p2 >= ps and dp2 > 0.0) or (p2 <= pr and dp2 < 0.0):
        dp2 = 0.0
    return vel, acc, dp1, dp2


def spool_derivatives(u_v, u_v_rate, u, prm):
    """Time derivatives (du_v/dt, d2u_v/dt2) of the valve's spool (eq. V1): its position ``u_v`` follows the
    command ``u`` through ``omega_v^2 / (s^2 + 2 zeta_v omega_v s + omega_v^2)`` (s: Laplace's variable).

    Parameters
    ----------
    u_v, u_v_rate : float
        The spool's position as the valve's effective command [V], and its rate [V/s].
    u : float
        Valve command [V].
    prm : ndarray
        Packed parameters, see :func:`pack_params` (``omega_v`` > 0: the spool is on).
    """
    omega_v = prm[14]
    zeta_v = prm[15]
    return u_v_rate, omega_v * omega_v * (u - u_v) - 2.0 * zeta_v * omega_v * u_v_rate


def project_state(x, v, p1, p2, prm):
    """Enforce the bounds on a state after an integration step.

    Returns the state clipped to the end stops (an inelastic impact: the
    velocity towards the stop becomes zero) and to the pressure range [pr, ps].

    Parameters
    ----------
    x, v, p1, p2 : float
        Position [m], velocity [m/s], piston- and rod-chamber pressure [Pa].
    prm : ndarray
        Packed parameters, see :func:`pack_params`.
    """
    x_max = prm[12]
    ps = prm[9]
    pr = prm[10]
    if x > x_max:
        x = x_max
        if v > 0.0:
            v = 0.0
    elif x < -x_max:
        x = -x_max
        if v < 0.0:
            v = 0.0
    if p1 > ps:
        p1 = ps
    elif p1 < pr:
        p1 = pr
    if p2 > ps:
        p2 = ps
    elif p2 < pr:
        p2 = pr
    return x, v, p1, p2


def rhs(state, u: float, d: float, params: ActuatorParams | np.ndarray) -> np.ndarray:
    """Vector form of :func:`derivatives` for analysis (interpreted, not for speed).

    Parameters
    ----------
    state : array of 4, or of 6 with the spool
        The state [x, v, p1, p2] (m, m/s, Pa, Pa); with the valve's spool dynamics on (eq. V1),
        [x, v, p1, p2, u_v, du_v/dt] (and V, V/s).
    u : float
        Valve command [V].
    d : float
        Load disturbance [N]; the constant part ``d0`` of the parameters is added.
    params : ActuatorParams or ndarray
        The parameters, or their packed vector (:func:`pack_params`).
    """
    prm = pack_params(params) if isinstance(params, ActuatorParams) else np.asarray(params, dtype=float)
    state = np.asarray(state, dtype=float).ravel()
    spool = prm.size > PARAM_INDEX["omega_v"] and prm[PARAM_INDEX["omega_v"]] > 0.0
    if state.size != (6 if spool else 4):
        raise not_allowed("state", state, "give [x, v, p1, p2, u_v, du_v/dt] (the valve's spool dynamics are on)"
                          if spool else "give [x, v, p1, p2] (the valve's spool dynamics are off)")
    x, v, p1, p2 = (float(s) for s in state[:4])
    if not spool:
        return np.array(derivatives(x, v, p1, p2, float(u), float(d), prm))
    u_v, u_v_rate = float(state[4]), float(state[5])
    # the orifices see the spool's position (eq. V1 into eq. 3)
    return np.array([*derivatives(x, v, p1, p2, u_v, float(d), prm), *spool_derivatives(u_v, u_v_rate, float(u), prm)])
