"""Structural variants of the actuator: effects the paper's model leaves out, each off by default.

The paper's model (eqs. 1-4, docs/model.md §1) has an instantaneous valve, no
flow between the chambers but through the valve, and friction ``B v + Af S(v)``
(eq. 2). :class:`Effects` adds three effects to it, each switched on by its
parameters (docs/model.md §6):

* **spool** (eq. V1): the valve's effective command ``u_v`` (the spool's position) follows ``u``
  through ``ω_v² / (s² + 2 ζ_v ω_v s + ω_v²)`` and the orifices (eq. 3) see
  ``u_v`` instead of ``u``; two more states ``[u_v, du_v/dt]``. On when ``omega_v > 0``.
* **leakage** (eq. V2): a laminar flow ``Q_L = C_L (p1 - p2)`` from chamber 1 to
  chamber 2 past the piston. On when ``C_L > 0``.
* **stribeck** (eq. V3): ``(F_c + (F_s - F_c) exp(-(v/v_s)²)) tanh(v/v_eps)``
  added to the paper's friction. On when ``F_c`` or ``F_s`` is not 0.

:data:`VARIANTS` names one actuator for each effect, at a size that shows
(in a frequency response, in the residuals of the paper's model, at low
velocity) without dominating what the paper's model explains; a class exercise
gives a student one by name (:func:`variant_effects`) and says what it assumes
(:func:`describe_effects`). An :class:`~eha_core.params.ActuatorParams` holds
its effects in the field ``effects``, which is not one of the form's
parameters (``FIELD_INFO``).

Examples
--------
>>> from eha_core.variants import VARIANTS, Effects, describe_effects, variant_effects
>>> list(VARIANTS)
['paper', 'spool', 'leakage', 'stribeck']
>>> variant_effects("paper") == Effects()
True
>>> variant_effects("spool+leakage").active
('spool', 'leakage')
>>> print(describe_effects(variant_effects("leakage")))
the paper's model (eqs. 1-4) with internal leakage (C_L = 5e-13 m³/(s·Pa))
>>> from eha_core.params import ActuatorParams
>>> ActuatorParams(effects=variant_effects("spool")).effects.n_states
6
>>> try:
...     variant_effects("stiction")
... except ValueError as error:          # a FieldError
...     print(error.field, error.value)
variant stiction
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

from ._checks import not_allowed

__all__ = ["Effects", "EFFECTS_OFF", "EFFECT_FIELDS", "EFFECT_UNITS", "EFFECT_NAMES", "Variant", "VARIANTS",
           "variant_effects", "describe_effects", "variant_name"]

#: The effects' parameters, in the order of :class:`Effects` and of the packed parameter vector's tail
#: (:data:`eha_core.model.PARAM_INDEX`).
EFFECT_FIELDS: tuple[str, ...] = ("omega_v", "zeta_v", "C_L", "F_c", "F_s", "v_s", "v_eps")
#: Each effect parameter's SI unit.
EFFECT_UNITS: dict[str, str] = {"omega_v": "rad/s", "zeta_v": "-", "C_L": "m³/(s·Pa)", "F_c": "N", "F_s": "N",
                                "v_s": "m/s", "v_eps": "m/s"}
#: The effects, in the order :attr:`Effects.active` and :func:`describe_effects` name them.
EFFECT_NAMES: tuple[str, ...] = ("spool", "leakage", "stribeck")


@dataclass(frozen=True)
class Effects:
    """The structural effects added to the paper's model, each off by default (docs/model.md §6).

    Parameters
    ----------
    omega_v : float
        Natural frequency of the valve's spool [rad/s] (eq. V1); 0 (default): the paper's
        instantaneous valve.
    zeta_v : float
        Damping ratio of the spool [-] (> 0; read only when ``omega_v > 0``).
    C_L : float
        Internal leakage coefficient [m³/(s·Pa)] (eq. V2): ``Q_L = C_L (p1 - p2)`` from chamber 1
        to chamber 2; 0 (default): none.
    F_c, F_s : float
        Coulomb and static levels of the Stribeck term [N] (eq. V3), added to the paper's
        ``Af S(v)``; ``0 <= F_c <= F_s``; both 0 (default): none.
    v_s : float
        Stribeck velocity [m/s] (> 0): the static level decays to the Coulomb one over it.
    v_eps : float
        Smoothing velocity of the Stribeck term's sign, ``tanh(v / v_eps)`` [m/s] (> 0); the
        default 1e-3 m/s is about the paper's 1/k_f (eq. 2).

    A value that is not allowed raises :class:`~eha_core._checks.FieldError` naming the field.
    """

    omega_v: float = 0.0
    zeta_v: float = 0.7
    C_L: float = 0.0
    F_c: float = 0.0
    F_s: float = 0.0
    v_s: float = 0.01
    v_eps: float = 1e-3

    def __post_init__(self):
        for name in EFFECT_FIELDS:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) and not _is_numpy_real(value):
                raise not_allowed(name, value, "must be a real number")
            if not math.isfinite(float(value)):
                raise not_allowed(name, value, "must be a finite number")
            # plain floats, so that equal effects hash equal (and the packed vector is what was given)
            object.__setattr__(self, name, float(value))
        for name, what in (("omega_v", "must be >= 0 rad/s (0: the paper's instantaneous valve)"),
                           ("C_L", "must be >= 0 m³/(s·Pa) (0: no internal leakage)"),
                           ("F_c", "must be >= 0 N (the Stribeck term's Coulomb level)")):
            if getattr(self, name) < 0:
                raise not_allowed(name, getattr(self, name), what)
        for name, what in (("zeta_v", "must be > 0 (the spool's damping ratio)"),
                           ("v_s", "must be > 0 m/s (the Stribeck velocity)"),
                           ("v_eps", "must be > 0 m/s (the smoothing velocity of the friction's sign)")):
            if getattr(self, name) <= 0:
                raise not_allowed(name, getattr(self, name), what)
        if self.F_s < self.F_c:
            raise not_allowed("F_s", self.F_s, f"the static level must be at least the Coulomb level "
                                               f"F_c = {self.F_c:.6g} N")

    @property
    def spool(self) -> bool:
        """Is the valve's spool dynamics on (eq. V1; two more states)?"""
        return self.omega_v > 0.0

    @property
    def leakage(self) -> bool:
        """Is the internal leakage on (eq. V2)?"""
        return self.C_L > 0.0

    @property
    def stribeck(self) -> bool:
        """Is the Stribeck term on (eq. V3)?"""
        return self.F_c != 0.0 or self.F_s != 0.0

    @property
    def active(self) -> tuple[str, ...]:
        """The names of the effects that are on, of :data:`EFFECT_NAMES`; empty: the paper's model."""
        return tuple(name for name in EFFECT_NAMES if getattr(self, name))

    @property
    def off(self) -> bool:
        """True when every effect is off: the paper's model, whatever the inactive parameters."""
        return not self.active

    @property
    def n_states(self) -> int:
        """The model's states: 4 (x, v, p1, p2), 6 with the spool (and u_v, du_v/dt)."""
        return 6 if self.spool else 4

    def packed(self) -> tuple[float, ...]:
        """The values in the order of :data:`EFFECT_FIELDS` (the packed parameter vector's tail)."""
        return tuple(getattr(self, name) for name in EFFECT_FIELDS)

    def to_dict(self) -> dict[str, float]:
        """The values by name (SI), JSON-ready; ``Effects(**e.to_dict()) == e``."""
        return {name: getattr(self, name) for name in EFFECT_FIELDS}

    def combined(self, other: Effects) -> Effects:
        """These effects with those that are on in ``other`` added (``other``'s values for them)."""
        changes = {}
        if other.spool:
            changes.update(omega_v=other.omega_v, zeta_v=other.zeta_v)
        if other.leakage:
            changes.update(C_L=other.C_L)
        if other.stribeck:
            changes.update(F_c=other.F_c, F_s=other.F_s, v_s=other.v_s, v_eps=other.v_eps)
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_value(cls, value) -> Effects:
        """``value`` as Effects: Effects as they are, None as :data:`EFFECTS_OFF`, a mapping (as
        :meth:`to_dict` writes it) by name, a variant's name as :func:`variant_effects` reads it.

        Parameters
        ----------
        value : Effects, None, mapping or str
            What to read.
        """
        if value is None:
            return EFFECTS_OFF
        if isinstance(value, Effects):
            return value
        if isinstance(value, str):
            return variant_effects(value)
        if isinstance(value, Mapping):
            unknown = sorted(set(value) - set(EFFECT_FIELDS))
            if unknown:
                raise not_allowed("effects", unknown[0], f"unknown effect parameter; known: {', '.join(EFFECT_FIELDS)}")
            return cls(**dict(value))
        raise not_allowed("effects", value, "give Effects, a mapping of its values, a variant's name or None")


