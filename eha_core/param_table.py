"""The facts of every physical parameter, written once: the table the core and the app both read.

For each field of :class:`eha_core.params.ActuatorParams` (:data:`FIELD_INFO`,
in the order of the form and of ``--param``): its symbol as the app shows it,
its SI unit, the display unit and scale, what it is, its group on the form,
and its bound (none, > 0, >= 0). Then the quantities derived from the fields
(:data:`DERIVED`: the areas, the end stop, the force balance), the layout of
the packed vector the compiled model reads (:data:`PACKED`), and the rules
that tie fields together (:data:`RULES`), each with the fields it ties, a
predicate on the SI values and the words of both messages: the core's, in
SI (:class:`ActuatorParams` raises it), and the app's, in display units, one
for each field it may be put on.

The app's words are templates (:meth:`str.format`) that the app fills in
with its own rendering of the fields as typed:

* ``{ref[NAME]}``: a field and its value as typed, ``Dc = 120 mm``;
* ``{value[QUANTITY]}``: a derived quantity in the display unit of the field
  :data:`DERIVED` names, ``240 mm``;
* ``{pressures}``: the pressure range as typed, ``[pr, ps] = [0, 32] MPa``.

The core's are templates on the SI values and the derived quantities
(``{Dc:.6g}``, ``{x_max:.6g}``).

Only :mod:`math` is imported here.

Examples
--------
>>> from eha_core.param_table import FIELD_INFO, RULES, broken_rules
>>> FIELD_INFO["beta_e"].label, FIELD_INFO["beta_e"].display_unit, FIELD_INFO["beta_e"].bound
('βe', 'GPa', '>')
>>> values = {"Dc": 0.12, "dc": 0.13, "pr": 0.0, "ps": 32e6}
>>> [rule.name for rule in broken_rules(values, RULES[:3])]
['rod inside the bore']
>>> RULES[1].refusal(values)
('dc', 0.13, 'the rod diameter must be smaller than the bore Dc = 0.12 m')
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass

__all__ = [
    "physically_possible",
    "FieldInfo",
    "FIELD_INFO",
    "PARAM_NAMES",
    "POSITIVE_FIELDS",
    "NON_NEGATIVE_FIELDS",
    "Derived",
    "DERIVED",
    "PACKED",
    "Saying",
    "Rule",
    "RULES",
    "PAPER_SOURCES",
    "broken_rules",
    "piston_area",
    "rod_area",
    "end_stop",
    "force_balance",
]

Values = Mapping[str, "float | None"]


@dataclass(frozen=True)
class FieldInfo:
    """The facts of one parameter: unit, meaning, display scaling, label and bound."""

    unit: str
    description: str
    display_unit: str
    display_scale: float  # value_in_display_unit = value_SI / display_scale
    group: str  # "main", "advanced" or "initial"
    label: str = ""  # the symbol the app's form and messages show ("βe")
    bound: str | None = None  # ">" (> 0), ">=" (>= 0) or None


_M3 = "m^3/(s V sqrt(Pa))"
_KQ = "1e-8 m³/(s V √Pa)"

#: Every parameter, in the order of ActuatorParams' fields, the form and ``--param``.
FIELD_INFO: dict[str, FieldInfo] = {
    "M": FieldInfo("kg", "load mass", "kg", 1.0, "main", "M", ">"),
    "B": FieldInfo("N s/m", "viscous friction coefficient", "N s/m", 1.0, "main", "B", ">="),
    "Af": FieldInfo("N", "Coulomb friction amplitude", "N", 1.0, "main", "Af", ">="),
    "beta_e": FieldInfo("Pa", "effective bulk modulus of the oil", "GPa", 1e9, "main", "βe", ">"),
    "Dc": FieldInfo("m", "cylinder bore diameter", "mm", 1e-3, "main", "Dc", ">"),
    "dc": FieldInfo("m", "piston rod diameter", "mm", 1e-3, "main", "dc", ">"),
    "d0": FieldInfo("N", "slow (constant) load disturbance", "N", 1.0, "main", "d0"),
    "L0": FieldInfo("m", "chamber length at x = 0", "mm", 1e-3, "advanced", "L0", ">"),
    "Kq1": FieldInfo(_M3, "valve flow gain, piston side", _KQ, 1e-8, "advanced", "Kq1", ">"),
    "Kq2": FieldInfo(_M3, "valve flow gain, rod side", _KQ, 1e-8, "advanced", "Kq2", ">"),
    "ps": FieldInfo("Pa", "supply pressure", "MPa", 1e6, "advanced", "ps", ">"),
    "pr": FieldInfo("Pa", "return (tank) pressure", "MPa", 1e6, "advanced", "pr", ">="),
    "k_f": FieldInfo("s/m", "friction slope of S(v) = (2/pi) atan(k_f v)", "s/m", 1.0, "advanced", "kf", ">="),
    "x0": FieldInfo("m", "initial piston position", "mm", 1e-3, "initial", "x(0)"),
    "v0": FieldInfo("m/s", "initial piston velocity", "mm/s", 1e-3, "initial", "v(0)"),
    "p1_0": FieldInfo("Pa", "initial piston-chamber pressure", "MPa", 1e6, "initial", "p1(0)"),
    "p2_0": FieldInfo("Pa", "initial rod-chamber pressure (blank: force balance)", "MPa", 1e6, "initial", "p2(0)"),
}

#: Where each default comes from in the paper (two are inferred from its eq. 23; d0 and the
#: initial state are the experiments' own).
PAPER_SOURCES: dict[str, str] = {
    "M": "Table 3", "B": "Table 3", "Af": "Table 3", "beta_e": "Table 3", "Dc": "Table 3", "dc": "Table 3",
    "d0": "Table 3 (no slow load)", "L0": "inferred from eq. 23's s coefficient",
    "Kq1": "inferred from eq. 23's gain", "Kq2": "inferred from eq. 23's gain", "ps": "Table 1", "pr": "Table 1",
    "k_f": "eq. 2", "x0": "section II-A", "v0": "section II-A", "p1_0": "section II-A",
    "p2_0": "section II-A: the force balance",
}

#: Names accepted by ``--param NAME=VALUE`` and by :meth:`ActuatorParams.replace`.
PARAM_NAMES: tuple[str, ...] = tuple(FIELD_INFO)

#: Fields that must be > 0, and fields that must be >= 0, from the table's bounds, in the order
#: ActuatorParams checks them (it reports the first broken one): the table's, except that the
#: friction law's k_f (eq. 2) has always been checked before the return pressure pr. The other
#: rules (:data:`RULES`) each tie two fields or more together.
POSITIVE_FIELDS: tuple[str, ...] = tuple(n for n, f in FIELD_INFO.items() if f.bound == ">")
NON_NEGATIVE_FIELDS: tuple[str, ...] = tuple(sorted((n for n, f in FIELD_INFO.items() if f.bound == ">="),
                                                    key=lambda n: n == "pr"))


def physically_possible(name: str, value: float) -> bool:
    """Is ``value`` finite and within the physical bound of field ``name`` (> 0 or >= 0; a field
    without one, or no field, only needs to be finite)?

    >>> physically_possible("B", -1626.0), physically_possible("B", 0.0), physically_possible("beta_e", 0.0)
    (False, True, False)
    """
    value = float(value)
    if not math.isfinite(value):
        return False
    bound = FIELD_INFO[name].bound if name in FIELD_INFO else None
    return not ((bound == ">" and value <= 0) or (bound == ">=" and value < 0))


# -- quantities derived from the fields ----------------------------------------------------------

def piston_area(v: Values) -> float:
    """Piston-side effective area ``A1 = pi Dc^2 / 4`` [m^2], from the SI values ``v`` by field name."""
    return math.pi * (v["Dc"] * v["Dc"]) / 4.0    # not **: a float overflows there with an exception


def rod_area(v: Values) -> float:
    """Rod-side effective area ``A2 = pi (Dc^2 - dc^2) / 4`` [m^2], from the SI values ``v`` by field name."""
    return math.pi * (v["Dc"] * v["Dc"] - v["dc"] * v["dc"]) / 4.0


def end_stop(v: Values) -> float:
    """End stop ``x_max = 0.8 L0``: ``|x| <= x_max`` [m], from the SI values ``v`` by field name."""
    return 0.8 * v["L0"]


def force_balance(v: Values) -> float:
    """The rod pressure that holds the piston still, ``(A1 p1_0 - d0) / A2`` (section II-A, eq. 10) [Pa],
    from the SI values ``v`` by field name."""
    return (piston_area(v) * v["p1_0"] - v["d0"]) / rod_area(v)


@dataclass(frozen=True)
class Derived:
    """A quantity computed from the fields, and the field whose display unit shows it."""

    compute: Callable[[Values], float]
    shown_as: str


#: The derived quantities the packed vector and the rules' messages use.
DERIVED: dict[str, Derived] = {
    "A1": Derived(piston_area, "Dc"),
    "A2": Derived(rod_area, "Dc"),
    "x_max": Derived(end_stop, "x0"),
    "balance": Derived(force_balance, "p2_0"),
}

#: The packed parameter vector the compiled model reads by index (:func:`eha_core.model.pack_params`):
#: fields and derived quantities, in this order.
PACKED: tuple[str, ...] = ("M", "B", "Af", "beta_e", "A1", "A2", "L0", "Kq1", "Kq2", "ps", "pr", "k_f", "x_max",
                           "d0")


# -- rules that tie fields together ----------------------------------------------------------------

@dataclass(frozen=True)
class Saying:
    """The app's message of a broken rule on one field: a template, said only ``when`` it holds (None: always)."""

    field: str
    template: str
    when: Callable[[Values], bool] | None = None


