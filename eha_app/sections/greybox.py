"""Tab 3, grey-box: the nonlinear model's physical parameters by output error (as MATLAB's nlgreyest),
from the signals a rig measures; the three routes side by side; the hand-in."""

from __future__ import annotations

import html
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import panel as pn

from eha_core.board import greybox_plant, plant_model
from eha_core.errors import ComputationError, FieldError, not_allowed
from eha_core.experiments import LSE_INPUT, LSE_INPUT_RICH, LSE_INPUT_RICH_T_END, LSE_SCENARIOS
from eha_core.grading import greybox_model_error
from eha_core.identify.greybox import GREYBOX_PARAMS, GREYBOX_SIGNALS
from eha_core.identify.holdout import (
    VALIDATION_WORDS,
    model_state_at,
    second_greybox_record,
    split_record,
    validate_params,
    validation_seed,
)
from eha_core.param_table import FIELD_INFO
from eha_core.params import ActuatorParams, ParameterError
from eha_core.signals import SignalSpecError, parse_signal
from eha_core.simulate import DEFAULT_H_MAX

from ..render.formatting import json_safe
from ..render.greybox import (
    GreyBoxFigure,
    correlation_html,
    greybox_table_html,
    identifiability_html,
    routes_html,
    verdicts_html,
)
from ..render.layout import side_by_side
from ..render.tables import SCENARIOS, assumed_model_html
from ..runtime.limits import RunCost
from ..runtime.tasks import PageProgress, apply_locked, on_click, watch
from ..session import (
    GuideStep,
    KeptWork,
    ReportPart,
    RestoreStep,
    Section,
    SectionSnapshot,
    run_off_notice,
    stale_note,
)
from ..session.form import Field, Form, Group, parse_fields, raised_to_bounds, regrouped, with_lower_bounds
from ..session.freshness import ResultView
from ..session.state import FIELD_LABELS
from .handin import HandInBox
from .least_squares import EXCITATIONS, validation_html
from .uploads import (
    ColumnMapping,
    FileUpload,
    check_size,
    download,
    file_source,
    kept_upload,
    known_on_file,
    read_kept,
    upload_name,
)

__all__ = ["GreyBoxPanel", "GreyBoxRequest", "GB_FORM", "GB_DEFAULTS", "parse_greybox"]

#: The parameters offered an initial guess (the initial state's guess is tab 1's, or the paper's if hidden).
GUESS_PARAMS = ("M", "B", "Af", "beta_e", "Kq1", "Kq2", "L0", "k_f", "d0")
#: How a parameter is typed: its name as the student may write it (case-insensitive) -> the core's name.
_ALIASES = {**{n.lower(): n for n in GREYBOX_PARAMS}, "a_f": "Af", "βe": "beta_e", "β_e": "beta_e", "beta": "beta_e",
            "kf": "k_f", "d_0": "d0", "l_0": "L0", "p1(0)": "p1_0", "p2(0)": "p2_0", "x(0)": "x0", "v(0)": "v0"}
_PAPER = ActuatorParams()
#: The other routes the side-by-side table reads.
_ROUTES = ("least_squares", "frequency")


def _guess_field(n: str) -> Field:
    info = FIELD_INFO[n]
    lo = None if n == "d0" else 0.0
    return Field(f"gb_guess_{n}", f"{info.label} initial guess", "number", unit=info.display_unit, lo=lo,
                 lo_open=lo is not None and n not in ("B", "Af", "k_f"), short=f"{info.label} guess",
                 tip=f"the estimate starts here ({info.description}); the paper's value by default")


#: How the estimate simulates the record (the core's ``shooting``), as the form offers it.
SHOOTING_OPTIONS = (("auto", "automatic: a growing record, multiple shooting when the checks fail"),
                    ("single", "the whole record (output error)"), ("multiple", "multiple shooting, then the whole"))


def _display(n: str, value: float) -> str:
    return f"{value / FIELD_INFO[n].display_scale:.6g}"


GB_FORM = (Group("Grey-box estimation", (
    Field("gb_params", "parameters to estimate", "text", short="parameters",
          tip=f"comma-separated, of {', '.join('βe' if n == 'beta_e' else n for n in GREYBOX_PARAMS)} (the rest "
              "are held at tab 1's values)"),
    Field("gb_measured", "signals measured", "text", short="measured",
          tip="comma-separated, of x, v, p1, p2: what the model's simulation is compared with (x alone works)"),
    Field("gb_excitation", "excitation", "select", options=(*EXCITATIONS.items(), ("custom", "custom u(t)")),
          short="excitation"),
    Field("gb_u", "custom u(t)", "text", unit="V", short="custom u(t)",
          tip="the valve command in the signal grammar, e.g. sine:6:2 or step:2+sine:1:5; a small one "
              "(sine:0.01:2) shows what the data cannot determine"),
    Field("gb_t_end", "record length", "number", unit="s", lo=1.0, hi=60.0, short="record length"),
    Field("gb_scenario", "disturbance", "select", options=tuple(SCENARIOS.items()), short="disturbance",
          tip="a load force on the plant, known to the model (an input of the record)"),
    Field("gb_validation", "validation", "select", options=tuple(VALIDATION_WORDS.items()), short="validation",
          tip="the estimated model simulated on data it was not fitted to: a second experiment (another "
              "excitation, a new noise draw), or the record's last third, held out of the estimation"),
    Field("gb_custom", "custom d(t)", "text", short="custom d(t)",
          tip="none, sine:AMP[:FREQ_HZ], white:SIGMA, or any signal of the simulation, e.g. sine:500:2+noise:100:1"),
    Field("gb_seed", "noise seed", "integer", lo=0, hi=10**6, short="noise seed"),
    Field("gb_shooting", "simulation", "select", short="simulation",
          options=SHOOTING_OPTIONS,
          tip="automatic fits the first 1 s, 3 s, ... of the record, each from the last, then all of it, and "
              "tries multiple shooting only when that estimate fails its checks; multiple shooting cuts the "
              "record into 1 s segments whose initial states are estimated too, joined by continuity: a wider "
              "basin for a poor initial guess, at several times the cost"),
)), Group("Sensor noise (simulated measurements)", (
    Field("gb_noise_x", "σ of x", "number", unit="mm", lo=0.0, hi=10.0, short="σ x",
          tip="white Gaussian noise added to the position sensor, drawn from the noise seed"),
    Field("gb_noise_v", "σ of v", "number", unit="mm/s", lo=0.0, hi=1000.0, short="σ v",
          tip="white Gaussian noise added to the velocity sensor"),
    Field("gb_noise_p", "σ of p1, p2", "number", unit="MPa", lo=0.0, hi=10.0, short="σ p",
          tip="white Gaussian noise added to each pressure sensor"),
), collapsible=True, collapsed=True), Group("Initial guess", tuple(_guess_field(n) for n in GUESS_PARAMS),
                                            collapsible=True, collapsed=True))
