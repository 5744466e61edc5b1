"""Operating point and linearisation (eqs. 9-14, 20-24 and the appendix).

The valve makes the linear model piecewise: l5 and l6 depend on the sign of u
(eq. 13), so the linearised model has two branches. Simulations switch between
them by default (as the paper's Figs. 3-7); transfer functions use the u >= 0
branch (eqs. 21-24) unless asked otherwise.

The structural variants (:mod:`eha_core.variants`, docs/model.md §6) change
the linear model: Stribeck friction adds its slope at v = 0 to l1; internal
leakage couples the chambers' pressures, and the piston is held still only
with the valve open enough to feed the leak (the operating point has
u_e != 0); the spool's dynamics add two states [u_v, du_v/dt], the valve's branch
then following the sign of u_v. For the paper's model (every effect off) the
formulas are the paper's own, to the bit.

Examples
--------
>>> from eha_core.params import ActuatorParams
>>> from eha_core.linear import linearize
>>> lin = linearize(ActuatorParams())
>>> num, den = lin.tf_coeffs()
>>> print(f"{num[-1]:.1f} / (s^3 + {den[1]:.1f} s^2 + {den[2]:.4g} s + {den[3]:g})")
243.7 / (s^3 + 430.1 s^2 + 1.721e+04 s + 0)
>>> num, den = lin.closed_loop_coeffs(kp=10.0)
>>> print(f"{num[-1]:.0f} / (s^3 + {den[1]:.1f} s^2 + {den[2]:.4g} s + {den[3]:.0f})")
2437 / (s^3 + 430.1 s^2 + 1.721e+04 s + 2437)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ._checks import not_allowed, positive_number
from .params import ActuatorParams, ParameterError

__all__ = ["OperatingPoint", "LinearModel", "operating_point", "linearize", "VALVE_BRANCHES", "PACKED_LINEAR",
           "N_PACKED_LINEAR", "PACKED_LINEAR_SPOOL", "N_PACKED_LINEAR_SPOOL"]

#: Branch names of the piecewise-linear model.
#: The valve's two linearisations: u >= 0 ('positive') and u < 0 ('negative'), eq. 13.
VALVE_BRANCHES = ("positive", "negative")


@dataclass(frozen=True)
class OperatingPoint:
    """Equilibrium of the nonlinear model: v = 0, u = 0, forces balanced (eqs. 9-10).

    With internal leakage (eq. V2) the valve feeds the leak: ``u`` is then the command that holds
    the piston still (and, with the spool's dynamics, the spool rests at u_v = u).
    """

    x: float
    v: float
    p1: float
    p2: float
    u: float = 0.0

    @property
    def state(self) -> np.ndarray:
        """[x, v, p1, p2] as a new array."""
        return np.array([self.x, self.v, self.p1, self.p2])

    def to_dict(self) -> dict[str, float]:
        """The point as plain numbers by name (SI): x, v, p1, p2, u."""
        return {"x": self.x, "v": self.v, "p1": self.p1, "p2": self.p2, "u": self.u}


def operating_point(params: ActuatorParams, x_e: float = 0.0, p1_e: float | None = None) -> OperatingPoint:
    """The working point of eq. 10.

    Any position is an equilibrium when u = 0 and the forces balance, so the
    point is chosen: x_e = 0 (docs/model.md §3) and p1_e = the initial
    piston-chamber pressure p1_0 unless given; p2_e = (A1 p1_e - d0) / A2.

    With internal leakage (eq. V2) only one pair of pressures holds still: the
    one where the valve's flows into and out of the chambers equal the leak
    (docs/model.md §6.2), with the command ``u_e`` that opens the valve that
    much; ``p1_e`` cannot then be chosen.

    Parameters
    ----------
    params : ActuatorParams
        The actuator.
    x_e : float
        The piston's position at the point [m], within the end stops.
    p1_e : float, optional
        The piston-chamber pressure at the point [Pa], within [pr, ps]; default ``params.p1_0``
        (not with internal leakage).
    """
    if abs(x_e) > params.x_max:
        raise ParameterError("x_e", x_e, f"must lie within the end stops +-{params.x_max:.6g} m")
    if params.effects.leakage:
        if p1_e is not None:
            raise ParameterError("p1_e", p1_e, "with internal leakage (C_L > 0) the pressures that hold the piston "
                                               "still are set by the valve's flows feeding the leak; leave p1_e out")
        return _leakage_point(params, float(x_e))
    p1 = params.p1_0 if p1_e is None else float(p1_e)
    if not params.pr <= p1 <= params.ps:
        raise ParameterError("p1_e", p1, f"must lie within [pr, ps] = [{params.pr:.6g}, {params.ps:.6g}] Pa")
    p2 = (params.A1 * p1 - params.d0) / params.A2
    if not params.pr <= p2 <= params.ps:
        raise ParameterError("p2_e", p2, "the force balance (A1 p1_e - d0)/A2 must lie within [pr, ps] = "
                             f"[{params.pr:.6g}, {params.ps:.6g}] Pa")
    return OperatingPoint(x=float(x_e), v=0.0, p1=p1, p2=p2)


def _leakage_point(params: ActuatorParams, x_e: float) -> OperatingPoint:
    """The equilibrium with internal leakage (docs/model.md §6.2): force balance A1 p1 - A2 p2 = d0
    (eq. 10) and the valve's flows equal to the leak, Q1 = Q_L = Q2 (eqs. 3, V2). The flows' ratio
    fixes the pressures, linear in p1 on each branch of the valve (eq. 3); the leak's size fixes u_e."""
    p = params
    k1, k2, ratio = p.Kq1 * p.Kq1, p.Kq2 * p.Kq2, p.A1 / p.A2
    shift = k2 * p.d0 / p.A2

    def p2_of(p1):
        return (p.A1 * p1 - p.d0) / p.A2

    # u < 0 (leak from chamber 2 to 1): Kq1^2 (p1 - pr) = Kq2^2 (ps - p2)
    p1 = (k2 * p.ps + k1 * p.pr + shift) / (k1 + k2 * ratio)
    if p1 - p2_of(p1) < 0.0:
        u_e = p.effects.C_L * (p1 - p2_of(p1)) / (p.Kq1 * math.sqrt(p1 - p.pr))
    else:
        # u > 0 (leak from chamber 1 to 2): Kq1^2 (ps - p1) = Kq2^2 (p2 - pr)
        p1 = (k1 * p.ps + k2 * p.pr + shift) / (k1 + k2 * ratio)
        if p1 - p2_of(p1) > 0.0:
            u_e = p.effects.C_L * (p1 - p2_of(p1)) / (p.Kq1 * math.sqrt(p.ps - p1))
        else:
            # no pressure difference, no leak: the valve closed
            p1, u_e = p.d0 / (p.A1 - p.A2), 0.0
    p2 = p2_of(p1)
    for name, value in (("p1_e", p1), ("p2_e", p2)):
        if not (p.pr <= value <= p.ps and math.isfinite(u_e)):
            raise ParameterError(name, value, "with internal leakage the pressures that hold the piston still "
                                 f"must lie within [pr, ps] = [{p.pr:.6g}, {p.ps:.6g}] Pa; change d0")
    return OperatingPoint(x=x_e, v=0.0, p1=float(p1), p2=float(p2), u=float(u_e))


#: Layout of :meth:`LinearModel.packed`, the vector the compiled integrator
#: reads: A row by row, B for u >= 0, B for u < 0, E, the operating point's state, and the valve's
#: offset B(sign u_e) u_e (zero unless the point holds with u_e != 0: internal leakage).
PACKED_LINEAR = {"A": slice(0, 16), "B_positive": slice(16, 20), "B_negative": slice(20, 24),
                 "E": slice(24, 28), "state": slice(28, 32), "offset": slice(32, 36)}
N_PACKED_LINEAR = 36
#: The same with the spool's dynamics (six states): A without the valve's column of the chambers
#: (``A_core``), that column for u_v >= 0 and u_v < 0 (``b_positive``, ``b_negative``), the input B, E, the
#: operating point's state and the offset b(sign u_e) u_e + B u_e (the spool rests at u_v = u_e).
PACKED_LINEAR_SPOOL = {"A_core": slice(0, 36), "b_positive": slice(36, 42), "b_negative": slice(42, 48),
                       "B": slice(48, 54), "E": slice(54, 60), "state": slice(60, 66), "offset": slice(66, 72)}
N_PACKED_LINEAR_SPOOL = 72
#: The states of the linear model with the spool's dynamics.
_SPOOL_STATES = ("dx", "dv", "dp1", "dp2", "du_v", "du_v_rate")


@dataclass(frozen=True)
class LinearModel:
    """The linearised model d(dxi)/dt = A dxi + B(sign u) du + E d (eqs. 11-13).

    ``lambdas`` are l1..l6 of Table 2 for the u >= 0 branch, ``lambdas_negative``
    the same with l5, l6 of the u < 0 branch. Away from x_e = 0 the two chambers
    see different stiffness, beta_e/(L0 + x_e) and beta_e/(L0 - x_e); l4 is the
    first and ``l4_rod`` the second (equal at x_e = 0, where Table 2 holds).

    With the spool's dynamics on (docs/model.md §6.1) the model has six states
    (``states``), the valve's branch follows the sign of the spool's position
    u_v: ``A`` is the matrix for u_v >= 0 and ``A_negative`` for u_v < 0, and B (the
    same on both branches) drives the spool.
    """

    params: ActuatorParams
    op: OperatingPoint
    lambdas: tuple[float, float, float, float, float, float]
    lambdas_negative: tuple[float, float, float, float, float, float]
    l4_rod: float
    A: np.ndarray = field(repr=False)
    B_positive: np.ndarray = field(repr=False)
    B_negative: np.ndarray = field(repr=False)
    E: np.ndarray = field(repr=False)
    A_negative: np.ndarray | None = field(default=None, repr=False)
    states: tuple[str, ...] = ("dx", "dv", "dp1", "dp2")

    @property
    def friction_damping(self) -> float:
        """2 k_f Af / pi [N s/m]: the friction's slope at v = 0, part of l1 M (Table 2); with Stribeck
        friction (eq. V3) its slope F_s / v_eps too."""
        p = self.params
        slope = 2.0 * p.k_f * p.Af / math.pi
        if p.effects.stribeck:
            slope += p.effects.F_s / p.effects.v_eps
        return slope

    @property
    def n_states(self) -> int:
        """The number of states: 4, or 6 with the spool's dynamics."""
        return len(self.states)

    def state_matrix(self, branch: str = "positive") -> np.ndarray:
        """The matrix A of the valve's ``branch`` (``'positive'``: u (or the spool's u_v) >= 0,
        ``'negative'``: < 0); the same on both without the spool's dynamics."""
        _check_branch(branch)
        return (self.A if branch == "positive" or self.A_negative is None else self.A_negative).copy()

    def gain(self, branch: str = "positive") -> float:
        """The numerator of P(s) (eq. 23), l5 l2 + l6 l3, for the valve's ``branch`` (``'positive'``:
        u >= 0, ``'negative'``: u < 0). With structural effects the same l5 l2 + l6 l3, the valve's gain
        into the piston's acceleration, which is then no longer P(s)'s whole numerator."""
        if not self.params.effects.off:
            _check_branch(branch)
            _, l2, l3, _, l5, l6 = self.lambdas if branch == "positive" else self.lambdas_negative
            return float(l5 * l2 + l6 * l3)
        return float(self.tf_coeffs(branch)[0][-1])

    def B(self, branch: str = "positive") -> np.ndarray:
        """Input vector of the valve's ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        _check_branch(branch)
        return (self.B_positive if branch == "positive" else self.B_negative).copy()

    # -- transfer functions as coefficient arrays (no python-control needed) --
    def tf_coeffs(self, branch: str = "positive") -> tuple[np.ndarray, np.ndarray]:
        """P(s) = X(s)/U(s) (eq. 21) as (num, den), descending powers of s, for the valve's
        ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        _check_branch(branch)
        if not self.params.effects.off:
            return self._tf_with_effects(branch)
        l1, l2, l3, l4, l5, l6 = self.lambdas if branch == "positive" else self.lambdas_negative
        gain = l5 * l2 + l6 * l3
        return np.array([gain]), np.array([1.0, l1, l2 * l4 + l3 * self.l4_rod, 0.0])

    def _tf_with_effects(self, branch: str) -> tuple[np.ndarray, np.ndarray]:
        """P(s) of the model with effects, as polynomials (exact, no eigenvalues): the chambers
        (2 x 2) solved for P1, P2, the force balance for V, X = V/s, and the spool's second order."""
        A = self.state_matrix(branch)
        a22, a23, a32, a33 = A[2, 2], A[2, 3], A[3, 2], A[3, 3]
        l4, l4r = -A[2, 1], A[3, 1]
        c5, c6 = (A[2, 4], -A[3, 4]) if self.n_states == 6 else (self.B(branch)[2], -self.B(branch)[3])
        p = self.params
        M, A1, A2 = p.M, p.A1, p.A2
        cf = -A[1, 1] * M
        delta = np.array([1.0, -(a22 + a33), a22 * a33 - a23 * a32])          # (s - a22)(s - a33) - a23 a32
        # (M s + cf) delta V = A1 P1 delta - A2 P2 delta, with the chambers' equations solved by Cramer's rule
        den_v = np.polyadd(np.polymul([M, cf], delta),
                           np.polyadd(A1 * l4 * np.array([1.0, -a33]) - np.array([0.0, A1 * a23 * l4r]),
                                      A2 * l4r * np.array([1.0, -a22]) - np.array([0.0, A2 * a32 * l4])))
        num_v = np.polyadd(A1 * c5 * np.array([1.0, -a33]) - np.array([0.0, A1 * a23 * c6]),
                           A2 * c6 * np.array([1.0, -a22]) - np.array([0.0, A2 * a32 * c5]))
        if den_v[-1] == 0.0 and num_v[-1] == 0.0:
            # no coupling of the chambers (no leak, valve closed at the point): the pressures' common
            # mode cancels, as in the paper's third-order P(s) (eq. 23)
            den_v, num_v = den_v[:-1], num_v[:-1]
        num, den = num_v / den_v[0], np.polymul(den_v / den_v[0], [1.0, 0.0])      # X = V / s
        if self.n_states == 6:
            e = p.effects
            num = num * (e.omega_v * e.omega_v)
            den = np.polymul(den, [1.0, 2.0 * e.zeta_v * e.omega_v, e.omega_v * e.omega_v])
        return np.trim_zeros(np.atleast_1d(num), "f") if np.any(num) else np.array([0.0]), den

    def closed_loop_coeffs(self, kp: float, branch: str = "positive") -> tuple[np.ndarray, np.ndarray]:
        """H(s) = Kp P / (1 + Kp P) (eq. 22) as (num, den), for the proportional gain ``kp`` [V/m] and
        the valve's ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        kp = positive_number("kp", kp, "must be a finite gain > 0 V/m")
        num, den = self.tf_coeffs(branch)
        den = den.copy()
        if num.size == 1:
            den[-1] += kp * num[-1]
        else:
            den[-num.size:] += kp * num
        return kp * num, den

    def poles(self, branch: str = "positive") -> np.ndarray:
        """Poles of P(s) [rad/s] for the valve's ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        return np.roots(self.tf_coeffs(branch)[1])

    def closed_loop_poles(self, kp: float, branch: str = "positive") -> np.ndarray:
        """Poles of H(s) [rad/s] for the proportional gain ``kp`` [V/m] and the valve's
        ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        return np.roots(self.closed_loop_coeffs(kp, branch)[1])

    @property
    def op_state(self) -> np.ndarray:
        """The operating point's state, of :attr:`n_states` (the spool at rest at u_v = u_e)."""
        if self.n_states == 6:
            return np.array([self.op.x, self.op.v, self.op.p1, self.op.p2, self.op.u, 0.0])
        return self.op.state

    def packed(self) -> np.ndarray:
        """The model as the float vector the compiled integrator reads (:data:`PACKED_LINEAR`; with the
        spool's dynamics :data:`PACKED_LINEAR_SPOOL`)."""
        u_e = self.op.u
        if self.n_states == 4:
            # the paper's model is linearised about u = 0 (eq. 10): no offset (exact zeros, not B * 0)
            held = u_e != 0.0 and not self.params.effects.off
            offset = (self.B_positive if u_e >= 0.0 else self.B_negative) * u_e if held else np.zeros(4)
            return np.concatenate([self.A.ravel(), self.B_positive, self.B_negative, self.E, self.op.state, offset])
        b_pos, b_neg = np.zeros(6), np.zeros(6)
        b_pos[2:4], b_neg[2:4] = self.A[2:4, 4], self.A_negative[2:4, 4]
        core = self.A.copy()
        core[2:4, 4] = 0.0
        offset = (b_pos if u_e >= 0.0 else b_neg) * u_e + self.B_positive * u_e
        return np.concatenate([core.ravel(), b_pos, b_neg, self.B_positive, self.E, self.op_state, offset])

    def to_dict(self, kp: float = 10.0) -> dict:
        """Everything of the linearisation as plain numbers (JSON-ready); H(s) for ``kp``."""
        num, den = self.tf_coeffs()
        cnum, cden = self.closed_loop_coeffs(kp)

        def pairs(values):
            return [[float(v.real), float(v.imag)] for v in values]

        out = {
            "operating_point": self.op.to_dict(),
            "lambdas": list(self.lambdas),
            "lambdas_negative_branch": list(self.lambdas_negative),
            "A": self.A.tolist(),
            "B": self.B_positive.tolist(),
            "B_negative_branch": self.B_negative.tolist(),
            "E": self.E.tolist(),
            "tf": {"num": num.tolist(), "den": den.tolist()},
            "closed_loop_tf": {"num": cnum.tolist(), "den": cden.tolist(), "kp": kp},
            "poles": pairs(self.poles()),
            "closed_loop_poles": pairs(self.closed_loop_poles(kp)),
        }
        if not self.params.effects.off:
            out["effects"] = self.params.effects.to_dict()
            out["states"] = list(self.states)
            if self.A_negative is not None:
                out["A_negative_branch"] = self.A_negative.tolist()
        return out

    # -- python-control interchange types --------------------------------------
    def tf(self, branch: str = "positive"):
        """P(s) as a :class:`control.TransferFunction` (input u, output x), for the valve's
        ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        import control

        num, den = self.tf_coeffs(branch)
        return control.tf(num, den, inputs="u", outputs="x")

    def closed_loop_tf(self, kp: float, branch: str = "positive"):
        """H(s) as a :class:`control.TransferFunction` (input r, output x), for the proportional gain
        ``kp`` [V/m] and the valve's ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        import control

        num, den = self.closed_loop_coeffs(kp, branch)
        return control.tf(num, den, inputs="r", outputs="x")

    def ss(self, branch: str = "positive"):
        """The state-space model as a :class:`control.StateSpace`, for the valve's
        ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0).

        Inputs [u, d], outputs the state deviations (C = I, D = 0): four, or six with the spool.
        """
        import control

        n = self.n_states
        b = np.column_stack([self.B(branch), self.E])
        return control.ss(self.state_matrix(branch), b, np.eye(n), np.zeros((n, 2)),
                          inputs=["u", "d"], outputs=list(self.states), states=list(self.states))


def linearize(params: ActuatorParams, op: OperatingPoint | None = None) -> LinearModel:
    """Linearise the nonlinear model at an operating point (appendix, eqs. 28-37).

    The A matrix is the Jacobian of :func:`eha_core.model.derivatives` with
    respect to the state at ``op``; B is its one-sided derivative with respect
    to u on each side of u = 0. With structural effects (``params.effects``,
    docs/model.md §6) the same Jacobian of the model with them.

    Parameters
    ----------
    params : ActuatorParams
        The actuator.
    op : OperatingPoint, optional
        The point linearised at; default :func:`operating_point`'s.
    """
    op = op if op is not None else operating_point(params)
    if not params.effects.off:
        return _linearize_with_effects(params, op)
    p = params
    l1 = (p.B + 2.0 * p.k_f * p.Af / math.pi) / p.M
    l2 = p.A1 / p.M
    l3 = p.A2 / p.M
    l4 = p.beta_e / (p.L0 + op.x)
    l4_rod = p.beta_e / (p.L0 - op.x)
    # eq. 13: pressure drops across the active orifices on each side of u = 0
    d3_pos, d4_pos = p.ps - op.p1, op.p2 - p.pr
    d3_neg, d4_neg = op.p1 - p.pr, p.ps - op.p2
    k1 = p.beta_e * p.Kq1 / (p.A1 * (p.L0 + op.x))
    k2 = p.beta_e * p.Kq2 / (p.A2 * (p.L0 - op.x))
    l5, l6 = k1 * math.sqrt(max(d3_pos, 0.0)), k2 * math.sqrt(max(d4_pos, 0.0))
    l5n, l6n = k1 * math.sqrt(max(d3_neg, 0.0)), k2 * math.sqrt(max(d4_neg, 0.0))

    A = np.array([
        [0.0, 1.0, 0.0, 0.0],
        [0.0, -l1, l2, -l3],
        [0.0, -l4, 0.0, 0.0],
        [0.0, l4_rod, 0.0, 0.0],
    ])
    E = np.array([0.0, -1.0 / p.M, 0.0, 0.0])
    return LinearModel(
        params=p, op=op,
        lambdas=(l1, l2, l3, l4, l5, l6),
        lambdas_negative=(l1, l2, l3, l4, l5n, l6n),
        l4_rod=l4_rod,
        A=A,
        B_positive=np.array([0.0, 0.0, l5, -l6]),
        B_negative=np.array([0.0, 0.0, l5n, -l6n]),
        E=E,
    )


def _linearize_with_effects(p: ActuatorParams, op: OperatingPoint) -> LinearModel:
    """The Jacobian of the model with its effects (docs/model.md §6) at an equilibrium ``op``."""
    e = p.effects
    V1, V2 = p.A1 * (p.L0 + op.x), p.A2 * (p.L0 - op.x)
    # eq. V3: the Stribeck term's slope at v = 0 is F_s / v_eps (tanh's), its exponential's is zero
    l1 = (p.B + 2.0 * p.k_f * p.Af / math.pi + (e.F_s / e.v_eps if e.stribeck else 0.0)) / p.M
    l2, l3 = p.A1 / p.M, p.A2 / p.M
    l4, l4_rod = p.beta_e / (p.L0 + op.x), p.beta_e / (p.L0 - op.x)
    # eq. 13 at the point's pressures, the valve's command on each side of zero
    k1, k2 = p.beta_e * p.Kq1 / V1, p.beta_e * p.Kq2 / V2
    l5, l6 = k1 * math.sqrt(max(p.ps - op.p1, 0.0)), k2 * math.sqrt(max(op.p2 - p.pr, 0.0))
    l5n, l6n = k1 * math.sqrt(max(op.p1 - p.pr, 0.0)), k2 * math.sqrt(max(p.ps - op.p2, 0.0))
    # the flows' slopes in the pressures at a point held with the valve open (u_e != 0, leakage)
    u_e = op.u
    dq1, dq2 = 0.0, 0.0
    if u_e > 0.0:
        dq1, dq2 = -p.Kq1 * u_e / (2.0 * math.sqrt(p.ps - op.p1)), p.Kq2 * u_e / (2.0 * math.sqrt(op.p2 - p.pr))
    elif u_e < 0.0:
        dq1, dq2 = p.Kq1 * u_e / (2.0 * math.sqrt(op.p1 - p.pr)), -p.Kq2 * u_e / (2.0 * math.sqrt(p.ps - op.p2))
    c_l = e.C_L
    core = np.array([
        [0.0, 1.0, 0.0, 0.0],
        [0.0, -l1, l2, -l3],
        [0.0, -l4, p.beta_e / V1 * (dq1 - c_l), p.beta_e / V1 * c_l],        # eqs. 1b, V2
        [0.0, l4_rod, p.beta_e / V2 * c_l, p.beta_e / V2 * (-dq2 - c_l)],    # eqs. 1c, V2
    ])
    b_pos, b_neg = np.array([0.0, 0.0, l5, -l6]), np.array([0.0, 0.0, l5n, -l6n])
    lambdas, lambdas_negative = (l1, l2, l3, l4, l5, l6), (l1, l2, l3, l4, l5n, l6n)
    if not e.spool:
        return LinearModel(params=p, op=op, lambdas=lambdas, lambdas_negative=lambdas_negative, l4_rod=l4_rod,
                           A=core, B_positive=b_pos, B_negative=b_neg, E=np.array([0.0, -1.0 / p.M, 0.0, 0.0]))
    # eq. V1: the orifices see the spool's position u_v, which the command drives through a second order
    w2 = e.omega_v * e.omega_v
    matrices = []
    for b in (b_pos, b_neg):
        A = np.zeros((6, 6))
        A[:4, :4] = core
        A[:4, 4] = b
        A[4, 5] = 1.0
        A[5, 4], A[5, 5] = -w2, -2.0 * e.zeta_v * e.omega_v
        matrices.append(A)
    B = np.array([0.0, 0.0, 0.0, 0.0, 0.0, w2])
    return LinearModel(params=p, op=op, lambdas=lambdas, lambdas_negative=lambdas_negative, l4_rod=l4_rod,
                       A=matrices[0], B_positive=B, B_negative=B.copy(),
                       E=np.array([0.0, -1.0 / p.M, 0.0, 0.0, 0.0, 0.0]), A_negative=matrices[1],
                       states=_SPOOL_STATES)


def _check_branch(branch: str) -> None:
    if branch not in VALVE_BRANCHES:
        raise not_allowed("branch", branch, f"use one of {', '.join(VALVE_BRANCHES)}")
