"""Operating point and linearisation (eqs. 9-14, 20-24 and the appendix).

The valve makes the linear model piecewise: l5 and l6 depend on the sign of u
(eq. 13), so the linearised model has two branches. Simulations switch between
them by default (as the paper's Figs. 3-7); transfer functions use the u >= 0
branch (eqs. 21-24) unless asked otherwise.

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
           "N_PACKED_LINEAR"]

#: Branch names of the piecewise-linear model.
#: The valve's two linearisations: u >= 0 ('positive') and u < 0 ('negative'), eq. 13.
VALVE_BRANCHES = ("positive", "negative")


@dataclass(frozen=True)
class OperatingPoint:
    """Equilibrium of the nonlinear model: v = 0, u = 0, forces balanced (eqs. 9-10)."""

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

    Parameters
    ----------
    params : ActuatorParams
        The actuator.
    x_e : float
        The piston's position at the point [m], within the end stops.
    p1_e : float, optional
        The piston-chamber pressure at the point [Pa], within [pr, ps]; default ``params.p1_0``.
    """
    p1 = params.p1_0 if p1_e is None else float(p1_e)
    if abs(x_e) > params.x_max:
        raise ParameterError("x_e", x_e, f"must lie within the end stops +-{params.x_max:.6g} m")
    if not params.pr <= p1 <= params.ps:
        raise ParameterError("p1_e", p1, f"must lie within [pr, ps] = [{params.pr:.6g}, {params.ps:.6g}] Pa")
    p2 = (params.A1 * p1 - params.d0) / params.A2
    if not params.pr <= p2 <= params.ps:
        raise ParameterError("p2_e", p2, "the force balance (A1 p1_e - d0)/A2 must lie within [pr, ps] = "
                             f"[{params.pr:.6g}, {params.ps:.6g}] Pa")
    return OperatingPoint(x=float(x_e), v=0.0, p1=p1, p2=p2)


#: Layout of :meth:`LinearModel.packed`, the vector the compiled integrator
#: reads: A row by row, B for u >= 0, B for u < 0, E, the operating point's state.
PACKED_LINEAR = {"A": slice(0, 16), "B_positive": slice(16, 20), "B_negative": slice(20, 24),
                 "E": slice(24, 28), "state": slice(28, 32)}
N_PACKED_LINEAR = 32


@dataclass(frozen=True)
class LinearModel:
    """The linearised model d(dxi)/dt = A dxi + B(sign u) du + E d (eqs. 11-13).

    ``lambdas`` are l1..l6 of Table 2 for the u >= 0 branch, ``lambdas_negative``
    the same with l5, l6 of the u < 0 branch. Away from x_e = 0 the two chambers
    see different stiffness, beta_e/(L0 + x_e) and beta_e/(L0 - x_e); l4 is the
    first and ``l4_rod`` the second (equal at x_e = 0, where Table 2 holds).
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

    @property
    def friction_damping(self) -> float:
        """2 k_f Af / pi [N s/m]: the friction's slope at v = 0, part of l1 M (Table 2)."""
        p = self.params
        return 2.0 * p.k_f * p.Af / math.pi

    def gain(self, branch: str = "positive") -> float:
        """The numerator of P(s) (eq. 23), l5 l2 + l6 l3, for the valve's ``branch`` (``'positive'``:
        u >= 0, ``'negative'``: u < 0)."""
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
        l1, l2, l3, l4, l5, l6 = self.lambdas if branch == "positive" else self.lambdas_negative
        gain = l5 * l2 + l6 * l3
        return np.array([gain]), np.array([1.0, l1, l2 * l4 + l3 * self.l4_rod, 0.0])

    def closed_loop_coeffs(self, kp: float, branch: str = "positive") -> tuple[np.ndarray, np.ndarray]:
        """H(s) = Kp P / (1 + Kp P) (eq. 22) as (num, den), for the proportional gain ``kp`` [V/m] and
        the valve's ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        kp = positive_number("kp", kp, "must be a finite gain > 0 V/m")
        num, den = self.tf_coeffs(branch)
        den = den.copy()
        den[-1] += kp * num[-1]
        return kp * num, den

    def poles(self, branch: str = "positive") -> np.ndarray:
        """Poles of P(s) [rad/s] for the valve's ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        return np.roots(self.tf_coeffs(branch)[1])

    def closed_loop_poles(self, kp: float, branch: str = "positive") -> np.ndarray:
        """Poles of H(s) [rad/s] for the proportional gain ``kp`` [V/m] and the valve's
        ``branch`` (``'positive'``: u >= 0, ``'negative'``: u < 0)."""
        return np.roots(self.closed_loop_coeffs(kp, branch)[1])

    def packed(self) -> np.ndarray:
        """The model as the float vector the compiled integrator reads (:data:`PACKED_LINEAR`)."""
        return np.concatenate([self.A.ravel(), self.B_positive, self.B_negative, self.E, self.op.state])

    def to_dict(self, kp: float = 10.0) -> dict:
        """Everything of the linearisation as plain numbers (JSON-ready); H(s) for ``kp``."""
        num, den = self.tf_coeffs()
        cnum, cden = self.closed_loop_coeffs(kp)

        def pairs(values):
            return [[float(v.real), float(v.imag)] for v in values]

        return {
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

        Inputs [u, d], outputs the four state deviations (C = I4, D = 0).
        """
        import control

        b = np.column_stack([self.B(branch), self.E])
        return control.ss(self.A, b, np.eye(4), np.zeros((4, 2)),
                          inputs=["u", "d"], outputs=["dx", "dv", "dp1", "dp2"],
                          states=["dx", "dv", "dp1", "dp2"])


def linearize(params: ActuatorParams, op: OperatingPoint | None = None) -> LinearModel:
    """Linearise the nonlinear model at an operating point (appendix, eqs. 28-37).

    The A matrix is the Jacobian of :func:`eha_core.model.derivatives` with
    respect to the state at ``op``; B is its one-sided derivative with respect
    to u on each side of u = 0.

    Parameters
    ----------
    params : ActuatorParams
        The actuator.
    op : OperatingPoint, optional
        The point linearised at; default :func:`operating_point`'s.
    """
    op = op if op is not None else operating_point(params)
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


def _check_branch(branch: str) -> None:
    if branch not in VALVE_BRANCHES:
        raise not_allowed("branch", branch, f"use one of {', '.join(VALVE_BRANCHES)}")
