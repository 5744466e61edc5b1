"""Tab 3, time domain: least squares on eqs. 15-18, the student's own data, the hand-in."""

from __future__ import annotations

import csv
import dataclasses
import html
import io
import json
import math
from dataclasses import dataclass
from functools import partial

import numpy as np
import panel as pn

from eha_core.board import lse_model
from eha_core.errors import ComputationError, FieldError, not_allowed
from eha_core.experiments import (
    LSE_INPUT,
    LSE_INPUT_RICH,
    LSE_INPUT_RICH_T_END,
    LSE_SCENARIOS,
    lse_cost,
    lse_data,
    lse_resimulation,
    run_lse_table,
)
from eha_core.grading import lse_model_error
from eha_core.identify.disturbance import MAX_FREQ_HZ
from eha_core.identify.holdout import (
    VALIDATION_WORDS,
    lse_model_params,
    second_lse_record,
    split_record,
    validate_params,
    validation_input,
    validation_seed,
)
from eha_core.identify.lse import identify_lse
from eha_core.identify.lse_reading import disturbance_leak
from eha_core.params import ParameterError
from eha_core.signals import SignalSpecError, parse_signal

from ..render import plots
from ..render.glossary import term
from ..render.layout import BUTTON_CONTRAST, side_by_side
from ..render.tables import (
    SCENARIOS,
    UNITS,
    assumed_model_html,
    lse_table_html,
    table4_html,
)
from ..runtime.limits import RunCost
from ..runtime.shared import shared_results
from ..runtime.tasks import apply_locked, on_click, watch
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

__all__ = ["LeastSquaresPanel", "LseRequest", "LSE_FORM", "LSE_DEFAULTS", "parse_lse"]

#: The columns the least squares need from a data file (eqs. 15-18).
LSE_COLUMNS = ("t", "x", "v", "p1", "p2", "u")


#: The estimates' symbols and SI units in the exported files (the tables' vocabulary).
_SYMBOLS = {"Af": "A_f", "d0": "d_0", "beta_e": "β_e", "d_sin": "d_sin", "d_cos": "d_cos"}

EXCITATIONS = {"paper": "u = 6 sin(4πt), 5 s (default)",
               "rich": "u = 8 sin(4πt) + 4 sin(10πt), 20 s (narrows B)"}

# -- the least-squares request ---------------------------------------------------------------

LSE_FORM = (Group("Least squares", (
    Field("lse_scenario", "disturbance", "select", options=tuple(SCENARIOS.items()), short="disturbance"),
    Field("lse_custom", "custom d(t)", "text", short="custom d(t)",
          tip="none, sine:AMP[:FREQ_HZ], white:SIGMA, or any signal of the simulation, e.g. sine:500:2+noise:100:1"),
    Field("lse_model", "disturbance model", "select", options=(("constant", "constant d0 (the paper's)"),
                                                               ("harmonic", "d0 + a sinusoid")),
          short="disturbance model"),
    Field("lse_freq", "harmonic frequency", "text", unit="Hz", placeholder="blank: estimate it",
          short="harmonic frequency"),
    Field("lse_estimator", "estimator", "select",
          options=(("ls", "least squares (the paper's)"), ("iv", "instrumental variables")), short="estimator",
          tip="least squares is biased when the force noise enters the filtered dv/dt (M, βe low); instrumental "
              "variables take their regressors from a noise-free simulation of the model (as SRIVC) and are not"),
    Field("lse_seed", "noise seed", "integer", lo=0, hi=10**6, short="noise seed"),
    Field("lse_excitation", "excitation", "select", options=tuple(EXCITATIONS.items()), short="excitation"),
    Field("lse_validation", "validation", "select", options=tuple(VALIDATION_WORDS.items()), short="validation",
          tip="the identified model simulated on data it was not fitted to: a second experiment (another "
              "excitation, a new noise draw), or the record's last third, held out of the estimation"),
)), Group("Sensor noise (simulated measurements)", (
    Field("lse_noise_x", "σ of x", "number", unit="mm", lo=0.0, hi=10.0, short="σ x",
          tip="white Gaussian noise added to the position sensor, drawn from the noise seed"),
    Field("lse_noise_v", "σ of v", "number", unit="mm/s", lo=0.0, hi=1000.0, short="σ v",
          tip="white Gaussian noise added to the velocity sensor"),
    Field("lse_noise_p", "σ of p1, p2", "number", unit="MPa", lo=0.0, hi=10.0, short="σ p",
          tip="white Gaussian noise added to each pressure sensor"),
), collapsible=True, collapsed=True),)
LSE_DEFAULTS = {"lse_scenario": "none", "lse_custom": "sine:1000:3", "lse_model": "constant", "lse_freq": "",
                "lse_estimator": "ls",
                "lse_seed": "0", "lse_excitation": "paper", "lse_validation": "none", "lse_noise_x": "0",
                "lse_noise_v": "0", "lse_noise_p": "0"}
_LSE_FIELDS = {f.name: f for g in LSE_FORM for f in g.fields}


@dataclass(frozen=True)
class LseRequest:
    """A parsed least-squares request."""

    scenario: str = "none"
    custom: str = "sine:1000:3"
    model: str = "constant"
    frequency_hz: float | None = None
    seed: int = 0
    excitation: str = "paper"
    noise: tuple[float, float, float] = (0.0, 0.0, 0.0)     # σ of x [mm], v [mm/s], p1 and p2 [MPa]
    estimator: str = "ls"
    validation: str = "second"

    def measurement_noise(self) -> dict[str, float] | None:
        """The sensors' noise in SI, for :func:`eha_core.experiments.lse_data` (None: noise-free)."""
        sx, sv, sp = self.noise
        if not any(self.noise):
            return None
        return {"x": sx * 1e-3, "v": sv * 1e-3, "p1": sp * 1e6, "p2": sp * 1e6}

    def disturbance(self):
        """d(t): a scenario of Table 4, or the custom text in the signal grammar."""
        spec = self.custom if self.scenario == "custom" else LSE_SCENARIOS[self.scenario]
        return parse_signal(spec, name="custom d(t)", seed=self.seed, hold_s=1e-3)

    def input_signal(self):
        return (LSE_INPUT, 5.0) if self.excitation == "paper" else (LSE_INPUT_RICH, LSE_INPUT_RICH_T_END)


