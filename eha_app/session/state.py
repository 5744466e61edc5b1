"""Per-session application state: what the user typed, validated parameters, results.

One :class:`AppState` per browser session (``create_app`` builds a new one),
so students never see each other's values. The numbers are entered as text in
display units (MPa, mm, GPa...) and checked here in those units, so that a
typo gets a message beside the widget that reads like the form: the field's
label, the value as typed with its display unit, and what is allowed.

A rule that ties fields together (dc < Dc, pr < ps, |x(0)| <= 0.8 L0, p1(0)
and p2(0) within [pr, ps], the force balance of the linearised model's
operating point) puts its message on the field the student typed last among
those it ties, and names the others with their values.

Examples
--------
>>> from eha_app.session.state import AppState
>>> s = AppState()
>>> s.set_text("M", "-5")
>>> s.valid, s.errors["M"]
(False, 'M = -5 kg is not allowed: must be > 0 kg (load mass)')
>>> s.set_text("M", "5000")
>>> s.valid, s.params.M
(True, 5000.0)
>>> s.set_text("ps", "10")
>>> s.errors["ps"]
'ps = 10 MPa is not allowed: the supply pressure must be at least the initial piston-chamber pressure p1(0) = 12 MPa'
"""

from __future__ import annotations

import math

import numpy as np
import param

from eha_core.errors import FieldError
from eha_core.linear import linearize, operating_point
from eha_core.param_table import DERIVED, FieldInfo, broken_rules
from eha_core.params import (
    FIELD_INFO,
    PARAM_NAMES,
    ActuatorParams,
    ParameterError,
)

__all__ = ["AppState", "FIELD_LABELS", "FORM_FIELDS", "KP_INFO", "DEFAULT_KP", "MAX_TEXT_CHARS", "display_text",
           "parse_display", "cross_field_errors", "shown_text"]

#: The most characters a field may hold. Every field goes into the page's address as it is
#: typed (a reload restores it): a 70,000-character field once made the address too long for
#: the server to load the page again.
MAX_TEXT_CHARS = 200


def shown_text(text: str, limit: int = 24) -> str:
    """A typed text as a message repeats it: whole, or its start when it is long."""
    text = str(text).strip()
    return text if len(text) <= limit else text[:limit] + "…"


def too_long(text) -> str | None:
    """What is wrong with a text of more than :data:`MAX_TEXT_CHARS` characters (None if it is not)."""
    n = len(str(text or ""))
    return f"at most {MAX_TEXT_CHARS} characters (it has {n})" if n > MAX_TEXT_CHARS else None

#: The controller's gain Kp of tab 1 (eq. 22): a field like the actuator's parameters, in the same
#: table's terms, but of the loop that H(s) closes rather than of the actuator.
KP_INFO = FieldInfo("V/m", "proportional gain", "V/m", 1.0, "initial", "Kp", ">")
#: Tab 1's fields: the actuator's parameters (the core's table of parameter facts) and Kp.
FORM_FIELDS: dict[str, FieldInfo] = {**FIELD_INFO, "kp": KP_INFO}
#: The names tab 1's form shows, which its messages use too.
FIELD_LABELS = {name: info.label for name, info in FORM_FIELDS.items()}
#: The controller gain as the page opens [V/m].
DEFAULT_KP = 10.0


def display_text(name: str, value_si: float | None) -> str:
    """A field's SI value written in its display unit."""
    if value_si is None:
        return ""
    return f"{value_si / FORM_FIELDS[name].display_scale:.6g}"


def parse_display(name: str, text: str) -> float | None:
    """Parse text typed in display units into SI; None for a blank p2_0 (force balance).

    Raises ParameterError naming the field when the text is not a number.
    """
    info = FORM_FIELDS[name]
    if too_long(text):
        raise ParameterError(name, shown_text(text), too_long(text))
    text = (text or "").strip().replace(",", ".") if text is not None else ""
    if text == "":
        if name == "p2_0":
            return None
        raise ParameterError(name, "(empty)", f"enter a number in {info.display_unit}")
    try:
        value = float(text)
    except ValueError:
        raise ParameterError(name, text, f"must be a number in {info.display_unit}") from None
    if not math.isfinite(value):
        raise ParameterError(name, text, f"must be a finite number in {info.display_unit}")
    return value * info.display_scale