def _is_numpy_real(value) -> bool:
    # numpy scalars without importing numpy here (the module stays light)
    return type(value).__module__ == "numpy" and hasattr(value, "dtype") and value.dtype.kind in "fiu"


#: Every effect off: the paper's model (the default of ActuatorParams.effects).
EFFECTS_OFF = Effects()


@dataclass(frozen=True)
class Variant:
    """A named actuator variant: its effects and what it is in one line."""

    name: str
    effects: Effects
    description: str


#: The named variants of the class exercise, each one effect at a size that shows on the paper's
#: actuator without dominating it (docs/model.md §6.4 says how each size was chosen).
VARIANTS: dict[str, Variant] = {
    "paper": Variant("paper", EFFECTS_OFF, "the paper's model: instantaneous valve, no internal leakage, "
                                           "viscous and Coulomb friction (eqs. 1-4)"),
    # 150 rad/s (24 Hz), ζ 0.7: 25° more phase lag at the open loop's pole at -45 rad/s, 5° at 10 rad/s;
    # between that pole and the one at -385 rad/s (eq. 23)
    "spool": Variant("spool", Effects(omega_v=150.0, zeta_v=0.7),
                     "a valve whose spool lags the command: second order, 150 rad/s (24 Hz), damping 0.7"),
    # with the valve shut and the piston held at mid-stroke the chambers' pressures equalise through the
    # leak in 1/(βe C_L (1/V1 + 1/V2)) = 2.5 s (free, in about a minute); holding still takes u_e = -0.03 V
    # (3 mm of steady error under Kp = 10 V/m); 3.3 cm³/s of leak, 1.2 % of the valve's flow at u = 2 V
    "leakage": Variant("leakage", Effects(C_L=5e-13),
                       "internal leakage past the piston: Q_L = C_L (p1 - p2), C_L = 5e-13 m³/(s·Pa)"),
    # the friction below a few mm/s is up to Af + F_s = 4500 N, falling to the paper's Af = 3000 N above
    # ~10 mm/s (the paper's cases reach 70 mm/s)
    "stribeck": Variant("stribeck", Effects(F_c=0.0, F_s=1500.0, v_s=0.005, v_eps=1e-3),
                        "Stribeck friction: up to 1500 N more at low speed, fading over 5 mm/s to the paper's "
                        "Coulomb level"),
}


