"""From an estimated closed loop back to the plant and its physical parameters (eqs. 26-27).

With a proportional controller Kp, H = Kp P / (1 + Kp P), so

    P_hat = H_hat / (Kp (1 - H_hat)) = N / (Kp (D - N))                 (eq. 26)

for H_hat = N / D. Identifying P_hat = b / (s^3 + a1 s^2 + a2 s + a3) with
eq. 21 and taking M, A1, A2, L0, Kq1, Kq2 and the operating pressures as
measured (eq. 27):

* a1 = l1 = (B + 2 k_f Af / pi) / M, so the total linearised damping is a1 M;
* b = l5 l2 + l6 l3 = beta_e (Kq1 sqrt(D3) + Kq2 sqrt(D4)) / (M L0), so
  beta_e = M L0 b / (Kq1 sqrt(D3) + Kq2 sqrt(D4));
* a2 = (l2 + l3) l4 = (A1 + A2) beta_e / (M L0), so, independently,
  beta_e = a2 M L0 / (A1 + A2);
* a3 should be 0 (the plant integrates velocity into position).

The map from H_hat's coefficients to these numbers is linear, so standard
errors carry over exactly from the estimate's covariance.

Why a1 comes out far below the linearised 430.1: l1 holds the slope of the
friction at v = 0, 2 k_f Af / pi = 1.72e6 N s/m, but in the experiment the
velocity swings through |v| >> 1/k_f = 1.1 mm/s, where S(v) = (2/pi) atan(k_f v)
is saturated: the friction then acts as a nearly constant force +-Af, which
adds almost no damping to the oscillation. What the data see is roughly B plus
the friction's average slope over the velocities reached, an order of magnitude
or two below the slope at zero (docs/model.md, section 4; the paper: 11.12).

Examples
--------
>>> from eha_core.identify.backout import open_loop_from_closed, backout
>>> from eha_core.linear import linearize
>>> from eha_core.params import ActuatorParams
>>> p = ActuatorParams()
>>> num_p, den_p = open_loop_from_closed(*linearize(p).closed_loop_coeffs(10.0), kp=10.0)
>>> b = backout(num_p, den_p, p)
>>> round(b.damping / p.M, 1), round(b.beta_e_from_gain / 1e9, 4), round(b.beta_e_from_stiffness / 1e9, 4)
(430.1, 1.1, 1.1)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._checks import not_allowed
from ..linear import OperatingPoint, operating_point
from ..params import ActuatorParams
from ._stats import Z95

__all__ = ["open_loop_instability", "BackoutResult", "open_loop_from_closed", "backout"]


def open_loop_from_closed(num_h, den_h, kp: float) -> tuple[np.ndarray, np.ndarray]:
    """P = N / (Kp (D - N)) for H = N / D (eq. 26), monic denominator.

    Parameters
    ----------
    num_h, den_h : array_like
        H_hat's numerator N and denominator D, descending powers of s (a proper H_hat).
    kp : float
        The proportional gain Kp of the loop [V/m].

    Returns
    -------
    num_p, den_p : numpy.ndarray
        P_hat's coefficients, the denominator monic.
    """
    # coefficients are shown in messages as lists (a few numbers, as typed)
    num_h = np.atleast_1d(np.asarray(num_h, dtype=float))
    den_h = np.atleast_1d(np.asarray(den_h, dtype=float))
    if not (math.isfinite(kp) and kp > 0):
        raise not_allowed("kp", kp, "must be a finite gain > 0")
    if num_h.size > den_h.size:
        raise not_allowed("num_h", num_h.tolist(), f"its degree {num_h.size - 1} exceeds the degree "
                                                 f"{den_h.size - 1} of den_h: the closed loop must be proper")
    pad = np.zeros(den_h.size)
    pad[den_h.size - num_h.size:] = num_h
    den_p = den_h - pad
    lead = den_p[0]
    if lead == 0:
        raise not_allowed("num_h", num_h.tolist(), "with den_h it gives H_hat a feedthrough of 1, so "
                                                 "P = H / (Kp (1 - H)) is not proper")
    return num_h / (kp * lead), den_p / lead


def open_loop_instability(num_h, den_h, kp: float) -> tuple[float, float] | None:
    """Why P_hat = H_hat / (Kp (1 - H_hat)) (eq. 26) is unstable, or None when it is not.

    Returns ``(pole, static_gain)``: the right-half-plane pole of P_hat with the
    largest real part [rad/s] and H_hat(0). The actuator's P(s) has an
    integrator (a pole at 0, eq. 21), so its loop has H(0) = 1 exactly; an
    estimate with H_hat(0) > 1 makes the constant term of 1 - H_hat negative and
    moves that pole into the right half-plane.

    Parameters
    ----------
    num_h, den_h : array_like
        H_hat's numerator and denominator, descending powers of s.
    kp : float
        The proportional gain Kp of the loop [V/m].
    """
    num_p, den_p = open_loop_from_closed(num_h, den_h, kp)
    poles = np.roots(den_p) if den_p.size > 1 else np.array([])
    unstable = poles[poles.real > 1e-12 * max(1.0, float(np.max(np.abs(poles), initial=0.0)))]
    if unstable.size == 0:
        return None
    worst = unstable[np.argmax(unstable.real)]
    den_h = np.atleast_1d(np.asarray(den_h, dtype=float))
    num_h = np.atleast_1d(np.asarray(num_h, dtype=float))
    gain = float(num_h[-1] / den_h[-1]) if den_h[-1] != 0 else math.inf
    return float(worst.real), gain


@dataclass(frozen=True)
class BackoutResult:
    """Physical parameters implied by an estimated plant P_hat (eq. 27).

    ``damping`` is B + 2 k_f Af / pi [N s/m]; ``damping_nominal`` its value at
    the nominal parameters (1.72e6 for the defaults). ``*_std`` are standard
    errors when the estimate's covariance was given, else NaN.
    """

    num_p: tuple[float, ...]
    den_p: tuple[float, ...]
    damping: float
    damping_nominal: float
    beta_e_from_gain: float
    beta_e_from_stiffness: float
    beta_e_nominal: float
    integrator_coefficient: float
    damping_std: float = float("nan")
    beta_e_from_gain_std: float = float("nan")
    beta_e_from_stiffness_std: float = float("nan")
    known: dict = field(default_factory=dict)

    @property
    def l1(self) -> float:
        return self.den_p[1] if len(self.den_p) > 1 else float("nan")

    def rel_errors(self) -> dict[str, float]:
        """Each backed-out value relative to its nominal one, minus 1 (NaN where the nominal value is 0:
        B = 0 with no Coulomb slope, k_f A_f = 0, has no relative error)."""
        def rel(v, nom):
            return v / nom - 1.0 if nom != 0 else math.nan

        return {
            "damping": rel(self.damping, self.damping_nominal),
            "beta_e_from_gain": rel(self.beta_e_from_gain, self.beta_e_nominal),
            "beta_e_from_stiffness": rel(self.beta_e_from_stiffness, self.beta_e_nominal),
        }

    def ci95(self) -> dict[str, tuple[float, float]]:
        """95 % intervals (value +- 1.96 standard errors) of ``damping``, ``beta_e_from_gain`` and
        ``beta_e_from_stiffness``; NaN bounds without the estimate's covariance."""
        out = {}
        for name in ("damping", "beta_e_from_gain", "beta_e_from_stiffness"):
            v, s = getattr(self, name), getattr(self, name + "_std")
            out[name] = (v - Z95 * s, v + Z95 * s)
        return out

    def to_dict(self) -> dict:
        """P_hat, the backed-out values, their errors and the known quantities as plain values (SI)."""
        return {
            "open_loop": {"num": list(self.num_p), "den": list(self.den_p)},
            "l1": self.l1,
            "damping_B_plus_2kfAf_over_pi": self.damping,
            "damping_nominal": self.damping_nominal,
            "damping_std": self.damping_std,
            "beta_e_from_gain": self.beta_e_from_gain,
            "beta_e_from_gain_std": self.beta_e_from_gain_std,
            "beta_e_from_stiffness": self.beta_e_from_stiffness,
            "beta_e_from_stiffness_std": self.beta_e_from_stiffness_std,
            "beta_e_nominal": self.beta_e_nominal,
            "integrator_coefficient": self.integrator_coefficient,
            "rel_errors": self.rel_errors(),
            "known": self.known,
        }

    def to_pandas(self):
        """``damping``, ``beta_e_from_gain`` and ``beta_e_from_stiffness`` as a :class:`pandas.DataFrame` indexed
        by name: ``value``, ``std_error``, ``ci95_low``, ``ci95_high`` (SI; NaN without the estimate's
        covariance), ``unit``, ``display_unit``, ``display_scale``."""
        from .._display import estimates_frame

        ci = self.ci95()
        return estimates_frame((n, getattr(self, n), getattr(self, n + "_std"), *ci[n]) for n in ci)

    def __repr__(self) -> str:
        from .._display import block, polynomial, with_error

        items = [with_error(n, getattr(self, n), getattr(self, n + "_std"))
                 for n in ("damping", "beta_e_from_gain", "beta_e_from_stiffness")]
        notes = [f"P_hat = {polynomial(self.num_p)} / ({polynomial(self.den_p)}) (eq. 26); damping = B + 2 k_f Af / pi",
                 "± 1 standard error; .to_pandas(): the 95 % intervals"]
        return block("BackoutResult: physical parameters from the plant estimate (eq. 27)", True, "", items, notes,
                     passed="no checks of its own (the estimate's are)")