#: The fields that describe the simulated experiment (its disturbance, excitation, noise): they do not apply to
#: the student's own file.
OWN_FILE_HIDDEN = ("lse_scenario", "lse_custom", "lse_seed", "lse_excitation", "lse_noise_x", "lse_noise_v",
                   "lse_noise_p")


def lse_hidden(texts: dict) -> list[str]:
    hidden = []
    if texts.get("lse_scenario") != "custom":
        hidden.append("lse_custom")
    if texts.get("lse_model") != "harmonic":
        hidden.append("lse_freq")
    return hidden


def parse_lse(texts: dict, fields: dict | None = None) -> tuple[LseRequest, dict]:
    """The least-squares request the form describes, and a message per invalid field (``fields``: the
    form's fields as an exercise bounds them, see :func:`exercise_fields`)."""
    hidden = set(lse_hidden(texts))
    values, errors = parse_fields((fields or _LSE_FIELDS).values(), texts, skip=hidden)
    freq = None
    text = str(texts.get("lse_freq", "")).strip()
    if "lse_freq" not in hidden and text:
        try:
            freq = float(text.replace(",", "."))
            if not (math.isfinite(freq) and 0 < freq < MAX_FREQ_HZ):
                raise ValueError
        except ValueError:
            errors["lse_freq"] = str(FieldError("harmonic frequency", text, f"a number in (0, {MAX_FREQ_HZ:g}) Hz, "
                                                "or blank to estimate it", value_text=text))
            freq = None
    req = LseRequest(scenario=values.get("lse_scenario", "none"), custom=texts.get("lse_custom", ""),
                     model=values.get("lse_model", "constant"), frequency_hz=freq,
                     seed=values.get("lse_seed", 0), excitation=values.get("lse_excitation", "paper"),
                     estimator=values.get("lse_estimator", "ls"), validation=values.get("lse_validation", "none"),
                     noise=tuple(float(values.get(k, 0.0)) for k in ("lse_noise_x", "lse_noise_v", "lse_noise_p")))
    if "lse_custom" not in hidden and not errors.get("lse_custom"):
        try:
            req.disturbance()
        except (ValueError, SignalSpecError) as exc:
            errors["lse_custom"] = " ".join(str(exc).split())
    return req, errors


#: The sensor-noise fields and the signals whose σ they set, with the display scale (value_SI / scale).
_NOISE_FIELDS = {"lse_noise_x": (("x",), 1e-3), "lse_noise_v": (("v",), 1e-3), "lse_noise_p": (("p1", "p2"), 1e6)}
#: The parameters the least squares estimate (eqs. 15-18): the ones a hand-in from them can carry.
LSE_ESTIMATED = ("M", "B", "Af", "beta_e", "d0")


def exercise_fields(conditions) -> dict:
    """The form's fields under an exercise's conditions: each σ field's lower bound is the exercise's
    noise floor (a student may raise the noise, not lower it)."""
    if conditions is None:
        return dict(_LSE_FIELDS)
    lows = {name: max(conditions.noise_floor(sig) for sig in signals) / scale
            for name, (signals, scale) in _NOISE_FIELDS.items()}
    return with_lower_bounds(_LSE_FIELDS, lows, "this exercise's sensor noise")


def velocity_from_position(data):
    """The record without a velocity sensor: v as the central difference of the measured x (its noise
    amplified by 1/Ts; the least squares' filter H(s) of eqs. 16-18 then smooths it like the others)."""
    return dataclasses.replace(data, v=np.gradient(data.x, data.t), source=data.source + ", v from dx/dt")


def validation_html(val, choice: str = "none", why_not: str = "") -> str:
    """The validation's fits in the words of every fit ("fit 97.3 % (simulation, initial conditions
    estimated)"), the record they are on and how its initial state was taken; or why there is none."""
    if val is None:
        if choice == "none":
            return ("<p class='eha-note eha-validation'>Validation: none chosen; the fit above is on the "
                    "estimation data only.</p>")
        return f"<p class='eha-note eha-validation'>No validation: {html.escape(why_not)}</p>" if why_not else ""
    head = (f"<h4 class='eha-validation-head'>Validation on {html.escape(VALIDATION_WORDS.get(val.kind, val.kind))}"
            "</h4>")
    if not val.success:
        return head + f"<p class='eha-warn eha-validation'>{html.escape(val.message)}</p>"
    fits = "".join(f"<li><b>{html.escape(s)}</b>: {html.escape(label)}</li>" for s, label in val.labels.items())
    how = val.initial_how[:1].upper() + val.initial_how[1:]
    return (head + f"<ul class='eha-validation'>{fits}</ul><p class='eha-note'>Record: {html.escape(val.record)}, "
            f"which the model was not fitted to. {html.escape(how)}.</p>")