def _always(_v: Values) -> bool:
    return True


@dataclass(frozen=True)
class Rule:
    """A rule that ties fields together.

    Attributes
    ----------
    name : str
        What it requires, in words.
    fields : tuple of str
        The fields it ties, its own first: the one the app's message goes on
        when none of them was typed.
    holds : callable
        ``holds(values)`` on the SI values (``p2_0`` None for the force balance).
    applies : callable
        Whether the rule is checked for these values (default: always).
    core : str or None
        The core's WHAT, a template on the SI values and :data:`DERIVED`
        (``"... Dc = {Dc:.6g} m"``); None for a rule the parameter set does
        not check (the linearisation's operating point checks it).
    core_field, core_value : str
        The field the core's message names and the quantity it shows (a field
        or a derived quantity); default the rule's own field.
    says : tuple of Saying
        The app's messages on the fields it may be put on (a field may have
        one for each side of a range, each said ``when`` it holds), in the
        order of :attr:`fields`: :meth:`sayings` picks those for given values.
    """

    name: str
    fields: tuple[str, ...]
    holds: Callable[[Values], bool]
    core: str | None
    says: tuple[Saying, ...]
    applies: Callable[[Values], bool] = _always
    core_field: str = ""
    core_value: str = ""

    def quantities(self, v: Values) -> dict[str, float | None]:
        """The SI values ``v`` (by field name) with the derived quantities (those that can be computed here)."""
        out = dict(v)
        for name, derived in DERIVED.items():
            try:
                out[name] = derived.compute(v)
            except (KeyError, TypeError, ZeroDivisionError):
                pass                   # not needed by this rule's words (or not defined here)
        return out

    def refusal(self, v: Values) -> tuple[str, float | None, str]:
        """``(field, value, what)`` of the core's message (in SI) for values ``v`` (SI, by field name)
        that break the rule."""
        q = self.quantities(v)
        field = self.core_field or self.fields[0]
        return field, q[self.core_value or field], self.core.format(**q)

    def sayings(self, v: Values) -> list[tuple[str, str]]:
        """``(field, template)`` of the app's messages for values ``v`` (SI, by field name) that break
        the rule, in order."""
        return [(s.field, s.template) for s in self.says if s.when is None or s.when(v)]