def backout(num_p, den_p, params: ActuatorParams | None = None, op: OperatingPoint | None = None,
            *, std_h: np.ndarray | None = None, kp: float | None = None) -> BackoutResult:
    """Physical parameters from a third-order plant estimate ``P_hat = num_p / den_p``.

    Parameters
    ----------
    num_p, den_p : array_like
        P_hat with a monic cubic denominator (eq. 26's result).
    params : ActuatorParams
        The quantities taken as measured: M, A1, A2, L0, Kq1, Kq2, ps, pr, and
        the nominal values to compare with.
    op : OperatingPoint, optional
        Operating pressures for D3, D4 (eq. 13, u >= 0 branch).
    std_h, kp : optional
        Standard errors of the closed-loop estimate's coefficients, ordered
        [den[1:], num] (as :class:`~eha_core.identify.tfest.TFEstimate` gives
        them), and the gain Kp: then the results get standard errors too.
    """
    p = params if params is not None else ActuatorParams()
    op = op if op is not None else operating_point(p)
    num_p = np.atleast_1d(np.asarray(num_p, dtype=float))
    den_p = np.atleast_1d(np.asarray(den_p, dtype=float))
    if den_p.size != 4 or num_p.size != 1:
        name, value = ("den_p", den_p) if den_p.size != 4 else ("num_p", num_p)
        raise not_allowed(name, value.tolist(), f"P_hat must be b / (s^3 + a1 s^2 + a2 s + a3) (3 poles, no zeros) "
                                              f"to back out the parameters; it has {num_p.size - 1} zeros and "
                                              f"{den_p.size - 1} poles")
    den_p = den_p / den_p[0]
    a1, a2, a3 = den_p[1:]
    b = num_p[-1] / 1.0
    d3 = max(p.ps - op.p1, 0.0)
    d4 = max(op.p2 - p.pr, 0.0)
    flow = p.Kq1 * math.sqrt(d3) + p.Kq2 * math.sqrt(d4)
    gain_factor = p.M * p.L0 / flow
    stiff_factor = p.M * p.L0 / (p.A1 + p.A2)
    damping_std = bg_std = bs_std = float("nan")
    if std_h is not None and kp is not None:
        std_h = np.asarray(std_h, dtype=float)
        # H = n / (s^3 + c1 s^2 + c2 s + c3): P's a1 = c1, a2 = c2, b = n / Kp
        damping_std = float(std_h[0] * p.M)
        bs_std = float(std_h[1] * stiff_factor)
        bg_std = float(std_h[3] / kp * gain_factor)
    return BackoutResult(
        num_p=tuple(float(v) for v in num_p), den_p=tuple(float(v) for v in den_p),
        damping=float(a1 * p.M),
        damping_nominal=float(p.B + 2.0 * p.k_f * p.Af / math.pi),
        beta_e_from_gain=float(b * gain_factor),
        beta_e_from_stiffness=float(a2 * stiff_factor),
        beta_e_nominal=float(p.beta_e),
        integrator_coefficient=float(a3),
        damping_std=damping_std, beta_e_from_gain_std=bg_std, beta_e_from_stiffness_std=bs_std,
        known={"M": p.M, "A1": p.A1, "A2": p.A2, "L0": p.L0, "Kq1": p.Kq1, "Kq2": p.Kq2,
               "D3": d3, "D4": d4},
    )