GB_DEFAULTS = {"gb_params": "M, B, Af, βe", "gb_measured": "x, p1, p2", "gb_excitation": "paper",
               "gb_u": "sine:6:2", "gb_t_end": "5",
               "gb_scenario": "none", "gb_custom": "sine:1000:3", "gb_seed": "0", "gb_shooting": "auto",
               "gb_validation": "none",
               "gb_noise_x": "0.01",
               "gb_noise_v": "0", "gb_noise_p": "0.05",
               **{f"gb_guess_{n}": _display(n, getattr(_PAPER, n)) for n in GUESS_PARAMS}}
_GB_FIELDS = {f.name: f for g in GB_FORM for f in g.fields}
#: The sensor-noise fields and the signals whose σ they set, with the display scale (value_SI / scale).
_NOISE_FIELDS = {"gb_noise_x": (("x",), 1e-3), "gb_noise_v": (("v",), 1e-3), "gb_noise_p": (("p1", "p2"), 1e6)}


@dataclass(frozen=True)
class GreyBoxRequest:
    """A parsed grey-box request."""

    names: tuple[str, ...] = ("M", "B", "Af", "beta_e")
    measured: tuple[str, ...] = ("x", "p1", "p2")
    excitation: str = "paper"
    scenario: str = "none"
    custom: str = "sine:1000:3"
    seed: int = 0
    noise: tuple[float, float, float] = (0.01, 0.0, 0.05)     # σ of x [mm], v [mm/s], p1 and p2 [MPa]
    guess: tuple[tuple[str, float], ...] = ()                 # SI, of GUESS_PARAMS
    u_text: str = "sine:6:2"
    t_end: float = 5.0
    shooting: str = "auto"
    validation: str = "second"

    def measurement_noise(self) -> dict[str, float]:
        sx, sv, sp = self.noise
        return {"x": sx * 1e-3, "v": sv * 1e-3, "p1": sp * 1e6, "p2": sp * 1e6}

    def disturbance_spec(self) -> str:
        return self.custom if self.scenario == "custom" else LSE_SCENARIOS[self.scenario]

    def input_signal(self):
        """(u(t), the record's length [s])."""
        if self.excitation == "custom":
            return parse_signal(self.u_text, name="custom u(t)"), self.t_end
        return (LSE_INPUT, 5.0) if self.excitation == "paper" else (LSE_INPUT_RICH, LSE_INPUT_RICH_T_END)


def _names(text: str, allowed, aliases, label: str) -> tuple[tuple[str, ...], str]:
    """The names a comma-separated field lists (each once, in the order of ``allowed``), or a message."""
    got = []
    for part in str(text).replace(";", ",").split(","):
        p = part.strip()
        if not p:
            continue
        n = aliases.get(p.lower())
        if n is None:
            return (), str(FieldError(label, text, f"{p} is not one of {', '.join(allowed)}", value_text=text))
        if n not in got:
            got.append(n)
    if not got:
        return (), str(FieldError(label, text.strip() or "(empty)", f"name at least one of {', '.join(allowed)}",
                                  value_text=text.strip() or "(empty)"))
    return tuple(n for n in allowed if n in got), ""


def listed_params(text: str, label: str = "parameters") -> tuple[tuple[str, ...], str]:
    """The grey-box parameters a comma-separated field names (aliases such as βe taken), or a message."""
    return _names(text, GREYBOX_PARAMS, _ALIASES, label)


def listed_signals(text: str, label: str = "measured") -> tuple[tuple[str, ...], str]:
    """The signals a comma-separated field names (of x, v, p1, p2), or a message."""
    return _names(text, GREYBOX_SIGNALS, {s: s for s in GREYBOX_SIGNALS}, label)


def gb_hidden(texts: dict) -> list[str]:
    hidden = [] if texts.get("gb_scenario") == "custom" else ["gb_custom"]
    return hidden + ([] if texts.get("gb_excitation") == "custom" else ["gb_u", "gb_t_end"])