def _above(quantity: Callable[[Values], float]) -> Callable[[Values], bool]:
    return lambda v: quantity(v) > v["ps"]


def _below(quantity: Callable[[Values], float]) -> Callable[[Values], bool]:
    return lambda v: quantity(v) < v["pr"]


def _within_pressures(name: str, own: str, quantity: Callable[[Values], float], *, core: str | None,
                      own_says: Iterable[Saying], what: str, applies=_always, core_field: str = "",
                      core_value: str = "", sides: Iterable[tuple[str, str]] = ()) -> Rule:
    """``pr <= quantity <= ps``: the app says ``own_says`` on the fields it ties, and, when the quantity is above
    ps (below pr), that the supply (return) pressure must be at least (at most) ``what``. ``sides``: fields
    whose message names the side the quantity left by ``{side}``."""
    above, below = _above(quantity), _below(quantity)
    says = list(own_says)
    for field, template in sides:
        # one side is named: above ps when it is (pr > ps is the rule before)
        says.append(Saying(field, template.replace("{side}", "above the supply pressure {ref[ps]}"), above))
        says.append(Saying(field, template.replace("{side}", "below the return pressure {ref[pr]}"),
                           lambda v: not above(v)))
    says += [Saying("ps", f"the supply pressure must be at least {what}", above),
             Saying("pr", f"the return pressure must be at most {what}", below)]
    fields = tuple(dict.fromkeys([own, *(s.field for s in says)]))
    return Rule(name, fields, lambda v: v["pr"] <= quantity(v) <= v["ps"], core, tuple(says), applies,
                core_field, core_value)


def _field(name: str) -> Callable[[Values], float]:
    return lambda v: v[name]


def _p2_typed(v: Values) -> bool:
    return v["p2_0"] is not None


