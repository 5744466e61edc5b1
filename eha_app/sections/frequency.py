"""Tab 3, frequency domain: the closed-loop experiment, tfest, validation and back-out (Figs. 8-13)."""

from __future__ import annotations

import dataclasses
import math
from functools import partial

import numpy as np
import panel as pn

from eha_core.board import BoardModel
from eha_core.errors import FieldError, not_allowed
from eha_core.experiments import (
    FrequencyExperiment,
    run_frequency_identification,
)
from eha_core.grading import frequency_model_error

from ..render import plots
from ..render.exports import bode_csv, frequency_figures_zip, tf_estimate_bytes
from ..render.glossary import GLOSSARY
from ..render.layout import WRAP_TAB_HEADERS, side_by_side
from ..render.tables import (
    assumed_model_html,
    backout_html,
    estimate_alert,
    freq_summary_html,
)
from ..runtime.limits import RunCost
from ..runtime.shared import shared_results
from ..runtime.tasks import apply_locked, held, on_click, watch
from ..session import GuideStep, KeptWork, ReportPart, RestoreStep, Section, SectionSnapshot, stale_note
from ..session.form import Field, Form, Group, parse_fields, raised_to_bounds, regrouped, with_lower_bounds
from ..session.freshness import ResultView
from .handin import HandInBox
from .uploads import download

__all__ = ["FrequencyPanel", "FREQ_FORM", "FREQ_DEFAULTS", "parse_freq"]

# -- the frequency-domain request --------------------------------------------------------------

FREQ_FORM = (
    Group("Excitation (idinput)", (
        Field("signal_type", "idinput type", "select",
              options=(("sine", "sine"), ("rgs", "rgs"), ("rbs", "rbs"), ("prbs", "prbs")), short="idinput type",
              tip=GLOSSARY["idinput"]),
        Field("n_samples", "samples N", "integer", lo=20, hi=20000, short="N"),
    )),
    # folded at first: the run button stays in view at 1366 x 768 (the defaults are the paper's)
    Group("Excitation details", (
        Field("freq_seed", "seed", "integer", lo=0, hi=10**6, short="seed"),
        Field("band_lo", "band low", "number", unit="× Nyquist", lo=0.0, hi=1.0, short="band low"),
        Field("band_hi", "band high", "number", unit="× Nyquist", lo=0.0, hi=1.0, short="band high"),
        Field("range_lo", "range min", "number", unit="m", short="range min"),
        Field("range_hi", "range max", "number", unit="m", short="range max"),
        Field("n_sines", "sinusoids", "integer", lo=1, hi=5000, short="sinusoids"),
        Field("n_trials", "trials", "integer", lo=1, hi=500, short="trials"),
        Field("grid_skip", "grid skip", "integer", lo=1, hi=100, short="grid skip"),
        Field("ts", "Ts", "number", unit="s", lo=1e-4, hi=1.0, short="Ts",
              tip="sample time of the controller; its output is held between samples (ZOH: " + GLOSSARY["ZOH"] + ")"),
        Field("noise_x", "σ of x", "number", unit="mm", lo=0.0, hi=10.0, short="σ x",
              tip="white noise of the position sensor on the record, drawn from the seed (the controller is fed "
                  "the true position)"),
    ), collapsible=True, collapsed=True),
    Group("Loop and model", (
        Field("model", "model in the loop", "select", options=(("nonlinear", "nonlinear"), ("linear", "linearised")),
              short="model", tip="the actuator's model the closed loop is simulated with"),
        Field("n_poles", "poles", "integer", lo=1, hi=6, short="poles", tip="poles: " + GLOSSARY["poles"]),
        Field("n_zeros", "zeros", "integer", lo=0, hi=5, short="zeros", tip="zeros: " + GLOSSARY["zeros"]),
    )),
    Group("Estimation options", (
        Field("initial_condition", "initial condition", "select", options=(("estimate", "estimate"), ("zero", "zero")),
              short="initial condition", tip=GLOSSARY["initial condition"]),
        Field("input_offset", "input offset", "select", options=(("estimate", "estimate"), ("zero", "zero")),
              short="input offset", tip=GLOSSARY["input offset"]),
        Field("input_delay", "input delay", "text", unit="s", placeholder="0, a time, or estimate",
              short="input delay",
              tip="a dead time of the model's input (MATLAB's iodelay): 0 for none, a time in s, or estimate"),
    ), collapsible=True, collapsed=True),
)
_FREQ_FIELDS = {f.name: f for g in FREQ_FORM for f in g.fields}
_CONFIG_NAME = {"signal_type": "signal_type", "n_samples": "n_samples", "freq_seed": "seed", "ts": "ts",
                "model": "model", "n_poles": "n_poles", "n_zeros": "n_zeros",
                "initial_condition": "initial_condition", "input_offset": "input_offset",
                "input_delay": "input_delay"}
