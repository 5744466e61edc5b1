"""A grey-box estimate's own checks: what decides that it holds, and what to try when it does not.

An optimiser stops where its steps stop helping; that is a minimum, not the answer. The estimate of
:func:`eha_core.identify.greybox.identify_greybox` is a success only when the record agrees with it:

* ``optimiser``: the optimiser converged (it did not run out of evaluations);
* ``noise``: each signal's residual spread is its noise: the sensors' σ as stated with the record, or,
  when none is stated, what the record's own sample-to-sample scatter says (a local minimum leaves
  residuals several times the noise: the model does not explain the signal);
* ``residuals``: each signal's residuals are white (Ljung-Box over 25 lags at a false-alarm rate of
  1e-3 per signal: a correct fit fails it once in a thousand; a local minimum's residuals are
  slow oscillations, p of 1e-100);
* ``bounds``: no estimate ended at the bound of its physical range (:func:`estimate_range`: a
  parameter that ran to a bound is where the optimiser's steps pushed it, not a measured value);
* ``rank``: the Jacobian at the estimate has full rank (a rank-deficient one gives no intervals).

A failed check says what was found and what to try; the estimate's intervals are then not printed as
if they held.

Only numpy, scipy and the core's own modules are imported here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.stats

from ..param_table import FIELD_INFO

__all__ = ["FitCheck", "estimate_range", "ljung_box", "noise_check", "whiteness_check", "bounds_check",
           "rank_check", "advice", "held_bias", "NOISE_RATIO", "WHITENESS_FALSE_ALARM"]

#: A signal whose residual σ is more than this times its noise (or less than its inverse) fails.
NOISE_RATIO = 1.25
#: The residual whiteness test's false alarm rate per signal.
WHITENESS_FALSE_ALARM = 1e-3
#: Lags of the whiteness test.
WHITENESS_LAGS = 25
#: A log-scaled estimate closer than this (in log units: 0.1 %) to its range's end is at the bound.
AT_BOUND = 1e-3
#: A fit whose residuals are at most this share of the signal's range reproduces it exactly.
EXACT = 1e-6
#: The Jacobian is rank-deficient when its smallest singular value is below this share of its largest.
RANK_TOL = 1e-8

#: The range an estimate may take (SI), wider than any actuator of this kind: it keeps an estimate
#: physical. A bound of 0 (B, Af, k_f may be 0) is reached, in the logarithm the estimate moves in,
#: at ``ZERO_FLOOR`` of the range's top: such an estimate is 0 for any purpose.
RANGES = {
    "M": (1.0, 1e6), "B": (0.0, 1e7), "Af": (0.0, 1e6), "beta_e": (1e7, 1e11), "Kq1": (1e-12, 1e-4),
    "Kq2": (1e-12, 1e-4), "L0": (1e-3, 10.0), "k_f": (0.0, 1e6), "d0": (-1e7, 1e7), "x0": (-10.0, 10.0),
    "v0": (-10.0, 10.0), "p1_0": (0.0, 1e9), "p2_0": (0.0, 1e9)}
ZERO_FLOOR = 1e-9


@dataclass(frozen=True)
class FitCheck:
    """One check of an estimate: its ``name`` (optimiser, noise, residuals, bounds, rank), whether it
    ``passed``, what it found (``says``, a sentence) and the parameters or signals it is about."""

    name: str
    passed: bool
    says: str
    about: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"name": self.name, "passed": self.passed, "says": self.says, "about": list(self.about)}


def estimate_range(name: str) -> tuple[float, float]:
    """The range (SI) the estimate of ``name`` stays in; for a positive one, in the logarithm's terms
    (a bound of 0 is :data:`ZERO_FLOOR` of the top)."""
    lo, hi = RANGES[name]
    if FIELD_INFO.get(name) is not None and FIELD_INFO[name].bound == ">=" and lo == 0.0:
        lo = ZERO_FLOOR * hi
    return lo, hi


def ljung_box(e: np.ndarray, lags: int = WHITENESS_LAGS) -> tuple[float, float]:
    """The Ljung-Box statistic of ``e``'s autocorrelation over ``lags`` lags and its p-value (chi-square
    with ``lags`` degrees of freedom): small p, residuals that are not white."""
    e = np.asarray(e, dtype=float) - float(np.mean(e))
    n = e.size
    lags = min(lags, n - 1)
    den = float(e @ e)
    if den <= 0 or lags < 1:
        return 0.0, 1.0
    r = np.array([float(e[:-k] @ e[k:]) / den for k in range(1, lags + 1)])
    q = float(n * (n + 2) * np.sum(r**2 / (n - np.arange(1, lags + 1))))
    return q, float(scipy.stats.chi2.sf(q, lags))


def noise_check(residual_sigma: dict, reference: dict, stated: bool, spans: dict, units) -> FitCheck:
    """Each signal's residual σ against its noise: ``reference`` (stated with the record when
    ``stated``, else from the record's scatter). ``spans``: each signal's range, for a noise-free record;
    ``units(signal, value)`` writes a value in the signal's unit."""
    bad = []
    for s, got in residual_sigma.items():
        ref = reference[s]
        if ref <= 0:                        # a noise-free record: the fit must reproduce it
            if got > EXACT * max(spans[s], 1e-300):
                bad.append((s, f"the residuals of {s} are {units(s, got)} on a record stated noise-free"))
            continue
        ratio = got / ref
        if ratio > NOISE_RATIO:
            what = f"the sensor's σ {units(s, ref)}" if stated else f"the record's own scatter, {units(s, ref)}"
            bad.append((s, f"the residuals of {s} are {ratio:.2g} times {what}: the model does not explain {s} "
                           "down to its noise"))
        elif stated and ratio < 1.0 / NOISE_RATIO:
            bad.append((s, f"the residuals of {s} ({units(s, got)}) are {1 / ratio:.2g} times smaller than the "
                           f"stated sensor σ {units(s, ref)}: the stated noise is not this record's"))
    if not bad:
        return FitCheck("noise", True, "every signal's residuals are its noise")
    return FitCheck("noise", False, "; ".join(text for _, text in bad), tuple(s for s, _ in bad))