def lse_validation(req, res, params, held, u, t_end, disturbance, measured, token):
    """The least squares' validation the request asks for (a HoldoutValidation, or None) and why there is none."""
    if req.validation == "none":
        return None, ""
    try:
        model, d_model = lse_model_params(res, params)
    except ParameterError as exc:
        return None, f"the estimate is not physical ({exc})"
    signals = tuple(measured)
    if req.validation == "split":
        return validate_params(model, held, kind="split", signals=signals, u=u, d=d_model, cancel=token), ""
    # the second experiment's random disturbance is drawn anew, as its sensors' noise
    d2 = disturbance(dataclasses.replace(req, seed=validation_seed(req.seed)))
    rec = second_lse_record(params, u, t_end=t_end, disturbance=d2, seed=req.seed,
                            measurement_noise=req.measurement_noise(), cancel=token)
    if "v" not in measured:
        rec = velocity_from_position(rec)
    return validate_params(model, rec, kind="second", signals=signals, u=validation_input(u, t_end), d=d_model,
                           cancel=token), ""


def _simulated_run(params, req, disturbance, u, t_end, measured, board_model, token):
    """The least squares on a simulated experiment: the record (as the sensors measure it), the estimate,
    its re-simulation, the board's model, the harmonic model beside and the validation (see
    ``LeastSquaresPanel.run``). With the split, the estimator and its re-simulation see the first part only."""
    data = lse_data(params, disturbance(req), u=u, t_end=t_end, seed=req.seed,
                    measurement_noise=req.measurement_noise(), cancel=token)
    if "v" not in measured:
        data = velocity_from_position(data)
    held = None
    if req.validation == "split":
        data, held = split_record(data)
    res = identify_lse(data, params, disturbance_model=req.model, disturbance_freq_hz=req.frequency_hz,
                       estimator=req.estimator, cancel=token)
    try:
        resim = lse_resimulation(res, params, data, u=u, cancel=token)
        resim_error = ""
    except ParameterError as exc:
        resim, resim_error = None, f"No re-simulation: the estimate is not physical ({exc})."
    validation = lse_validation(req, res, params, held, u, t_end, disturbance, measured, token)
    return (res, plots.lse_view(data, resim), resim_error, data, resim, board_model(res),
            _beside(req.model, res, data, params, token), validation)


def _beside(model: str, res, data, params, token):
    """The harmonic model on the same data and why the constant one failed: (alternative, leak),
    (None, None) when the constant model left no sinusoid out (see disturbance_leak)."""
    if model != "constant" or not res.success:
        return None, None
    try:
        alt = identify_lse(data, params, disturbance_model="harmonic", estimator=res.estimator, cancel=token)
    except ComputationError:
        return None, None
    leak = disturbance_leak(res, alt, data, params)
    return (alt, leak) if leak is not None else (None, None)


def validation_view(val):
    """The validation record and the model's simulation on it, as :class:`~eha_app.render.plots.LseFitFigure` draws."""
    from types import SimpleNamespace

    measured = SimpleNamespace(t=val.t, x=val.measured.get("x", val.simulated[:, 0]),
                               p1=val.measured.get("p1", val.simulated[:, 2]))
    model = SimpleNamespace(t=val.t, x=val.simulated[:, 0], p1=val.simulated[:, 2])
    return plots.lse_view(measured, model, label="simulated with the estimates (not fitted to this record)")


def _own_run(own, params, req, board_model, token):
    """The least squares on the student's record: as :func:`_simulated_run` gives it, without re-simulation
    (the input is known only at its samples) and without a second experiment (there is no plant to run)."""
    rec, held = split_record(own) if req.validation == "split" else (own, None)
    res = identify_lse(rec, params, disturbance_model=req.model, disturbance_freq_hz=req.frequency_hz,
                       estimator=req.estimator, cancel=token)
    if held is not None:
        try:
            model_params, d_model = lse_model_params(res, params)
            validation = (validate_params(model_params, held, kind="split", d=d_model, cancel=token), "")
        except ParameterError as exc:
            validation = (None, f"the estimate is not physical ({exc})")
    else:
        validation = (None, "" if req.validation == "none" else
                      "a second experiment needs the simulated actuator; on your file, choose the record's last third")
    return (res, plots.lse_view(rec, None), (f"Your data ({html.escape(own.source)}, {own.t.size} samples): the "
                                             "model is not re-simulated (the input is known only at its samples)."),
            rec, None, board_model(res), _beside(req.model, res, rec, params, token), validation)


