"""Tab 1: physical parameters and initial conditions, with live derived values."""

from __future__ import annotations

import dataclasses
import html
from functools import lru_cache
from pathlib import Path

import panel as pn

from eha_core.param_table import FIELD_INFO

from ..render.layout import side_by_side
from ..render.tables import SYMBOLS_HTML, derived_html
from ..runtime.tasks import on_click, watch
from ..session import GuideStep, ReportPart, Section, SectionSnapshot
from ..session.form import Field, Form, Group
from ..session.state import FIELD_LABELS, FORM_FIELDS, AppState

__all__ = ["ParametersTab", "SCHEMATIC_PATH", "PARAMETER_FORM"]

#: The actuator's schematic, shipped inside the package (package data): a
#: regular, non-editable install must carry it too.
SCHEMATIC_PATH = Path(__file__).resolve().parents[1] / "assets" / "eha_schematic.svg"

#: the labels, one list for the form and its messages (AppState words them)
_PLAIN = FIELD_LABELS


def _field(name: str) -> Field:
    info = FORM_FIELDS[name]
    return Field(name, FIELD_LABELS.get(name, name), kind="text", unit=info.display_unit, tip=info.description,
                 placeholder="force balance" if name == "p2_0" else "")


def _group(group: str) -> tuple[Field, ...]:
    return tuple(_field(n) for n, info in FORM_FIELDS.items() if info.group == group)


#: Tab 1's form: the model's parameters and the controller gain, in display units (parsed by AppState).
PARAMETER_FORM = (
    Group("Load, friction, cylinder", _group("main")),
    Group("Advanced: valve, supply, chamber", _group("advanced"), collapsible=True, collapsed=True),
    Group("Initial conditions and controller", _group("initial"), collapsible=True, collapsed=True),
)


@lru_cache(maxsize=1)
def default_texts() -> dict:
    """Tab 1's fields as they open: the paper's values in display units."""
    return dict(AppState().texts)


@lru_cache(maxsize=1)
def _schematic_svg() -> str:
    # read once per server process: every session shows the same picture
    if not SCHEMATIC_PATH.exists():
        return (f"<p class='eha-warn'>The schematic ({SCHEMATIC_PATH.name}) is missing from this installation: "
                "reinstall the package.</p>")
    return SCHEMATIC_PATH.read_text(encoding="utf-8")


@lru_cache(maxsize=256)
def _derived(params, kp: float, stale: bool, hidden: tuple = ()) -> str:
    # a pure function of hashable inputs: the page of every student who has
    # not changed a value yet is the same, computed once per server process
    return derived_html(params, kp, stale=stale, hidden=hidden)


def form_groups(hidden=()) -> list[Group]:
    """Tab 1's groups without an exercise's hidden parameters (they are not the student's to see)."""
    return [dataclasses.replace(g, fields=tuple(f for f in g.fields if f.name not in hidden))
            for g in PARAMETER_FORM]