def parse_greybox(texts: dict, fields: dict | None = None, *, measurable=GREYBOX_SIGNALS) -> tuple[GreyBoxRequest,
                                                                                                   dict]:
    """The grey-box request the form describes, and a message per invalid field (``fields``: as an
    exercise bounds them; ``measurable``: the signals the student's sensors give)."""
    hidden = set(gb_hidden(texts))
    values, errors = parse_fields((fields or _GB_FIELDS).values(), texts, skip=hidden)
    names, msg = listed_params(texts.get("gb_params", ""))
    if msg:
        errors["gb_params"] = msg
    measured, msg = listed_signals(texts.get("gb_measured", ""))
    if msg:
        errors["gb_measured"] = msg
    elif any(s not in measurable for s in measured):
        missing = [s for s in measured if s not in measurable]
        text = texts.get("gb_measured", "")
        errors["gb_measured"] = str(FieldError("measured", text, f"this exercise does not measure "
                                               f"{', '.join(missing)}; use {', '.join(measurable)}", value_text=text))
    guess = tuple((n, float(values[f"gb_guess_{n}"]) * FIELD_INFO[n].display_scale)
                  for n in GUESS_PARAMS if f"gb_guess_{n}" in values)
    req = GreyBoxRequest(names=names or GreyBoxRequest.names, measured=measured or GreyBoxRequest.measured,
                         excitation=values.get("gb_excitation", "paper"), scenario=values.get("gb_scenario", "none"),
                         custom=texts.get("gb_custom", ""), seed=values.get("gb_seed", 0),
                         noise=tuple(float(values.get(k, 0.0)) for k in _NOISE_FIELDS), guess=guess,
                         u_text=texts.get("gb_u", ""), t_end=float(values.get("gb_t_end", 5.0)),
                         shooting=values.get("gb_shooting", "auto"), validation=values.get("gb_validation", "none"))
    if "gb_custom" not in hidden and not errors.get("gb_custom"):
        try:
            parse_signal(req.disturbance_spec(), name="custom d(t)", seed=req.seed, hold_s=1e-3)
        except (ValueError, SignalSpecError) as exc:
            errors["gb_custom"] = " ".join(str(exc).split())
    if "gb_u" not in hidden and not errors.get("gb_u"):
        try:
            req.input_signal()
        except (ValueError, SignalSpecError) as exc:
            errors["gb_u"] = " ".join(str(exc).split())
    return req, errors


def exercise_fields(conditions) -> dict:
    """The form's fields under an exercise's conditions: each σ field's lower bound is its noise floor
    (a student may raise the noise, not lower it), as in the least squares."""
    if conditions is None:
        return dict(_GB_FIELDS)
    lows = {name: max(conditions.noise_floor(sig) for sig in signals) / scale
            for name, (signals, scale) in _NOISE_FIELDS.items()}
    return with_lower_bounds(_GB_FIELDS, lows, "this exercise's sensor noise")


#: A grey-box estimate simulates its record some 25 times, each with one more evaluation of the model
#: per estimated parameter (the sensitivities); multiple shooting about three times as much.
GREYBOX_SIMULATIONS = 25
#: Each strategy's simulations as a share of :data:`GREYBOX_SIMULATIONS`. ``auto`` is single shooting
#: (its first fits over the record's first seconds start the whole record's fit near its minimum) plus
#: the chance that its checks fail and it goes on to multiple shooting (x3): counted as 1.5, so that a
#: server's limit refuses what a likely escalation could not finish, without refusing every run as if
#: it escalated.
SHOOTING_COST = {"single": 1.0, "auto": 1.5, "multiple": 3.0}
#: At most this many progress updates a second reach the page.
_PROGRESS_HZ = 4.0