_DEFAULT_CONFIG = FrequencyExperiment()
FREQ_DEFAULTS = {
    "signal_type": _DEFAULT_CONFIG.signal_type, "n_samples": str(_DEFAULT_CONFIG.n_samples),
    "freq_seed": str(_DEFAULT_CONFIG.seed), "band_lo": f"{_DEFAULT_CONFIG.band[0]:g}",
    "band_hi": f"{_DEFAULT_CONFIG.band[1]:g}", "range_lo": f"{_DEFAULT_CONFIG.range[0]:g}",
    "range_hi": f"{_DEFAULT_CONFIG.range[1]:g}", "n_sines": str(_DEFAULT_CONFIG.sinedata[0]),
    "n_trials": str(_DEFAULT_CONFIG.sinedata[1]), "grid_skip": str(_DEFAULT_CONFIG.sinedata[2]),
    "ts": f"{_DEFAULT_CONFIG.ts:g}", "model": _DEFAULT_CONFIG.model,
    "n_poles": str(_DEFAULT_CONFIG.n_poles), "n_zeros": str(_DEFAULT_CONFIG.n_zeros),
    "initial_condition": _DEFAULT_CONFIG.initial_condition, "input_offset": _DEFAULT_CONFIG.input_offset,
    "input_delay": "0", "noise_x": "0",
}


def freq_hidden(texts: dict) -> list[str]:
    return [] if texts.get("signal_type", "sine") == "sine" else ["n_sines", "n_trials", "grid_skip"]


def _field_of(error) -> str:
    """The form field a core error (a :class:`~eha_core._checks.FieldError`) is about ("" if none)."""
    name = getattr(error, "field", "")
    for form_name, config_name in _CONFIG_NAME.items():
        if name == config_name:
            return form_name
    return {"band": "band_lo", "range": "range_lo", "sinedata": "n_sines"}.get(name, "")


def _parse_delay(text) -> tuple[float | str, str]:
    """The input delay field: blank or 0 (none), a time in s, or "estimate"; and its message."""
    raw = str(text).strip()
    if raw.lower() in ("", "0", "none"):
        return 0.0, ""
    if raw.lower() in ("estimate", "est"):
        return "estimate", ""
    try:
        value = float(raw.replace(",", "."))
        if not (math.isfinite(value) and value >= 0):
            raise ValueError
    except ValueError:
        return 0.0, str(FieldError("input delay", raw, "enter a time >= 0 s, or estimate", value_text=raw))
    return value, ""


def parse_freq(texts: dict, kp: float = _DEFAULT_CONFIG.kp, fields: dict | None = None,
               ) -> tuple[FrequencyExperiment | None, dict]:
    """The experiment the form describes (None if invalid), and a message per invalid field ("" for the rest).

    ``kp`` is the controller gain: tab 1's, the one H(s) is shown with everywhere; ``fields``: the
    form's fields as an exercise bounds them (:func:`exercise_fields`).
    """
    hidden = set(freq_hidden(texts))
    values, errors = parse_fields((fields or _FREQ_FIELDS).values(), texts, skip=hidden | {"input_delay"})
    delay, delay_error = _parse_delay(texts.get("input_delay", "0"))
    if delay_error:
        errors["input_delay"] = delay_error
    if errors:
        return None, errors
    d = _DEFAULT_CONFIG
    try:
        cfg = FrequencyExperiment(
            n_samples=values["n_samples"], ts=values["ts"], signal_type=values["signal_type"],
            band=(values["band_lo"], values["band_hi"]), range=(values["range_lo"], values["range_hi"]),
            sinedata=(values.get("n_sines", d.sinedata[0]), values.get("n_trials", d.sinedata[1]),
                      values.get("grid_skip", d.sinedata[2])),
            seed=values["freq_seed"], kp=kp, model=values["model"], n_poles=values["n_poles"],
            n_zeros=values["n_zeros"], initial_condition=values["initial_condition"],
            input_offset=values["input_offset"], input_delay=delay, noise_x=values.get("noise_x", 0.0) * 1e-3)
    except (ValueError, TypeError) as exc:
        message = " ".join(str(exc).split())
        if getattr(exc, "field", "") == "input_delay":   # the field's label and the text as typed
            typed = str(texts.get("input_delay", "")).strip()
            return None, {"input_delay": exc.render("input delay", value_text=typed)}
        return None, {_field_of(exc): message}
    return cfg, {}