class LeastSquaresPanel(Section):
    """Time domain: least squares on eqs. 15-18, one scenario or Table 4."""

    key = "least_squares"
    title = "Least squares"
    defaults = LSE_DEFAULTS
    guide_step = GuideStep(
        "3. Least squares", "Step 3, time domain: estimate M, B, A<sub>f</sub>, d<sub>0</sub> and β<sub>e</sub> from "
        "the sensors' records (eqs. 15-18, Tables 3-4); the form chooses the disturbance (none to start).",
        "3. Identification: least squares", "Press <b>Run least squares</b>.")
    form_css = "eha-lse-form"
    content_css = "eha-lse-table"
    run_buttons = ("Run least squares", "Run all four scenarios (Table 4)")

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state = self.state
        self.result = None
        self.result_context = {}            # what the table shows beside the result (lse_table_html's keywords)
        self.all_results = None
        self.all_context = {}
        # an exercise's conditions: the noise floors bound the σ fields, its disturbance always acts
        ex = state.exercise if state.hidden else None
        self.conditions = ex.conditions if ex is not None else None
        self.fields = exercise_fields(self.conditions)
        self.last_settings: dict = {}
        self.last_conditions: dict = {}
        texts = raised_to_bounds(self.initial_texts(), self.fields, _NOISE_FIELDS)
        self.form = Form(spec=[g.to_spec() for g in regrouped(LSE_FORM, self.fields)], values=texts,
                         url_defaults=LSE_DEFAULTS, width=270,
                         css_classes=[self.form_css], margin=(5, 10))
        watch(self.form, self._update_enabled, "values")
        self.table = pn.pane.HTML("<p>Choose a disturbance and run the least squares.</p>",
                                  sizing_mode="stretch_width", css_classes=["eha-lse-table"])
        # the figure is built with the first result: an empty figure is no use to
        # anyone and makes Bokeh complain that it cannot range it
        self.figure: plots.LseFitFigure | None = None
        self.plot = pn.Column(sizing_mode="stretch_width", css_classes=["eha-lse-plot"])
        # the fit on data the estimate did not see: its words, and the record against the model's simulation
        self.validation = None
        self.validation_note = ""
        self.validation_pane = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-lse-validation"])
        self.validation_figure: plots.LseFitFigure | None = None
        self.validation_plot = pn.Column(sizing_mode="stretch_width", css_classes=["eha-lse-validation-plot"])
        self.area = pn.Column(self.table, self.plot, self.validation_pane, self.validation_plot,
                              sizing_mode="stretch_width")
        self.table4 = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-table4-pane"])
        self.table4_area = pn.Column(self.table4, sizing_mode="stretch_width")
        self.view = ResultView("lse", self.area, run_hint="Press “Run least squares” to update it.")
        self.table4_view = ResultView("table4", self.table4_area,
                                      run_hint="Press “Run all four scenarios” to update it.")
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-lse-alert"])
        self.notice = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-lse-notice"])
        self.queue_note = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-queue-note"],
                                       styles={"color": "#555", "font-size": "12px"})
        self.button = pn.widgets.Button(label="Run least squares", color="primary", width=260,
                                        css_classes=["eha-run-lse"])
        self.all_button = pn.widgets.Button(label="Run all four scenarios (Table 4)", color="success", width=260,
                                            css_classes=["eha-run-table4"], stylesheets=[BUTTON_CONTRAST])
        on_click(self.button, lambda _e: self.run())
        on_click(self.all_button, lambda _e: self.run_all())
        # an exercise: hand in the hidden parameters' estimates (Table 4 would show the truth)
        self.all_button.visible = not state.hidden
        self.handin = HandInBox(self, "lse", self._handin_estimates)
        self.handin_button, self.verdict = self.handin.button, self.handin.verdict
        # the student's own data (CSV or .mat), instead of the simulated sensors
        self.own_data = None                # MeasuredData of an upload, when one is in use
        self.own_source: dict = {}          # what a hand-in records of that file (uploads.file_source)
        self.result_source: dict = {}       # ... and of the data behind the last result
        self.own_data_key = None
        self.last_data = None               # the data behind the table and the plot (for downloads)
        self.last_resim = None              # the plot's re-simulation with the estimates
        self._upload = None
        self.upload = FileUpload(accept=".csv,.mat", width=260, css_classes=["eha-lse-upload"],
                                 label="Your own measurements (a CSV or .mat file)")
        watch(self.upload, self._uploaded, "value")
        self.upload_note = pn.pane.HTML(
            "<span class='eha-note'>Or use your own measurements: a CSV or MATLAB .mat file with columns "
            "t, x, v, p1, p2, u (SI, or units in the header such as <code>p1[MPa]</code>).</span>",
            width=270, css_classes=["eha-lse-upload-note"])
        self.column_mapping = ColumnMapping(
            {c: (c, ()) for c in LSE_COLUMNS}, "lse",
            if_missing={"v": "No velocity in your file? The least squares needs v (eq. 15a: its regressors are v "
                             "and dv/dt); grey-box estimation (tab 3, “Grey-box (nonlinear)”) needs no velocity: "
                             "x alone works there."})
        self.mapping = self.column_mapping.panel
        # the part of the student's record to use (preprocessing: a time range)
        self.window_form = Form(spec=[Group("Part of your record to use", (
            Field("own_from", "from t", "text", unit="s", placeholder="its start", short="from t"),
            Field("own_to", "to t", "text", unit="s", placeholder="its end", short="to t"),
        )).to_spec()], values={"own_from": "", "own_to": ""}, width=270, visible=False,
            css_classes=["eha-lse-window"], margin=(5, 10))
        # shown through a box: the form's own "visible" did not hide it when the page first drew it
        self.window_box = pn.Column(self.window_form, visible=False, margin=0)
        watch(self.window_form, lambda _e: self._update_enabled(), "values")
        self.simulated_button = pn.widgets.Button(label="Back to simulated data", width=260, visible=False,
                                                  css_classes=["eha-lse-simulated"])
        on_click(self.simulated_button, lambda _e: self.use_simulated())
        self.downloads = [
            download(lambda: self.data_bytes("csv"), "eha_lse_data.csv", "Data (CSV)", "eha-dl-data-csv"),
            download(lambda: self.data_bytes("mat"), "eha_lse_data.mat", "Data (.mat)", "eha-dl-data-mat"),
            download(lambda: self.estimates_bytes("csv"), "eha_lse_estimates.csv", "Estimates (CSV)", "eha-dl-est-csv"),
            download(lambda: self.estimates_bytes("json"), "eha_lse_estimates.json",
                     "Estimates (JSON)", "eha-dl-est-json"),
        ]
        state.param.watch(self._update_enabled, "valid")
        state.param.watch(self._inputs_changed, ["params", "valid"])
        self._update_enabled()

    def request(self) -> tuple[LseRequest, dict]:
        return parse_lse(self.form.values, self.fields)

    def _conditions_refusal(self, req) -> str | None:
        """Why the exercise's conditions refuse this run (None: they allow it)."""
        c = self.conditions
        if c is None:
            return None
        why = c.lse_refusal()
        if why:
            return why
        if req.input_signal()[1] > c.max_record_s:
            return str(not_allowed("excitation", EXCITATIONS[req.excitation],
                                   f"this exercise's records are at most {c.max_record_s:g} s"))
        return None

    def _disturbance(self, req):
        """d(t) as the student chose it, plus the load the exercise always applies."""
        extra = self.conditions.disturbance.strip() if self.conditions is not None else "none"
        if extra.lower() in ("", "none"):
            return req.disturbance()
        spec = req.custom if req.scenario == "custom" else LSE_SCENARIOS[req.scenario]
        text = extra if spec.strip().lower() in ("", "none") else f"{spec}+{extra}"
        return parse_signal(text, name="custom d(t)", seed=req.seed, hold_s=1e-3)

    def run_key(self):
        """What a least-squares run with the current inputs is computed from (None if they are not valid)."""
        req, errors = self.request()
        if errors or not self.state.valid or self.window_errors():
            return None
        return self.state.params, req, self.own_data_key, self.window() if self.own_data is not None else None

    def window(self) -> tuple[float | None, float | None]:
        """The time range of the student's record to use (None: its start or end)."""
        out = []
        for name in ("own_from", "own_to"):
            text = str(self.window_form.values.get(name, "")).strip().replace(",", ".")
            out.append(float(text) if text else None)
        return out[0], out[1]

    def window_errors(self) -> dict:
        """Messages of the time-range fields (in seconds, within the record, at least 50 samples)."""
        if self.own_data is None:
            return {}
        t = self.own_data.t
        errors, values = {}, {}
        for name, label in (("own_from", "from t"), ("own_to", "to t")):
            text = str(self.window_form.values.get(name, "")).strip()
            if not text:
                continue
            try:
                v = float(text.replace(",", "."))
                if not math.isfinite(v):
                    raise ValueError
            except ValueError:
                errors[name] = str(FieldError(label, text, "enter a time in s, or leave it blank", value_text=text))
                continue
            if not t[0] <= v <= t[-1]:
                errors[name] = str(FieldError(label, text, f"your record runs from {t[0]:g} to {t[-1]:g} s",
                                              value_text=f"{text} s"))
            values[name] = v
        if not errors:
            lo, hi = values.get("own_from", t[0]), values.get("own_to", t[-1])
            n = int(np.count_nonzero((t >= lo) & (t <= hi)))
            if n < 50:
                target = "own_to" if "own_to" in values else "own_from"
                typed = str(self.window_form.values[target])
                errors[target] = str(FieldError("to t" if target == "own_to" else "from t", typed,
                                                f"the range [{lo:g}, {hi:g}] s holds {n} samples; need at least 50",
                                                value_text=f"{typed} s"))
        return errors

    def windowed(self):
        """The student's record cut to the chosen time range."""
        from eha_core.identify.lse import MeasuredData

        d = self.own_data
        lo, hi = self.window()
        keep = (d.t >= (d.t[0] if lo is None else lo)) & (d.t <= (d.t[-1] if hi is None else hi))
        if keep.all():
            return d
        return MeasuredData(d.t[keep], d.x[keep], d.v[keep], d.p1[keep], d.p2[keep], d.u[keep],
                            source=f"{d.source}, t in [{d.t[keep][0]:g}, {d.t[keep][-1]:g}] s")

    # -- the student's own data ---------------------------------------------------------
    def _uploaded(self, _event) -> None:
        if self.upload.value is None:
            return
        self._upload = (bytes(self.upload.value), upload_name(self.upload.filename))
        self.read_upload()

    def use_file(self, data: bytes, filename: str, mapping: dict | None = None):
        """Use ``data`` (a file named ``filename``) as the student's data, its columns read with ``mapping``
        (None: by their names); returns the job that reads it."""
        self._upload = (data, filename)
        return self.read_upload(mapping)

    def read_upload(self, mapping: dict | None = None):
        """Read the uploaded file (in a worker): use it, or ask which columns are which."""
        from eha_core.data import DataError, file_columns, read_data, sample_time
        from eha_core.identify.lse import MeasuredData

        if self._upload is None:
            return None
        data, filename = self._upload
        try:
            check_size(data, filename)
        except ValueError as exc:
            self._upload_problem(str(exc))
            return None

        def compute(_token):
            try:
                cols = read_data(data, LSE_COLUMNS, name="your file", filename=filename, mapping=mapping,
                                 min_rows=50)
            except DataError as exc:
                if exc.missing_columns:
                    return "map", file_columns(data, filename, name="your file"), str(exc)
                raise
            ts = sample_time(cols["t"], name="your file", path=filename)
            return "ok", MeasuredData(**cols, source=filename), ts, file_source(filename, data)

        def show(out, _job):
            if out[0] == "map":
                self._ask_mapping(out[1], filename)
                return
            _, measured, ts, source = out
            self.own_data = measured
            self.own_source = source
            self.own_data_key = (filename, len(data), tuple(sorted((mapping or {}).items())))
            self.mapping.visible = False
            self.window_box.visible = True
            self.simulated_button.visible = True
            self._update_enabled()          # the run waited for the columns
            self.upload_note.object = (f"<span class='eha-ok'>Using your data: {html.escape(filename)}, "
                                       f"{measured.t.size} samples every {ts * 1e3:.4g} ms. "
                                       "Run the least squares on it.</span>")
            self._inputs_changed()

        return self.runner.run("reading your data", compute, show, fail=self._upload_problem, note=self._note)

    def _upload_problem(self, message: str) -> None:
        self.upload_note.object = f"<span class='eha-warn'>{html.escape(message)}</span>"

    def _ask_mapping(self, available: list, filename: str) -> None:
        """Which of the file's columns is t, x, v, p1, p2, u? (a question: the run waits for the answer)"""
        self.column_mapping.ask(available, filename, lambda chosen: self.read_upload(mapping=chosen))
        self.simulated_button.visible = True        # or give up on the file
        self.upload_note.object = (f"<span class='eha-note'>{html.escape(filename)} is read once you say which "
                                   "column is which (below).</span>")
        self._update_enabled()

    @property
    def mapping_selects(self) -> dict:
        return self.column_mapping.selects

    @property
    def mapping_button(self):
        return self.column_mapping.button

    def use_simulated(self) -> None:
        self.own_data, self.own_data_key, self._upload = None, None, None
        self.simulated_button.visible = False
        self.window_box.visible = False
        self.mapping.visible = False
        self.upload_note.object = "<span class='eha-note'>Using the simulated sensors again.</span>"
        self._update_enabled()

    # -- downloads ---------------------------------------------------------------------
    def data_bytes(self, kind: str) -> bytes:
        """The measurements behind the table and the plot, as CSV or .mat (read back by the upload),
        with the plot's re-simulation with the estimates beside them (``x_resim``, ...) when there is one."""
        from eha_core.data import write_data

        d = self.last_data
        cols = {"t": d.t, "x": d.x, "v": d.v, "p1": d.p1, "p2": d.p2, "u": d.u}
        r = self.last_resim
        if r is not None and r.t.size == d.t.size:
            cols.update(x_resim=r.x, v_resim=r.v, p1_resim=r.p1, p2_resim=r.p2)
        return write_data(cols, kind, units="si")      # t[s], x[m], p1[Pa]...: read back as they are

    def estimates_bytes(self, kind: str) -> bytes:
        """The estimates with their standard errors and 95 % intervals (no hidden nominal value)."""
        res = self.result
        rows = []
        for k, v in res.estimates.items():
            lo, hi = res.ci95[k]
            nominal = None if k in self.state.hidden else res.nominal.get(k)
            rows.append({"parameter": k, "symbol": _SYMBOLS.get(k, k), "unit": UNITS.get(k, ""),
                         "estimate": float(v), "std_error": float(res.std_errors[k]),
                         "ci95_low": float(lo), "ci95_high": float(hi),
                         "nominal": None if nominal is None else float(nominal)})
        if kind == "json":
            source = self.last_data.source if self.last_data is not None else ""
            return json.dumps({"disturbance_model": res.disturbance_model, "data": source,
                               "estimates": rows}, indent=1).encode()
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
        return buf.getvalue().encode()

    def table4_key(self):
        req, errors = self.request()
        return None if "lse_seed" in errors or not self.state.valid else (self.state.params, int(req.seed))

    def _inputs_changed(self, *_events) -> None:
        why = "a parameter on tab 1 is not valid" if not self.state.valid else ""
        self.view.inputs_changed(self.run_key(), why=why)
        self.table4_view.inputs_changed(self.table4_key(), why=why)
        self._handin_tip()

    def _handin_tip(self) -> None:
        """The hand-in button's state and tooltip say what is true now (it said "run the least squares
        first" after a run)."""
        if not self.state.hidden:
            return
        names = ", ".join(FIELD_LABELS.get(n, n) for n in self.state.hidden if n in LSE_ESTIMATED)
        if self.result is None:
            self.handin.set_tip(False, "run the least squares first: the hand-in takes the estimates of its table")
        elif self.result_context.get("own_record") and not self.handin.takes_files:
            self.handin.set_tip(False, "a hand-in comes from your actuator's experiment, not from a file: run the "
                                       "least squares on the simulated sensors")
        elif self.view.status == "current":
            self.handin.set_tip(True, f"hand in the estimates of {names} in the table")
        else:
            self.handin.set_tip(True, f"hand in the estimates of {names} in the table, from the previous settings "
                                      "(run again to hand in estimates for the new ones)")

    def _update_enabled(self, *_events) -> None:
        _, errors = self.request()
        self.form.errors = errors
        # on the student's own file, the settings that make the simulated record do not apply: not shown (one
        # that is not valid stays, with its message, since it holds the run)
        own = [f for f in OWN_FILE_HIDDEN if f not in errors] if self.own_data is not None else []
        self.form.hidden = list(dict.fromkeys(lse_hidden(self.form.values) + own))
        window_errors = self.window_errors()
        self.window_form.errors = window_errors
        errors = {**errors, **window_errors}
        ok = self.state.valid
        waiting = self.column_mapping.waiting
        self.button.disabled = not ok or bool(errors) or waiting
        self.all_button.disabled = not ok or "lse_seed" in errors
        self.notice.object = run_off_notice("Run least squares", tab1_valid=ok, errors=errors, waiting=waiting,
                                            buttons="The buttons are")
        self.notice.visible = not ok or bool(errors) or waiting
        self._inputs_changed()

    def _fail(self, message: str) -> None:
        self.alert.object = f"The identification failed: {message}"
        self.alert.visible = True

    def run(self):
        req, errors = self.request()
        if errors or not self.state.valid or self.column_mapping.waiting:
            return None
        u, t_end = req.input_signal()
        self.alert.visible = False
        try:
            self.check_cost()
        except ValueError as exc:
            self._fail(str(exc))
            return None
        refusal = self._conditions_refusal(req)
        if refusal:
            self._fail(refusal)
            return None
        measured = self.conditions.measured if self.conditions is not None else ("x", "v", "p1", "p2")
        run_settings = self.settings()
        run_conditions = ({"noise": req.measurement_noise() or {}, "disturbance_applied": self._disturbance_text(req),
                           "v": "measured" if "v" in measured else "dx/dt of the measured x"}
                          if self.conditions is not None else {})
        params = self.state.params
        key = self.run_key()
        scenario = req.scenario if req.excitation == "paper" else None

        own = self.windowed() if self.own_data is not None else None
        paper_note = ""
        if own is not None:
            # on a file, a hidden value is never taken as known: it would come back out of the estimates
            try:
                params, paper_note = known_on_file(self.state, LSE_ESTIMATED)
            except ParameterError as exc:
                self._fail(str(exc))
                return None
        kp = self.state.kp
        own_source = dict(self.own_source)
        what = (f"your data {own.source}" if own is not None else
                f"{SCENARIOS.get(req.scenario, req.scenario)}, {req.model} model")

        def board_model(res):
            """The run as the board shows it: eq. 24 with its estimates (None if they are not physical)."""
            if not res.success:
                return None
            try:
                # the paper's model with the estimates (a variant actuator's effects are the plant's only)
                return lse_model(res, params.replace(effects=None), kp, "LS",
                                 f"least squares ({what}) → eq. 24, Kp = {kp:g} V/m")
            except ParameterError:
                return None

        def compute(token):
            if own is not None:     # the student's measurements: nothing to simulate
                return _own_run(own, params, req, board_model, token)
            return shared_results.get(shared_key, simulated, token)

        # a simulated run is a function of these alone: students with the same inputs share it
        simulated = partial(_simulated_run, params, req, self._disturbance, u, t_end, measured, board_model)
        shared_key = ("least squares", params, req, tuple(measured), self._disturbance_text(req), kp, what)

        def show(out, job):
            res, view, resim_error, data, resim, model, (alt, leak), (validation, why_not) = out
            self.result = res
            self.validation = validation
            self.validation_note = validation_html(validation, req.validation, why_not)
            self.last_settings, self.last_conditions = run_settings, run_conditions
            # what the hand-in's grading needs of the experiment (the route's own error on it, at the truth)
            self.last_reference = None if own is not None else dict(
                truth=params, u=u, t_end=t_end, disturbance=self._disturbance(req),
                harmonic="sine" in self._disturbance_text(req).lower(), measured=tuple(measured),
                noise=req.measurement_noise(), seed=req.seed)
            self.result_context = {"alternative": alt, "leak": leak, "seed": req.seed, "own_record": own is not None}
            self.result_source = own_source if own is not None else {"kind": "simulated"}
            self.last_data, self.last_resim = data, resim
            for d in self.downloads:
                d.disabled = False
            # the student's record is identified, not simulated: one sentence that says so, not two that disagree
            done = "Identified" if own is not None else "Simulated, identified and re-simulated"
            note = (f"<p class='eha-note'>{done} in {job.run_s * 1e3:.0f} ms"
                    + (f" (and {job.wait_s:.1f} s waiting for the server)" if job.wait_s > 0.05 else "")
                    + f". {resim_error}</p>" + paper_note)
            warn = "" if res.success else f"<div class='eha-warn'>{res.message}</div>"
            self.table.object = (warn + lse_table_html(res, scenario if scenario != "custom" else None,
                                                       hidden=self.state.hidden, **self.result_context) + note
                                 + assumed_model_html("lse"))
            self.figure = _fit_figure(self.figure, self.plot, view)
            self._draw_validation(validation)
            self.view.shown(key)
            self._inputs_changed()          # typed while it computed
            if model is not None:
                # the board's list is rebuilt in a page update of its own: the result goes out first
                apply_locked(partial(self.session.post, "board", model))

        return self.runner.run("least squares", compute, show, fail=self._fail, busy=[self.area], note=self._note)

    def _draw_validation(self, val) -> None:
        """The validation's words and, when the model was simulated, its record against the model."""
        self.validation_pane.object = self.validation_note
        if val is None or val.simulated is None:
            self.validation_plot.objects = []
            self.validation_figure = None
            return
        self.validation_figure = _fit_figure(self.validation_figure, self.validation_plot, validation_view(val))

    def run_all(self):
        req, errors = self.request()
        if not self.state.valid or "lse_seed" in errors:
            return None
        self.alert.visible = False
        params = self.state.params
        seed = int(req.seed)                # as the form parsed it ("1e3", "1_000": 1000), not the raw text
        key = self.table4_key()

        def compute(token):
            results = {m: run_lse_table(params, disturbance_model=m, seed=seed, cancel=token)
                       for m in ("constant", "harmonic")}
            leaks = {}
            for scen in ("200 sin", "5000 sin"):
                # the data of the two models' runs (the same simulation), for the regressors the sinusoid leaks into
                data = lse_data(params, LSE_SCENARIOS[scen], seed=seed, cancel=token)
                leak = disturbance_leak(results["constant"][scen], results["harmonic"][scen], data, params)
                if leak is not None:
                    leaks[scen] = leak
            return results, leaks

        def show(out, job):
            results, leaks = out
            self.all_results = results
            self.all_context = {"leaks": leaks, "seed": seed}
            self.table4.object = (f"<h4>Table 4: four scenarios, both disturbance models, beside the paper "
                                  f"({job.run_s * 1e3:.0f} ms)</h4>" + table4_html(results, **self.all_context))
            self.table4_view.shown(key)
            self._inputs_changed()

        return self.runner.run("Table 4", compute, show, fail=self._fail, busy=[self.table4_area], note=self._note)

    def _handin_estimates(self):
        """The hidden parameters the least squares estimate, from the last run, with its settings."""
        if self.result is None:
            return None
        estimates = {n: float(self.result.estimates[n]) for n in self.state.hidden if n in self.result.estimates}
        settings = dict(self.last_settings or self.settings())
        if self.result_context.get("own_record"):
            settings["record"] = "the student's own file"
        # the data the estimates came from (HandInBox refuses a file's unless the exercise allows them)
        settings["_source"] = dict(self.result_source) or {"kind": "simulated"}
        settings["_conditions"] = dict(self.last_conditions)
        # the precision of the student's record, as this server computed it (zscore grading), and the
        # route's own error on the same experiment (computed with the hand-in, in its worker)
        settings["_se"] = {n: float(self.result.std_errors[n]) for n in estimates if n in self.result.std_errors}
        ref = getattr(self, "last_reference", None)
        if ref is not None and self.state.exercise is not None and self.state.exercise.grading == "zscore":
            settings["_model_error"] = partial(lse_model_error, **ref)
        return estimates, settings

    def _disturbance_text(self, req) -> str:
        spec = req.custom if req.scenario == "custom" else LSE_SCENARIOS[req.scenario]
        extra = self.conditions.disturbance if self.conditions is not None else "none"
        return spec if extra.strip().lower() in ("", "none") else f"{spec} + {extra} (the exercise's)"

    def hand_in(self):
        """Hand in the last estimates of the exercise's hidden parameters (see HandInBox)."""
        return self.handin.hand_in()

    # -- the section's protocol -----------------------------------------------------------
    def result_views(self) -> list:
        return [self.view, self.table4_view]

    def run_cost(self) -> RunCost | None:
        """The experiment (simulation, estimation, re-simulation; the instrumental variables' passes too)."""
        req, errors = self.request()
        if errors:
            return None
        _, t_end = req.input_signal()
        cost = lse_cost(t_end, resimulation=True, estimator=req.estimator)
        steps = cost.steps
        if req.validation == "second":
            # the second experiment: the plant's record and the model's run on it, each a re-simulation's cost
            steps += 2 * (lse_cost(t_end, resimulation=True).steps - lse_cost(t_end).steps)
        return RunCost("least-squares excitation", f"{t_end:g} s", steps, cost.peak_bytes, t_end,
                       "use a shorter excitation")

    def kept_work(self) -> KeptWork | None:
        views = [name for name, view in (("lse", self.view), ("table4", self.table4_view)) if view.is_current]
        run: dict = {"views": views}
        upload = kept_upload(self.key, self._upload, self.own_data, self.own_data_key)
        if upload is not None:
            # the file's part is no field of the settings: kept here, put back once the file is read
            run["window"] = {k: str(self.window_form.values.get(k, "")) for k in ("own_from", "own_to")}
            run["file"] = upload.name
        if not views and upload is None:
            return None
        return KeptWork(run, upload)

    @classmethod
    def restore_work(cls, kept: KeptWork, texts) -> list[RestoreStep]:
        run, upload = kept.run or {}, kept.file
        views, steps = run.get("views", ()), []
        if upload is not None:
            steps.append(read_kept(upload))
            window = run.get("window")
            if window:
                steps.append(RestoreStep("", lambda section: section.window_form.set_values(**window)))
        # a run on a file that was not kept (the class's space for files was full) is not run again on
        # the simulated sensors instead: that would be another result under the same name
        if "lse" in views and (upload is not None or not run.get("file")):
            steps.append(RestoreStep("Least squares", lambda section: section.run()))
        if "table4" in views:
            steps.append(RestoreStep("Table 4", lambda section: section.run_all()))
        return steps

    def snapshot(self) -> SectionSnapshot:
        req, _ = self.request()
        scenario = req.scenario if req.excitation == "paper" and req.scenario != "custom" else None
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(),
                               content=(self.result, self.last_data, self.last_resim, scenario, self.all_results,
                                        dict(self.result_context), dict(self.all_context), self.validation,
                                        self.validation_note))

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        result, data, resim, scenario, all_results, context, all_context, _validation, validation_note = (
            snapshot.content or (None,) * 5 + ({}, {}, None, ""))
        if result is None and all_results is None:
            return None
        body, figures = stale_note(snapshot), {}
        if result is not None:
            fig = plots.LseFitFigure()
            fig.update(plots.lse_view(data, resim))
            figures["lse"] = fig.layout
            # the validation's fits in words (its plot stays on the page: the report's figures are the runs')
            body += lse_table_html(result, scenario, hidden=hidden, **context) + "{{lse}}" + validation_note
        if all_results is not None:
            body += ("<h3>Table 4: four scenarios, both disturbance models</h3>"
                     + table4_html(all_results, **all_context))
        return ReportPart("Least squares (eqs. 15-18)", body, figures)

    def __panel__(self):
        # the run first, below its settings: in view at 1366 x 768; the student's own file after it
        controls = pn.Column(self.form, self.notice, self.button, self.all_button, self.handin_button, self.verdict,
                             self.handin.confirm, self.upload_note, self.upload, self.mapping, self.window_box,
                             self.simulated_button,
                             pn.FlexBox(*self.downloads, width=270, sizing_mode="fixed"), self.queue_note, width=280)
        explain = pn.pane.HTML(
            "<p class='eha-note'>Least squares on eq. 15 filtered by H(s) = 1/(0.01 s + 1) (eqs. 16-18): "
            "y<sub>1</sub> = A<sub>1</sub>p<sub>1</sub> − A<sub>2</sub>p<sub>2</sub> = M dv/dt + B v + "
            "A<sub>f</sub> S(v) + d<sub>0</sub>, and dp<sub>1</sub>/dt = β<sub>e</sub> φ<sub>2</sub>: each "
            f"unknown multiplies a {term('regressor')} formed from the measurements. "
            "D<sub>c</sub>, d<sub>c</sub>, L<sub>0</sub>, K<sub>q</sub> are measured; 1 kHz sensors.</p>",
            sizing_mode="stretch_width")
        results = pn.Column(explain, self.alert, self.view.banner, self.area, self.table4_view.banner,
                            self.table4_area, sizing_mode="stretch_width", min_width=440)
        return side_by_side(controls, results)


def _fit_figure(figure, area, view):
    """``figure`` (an :class:`~eha_app.render.plots.LseFitFigure`, made and put in ``area`` when None)
    showing ``view``: the same Bokeh models for every run, new data only."""
    if figure is None:
        figure = plots.LseFitFigure()
        figure.update(view)
        area.objects = [pn.pane.Bokeh(figure.layout, sizing_mode="stretch_width")]
    else:
        figure.update(view)
    return figure
