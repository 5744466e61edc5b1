"""Tab 1: physical parameters and initial conditions, with live derived values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import panel as pn
import param

from eha_core.params import FIELD_INFO, PARAM_NAMES

from ..formatting import num_html, poles_html, table_html, tf_html
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
        self.derived.object = self._derived_html()

    def _derived_html(self) -> str:
        s = self.state
        p = s.params
        lin = s.linear_model
        op = lin.op
        num, den = lin.tf_coeffs()
        cnum, cden = lin.closed_loop_coeffs(s.kp)
        stale = "" if s.valid else '<p class="eha-stale">Showing the last valid parameters.</p>'
        geometry = table_html(["quantity", "value"], [
            ["A<sub>1</sub> = π D<sub>c</sub><sup>2</sup>/4", f"{p.A1 * 1e4:.4g} cm<sup>2</sup>"],
            ["A<sub>2</sub> = π (D<sub>c</sub><sup>2</sup> − d<sub>c</sub><sup>2</sup>)/4", f"{p.A2 * 1e4:.4g} cm<sup>2</sup>"],
            ["end stops ±0.8 L<sub>0</sub>", f"±{p.x_max * 1e3:.4g} mm"],
            ["operating point (eq. 10)", f"x = {op.x * 1e3:.3g} mm, v = 0, p<sub>1</sub> = {op.p1 / 1e6:.4g} MPa, "
                                          f"p<sub>2</sub> = {op.p2 / 1e6:.5g} MPa, u = 0"],
        ])
        lam_rows = []
        formulas = ["(B + 2k<sub>f</sub>A<sub>f</sub>/π)/M", "A<sub>1</sub>/M", "A<sub>2</sub>/M", "β<sub>e</sub>/L<sub>0</sub>",
                    "β<sub>e</sub>K<sub>q1</sub>√D<sub>3</sub>/(A<sub>1</sub>L<sub>0</sub>)",
                    "β<sub>e</sub>K<sub>q2</sub>√D<sub>4</sub>/(A<sub>2</sub>L<sub>0</sub>)"]
        for i, (lp, ln, f) in enumerate(zip(lin.lambdas, lin.lambdas_negative, formulas), start=1):
            lam_rows.append([f"λ<sub>{i}</sub>", f, num_html(lp), num_html(ln) if ln != lp else "same"])
        lambdas = table_html(["", "formula (Table 2)", "u ≥ 0", "u < 0"], lam_rows)
        a = p.a
        a_rows = [[f"a<sub>{k[1:]}</sub>", num_html(v)] for k, v in a.items()]
        half = (len(a_rows) + 1) // 2
        a_table = table_html(["", "Table 1"], a_rows[:half]) + table_html(["", "Table 1"], a_rows[half:])
        P = tf_html("P(s) = X(s)/U(s)", num, den, "eq. 21/23, u ≥ 0")
        H = tf_html(f"H(s), K<sub>p</sub> = {s.kp:g}", cnum, cden, "eq. 22/24")
        poles = (f"<p>Poles of P(s): {poles_html(lin.poles())} rad/s<br>"
                 f"Poles of H(s): {poles_html(lin.closed_loop_poles(s.kp))} rad/s</p>")
        return (f'{stale}<h4>Geometry and operating point</h4>{geometry}'
                f'<h4>Transfer functions</h4>{P}{H}{poles}'
                f'<h4>Linearised model parameters λ<sub>1</sub>…λ<sub>6</sub> (eq. 12)</h4>{lambdas}'
                f'<h4>Compact model a<sub>1</sub>…a<sub>10</sub> (eqs. 6-8)</h4><div class="eha-two">{a_table}</div>')

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