def exercise_fields(conditions) -> dict:
    """The form's fields under an exercise's conditions: σ of x at least the position sensor's floor,
    Ts at least the shortest sample time."""
    if conditions is None:
        return dict(_FREQ_FIELDS)
    return with_lower_bounds(_FREQ_FIELDS, {"noise_x": conditions.noise_floor("x") / 1e-3, "ts": conditions.min_ts_s},
                             "this exercise's conditions")


#: The physical parameters the frequency route hands in (eq. 27): β_e alone (the back-out's damping is
#: B + 2 k_f A_f / π, not B; Table 3's lesson) from the s coefficient (eq. 27b-d) or the gain (eq. 27e-f).
BACKOUT_SOURCES = {"beta_e_from_stiffness": "the s coefficient (eq. 27b-d)",
                   "beta_e_from_gain": "the gain (eq. 27e-f)"}


# short titles: the six fit beside the form at 800 px (each figure's own title says what it shows)
_FIGURES = (("Fig. 8", "excitation", plots.ExcitationFigure),
            ("Fig. 9", "data", plots.ClosedLoopFigure),
            ("Fig. 11", "fit", plots.FitFigure),
            ("Fig. 12 Bode", "bode", plots.BodeFigure),
            ("Fig. 13", "validation", plots.ValidationFigure),
            ("Residuals", "residuals", plots.ResidualFigure))


