"""Physical parameters of the actuator, their units, validation and derived values.

The defaults are those of the paper (Tables 1 and 3); L0 and Kq1 = Kq2 are not
printed there and are the values that reproduce eq. 23 (docs/model.md §2).

Examples
--------
>>> from eha_core.params import ActuatorParams
>>> p = ActuatorParams()
>>> round(p.A1, 6), round(p.A2, 6)
(0.01131, 0.007461)
>>> round(p.p2_init / 1e6, 3)          # force balance: (A1/A2) p1_0
18.189
>>> ActuatorParams(M=-1.0)
Traceback (most recent call last):
...
eha_core.params.ParameterError: M = -1 is not allowed: must be > 0 kg (load mass)
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ._checks import FieldError

__all__ = [
    "ActuatorParams",
    "ParameterError",
    "FieldInfo",
    "FIELD_INFO",
    "PARAM_NAMES",
    "POSITIVE_FIELDS",
    "NON_NEGATIVE_FIELDS",
    "parse_param_assignments",
]


class ParameterError(FieldError):
    """A parameter value outside what the model allows (a :class:`~eha_core._checks.FieldError`).

    Attributes
    ----------
    field : str
        Name of the offending field (as in :class:`ActuatorParams`).
    value : object
        The rejected value.
    allowed : str
        What would have been accepted, in words (the same as ``what``).
    """

    def __init__(self, field: str, value, allowed: str):
        self.allowed = allowed
        super().__init__(field, value, allowed)


@dataclass(frozen=True)
class FieldInfo:
    """Metadata of one parameter: unit, meaning, and display scaling for the app."""

    unit: str
    description: str
    display_unit: str
    display_scale: float  # value_in_display_unit = value_SI / display_scale
    group: str  # "main", "advanced" or "initial"


FIELD_INFO: dict[str, FieldInfo] = {
    "M": FieldInfo("kg", "load mass", "kg", 1.0, "main"),
    "B": FieldInfo("N s/m", "viscous friction coefficient", "N s/m", 1.0, "main"),
    "Af": FieldInfo("N", "Coulomb friction amplitude", "N", 1.0, "main"),
    "beta_e": FieldInfo("Pa", "effective bulk modulus of the oil", "GPa", 1e9, "main"),
    "Dc": FieldInfo("m", "cylinder bore diameter", "mm", 1e-3, "main"),
    "dc": FieldInfo("m", "piston rod diameter", "mm", 1e-3, "main"),
    "d0": FieldInfo("N", "slow (constant) load disturbance", "N", 1.0, "main"),
    "L0": FieldInfo("m", "chamber length at x = 0", "mm", 1e-3, "advanced"),
    "Kq1": FieldInfo("m^3/(s V sqrt(Pa))", "valve flow gain, piston side", "1e-8 m³/(s V √Pa)", 1e-8, "advanced"),
    "Kq2": FieldInfo("m^3/(s V sqrt(Pa))", "valve flow gain, rod side", "1e-8 m³/(s V √Pa)", 1e-8, "advanced"),
    "ps": FieldInfo("Pa", "supply pressure", "MPa", 1e6, "advanced"),
    "pr": FieldInfo("Pa", "return (tank) pressure", "MPa", 1e6, "advanced"),
    "k_f": FieldInfo("s/m", "friction slope of S(v) = (2/pi) atan(k_f v)", "s/m", 1.0, "advanced"),
    "x0": FieldInfo("m", "initial piston position", "mm", 1e-3, "initial"),
    "v0": FieldInfo("m/s", "initial piston velocity", "mm/s", 1e-3, "initial"),
    "p1_0": FieldInfo("Pa", "initial piston-chamber pressure", "MPa", 1e6, "initial"),
    "p2_0": FieldInfo("Pa", "initial rod-chamber pressure (blank: force balance)", "MPa", 1e6, "initial"),
}

#: Names accepted by ``--param NAME=VALUE`` and by :meth:`ActuatorParams.replace`.
PARAM_NAMES: tuple[str, ...] = tuple(FIELD_INFO)

#: Fields that must be > 0, and fields that must be >= 0. The other rules
#: (:meth:`ActuatorParams.__post_init__`) each tie two fields or more together.
POSITIVE_FIELDS: tuple[str, ...] = ("M", "beta_e", "Dc", "dc", "L0", "Kq1", "Kq2", "ps")
NON_NEGATIVE_FIELDS: tuple[str, ...] = ("B", "Af", "k_f", "pr")


def _unit_and_meaning(name: str) -> str:
    """``"kg (mass of the piston and load)"``: how a bound's message names the field."""
    return f"{FIELD_INFO[name].unit} ({FIELD_INFO[name].description})"


