"""Tab 1: physical parameters and initial conditions, with live derived values."""

from __future__ import annotations

from pathlib import Path

import panel as pn

from eha_core.params import FIELD_INFO, PARAM_NAMES

from ..tables import derived_html
from ..state import AppState

__all__ = ["ParametersTab", "SCHEMATIC_PATH"]

SCHEMATIC_PATH = Path(__file__).resolve().parents[2] / "assets" / "eha_schematic.svg"

_SYMBOL = {"beta_e": "β<sub>e</sub>", "Af": "A<sub>f</sub>", "Dc": "D<sub>c</sub>", "dc": "d<sub>c</sub>",
           "d0": "d<sub>0</sub>", "L0": "L<sub>0</sub>", "Kq1": "K<sub>q1</sub>", "Kq2": "K<sub>q2</sub>",
           "ps": "p<sub>s</sub>", "pr": "p<sub>r</sub>", "k_f": "k<sub>f</sub>", "x0": "x(0)", "v0": "v(0)",
           "p1_0": "p<sub>1</sub>(0)", "p2_0": "p<sub>2</sub>(0)"}
_PLAIN = {"beta_e": "βe", "Af": "Af", "Dc": "Dc", "dc": "dc", "d0": "d0", "L0": "L0", "Kq1": "Kq1", "Kq2": "Kq2",
          "ps": "ps", "pr": "pr", "k_f": "kf", "x0": "x(0)", "v0": "v(0)", "p1_0": "p1(0)", "p2_0": "p2(0)"}


class NumberField(pn.viewable.Viewer):
    """A labelled text input in display units with its error message beneath."""

    def __init__(self, state: AppState, name: str, **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.name_ = name
        if name == "kp":
            label, tip, text = "Kp [V/m]", "proportional gain of the controller in H(s) (eq. 22)", state.kp_text
        else:
            info = FIELD_INFO[name]
            label = f"{_PLAIN.get(name, name)} [{info.display_unit}]"
            tip = info.description
            text = state.texts[name]
        self.input = pn.widgets.TextInput(label=label, value=text, description=tip, width=190,
                                          placeholder="force balance" if name == "p2_0" else "",
                                          css_classes=[f"eha-field-{name}"])
        self.error = pn.pane.HTML("", visible=False, css_classes=["eha-error", f"eha-error-{name}"],
                                  styles={"color": "#b00020", "font-size": "12px"}, width=190, margin=(0, 10, 6, 10))
        self.input.param.watch(self._typed, "value_input")
        self.input.param.watch(self._typed, "value")

    def _typed(self, event) -> None:
        if event.new is not None:
            self.state.set_text(self.name_, event.new)

    def refresh(self) -> None:
        """Show the state's text (after a reset) and this field's error, if any."""
        text = self.state.kp_text if self.name_ == "kp" else self.state.texts[self.name_]
        if self.input.value_input != text:
            self.input.value = text
        message = self.state.errors.get(self.name_, "")
        self.error.object = message
        self.error.visible = bool(message)
        self.input.css_classes = [f"eha-field-{self.name_}"] + (["eha-invalid"] if message else [])

    def __panel__(self):
        return pn.Column(self.input, self.error, margin=0)


class ParametersTab(pn.viewable.Viewer):
    """Step 1 of the paper: fill in the physical parameters (Fig. 15)."""

    def __init__(self, state: AppState, **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.fields = {n: NumberField(state, n) for n in PARAM_NAMES + ("kp",)}
        self.reset_button = pn.widgets.Button(label="Reset to paper defaults", color="default")
        self.reset_button.on_click(self._reset)
        self.derived = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-derived"])
        self.status = pn.pane.HTML("", sizing_mode="stretch_width")
        state.param.watch(self._on_state, ["errors", "revision", "kp"])
        self._on_state()

    def _group(self, group: str):
        return [self.fields[n] for n in PARAM_NAMES if FIELD_INFO[n].group == group]

    def _reset(self, _event=None) -> None:
        self.state.reset_defaults()
        for f in self.fields.values():
            f.refresh()

    def _on_state(self, *_events) -> None:
        for f in self.fields.values():
            f.refresh()
        s = self.state
        if s.valid:
            self.status.object = ('<div class="eha-ok">All inputs valid. The derived values below follow '
                                  'what you type.</div>')
        else:
            first = next(iter(s.errors.values()))
            self.status.object = (f'<div class="eha-warn">Fix the highlighted input to enable the runs: {first}</div>')
        self.derived.object = derived_html(self.state.params, self.state.kp, stale=not self.state.valid)

    def __panel__(self):
        main = pn.Card(*self._group("main"), title="Load, friction, cylinder", collapsible=False,
                       sizing_mode="stretch_width")
        advanced = pn.Card(*self._group("advanced"), title="Advanced: valve, supply, chamber", collapsed=True,
                           sizing_mode="stretch_width")
        initial = pn.Card(*self._group("initial"), self.fields["kp"], title="Initial conditions and controller",
                          collapsed=True, sizing_mode="stretch_width")
        inputs = pn.Column(self.reset_button, main, advanced, initial, width=250, scroll=True, max_height=1400)
        schematic = pn.pane.SVG(SCHEMATIC_PATH, width=520, css_classes=["eha-schematic"]) \
            if SCHEMATIC_PATH.exists() else pn.pane.HTML("")
        picture = pn.Column(self.status, schematic, width=540)
        derived = pn.Column(self.derived, sizing_mode="stretch_width", min_width=420)
        return pn.Row(inputs, picture, derived, sizing_mode="stretch_width")