def _balance_defined(v: Values) -> bool:
    # without dc < Dc there is no rod-side area to balance with (that rule is broken first)
    return v["dc"] < v["Dc"]


_PRESSURES = "[pr, ps] = [{pr:.6g}, {ps:.6g}] Pa"
_BALANCE = "(A1 p1(0) − d0)/A2 = {value[balance]}"
_CHANGE = ("p1_0", "d0", "Dc", "dc")

#: The rules that tie fields together, in the order they are checked (ActuatorParams raises the first
#: broken one; the app shows each broken one on one field).
RULES: tuple[Rule, ...] = (
    # a bore typed at 1e200 m is a positive number, but its area A1 = pi Dc^2 / 4 is not one
    Rule("bore area finite", ("Dc",), lambda v: math.isfinite(piston_area(v)),
         core="the bore is too large: its area pi Dc^2 / 4 is not a finite number",
         says=(Saying("Dc", "the bore is too large: its area π Dc²/4 is not a finite number"),)),
    Rule("rod inside the bore", ("dc", "Dc"), lambda v: v["dc"] < v["Dc"],
         core="the rod diameter must be smaller than the bore Dc = {Dc:.6g} m",
         says=(Saying("dc", "the rod diameter must be smaller than the bore {ref[Dc]}"),
               Saying("Dc", "the bore must be larger than the rod diameter {ref[dc]}"))),
    Rule("return below supply", ("pr", "ps"), lambda v: v["pr"] < v["ps"],
         core="the return pressure must be below the supply pressure ps = {ps:.6g} Pa",
         says=(Saying("pr", "the return pressure must be below the supply pressure {ref[ps]}"),
               Saying("ps", "the supply pressure must be above the return pressure {ref[pr]}"))),
    Rule("within the end stops", ("x0", "L0"), lambda v: abs(v["x0"]) <= end_stop(v),
         core="must lie within the end stops [-{x_max:.6g}, {x_max:.6g}] m (|x0| <= 0.8 L0)",
         says=(Saying("x0", "the initial position must lie within the end stops ±0.8 L0 = ±{value[x_max]} "
                            "({ref[L0]})"),
               Saying("L0", "the end stops ±0.8 L0 = ±{value[x_max]} must hold the initial position {ref[x0]}"))),
    _within_pressures(
        "initial piston-chamber pressure within [pr, ps]", "p1_0", _field("p1_0"),
        core=f"must lie within {_PRESSURES}",
        own_says=[Saying("p1_0", "the initial piston-chamber pressure must lie within {pressures}")],
        what="the initial piston-chamber pressure {ref[p1_0]}"),
    _within_pressures(
        "initial rod-chamber pressure within [pr, ps]", "p2_0", _field("p2_0"), applies=_p2_typed,
        core=f"must lie within {_PRESSURES}",
        own_says=[Saying("p2_0", "the initial rod-chamber pressure must lie within {pressures}")],
        what="the initial rod-chamber pressure {ref[p2_0]}"),
    # p2(0) blank: the initial rod pressure is the force balance, which must lie within [pr, ps]
    _within_pressures(
        "force balance within [pr, ps]", "p1_0", force_balance,
        applies=lambda v: not _p2_typed(v) and _balance_defined(v),
        core=f"the force balance (A1 p1_0 - d0)/A2 must lie within {_PRESSURES}; change p1_0 or d0, or set p2_0",
        core_field="p2_0", core_value="balance", own_says=(),
        sides=[(f, f"the force balance then gives the initial rod-chamber pressure p2(0) = {_BALANCE}, {{side}}; "
                   "change p1(0) or d0, or type p2(0)") for f in _CHANGE],
        what=f"the initial rod-chamber pressure p2(0) = {_BALANCE} (force balance)"),
    # p2(0) typed: the linearised model's operating point (eq. 10) still takes the rod pressure from the force
    # balance; eha_core.linear.operating_point refuses it (the parameter set itself is valid)
    _within_pressures(
        "operating point's force balance within [pr, ps]", "p1_0", force_balance,
        applies=lambda v: _p2_typed(v) and _balance_defined(v), core=None, own_says=(),
        sides=[(f, f"the linearised model's operating point (eq. 10) then has the rod-chamber pressure {_BALANCE}, "
                   "{side}; change p1(0) or d0") for f in _CHANGE],
        what=f"the rod-chamber pressure of the linearised model's operating point, {_BALANCE}"),
)


def broken_rules(v: Values, rules: Iterable[Rule] = RULES) -> Iterator[Rule]:
    """The rules among ``rules`` that apply to the SI values ``v`` and do not hold, in order."""
    for rule in rules:
        if rule.applies(v) and not rule.holds(v):
            yield rule