class GreyBoxPanel(Section):
    """Grey-box identification of the nonlinear model, and the three routes side by side."""

    key = "greybox"
    title = "Grey-box (nonlinear)"
    defaults = GB_DEFAULTS
    guide_step = GuideStep(
        "3. Grey-box", "Step 3, the nonlinear model: estimate the physical parameters from what is measured (output "
        "error, as nlgreyest) and compare the three routes side by side.", "3. Identification: grey-box",
        "Press <b>Run grey-box estimation</b>.")
    form_css = "eha-gb-form"
    run_buttons = ("Run grey-box estimation",)

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state = self.state
        self.result = None
        self.result_context: dict = {}
        ex = state.exercise if state.hidden else None
        self.conditions = ex.conditions if ex is not None else None
        self.fields = exercise_fields(self.conditions)
        self.last_settings: dict = {}
        self.last_conditions: dict = {}
        self.last_data = None
        texts = raised_to_bounds(self.initial_texts(), self.fields, _NOISE_FIELDS)
        self.form = Form(spec=[g.to_spec() for g in regrouped(GB_FORM, self.fields)], values=texts,
                         url_defaults=GB_DEFAULTS, width=270, css_classes=[self.form_css], margin=(5, 10))
        watch(self.form, self._update_enabled, "values")
        self.table = pn.pane.HTML("<p>Choose what to estimate and press “Run grey-box estimation”.</p>",
                                  sizing_mode="stretch_width", css_classes=["eha-gb-table-pane"])
        self.plot = pn.Column(sizing_mode="stretch_width", css_classes=["eha-gb-plot"])
        self.figure: GreyBoxFigure | None = None
        self.details = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-gb-details"])
        # the fit on data the estimate did not see: its words, and the record against the model's simulation
        self.validation = None
        self.validation_note = ""
        self.validation_pane = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-gb-validation"])
        self.validation_figure: GreyBoxFigure | None = None
        self.validation_plot = pn.Column(sizing_mode="stretch_width", css_classes=["eha-gb-validation-plot"])
        self.area = pn.Column(self.table, self.plot, self.validation_pane, self.validation_plot, self.details,
                              sizing_mode="stretch_width")
        self.view = ResultView("gb", self.area, run_hint="Press “Run grey-box estimation” to update it.")
        self.routes = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-routes-pane"])
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-gb-alert"])
        self.notice = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-gb-notice"])
        self.queue_note = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-queue-note"],
                                       styles={"color": "#555", "font-size": "12px"})
        self.button = pn.widgets.Button(label="Run grey-box estimation", color="primary", width=260,
                                        css_classes=["eha-run-gb"])
        on_click(self.button, lambda _e: self.run())
        # a run's progress (the core's stage, in words) and its cancel, as the study's
        self.cancel_button = pn.widgets.Button(label="Cancel the estimation", width=260, disabled=True,
                                               css_classes=["eha-cancel-gb"])
        on_click(self.cancel_button, lambda _e: self.cancel())
        self.progress = pn.indicators.Progress(value=-1, active=False, width=260, visible=False,
                                               css_classes=["eha-gb-progress-bar"])
        self.progress_text = pn.pane.HTML("", width=270, visible=False, css_classes=["eha-gb-progress"])
        self._job = None                    # the last run asked for
        self._token = None                  # the cancel token of the run computing
        self.handin = HandInBox(self, "greybox", self._handin_estimates, label="Hand in the grey-box estimates",
                                refusal=self._handin_refusal)
        self.handin_button, self.verdict = self.handin.button, self.handin.verdict
        # the student's own record (CSV or .mat): t, u and the measured signals
        self.own_data = None
        self.own_data_key = None
        self.own_source: dict = {}          # what a hand-in records of the file (uploads.file_source)
        self.result_source: dict = {}       # ... and of the data behind the last result
        self._upload = None
        self.upload = FileUpload(accept=".csv,.mat", width=260, css_classes=["eha-gb-upload"],
                                 label="Your own record (a CSV or .mat file)")
        watch(self.upload, self._uploaded, "value")
        self.upload_note = pn.pane.HTML(
            "<span class='eha-note'>Or use your own record: a CSV or MATLAB .mat file with columns t, u and the "
            "measured signals (SI, or units in the header such as <code>p1[MPa]</code>), uniformly sampled.</span>",
            width=270, css_classes=["eha-gb-upload-note"])
        self.column_mapping = ColumnMapping({c: (c, ()) for c in ("t", "u", *GREYBOX_SIGNALS)}, "gb")
        self.mapping = self.column_mapping.panel
        self.simulated_button = pn.widgets.Button(label="Back to simulated data", width=260, visible=False,
                                                  css_classes=["eha-gb-simulated"])
        on_click(self.simulated_button, lambda _e: self.use_simulated())
        self.downloads = [
            download(self.data_bytes, "eha_greybox_data.csv", "Data (CSV)", "eha-dl-gb-data"),
            download(self.estimates_bytes, "eha_greybox_estimates.json", "Estimates (JSON)", "eha-dl-gb-est"),
        ]
        state.param.watch(self._update_enabled, "valid")
        state.param.watch(self._inputs_changed, ["params", "valid"])
        self._update_enabled()
        # the side-by-side table follows the other routes' runs, whichever sub-tab the student is on
        for key in _ROUTES:
            if session.section(key) is not None:
                self._follow(session.section(key))
        session.when_built(self._follow)
        self.show_routes()

    def _follow(self, section) -> None:
        if section.key in _ROUTES:
            section.param.watch(lambda _e: self.show_routes(), "result")

    # -- the request ---------------------------------------------------------------------------------
    def measurable(self) -> tuple[str, ...]:
        return self.conditions.measured if self.conditions is not None else GREYBOX_SIGNALS

    def request(self) -> tuple[GreyBoxRequest, dict]:
        return parse_greybox(self.form.values, self.fields, measurable=self.measurable())

    def run_key(self):
        req, errors = self.request()
        if errors or not self.state.valid:
            return None
        return self.state.params, req, self.own_data_key

    def guess(self, req: GreyBoxRequest, base: ActuatorParams | None = None) -> ActuatorParams:
        """The initial values: the form's guesses of the estimated parameters; everything else as tab 1
        says (what the rig's maker measured), except a hidden one, which starts at the paper's value.
        ``base``: the parameters taken as known (on a file, :func:`~eha_app.sections.uploads.known_on_file`'s)."""
        base = self.state.params if base is None else base
        hidden = set(self.state.hidden)
        typed = dict(req.guess)
        values = {}
        for n in req.names:
            if n in typed:
                values[n] = typed[n]
            elif n in hidden:
                values[n] = _PAPER.initial_state[3] if n == "p2_0" else getattr(_PAPER, n)
        # a hidden parameter held (not estimated) stays at the truth: the plant's simulation and the model
        # agree on it, as the least squares' regressors use it; it is never shown. The model is the
        # paper's (eqs. 1-4), whatever the plant: an effect of a variant actuator (a lagging spool,
        # leakage, Stribeck friction) is not the model's, and shows in the residuals
        return base.replace(effects=None, **values)

    def _known(self, req, own) -> tuple[ActuatorParams, str] | None:
        """The parameters the run takes as known and the sentence about them: tab 1's on the student's
        simulated record; on a file, never a hidden value (it would come back out of the estimates).
        None, with the failure shown, when the paper's values do not fit what the student typed."""
        if own is None:
            return self.state.params, ""
        try:
            return known_on_file(self.state, req.names)
        except ParameterError as exc:
            self._fail(str(exc))
            return None

    def _conditions_refusal(self, req) -> str | None:
        c = self.conditions
        if c is None:
            return None
        if "greybox" not in c.methods:
            return "this exercise does not use grey-box identification"
        if req.input_signal()[1] > c.max_record_s:
            return str(not_allowed("excitation", dict(EXCITATIONS).get(req.excitation, f"{req.t_end:g} s"),
                                   f"this exercise's records are at most {c.max_record_s:g} s"))
        return None

    def _disturbance_text(self, req) -> str:
        spec = req.disturbance_spec()
        extra = self.conditions.disturbance.strip() if self.conditions is not None else "none"
        if extra.lower() in ("", "none"):
            return spec
        return extra if spec.strip().lower() in ("", "none") else f"{spec}+{extra}"

    # -- the page's state ------------------------------------------------------------------------------
    def _inputs_changed(self, *_events) -> None:
        why = "a parameter on tab 1 is not valid" if not self.state.valid else ""
        self.view.inputs_changed(self.run_key(), why=why)
        self._handin_tip()

    def _handin_tip(self) -> None:
        if not self.state.hidden:
            return
        if self.result is None:
            self.handin.set_tip(False, "run the grey-box estimation first: the hand-in takes the estimates of its "
                                       "table")
            return
        if self.result_context.get("own_record") and not self.handin.takes_files:
            self.handin.set_tip(False, "a hand-in comes from your actuator's experiment, not from a file")
            return
        why = self._handin_refusal()
        self.handin.show_refusal(why)
        if why:
            return
        names = ", ".join(FIELD_LABELS.get(n, n) for n in self.state.hidden
                          if n in self.result.estimates and n not in self.result.held)
        if not names:
            self.handin.set_tip(False, "the last run estimated none of the hidden parameters")
        elif self.view.status == "current":
            self.handin.set_tip(True, f"hand in the estimates of {names} in the table")
        else:
            self.handin.set_tip(True, f"hand in the estimates of {names} in the table, from the previous settings "
                                      "(run again to hand in estimates for the new ones)")

    def _update_enabled(self, *_events) -> None:
        _, errors = self.request()
        self.form.errors = errors
        self.form.hidden = gb_hidden(self.form.values)
        ok = self.state.valid
        waiting = self.column_mapping.waiting
        self.button.disabled = not ok or bool(errors) or waiting
        self.notice.object = run_off_notice("Run grey-box estimation", tab1_valid=ok, errors=errors, waiting=waiting)
        self.notice.visible = not ok or bool(errors) or waiting
        self._inputs_changed()

    def _fail(self, message: str) -> None:
        self.alert.object = f"The grey-box estimation failed: {html.escape(message)}"
        self.alert.visible = True

    # -- the run -------------------------------------------------------------------------------------------
    def _draw(self, data, res) -> None:
        """The record against the estimate's simulation; the same figures for every run with the same
        signals (new data, no new Bokeh models to make, send and lay out)."""
        if self.figure is None or not self.figure.update(data.t, data.signals, res.simulated):
            self.figure = GreyBoxFigure(data.t, data.signals, res.simulated)
            self.plot.objects = [pn.pane.Bokeh(self.figure.layout, sizing_mode="stretch_width")]

    def _draw_validation(self, val) -> None:
        """The validation's words and, when the model was simulated, its record against the model's run."""
        self.validation_pane.object = self.validation_note
        if val is None or val.simulated is None:
            self.validation_plot.objects, self.validation_figure = [], None
            return
        if self.validation_figure is None or not self.validation_figure.update(val.t, val.measured, val.simulated):
            self.validation_figure = GreyBoxFigure(val.t, val.measured, val.simulated)
            self.validation_plot.objects = [pn.pane.Bokeh(self.validation_figure.layout, sizing_mode="stretch_width")]

    def run(self):
        from eha_core.identify.greybox import GreyBoxData, greybox_data, identify_greybox

        req, errors = self.request()
        if errors or not self.state.valid or self.column_mapping.waiting:
            return None
        self.alert.visible = False
        refusal = self._conditions_refusal(req)
        if refusal:
            self._fail(refusal)
            return None
        own = self.own_data
        if own is not None:
            missing = [s for s in req.measured if s not in own.signals]
            if missing:
                self._fail(f"your file has no {', '.join(missing)}: measure only "
                           f"{', '.join(own.signals)}, or load a file with them")
                return None
        u, t_end = req.input_signal()
        if own is not None:
            t_end = float(own.t[-1] - own.t[0])
        try:       # what it may cost on a shared server, before it is queued
            self.check_cost()
        except ValueError as exc:
            self._fail(str(exc))
            return None
        kp, key = self.state.kp, self.run_key()
        known = self._known(req, own)
        if known is None:
            return None
        params, paper_note = known
        guess = self.guess(req, params)
        own_source = dict(self.own_source)
        run_settings = self.settings()
        d_text = self._disturbance_text(req)
        run_conditions = ({"noise": req.measurement_noise(), "disturbance_applied": d_text,
                           "measured": list(req.measured)} if self.conditions is not None else {})
        scenario = req.scenario if req.excitation == "paper" and req.scenario != "custom" and own is None else None

        # the core's stage, from the worker: a few updates a second reach the page
        stage = PageProgress(self._show_stage, hz=_PROGRESS_HZ)

        def compute(token):
            self._token = token         # the cancel button's way to the running estimate
            if own is not None:
                data = GreyBoxData(t=own.t, u=own.u, signals={s: own.signals[s] for s in req.measured},
                                   source=own.source)
            else:
                d = parse_signal(d_text, name="custom d(t)", seed=req.seed, hold_s=1e-3)
                noise = {s: v for s, v in req.measurement_noise().items() if s in req.measured}
                data = greybox_data(params, u, t_end=t_end, d=d, noise=noise, seed=req.seed, measured=req.measured)
            # with the split, the estimate sees the record's first part only
            whole, (data, held) = data, (split_record(data) if req.validation == "split" else (data, None))
            res = identify_greybox(data, req.names, measured=req.measured, guess=guess, shooting=req.shooting,
                                   cancel=token, progress=stage)
            validation = _validation(req, res, params, whole, held, u, t_end, d_text, own is not None, token)
            model = None
            if res.success:
                # a nonlinear model of the actuator: the board closes its loop, simulates it on its
                # record and for its step, and draws its linearisation (eq. 24) with bands
                try:
                    model = plant_model(greybox_plant(res), kp, name="GB", ts=data.ts,
                                        description=f"grey-box ({', '.join(req.names)} from "
                                                    f"{', '.join(req.measured)}): the nonlinear model, "
                                                    f"Kp = {kp:g} V/m",
                                        params=params if own is None else None)
                except (ParameterError, ValueError, ComputationError):
                    model = None
            return res, data, model, validation

        def show(out, job):
            res, data, model, (validation, why_not) = out
            self.result = res
            self.validation = validation
            self.validation_note = validation_html(validation, req.validation, why_not)
            self.last_data = data
            self.last_settings, self.last_conditions = run_settings, run_conditions
            # what the hand-in's grading needs of the experiment: on a variant of the paper's actuator, the
            # grey-box's own error on a noise-free record of it (its model is the paper's, not the plant's)
            self.last_reference = None if own is not None else dict(
                truth=params, u=u, t_end=t_end, d=parse_signal(d_text, name="custom d(t)", seed=req.seed, hold_s=1e-3),
                measured=tuple(req.measured), guess=guess)
            self.result_context = {"scenario": scenario, "own_record": own is not None, "params": params}
            self.result_source = own_source if own is not None else {"kind": "simulated"}
            note = _run_note(job, data, res, own is not None) + paper_note
            self.table.object = self._table_html() + note + assumed_model_html("greybox")
            self._draw(data, res)
            self._draw_validation(validation)
            self.details.object = self._details_html()
            for d in self.downloads:
                d.disabled = False
            self.view.shown(key)
            self.show_routes()
            self._inputs_changed()
            if model is not None:
                apply_locked(partial(self.session.post, "board", model))

        self._running(True)
        self._show_stage("starting")
        job = self._job = self.runner.run("grey-box estimation", compute, show, fail=self._fail, busy=[self.area],
                                          note=self._note, cancelled=partial(self._cancelled, stage))
        self.runner.then(job, partial(self._ended, stage))
        return job

    def _cancelled(self, stage: PageProgress, _job) -> None:
        stage.close()
        self.progress_text.object = ("<span class='eha-note eha-gb-cancelled'>The grey-box estimation was cancelled"
                                     + ("; the table shows the previous result" if self.result is not None else "")
                                     + ".</span>")
        self.progress_text.visible = True

    def _ended(self, stage: PageProgress, job) -> None:
        """Whatever the run's end (shown, failed, cancelled, replaced by a newer request): it is over."""
        stage.close()
        if job is self._job:
            self._running(False)
            if job.state != "cancelled":
                self.progress_text.visible = False

    def cancel(self) -> None:
        """Stop the grey-box estimation: a waiting one never starts, a running one stops at its next
        simulation; the table keeps the previous result."""
        for token in (self._token, self._job.token if self._job is not None else None):
            if token is not None:
                token.cancel("the grey-box estimation was cancelled")

    def _running(self, on: bool) -> None:
        self.cancel_button.disabled = not on
        self.progress.active = on
        self.progress.visible = on

    def _show_stage(self, text: str) -> None:
        """The run's stage under the button (the core's sentence: what it is doing now)."""
        self.progress_text.object = f"<span class='eha-note'>{html.escape(text[:1].upper() + text[1:])}…</span>"
        self.progress_text.visible = True

    def _table_html(self) -> str:
        c = self.result_context
        return greybox_table_html(self.result, c.get("params"), hidden=self.state.hidden, scenario=c.get("scenario"),
                                  own_record=c.get("own_record", False))

    def _details_html(self) -> str:
        return _details(self.result)

    # -- the three routes -------------------------------------------------------------------------------
    def routes_content(self):
        """The last result of each route in this session (None: not run), for the side-by-side table."""
        lse = self.session.section("least_squares")
        freq = self.session.section("frequency")
        lse_res = getattr(lse, "result", None) if lse is not None else None
        if lse is not None and getattr(lse, "result_context", {}).get("own_record"):
            lse_res = None          # another record's numbers do not compare with tab 1's
        fi = getattr(freq, "result", None) if freq is not None else None
        backout = getattr(fi, "backout", None) if fi is not None else None
        gb = self.result if not self.result_context.get("own_record") else None
        return self.state.params, lse_res, backout, gb

    def show_routes(self) -> None:
        params, lse, backout, gb = self.routes_content()
        self.routes.object = ("<h4>The three routes side by side</h4>"
                              + routes_html(params, lse, backout, gb, hidden=self.state.hidden))

    # -- the student's own record ------------------------------------------------------------------------
    def _uploaded(self, _event) -> None:
        if self.upload.value is None:
            return
        self._upload = (bytes(self.upload.value), upload_name(self.upload.filename))
        self.read_upload()

    def use_file(self, data: bytes, filename: str, mapping: dict | None = None):
        """Use ``data`` (a file named ``filename``) as the student's record, its columns read with ``mapping``
        (None: by their names); returns the job that reads it."""
        self._upload = (data, filename)
        return self.read_upload(mapping)

    def read_upload(self, mapping: dict | None = None):
        """Read the uploaded file (in a worker): t, u and the measured signals; or ask which column is which."""
        from eha_core.data import DataError, file_columns, read_data, sample_time

        if self._upload is None:
            return None
        data, filename = self._upload
        try:
            check_size(data, filename)
        except ValueError as exc:
            self._upload_problem(str(exc))
            return None
        req, _ = self.request()
        columns = ("t", "u", *req.measured)

        def compute(_token):
            try:
                cols = read_data(data, columns, name="your file", filename=filename, mapping=mapping, min_rows=50)
            except DataError as exc:
                if exc.missing_columns:
                    return "map", file_columns(data, filename, name="your file"), str(exc)
                raise
            ts = sample_time(cols["t"], name="your file", path=filename)
            return ("ok", _OwnRecord(cols["t"], cols["u"], {s: cols[s] for s in req.measured}, filename), ts,
                    file_source(filename, data))

        def show(out, _job):
            if out[0] == "map":
                self.column_mapping.needed = {c: (c, ()) for c in columns}
                self.column_mapping.ask(out[1], filename, lambda chosen: self.read_upload(mapping=chosen))
                self.simulated_button.visible = True
                self.upload_note.object = (f"<span class='eha-note'>{html.escape(filename)} is read once you say "
                                           "which column is which (below).</span>")
                self._update_enabled()
                return
            _, rec, ts, source = out
            self.own_data = rec
            self.own_source = source
            self.own_data_key = (filename, len(data), tuple(sorted((mapping or {}).items())), columns)
            self.mapping.visible = False
            self.simulated_button.visible = True
            self._update_enabled()
            self.upload_note.object = (f"<span class='eha-ok'>Using your record: {html.escape(filename)}, "
                                       f"{rec.t.size} samples every {ts * 1e3:.4g} ms, with "
                                       f"{', '.join(rec.signals)}. Run the grey-box estimation on it.</span>")

        return self.runner.run("reading your data", compute, show, fail=self._upload_problem, note=self._note)

    def _upload_problem(self, message: str) -> None:
        self.upload_note.object = f"<span class='eha-warn'>{html.escape(message)}</span>"

    def use_simulated(self) -> None:
        self.own_data, self.own_data_key, self._upload = None, None, None
        self.simulated_button.visible = False
        self.mapping.visible = False
        self.upload_note.object = "<span class='eha-note'>Using the simulated sensors again.</span>"
        self._update_enabled()

    # -- downloads --------------------------------------------------------------------------------------------
    def data_bytes(self) -> bytes:
        """The record behind the table (t, u or r, the measured signals) and the model simulated with the
        estimates beside them (``x_sim``, ...), SI: the upload reads it back."""
        from eha_core.data import write_data

        d, res = self.last_data, self.result
        cols = {"t": d.t, "u": d.u if d.u is not None else d.r}
        cols.update(d.signals)
        for s in d.signals:
            cols[f"{s}_sim"] = res.simulated[:, ("x", "v", "p1", "p2").index(s)]
        return write_data(cols, "csv", units="si")

    def estimates_bytes(self) -> bytes:
        """The estimates, intervals, correlations, fits and sentences (no hidden value: the core's own dict)."""
        import json

        out = self.result.to_dict()
        out["source"] = self.last_data.source if self.last_data is not None else ""
        # a value the estimate does not give (an interval of one that failed its checks) is null, not NaN
        return json.dumps(json_safe(out), indent=1, allow_nan=False).encode()

    # -- the hand-in ----------------------------------------------------------------------------------------
    def _handin_estimates(self):
        """The hidden parameters the last run estimated (not those it held), with its settings."""
        res = self.result
        if res is None:
            return None
        estimates = {n: float(res.estimates[n]) for n in self.state.hidden
                     if n in res.estimates and n not in res.held}
        if not estimates:
            return None
        settings = dict(self.last_settings or self.settings())
        # the data the estimates came from (HandInBox refuses a file's unless the exercise allows them)
        settings["_source"] = dict(self.result_source) or {"kind": "simulated"}
        settings["_conditions"] = dict(self.last_conditions)
        # the precision of the student's record, as this server computed it (zscore grading): the
        # inverse Fisher information at the estimate
        settings["_se"] = {n: float(res.std_errors[n]) for n in estimates if n in res.std_errors}
        ref = getattr(self, "last_reference", None)
        exercise = self.state.exercise
        if (ref is not None and exercise is not None and exercise.grading == "zscore"
                and not ref["truth"].effects.off):
            settings["_model_error"] = partial(greybox_model_error, names=tuple(estimates), **ref)
        return estimates, settings

    def _handin_refusal(self) -> str | None:
        """Why the last result cannot be handed in (None: it can): an estimate that failed its checks may
        be wrong, and a hand-in is scored as if it were the student's measurement."""
        res = self.result
        if res is None or res.success:
            return None
        found = "; ".join(c.says for c in res.failed_checks) or res.message
        again = f", e.g. {res.advice[0]}" if res.advice else ""
        return f"this estimate failed its checks: {found} — run it again{again}"

    def hand_in(self):
        return self.handin.hand_in()

    # -- the section's protocol ---------------------------------------------------------------------------
    def result_views(self) -> list:
        return [self.view]

    def run_cost(self) -> RunCost | None:
        """Its simulations with sensitivities, counted as plain integration steps."""
        req, errors = self.request()
        if errors:
            return None
        own = self.own_data
        t_end = req.input_signal()[1] if own is None else float(own.t[-1] - own.t[0])
        n_samples = int(round(t_end * 1000)) + 1 if own is None else own.t.size
        n_params = len(req.names)
        runs = GREYBOX_SIMULATIONS * SHOOTING_COST.get(req.shooting, 1.0)
        steps = int(t_end / DEFAULT_H_MAX * (1 + n_params) * runs)
        peak = n_samples * (4 + len(req.measured)) * (1 + n_params) * 8 * 3     # states, sensitivities, Jacobian
        return RunCost("record length × (1 + parameters)", f"{t_end:g} s × {1 + n_params}", steps, peak,
                       t_end * runs, "estimate fewer parameters at once, or use a shorter record")

    def kept_work(self) -> KeptWork | None:
        views = ["gb"] if self.view.is_current else []
        run: dict = {"views": views}
        upload = kept_upload(self.key, self._upload, self.own_data, self.own_data_key)
        if upload is not None:
            run["file"] = upload.name
        if not views and upload is None:
            return None
        return KeptWork(run, upload)

    @classmethod
    def restore_work(cls, kept: KeptWork, texts) -> list[RestoreStep]:
        run, upload, steps = kept.run or {}, kept.file, []
        if upload is not None:
            steps.append(read_kept(upload))
        # a run on a file that was not kept is not run again on the simulated record instead
        if "gb" in run.get("views", ()) and (upload is not None or not run.get("file")):
            steps.append(RestoreStep(cls.title, lambda section: section.run()))
        return steps

    def snapshot(self) -> SectionSnapshot:
        params, lse, backout, gb = self.routes_content()
        c = self.result_context
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(),
                               content=(self.result, self.last_data, c.get("params"), c.get("scenario"),
                                        bool(c.get("own_record")), (params, lse, backout, gb), self.validation,
                                        self.validation_note))

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        if not snapshot.content:
            return None
        result, data, params, scenario, own, (tab1, lse, backout, gb), _validation, validation_note = snapshot.content
        if result is None and lse is None and backout is None:
            return None
        body, figures = stale_note(snapshot), {}
        if result is not None:
            figures["greybox"] = GreyBoxFigure(data.t, data.signals, result.simulated).layout
            body += (greybox_table_html(result, params, hidden=hidden, scenario=scenario, own_record=own)
                     + "{{greybox}}" + validation_note + _details(result))
        body += "<h3>The three routes side by side</h3>" + routes_html(tab1, lse, backout, gb, hidden=hidden)
        return ReportPart("Grey-box identification (the nonlinear model)", body, figures)

    def __panel__(self):
        controls = pn.Column(self.form, self.notice, self.button, self.cancel_button, self.progress, self.progress_text,
                             self.handin_button, self.verdict, self.handin.confirm, self.upload_note,
                             self.upload, self.mapping, self.simulated_button,
                             pn.FlexBox(*self.downloads, width=270, sizing_mode="fixed"), self.queue_note, width=280)
        explain = pn.pane.HTML(
            "<p class='eha-note'>Grey-box identification (output error, as MATLAB's nlgreyest): the nonlinear model "
            "of eqs. 1-4 is simulated with candidate parameters and compared with the measured signals; "
            "Levenberg-Marquardt minimises the noise-weighted squared differences. It needs only what is "
            "measured (x alone works), not every state as the least squares do. The plant is tab 1's actuator; "
            "the parameters not estimated are held at tab 1's values.</p>", sizing_mode="stretch_width")
        results = pn.Column(explain, self.alert, self.view.banner, self.area, self.routes,
                            sizing_mode="stretch_width", min_width=440)
        return side_by_side(controls, results)