def whiteness_check(residuals: dict, spans: dict) -> FitCheck:
    """Each signal's residuals white (:func:`ljung_box` at :data:`WHITENESS_FALSE_ALARM`); a signal
    reproduced to :data:`EXACT` of its range (a noise-free record) has only rounding left to test."""
    bad = []
    for s, e in residuals.items():
        if float(np.sqrt(np.mean(np.square(e)))) <= EXACT * spans[s]:
            continue
        q, p = ljung_box(e)
        if p < WHITENESS_FALSE_ALARM:
            bad.append((s, f"the residuals of {s} are not white (Ljung-Box over {WHITENESS_LAGS} lags: p = {p:.1g}): "
                           "they hold structure the model has not explained"))
    if not bad:
        return FitCheck("residuals", True, "every signal's residuals are white")
    return FitCheck("residuals", False, "; ".join(text for _, text in bad), tuple(s for s, _ in bad))


def bounds_check(names, z, lower, upper, values: dict, units) -> FitCheck:
    """No estimate at its range's end (``lower``/``upper`` in the optimiser's scaled terms ``z``)."""
    bad = []
    for n, zj, lo, hi in zip(names, z, lower, upper, strict=True):
        if zj - lo <= AT_BOUND * max(1.0, abs(lo)) or hi - zj <= AT_BOUND * max(1.0, abs(hi)):
            end = "lower" if zj - lo <= hi - zj else "upper"
            zero = end == "lower" and RANGES.get(n, (1.0,))[0] == 0.0
            bad.append((n, f"{n} ended at the {end} bound of its range ({units(n, values[n])}"
                           + (", effectively 0" if zero else "") + "): the optimiser pushed it there; it is not "
                           "a measured value"))
    if not bad:
        return FitCheck("bounds", True, "no estimate is at a bound")
    return FitCheck("bounds", False, "; ".join(text for _, text in bad), tuple(n for n, _ in bad))


def rank_check(J: np.ndarray, names) -> FitCheck:
    """The weighted, scaled Jacobian at the estimate of full rank."""
    names = tuple(names)
    if not np.all(np.isfinite(J)):
        return FitCheck("rank", False, "the model's sensitivities at the estimate are not finite", names)
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    if s.size and s[0] > 0 and s[-1] >= RANK_TOL * s[0]:
        return FitCheck("rank", True, "the Jacobian at the estimate has full rank")
    v = vt[-1]
    who = tuple(names[i] for i in range(len(names)) if abs(v[i]) >= 0.3 * np.max(np.abs(v)))
    return FitCheck("rank", False, f"the Jacobian at the estimate is rank-deficient: the signals do not move with "
                                   f"{' and '.join(who)} independently there, so no interval can be given", who)


def advice(checks, *, shooting_tried: bool, measured, names) -> tuple[str, ...]:
    """What to try, from the failed ``checks``."""
    failed = {c.name for c in checks if not c.passed}
    if not failed:
        return ()
    out = []
    if failed & {"noise", "residuals", "optimiser"}:
        out.append("start from other values (the least-squares or frequency-response estimates of this record "
                   "are good starts)" if shooting_tried else
                   "run it with multiple shooting, or start from other values")
        out.append("a richer input (a PRBS or a chirp excites more of the dynamics than one sine)")
        out.append("check the record: SI units (u in V, x in m, v in m/s, p1 and p2 in Pa), how u moves between "
                   "samples (held or linear), a load the model does not know")
    if "bounds" in failed:
        at = [n for c in checks if c.name == "bounds" and not c.passed for n in c.about]
        out.append(f"hold {', '.join(at)} at a known value, or estimate {'it' if len(at) == 1 else 'them'} from a "
                   "record that excites it")
    if "rank" in failed:
        out.append("estimate fewer parameters (hold one at a known value), or measure more signals"
                   + ("" if {"p1", "p2"} <= set(measured) else " (the pressures p1, p2)"))
    return tuple(dict.fromkeys(out))


def held_bias(J_free: np.ndarray, J_held: np.ndarray, free, held, scale_free, estimates: dict,
              step: float = 0.1) -> dict:
    """How a held parameter, if wrong, moves the estimated ones: for each held parameter (``J_held``'s
    columns: sensitivities to its logarithm), the relative change of each free estimate when the held
    one is ``step`` (10 %) above its held value, ``-(J_f^T J_f)^-1 J_f^T J_h`` (first order, in the
    scaled terms), as ``{held: {free: change}}``. ``scale_free``: per free parameter, None for one
    estimated in log terms, else its linear scale."""
    out = {}
    if J_free.size == 0 or J_held.size == 0 or not (np.all(np.isfinite(J_free)) and np.all(np.isfinite(J_held))):
        return out
    shift, *_ = np.linalg.lstsq(J_free, J_held, rcond=None)         # P_free x P_held
    dz = -shift * math.log1p(step)
    for k, h in enumerate(held):
        row = {}
        for j, (n, scale) in enumerate(zip(free, scale_free, strict=True)):
            if scale is None:
                row[n] = float(math.expm1(dz[j, k]))
            else:
                value = estimates[n]
                row[n] = float(dz[j, k] * scale / value) if value else math.nan
        out[h] = row
    return out