def variant_effects(name: str) -> Effects:
    """The effects of the variant ``name`` of :data:`VARIANTS`; several joined by ``+``
    (``"spool+leakage"``) have the effects of each.

    Parameters
    ----------
    name : str
        A key of :data:`VARIANTS`, or several joined by ``+``.

    Raises
    ------
    FieldError
        ``variant = NAME is not allowed`` for a name that is not one, with the names that are.
    """
    allowed = f"use one of {', '.join(VARIANTS)} (or several joined by +, e.g. spool+leakage)"
    if not isinstance(name, str):
        raise not_allowed("variant", name, allowed)
    parts = [part.strip() for part in name.split("+")]
    effects = EFFECTS_OFF
    for part in parts:
        if part not in VARIANTS:
            raise not_allowed("variant", name, allowed)
        effects = effects.combined(VARIANTS[part].effects)
    return effects


def variant_name(effects: Effects) -> str | None:
    """The name of the variant of :data:`VARIANTS` whose effects are ``effects`` (all off: ``"paper"``),
    or None.

    Parameters
    ----------
    effects : Effects
        The effects to name.
    """
    if effects.off:
        return "paper"
    for name, variant in VARIANTS.items():
        if variant.effects == effects:
            return name
    return None


def describe_effects(effects: Effects | None) -> str:
    """Which effects a model assumes, in one line: the paper's model, or the paper's with each effect
    that is on and its values.

    Parameters
    ----------
    effects : Effects or None
        The effects (None: all off).

    Examples
    --------
    >>> describe_effects(None)
    "the paper's model (eqs. 1-4): instantaneous valve, no internal leakage, friction B v + Af S(v)"
    >>> describe_effects(Effects(F_s=1500.0, v_s=0.005))
    "the paper's model (eqs. 1-4) with Stribeck friction (F_c = 0 N, F_s = 1500 N, v_s = 0.005 m/s, v_eps = 0.001 m/s)"
    """
    effects = Effects.from_value(effects)
    if effects.off:
        return "the paper's model (eqs. 1-4): instantaneous valve, no internal leakage, friction B v + Af S(v)"
    words = []
    if effects.spool:
        words.append(f"a second-order valve spool (ω_v = {effects.omega_v:.6g} rad/s, ζ_v = {effects.zeta_v:.6g})")
    if effects.leakage:
        words.append(f"internal leakage (C_L = {effects.C_L:.6g} m³/(s·Pa))")
    if effects.stribeck:
        words.append(f"Stribeck friction (F_c = {effects.F_c:.6g} N, F_s = {effects.F_s:.6g} N, "
                     f"v_s = {effects.v_s:.6g} m/s, v_eps = {effects.v_eps:.6g} m/s)")
    listed = words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]
    return f"the paper's model (eqs. 1-4) with {listed}"