# -- messages in display units ------------------------------------------------------------------

def _unit(name: str) -> str:
    return FORM_FIELDS[name].display_unit


def _quantity(number: str, name: str) -> str:
    """``"130 mm"``; a unit that starts with a factor reads ``"3 × 1e-8 m³/(s V √Pa)"``."""
    unit = _unit(name)
    return f"{number} × {unit}" if unit[:1].isdigit() else f"{number} {unit}"


def _refusal(name: str, value: str, what: str) -> str:
    """The project's one form of a message, with the label the form shows (``value`` as typed)."""
    return str(FieldError(FIELD_LABELS.get(name, name), value, what, value_text=value))


def _bound(name: str, relation: str, description: str) -> str:
    """``"must be > 0 mm (cylinder bore diameter)"`` (no unit after a bare 0 when it starts with a factor)."""
    unit = _unit(name)
    zero = "0" if unit[:1].isdigit() else f"0 {unit}"
    return f"must be {relation} {zero} ({description})"


class _Named:
    """How messages name fields: their labels and their values as typed, in display units."""

    def __init__(self, texts: dict):
        self.texts = texts

    def typed(self, name: str) -> str:
        """``"130 mm"``: the value of a field as typed, with its unit."""
        return _quantity(str(self.texts.get(name, "")).strip(), name)

    def ref(self, name: str) -> str:
        """``"Dc = 120 mm"``."""
        return f"{FIELD_LABELS[name]} = {self.typed(name)}"

    def value(self, name: str, value_si: float) -> str:
        """A computed value in the display unit of ``name`` (four significant digits)."""
        return _quantity(f"{value_si / FIELD_INFO[name].display_scale:.4g}", name)

    def pressures(self) -> str:
        """``"[pr, ps] = [0, 32] MPa"``."""
        pr, ps = (str(self.texts.get(n, "")).strip() for n in ("pr", "ps"))
        return f"[pr, ps] = [{pr}, {ps}] {FIELD_INFO['ps'].display_unit}"


class _Quantities:
    """``{value[x_max]}`` of a rule's words: a derived quantity in the display unit the core's table names."""

    def __init__(self, values: dict, n: _Named):
        self.values, self.n = values, n

    def __getitem__(self, name: str) -> str:
        derived = DERIVED[name]
        return self.n.value(derived.shown_as, derived.compute(self.values))


class _Refs:
    """``{ref[Dc]}`` of a rule's words: ``"Dc = 120 mm"``."""

    def __init__(self, n: _Named):
        self.n = n

    def __getitem__(self, name: str) -> str:
        return self.n.ref(name)


def _rules(v: dict, n: _Named) -> list[dict]:
    """The broken rules among those that tie fields together (the core's table, eha_core.param_table.RULES).

    Each is ``{field: what to say on it}`` for every field it may be put on, its own field first, worded
    from the table's templates with the fields as typed, in display units.
    """
    words = {"ref": _Refs(n), "value": _Quantities(v, n), "pressures": n.pressures()}
    return [{field: template.format(**words) for field, template in rule.sayings(v)} for rule in broken_rules(v)]


def cross_field_errors(values: dict, texts: dict, typed=()) -> dict[str, str]:
    """Messages of the broken rules that tie fields together, by the field each is put on.

    ``values`` are the fields in SI (each valid on its own), ``texts`` as typed
    (display units), ``typed`` the field names in the order they were typed: a
    message goes on the field typed last among those its rule ties, else on the
    rule's own field (the one :class:`ActuatorParams` names; p1(0) for the
    force balance, whose p2(0) box is blank).
    """
    n = _Named(texts)
    recency = {name: i for i, name in enumerate(typed)}
    errors: dict[str, str] = {}
    for rule in _rules(values, n):
        target = max(rule, key=lambda name: recency.get(name, -1))
        if target not in errors:
            errors[target] = _refusal(target, n.typed(target), rule[target])
    return errors


