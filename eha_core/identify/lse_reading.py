"""What a least-squares estimate and its interval say, in one word and one sentence each.

A table that marks an interval ✓ when it covers the nominal value and ✗ when
it misses teaches the wrong lesson at both ends:

* **without noise** the residual is the regressors' numerical error
  (~0.003 %, see :mod:`eha_core.identify.lse`), the interval collapses to a
  few parts per million and misses a nominal value the estimate equals to
  every printed digit: that is an *exact* estimate, not a failure;
* an estimate that no actuator can have (a negative mass, friction or bulk
  modulus) is *impossible*, whatever its interval; and an interval wider
  than the estimate itself (one that reaches past zero) covers almost
  anything: the data *do not determine* the parameter, and "covers" would
  read as success.

:func:`read_estimate` gives each estimate one of these readings, from the
result's own numbers; :func:`disturbance_leak` explains, from a run with both
disturbance models, why the paper's constant model fails under a sinusoidal
force.

Examples
--------
>>> from eha_core.experiments import lse_data
>>> from eha_core.identify.lse import identify_lse
>>> res = identify_lse(lse_data(disturbance="none"))
>>> [read_estimate(res, k).kind for k in ("M", "B", "Af", "d0", "beta_e")]
['exact', 'exact', 'exact', 'exact', 'exact']
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..param_table import FIELD_INFO, physically_possible
from ..params import ActuatorParams

__all__ = ["EstimateReading", "READING_KINDS", "read_estimate", "read_all", "DisturbanceLeak",
           "disturbance_leak", "EXACT_TOLERANCE"]

#: Relative agreement with the nominal value that counts as exact when the interval has collapsed:
#: ten times the regressors' numerical error without noise (~1e-5, eq. 18 on the fine grid).
EXACT_TOLERANCE = 1e-4

#: Every reading, the best first. ``ok`` is True for exact and covers, False for impossible and
#: misses, None for the readings that neither pass nor fail (undetermined, no nominal value).
READING_KINDS = ("exact", "covers", "undetermined", "estimated", "misses", "impossible")

_FORCES = ("d0", "d_sin", "d_cos")
_SYMBOLS = {"M": "M", "B": "B", "Af": "Af", "d0": "d0", "d_sin": "d_sin", "d_cos": "d_cos", "beta_e": "β_e"}
_UNITS = {**{n: FIELD_INFO[n].unit for n in ("M", "B", "Af", "d0", "beta_e")}, "d_sin": "N", "d_cos": "N"}
_PHYSICAL = {"M": "a mass", "B": "a viscous friction coefficient", "Af": "a Coulomb friction amplitude",
             "beta_e": "a bulk modulus"}


@dataclass(frozen=True)
class EstimateReading:
    """One estimate read against its interval, its nominal value and physics.

    Attributes
    ----------
    name : str
    kind : str
        One of :data:`READING_KINDS`.
    ok : bool or None
        True (exact, covers), False (impossible, misses), None (undetermined,
        or no nominal value to compare with).
    value, lo, hi : float
        The estimate and its 95 % interval (SI units).
    nominal : float or None
        The value it is read against (None: none known or shown).
    narrow : bool
        For *misses*: the interval is within ten times the exact tolerance
        (the error is the model's, not the noise's).
    """

    name: str
    kind: str
    ok: bool | None
    value: float
    lo: float
    hi: float
    nominal: float | None = None
    narrow: bool = False

    @property
    def sentence(self) -> str:
        """What the reading means, with the numbers (plain text)."""
        return self.describe()

    def describe(self, fmt=None, symbol: str | None = None, unit: str | None = None, nominal: str = "nominal") -> str:
        """The sentence with numbers written by ``fmt`` (default 5 significant digits) and the
        parameter named ``symbol`` in ``unit`` (defaults: β_e, Pa, ...), for a page or a terminal;
        ``nominal`` is what the value compared with is called ("known" in an exercise)."""
        fmt = fmt or _g
        sym = symbol or _SYMBOLS.get(self.name, self.name)
        unit = _UNITS.get(self.name, "") if unit is None else unit
        u = f" {unit}" if unit else ""
        v, nom = self.value, self.nominal
        interval = f"[{fmt(self.lo)}, {fmt(self.hi)}]{u}"
        if self.kind == "impossible":
            bound = FIELD_INFO[self.name].bound if self.name in FIELD_INFO else ">"
            need = "> 0" if bound == ">" else "≥ 0"
            return (f"{sym} = {fmt(v)}{u} is impossible: {_PHYSICAL.get(self.name, 'it')} must be {need}. The "
                    "model does not describe these data (a disturbance it leaves out, or too little excitation).")
        if self.kind == "exact":
            off = abs(100 * (v - nom) / nom) if nom else None
            rel = "" if off is None else (f" (off by {off:.4f} %)" if off >= 5e-5 else " (off by less than 0.0001 %)")
            return (f"{sym} is exact: without noise the estimate equals the {nominal} {fmt(nom)}{u} to within the "
                    f"regressors' numerical error{rel}, and the interval {interval} collapses to that error.")
        if self.kind == "undetermined":
            covers = "" if nom is None else (f" It covers the {nominal} value, which says little."
                                             if self.lo <= nom <= self.hi else f" It misses the {nominal} value too.")
            return (f"The data do not determine {sym}: its 95 % interval {interval} is wider than the estimate "
                    f"{fmt(v)} itself.{covers}")
        if self.kind == "estimated":
            return f"{sym} = {fmt(v)}{u}, 95 % interval {interval}."
        if self.kind == "covers":
            return f"The 95 % interval of {sym} {interval} covers the {nominal} {fmt(nom)}{u}."
        return (f"The 95 % interval of {sym} {interval} misses the {nominal} {fmt(nom)}{u}"
                + (": it is narrow, so the error is the model's, not the noise's." if self.narrow else "."))


def _g(v: float) -> str:
    return f"{v:.5g}"


def _tolerance(res, name: str, nominal: float | None) -> float:
    """The absolute difference below which an estimate equals ``nominal``: EXACT_TOLERANCE of it,
    or of the filtered force (the left side of eq. 15a) for a force whose nominal value is 0."""
    if nominal:
        return EXACT_TOLERANCE * abs(nominal)
    if name in _FORCES and res.y1f is not None and np.any(np.isfinite(res.y1f)):
        y = res.y1f[np.isfinite(res.y1f)]
        return EXACT_TOLERANCE * float(np.sqrt(np.mean(y * y)))
    return 0.0


def read_estimate(res, name: str, *, known: bool = True) -> EstimateReading:
    """The reading of ``res.estimates[name]`` (``res`` an :class:`~eha_core.identify.lse.LSEResult`,
    ``name`` one of its estimates: M, B, Af, d0, d_sin, d_cos or beta_e).

    In order: *impossible* when the estimate breaks the parameter's physical
    bound (M, β_e > 0; B, Af >= 0); *exact* when the interval has collapsed
    (half-width within :data:`EXACT_TOLERANCE`) and the estimate equals the
    nominal value within it; *undetermined* when the interval is wider than
    the estimate (for M, B, Af, β_e: the data do not determine it); then
    *covers* or *misses* against the nominal value, or *estimated* when there
    is none. ``known`` False reads without the nominal value (a student's own
    record, an exercise's hidden parameter): the truth never shapes the
    reading.
    """
    v = float(res.estimates[name])
    lo, hi = (float(b) for b in res.ci95[name])
    nom = res.nominal.get(name) if known else None
    if not physically_possible(name, v):
        return EstimateReading(name, "impossible", False, v, lo, hi, nom)
    half = 0.5 * (hi - lo)
    tol = _tolerance(res, name, nom) if nom is not None else 0.0
    if nom is not None and math.isfinite(half) and half <= tol and abs(v - nom) <= tol:
        return EstimateReading(name, "exact", True, v, lo, hi, nom)
    if name in _PHYSICAL and not (hi - lo <= abs(v)):
        return EstimateReading(name, "undetermined", None, v, lo, hi, nom)
    if nom is None:
        return EstimateReading(name, "estimated", None, v, lo, hi)
    if lo <= nom <= hi:
        return EstimateReading(name, "covers", True, v, lo, hi, nom)
    return EstimateReading(name, "misses", False, v, lo, hi, nom, narrow=bool(half <= 10 * tol))


def read_all(res, hidden=()) -> dict[str, EstimateReading]:
    """:func:`read_estimate` for every estimate of ``res``, in its order; the names in ``hidden``
    are read without their nominal value."""
    return {k: read_estimate(res, k, known=k not in hidden) for k in res.estimates}


@dataclass(frozen=True)
class DisturbanceLeak:
    """Why the constant disturbance model fails: a sinusoid it leaves out, partly carried by the regressors.

    Attributes
    ----------
    freq_hz, amplitude : float
        The sinusoid the harmonic model found [Hz, N].
    residual_ratio : float
        RMS residual of eq. 15a with the harmonic model over that with the constant one.
    partial_correlations : dict
        Correlation of that sinusoid with each parameter's regressor of eq. 15a
        once the other regressors are regressed out (M: dv/dt, B: v, Af: S(v)):
        the share of the sinusoid least squares can only explain with that
        parameter.
    reach : dict
        The largest force each term carries over the record [N] (M |dv/dt|,
        B |v|, Af |S(v)| at the harmonic model's estimates).
    shifted : dict
        Estimate with the constant model minus that with the harmonic one, for M, B, Af.
    worst : str
        The parameter moved most against its own value.
    sentence : str
    """

    freq_hz: float
    amplitude: float
    residual_ratio: float
    partial_correlations: dict
    reach: dict
    shifted: dict
    worst: str
    sentence: str


_REGRESSOR_NAMES = {"M": "dv/dt", "B": "v", "Af": "S(v)"}


def disturbance_leak(constant, harmonic, data, params=None) -> DisturbanceLeak | None:
    """The sinusoid the constant model leaves out, and which estimate it moves.

    ``constant`` and ``harmonic`` are least-squares results on the same
    ``data`` (a :class:`~eha_core.identify.lse.MeasuredData`) with the two
    disturbance models; ``params`` gives the friction slope k_f of S(v)
    (eq. 2; the paper's by default). None when the harmonic model does not
    explain the residual (it leaves more than half of the constant model's
    RMS residual): there is no sinusoid to speak of.

    Least squares assumes the disturbance is uncorrelated with the
    regressors. Whatever share of the sinusoid the regressors can represent
    (the omitted-variable shift ``(Phi^T Phi)^-1 Phi^T d``) goes into M, B and
    Af; a parameter whose term is small against the sinusoid (B v reaches
    ~140 N against 5000 N in the paper's experiment) is moved far by a tiny
    share.
    """
    if harmonic.disturbance_freq_hz is None or constant.disturbance_model != "constant":
        return None
    r_c, r_h = constant.residual_rms["y1"], harmonic.residual_rms["y1"]
    if not (r_c > 0 and r_h <= 0.5 * r_c):
        return None
    f = float(harmonic.disturbance_freq_hz)
    a, b = harmonic.estimates["d_sin"], harmonic.estimates["d_cos"]
    t = data.t
    d = a * np.sin(2 * np.pi * f * t) + b * np.cos(2 * np.pi * f * t)
    k_f = (params if params is not None else ActuatorParams()).k_f
    cols = {"M": np.gradient(data.v, t), "B": data.v, "Af": (2.0 / math.pi) * np.arctan(k_f * data.v)}
    X = np.column_stack(list(cols.values()) + [np.ones_like(t)])
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(d))):
        return None
    partial = {}
    for j, k in enumerate(cols):
        others = np.delete(X, j, axis=1)

        def resid(y, others=others):
            return y - others @ np.linalg.lstsq(others, y, rcond=None)[0]

        rx, rd = resid(X[:, j]), resid(d)
        den = float(np.linalg.norm(rx) * np.linalg.norm(rd))
        partial[k] = float(rx @ rd / den) if den > 0 else 0.0
    reach = {k: float(abs(harmonic.estimates[k]) * np.max(np.abs(x))) for k, x in cols.items()}
    shifted = {k: float(constant.estimates[k] - harmonic.estimates[k]) for k in cols}
    worst = max(shifted, key=lambda k: abs(shifted[k]) / max(abs(harmonic.estimates[k]), 1e-300))
    amp = float(math.hypot(a, b))
    sym, unit = _SYMBOLS[worst], _UNITS[worst]
    sentence = (f"The constant d0 leaves out a {f:.3g} Hz sinusoid of {amp:.4g} N. Least squares assumes the "
                f"disturbance is uncorrelated with the regressors; this one is correlated with "
                f"{_REGRESSOR_NAMES[worst]} (ρ = {partial[worst]:+.2g} once the other regressors are taken out), "
                f"and the {sym} term reaches only {reach[worst]:.3g} N against {amp:.4g} N, so that share moves "
                f"{sym} by {shifted[worst]:+.5g} {unit}. Modelled as d0 + a sinusoid, {sym} = "
                f"{harmonic.estimates[worst]:.5g} {unit} and the residual falls to {100 * r_h / r_c:.2g} % of the "
                "constant model's.")
    return DisturbanceLeak(f, amp, float(r_h / r_c), partial, reach, shifted, worst, sentence)