class ParametersTab(Section):
    """Step 1 of the paper: fill in the physical parameters (Fig. 15).

    Its fields are the session's :class:`~eha_app.session.state.AppState`: they exist (from the page's
    address or a settings file) before the tab is made, and in an exercise the hidden ones are
    neither shown, saved nor loaded.
    """

    key = "parameters"
    title = "Parameters"
    defaults = default_texts()
    guide_step = GuideStep(
        "1. Parameters", "Step 1: the actuator's physical parameters (Table 3) and initial state. P(s), H(s) and the "
        "linearised model follow as you type.", "1. Parameters",
        "Type into a field: what is derived from it follows at once.", runs=False)
    form_css = "eha-param-form"

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state = self.state
        self.form = Form(spec=[g.to_spec() for g in form_groups(state.hidden)], values=self._texts(), width=250,
                         url_defaults=default_texts(), css_classes=[self.form_css], margin=(5, 10))
        watch(self.form, self._typed, "values")
        self.reset_button = pn.widgets.Button(label="Reset to paper defaults", color="default", width=250)
        on_click(self.reset_button, self._reset)
        self.derived = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-derived"])
        self.status = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-param-status"])
        state.param.watch(self._on_state, ["errors", "revision", "kp"])
        self._on_state()

    # -- the section's protocol: its fields are the state's --------------------------------------
    @classmethod
    def unbuilt_settings(cls, session) -> dict[str, str]:
        return _state_texts(session.state)

    @classmethod
    def load_unbuilt(cls, session, texts) -> None:
        for name, text in texts.items():
            session.state.set_text(name, text)

    def settings(self) -> dict[str, str]:
        return _state_texts(self.state)

    def load(self, texts) -> None:
        self.load_unbuilt(self.session, texts)
        self.form.values = self._texts()

    def guide_done(self) -> bool:
        return True             # no run: what is derived follows the fields

    def snapshot(self) -> SectionSnapshot:
        s = self.state
        return SectionSnapshot(self.key, self.title, self.settings(), stale=not s.valid,
                               content=(s.params, s.kp, dict(s.errors)))

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart:
        from eha_core.param_table import PAPER_SOURCES
        from eha_core.params import ActuatorParams

        from ..render.formatting import num_html
        from ..render.tables import table_html

        params = errors = None
        if snapshot.content is not None:
            params, _kp, errors = snapshot.content
        paper = ActuatorParams()
        rows = []
        for k, typed in snapshot.settings.items():
            info = FORM_FIELDS.get(k)
            unit = info.display_unit if info is not None else ""
            label = SYMBOLS_HTML.get(k, html.escape(FIELD_LABELS.get(k, k)))
            shown = f"{html.escape(typed)} {unit}".strip() if typed.strip() else "(blank)"
            si = ""
            if params is not None and not errors and k in FIELD_INFO and k not in hidden:
                value = params.p2_init if k == "p2_0" else getattr(params, k)
                si = f"{num_html(value, 5)} {FIELD_INFO[k].unit}"
                if k == "p2_0" and not typed.strip():
                    si += " (force balance)"
            source = PAPER_SOURCES.get(k)
            ref = ""
            if k == "kp":
                ref = "10 V/m<br><small class='eha-cite'>eq. 24</small>"
            elif source is not None:
                value = paper.p2_init if k == "p2_0" else getattr(paper, k)
                ref = f"{num_html(value, 5)} {FIELD_INFO[k].unit}<br><small class='eha-cite'>{source}</small>"
            rows.append([f"{label} <small>{html.escape(info.description if info else '')}</small>", shown, si, ref])
        body = table_html(["parameter", "as typed", "in SI units", "the paper's"], rows)
        if errors:
            body += "<p class='eha-warn'>Not valid: " + html.escape("; ".join(errors.values())) + "</p>"
        elif params is not None:
            body += _derived(params, snapshot.content[1], False, tuple(hidden))
        return ReportPart("Parameters (tab 1)", body)

    # -- the page ---------------------------------------------------------------------------------
    def _texts(self) -> dict:
        return _state_texts(self.state)

    def _typed(self, event) -> None:
        old = event.old or {}
        for name, text in event.new.items():
            if old.get(name) != text and text is not None:
                self.state.set_text(name, text)

    def _reset(self, _event=None) -> None:
        self.state.reset_defaults()
        self.form.values = self._texts()

    def _on_state(self, *_events) -> None:
        s = self.state
        self.form.errors = dict(s.errors)
        if s.valid:
            self.status.object = ('<div class="eha-ok">All inputs valid. The derived values below follow '
                                  'what you type.</div>')
        else:
            first = next(iter(s.errors.values()))
            self.status.object = f'<div class="eha-warn">Fix the highlighted input to enable the runs: {first}</div>'
        self.derived.object = _derived(s.params, s.kp, not s.valid, s.hidden)

    def __panel__(self):
        inputs = pn.Column(self.reset_button, self.form, width=270)
        svg = _schematic_svg()
        schematic = pn.pane.HTML(svg, width=520, css_classes=["eha-schematic"]) if svg else pn.pane.HTML("")
        picture = pn.Column(self.status, schematic, width=540)
        derived = pn.Column(self.derived, sizing_mode="stretch_width", min_width=420)
        return side_by_side(inputs, picture, derived)


def _state_texts(state) -> dict[str, str]:
    """Tab 1's fields as typed (an exercise's hidden ones left out)."""
    return {k: v for k, v in state.texts.items() if k not in state.hidden}