@dataclass(frozen=True)
class ActuatorParams:
    """Parameters and initial conditions of the single-rod cylinder and its valve.

    All values in SI units. ``p2_0 = None`` means "force balance": the rod
    pressure that holds the piston still, ``(A1 p1_0 - d0) / A2`` (section II-A
    of the paper gives 18.189 MPa for the defaults).

    Validation happens at construction; a bad value raises
    :class:`ParameterError` naming the field, the value and the allowed range.
    """

    M: float = 4000.0
    B: float = 1500.0
    Af: float = 3000.0
    beta_e: float = 1.1e9
    Dc: float = 0.12
    dc: float = 0.07
    d0: float = 0.0
    L0: float = 0.3
    Kq1: float = 3.043e-8
    Kq2: float = 3.043e-8
    ps: float = 32e6
    pr: float = 0.0
    k_f: float = 900.0
    x0: float = 0.0
    v0: float = 0.0
    p1_0: float = 12e6
    p2_0: float | None = None

    def __post_init__(self):
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if value is None and f.name == "p2_0":
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise ParameterError(f.name, value, "must be a real number")
            if not math.isfinite(float(value)):
                raise ParameterError(f.name, value, "must be a finite number")
            # store plain floats so that equal parameter sets hash equal
            object.__setattr__(self, f.name, float(value))

        for name in POSITIVE_FIELDS:
            if getattr(self, name) <= 0:
                raise ParameterError(name, getattr(self, name), f"must be > 0 {_unit_and_meaning(name)}")
        for name in NON_NEGATIVE_FIELDS:
            if getattr(self, name) < 0:
                raise ParameterError(name, getattr(self, name), f"must be >= 0 {_unit_and_meaning(name)}")
        if self.dc >= self.Dc:
            raise ParameterError("dc", self.dc, f"the rod diameter must be smaller than the bore Dc = {self.Dc:.6g} m")
        if self.pr >= self.ps:
            raise ParameterError("pr", self.pr,
                                 f"the return pressure must be below the supply pressure ps = {self.ps:.6g} Pa")
        x_max = self.x_max
        if abs(self.x0) > x_max:
            raise ParameterError("x0", self.x0,
                                 f"must lie within the end stops [-{x_max:.6g}, {x_max:.6g}] m (|x0| <= 0.8 L0)")
        if not self.pr <= self.p1_0 <= self.ps:
            raise ParameterError("p1_0", self.p1_0, f"must lie within [pr, ps] = [{self.pr:.6g}, {self.ps:.6g}] Pa")
        p2 = self.p2_init
        if not self.pr <= p2 <= self.ps:
            bounds = f"[pr, ps] = [{self.pr:.6g}, {self.ps:.6g}] Pa"
            if self.p2_0 is not None:
                raise ParameterError("p2_0", p2, f"must lie within {bounds}")
            raise ParameterError("p2_0", p2, f"the force balance (A1 p1_0 - d0)/A2 must lie within {bounds}; "
                                             "change p1_0 or d0, or set p2_0")

    # -- derived geometry -------------------------------------------------
    @property
    def A1(self) -> float:
        """Piston-side effective area pi Dc^2 / 4 [m^2]."""
        return math.pi * self.Dc**2 / 4.0

    @property
    def A2(self) -> float:
        """Rod-side effective area pi (Dc^2 - dc^2) / 4 [m^2]."""
        return math.pi * (self.Dc**2 - self.dc**2) / 4.0

    @property
    def x_max(self) -> float:
        """End stop: |x| <= 0.8 L0 [m]."""
        return 0.8 * self.L0

    @property
    def p2_init(self) -> float:
        """Initial rod pressure: ``p2_0`` or, when None, the force balance [Pa]."""
        if self.p2_0 is not None:
            return self.p2_0
        return (self.A1 * self.p1_0 - self.d0) / self.A2

    @property
    def initial_state(self) -> np.ndarray:
        """[x0, v0, p1_0, p2_0] as a new array."""
        return np.array([self.x0, self.v0, self.p1_0, self.p2_init])

    @property
    def a(self) -> dict[str, float]:
        """Compact-form parameters a1..a10 of Table 1 (eqs. 6-8)."""
        be = self.beta_e
        return {
            "a1": self.B / self.M,
            "a2": 2.0 * self.Af / (math.pi * self.M),
            "a3": self.A1 / self.M,
            "a4": self.A2 / self.M,
            "a5": self.L0 / be,
            "a6": 1.0 / be,
            "a7": self.L0 * self.A1 / (be * self.Kq1),
            "a8": self.A1 / (be * self.Kq1),
            "a9": self.L0 * self.A2 / (be * self.Kq2),
            "a10": self.A2 / (be * self.Kq2),
        }

    # -- conversions ------------------------------------------------------
    def replace(self, **changes) -> ActuatorParams:
        """A copy with some fields changed (validated again).

        >>> ActuatorParams().replace(M=5000.0).M
        5000.0
        """
        unknown = sorted(set(changes) - set(PARAM_NAMES))
        if unknown:
            raise ParameterError(unknown[0], changes[unknown[0]], f"unknown parameter; known: {', '.join(PARAM_NAMES)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, float | None]:
        """Field values by name (SI units)."""
        return dataclasses.asdict(self)


def parse_param_assignments(items, base: ActuatorParams | None = None) -> ActuatorParams:
    """Apply ``NAME=VALUE`` strings (the command line's ``--param``) to ``base``.

    >>> parse_param_assignments(["M=5000", "p1_0=10e6"]).M
    5000.0
    >>> parse_param_assignments(["mass=1"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    eha_core.params.ParameterError: mass = 1 is not allowed: unknown parameter; known: M, B, Af, beta_e, ..., p2_0
    """
    base = base if base is not None else ActuatorParams()
    changes: dict[str, float | None] = {}
    for item in items or ():
        if "=" not in item:
            raise ParameterError("--param", item, "expected NAME=VALUE, e.g. M=4000")
        name, _, text = item.partition("=")
        name, text = name.strip(), text.strip()
        if name not in FIELD_INFO:
            raise ParameterError(name, text, f"unknown parameter; known: {', '.join(PARAM_NAMES)}")
        if name == "p2_0" and text.lower() in ("", "none", "balance"):
            changes[name] = None
            continue
        try:
            changes[name] = float(text)
        except ValueError:
            raise ParameterError(name, text, f"must be a number in {FIELD_INFO[name].unit}") from None
    return base.replace(**changes)
