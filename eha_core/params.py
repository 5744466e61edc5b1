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
from dataclasses import dataclass, field

import numpy as np

from ._checks import FieldError
from .param_table import (
    FIELD_INFO,
    NON_NEGATIVE_FIELDS,
    PARAM_NAMES,
    POSITIVE_FIELDS,
    RULES,
    FieldInfo,
    broken_rules,
    end_stop,
    force_balance,
    piston_area,
    rod_area,
)
from .variants import EFFECTS_OFF, Effects

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


#: The rules ActuatorParams checks (the others are the linearisation's, see eha_core.param_table.RULES).
_CHECKED_RULES = tuple(rule for rule in RULES if rule.core is not None)


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

    ``effects`` (:class:`eha_core.variants.Effects`, default all off: the
    paper's model) adds structural effects the paper leaves out: the valve's
    spool dynamics, internal leakage, Stribeck friction (docs/model.md §6). It
    is not one of the form's parameters (:data:`FIELD_INFO`); the repr and
    :meth:`to_dict` show it only when it is not the default.
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
    effects: Effects = field(default=EFFECTS_OFF, repr=False)

    def __post_init__(self):
        # the effects: Effects, None (off), their mapping (to_dict) or a variant's name (eha_core.variants)
        try:
            object.__setattr__(self, "effects", Effects.from_value(self.effects))
        except FieldError as error:
            raise ParameterError(error.field, error.value, error.what) from None
        for f in dataclasses.fields(self):
            if f.name == "effects":
                continue
            value = getattr(self, f.name)
            if value is None and f.name == "p2_0":
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise ParameterError(f.name, value, "must be a real number")
            if not math.isfinite(float(value)):
                raise ParameterError(f.name, value, "must be a finite number")
            # store plain floats so that equal parameter sets hash equal
            object.__setattr__(self, f.name, float(value))

        # the facts of eha_core.param_table: each field's bound, then the rules that tie fields
        # together, in the table's order (the first broken one is reported)
        for name in POSITIVE_FIELDS:
            if getattr(self, name) <= 0:
                raise ParameterError(name, getattr(self, name), f"must be > 0 {_unit_and_meaning(name)}")
        for name in NON_NEGATIVE_FIELDS:
            if getattr(self, name) < 0:
                raise ParameterError(name, getattr(self, name), f"must be >= 0 {_unit_and_meaning(name)}")
        for rule in broken_rules(vars(self), _CHECKED_RULES):
            raise ParameterError(*rule.refusal(vars(self)))

    # -- derived geometry -------------------------------------------------
    @property
    def A1(self) -> float:
        """Piston-side effective area pi Dc^2 / 4 [m^2]."""
        return piston_area(vars(self))

    @property
    def A2(self) -> float:
        """Rod-side effective area pi (Dc^2 - dc^2) / 4 [m^2]."""
        return rod_area(vars(self))

    @property
    def x_max(self) -> float:
        """End stop: |x| <= 0.8 L0 [m]."""
        return end_stop(vars(self))

    @property
    def p2_init(self) -> float:
        """Initial rod pressure: ``p2_0`` or, when None, the force balance [Pa]."""
        if self.p2_0 is not None:
            return self.p2_0
        return force_balance(vars(self))

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
        """A copy with some fields changed (validated again); ``effects`` may be among them.

        >>> ActuatorParams().replace(M=5000.0).M
        5000.0
        """
        unknown = sorted(set(changes) - set(PARAM_NAMES) - {"effects"})
        if unknown:
            raise ParameterError(unknown[0], changes[unknown[0]], f"unknown parameter; known: {', '.join(PARAM_NAMES)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        """Field values by name (SI units); ``effects`` (as a mapping) only when they are not the default
        (every effect off), so that ``ActuatorParams(**p.to_dict()) == p``."""
        out: dict = {name: getattr(self, name) for name in PARAM_NAMES}
        if self.effects != EFFECTS_OFF:
            out["effects"] = self.effects.to_dict()
        return out

    def __repr__(self) -> str:
        # the dataclass's own form, with the effects only when they are not the default
        # (the paper's parameter sets print as they always have)
        fields = ", ".join(f"{name}={getattr(self, name)!r}" for name in PARAM_NAMES)
        extra = f", effects={self.effects!r}" if self.effects != EFFECTS_OFF else ""
        return f"{type(self).__qualname__}({fields}{extra})"


def parse_param_assignments(items, base: ActuatorParams | None = None) -> ActuatorParams:
    """Apply the ``NAME=VALUE`` strings of ``items`` (the command line's ``--param``, values in SI;
    ``p2_0=none`` leaves p2(0) to the force balance) to ``base`` (default the paper's parameters).

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
