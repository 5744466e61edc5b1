"""Tab 3: identification, in the time domain (least squares) and the frequency domain."""

from __future__ import annotations

import math

import panel as pn
import param

from eha_core.experiments import (
    LSE_INPUT, LSE_INPUT_RICH, LSE_INPUT_RICH_T_END, LSE_SCENARIOS, FrequencyExperiment, lse_data,
    lse_resimulation, parse_disturbance, run_frequency_identification, run_lse_table,
)
from eha_core.identify.lse import identify_lse
from eha_core.params import ParameterError
from eha_core.signals import SignalSpecError, parse_signal

from .. import plots
from ..state import AppState
from ..tables import SCENARIOS, backout_html, freq_summary_html, lse_table_html, table4_html
from ..tasks import run_task

__all__ = ["IdentificationTab", "LseRequest", "FreqRequest"]

EXCITATIONS = {"paper": "u = 6 sin(4πt), 5 s (default)",
               "rich": "u = 8 sin(4πt) + 4 sin(10πt), 20 s (narrows B)"}


class LseRequest(param.Parameterized):
    scenario = param.Selector(default="none", objects=list(SCENARIOS), label="disturbance")
    custom = param.String(default="sine:1000:3", label="custom d(t)")
    model = param.Selector(default="constant", objects=["constant", "harmonic"], label="disturbance model")
    freq_text = param.String(default="", label="harmonic frequency [Hz] (blank: estimate)")
    seed = param.Integer(default=0, bounds=(0, 10**6), label="noise seed")
    excitation = param.Selector(default="paper", objects=list(EXCITATIONS), label="excitation")

    def disturbance(self):
        spec = self.custom if self.scenario == "custom" else LSE_SCENARIOS[self.scenario]
        try:
            return parse_disturbance(spec, seed=self.seed, dt=1e-3, name="custom d(t)")
        except ValueError:
            if self.scenario != "custom":
                raise
            # any signal the simulation tab understands, e.g. sine:500:2+noise:100:1
            return parse_signal(spec, name="custom d(t)")

    def frequency(self) -> float | None:
        text = self.freq_text.strip()
        if self.model != "harmonic" or not text:
            return None
        try:
            f = float(text)
        except ValueError:
            raise ValueError(f"harmonic frequency = {text!r} is not allowed: a number in Hz, or blank to estimate it") from None
        if not (math.isfinite(f) and 0 < f < 500):
            raise ValueError(f"harmonic frequency = {text} is not allowed: must lie in (0, 500) Hz")
        return f

    def input_signal(self):
        return (LSE_INPUT, 5.0) if self.excitation == "paper" else (LSE_INPUT_RICH, LSE_INPUT_RICH_T_END)

    def check(self) -> dict[str, str]:
        errors = {}
        try:
            self.disturbance()
        except (ValueError, SignalSpecError) as exc:
            errors["custom"] = str(exc)
        try:
            self.frequency()
        except ValueError as exc:
            errors["freq_text"] = str(exc)
        return errors


class FreqRequest(param.Parameterized):
    signal_type = param.Selector(default="sine", objects=["sine", "rgs", "rbs", "prbs"], label="idinput type")
    n_samples = param.Integer(default=1000, bounds=(50, 20000), label="samples N")
    band_lo = param.Number(default=0.0, bounds=(0.0, 1.0), step=0.01, label="band low [× Nyquist]")
    band_hi = param.Number(default=1.0, bounds=(0.0, 1.0), step=0.01, label="band high [× Nyquist]")
    range_lo = param.Number(default=-1.0, label="range min")
    range_hi = param.Number(default=1.0, label="range max")
    n_sines = param.Integer(default=100, bounds=(1, 5000), label="sinusoids")
    n_trials = param.Integer(default=50, bounds=(1, 500), label="trials")
    grid_skip = param.Integer(default=1, bounds=(1, 100), label="grid skip")
    seed = param.Integer(default=0, bounds=(0, 10**6), label="seed")
    ts = param.Number(default=0.01, bounds=(1e-4, 1.0), label="Ts [s]")
    kp = param.Number(default=10.0, bounds=(0.01, 1000.0), label="Kp [V/m]")
    plant = param.Selector(default="nonlinear", objects=["nonlinear", "linear"], label="plant")
    n_poles = param.Integer(default=3, bounds=(1, 6), label="poles")
    n_zeros = param.Integer(default=0, bounds=(0, 5), label="zeros")
    initial_condition = param.Selector(default="estimate", objects=["estimate", "zero"], label="initial condition")
    input_offset = param.Selector(default="estimate", objects=["estimate", "zero"], label="input offset")

    def config(self) -> FrequencyExperiment:
        return FrequencyExperiment(
            n_samples=self.n_samples, ts=self.ts, signal_type=self.signal_type,
            band=(self.band_lo, self.band_hi), range=(self.range_lo, self.range_hi),
            sinedata=(self.n_sines, self.n_trials, self.grid_skip), seed=self.seed, kp=self.kp,
            plant=self.plant, n_poles=self.n_poles, n_zeros=self.n_zeros,
            initial_condition=self.initial_condition, input_offset=self.input_offset)

    def check(self) -> str:
        """'' when the experiment can run, else the message."""
        try:
            cfg = self.config()
            cfg.excitation()
        except (ValueError, TypeError) as exc:
            return " ".join(str(exc).split())
        return ""