def _field_errors(texts: dict, secret: dict | None = None) -> tuple[dict, dict]:
    """Each field on its own: (SI values of those that are valid, messages of the others).
    ``secret``: the hidden parameters' values (an exercise), taken as they are."""
    values, errors = dict(secret or {}), {}
    for name, info in FORM_FIELDS.items():
        if name in values:
            continue
        try:
            value = parse_display(name, texts.get(name, ""))
        except ParameterError as exc:
            errors[name] = _refusal(name, str(exc.value).strip() or "(empty)", exc.allowed)
            continue
        relation = info.bound
        if relation is not None and not (value > 0 if relation == ">" else value >= 0):
            typed = _quantity(str(texts[name]).strip(), name)
            errors[name] = _refusal(name, typed, _bound(name, relation, info.description))
            continue
        values[name] = value
    return values, errors


# where a core message the app's rules missed is shown: the operating point's names are the initial state's
_CORE_FIELD = {"x_e": "x0", "p1_e": "p1_0", "p2_e": "p1_0"}


def _build(values: dict) -> tuple[ActuatorParams | None, dict]:
    """The parameter set, checked by the core too (its message, in SI, only if the app's rules missed one)."""
    try:
        params = ActuatorParams(**values)
        operating_point(params)         # the linearised model the first tab shows needs one
    except ParameterError as exc:
        return None, {_CORE_FIELD.get(exc.field, exc.field): str(exc)}
    return params, {}