@dataclass(frozen=True, eq=False)
class _OwnRecord:
    """The student's record as read: t, u and the measured signals (SI)."""

    t: np.ndarray
    u: np.ndarray
    signals: dict
    source: str


def _validation(req, res, params, whole, held, u, t_end, d_text, own_record: bool, token):
    """The grey-box estimate's validation the request asks for: (HoldoutValidation or None, why there is none).

    A held-out part starts where the model's own simulation of the estimation part leaves the states the
    record does not measure; a second experiment is the same plant under another excitation, its random
    load and sensor noise drawn anew (the plant, in an exercise the hidden actuator, only simulates it)."""
    if req.validation == "none":
        return None, ""
    try:
        if req.validation == "split":
            read = res.extras.get("intersample", {}).get("used")
            rec = replace(held, intersample=read) if read in ("foh", "zoh") else held
            whole_read = replace(whole, intersample=read) if read in ("foh", "zoh") else whole
            carried = model_state_at(res.params, whole_read, float(held.t[0]), cancel=token)
            return validate_params(res.params, rec, kind="split", signals=req.measured, carried_state=carried,
                                   cancel=token), ""
        if own_record:
            return None, ("a second experiment needs the simulated actuator; on your file, choose the record's "
                          "last third")
        d2 = parse_signal(d_text, name="custom d(t)", seed=validation_seed(req.seed), hold_s=1e-3)
        noise = {s: v for s, v in req.measurement_noise().items() if s in req.measured}
        rec = second_greybox_record(params, u, t_end=t_end, d=d2, noise=noise, seed=req.seed, measured=req.measured)
        return validate_params(res.params, rec, kind="second", signals=req.measured, cancel=token), ""
    except (ComputationError, ValueError) as exc:
        return None, str(exc)


def _details(res) -> str:
    return ("<h4>What the data determine</h4>" + identifiability_html(res)
            + "<h4>Correlation of the estimates</h4>" + correlation_html(res)
            + "<h4>Residual tests</h4>" + verdicts_html(res))


def _run_note(job, data, res, own_record: bool) -> str:
    """Under the table: how long the run took, the record, and for a student's own file how u was taken to
    move between its samples (the file does not say) and why."""
    note = (f"<p class='eha-note'>Simulated and estimated in {job.run_s:.1f} s"
            + (f" (and {job.wait_s:.1f} s waiting for the server)" if job.wait_s > 0.05 else "")
            + f". Record: {html.escape(data.source)}, {data.t.size} samples.</p>")
    how = res.extras.get("intersample") if own_record else None
    if how:
        note += (f"<p class='eha-note eha-gb-intersample'>u between samples: "
                 f"{'linear' if how['used'] == 'foh' else 'held'} ({html.escape(how['how'])}).</p>")
    return note
