"""Per-session application state: what the user typed, validated parameters, results.

One :class:`AppState` per browser session (``create_app`` builds a new one),
so students never see each other's values. The numbers are entered as text in
display units (MPa, mm, GPa...) and parsed here, so that a typo gets a message
naming the field, the value and what is allowed, shown beside the widget.

Examples
--------
>>> from eha_app.state import AppState
>>> s = AppState()
>>> s.set_text("M", "-5")
>>> s.valid, s.errors["M"]
(False, 'M = -5 is not allowed: must be > 0 kg (load mass)')
>>> s.set_text("M", "5000")
>>> s.valid, s.params.M
(True, 5000.0)
"""

from __future__ import annotations

import math

import param

from eha_core.params import FIELD_INFO, PARAM_NAMES, ActuatorParams, ParameterError

__all__ = ["AppState", "display_text", "parse_display"]


def display_text(name: str, value_si: float | None) -> str:
    """A parameter's SI value written in its display unit."""
    if value_si is None:
        return ""
    return f"{value_si / FIELD_INFO[name].display_scale:.6g}"


def parse_display(name: str, text: str) -> float | None:
    """Parse text typed in display units into SI; None for a blank p2_0 (force balance).

    Raises ParameterError naming the field when the text is not a number.
    """
    info = FIELD_INFO[name]
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


class AppState(param.Parameterized):
    """State of one session. The tabs read and write it; the core computes."""

    texts = param.Dict(default={}, doc="what the user typed, by field, in display units")
    params = param.ClassSelector(class_=ActuatorParams, doc="the last valid parameter set (SI)")
    errors = param.Dict(default={}, doc="messages by field name; empty when the inputs are valid")
    valid = param.Boolean(default=True, doc="all inputs valid: run buttons are enabled")
    kp = param.Number(default=10.0, doc="proportional gain for H(s) [V/m]")
    kp_text = param.String(default="10")
    revision = param.Integer(default=0, doc="bumped whenever the valid parameters change")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.reset_defaults()

    # -- inputs ------------------------------------------------------------------
    def reset_defaults(self) -> None:
        """Back to the paper's parameters (docs/model.md §2)."""
        defaults = ActuatorParams()
        self.kp_text = "10"
        self.kp = 10.0
        self.texts = {n: display_text(n, getattr(defaults, n)) for n in PARAM_NAMES}
        self._revalidate()

    def set_text(self, name: str, text: str) -> None:
        """Record what was typed into a field and revalidate everything."""
        if name == "kp":
            self.kp_text = text
        elif name in FIELD_INFO:
            self.texts = {**self.texts, name: text}
        else:
            raise KeyError(name)
        self._revalidate()

    def _revalidate(self) -> None:
        errors: dict[str, str] = {}
        values: dict[str, float | None] = {}
        for name in PARAM_NAMES:
            try:
                values[name] = parse_display(name, self.texts.get(name, ""))
            except ParameterError as exc:
                errors[name] = str(exc)
        kp = None
        try:
            kp = float(self.kp_text.strip().replace(",", "."))
            if not math.isfinite(kp) or kp <= 0:
                raise ValueError
        except ValueError:
            errors["kp"] = f"Kp = {self.kp_text.strip() or '(empty)'} is not allowed: must be a number > 0 V/m"
        new_params = None
        if not any(n in errors for n in PARAM_NAMES):
            try:
                new_params = ActuatorParams(**values)
            except ParameterError as exc:
                errors[exc.field] = str(exc)
        with param.parameterized.batch_call_watchers(self):
            self.errors = errors
            self.valid = not errors
            if kp is not None and "kp" not in errors:
                self.kp = kp
            if new_params is not None and new_params != self.params:
                self.params = new_params
                self.revision += 1