def _show_figure(area: pn.Column, rows) -> None:
    """Replace what ``area`` shows by rows of Bokeh figures, one pane each."""
    area.objects = [pn.Row(*(pn.pane.Bokeh(fig) for fig in row)) for row in rows]


class IdentificationTab(pn.viewable.Viewer):
    """Step 3 of the paper: identification (Fig. 17), time and frequency domain."""

    def __init__(self, state: AppState, **kwargs):
        super().__init__(**kwargs)
        self.state = state
        self.lse_req = LseRequest()
        self.freq_req = FreqRequest()
        self.lse_result = None
        self.lse_all = None
        self.freq_result = None
        # time domain
        self.lse_table = pn.pane.HTML("<p>Choose a disturbance and run the least squares.</p>",
                                      sizing_mode="stretch_width", css_classes=["eha-lse-table"])
        self.lse_plot = pn.Column(min_height=290)
        self.lse_area = pn.Column(self.lse_table, self.lse_plot, sizing_mode="stretch_width")
        self.table4 = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-table4-pane"])
        self.table4_area = pn.Column(self.table4, sizing_mode="stretch_width")
        self.lse_alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width")
        self.lse_errors = {k: pn.pane.HTML("", visible=False, styles={"color": "#b00020", "font-size": "12px"},
                                           css_classes=["eha-error", f"eha-error-{k}"], width=260)
                           for k in ("custom", "freq_text")}
        self.lse_button = pn.widgets.Button(label="Run least squares", color="primary", width=260,
                                            css_classes=["eha-run-lse"])
        self.lse_all_button = pn.widgets.Button(label="Run all four scenarios (Table 4)", color="success",
                                                width=260, css_classes=["eha-run-table4"])
        self.lse_button.on_click(self._run_lse)
        self.lse_all_button.on_click(self._run_lse_all)
        # frequency domain
        self.freq_error = pn.pane.HTML("", visible=False, styles={"color": "#b00020", "font-size": "12px"},
                                       css_classes=["eha-error", "eha-error-freq"], width=260)
        self.freq_button = pn.widgets.Button(label="Run experiment and estimate", color="primary", width=260,
                                             css_classes=["eha-run-freq"])
        self.freq_button.on_click(self._run_freq)
        self.freq_summary = pn.pane.HTML("<p>Configure the excitation (Fig. 8) and run the closed-loop experiment.</p>",
                                         sizing_mode="stretch_width", css_classes=["eha-freq-summary"])
        self.backout = pn.pane.HTML("", sizing_mode="stretch_width", css_classes=["eha-backout"])
        self.excitation_plot = pn.Column(min_height=250)
        self.freq_plots = {k: pn.Column(min_height=270) for k in ("data", "fit", "bode", "validation", "residuals")}
        self.freq_alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width")
        self.freq_area = pn.Column(self.freq_summary, self.backout, sizing_mode="stretch_width")

        self.lse_req.param.watch(self._update_enabled, list(self.lse_req.param)[1:])
        self.freq_req.param.watch(self._on_freq_config, list(self.freq_req.param)[1:])
        state.param.watch(self._update_enabled, "valid")
        self._on_freq_config()

    # -- enabling ----------------------------------------------------------------------
    def _update_enabled(self, *_events) -> None:
        errors = self.lse_req.check()
        for k, pane in self.lse_errors.items():
            pane.object = errors.get(k, "")
            pane.visible = k in errors
        ok = self.state.valid
        self.lse_button.disabled = not ok or bool(errors)
        self.lse_all_button.disabled = not ok
        self.freq_button.disabled = not ok or bool(self.freq_error.object)

    def _on_freq_config(self, *_events) -> None:
        message = self.freq_req.check()
        self.freq_error.object = message
        self.freq_error.visible = bool(message)
        if not message:
            cfg = self.freq_req.config()
            _show_figure(self.excitation_plot, plots.bokeh_rows(plots.excitation_plot(cfg.excitation(), cfg.ts)))
        self._update_enabled()

    # -- time domain -------------------------------------------------------------------
    def compute_lse(self):
        req = self.lse_req
        params = self.state.params
        d = req.disturbance()
        u, t_end = req.input_signal()
        data = lse_data(params, d, u=u, t_end=t_end, seed=req.seed)
        res = identify_lse(data, params, disturbance_model=req.model, disturbance_freq_hz=req.frequency())
        try:
            resim = lse_resimulation(res, params, data, u=u)
            resim_error = ""
        except ParameterError as exc:
            resim, resim_error = None, f"No re-simulation: the estimate is not physical ({exc})."
        return res, data, resim, resim_error

    async def _run_lse(self, _event=None) -> None:
        scenario = self.lse_req.scenario if self.lse_req.excitation == "paper" else None

        def apply(out, elapsed):
            res, data, resim, resim_error = out
            self.lse_result = res
            note = f"<p class='eha-note'>Simulated, identified and re-simulated in {elapsed * 1e3:.0f} ms. {resim_error}</p>"
            warn = "" if res.success else f"<div class='eha-warn'>{res.message}</div>"
            self.lse_table.object = warn + lse_table_html(res, scenario if scenario != "custom" else None) + note
            _show_figure(self.lse_plot, plots.bokeh_rows(plots.lse_fit_plot(data, resim if resim is not None else data)))

        await run_task(self.compute_lse, apply, self._lse_fail, busy=[self.lse_area])

    async def _run_lse_all(self, _event=None) -> None:
        params = self.state.params
        seed = self.lse_req.seed

        def compute():
            return {m: run_lse_table(params, disturbance_model=m, seed=seed) for m in ("constant", "harmonic")}

        def apply(results, elapsed):
            self.lse_all = results
            self.table4.object = (f"<h4>Table 4: four scenarios, both disturbance models, beside the paper "
                                  f"({elapsed * 1e3:.0f} ms)</h4>" + table4_html(results))

        await run_task(compute, apply, self._lse_fail, busy=[self.table4_area])

    def _lse_fail(self, message: str) -> None:
        self.lse_alert.object = f"The identification failed: {message}"
        self.lse_alert.visible = True

    # -- frequency domain ----------------------------------------------------------------
    def compute_freq(self):
        fi = run_frequency_identification(self.state.params, self.freq_req.config())
        figures = {"data": plots.closed_loop_plot(fi.data)}
        if fi.validation is not None:
            figures.update(fit=plots.fit_plot(fi), bode=plots.bode_plots(fi),
                           validation=plots.validation_plot(fi), residuals=plots.residual_plots(fi))
        # rendered here, in the worker thread: only swapping models is left for the page
        return fi, {k: plots.bokeh_rows(v) for k, v in figures.items()}

    async def _run_freq(self, _event=None) -> None:
        self.freq_alert.visible = False

        def apply(out, elapsed):
            fi, figures = out
            self.freq_result = fi
            timing = (f"<p class='eha-note'>Experiment, estimation, validation and figures in {elapsed:.2f} s "
                      f"(estimation alone {fi.timings.get('tfest', float('nan')):.2f} s).</p>")
            self.freq_summary.object = freq_summary_html(fi) + timing
            self.backout.object = "<h4>Backed-out parameters (eq. 27)</h4>" + backout_html(fi)
            for k, area in self.freq_plots.items():
                _show_figure(area, figures.get(k, []))

        def fail(message):
            self.freq_alert.object = f"The experiment failed: {message}"
            self.freq_alert.visible = True

        await run_task(self.compute_freq, apply, fail, busy=[self.freq_area])

    # -- layout ----------------------------------------------------------------------------
    def _lse_panel(self):
        r = self.lse_req
        custom = pn.widgets.TextInput.from_param(r.param.custom, width=260)
        custom.param.watch(lambda e: setattr(r, "custom", e.new), "value_input")
        custom.visible = pn.bind(lambda s: s == "custom", r.param.scenario)
        self.lse_errors["custom"].visible = False
        freq = pn.widgets.TextInput.from_param(r.param.freq_text, width=260)
        freq.param.watch(lambda e: setattr(r, "freq_text", e.new), "value_input")
        freq.visible = pn.bind(lambda m: m == "harmonic", r.param.model)
        controls = pn.Column(
            pn.widgets.Select.from_param(r.param.scenario, width=260, css_classes=["eha-lse-scenario"]),
            custom, self.lse_errors["custom"],
            pn.widgets.Select.from_param(r.param.model, width=260, css_classes=["eha-lse-model"]),
            freq, self.lse_errors["freq_text"],
            pn.widgets.IntInput.from_param(r.param.seed, width=120),
            pn.widgets.Select.from_param(r.param.excitation, width=260),
            self.lse_button, self.lse_all_button, width=280)
        explain = pn.pane.HTML(
            "<p class='eha-note'>Least squares on eq. 15 filtered by H(s) = 1/(0.01 s + 1) (eqs. 16-18): "
            "y<sub>1</sub> = A<sub>1</sub>p<sub>1</sub> − A<sub>2</sub>p<sub>2</sub> = M dv/dt + B v + "
            "A<sub>f</sub> S(v) + d<sub>0</sub>, and dp<sub>1</sub>/dt = β<sub>e</sub> φ<sub>2</sub>. "
            "D<sub>c</sub>, d<sub>c</sub>, L<sub>0</sub>, K<sub>q</sub> are measured; 1 kHz sensors.</p>",
            sizing_mode="stretch_width")
        return pn.Row(controls, pn.Column(explain, self.lse_alert, self.lse_area, self.table4_area,
                                          sizing_mode="stretch_width"), sizing_mode="stretch_width")

    def _freq_panel(self):
        r = self.freq_req
        w = dict(width=125)
        config = pn.Column(
            pn.widgets.Select.from_param(r.param.signal_type, width=260),
            pn.Row(pn.widgets.IntInput.from_param(r.param.n_samples, **w),
                   pn.widgets.IntInput.from_param(r.param.seed, **w)),
            pn.Row(pn.widgets.FloatInput.from_param(r.param.band_lo, **w),
                   pn.widgets.FloatInput.from_param(r.param.band_hi, **w)),
            pn.Row(pn.widgets.FloatInput.from_param(r.param.range_lo, **w),
                   pn.widgets.FloatInput.from_param(r.param.range_hi, **w)),
            pn.Row(pn.widgets.IntInput.from_param(r.param.n_sines, width=80),
                   pn.widgets.IntInput.from_param(r.param.n_trials, width=80),
                   pn.widgets.IntInput.from_param(r.param.grid_skip, width=80)),
            pn.Row(pn.widgets.FloatInput.from_param(r.param.ts, **w),
                   pn.widgets.FloatInput.from_param(r.param.kp, **w)),
            pn.widgets.Select.from_param(r.param.plant, width=260),
            pn.Row(pn.widgets.IntInput.from_param(r.param.n_poles, **w),
                   pn.widgets.IntInput.from_param(r.param.n_zeros, **w)),
            pn.Row(pn.widgets.Select.from_param(r.param.initial_condition, **w),
                   pn.widgets.Select.from_param(r.param.input_offset, **w)),
            self.freq_error, self.freq_button, width=280)
        figures = pn.Tabs(
            ("Fig. 8 excitation", self.excitation_plot),
            ("Fig. 9 closed-loop data", self.freq_plots["data"]),
            ("Fig. 11 fit", self.freq_plots["fit"]),
            ("Fig. 12 Bode", self.freq_plots["bode"]),
            ("Fig. 13 validation", self.freq_plots["validation"]),
            ("Residuals", self.freq_plots["residuals"]),
            dynamic=False, sizing_mode="stretch_width")
        return pn.Row(config, pn.Column(self.freq_alert, figures, self.freq_area, sizing_mode="stretch_width"),
                      sizing_mode="stretch_width")

    def __panel__(self):
        self._update_enabled()
        return pn.Tabs(("Time domain: least squares", self._lse_panel()),
                       ("Frequency domain: transfer function", self._freq_panel()),
                       dynamic=False, sizing_mode="stretch_width")