def _not_computable(params: ActuatorParams, kp: float) -> str | None:
    """Why tab 1 could not show this set's derived values (λ, a1..a10, P(s), H(s) and their poles),
    or None: numbers each allowed on its own can overflow together (βe = 1e308 GPa makes λ4
    infinite), and a student must be told so beside the field rather than see a page that
    stops following."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):     # an overflow is the answer
        lin = linearize(params)
        num, den = lin.tf_coeffs()
        cnum, cden = lin.closed_loop_coeffs(kp)
        numbers = [*lin.lambdas, *lin.lambdas_negative, *params.a.values(), *num, *den, *cnum, *cden]
    if all(math.isfinite(float(v)) for v in numbers):
        try:
            np.roots(den), np.roots(cden)
            return None
        except np.linalg.LinAlgError:
            pass
    return ("with the other values, the linearised model's coefficients (λ, a1..a10, P(s), H(s)) are not "
            "finite numbers; use the values of a physical actuator")


class AppState(param.Parameterized):
    """State of one session. The tabs read and write it; the core computes."""

    texts = param.Dict(default={}, doc="what the user typed, by field, in display units")
    params = param.ClassSelector(class_=ActuatorParams, doc="the last valid parameter set (SI)")
    errors = param.Dict(default={}, doc="messages by field name; empty when the inputs are valid")
    valid = param.Boolean(default=True, doc="all inputs valid: run buttons are enabled")
    kp = param.Number(default=DEFAULT_KP, doc="the controller's proportional gain for H(s) [V/m] (the last valid)")
    revision = param.Integer(default=0, doc="bumped whenever the valid parameters change")
    # An exercise (eha serve --exercise): the student's id, and the values of the hidden
    # parameters, which the server uses and never sends (their texts read "hidden").
    student = param.String(default="", doc="the student's normalised id in an exercise")
    student_name = param.String(default="", doc="the student's name in the exercise's roster (\"\" without one)")
    secret = param.Dict(default={}, doc="hidden parameters' SI values: used, never shown")
    exercise = param.Parameter(default=None, doc="the eha_core.exercise.Exercise being run, if any")
    handins = param.Parameter(default=None, doc="where the exercise's hand-ins go (eha_app.runtime.handins.HandIns)")

    def __init__(self, **kwargs):
        # the fields in the order they were last typed (the last typed last)
        self._typed: list[str] = []
        super().__init__(**kwargs)
        self.reset_defaults()

    def __repr__(self) -> str:
        # Param's repr lists every parameter: the parameters (hidden ones included) and the
        # exercise with its key would go into any log line or traceback that shows the state
        return f"<AppState {self.name}{' (exercise)' if self.secret else ''}>"

    __str__ = __repr__

    # -- inputs ------------------------------------------------------------------
    @property
    def hidden(self) -> tuple[str, ...]:
        """The parameters an exercise hides (none outside one)."""
        return tuple(self.secret)

    def start_exercise(self, exercise, student_id: str, handins=None, name: str = "") -> None:
        """Run ``exercise`` as ``student_id`` (the roster's id of a checked code, or the id typed in an
        open exercise): their actuator, its hidden values kept here. (The page notes them as here in
        the store, off the event loop: :meth:`eha_app.app.Page._join`.)"""
        from eha_core.exercise import normalize_id

        student = normalize_id(student_id)
        actuator = exercise.student_params(student)
        import hashlib

        from ..runtime.redaction import keep_out_of_logs, register_student

        self.exercise = exercise
        self.handins = handins
        self.student = student
        self.student_name = name
        self.secret = {n: getattr(actuator, n) for n in exercise.hide}
        keep_out_of_logs(exercise.secret)
        # the student's hidden values are kept out of the log while a page of theirs is open (a registration
        # per page, released when it closes or gives way: the log's guard does not grow all day)
        self.forget_secrets()
        key = hashlib.sha256(exercise.secret.encode()).hexdigest()[:16]
        self._log_hold = register_student(key, student, self.secret.values())
        self.reset_defaults()

    def forget_secrets(self) -> None:
        """Release this page's hold on the log's guard of the student's hidden values (the page closed)."""
        hold = getattr(self, "_log_hold", None)
        if hold is not None:
            hold.release()
            self._log_hold = None

    def known_params(self) -> ActuatorParams:
        """The parameters a route may take as known on a record that is not the student's own
        actuator's experiment (an uploaded file): tab 1's, each hidden one at the paper's value.

        The hidden values are the truth of the student's actuator. Used as known on a file whose
        origin the student knows, they come back out of the estimates: the least squares' βe is a
        fixed function of L0, and one run on the paper's own record gave a hidden L0 to six digits.
        On the student's simulated record they are the experiment itself, and stay.

        Raises :class:`ParameterError` when the paper's values break a rule with what the student
        typed (a rod the student made wider than the paper's bore)."""
        if not self.secret:
            return self.params
        paper = ActuatorParams()
        return self.params.replace(**{n: getattr(paper, n) for n in self.secret})

    @property
    def kp_text(self) -> str:
        """Kp as typed."""
        return self.texts.get("kp", "")

    def reset_defaults(self) -> None:
        """Back to the paper's parameters (docs/model.md §2) and Kp = 10 V/m; an exercise's hidden ones stay."""
        defaults = {**ActuatorParams().to_dict(), "kp": DEFAULT_KP}
        self._typed = []
        self.kp = DEFAULT_KP
        self.texts = {n: "hidden" if n in self.secret else display_text(n, defaults[n]) for n in FORM_FIELDS}
        self._revalidate()

    def set_text(self, name: str, text: str) -> None:
        """Record what was typed into a field and revalidate everything."""
        if name in self.secret:
            return                          # a hidden parameter is not the student's to set
        if name not in FORM_FIELDS:
            raise KeyError(name)
        self.texts = {**self.texts, name: text}
        self._typed = [n for n in self._typed if n != name] + [name]
        self._revalidate()

    def _revalidate(self) -> None:
        values, errors = _field_errors(self.texts, self.secret)
        kp = values.pop("kp", None)
        new_params = None
        if len(values) == len(PARAM_NAMES):
            rules = cross_field_errors(values, self.texts, self._typed)
            errors.update(rules)
            if not rules:
                new_params, core = _build(values)
                errors.update(core)
        # what tab 1 would draw: the new parameters (or the last valid ones) with the new Kp (or the last)
        candidate = new_params if new_params is not None else self.params
        if candidate is not None and (why := _not_computable(candidate, kp if kp is not None else self.kp)):
            # on the field typed last (the one that tipped it), in the words of that field
            target = self._typed[-1] if self._typed else "M"
            errors[target] = _refusal(target, _quantity(str(self.texts[target]).strip(), target), why)
            new_params = kp = None
        with param.parameterized.batch_call_watchers(self):
            self.errors = errors
            self.valid = not errors
            if kp is not None:
                self.kp = kp
            if new_params is not None and new_params != self.params:
                self.params = new_params
                self.revision += 1