class FrequencyPanel(Section):
    """Frequency domain: the closed-loop experiment, tfest, validation, back-out (Figs. 8-13).

    The student's own record is a section within it (:mod:`eha_app.sections.record`), laid out here.
    """

    key = "frequency"
    title = "Transfer function"
    defaults = FREQ_DEFAULTS
    guide_step = GuideStep(
        "3. Transfer function", "Step 3, frequency domain: excite the closed loop, estimate Ĥ(s) (Figs. 8-13) and back "
        "out the parameters (eqs. 26-27).", "3. Identification: transfer function",
        "Press <b>Run experiment and estimate</b>.")
    form_css = "eha-freq-form"
    content_css = "eha-freq-summary"
    run_buttons = ("Run experiment and estimate",)

    def __init__(self, session, **kwargs):
        super().__init__(session, **kwargs)
        state, runner = self.state, self.runner
        # the excitation preview is a job of its own: typing N must not wait behind an experiment
        self.preview_runner = runner.sub("preview")
        self.result = None
        self.view: plots.FrequencyView | None = None
        self.preview = None
        ex = state.exercise if state.hidden else None
        self.conditions = ex.conditions if ex is not None else None
        self.fields = exercise_fields(self.conditions)
        texts = raised_to_bounds(self.initial_texts(), self.fields, ("noise_x", "ts"))
        self.form = Form(spec=[g.to_spec() for g in regrouped(FREQ_FORM, self.fields)], values=texts,
                         url_defaults=FREQ_DEFAULTS, width=270,
                         css_classes=[self.form_css], margin=(5, 10))
        watch(self.form, self._on_config, "values")
        self.error = pn.pane.HTML("", visible=False, width=260, css_classes=["eha-error", "eha-error-freq"],
                                  styles={"color": "#b00020", "font-size": "12px"})
        self.button = pn.widgets.Button(label="Run experiment and estimate", color="primary", width=260,
                                        css_classes=["eha-run-freq"])
        on_click(self.button, lambda _e: self.run())
        self.queue_note = pn.pane.HTML("", visible=False, width=270, css_classes=["eha-queue-note"],
                                       styles={"color": "#555", "font-size": "12px"})
        self.summary = pn.pane.HTML("<p>Configure the excitation (Fig. 8) and run the closed-loop experiment.</p>",
                                    sizing_mode="stretch_width", css_classes=["eha-freq-summary"])
        self.backout = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-backout"])
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   css_classes=["eha-freq-alert"])
        self.unstable = pn.pane.Alert("", alert_type="warning", visible=False, sizing_mode="stretch_width",
                                      css_classes=["eha-freq-unstable"])
        self.downloads = [
            download(lambda: self.data_bytes("csv"), "eha_closed_loop.csv", "Data (CSV)", "eha-dl-freq-csv"),
            download(lambda: self.data_bytes("mat"), "eha_closed_loop.mat", "Data (.mat)", "eha-dl-freq-mat"),
            download(lambda: self.estimate_bytes("csv"), "eha_transfer_function.csv",
                     "Estimate (CSV)", "eha-dl-freq-est-csv"),
            download(lambda: self.estimate_bytes("json"), "eha_transfer_function.json",
                     "Estimate (JSON)", "eha-dl-freq-json"),
            download(lambda: self.bode_bytes(), "eha_bode.csv", "Bode curves (CSV)", "eha-dl-freq-bode"),
            download(lambda: self.figures_bytes(), "eha_frequency_figures.zip",
                     "All figures' data", "eha-dl-freq-zip",
                     description="Figs. 8-13 and the residuals: one CSV per figure and a .mat"),
        ]
        self.area = pn.Column(self.unstable, self.summary, self.backout, sizing_mode="stretch_width")
        # an exercise: hand in the back-out's β_e, computed with the student's own values of what eq. 27
        # takes as measured (a hidden M is their least-squares estimate, or the paper's 4000 kg)
        self.handin = HandInBox(self, "frequency", self._handin_estimates, label="Hand in the back-out's βe")
        self.handin_button, self.verdict = self.handin.button, self.handin.verdict
        if "beta_e" not in state.hidden:
            self.handin_button.visible = False
        self.handin_source = pn.widgets.Select(label="βe from", options={v: k for k, v in BACKOUT_SOURCES.items()},
                                               width=260, visible=self.handin_button.visible,
                                               css_classes=["eha-handin-source"])
        watch(self.handin_source, lambda _e: self._handin_tip(), "value")
        self.kp_note = pn.pane.HTML("", width=260, css_classes=["eha-freq-kp"], margin=(0, 10))
        self.config_errors: dict = {}
        self.excitation_errors: dict = {}
        self.figures: dict[str, object] = {}
        self._slots = {key: pn.Column(pn.pane.HTML(
            "<p class='eha-note'>" + ("Computing the excitation…" if key == "excitation" else
                                      "Run the experiment to see this figure.") + "</p>"),
            min_height=260, sizing_mode="stretch_width") for _, key, _ in _FIGURES}
        hint = "Press “Run experiment and estimate” to update it."
        # Fig. 8 follows the settings by itself (a preview); the others come from the experiment
        self.views = {key: ResultView(f"freq-{key}", self._slots[key], run_hint=hint) for _, key, _ in _FIGURES}
        self.views["summary"] = ResultView("freq-summary", self.area, run_hint=hint)
        self.figure_tabs = pn.Tabs(*((title, pn.Column(self.views[key].banner, self._slots[key],
                                                       sizing_mode="stretch_width"))
                                     for title, key, _ in _FIGURES), dynamic=False,
                                   sizing_mode="stretch_width", css_classes=["eha-freq-figures"],
                                   stylesheets=[WRAP_TAB_HEADERS])
        self._shown = {"excitation"}
        watch(self.figure_tabs, self._on_figure_tab, "active")
        state.param.watch(self._update_enabled, "valid")
        state.param.watch(self._on_config, ["params", "kp", "valid"])
        self._on_config()

    def config(self):
        """The experiment the form and tab 1's Kp describe (None if invalid), and the messages."""
        cfg, errors = parse_freq(self.form.values, self.state.kp, self.fields)
        extra = self.conditions.disturbance.strip() if self.conditions is not None else "none"
        if cfg is not None and extra.lower() not in ("", "none"):
            cfg = dataclasses.replace(cfg, disturbance=extra)        # the exercise's load always acts
        return cfg, errors

    def run_key(self, cfg=None):
        """What the experiment's results are computed from (None if the inputs are not valid)."""
        cfg = cfg if cfg is not None else self.config()[0]
        return None if cfg is None or not self.state.valid else (self.state.params, cfg)

    @staticmethod
    def excitation_key(cfg):
        return None if cfg is None else (cfg.signal_type, cfg.n_samples, cfg.seed, cfg.band, cfg.range,
                                         cfg.sinedata, cfg.ts)

    def _mark(self, cfg, *, preview_queued: bool) -> None:
        """Mark every view of this panel against the current inputs."""
        why = "a parameter on tab 1 is not valid" if not self.state.valid else ""
        key = self.run_key(cfg)
        for name, view in self.views.items():
            if name == "excitation":
                view.inputs_changed(self.excitation_key(cfg), updating=preview_queued, why=why)
            else:
                view.inputs_changed(key, why=why)

    # A figure is built when it is first shown with data to draw; afterwards
    # only its data change.
    def _on_figure_tab(self, event) -> None:
        key = _FIGURES[event.new][1]
        self._shown.add(key)
        apply_locked(lambda: self._draw(key))

    def _has_data(self, key: str) -> bool:
        return self.preview is not None if key == "excitation" else self.view is not None

    def _draw(self, key: str) -> None:
        if key not in self._shown or not self._has_data(key):
            return
        fig = self.figures.get(key)
        built = fig is None
        if built:
            fig = self.figures[key] = next(c for _, k, c in _FIGURES if k == key)()
        if key == "excitation":
            fig.update(*self.preview)
        elif key == "fit":
            fig.update(self.view, self.result.config.model if self.result is not None else "nonlinear")
        else:
            fig.update(self.view)
        if built:
            self._slots[key].objects = [pn.pane.Bokeh(fig.layout, sizing_mode="stretch_width")]

    def _update_enabled(self, *_events) -> None:
        errors = {**self.config_errors, **self.excitation_errors}
        self.form.errors = {k: v for k, v in errors.items() if k}
        ok = self.state.valid and not errors
        self.button.disabled = not ok
        if not self.state.valid:
            self.error.object = "A parameter on the first tab is not valid: fix it to run the experiment."
        else:
            self.error.object = errors.get("", "") or (f"Fix the input to run: {next(iter(errors.values()))}"
                                                       if errors else "")
        self.error.visible = bool(self.error.object)
        self._inner_inputs_changed()        # the record's button and marks follow the form's messages too

    def _on_config(self, *_events) -> None:
        # the marks of seven views, the form and the note: one message, not twenty (each one
        # lays out the page in the browser)
        with held():
            self._config_changed()

    def _config_changed(self) -> None:
        cfg, errors = self.config()
        self.config_errors = errors
        self.form.hidden = freq_hidden(self.form.values)
        self.kp_note.object = (f"<span class='eha-note'>Controller gain K<sub>p</sub> = {self.state.kp:g} V/m, "
                               "set on tab 1 (the same K<sub>p</sub> as tab 1's H(s)).</span>")
        if cfg is None:
            self._mark(None, preview_queued=False)
            self._update_enabled()
            return
        ts = cfg.ts
        exc_key = self.excitation_key(cfg)
        if exc_key == self.views["excitation"].computed_from:
            self.excitation_errors = {}         # these settings made the preview on screen: idinput took them
            self._mark(cfg, preview_queued=False)
            self._update_enabled()
            return

        def show(out, _job):
            self.excitation_errors = {}
            self.preview = out
            self._draw("excitation")
            self.views["excitation"].shown(exc_key)
            # settings typed while it computed that start no preview of their own (a form that no
            # longer parses): the preview just drawn is marked against them, not left current
            cfg_now = self.config()[0]
            if self.excitation_key(cfg_now) != exc_key:
                self._mark(cfg_now, preview_queued=cfg_now is not None)
            self._update_enabled()

        def failed(error):
            if not isinstance(error, FieldError):
                # a fault of the preview itself (logged), not of the settings: nothing beside a field
                self.views["excitation"].inputs_changed(None, why="the excitation preview failed")
                return
            # idinput checks the band, range and sinusoid settings against N
            self.excitation_errors = {_field_of(error): " ".join(str(error).split())}
            self.views["excitation"].inputs_changed(None, why="the excitation's settings are not valid")
            self._update_enabled()

        self._update_enabled()
        self._mark(cfg, preview_queued=True)
        self.preview_runner.run("excitation preview", lambda token: plots.excitation_view(cfg.excitation(), ts),
                                show, fail=lambda _m: None, failed=failed)

    def data_bytes(self, kind: str) -> bytes:
        """The closed-loop record the estimate was made from: t, r, x, u (SI), as CSV or .mat."""
        from eha_core.data import write_data

        d = self.result.data
        return write_data({"t": d.t, "r": d.r, "x": d.x, "u": d.u}, kind, units="si")

    def estimate_bytes(self, kind: str = "json") -> bytes:
        """The estimated transfer function with its intervals, fits and settings (CSV or JSON)."""
        fi = self.result
        settings = {k: getattr(fi.config, k) for k in (
            "signal_type", "n_samples", "seed", "ts", "kp", "model", "n_poles", "n_zeros", "initial_condition",
            "input_offset", "input_delay")}
        return tf_estimate_bytes(fi.estimate, kind, settings=settings, fits={
            "fit_percent": fi.estimate.fit_percent,
            "validation_fit_percent": None if fi.validation is None else fi.validation.fit_percent})

    def bode_bytes(self) -> bytes:
        """Fig. 12's curves as CSV (eq. 24's left out in an exercise: it is computed from the hidden values)."""
        return bode_csv(self.result.bode, theoretical=not self.state.hidden)

    def figures_bytes(self) -> bytes:
        """The data behind Figs. 8-13 and the residual plots (zip of CSVs and one .mat)."""
        return frequency_figures_zip(self.result, hidden=bool(self.state.hidden))

    def _fail(self, message: str) -> None:
        self.alert.object = f"The experiment failed: {message}"
        self.alert.visible = True

    def run(self):
        cfg, errors = self.config()
        if cfg is None or not self.state.valid or self.excitation_errors:
            return None
        self.alert.visible = False
        try:
            self.check_cost()
        except ValueError as exc:
            self._fail(str(exc))
            return None
        c = self.conditions
        if c is not None and "frequency" not in c.methods:
            self._fail("this exercise does not use the frequency domain")
            return None
        if c is not None and cfg.n_samples * cfg.ts > c.max_record_s:
            self._fail(str(not_allowed("samples N × Ts", f"{cfg.n_samples * cfg.ts:g} s",
                                       f"this exercise's records are at most {c.max_record_s:g} s")))
            return None
        params = self.state.params
        run_key = (params, cfg)

        hidden = self.state.hidden

        def experiment(token):
            fi = run_frequency_identification(params, cfg, cancel=token)
            return fi, plots.frequency_view(fi, hidden)

        def compute(token):
            # a function of these alone: students with the same actuator and settings share it
            return shared_results.get(("frequency", params, cfg, bool(hidden)), experiment, token)

        def show(out, job):
            fi, view = out
            if hidden and fi.open_loop is not None:
                # an exercise: the back-out with the student's own values of what eq. 27 takes as measured
                # (the true M, L0, Kq of a hidden one would give the hidden values away), everywhere it shows
                fi = dataclasses.replace(fi, backout=self._assumed_backout(fi))
            self.result = fi
            self.view = view
            self._handin_tip()
            self.preview = (view.excitation_t, view.excitation_r, view.excitation_title)
            timing = (f"<p class='eha-note'>Experiment, estimation and validation in {job.run_s:.2f} s "
                      f"(estimation alone {fi.timings.get('tfest', float('nan')):.2f} s)"
                      + (f", after {job.wait_s:.1f} s waiting for the server" if job.wait_s > 0.05 else "")
                      + ".</p>")
            self.summary.object = freq_summary_html(fi, hidden) + timing
            self.backout.object = ("<h4>Backed-out parameters (eq. 27)</h4>" + backout_html(fi, hidden)
                                   + assumed_model_html("frequency"))
            for d in self.downloads:
                d.disabled = fi.bode is None and "bode" in d.css_classes[0]
            alert = estimate_alert(fi.estimate)
            self.unstable.object = alert
            self.unstable.visible = bool(alert)
            for _, key, _ in _FIGURES:
                self._draw(key)
            for name, view in self.views.items():
                view.shown(self.excitation_key(cfg) if name == "excitation" else run_key)
            self._mark(self.config()[0], preview_queued=False)      # typed while it computed
            e = fi.estimate
            if e.success and np.all(np.isfinite(e.den)):
                # the board's list is rebuilt in a page update of its own: the result goes out first
                apply_locked(partial(self.session.post, "board", BoardModel(
                    name="H", kind="tf", estimate=e, num=e.num, den=e.den,
                    input_delay=getattr(e, "input_delay", 0.0), ts=cfg.ts, kp=cfg.kp, params=fi.params,
                    description=f"{e.n_poles} poles, {e.n_zeros} zeros; idinput {cfg.signal_type} seed {cfg.seed}, "
                                f"N {cfg.n_samples}, {cfg.model} plant, Kp = {cfg.kp:g} V/m; fit "
                                f"{e.fit_percent:.1f} %")))

        return self.runner.run("frequency experiment", compute, show, fail=self._fail, busy=[self.area],
                               note=self._note)

    def assumed_params(self):
        """The actuator eq. 27 takes as measured, as the student knows it: tab 1's values, and for a
        hidden parameter their least-squares estimate (the last run) or else the paper's value."""
        from eha_core.params import ActuatorParams

        state, paper = self.state, ActuatorParams()
        lse = self.session.section("least_squares")
        estimates = lse.result.estimates if lse is not None and lse.result is not None else {}
        values, sources = {}, {}
        for n in state.hidden:
            if n in estimates and float(estimates[n]) > 0:
                values[n], sources[n] = float(estimates[n]), "your least-squares estimate"
            else:
                values[n], sources[n] = getattr(paper, n), "the paper's value"
        # eq. 27 is the paper's model linearised: the effects of a variant actuator are not the student's to
        # know (the plant's, never the model's)
        try:
            return state.params.replace(effects=None, **values), sources
        except ValueError:
            return state.params.replace(effects=None, **{n: getattr(paper, n) for n in values}), {
                n: "the paper's value" for n in values}

    def _assumed_backout(self, fi):
        from eha_core.identify.backout import backout
        from eha_core.linear import operating_point

        assumed, _ = self.assumed_params()
        return backout(*fi.open_loop, assumed, operating_point(assumed), std_h=fi.estimate.param_std, kp=fi.config.kp)

    def _backout_for_handin(self):
        fi = self.result
        if fi is None or fi.open_loop is None:
            return None
        assumed, sources = self.assumed_params()
        return self._assumed_backout(fi), assumed, sources

    def _handin_estimates(self):
        """β_e backed out of the last run with the student's own values (see assumed_params)."""
        got = self._backout_for_handin()
        if got is None:
            return None
        b, assumed, sources = got
        key = self.handin_source.value
        settings = {**self.settings(), "beta_e_from": key,
                    "assumed": {n: getattr(assumed, n) for n in sources}, "assumed_from": sources}
        settings["_conditions"] = {"noise": {"x": self.result.config.noise_x}}
        # the precision of the student's record, as this server computed it (zscore grading): the
        # estimate's covariance carried through eq. 27 (the values assumed count as exact)
        settings["_se"] = {"beta_e": float(getattr(b, key + "_std"))}
        exercise = self.state.exercise
        if exercise is not None and exercise.grading == "zscore" and getattr(self, "own_data", None) is None:
            # eq. 27's own error on this experiment at the student's actuator (computed with the hand-in)
            settings["_model_error"] = partial(frequency_model_error, self.state.params, self.result.config)
        return {"beta_e": float(getattr(b, key))}, settings

    def hand_in(self):
        """Hand in the back-out's β_e (see HandInBox)."""
        return self.handin.hand_in()

    def _handin_tip(self) -> None:
        if not self.handin_button.visible:
            return
        if self.result is None:
            self.handin.set_tip(False, "run the experiment first: the hand-in takes the back-out of its estimate")
        elif self.result.open_loop is None:
            self.handin.set_tip(False, "the back-out (eq. 27) needs a model with 3 poles and no zero")
        else:
            _, sources = self.assumed_params()
            used = "; ".join(f"{n} = {src}" for n, src in sources.items() if n != "beta_e")
            self.handin.set_tip(True, f"hand in βe from {BACKOUT_SOURCES[self.handin_source.value]}"
                                      + (f", with {used}" if used else ""))

    # -- what the sections within it use ----------------------------------------------------------
    @property
    def record(self):
        """The student's own record (a section within this one)."""
        return self.session.section("record")

    def inner(self) -> list:
        return [self.session.section(p.key) for p in self.session.registry.within(self.key)
                if self.session.section(p.key) is not None]

    def _inner_inputs_changed(self) -> None:
        for section in self.inner():
            section.inputs_changed()

    def queue_note_text(self, text: str) -> None:
        self._note(text)

    def fail(self, message: str) -> None:
        self._fail(message)

    # -- the section's protocol ---------------------------------------------------------------------
    def result_views(self) -> list:
        return [v for k, v in self.views.items() if k != "excitation"]

    def run_cost(self) -> RunCost | None:
        """The closed-loop experiment (estimation and validation runs, tfest)."""
        cfg, _ = self.config()
        if cfg is None:
            return None
        cost = cfg.cost()
        return RunCost("N × Ts", f"{cfg.n_samples} × {cfg.ts:g} s", cost.steps, cost.peak_bytes,
                       2 * cfg.n_samples * cfg.ts, "lower N or Ts")

    def kept_work(self) -> KeptWork | None:
        return KeptWork({"views": ["summary"]}) if self.views["summary"].is_current else None

    @classmethod
    def restore_work(cls, kept: KeptWork, texts) -> list[RestoreStep]:
        if "summary" not in (kept.run or {}).get("views", ()):
            return []
        return [RestoreStep(cls.title, lambda section: section.run())]

    def snapshot(self) -> SectionSnapshot:
        return SectionSnapshot(self.key, self.title, self.settings(), stale=self.is_stale(), content=self.result)

    @classmethod
    def report(cls, snapshot: SectionSnapshot, hidden=()) -> ReportPart | None:
        fi = snapshot.content
        if fi is None:
            return None
        view = plots.frequency_view(fi, hidden)
        figures = {}
        for key, fig_cls in (("fit", plots.FitFigure), ("bode", plots.BodeFigure),
                             ("validation", plots.ValidationFigure)):
            fig = fig_cls()
            if key == "fit":
                fig.update(view, fi.config.model)
            else:
                fig.update(view)
            figures[key] = fig.layout
        return ReportPart("Transfer function (eqs. 19-27)", stale_note(snapshot) + freq_summary_html(fi, hidden)
                          + "{{fit}}{{bode}}{{validation}}<h3>Backed-out parameters (eq. 27)</h3>"
                          + backout_html(fi, hidden), figures)

    def __panel__(self):
        inner = self.inner()
        # the hand-in's widgets only in an exercise: a page without one sends three models fewer
        handin = ([self.handin_source, self.handin_button, self.verdict, self.handin.confirm]
                  if self.handin_button.visible else [])
        config = pn.Column(self.form, self.error, self.button, *handin, self.kp_note,
                           pn.FlexBox(*self.downloads, width=270, sizing_mode="fixed"),
                           *[c for s in inner for c in s.controls()], self.queue_note, width=280)
        results = pn.Column(self.alert, self.figure_tabs, self.views["summary"].banner, self.area,
                            *[r for s in inner for r in s.results()], sizing_mode="stretch_width", min_width=440)
        return side_by_side(config, results)
